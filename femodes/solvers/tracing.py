"""Solvers layer: one run of :func:`~femodes.solvers.continuation.continuation`, the tracer.

:class:`Tracer` starts (or resumes) the branch and repeats one predictor-corrector step from the
last point until the run ends. Its parts are small objects that share the run's
:class:`~femodes.solvers.trace_record.BranchRecord`: the predictor
(:class:`~femodes.solvers.predictors.Predictor`), the step size
(:class:`~femodes.solvers.step_control.StepControl`), the branch-jumping guard
(:class:`~femodes.solvers.guard.BranchGuard`), the folds
(:class:`~femodes.solvers.folds.FoldLocator`) and the exact ends on the span boundary
(:class:`~femodes.solvers.span_ends.SpanEnds`). Rejecting a step raises
:class:`~femodes.solvers.trace_record.RetryStep`; every end of the run raises
:class:`~femodes.solvers.trace_record.StopRun`, which :meth:`Tracer.trace` turns into the
:class:`~femodes.solvers.continuation_types.ContinuationResult`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any

import numpy as np

from .arclength import ArclengthSystem
from .continuation_types import (
    STATUS_MESSAGES,
    ContinuationOptions,
    ContinuationPoint,
    ContinuationResult,
    ContinuationState,
)
from .folds import FoldLocator
from .guard import BranchGuard
from .span_ends import SpanEnds
from .step_control import StepControl
from .trace_record import BranchRecord, RetryStep, StopRun, TracePoint, contraction

__all__ = ["Tracer"]

# the continuation's log channel (one for all parts of the tracer)
logger = logging.getLogger("femodes.solvers.continuation")

#: Minimal number of Newton iterations allowed for the initial correction of x0.
INITIAL_MAX_ITER = 50
#: Log progress at INFO level every this many accepted points.
LOG_EVERY = 10


class Tracer:
    """One run of :func:`continuation`: the points accepted so far and the parts of the algorithm."""

    def __init__(self, system: ArclengthSystem, options: ContinuationOptions, span: tuple[float, float],
                 start: ContinuationState | None) -> None:
        self.sys = system
        self.n = system.n
        self.opt = options
        self.p_start, self.p_end = span
        self.start = start
        self.record = BranchRecord(i0=start.index if start is not None else 0, skip=1 if start is not None else 0)
        self.x_scale: np.ndarray | None = None  # arclength scales, fixed for the whole run
        self.p_scale = math.nan
        self.predictor = options.predictor.bind(system)
        self.steps = StepControl(system, options, self.record)
        self.guard = BranchGuard(system, options, self.record, self.steps)
        self.ends = SpanEnds(system, options, span, self.record, self.emit)
        self.folds = FoldLocator(system, options, self.record, self.steps, self.ends, self.emit)

    def trace(self, x_init: np.ndarray | None) -> ContinuationResult:
        """Run from ``x_init`` (a new run) or from ``start`` until a stop; the result."""
        try:
            if self.start is None:
                if x_init is None:
                    raise ValueError("continuation: a new run needs a start point x0")
                self.begin(x_init)
            else:
                self.resume(self.start)
            while True:
                try:
                    self.advance()
                except RetryStep:
                    pass
        except StopRun as stop:
            return self.result(stop.status, stop.extra)

    # -- start ------------------------------------------------------------- #
    def begin(self, x_init: np.ndarray) -> None:
        """Correct ``x_init`` at ``p_start``, fix the scales, emit the start point with its tangent."""
        opt, n = self.opt, self.n
        init_opts = dataclasses.replace(opt.newton, max_iter=max(opt.newton.max_iter, INITIAL_MAX_ITER))
        res0 = self.sys.solve_fixed_p(x_init, self.p_start, init_opts)
        self.p_scale = float(opt.p_scale) if opt.p_scale is not None else abs(self.p_end - self.p_start)
        if not res0.success:
            self.x_scale = (np.ones(n) if opt.x_scale is None
                            else np.broadcast_to(np.asarray(opt.x_scale, float), (n,)).copy())
            raise StopRun(5, f"Newton at p={self.p_start:g}: {res0.message}")
        x_start = np.array(res0.x)
        if opt.x_scale is None:
            rms = float(np.sqrt(np.mean(x_start**2)))
            x_scale = np.full(n, rms if rms > 0 and np.isfinite(rms) else 1.0)
        else:
            x_scale = np.broadcast_to(np.asarray(opt.x_scale, dtype=float), (n,)).copy()
        self.set_scales(x_scale, self.p_scale)
        self.first_point(x_start, res0.nit, res0.residual_norm)

    def first_point(self, x_start: np.ndarray, nit: int, rnorm: float) -> None:
        """Start point with the tangent ``[[r_x, r_p], [e_p^T]] t = e_{n+1}``, oriented by ``direction``."""
        n = self.n
        e_p = np.zeros(n + 1)
        e_p[n] = 1.0
        y0 = np.append(x_start, self.p_start)
        t0 = self.sys.tangent_at(x_start, self.p_start, e_p)
        first = TracePoint(y=y0, t=t0 if t0 is not None else np.full(n + 1, np.nan), nit=nit, rnorm=rnorm, step=0.0)
        if t0 is None:
            self.record.pts.append(first)
            raise StopRun(6, f"r_x singular at the start point p={self.p_start:g} (start exactly at a fold?)")
        if np.sign(t0[n]) != self.opt.direction * self.ends.span_sign:
            t0 = -t0
            t0.flags.writeable = False
            first.t = t0
        self.steps.ds = float(self.opt.step)
        self.folds.last_sign = float(np.sign(t0[n]))
        if not self.emit(first, False, self.steps.ds):
            raise StopRun(3)

    def resume(self, start: ContinuationState) -> None:
        """Continue from ``start``: its point (not returned again), tangent, step, folds, scales, counters."""
        self.set_scales(np.array(start.x_scale), start.p_scale)
        self.sys.n_newton = start.n_newton
        self.steps.n_rejected = start.n_rejected
        self.record.pts.append(TracePoint(y=np.append(start.x, start.p), t=start.tangent, nit=0, rnorm=math.nan,
                                          step=0.0))
        self.record.folds.extend(start.folds)
        self.steps.ds = min(max(start.step, self.opt.min_step), self.opt.max_step)
        self.folds.last_sign = start.dp_sign

    def set_scales(self, x_scale: np.ndarray, p_scale: float) -> None:
        """Fix the arclength scales of the run."""
        x_scale.flags.writeable = False  # shared by the result and every ContinuationState
        self.x_scale, self.p_scale = x_scale, p_scale
        self.sys.set_scales(x_scale, p_scale)

    # -- one step ---------------------------------------------------------- #
    def advance(self) -> None:
        """Predictor, corrector, end and fold tests, step control and emission of one point."""
        n, rec, ends, steps = self.n, self.record, self.ends, self.steps
        if rec.i0 + len(rec.pts) >= self.opt.max_points:
            raise StopRun(2, f"{rec.i0 + len(rec.pts)} points, last p={rec.pts[-1].y[n]:g}")
        a = rec.pts[-1]
        y_pred = self.predictor.predict(a, steps.ds)
        bound = ends.crossed(y_pred[n])
        if bound is not None:
            ends.try_finish(a, y_pred, bound)
            # the branch may turn back before the boundary: do a regular step
        b = self.correct(a, y_pred)
        bound = ends.crossed(b.y[n])
        if bound is not None:
            ends.try_finish(a, b.y, bound)
            steps.reject(a, f"end point at p={bound:g} could not be computed",
                         failure=f"end point at p={bound:g} could not be computed")
        is_fold_b = self.folds.detect(a, b)
        # step control before emitting b: its state carries the next step
        steps.control(b)
        if not self.emit(b, is_fold_b, steps.ds):
            raise StopRun(3)

    def correct(self, a: TracePoint, y_pred: np.ndarray) -> TracePoint:
        """Corrector from ``y_pred`` on the hyperplane orthogonal to ``a.t``, and the new tangent."""
        n, steps = self.n, self.steps
        res = self.sys.correct(y_pred, self.sys.w * a.t, self.opt.corrector_deadline)
        if not res.success:
            steps.prev_geo = None
            steps.reject(a, f"corrector failed: {res.message}",
                         failure=f"at p={a.y[n]:g} (last corrector: {res.message})")
        t_b = self.sys.tangent_from(res.jac)
        if t_b is None:
            steps.prev_geo = None
            steps.reject(a, "singular bordered system at the new point",
                         failure=f"at p={a.y[n]:g} (singular bordered system)")
        y_b = np.array(res.x)
        angle, dist = self.guard.check(a, y_pred, y_b, t_b, self.predictor.reference_tangent(a))
        return TracePoint(y=y_b, t=t_b, nit=res.nit, rnorm=float(np.max(np.abs(res.fun[:n]))), step=steps.ds,
                          angle=angle, dist=dist, theta=contraction(res.history), tau=self.predictor.tau or 0.0)

    # -- output ------------------------------------------------------------ #
    def emit(self, q: TracePoint, is_fold: bool, next_step: float | None) -> bool:
        """Append an accepted point; return False if the callback asks to stop.

        ``next_step``: the step the run takes from ``q``, or ``None`` if the
        run does not continue from ``q`` (inserted fold point, end point).
        """
        n, rec = self.n, self.record
        rec.pts.append(q)
        idx = rec.last_index()
        if is_fold:
            rec.folds.append(idx)
        if idx % LOG_EVERY == 0:
            logger.info("continuation: point %d p=%.6g step=%.3g nit=%d |r|=%.2e",
                        idx, q.y[n], q.step, q.nit, q.rnorm)
        if self.opt.callback is None:
            return True
        xv = q.y[:n].copy()
        xv.flags.writeable = False
        state = None if next_step is None else self.state(xv, q, idx, next_step)
        cp = ContinuationPoint(x=xv, p=float(q.y[n]), tangent=q.t, nit=q.nit, residual_norm=q.rnorm,
                               step=q.step, is_fold=is_fold, index=idx, state=state)
        return self.opt.callback(cp) is not False

    def state(self, xv: np.ndarray, q: TracePoint, idx: int, next_step: float) -> ContinuationState:
        """What a resumed run needs to continue from point ``idx`` (``q``, unknowns ``xv``)."""
        assert self.x_scale is not None  # fixed when the run began
        return ContinuationState(
            x=xv, p=float(q.y[self.n]), tangent=q.t, step=next_step, index=idx, folds=tuple(self.record.folds),
            dp_sign=self.folds.last_sign, x_scale=self.x_scale, p_scale=self.p_scale, n_newton=self.sys.n_newton,
            n_rejected=self.steps.n_rejected,
        )

    def result(self, status: int, extra: str = "") -> ContinuationResult:
        """The points after ``start`` (all points of a new run) as read-only arrays, and the outcome."""
        n, rec = self.n, self.record
        msg = STATUS_MESSAGES[status] + (f": {extra}" if extra else "")
        out = rec.pts[rec.skip:]
        store = self.opt.store_tangents
        if out:
            X = np.array([q.y[:n] for q in out])
            P = np.array([q.y[n] for q in out])
            T = np.array([q.t for q in out]) if store else None
        else:
            X = np.empty((0, n))
            P = np.empty(0)
            T = np.empty((0, n + 1)) if store else None
        arrays: dict[str, Any] = dict(
            x=X,
            p=P,
            nit=np.array([q.nit for q in out], dtype=int),
            residual_norm=np.array([q.rnorm for q in out], dtype=float),
            step=np.array([q.step for q in out], dtype=float),
            tangents=T,
            x_scale=self.x_scale,
        )
        for a in arrays.values():
            if a is not None:
                a.flags.writeable = False
        success = status <= 3
        (logger.info if success and status != 2 else logger.warning)(  # max_points: the span is not done
            "continuation finished: %s (%d points, %d folds, %d Newton iterations, %d rejected steps)",
            msg, rec.i0 + len(rec.pts), len(rec.folds), self.sys.n_newton, self.steps.n_rejected,
        )
        return ContinuationResult(
            folds=tuple(rec.folds),
            success=success,
            status=status,
            message=msg,
            n_newton=self.sys.n_newton,
            n_rejected=self.steps.n_rejected,
            p_scale=self.p_scale,
            first_index=rec.i0 + rec.skip,
            located=tuple(rec.located),
            **arrays,
        )
