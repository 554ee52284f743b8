"""Analyses layer: orbits of a period-driven sweep refined in harmonics, and the family traced with
fewer harmonics that guides a sweep with many (:mod:`femodes.nonsmooth_modes`, issue 35).

:func:`solve_in_stages` reaches an orbit with all of a problem's harmonics through ``k``, ``2k``,
... harmonics, each stage started from the last one's orbit (its new harmonics zero): with many
harmonics Newton does not converge from the linear mode or from an orbit of another family, but
does from the same orbit with fewer harmonics. :class:`Guide` is the family traced first with
``PeriodDriven.start_harmonics``: its frequency at a given energy, and its orbit at a given
frequency refined up to all the harmonics.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from .hbm.problems import NonlinearModeProblem, PeriodDrivenModeProblem
from .model import StructuralModel
from .solvers import NewtonOptions, semismooth_newton

__all__ = ["Guide", "at_frequency", "padded_coefficients", "solve_in_stages"]


def at_frequency(pd: Any, w: float) -> Callable[[np.ndarray], Any]:
    """The residual and Jacobian of the period-driven problem ``pd`` at the frequency ``w``."""
    def fun(z: np.ndarray) -> Any:
        return pd.residual(z, w)[:2]
    return fun


def padded_coefficients(Q: np.ndarray, P: np.ndarray, n_coef: int) -> tuple[np.ndarray, np.ndarray]:
    """``Q`` and ``P`` with ``n_coef`` coefficient rows: cut, or padded with zero harmonics."""
    Qk, Pk = np.zeros((n_coef, Q.shape[1])), np.zeros((n_coef, P.shape[1]))
    m = min(n_coef, Q.shape[0])
    Qk[:m], Pk[:m] = Q[:m], P[:m]
    return Qk, Pk


def solve_in_stages(model: StructuralModel, problem: NonlinearModeProblem, w: float, first: int,
                    starts: Callable[[int, tuple | None], Iterable[tuple]], newton: NewtonOptions):
    """Newton's result at ``w`` with all of ``problem``'s harmonics, reached through ``first``,
    ``2 first``, ... harmonics; at each stage with ``k`` harmonics the starts ``starts(k, previous)``
    (pairs ``(Q, P)``; ``previous`` is the last stage's orbit, None at the first) are tried in turn.
    None if every start of a stage fails."""
    s = problem.system
    H = s.h.n_harmonics
    stages = [first]
    while 2 * stages[-1] < H:
        stages.append(2 * stages[-1])
    previous = None
    res = None
    for k in stages + [H]:
        h = s.h if k == H else type(s.h)(n_harmonics=k, subharmonic=s.h.subharmonic)
        pd = PeriodDrivenModeProblem(model, h, problem.mode, reference_energy=problem.reference_energy,
                                     projection=s.projection)
        for Q, P in starts(k, previous):
            res = semismooth_newton(at_frequency(pd, w), pd.pack(*padded_coefficients(Q, P, h.n_coef), w),
                                    options=newton)
            if res.success:
                break
        else:
            return None
        u = pd.unpack(res.x, 0.0)
        previous = (u.Q, u.P)
    return res


class Guide:
    """The family traced first with fewer harmonics (``coarse``, the problem it was traced with, and
    its ``orbits``, objects with ``omega``, ``energy`` and ``x``): its frequency at a given energy
    (:meth:`holds` tells whether an orbit lies on it within ``strategy.family_tol``), and its orbit
    at a given frequency refined up to all of ``problem``'s harmonics (:meth:`refine`)."""

    def __init__(self, model, problem, coarse, orbits, strategy, newton):
        self.model, self.problem, self.coarse = model, problem, coarse
        self.strategy, self.newton = strategy, newton
        by_w = sorted(orbits, key=lambda o: o.omega)
        self.w = np.array([o.omega for o in by_w])
        self.x = np.array([o.x for o in by_w])
        self.logE_w = np.log([o.energy for o in by_w])
        by_e = sorted(orbits, key=lambda o: o.energy)
        self.logE = np.log([o.energy for o in by_e])
        self.wE = np.array([o.omega for o in by_e])

    def covers(self, w: float) -> bool:
        return bool(self.w[0] <= w <= self.w[-1])

    def _interp(self, w: float) -> np.ndarray:
        k = int(np.clip(np.searchsorted(self.w, w), 1, self.w.size - 1))
        t = (w - self.w[k - 1]) / (self.w[k] - self.w[k - 1])
        return (1.0 - t) * self.x[k - 1] + t * self.x[k]

    def padded(self, w: float) -> np.ndarray:
        """The coarse family's unknowns at ``w`` (interpolated), in the layout of all the harmonics
        (the others zero)."""
        c, s = self.coarse.system, self.problem.system
        x = self._interp(w)
        Q, P = c.split(x[: c.size])
        return np.concatenate([s.join(*padded_coefficients(Q, P, s.h.n_coef)), x[c.size:]])

    def slope(self, w: float) -> float:
        """``d log E / d w`` of the coarse family at ``w`` (between its two neighbouring orbits; nan
        outside it)."""
        if not self.covers(w):
            return math.nan
        k = int(np.clip(np.searchsorted(self.w, w), 1, self.w.size - 1))
        return float((self.logE_w[k] - self.logE_w[k - 1]) / (self.w[k] - self.w[k - 1]))

    def log_energy(self, w: float) -> float:
        """``log E`` of the coarse family at ``w`` (interpolated)."""
        return float(np.interp(w, self.w, self.logE_w))

    def omega_at(self, energy: float) -> float:
        """The coarse family's frequency at ``energy`` (interpolated in ``log E``; below or above its
        orbits, the first or last frequency)."""
        return float(np.interp(math.log(energy), self.logE, self.wE)) if energy > 0 else math.nan

    def holds(self, w: float, energy: float) -> bool:
        """Whether the orbit ``(w, energy)`` lies on the coarse family: within ``family_tol`` of its
        frequency at that energy, or, above the coarse family's last energy, not below its last
        frequency by more than that (the family's frequency rises with the energy)."""
        if not (math.isfinite(energy) and energy > 0):
            return False
        wc = self.omega_at(energy)
        tol = self.strategy.family_tol
        if math.log(energy) > self.logE[-1]:
            return w >= wc * (1.0 - tol)
        return abs(w / wc - 1.0) <= tol

    def refine(self, w: float):
        """Newton's result at ``w`` with all the harmonics, started from the coarse family's orbit
        there (interpolated between its two neighbours in ``w``; :func:`solve_in_stages` from the
        coarse harmonics), or None if ``w`` is outside the coarse family or a stage fails."""
        if not self.covers(w):
            return None
        c = self.coarse.system
        x = self._interp(w)
        start = c.split(x[: c.size])
        return solve_in_stages(self.model, self.problem, w, c.h.n_harmonics,
                               lambda k, previous: [previous if previous is not None else start], self.newton)
