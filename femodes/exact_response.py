"""Analyses layer: the forced response of a linear model with rigid stops, orbit by exact orbit
(:func:`exact_frequency_response`): continuation in the forcing frequency of the periodic orbits
of the exact flow (:class:`~femodes.time.exact.LinearImpactFlow`), the limit harmonic balance
converges to, with its folds, returned as an :class:`~femodes.ExactBranch`."""

from __future__ import annotations

import collections
import dataclasses
import logging
import math
import warnings

import numpy as np

from .exact_branch import EXACT_FOLD_RTOL, ExactBranch, fold_window
from .model import StructuralModel
from .solvers import ContinuationOptions, continuation
from .solvers.checks import InputTypeError, InputValueError, entry_point, user_stacklevel
from .time.exact import LinearImpactFlow, periodicity_residual, undamped

__all__ = ["exact_frequency_response", "EXACT_BRANCH_RTOL"]

log = logging.getLogger(__name__)

#: Default Newton tolerance of :func:`exact_frequency_response`, relative to the larger of the
#: largest gap and the start state of the response without contact at the first frequency. On the
#: cantilever of ``benchmarks/bench_cantilever_time.py`` (scale 0.02) the continuation's default
#: 1e-10 was not reached: the corrector stalled at residuals of 4e-9, 2e-7 of the scale (stiff
#: modes: event times to round-off still leave that much in their velocities).
EXACT_BRANCH_RTOL = 1e-6

#: Runs of the continuation's residual kept until it accepts a point (the corrector's last
#: iterate is evaluated last, or nearly: fold location and tangents come between).
RECENT_RUNS = 32


class _ShootingResidual:
    """``r(x, w) = x(T) - x`` over one forcing period ``T = 2 pi / w`` from ``x(0) = x`` (the
    inertial entries of the state), with ``dr/dx = Phi - I`` and ``dr/dw`` from the variational
    run (``FlowRun.x_end_omega``). The last :data:`RECENT_RUNS` runs (``FlowRun.plain``)
    are kept by start state and frequency; :meth:`keep` (the continuation's callback) moves an
    accepted point's into ``orbits``: its orbit and its massless DOFs' entries."""

    def __init__(self, flow: LinearImpactFlow):
        self.flow, self.S = flow, flow.state_index
        self.massless = np.setdiff1d(np.arange(2 * flow.n), flow.state_index)
        self.runs = 0
        self.recent: collections.OrderedDict = collections.OrderedDict()
        self.orbits: dict = {}

    def keep(self, y: np.ndarray, w: float) -> None:
        key = (np.asarray(y, dtype=float).tobytes(), float(w))
        run = self.recent.get(key)
        if run is not None:
            self.orbits[key] = run

    def callback(self, then=None):
        """A continuation callback that keeps every accepted point's run, then calls ``then``."""
        def cb(point):
            self.keep(point.x, point.p)
            return None if then is None else then(point)
        return cb

    def full(self, y: np.ndarray) -> np.ndarray:
        x = np.zeros(2 * self.flow.n)
        x[self.S] = y
        return x

    def residual(self, y: np.ndarray, w: float):
        S = self.S
        x = self.full(y)
        self.runs += 1
        try:
            r, drdx, drdw, run = periodicity_residual(self.flow, x, w)
        except ValueError:
            # an iterate the flow cannot start from (inside an obstacle, w <= 0, an accumulation of
            # events): a non-finite residual, which makes Newton's line search cut the step
            nan = np.full(S.size, np.nan)
            return nan, np.full((S.size, S.size), np.nan), nan
        self.recent[(y.tobytes(), float(w))] = run.plain()
        if len(self.recent) > RECENT_RUNS:
            self.recent.popitem(last=False)
        return r[S], drdx[np.ix_(S, S)], drdw[S]


@entry_point("exact_frequency_response")
def exact_frequency_response(model: StructuralModel, omega=None, *, x0=None, restitution: float = 1.0,
                             options=None, span=None) -> ExactBranch:
    """The forced response of a linear model with rigid stops, orbit by exact orbit.

    Pseudo-arclength continuation of the periodic orbits of :class:`~femodes.time.exact.LinearImpactFlow`
    in the forcing frequency: unknowns the start state at ``t = 0``, residual ``x(T) - x(0)``, Jacobian
    the monodromy matrix (saltation at impacts). Every point is a periodic orbit of the semi-discrete
    model to round-off (what harmonic balance converges to as H grows); folds are located. The orbits
    need not be stable (:func:`femodes.stability` says which are).

    Parameters
    ----------
    model : StructuralModel
        Linear, with unilateral contacts (on DOFs with or without mass) and harmonic forcing; no smooth
        laws or penalty contacts (:func:`~femodes.time.exact.exact_flow_unsupported` says why).
    omega : (float, float)
        Forcing frequencies ``(w_start, w_end)`` in rad/s, positive; may decrease (as
        :func:`femodes.frequency_response`).
    x0 : array_like (2 n_dofs,), optional
        Start state ``[q; v]`` at ``w_start``; default: the response without contact there
        (right when it keeps off the stops, a first guess otherwise).
    restitution : float
        Newton's coefficient of the impacts on DOFs with mass (1: the limit of harmonic balance).
    options : ContinuationOptions, optional
        Default: ``max_points=3000`` and Newton's ``atol`` :data:`EXACT_BRANCH_RTOL` times the
        larger of the largest gap and the size of the start state without contact at
        ``w_start``.
    span : (float, float), optional
        Deprecated spelling of ``omega`` (a ``DeprecationWarning``; removed in a later release).

    Returns
    -------
    ExactBranch
        ``success``/``message`` report how the continuation ended; never raises on numerical failure.

    Raises
    ------
    TypeError
        ``model`` is not a model, ``options`` not a ContinuationOptions.
    ValueError
        A model the flow cannot take, a bad ``omega`` or ``x0``.
    """
    if span is not None:
        if omega is not None:
            raise InputTypeError("give omega= only (span= is its deprecated spelling), not both")
        warnings.warn("exact_frequency_response(model, span=...) is deprecated; use exact_frequency_response(model, "
                      "omega=...), as frequency_response", DeprecationWarning,
                      stacklevel=user_stacklevel())
        omega = span
    if omega is None:
        raise InputTypeError("missing the forcing frequencies omega=(w_start, w_end)")
    if not isinstance(model, StructuralModel):
        raise InputTypeError(f"model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
    try:
        w0, w1 = (float(omega[0]), float(omega[1]))
    except (TypeError, ValueError, IndexError):
        raise InputValueError(f"omega must be two forcing frequencies (w_start, w_end), got {omega!r}") from None
    if len(omega) != 2 or not (math.isfinite(w0) and math.isfinite(w1) and w0 > 0.0 and w1 > 0.0) or w0 == w1:
        raise InputValueError(f"omega must be two different finite positive frequencies, got {omega!r}")
    if not model.forces:
        raise InputValueError("the model has no harmonic forcing (add one with with_forcing)")
    if undamped(model, restitution):
        raise InputValueError(f"the model has no damping (C = 0) and restitution = {restitution:g}: nothing "
                         "dissipates, so near a resonance of the impacting structure the forced orbits grow without "
                         "bound and the continuation cannot pass it (an undamped oscillator against a stop ran 3000 "
                         "points to a step-size failure); add damping (model.with_damping(alpha=..., beta=...) or "
                         "modal=...) or use restitution < 1")
    flow = LinearImpactFlow(model, w0, restitution=restitution)
    n2 = 2 * model.n_dofs
    particular = flow.particular(0.0)
    if x0 is None:
        x0 = particular
    else:
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (n2,) or not np.all(np.isfinite(x0)):
            raise InputValueError(f"x0 must be {n2} finite numbers [q; v], got shape {x0.shape}")
    if options is None:
        scale = max(float(np.linalg.norm(particular[flow.state_index])), float(np.max(np.abs(flow.gaps), initial=0.0)))
        base = ContinuationOptions()
        options = ContinuationOptions(max_points=3000, newton=dataclasses.replace(
            base.newton, atol=EXACT_BRANCH_RTOL * max(scale, 1e-300)))
    elif not isinstance(options, ContinuationOptions):
        raise InputTypeError(f"options must be a ContinuationOptions or None, got {type(options).__name__}")
    problem = _ShootingResidual(flow)
    options = dataclasses.replace(options, callback=problem.callback(options.callback))
    res = continuation(problem, (w0, w1), x0=x0[flow.state_index], options=options)
    pieces = [res]
    if res.status == 4 and len(res.p):
        # the corrector gave up inside the span (a grazing orbit: the flow's derivative jumps
        # there): trace the rest back from the other end, from its response without contact
        w_stop = float(res.p[-1])
        back = continuation(problem, (w1, w_stop), x0=flow.at(w1).particular(0.0)[flow.state_index], options=options)
        log.info("exact_frequency_response: stopped at w = %.6g (%s); traced back from w = %.6g to %.6g (%s)",
                 w_stop, res.message, w1, float(back.p[-1]) if len(back.p) else w1, back.message)
        if len(back.p):
            pieces.append(back)
    def joined(arrays):  # the pieces' arrays in the branch's order: the back piece reversed
        return np.concatenate([np.asarray(a, dtype=float)[::1 if k == 0 else -1] for k, a in enumerate(arrays)])

    omega = joined([r.p for r in pieces])
    ys = joined([np.reshape(r.x, (len(r.p), flow.state_index.size)) for r in pieces])
    steps = joined([r.step for r in pieces])
    folds, located = list(res.folds), set(res.located)
    if len(pieces) == 2:  # the back piece's index i is the branch's omega.size - 1 - i
        folds += [omega.size - 1 - int(i) for i in sorted(pieces[1].folds, reverse=True)]
        located |= {omega.size - 1 - int(i) for i in pieces[1].located}
    # the refinement steps in the first run's arclength norm (scales), comparable with its steps
    scaled = dataclasses.replace(options, x_scale=np.asarray(res.x_scale), p_scale=float(res.p_scale))
    refined = {j: got for j in folds if j not in located
               and (got := _refine_fold(problem, omega, ys, steps, j, scaled)) is not None}
    # the points' orbits: the continuation's runs from them (one more run where its last step was
    # not evaluated), and from those the massless DOFs' entries (consistent with the inertial
    # ones, which are the continuation's own: periodic to its Newton tolerance)
    states = np.zeros((omega.size, n2))
    orbits = []
    for i, (y, w) in enumerate(zip(ys, omega)):
        states[i] = problem.full(y)
        run = problem.orbits.get((y.tobytes(), float(w)))
        if run is None:
            problem.runs += 1
            run = flow.at(w).run(states[i], 0.0)
        orbits.append(run)
        states[i, problem.massless] = run.x_end[problem.massless]
    problem.orbits.clear()
    problem.recent.clear()
    return ExactBranch(flow, omega, states, pieces, folds, problem.runs, options.newton.atol, refined, orbits)


#: Points of :func:`_refine_fold`'s continuations toward a fold, from either side.
REFINE_FOLD_POINTS = 60


def _refine_fold(problem: _ShootingResidual, omega: np.ndarray, ys: np.ndarray, steps: np.ndarray, j: int,
                 options: ContinuationOptions) -> tuple[float, float] | None:
    """A fold ``j`` the continuation detected but did not locate: where the corrector fails at
    the turn (a grazing there), the branch jumped across it. Continuations with a quarter of the
    steps into and out of ``j`` (:data:`REFINE_FOLD_POINTS` points at most) from the points two before and two
    after ``j`` toward it, beyond it in frequency, in the first run's arclength scales: ``(the
    extreme frequency of theirs and the branch's points, the larger distance of either side's
    extreme from it relative to it (at least EXACT_FOLD_RTOL))``, or None if a side gets no
    point (the sampled window then stands). On the cantilever of ``benchmarks/bench_cantilever_time.py``
    (3 % modal damping) the lower fold was detected at 3.7193283 before the continuation located
    sharp folds (``_FOLD_SHARP_ITER``); the two sides reached 3.71931195 and 3.7193120 (233 runs),
    4.4e-6 lower, where the fold search of :mod:`femodes.accuracy` puts it (3.7193120 +- 2.3e-7).
    Seed case 2's lower fold, a grazing where the corrector fails, is still refined so."""
    upper, extreme = fold_window(omega, j)[1:]
    lo, hi = max(j - 2, 0), min(j + 2, omega.size - 1)
    if lo == j or hi == j:
        return None
    step = max(0.25 * float(np.max(steps[j - 1:j + 2])), options.min_step)  # the steps into and out of j
    opt = dataclasses.replace(options, step=step, max_step=step, max_points=REFINE_FOLD_POINTS, callback=None)
    ext = []
    for k in (lo, hi):
        reach = 10.0 * abs(omega[k] - omega[j]) + EXACT_FOLD_RTOL * abs(omega[j])
        end = omega[k] + reach if upper else omega[k] - reach
        r = continuation(problem, (float(omega[k]), float(end)), x0=ys[k], options=opt)
        if len(r.p) < 2:
            return None
        p = np.asarray(r.p, dtype=float)
        ext.append(float(p.max() if upper else p.min()))
    # the branch's own points bound the fold too: the extreme of all, and how far each side fell short
    best = max(ext + [extreme]) if upper else min(ext + [extreme])
    log.info("exact branch: fold %d detected at w = %.8g, refined from both sides to %.8g and %.8g", j, omega[j], *ext)
    return best, max(max(abs(best - e) for e in ext) / abs(best), EXACT_FOLD_RTOL)
