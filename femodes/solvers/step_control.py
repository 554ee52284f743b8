"""Solvers layer: the step size of a continuation run: growth and shrinking from what an accepted
step measured (Allgower & Georg [AG03] sec. 6.1, Deuflhard [D04] sec. 5.1; see ``target_angle`` in
:class:`~femodes.solvers.continuation_types.ContinuationOptions`), halving on rejection, and the
kink test of the branch-jumping guard."""

from __future__ import annotations

import logging
import math
from typing import NoReturn

import numpy as np

from .arclength import ArclengthSystem
from .continuation_types import ContinuationOptions
from .trace_record import BranchRecord, RetryStep, StopRun, TracePoint

__all__ = ["StepControl", "KINK_RATIO", "KINK_MAX_DISTANCE"]

# the continuation's log channel (one for all parts of the tracer)
logger = logging.getLogger("femodes.solvers.continuation")

#: Kink acceptance (see ContinuationOptions.max_turn_angle): after a geometric
#: rejection, the halved step is accepted as crossing a kink when the turn angle
#: kept >= 75 % of its value, the predictor distance shrank to <= 75 % and is
#: at most 2 ds.
KINK_RATIO = 0.75
KINK_MAX_DISTANCE = 2.0


class StepControl:
    """The next step ``ds`` of a run, the rejected steps and the last geometric rejection."""

    def __init__(self, system: ArclengthSystem, options: ContinuationOptions, record: BranchRecord) -> None:
        self.sys = system
        self.n = system.n
        self.opt = options
        self.record = record
        self.ds = math.nan  # the next step
        self.n_rejected = 0
        self.just_rejected = False  # no step growth right after a rejection
        self.prev_geo: tuple[float, float] | None = None  # (angle, distance) of the last geometric rejection

    def reject(self, a: TracePoint, reason: str, *, failure: str) -> NoReturn:
        """Halve the step and retry from ``a`` (raises :class:`RetryStep`); below ``min_step`` the
        run fails (status 4, ``failure`` in the message)."""
        self.n_rejected += 1
        self.just_rejected = True
        logger.debug("step ds=%.3g from p=%.6g rejected: %s", self.ds, a.y[self.n], reason)
        self.ds *= 0.5
        if self.ds < self.opt.min_step:
            raise StopRun(4, failure)
        raise RetryStep

    def is_kink(self, angle: float, dist: float) -> bool:
        """A kink of a semismooth branch turns the tangent by a fixed angle however small the step,
        with a predictor distance ~ ds; a smooth turn has angle ~ ds and distance ~ ds**2; a jump
        to another branch has a distance that does not shrink with ds."""
        return (
            self.prev_geo is not None
            and angle >= KINK_RATIO * self.prev_geo[0]
            and dist <= KINK_RATIO * self.prev_geo[1]
            and dist <= KINK_MAX_DISTANCE * self.ds
        )

    def control(self, b: TracePoint) -> None:
        """Next step from what the accepted step to ``b`` measured (see
        :class:`ContinuationOptions`, ``target_angle``): ``ds / f`` with ``f`` the largest of the
        deceleration factors ``nit / target_iterations``, ``angle / target_angle``,
        ``sqrt(theta / target_contraction)`` and ``|ln(|x_b| / |x_a|)| / ln(1 +
        target_norm_change)``, ``1/f`` clipped to ``[0.5, max_growth]`` (no growth
        right after a rejection) and ``ds`` to ``[min_step, max_step]``."""
        opt = self.opt
        # Allgower & Georg [AG03] sec. 6.1: each measure m of a step h behaves like m ~ c h^q
        # (angle between tangents q = 1, contraction of the first corrector iteration q = 2 for a
        # tangent predictor, Deuflhard [D04] sec. 5.1), so the step that gives the nominal value
        # m~ is h (m~/m)^(1/q); the most restrictive measure wins.
        f = max(b.nit, 1) / opt.target_iterations
        if opt.target_contraction is not None and f < 1:
            # the contraction decides the growth; few iterations do not ask for more (a larger
            # step costs a few more iterations but fewer points: fewer evaluations in all)
            f = 0.0
        f_angle = f_theta = 0.0
        if opt.target_angle is not None and math.isfinite(b.angle):
            # the turn left after the phase delay, and the phase delay itself (the motion's phase
            # turns by at most target_angle per step, as the tangent predictor's angle kept it)
            f_angle = max(b.angle, math.degrees(abs(b.tau))) / opt.target_angle
        if opt.target_contraction is not None and math.isfinite(b.theta):
            f_theta = math.sqrt(b.theta / opt.target_contraction)
        f_norm = 0.0
        pts = self.record.pts
        if opt.target_norm_change is not None and pts:
            na, nb = self.x_norm(pts[-1]), self.x_norm(b)
            if na > 0 and nb > 0 and math.isfinite(na / nb):
                f_norm = abs(math.log(nb / na)) / math.log1p(opt.target_norm_change)
        f = max(f, f_angle, f_theta, f_norm)
        factor = min(max(1.0 / f, 0.5), opt.max_growth) if f > 0 else opt.max_growth
        if self.just_rejected:
            factor = min(factor, 1.0)
        self.just_rejected = False
        logger.debug("step control at p=%.6g: ds=%.3g nit=%d angle=%.2f deg dist=%.3g theta=%.3g -> x%.3g",
                     b.y[self.n], self.ds, b.nit, b.angle, b.dist, b.theta, factor)
        self.ds = min(max(self.ds * factor, opt.min_step), opt.max_step)

    def x_norm(self, q: TracePoint) -> float:
        """Scaled norm of the unknowns ``x`` of ``q`` (the parameter left out)."""
        return self.sys.norm(np.append(q.y[: self.n], 0.0))
