"""Solvers layer: folds (turning points) of a continuation run: a sign change of ``dp/ds``
between consecutive points is located by regula falsi on ``dp/ds`` along the step family and
inserted as a point (``ContinuationOptions.locate_folds``), or the nearer point is marked."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from .arclength import ArclengthSystem
from .continuation_types import ContinuationOptions
from .roots import illinois
from .span_ends import SpanEnds
from .step_control import StepControl
from .trace_record import BranchRecord, StopRun, TracePoint

__all__ = ["FoldLocator", "FOLD_MAX_ITER", "FOLD_TOL", "FOLD_SHARP_ITER", "FOLD_ACCEPT", "FOLD_RETRY_STEP"]

# the continuation's log channel (one for all parts of the tracer)
logger = logging.getLogger("femodes.solvers.continuation")

#: Iterations and tolerance of the fold localisation (regula falsi on dp/ds).
FOLD_MAX_ITER = 12
FOLD_TOL = 1e-9
#: Further evaluations, with bisection where regula falsi does not halve the bracket, for a fold
#: that ``FOLD_MAX_ITER`` did not locate although every corrector converged (a sharp fold:
#: ``dp/ds`` turns within a small part of the step). The exact branch of the cantilever with 3 %
#: modal damping (benchmarks/README_accuracy.md, section 5) turns at its lower fold within about
#: 1e-4 of the step: regula falsi left ``|dp/ds|`` at 0.035 of 0.04 after 12 evaluations, and
#: the step was halved nine times before a step short enough located it (1380 runs of the exact
#: flow for the branch); with 16 more evaluations it is located after one halving (996 runs).
FOLD_SHARP_ITER = 16
#: A fold counts as located when ``|dp/ds|`` at the best point found is at most this fraction of
#: the larger ``|dp/ds|`` at the two ends of the step (regula falsi converged, not stopped by a
#: failed corrector). Seed case 1, penalty law, H = 40, phase predictor: a step of 0.83 across the
#: lower fold (a grazing point) had its second trial corrector fail, and the one point found
#: (|dp/ds| 0.027 of 0.12) was taken as the fold, 0.4 % off in w.
FOLD_ACCEPT = 1e-3
#: A fold that is not located (``FOLD_ACCEPT``) is retried with the step halved while the step is
#: longer than this fraction of the initial step (``ContinuationOptions.step``); below it the
#: nearer end of the step is marked (a rule of the step alone, so that a resumed run repeats it;
#: with the initial step itself as the limit, seed case 2 at H = 10 marked one 0.24 % off). 1/64:
#: on the penalty seed case at H = 40 (tangent predictor, ``target_norm_change=0.3``) the lower
#: fold, a corner at grazing, is located with the shorter steps; with 1/4 its step stopped at
#: 0.0125 and the marked point was 2e-4 off in w. Where folds are located anyway (the benchmark
#: cases with the default options) nothing changes.
FOLD_RETRY_STEP = 1.0 / 64.0


class FoldLocator:
    """The folds of one run; :attr:`last_sign` is the sign of ``dp/ds`` at the last point where it
    was non-zero. ``emit(point, is_fold, next_step)`` appends a point to the run."""

    def __init__(self, system: ArclengthSystem, options: ContinuationOptions, record: BranchRecord,
                 steps: StepControl, ends: SpanEnds, emit: Callable[[TracePoint, bool, float | None], bool]) -> None:
        self.sys = system
        self.n = system.n
        self.opt = options
        self.record = record
        self.steps = steps
        self.ends = ends
        self.emit = emit
        self.last_sign = 0.0

    def detect(self, a: TracePoint, b: TracePoint) -> bool:
        """Handle a sign change of ``dp/ds`` between ``a`` and ``b``; True if ``b`` is the fold point."""
        sign_b = float(np.sign(b.t[self.n]))
        is_fold_b = False
        if sign_b != 0 and self.last_sign != 0 and sign_b != self.last_sign:
            is_fold_b = self.record_fold(a, b)
        if sign_b != 0:
            self.last_sign = sign_b
        return is_fold_b

    def record_fold(self, a: TracePoint, b: TracePoint) -> bool:
        """Locate the fold between ``a`` and ``b`` and emit it, or (not located) mark the nearer of
        the two; True if that is ``b``.  A located fold beyond the span ends the run there."""
        n, opt, rec, steps = self.n, self.opt, self.record, self.steps
        located = None
        tried = opt.locate_folds and rec.i0 + len(rec.pts) + 2 <= opt.max_points
        if tried:
            located = self.locate(a, steps.ds, b)
        if located is None and tried and steps.ds > FOLD_RETRY_STEP * opt.step and 0.5 * steps.ds >= opt.min_step:
            steps.reject(a, "fold not located: a shorter step", failure="fold not located")
        bound = None if located is None else self.ends.crossed(located.y[n])
        if located is not None and bound is not None:
            # the branch left the span between a and b (excursion through the
            # fold): stop on the boundary before the fold
            logger.info("continuation: branch leaves the span through p=%g before a fold", bound)
            self.ends.try_finish(a, located.y, bound)
            steps.reject(a, f"fold beyond p={bound:g}, but the end point could not be computed",
                         failure=f"end point at p={bound:g} could not be computed")
        if located is not None:
            logger.info("continuation: fold located at p=%.8g", located.y[n])
            rec.located.append(rec.i0 + len(rec.pts))  # the index emit gives it
            if not self.emit(located, True, None):
                raise StopRun(3)
            return False
        here = rec.last_index()  # index of a
        is_fold_b = bool(abs(b.t[n]) <= abs(a.t[n]) or (rec.folds and rec.folds[-1] == here))
        if not is_fold_b:
            rec.folds.append(here)
        logger.info("continuation: fold detected near p=%.8g", (b if is_fold_b else a).y[n])
        return is_fold_b

    def locate(self, a: TracePoint, ds: float, b: TracePoint) -> TracePoint | None:
        """Regula falsi (Illinois) on s -> dp/ds along the step family from ``a``."""
        n = self.n
        c = self.sys.w * a.t
        found: list[TracePoint] = []

        def dp_ds(s: float) -> float | None:
            res = self.sys.correct(a.y + s * a.t, c)
            if not res.success:
                return None
            t = self.sys.tangent_from(res.jac)
            if t is None:
                return None
            found.append(TracePoint(y=np.array(res.x), t=t, nit=res.nit, rnorm=float(np.max(np.abs(res.fun[:n]))),
                                    step=s))
            return t[n]

        def best() -> TracePoint | None:
            q = min(found, key=lambda q: abs(q.t[n])) if found else None
            return None if q is None or abs(q.t[n]) > FOLD_ACCEPT * max(abs(a.t[n]), abs(b.t[n])) else q

        br = illinois(dp_ds, 0.0, ds, a.t[n], b.t[n], max_iter=FOLD_MAX_ITER, ftol=FOLD_TOL, xtol=1e-12 * ds)
        if best() is None and br.nfev == FOLD_MAX_ITER and len(found) == br.nfev:
            # a sharp fold: dp/ds turns within a small part of the step and looks like a jump on its
            # scale, where regula falsi crawls; bisection narrows the bracket down to where it turns
            illinois(dp_ds, br.lo, br.hi, br.f_lo, br.f_hi, max_iter=FOLD_SHARP_ITER, ftol=FOLD_TOL,
                     xtol=1e-12 * ds, bisect_if_slow=True)
        return best()
