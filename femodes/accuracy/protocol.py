"""The estimators' common ground: the per-point record they fill (:class:`PointErrors`) and the
small protocol each estimator follows (:class:`Estimator`). :func:`~femodes.estimate_error` runs
them in turn, each on the points the ones before it left:

* :class:`~.shooting.Shooting`: the exact orbits of the flow with rigid stops on the points'
  hyperplanes (the ``H -> inf`` limit itself), folds by a fold search on the exact curve;
* :class:`~.exact_branch.ExactFolds`: the folds the fold search missed, paired with the folds
  of the exact branch over the span;
* :class:`~.levels.Levels`: harmonic balance at other numbers of harmonics (the levels),
  extrapolated in ``H``; the only estimator of smooth laws, penalty contacts and nonlinear modes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..hbm.harmonics import Harmonics
from ..results.error_estimate import AMPLITUDE_SAMPLES, AMPLITUDE_SAMPLING
from .ladder import Ladder

__all__ = ["orbit_amplitudes", "Estimator", "PointErrors"]


@dataclass
class PointErrors:
    """The estimate of every point of a branch as the estimators fill it (arrays over the points;
    the fields of :class:`~femodes.results.ErrorEstimate` of the same names; ``omega_limit`` and
    ``omega_limit_error`` only with complementarity contacts)."""

    omega: np.ndarray
    amplitude: np.ndarray
    rate: np.ndarray
    omega_limit: np.ndarray | None
    omega_limit_error: np.ndarray | None
    finest: np.ndarray
    method: np.ndarray
    #: ``max_t |q_d(t)|`` of each point's exact orbit per DOF (``(n_points, n_dofs)``, NaN rows
    #: where no exact orbit answered); created by the first :meth:`record_exact`
    amplitude_limit: np.ndarray | None = None
    #: relative error bar of those amplitudes per point (NaN where there are none)
    amplitude_limit_error: np.ndarray | None = None

    @classmethod
    def empty(cls, n: int, impacts: bool, finest: int) -> PointErrors:
        """No estimate yet at ``n`` points (method "doubling", the levels' finest ``finest``)."""
        nan = np.full(n, np.nan)
        return cls(nan.copy(), nan.copy(), nan.copy(), nan.copy() if impacts else None,
                   nan.copy() if impacts else None, np.full(n, finest), np.full(n, "doubling", dtype=object))

    def clear(self) -> None:
        """Every estimate dropped (``finest`` kept): an estimator that failed half way."""
        self.omega[:] = self.amplitude[:] = self.rate[:] = np.nan
        if self.omega_limit is not None:
            self.omega_limit[:] = self.omega_limit_error[:] = np.nan
        self.method[:] = "doubling"
        self.amplitude_limit = self.amplitude_limit_error = None

    def record_exact(self, lad: Ladder, i: int, w: float, half: float, Q: np.ndarray, hk: Harmonics,
                     amplitudes: np.ndarray | None = None, amplitude_error: float | None = None) -> None:
        """Point ``i``'s estimate from an exact orbit: its frequency ``w`` (relative half-width
        ``half``) and displacement coefficients ``Q`` on the harmonics ``hk`` (8 H: the error
        includes the tail); with the orbit's ``amplitudes`` per DOF at ``w``
        (:func:`orbit_amplitudes` of its run), their relative error bar
        ``amplitude_error`` (default: ``half``; at a fold, where the amplitude moves like the
        square root of the frequency, ``sqrt(half)``), at least the sampling's."""
        branch = lad.branch
        if amplitudes is not None:
            if self.amplitude_limit is None:
                self.amplitude_limit = np.full((len(branch), branch.Q.shape[2]), np.nan)
                self.amplitude_limit_error = np.full(len(branch), np.nan)
            self.amplitude_limit[i] = amplitudes
            if amplitude_error is None or not math.isfinite(amplitude_error):
                amplitude_error = math.sqrt(half) if i in branch.folds else half
            self.amplitude_limit_error[i] = max(amplitude_error, AMPLITUDE_SAMPLING)
        dQ = Q - lad.harmonics(branch.harmonics.n_harmonics).layout.convert(branch.Q[i], hk)
        self.omega_limit[i], self.omega_limit_error[i] = w, half
        self.omega[i] = abs(branch.omega_truncated[i] - w) / lad.omega_ref(i) + half
        self.amplitude[i] = float(np.linalg.norm(dQ)) / lad.Q_norm(i)
        self.rate[i] = math.nan
        self.finest[i] = 0
        self.method[i] = "shooting"


def orbit_amplitudes(run) -> np.ndarray:
    """``max_t |q_d(t)|`` per DOF of an exact orbit (a run of one period of the exact flow), from
    its closed form at :data:`~femodes.results.error_estimate.AMPLITUDE_SAMPLES` equidistant times and at its contact events
    (where the maximum of a contact DOF sits, at the stop): a smooth maximum between samples
    ``dt`` apart is missed by at most ``(w_max dt)^2 / 8`` of it, 1.9e-5 for the harmonics up to
    the 8th (:data:`~femodes.results.error_estimate.AMPLITUDE_SAMPLING`). Evaluated in blocks of
    times (the memory of a few columns of the model, not of the whole period)."""
    t = np.linspace(run.t0, run.t1, AMPLITUDE_SAMPLES + 1)
    events = [tb for (_, tb, _, _) in run.segments]
    t = np.unique(np.clip(np.concatenate([t, events]), run.t0, run.t1))
    return np.max([np.max(np.abs(run.displacement(t[k:k + 512])), axis=0) for k in range(0, t.size, 512)], axis=0)


class Estimator(Protocol):
    """A way to the error of a branch's points (a strategy of :func:`~femodes.estimate_error`)."""

    def estimate(self, lad: Ladder, errors: PointErrors, todo: np.ndarray) -> np.ndarray:
        """Estimate the points ``todo`` (a boolean mask over ``lad.branch``) into ``errors``;
        return the mask of the points left to the next estimator. ValueError if the estimator
        cannot take the branch at all (``errors`` may then hold part of its work:
        :meth:`PointErrors.clear`)."""
        ...
