"""Solvers layer: the branch-jumping guard of a continuation step. A corrected point too far from
the predictor, whose tangent turned too much, or that landed on the part of the branch already
traced going the same way, is rejected (the step halved), unless it is a kink of the branch or the
step is minimal."""

from __future__ import annotations

import logging
import math

import numpy as np

from .arclength import ArclengthSystem
from .continuation_types import ContinuationOptions
from .step_control import StepControl
from .trace_record import BranchRecord, TracePoint

__all__ = ["BranchGuard", "RETRACE_DISTANCE", "RETRACE_SKIP", "RETRACE_ANGLE"]

# the continuation's log channel (one for all parts of the tracer)
logger = logging.getLogger("femodes.solvers.continuation")

#: Retrace guard (:meth:`BranchGuard.retraced`): a corrected point within this many steps ``ds`` of
#: the branch already traced (all but the last RETRACE_SKIP points), in a direction within
#: RETRACE_ANGLE degrees of the branch there, is a jump back onto it.
RETRACE_DISTANCE = 0.5
RETRACE_SKIP = 3
RETRACE_ANGLE = 30.0


class BranchGuard:
    """The guard of the steps of one run, on its ``record`` of accepted points."""

    def __init__(self, system: ArclengthSystem, options: ContinuationOptions, record: BranchRecord,
                 steps: StepControl) -> None:
        self.sys = system
        self.n = system.n
        self.opt = options
        self.record = record
        self.steps = steps

    def check(self, a: TracePoint, y_pred: np.ndarray, y_b: np.ndarray, t_b: np.ndarray,
              t_ref: np.ndarray) -> tuple[float, float]:
        """Reject (:meth:`StepControl.reject`) a corrected point ``y_b`` too far from the predictor
        ``y_pred`` or whose tangent ``t_b`` turned too much from ``t_ref`` (the previous tangent,
        delayed by the predictor's phase), unless it is a kink of the branch or the step is
        minimal. Returns the turn angle (degrees) and the predictor-corrector distance of an
        accepted step."""
        opt, steps = self.opt, self.steps
        dist = self.sys.norm(y_b - y_pred)
        angle = math.degrees(math.acos(max(-1.0, min(1.0, self.sys.dot(t_ref, t_b)))))
        geometric = None
        if dist > opt.max_corrector_distance * steps.ds:
            geometric = f"corrector moved {dist:.3g} > {opt.max_corrector_distance:g}*ds from the predictor"
        elif angle > opt.max_turn_angle:
            geometric = f"tangent turned by {angle:.1f} deg"
        else:
            geometric = self.retraced(y_b, t_b)
        if geometric is not None:
            if steps.is_kink(angle, dist):
                logger.info("continuation: accepting a kink of the branch at p=%.6g (%s)", y_b[self.n], geometric)
            elif 0.5 * steps.ds >= opt.min_step:
                steps.prev_geo = (angle, dist)
                steps.reject(a, geometric, failure=geometric)  # the halved step stays >= min_step: a retry
            else:
                logger.info("accepting step at minimal step size despite: %s (kink of the branch?)", geometric)
        steps.prev_geo = None
        return angle, dist

    def retraced(self, y_b: np.ndarray, t_b: np.ndarray) -> str | None:
        """Why the corrected point ``y_b`` (tangent ``t_b``) is on the part of the branch already
        traced, going the same way, or None: within ``RETRACE_DISTANCE * ds`` of a segment between
        two accepted points (all but the last :data:`RETRACE_SKIP`) whose direction is within
        :data:`RETRACE_ANGLE` of ``t_b``. A corrector can land there after a sharp turn, and the run
        then repeats the same loop until ``max_points`` (20-DOF cantilever with a tip stop, H = 20:
        after the second fold of a tongue a step turned by 57 degrees, under ``max_turn_angle``,
        back onto the branch 0.03 lower in w; 89 folds in 2000 points). The other side of a fold is
        traced the opposite way and a crossing of the branch with itself at an angle, so neither
        is taken for a retrace."""
        pts, n = self.record.pts, self.n
        m = len(pts) - RETRACE_SKIP
        if m < 2:
            return None
        w = self.sys.w
        reach = RETRACE_DISTANCE * self.steps.ds
        # the parameter part of the distance alone bounds it from below: only the segments whose
        # parameter range comes within reach of y_b's are measured in full (no copy of the whole
        # branch per step: 1e5-1e6 unknowns times hundreds of points)
        P = np.array([q.y[n] for q in pts[:m]])
        lo, hi = np.minimum(P[:-1], P[1:]), np.maximum(P[:-1], P[1:])
        gap = np.maximum(np.maximum(lo - y_b[n], y_b[n] - hi), 0.0)
        near = np.flatnonzero(math.sqrt(w[n]) * gap < reach)
        if not near.size:
            return None
        Y0 = np.array([pts[k].y for k in near])
        D = np.array([pts[k + 1].y for k in near]) - Y0  # segments k -> k + 1
        R = y_b - Y0
        dd = np.einsum("ij,ij,j->i", D, D, w)
        theta = np.clip(np.einsum("ij,ij,j->i", R, D, w) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        E = R - theta[:, None] * D
        dist = np.sqrt(np.maximum(np.einsum("ij,ij,j->i", E, E, w), 0.0))
        cos = np.einsum("ij,j,j->i", D, t_b, w) / np.sqrt(np.where(dd > 0, dd, np.inf))
        hit = (dist < reach) & (cos > math.cos(math.radians(RETRACE_ANGLE)))
        if not hit.any():
            return None
        j = int(np.flatnonzero(hit)[np.argmin(dist[hit])])
        k = int(near[j])
        i0 = self.record.i0
        return (f"corrector landed on the branch already traced (between points {i0 + k} and {i0 + k + 1}, "
                f"distance {dist[j]:.3g}, same direction)")
