"""Solvers layer: the exact end of a continuation run on the boundary of its parameter span:
when a predictor or a corrected point passes ``p_end`` (or ``p_start`` after turning back), the
last point is computed exactly at that ``p`` by Newton in ``x`` from a linear interpolation."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from .arclength import ArclengthSystem
from .continuation_types import ContinuationOptions
from .trace_record import BranchRecord, StopRun, TracePoint

__all__ = ["SpanEnds"]

# the continuation's log channel (one for all parts of the tracer)
logger = logging.getLogger("femodes.solvers.continuation")


class SpanEnds:
    """The span ``(p_start, p_end)`` of a run and its end points; ``emit(point, is_fold,
    next_step)`` appends a point to the run."""

    def __init__(self, system: ArclengthSystem, options: ContinuationOptions, span: tuple[float, float],
                 record: BranchRecord, emit: Callable[[TracePoint, bool, float | None], bool]) -> None:
        self.sys = system
        self.n = system.n
        self.opt = options
        self.p_start, self.p_end = span
        self.span_sign = 1.0 if self.p_end > self.p_start else -1.0
        self.record = record
        self.emit = emit

    def crossed(self, p: float) -> float | None:
        """The span boundary that ``p`` lies beyond, if any."""
        if self.span_sign * (p - self.p_end) > 0:
            return self.p_end
        if self.span_sign * (p - self.p_start) < 0:
            return self.p_start
        return None

    def try_finish(self, a: TracePoint, y_far: np.ndarray, bound: float) -> None:
        """End the run (status 0 at ``p_end``, 1 at ``p_start``) with a point exactly at ``p = bound``
        between ``a`` and ``y_far``; return if that point cannot be computed."""
        n, rec = self.n, self.record
        if a.y[n] == bound:  # already on the boundary (e.g. direction=-1 at the start)
            raise StopRun(0 if bound == self.p_end else 1)
        got = self.end_point(a, y_far, bound)
        if got is None:
            return
        q, fold = got
        if fold:
            # record the point nearest to the fold (smaller |dp/ds|)
            if abs(q.t[n]) >= abs(a.t[n]):
                fold = False
                if not (rec.folds and rec.folds[-1] == rec.last_index()):
                    rec.folds.append(rec.last_index())
        self.emit(q, fold, None)
        raise StopRun(0 if bound == self.p_end else 1)

    def end_point(self, a: TracePoint, y_far: np.ndarray, bound: float) -> tuple[TracePoint, bool] | None:
        """Point exactly at ``p = bound`` from linear interpolation between ``a`` and ``y_far``,
        and whether ``dp/ds`` changed sign from ``a``."""
        n, opt = self.n, self.opt
        pa, pf = a.y[n], y_far[n]
        theta = (bound - pa) / (pf - pa)
        y_lin = a.y + theta * (y_far - a.y)
        res = self.sys.solve_fixed_p(y_lin[:n], bound)
        if not res.success:
            logger.debug("end point at p=%g failed: %s", bound, res.message)
            return None
        y_end = np.append(res.x, bound)
        chord = self.sys.norm(y_far - a.y)
        if self.sys.norm(y_end - y_lin) > opt.max_corrector_distance * max(chord, opt.min_step):
            logger.debug("end point at p=%g rejected: too far from the interpolation", bound)
            return None
        t_end = self.sys.tangent_at(res.x, bound, self.sys.w * a.t)
        if t_end is None:
            logger.warning("tangent at the end point p=%g is singular; using the previous tangent", bound)
            t_end = a.t
        fold = bool(np.sign(t_end[n]) * np.sign(a.t[n]) < 0)
        return (TracePoint(y=y_end, t=t_end, nit=res.nit, rnorm=res.residual_norm, step=self.sys.norm(y_end - a.y)),
                fold)
