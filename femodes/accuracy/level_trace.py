"""Tracing a level by a continuation of its own (it is cheaper and surer than walking it along the
branch's points once the levels are far apart): each needed point is the crossing of the level's
curve with the point's hyperplane, polished by Newton there. A trace runs from a point without
contact (every level is the branch's point there), forward, or backward from the branch's end for
a far second group of points (:func:`plan_traces`), and stops a few points past the last needed
point (:class:`Progress`); points it misses are walked (:mod:`.walk`) and the trace restarted
from them (:func:`complete_level`). Measurements: docs/guide/accuracy.md ("Levels") and
benchmarks/README_accuracy.md.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from ..results import Branch
from ..solvers import ContinuationOptions, continuation
from ..solvers.protocols import phase_hook
from .ladder import Ladder
from .options import AccuracyOptions
from .points import State, anchor, free_before, without_contact
from .walk import level_point, locate_fold

__all__ = ["Progress", "between", "complete_level", "plan_traces", "trace_by_continuation",
           "trace_level_by_continuation", "trace_segment"]

log = logging.getLogger(__name__)


def trace_level_by_continuation(lad: Ladder, H: int, options: AccuracyOptions) -> list:
    """Every point of the branch at level ``H`` (branches with impacts): the points without
    contact force as they are (:func:`~.points.without_contact`), the others from a continuation
    of the level itself (:func:`trace_by_continuation`), the points it misses walked from their
    predecessor as :func:`~.walk.trace_level` does, and a missed fold located by a short
    continuation (:func:`complete_level`). Seed's forced case at H = 20: 27 of 94 points without
    contact; levels 10 and 40 took 51 and 96 continuation points over the whole branch, 30 and 67
    over its contact part.

    Walking level 2H along every point costs more than tracing it: on the seed's forced case at
    H = 20, 230 hyperplane solves (26 failing, halved) and 33 s of CPU for level 40, against
    10 s by continuation with the same fold bracket; at H = 40 the walk lost level 80 one point
    before the upper fold and never recovered (NaN at the fold after 15 minutes).

    So a continuation that stops short is started again from the first point walked after the
    stop that has ``options.restart_min_points`` unsolved points after it (at most
    ``options.level_restarts`` times), and the walk's Newton solves are abandoned early
    (``options.walk_deadline``). ``cant20`` of benchmarks/README_accuracy.md (exact orbits that
    chatter) from H = 20: level 40's continuation stops at w = 3.63913, where its corrector makes
    no progress (residual 8e-8 at best); walking the 121 points left took 87 s of CPU and solved
    44 of them; with one restart from point 186 and the deadline, 49 points are walked and the
    level has 277 of the 316 points with contact instead of 246, in 39 s instead of 103 s for the
    whole level."""
    branch = lad.branch
    n = len(branch)
    if H == branch.harmonics.n_harmonics:
        return [anchor(branch, i) for i in range(n)]
    free = without_contact(branch)
    out = trace_by_continuation(lad, H, ~free, options) if not free.all() else [None] * n
    return complete_level(lad, H, out, options)


def complete_level(lad: Ladder, H: int, out: list, options: AccuracyOptions) -> list:
    """``out`` (level ``H`` at the points its continuation found, None elsewhere) completed: the
    points without contact force padded, the others walked from their predecessor
    (:func:`~.walk.level_point`), the continuation restarted from a walked point followed by
    ``options.restart_min_points`` unsolved ones, and the folds still missing located."""
    branch = lad.branch
    n = len(branch)
    free = without_contact(branch)
    for i in np.flatnonzero(free):  # the branch's point is the level's (padded): nothing to solve
        out[i] = lad.padded(H, i)
    folds = set(branch.folds)
    missed = restarts = 0
    for i in range(n):
        if out[i] is not None or i in folds:
            continue
        missed += 1
        prev = (anchor(branch, i - 1), out[i - 1]) if i > 0 and out[i - 1] is not None and i - 1 not in folds else None
        out[i] = level_point(lad, H, i, anchor(branch, i), prev, options)
        if (out[i] is not None and restarts < options.level_restarts and i + options.restart_min_points < n
                and all(out[k] is None and k not in folds for k in range(i + 1, i + 1 + options.restart_min_points))):
            restarts += 1  # the level's own continuation again, from the point just walked
            trace_segment(lad, H, np.array([k for k in range(i + 1, n) if out[k] is None and k not in folds]),
                          True, out, options, start=(i, out[i]))
    for f in branch.folds:
        if out[f] is None:
            out[f] = locate_fold(lad, H, out, f)
    if missed:
        log.info("accuracy: level H = %d: %d of %d points not on its continuation, walked (%d restarts of the "
                 "continuation)", H, missed, n, restarts)
    return out


def trace_by_continuation(lad: Ladder, H: int, need: np.ndarray, options: AccuracyOptions) -> list:
    """The points ``need`` of the branch at level ``H``, from continuations of level ``H`` itself.

    Walking a fine level along the branch's own points (:func:`~.walk.trace_level`) fails often
    once the levels are far apart (seed's forced case from H = 10: 376 hyperplane solves for 111
    points at H = 40, 604 at H = 80, 8 minutes in all). Here level ``H`` is traced by the continuation with
    its own step control, from a point without contact (where every level is the branch's point)
    and stopped a few points past the last needed point it meets (:class:`Progress`); each needed
    point is then the crossing of that curve with the point's hyperplane nearest to the point
    (linear interpolation between two level points), polished by Newton on the hyperplane. A fold
    of the branch is the nearest fold of the level's continuation.

    The trace runs forward from the last point without contact before the first needed point;
    or, when the needed points fall in two groups (:func:`plan_traces`), the first group forward
    that way and the second backward from the branch's end, if the branch ends without contact
    (the contact-free tail costs a few steps). The continuation cannot start where the second
    group's own contact-free neighbour is: the branch returns past that frequency after its lower
    fold, and a continuation stops where it passes its start again.
    """
    out: list = [None] * len(lad.branch)
    for idx, forward in plan_traces(lad.branch, need, options):
        trace_segment(lad, H, idx, forward, out, options)
    return out


def plan_traces(branch: Branch, need: np.ndarray, options: AccuracyOptions) -> list[tuple[np.ndarray, bool]]:
    """``(needed points, forward)`` of each continuation that traces a level for ``need``: one
    forward trace, or two (forward to the end of the first group, backward from the branch's
    end to the start of the second) when they pass enough fewer points with contact
    (``options.split_gain``). The groups are split at the widest gap between needed points.
    Seed's forced case at rtol 1e-3, level H = 160: the needed points are 22-36 (rising side) and 69-76
    (the unstable side next to the lower fold): one trace passes 66 points with contact (13-78),
    two pass 39."""
    idx = np.flatnonzero(need)
    contact = ~without_contact(branch)
    n = len(branch)
    one = [(idx, True)]
    if idx.size < 2 or contact[-1] or not contact.any():
        return one

    def cost(a: int, b: int) -> int:  # points with contact from a to b (inclusive)
        a, b = max(a, 0), min(b, n - 1)
        return int(contact[a : b + 1].sum())

    gap = int(np.argmax(np.diff(idx)))
    first, second = idx[: gap + 1], idx[gap + 1 :]
    start = free_before(branch, int(idx[0]))
    single = cost(start, int(idx[-1]) + options.past_last)
    split = cost(start, int(first[-1]) + options.past_last) + cost(int(second[0]) - options.past_last, n - 1)
    log.debug("accuracy: trace plan: one trace passes %d points with contact, two %d", single, split)
    if split > options.split_gain * single:
        return one
    return [(first, True), (second, False)]


def trace_segment(lad: Ladder, H: int, idx: np.ndarray, forward: bool, out: list, options: AccuracyOptions,
                  start: tuple[int, State] | None = None) -> None:
    """One continuation of level ``H`` for the needed points ``idx`` (:func:`trace_by_continuation`):
    forward from the last point without contact before ``idx[0]``, or backward from the branch's
    last point (without contact), or forward from ``start = (i, state)``, the level's point of
    branch point ``i`` (in the direction the branch goes there, up to the branch's extreme
    parameter that way); the level points of ``idx`` are written into ``out``."""
    branch = lad.branch
    n = len(branch)
    prob = lad.problem(H)
    if start is None:
        start_i = free_before(branch, int(idx[0])) if forward else n - 1
        a0 = anchor(branch, start_i)
        x0 = lad.vector(H, a0.Q, a0.P, a0.omega, a0.xi, a0.p)[:-1]
        span = (a0.p, float(branch.parameter[-1] if forward else branch.parameter[0]))
    else:
        start_i, s0 = start
        x0 = lad.vector(H, s0.Q, s0.P, s0.omega, s0.xi, s0.p)[:-1]
        up = lad.tangents[start_i].p > 0
        span = (s0.p, float(np.max(branch.parameter) if up else np.min(branch.parameter)))
    if span[1] == span[0]:
        return
    w = lad.weights(H)
    x_scale = 1.0 / np.sqrt(w[:-1] * x0.size)  # the branch's arclength metric on level H
    # nearness in displacements and frequency only: contact forces of two levels differ by far
    # more than their displacements (their harmonics are where the truncation error sits)
    h = lad.harmonics(H)
    near = w.copy()
    near[:-1][prob.pack(np.zeros((h.n_coef, branch.Q.shape[2])), np.ones((h.n_coef, branch.P.shape[2])), 0.0,
                        0.0) != 0] = 0.0
    if forward:
        last = int(idx[-1]) + options.past_last
        progress = Progress(lad, H, near, start_i, last, options) if last < n - 1 or start is not None else None
    else:  # followed from the first point without contact after the group (the level's own point
        # up to there, wherever the long contact-free steps land)
        last = int(idx[0]) - options.past_last
        after = int(idx[-1]) + int(np.argmax(without_contact(branch)[idx[-1]:]))
        progress = Progress(lad, H, near, after, last, options, step=-1) if last > 0 else None
    # folds of the level are located only if a fold of the branch is among the needed points
    # (level 160 of the seed case at rtol 1e-3, whose backward trace passes the lower fold, not
    # needed there: 8.8 -> 6.9 s)
    locate = any(f in idx for f in branch.folds)
    opts = ContinuationOptions(step=0.05, max_step=2.0, newton=lad.newton, x_scale=x_scale,
                               p_scale=float(1.0 / math.sqrt(w[-1])), max_points=20 * max(n, 50), callback=progress,
                               locate_folds=locate)
    with np.errstate(all="ignore"):
        res = continuation(prob, span, x0=x0, options=opts)
    log.info("accuracy: level H = %d traced by continuation %s from point %d%s: %d points (%s)", H,
             "forward" if forward else "backward", start_i, "" if start is None else " (walked, restart)",
             len(res.p), res.message)
    Y = np.column_stack([res.x, res.p])
    tangents = lad.tangents
    for i in idx:
        point = anchor(branch, int(i))
        a = lad.vector(H, point.Q, point.P, point.omega, point.xi, point.p)
        t = tangents[i]
        c = w * lad.vector(H, t.Q, t.P, t.omega, t.xi, t.p)
        sd = (Y - a) @ c
        k = np.flatnonzero(sd[:-1] * sd[1:] <= 0.0)
        if not k.size:
            continue
        theta = sd[k] / np.where(sd[k] == sd[k + 1], 1.0, sd[k] - sd[k + 1])
        cand = np.array([between(prob, Y[j], Y[j + 1], th) for j, th in zip(k, theta)])
        best = cand[int(np.argmin(((cand - a) ** 2) @ near))]
        out[i] = lad.solve(H, point, t, lad.state(H, best))
    for f in branch.folds:
        if f in idx and res.folds:
            a = lad.vector(H, branch.Q[f], branch.P[f], float(branch.omega_truncated[f]), float(branch.xi[f]),
                           float(branch.parameter[f]))
            k = min(res.folds, key=lambda j: float(((Y[j] - a) ** 2) @ near))
            out[f] = lad.state(H, Y[k])


class Progress:
    """Callback of a level's continuation: follows which branch point the level is nearest to
    (in the direction ``step`` of the trace only, a few points ahead, in displacements and
    frequency) and stops the run once that is past branch point ``last``. On the seed's forced
    case from H = 20 at rtol 1e-3 the needed points of levels 80 and 160 end at w = 1.11 on the
    lower branch; the rest of the branch up to w = 2 was 24 of the 122 points of level 80 and 24
    of the 215 of level 160 (few contacts there, cheap points: about 1 s of the 25 s run). Without
    the stop a level is traced to the end. It also stops a level that takes too many points for the
    branch points it passes (``options.level_points_per_point``)."""

    def __init__(self, lad: Ladder, H: int, near: np.ndarray, first: int, last: int, options: AccuracyOptions,
                 step: int = 1):
        self.lad, self.H, self.near, self.at, self.last, self.step = lad, H, near, first, last, step
        self.options = options
        self.first = first
        self.points = 0
        self.vectors: dict = {}

    def _vector(self, i: int) -> np.ndarray:
        if i not in self.vectors:
            a = anchor(self.lad.branch, i)
            self.vectors[i] = self.lad.vector(self.H, a.Q, a.P, a.omega, a.xi, a.p)
        return self.vectors[i]

    def __call__(self, point) -> bool:
        if self.lad.deadline is not None and time.perf_counter() > self.lad.deadline:
            return False  # the caller's check_time raises once the continuation has returned
        y = np.append(point.x, point.p)
        if self.step > 0:
            ahead = range(self.at, min(self.at + 4, len(self.lad.branch)))
        else:
            ahead = range(self.at, max(self.at - 4, -1), -1)
        self.at = ahead[int(np.argmin([float(((y - self._vector(i)) ** 2) @ self.near) for i in ahead]))]
        for i in [k for k in self.vectors if (k - self.at) * self.step < 0]:
            del self.vectors[i]
        self.points += 1
        passed = (self.at - self.first) * self.step
        if self.points > self.options.level_points_per_point * passed + self.options.level_points_slack:
            log.info("accuracy: level H = %d stopped after %d continuation points for %d points of the branch (more "
                     "than %d per point: it follows loops the branch does not have)", self.H, self.points, passed,
                     self.options.level_points_per_point)
            return False
        return (self.last - self.at) * self.step >= 0


def between(prob, y0: np.ndarray, y1: np.ndarray, theta: float) -> np.ndarray:
    """The point a fraction ``theta`` of the way from ``y0`` to ``y1`` (``[x; p]`` of two points
    of a continuation of ``prob``). For a problem that can delay its motion (``phase_shift``),
    the phase is interpolated: ``y1`` is delayed back by the phase ``tau`` between the two points
    (weighted mean of the first harmonics' phase differences), blended linearly with ``y0``, and
    the blend delayed by ``theta tau``; harmonic ``k`` then turns by ``k theta tau`` instead of
    moving along its chord. Measured on the seed case at rtol 1e-3: the continuation's points are
    far enough apart (phase predictor) that the linear blend, a poor start for the contact-force
    harmonics at H = 80-160, cost 56-65 Newton evaluations per hyperplane solve."""
    x0, x1, p0, p1 = y0[:-1], y1[:-1], float(y0[-1]), float(y1[-1])
    p = p0 + theta * (p1 - p0)
    hook = phase_hook(prob)  # the optional hook of the continuation's problem protocol
    shift = None if hook is None else hook.phase_shift
    if shift is None:
        return y0 + theta * (y1 - y0)
    u0, u1 = prob.unpack(x0, p0), prob.unpack(x1, p1)
    # first harmonics (rows 1, 2: c_1, s_1) of all displacements and contact forces
    z0 = np.concatenate([u0.Q[1] + 1j * u0.Q[2], u0.P[1] + 1j * u0.P[2]]) if u0.Q.shape[0] > 2 else np.zeros(0)
    z1 = np.concatenate([u1.Q[1] + 1j * u1.Q[2], u1.P[1] + 1j * u1.P[2]]) if u1.Q.shape[0] > 2 else np.zeros(0)
    # c cos + s sin = Re((c - i s) e^{i theta}): a delay tau multiplies c + i s by e^{i tau}
    cross = np.sum(z1 * np.conj(z0))
    if not abs(cross) > 0:
        return y0 + theta * (y1 - y0)
    tau = float(np.angle(cross))
    back = np.asarray(shift(x1, -tau), dtype=float)
    return np.append(np.asarray(shift(x0 + theta * (back - x0), theta * tau), dtype=float), p)
