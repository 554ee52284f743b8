"""The levels estimator (:class:`Levels`): each point solved again with other numbers of harmonics
(``H // 2, H, 2 H``: :func:`~.extrapolation.estimate_levels`) on its hyperplane, the error from
their contraction and, with rigid impacts, the converged frequency bracketed by extrapolation
(:class:`~.extrapolation.PointLevels`). With ``rtol``, the points whose bracket is wider get further
levels ``4 H``, ``8 H``, ... up to ``max_harmonics``, each traced by a continuation of its own over
the part of the branch that needs it (:mod:`.level_trace`).
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from .extrapolation import PointLevels, bounded_by_bracket, contracting, estimate_levels
from .ladder import Ladder
from .level_trace import trace_by_continuation, trace_level_by_continuation
from .options import AccuracyOptions
from .points import anchor, period_driven, without_contact
from .protocol import PointErrors
from .walk import trace_level

__all__ = ["Levels"]

log = logging.getLogger(__name__)


class Levels:
    """Harmonic balance at other numbers of harmonics, extrapolated in ``H`` (an
    :class:`~.protocol.Estimator`); ``rtol`` (with ``max_harmonics``) refines the brackets of
    branches with complementarity contacts. Raises :class:`~.ladder.OutOfTime` past the ladder's
    deadline, with the estimates done so far in the record."""

    def __init__(self, options: AccuracyOptions, rtol: float | None = None, max_harmonics: int | None = None):
        self.options, self.rtol, self.max_harmonics = options, rtol, max_harmonics

    def estimate(self, lad: Ladder, errors: PointErrors, todo: np.ndarray) -> np.ndarray:
        branch = lad.branch
        H = branch.harmonics.n_harmonics
        levels, of = estimate_levels(H)
        if H >= 4 and H % 2:
            log.info("accuracy: odd H = %d: levels %d, %d, %d (H // 2 would not be a doubling; an even H is "
                     "about 4x cheaper to estimate)", H, *levels)
        impacts = "complementarity" in branch.contacts.kinds
        traced = self._trace(lad, levels, todo, impacts)
        for i in np.flatnonzero(todo):
            sts = [t[i] for t in traced]
            if any(st is None for st in sts):
                continue
            lv = PointLevels(sts, lad.Q_norm(i), lad.omega_ref(i), self.options)
            errors.omega[i], errors.amplitude[i], errors.rate[i] = lv.error(2, of=of)
            if impacts:
                errors.omega_limit[i], errors.omega_limit_error[i] = lv.frequency_bracket()
                errors.omega[i] = bounded_by_bracket(errors.omega[i], sts[of].omega, errors.omega_limit[i],
                                                     errors.omega_limit_error[i], lad.omega_ref(i))
        errors.finest[todo] = levels[-1]
        if self.rtol is not None and impacts:
            self._refine(lad, errors, todo, [[t[i] for t in traced] for i in range(len(branch))], levels[-1])
        return np.zeros(len(branch), dtype=bool)

    def _trace(self, lad: Ladder, levels: list[int], todo: np.ndarray, impacts: bool) -> list[list]:
        """Every level's states at every point (None where it has none near the point): traced over
        the whole branch, or, for some points only (where shooting failed), by continuations over
        their part of the branch."""
        branch = lad.branch
        H = branch.harmonics.n_harmonics
        traced = []
        if todo.all():
            by_continuation = impacts and not period_driven(branch)
            for H_l in levels:
                t0 = time.perf_counter()
                lad.level_times[H_l] = math.nan  # started
                if by_continuation:
                    traced.append(trace_level_by_continuation(lad, H_l, self.options))
                else:
                    traced.append(trace_level(lad, H_l, self.options))
                lad.level_times[H_l] = time.perf_counter() - t0
                lad.check_time()
            return traced
        free = without_contact(branch)
        for H_l in levels:
            if H_l == H:
                sts = [anchor(branch, i) for i in range(len(branch))]
            else:
                sts = trace_by_continuation(lad, H_l, todo, self.options)
            lad.check_time()
            for i in np.flatnonzero(free):
                sts[i] = lad.padded(H_l, i)
            traced.append(sts)
        return traced

    def _refine(self, lad: Ladder, errors: PointErrors, todo: np.ndarray, chains: list[list], top: int) -> None:
        """Further levels ``2 top``, ``4 top``, ... up to ``max_harmonics`` for the points whose
        bracket is wider than ``rtol`` (or who have none) and whose last levels contract; each
        point's bracket then from its last three levels."""
        rtol, n = self.rtol, len(lad.branch)
        while 2 * top <= self.max_harmonics:
            err = np.where(np.isfinite(errors.omega_limit_error), errors.omega_limit_error, errors.omega)
            need = todo & ~(np.isfinite(err) & (err <= rtol)) & (errors.finest == top)
            stays = np.array([need[i] and not contracting(chains[i], lad.Q_norm(i), lad.omega_ref(i))
                              for i in range(n)], dtype=bool)
            if stays.any():
                log.info("accuracy: %d point(s) above rtol = %g whose last levels do not contract (or are missing): "
                         "no level H = %d for them (no convergence to extrapolate)", int(stays.sum()), rtol, 2 * top)
            need &= ~stays
            if not need.any():
                break
            top *= 2
            lad.check_time()
            log.info("accuracy: %d point(s) above rtol = %g; level H = %d", int(need.sum()), rtol, top)
            states = trace_by_continuation(lad, top, need, self.options)
            lad.check_time()
            for i in np.flatnonzero(need):
                if states[i] is None or any(st is None for st in chains[i][-2:]):
                    continue
                chains[i] = chains[i][-2:] + [states[i]]
                lv = PointLevels(chains[i], lad.Q_norm(i), lad.omega_ref(i), self.options)
                errors.omega_limit[i], errors.omega_limit_error[i] = lv.frequency_bracket()
                errors.finest[i] = top
