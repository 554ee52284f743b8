"""Walking a level along the branch, point after point: the guess at point ``i`` is the level's
solution at ``i - 1`` moved by the branch's own step, projected on the hyperplane of ``i``; a
failed step is halved. A level cannot be solved from the branch's own point by Newton alone
(from the H = 20 point of the seed's forced case, semismooth Newton stalls at residual 1e-2 at
H = 10 and H = 40: the truncated or padded contact forces are too far from the level's). The
branch's folds are located on the level by a short continuation of its own (:func:`locate_fold`).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..solvers import ContinuationOptions, continuation
from .ladder import Ladder
from .options import AccuracyOptions
from .points import State, anchor, blend, period_driven

__all__ = ["level_point", "locate_fold", "trace_level", "walk"]

log = logging.getLogger(__name__)


def walk(lad: Ladder, H: int, prev: tuple, target_anchor: State, t0: State, t1: State,
         options: AccuracyOptions) -> State | None:
    """The level-``H`` point of ``target_anchor`` from the level's point ``prev = (anchor0, state0)``
    of the previous branch point: in one step, or in fractions of it (halved down to
    ``options.min_fraction``) through intermediate anchors on the segment between the two branch
    points (tangents interpolated); each solve abandoned after ``options.walk_deadline``."""
    a0, s0 = prev
    done, frac = 0.0, 1.0
    while done < 1.0:
        frac = min(frac, 1.0 - done)
        theta = done + frac
        target = target_anchor if theta >= 1.0 else blend(a0, target_anchor, theta)
        tangent = t1 if theta >= 1.0 else blend(t0, t1, theta)
        st = lad.solve(H, target, tangent, lad.moved(H, s0, blend(a0, target_anchor, done), target),
                       options.walk_deadline)
        if st is None:
            if frac <= options.min_fraction:
                return None
            frac *= 0.5
            continue
        s0, done = st, theta
        frac *= 2.0
    return s0


def level_point(lad: Ladder, H: int, i: int, point: State, prev: tuple | None,
                options: AccuracyOptions) -> State | None:
    """Point ``i`` (``point``, on the branch's harmonics) at level ``H``: walked from the level's
    point ``prev = (anchor, state)`` of point ``i - 1`` if there is one (:func:`walk`), else (or if
    that fails) solved on its hyperplane from the branch's own point."""
    lad.check_time()
    tangents = lad.tangents
    st = walk(lad, H, prev, point, tangents[i - 1], tangents[i], options) if prev is not None else None
    if st is None:
        st = lad.solve(H, point, tangents[i], None, options.walk_deadline)
    if st is None:
        log.info("accuracy: point %d has no solution with H = %d near it", i, H)
    return st


def trace_level(lad: Ladder, H: int, options: AccuracyOptions) -> list:
    """Every point of the branch at level ``H``, in branch order, walked along the branch
    (:func:`level_point`; a period-driven backbone's points each from the branch's own orbit);
    the branch's folds then located on the level (:func:`locate_fold`)."""
    branch = lad.branch
    n = len(branch)
    out: list = [None] * n
    if H == branch.harmonics.n_harmonics:
        for i in range(n):
            out[i] = anchor(branch, i)
    else:
        prev = None  # (branch anchor, level state) of the last solved point
        walks = not period_driven(branch)
        for i in range(n):
            a = anchor(branch, i)
            out[i] = st = level_point(lad, H, i, a, prev, options)
            prev = None if st is None or not walks else (a, st)
    for f in branch.folds if H != branch.harmonics.n_harmonics else ():  # the branch's own are located
        out[f] = locate_fold(lad, H, out, f)
    return out


def locate_fold(lad: Ladder, H: int, states: list, f: int) -> State | None:
    """The fold of level ``H`` that corresponds to the branch's fold ``f``.

    Normal hyperplanes cannot find it: the level's fold lies off the branch's by the error
    being measured (the H = 40 curve of the seed's forced case peaks below the amplitude of the
    H = 20 fold, so the hyperplane through that fold misses it). It is traced instead: a
    continuation of level ``H`` from the level's solution a few points before the fold, in
    the branch's direction, with the fold located by the continuation (regula falsi on dp/ds).
    """
    branch = lad.branch
    j = next((j for j in range(f - 2, max(f - 60, -1), -1) if states[j] is not None), None)
    if j is None:
        return None
    st = states[j]
    dp = float(branch.parameter[f] - branch.parameter[j])
    width = max(4.0 * abs(dp), 0.1 * abs(float(branch.parameter[f])) if lad.forced else 0.5)
    prob = lad.problem(H)
    x0 = lad.vector(H, st.Q, st.P, st.omega, st.xi, st.p)[:-1]
    span = (st.p, st.p + math.copysign(width, dp or 1.0))
    rms = float(np.sqrt(np.mean(x0 ** 2))) or 1.0
    opts = ContinuationOptions(step=0.02, max_step=0.1, max_points=300, x_scale=rms, p_scale=width,
                               newton=lad.newton)
    with np.errstate(all="ignore"):
        res = continuation(prob, span, x0=x0, options=opts)
    if not res.folds:
        log.info("accuracy: the fold near point %d was not found with H = %d (%s)", f, H, res.message)
        return None
    k = res.folds[0]
    out = lad.state(H, np.append(res.x[k], res.p[k]))
    out.nit, out.residual_norm = int(res.nit[k]), float(res.residual_norm[k])
    return out
