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
from .ladder import Ladder

__all__ = ["Estimator", "PointErrors"]


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

    def record_exact(self, lad: Ladder, i: int, w: float, half: float, Q: np.ndarray, hk: Harmonics) -> None:
        """Point ``i``'s estimate from an exact orbit: its frequency ``w`` (relative half-width
        ``half``) and displacement coefficients ``Q`` on the harmonics ``hk`` (8 H: the error
        includes the tail)."""
        branch = lad.branch
        dQ = Q - lad.harmonics(branch.harmonics.n_harmonics).convert(branch.Q[i], hk)
        self.omega_limit[i], self.omega_limit_error[i] = w, half
        self.omega[i] = abs(branch.omega_truncated[i] - w) / lad.omega_ref(i) + half
        self.amplitude[i] = float(np.linalg.norm(dQ)) / lad.Q_norm(i)
        self.rate[i] = math.nan
        self.finest[i] = 0
        self.method[i] = "shooting"


class Estimator(Protocol):
    """A way to the error of a branch's points (a strategy of :func:`~femodes.estimate_error`)."""

    def estimate(self, lad: Ladder, errors: PointErrors, todo: np.ndarray) -> np.ndarray:
        """Estimate the points ``todo`` (a boolean mask over ``lad.branch``) into ``errors``;
        return the mask of the points left to the next estimator. ValueError if the estimator
        cannot take the branch at all (``errors`` may then hold part of its work:
        :meth:`PointErrors.clear`)."""
        ...
