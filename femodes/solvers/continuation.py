r"""Pseudo-arclength continuation of solution branches of :math:`r(x, p) = 0`.

The branch :math:`\{y = (x, p) \in \mathbb{R}^{n+1} : r(x, p) = 0\}` is traced
by a tangent predictor (or, for periodic motions that can be delayed in phase, one that follows
the phase: ``ContinuationOptions.predictor``) and a corrector on the hyperplane orthogonal (in a
scaled inner product) to the previous tangent, following Allgower & Georg
[AG03]_ (chapters 2 and 6) and Keller's pseudo-arclength method [K77]_:

.. math::

    y_{\mathrm{pred}} = y_k + \Delta s\, t_k, \qquad
    \begin{bmatrix} r(x, p) \\ t_k^{\mathsf T} S\,(y - y_{\mathrm{pred}}) \end{bmatrix} = 0,

solved by :func:`~femodes.solvers.newton.semismooth_newton`.  The tangent
at a point is obtained from the bordered system

.. math::

    \begin{bmatrix} r_x & r_p \\ t_{\mathrm{prev}}^{\mathsf T} S \end{bmatrix} t
    = \begin{bmatrix} 0 \\ 1 \end{bmatrix}, \qquad t \leftarrow t / \|t\|_S,

which orients ``t`` so that :math:`t^{\mathsf T} S\, t_{\mathrm{prev}} > 0`;
this is what carries the continuation through turning points (folds), where
:math:`r_x` is singular but the bordered matrix is not.

The scaled inner product is

.. math::

    \langle u, v\rangle_S = \frac1n \sum_{i=1}^n \frac{u_i v_i}{s_{x,i}^2}
    + \frac{u_p v_p}{s_p^2},

i.e. the unknowns enter through their root-mean-square, so that the step
``ds`` measures *relative* changes independently of the number of unknowns.

Sparse bordered systems are solved by default with :func:`bordered_solver`
(block elimination on the sparse LU of ``r_x`` plus iterative refinement),
which avoids the fill-in a direct LU of the bordered matrix can suffer from
its dense last row; ``NewtonOptions.linear_solver`` replaces it.

The module knows nothing about harmonic balance: ``problem`` is any object with
a method ``residual(x, p) -> (r, dr_dx, dr_dp)``.

Layout: this module holds :func:`continuation` (checks its input and starts a
``_Tracer``) and the tracer, one method per part of the algorithm (start or
resume, predictor-corrector step, branch-jumping guard, step control, fold
detection and location, exact end on the span boundary, the result).  The
options and result types are in :mod:`femodes.solvers.continuation_types`, the
bordered linear algebra in :mod:`femodes.solvers.bordered`, the problem's
evaluation and scaled geometry in :mod:`femodes.solvers.arclength`; all public
names are importable from here.

References
----------
.. [AG03] E. L. Allgower and K. Georg, *Introduction to Numerical
   Continuation Methods*, SIAM Classics in Applied Mathematics 45 (2003).
.. [D04] P. Deuflhard, *Newton Methods for Nonlinear Problems: Affine
   Invariance and Adaptive Algorithms*, Springer (2004), sec. 5.1.
.. [K77] H. B. Keller, "Numerical solution of bifurcation and nonlinear
   eigenvalue problems", in *Applications of Bifurcation Theory*, Academic
   Press (1977) 359-384.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .arclength import ArclengthSystem
from .bordered import bordered_matrix, bordered_solver
from .checks import is_real_number, show, start_vector
from .roots import illinois
from .continuation_types import (
    STATUS_MESSAGES,
    ContinuationOptions,
    ContinuationPoint,
    ContinuationResult,
    ContinuationState,
)

__all__ = [
    "ContinuationOptions",
    "ContinuationPoint",
    "ContinuationResult",
    "ContinuationState",
    "continuation",
    "STATUS_MESSAGES",
    "bordered_matrix",
    "bordered_solver",
]

logger = logging.getLogger(__name__)

#: Minimal number of Newton iterations allowed for the initial correction of x0.
_INITIAL_MAX_ITER = 50
#: Iterations and tolerance of the fold localisation (regula falsi on dp/ds).
_FOLD_MAX_ITER = 12
_FOLD_TOL = 1e-9
#: Further evaluations, with bisection where regula falsi does not halve the bracket, for a fold
#: that ``_FOLD_MAX_ITER`` did not locate although every corrector converged (a sharp fold:
#: ``dp/ds`` turns within a small part of the step). The exact branch of the cantilever with 3 %
#: modal damping (benchmarks/README_accuracy.md, section 5) turns at its lower fold within about
#: 1e-4 of the step: regula falsi left ``|dp/ds|`` at 0.035 of 0.04 after 12 evaluations, and
#: the step was halved nine times before a step short enough located it (1380 runs of the exact
#: flow for the branch); with 16 more evaluations it is located after one halving (996 runs).
_FOLD_SHARP_ITER = 16
#: A fold counts as located when ``|dp/ds|`` at the best point found is at most this fraction of
#: the larger ``|dp/ds|`` at the two ends of the step (regula falsi converged, not stopped by a
#: failed corrector). Seed case 1, penalty law, H = 40, phase predictor: a step of 0.83 across the
#: lower fold (a grazing point) had its second trial corrector fail, and the one point found
#: (|dp/ds| 0.027 of 0.12) was taken as the fold, 0.4 % off in w.
_FOLD_ACCEPT = 1e-3
#: A fold that is not located (``_FOLD_ACCEPT``) is retried with the step halved while the step is
#: longer than this fraction of the initial step (``ContinuationOptions.step``); below it the
#: nearer end of the step is marked (a rule of the step alone, so that a resumed run repeats it;
#: with the initial step itself as the limit, seed case 2 at H = 10 marked one 0.24 % off). 1/64:
#: on the penalty seed case at H = 40 (tangent predictor, ``target_norm_change=0.3``) the lower
#: fold, a corner at grazing, is located with the shorter steps; with 1/4 its step stopped at
#: 0.0125 and the marked point was 2e-4 off in w. Where folds are located anyway (the benchmark
#: cases with the default options) nothing changes.
_FOLD_RETRY_STEP = 1.0 / 64.0
#: Kink acceptance (see ContinuationOptions.max_turn_angle): after a geometric
#: rejection, the halved step is accepted as crossing a kink when the turn angle
#: kept >= 75 % of its value, the predictor distance shrank to <= 75 % and is
#: at most 2 ds.
_KINK_RATIO = 0.75
_KINK_MAX_DISTANCE = 2.0
#: Retrace guard (:meth:`_Tracer.retraced`): a corrected point within this many steps ``ds`` of
#: the branch already traced (all but the last RETRACE_SKIP points), in a direction within
#: RETRACE_ANGLE degrees of the branch there, is a jump back onto it.
RETRACE_DISTANCE = 0.5
RETRACE_SKIP = 3
RETRACE_ANGLE = 30.0
#: Log progress at INFO level every this many accepted points.
_LOG_EVERY = 10


@dataclass
class _Pt:
    """Record of an accepted point (internal): y = (x, p), unit tangent t."""

    y: np.ndarray
    t: np.ndarray
    nit: int
    rnorm: float
    step: float
    #: what the step that produced the point measured (step control): turn of the tangent
    #: [degrees], predictor-corrector distance, contraction of the first corrector iteration
    angle: float = math.nan
    dist: float = math.nan
    theta: float = math.nan
    #: phase delay of the step's predictor (radians; 0 for the tangent predictor)
    tau: float = 0.0


def _contraction(history: tuple[float, ...]) -> float:
    """Contraction ``|r_1| / |r_0|`` of the first corrector iteration (NaN without an iteration)."""
    if len(history) < 2:
        return math.nan
    r0, r1 = history[0], history[1]
    if not r0 > 0:
        return 0.0
    return r1 / r0


def _validate_span(p_span: Any) -> tuple[float, float]:
    try:
        p0, p1 = (float(v) for v in p_span)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"p_span must be a pair of finite numbers (p_start, p_end), got {show(p_span)}") from exc
    if not (math.isfinite(p0) and math.isfinite(p1)) or p0 == p1:
        raise ValueError(
            f"p_span must be a pair of distinct finite numbers (p_start, p_end), got {show(p_span)}"
        )
    # (p1 - p0) * (p1 - p0): a Python float's ** raises OverflowError where * gives inf
    if not math.isfinite((p1 - p0) * (p1 - p0)) or (p1 - p0) * (p1 - p0) == 0.0:
        raise ValueError(f"p_span {show(p_span)}: its width squared under- or overflows; rescale the parameter")
    return p0, p1


# --------------------------------------------------------------------------- #
# main routine
# --------------------------------------------------------------------------- #
def continuation(
    problem: Any,
    p_span: tuple[float, float],
    *,
    x0: Any = None,
    options: ContinuationOptions | None = None,
    start: ContinuationState | None = None,
) -> ContinuationResult:
    r"""Trace the solution branch of :math:`r(x, p) = 0` from ``p_span[0]`` to ``p_span[1]``.

    Pseudo-arclength predictor-corrector continuation (Keller 1977; Allgower
    & Georg 2003, ch. 2):

    1. ``x0`` is corrected at ``p = p_span[0]`` by semismooth Newton with
       ``p`` fixed.
    2. Tangent ``t`` from ``[[r_x, r_p], [c^T]] t = [0; 1]`` (``c = e_p`` for
       the first tangent, whose sign of ``dp`` is set by ``direction``;
       ``c = S t_prev`` afterwards, which keeps ``<t, t_prev>_S > 0`` and
       passes folds), normalised in the scaled norm.
    3. Predictor ``y + ds t`` (``predictor="phase"`` with a problem that has
       ``phase_shift``/``phase_generator``: the phase part of ``t`` applied
       as an exact delay, see :class:`ContinuationOptions`); corrector:
       semismooth Newton on the bordered
       system ``[r(x, p); t^T S (y - y_pred)] = 0`` (sparse ``bmat`` if
       ``r_x`` is sparse, dense otherwise).
    4. Step control from the geometry of the branch (turn of the tangent)
       and the corrector (contraction of its first iteration, iteration
       count), see ``target_angle`` in :class:`ContinuationOptions`; on
       corrector failure (or a corrector abandoned at ``corrector_deadline``)
       the step is halved and retried from the same point.  A converged
       point farther than ``max_corrector_distance * ds`` from the predictor,
       or whose tangent turns by more than ``max_turn_angle``, or that lands
       on the part of the branch already traced going the same way
       (:meth:`_Tracer.retraced`), is also rejected (branch-jumping guard)
       unless the step is already minimal.
    5. Folds: a sign change of ``dp/ds`` between consecutive points; with
       ``locate_folds`` the fold is located and inserted as a point.
    6. End: when a predictor or a converged point passes ``p_span[1]`` (or
       ``p_span[0]`` after turning back), the final point is computed
       exactly at that ``p`` by Newton in ``x`` from a linear interpolation,
       appended, and the run stops (status 0, resp. 1).

    Resuming: ``start=point.state`` (a :class:`ContinuationState` received
    by the callback, possibly saved and rebuilt) skips steps 1-2 and
    continues from that point with its tangent, step size, fold record and
    arclength scales, so that the run computes exactly the points the
    original run computed after it.  Pass the same ``problem``, ``p_span``
    and options; the scales of ``start`` replace ``options.x_scale`` and
    ``options.p_scale``.

    Parameters
    ----------
    problem : object
        Has ``residual(x, p) -> (r, dr_dx, dr_dp)`` with ``r`` of shape
        ``(n,)``, ``dr_dx`` of shape ``(n, n)`` (dense ``ndarray`` or
        ``scipy.sparse``) and ``dr_dp`` of shape ``(n,)``.  ``dr_dx`` may be
        a generalized Jacobian (semismooth ``r``).
    p_span : (float, float)
        Start and end parameter values; may be decreasing.
    x0 : array_like, shape (n,), optional
        Initial guess of the solution at ``p_span[0]``. If omitted, the problem
        must provide ``initial_guess(p)`` (the HBM problems do).
    options : ContinuationOptions, optional
    start : ContinuationState, optional
        Continue a run from this state instead of starting at ``p_span[0]``
        (then ``x0`` must be omitted).  The returned arrays hold only the
        points after ``start`` (``first_index = start.index + 1``); point
        indices, ``folds``, ``max_points`` and the counters count the whole
        branch.

    Returns
    -------
    ContinuationResult
        Never raises on numerical failure; ``success``, ``status`` and
        ``message`` report the outcome (see :data:`STATUS_MESSAGES`).

    Raises
    ------
    ValueError
        Invalid ``p_span``, ``x0`` or ``x_scale`` length, ``x0`` together
        with ``start``, ``start.p`` outside ``p_span``, or wrongly shaped
        arrays returned by ``problem.residual``.
    TypeError
        ``problem`` has no callable ``residual``, or ``options`` or ``start``
        has the wrong type.
    """
    if options is None:
        options = ContinuationOptions()
    elif not isinstance(options, ContinuationOptions):
        raise TypeError(f"options must be a ContinuationOptions instance or None, got {type(options).__name__}")
    if not callable(getattr(problem, "residual", None)):
        raise TypeError("problem must have a callable method residual(x, p) -> (r, dr_dx, dr_dp)")
    p_start, p_end = _validate_span(p_span)
    if start is not None:
        _check_start(start, x0, p_start, p_end)
        x_init, n = None, start.x.size
    else:
        x_init = _first_guess(problem, x0, p_start, options)
        n = x_init.size
    # bordered_solver is looked up here, at call time, so that replacing
    # femodes.solvers.continuation.bordered_solver (e.g. to time it) takes effect
    system = ArclengthSystem(problem, n, options.newton, bordered_solver)
    return _Tracer(system, options, (p_start, p_end), start).trace(x_init)


def _check_start(start: Any, x0: Any, p_start: float, p_end: float) -> None:
    """``start`` is a state inside the span of a resumed run, which takes no ``x0``."""
    span_sign = 1.0 if p_end > p_start else -1.0
    if not isinstance(start, ContinuationState):
        raise TypeError(
            f"start must be a ContinuationState (point.state of a callback) or None, got {type(start).__name__}"
        )
    if x0 is not None:
        raise ValueError("continuation: pass either x0= (a new run) or start= (a resumed run), not both")
    if span_sign * (start.p - p_start) < 0 or span_sign * (start.p - p_end) > 0:
        raise ValueError(f"start.p = {start.p:g} lies outside p_span = ({p_start:g}, {p_end:g})")


def _first_guess(problem: Any, x0: Any, p_start: float, options: ContinuationOptions) -> np.ndarray:
    """``x0`` (or ``problem.initial_guess(p_start)``) as a fresh vector matching ``options.x_scale``."""
    if x0 is None:
        guess = getattr(problem, "initial_guess", None)
        if not callable(guess):
            raise TypeError("continuation: pass x0=, or give the problem a method initial_guess(p)")
        x0 = guess(p_start)
    x_init = start_vector(x0)
    n = x_init.size
    size = getattr(problem, "size", None)
    if isinstance(size, (int, np.integer)) and not isinstance(size, bool) and n != size:
        raise ValueError(f"continuation: x0 has {n} values, the problem has {int(size)} unknowns (problem.size); pass "
                         "an x0 of the problem's size")
    if options.x_scale is not None and not is_real_number(options.x_scale):
        if np.shape(options.x_scale) != (n,):
            raise ValueError(f"x_scale has shape {np.shape(options.x_scale)}, expected ({n},) matching x0")
    return x_init


# --------------------------------------------------------------------------- #
# the tracer
# --------------------------------------------------------------------------- #
class _Stop(Exception):
    """End of the run with ``status`` (see :data:`STATUS_MESSAGES`) and a detail for the message."""

    def __init__(self, status: int, extra: str = "") -> None:
        super().__init__(extra)
        self.status, self.extra = status, extra


class _Retry(Exception):
    """The step was rejected and halved: try again from the same point."""


class _Tracer:
    """One run of :func:`continuation`: the points accepted so far and the state of the step.

    :meth:`trace` starts (or resumes) the branch and repeats :meth:`advance`, one
    predictor-corrector step from the last point, until the run ends.  Rejecting a step
    (:meth:`reject`) raises :class:`_Retry`; every end of the run raises :class:`_Stop`, which
    :meth:`trace` turns into the :class:`ContinuationResult`.
    """

    def __init__(self, system: ArclengthSystem, options: ContinuationOptions, span: tuple[float, float],
                 start: ContinuationState | None) -> None:
        self.sys = system
        self.n = system.n
        self.opt = options
        self.p_start, self.p_end = span
        self.span_sign = 1.0 if self.p_end > self.p_start else -1.0
        self.start = start
        self.pts: list[_Pt] = []
        self.folds: list[int] = []
        self.located: list[int] = []  # folds located as turning points in this run
        self.n_rejected = 0
        # A resumed run keeps its start point as pts[0] (the previous point of the
        # first step) but does not return it: branch index of pts[k] is i0 + k.
        self.i0 = start.index if start is not None else 0
        self.skip = 1 if start is not None else 0
        self.x_scale: np.ndarray | None = None  # arclength scales, fixed for the whole run
        self.p_scale = math.nan
        self.ds = math.nan  # the next step
        self.last_sign = 0.0  # sign of dp/ds at the last point where it was non-zero (fold detection)
        self.just_rejected = False  # no step growth right after a rejection
        self.prev_geo: tuple[float, float] | None = None  # (angle, distance) of the last geometric rejection
        # phase-following predictor (ContinuationOptions.predictor): the problem's delay and its
        # generator, and the phase delay of the current step's predictor (None: tangent predictor)
        problem = system.problem
        self.phase = None
        if (options.predictor == "phase" and callable(getattr(problem, "phase_shift", None))
                and callable(getattr(problem, "phase_generator", None))):
            self.phase = (problem.phase_shift, problem.phase_generator)
        self.tau: float | None = None

    def trace(self, x_init: np.ndarray | None) -> ContinuationResult:
        """Run from ``x_init`` (a new run) or from ``start`` until a stop; the result."""
        try:
            if self.start is None:
                self.begin(x_init)
            else:
                self.resume(self.start)
            while True:
                try:
                    self.advance()
                except _Retry:
                    pass
        except _Stop as stop:
            return self.result(stop.status, stop.extra)

    # -- start ------------------------------------------------------------- #
    def begin(self, x_init: np.ndarray) -> None:
        """Correct ``x_init`` at ``p_start``, fix the scales, emit the start point with its tangent."""
        opt, n = self.opt, self.n
        init_opts = dataclasses.replace(opt.newton, max_iter=max(opt.newton.max_iter, _INITIAL_MAX_ITER))
        res0 = self.sys.solve_fixed_p(x_init, self.p_start, init_opts)
        self.p_scale = float(opt.p_scale) if opt.p_scale is not None else abs(self.p_end - self.p_start)
        if not res0.success:
            self.x_scale = (np.ones(n) if opt.x_scale is None
                            else np.broadcast_to(np.asarray(opt.x_scale, float), (n,)).copy())
            raise _Stop(5, f"Newton at p={self.p_start:g}: {res0.message}")
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
        first = _Pt(y=y0, t=t0 if t0 is not None else np.full(n + 1, np.nan), nit=nit, rnorm=rnorm, step=0.0)
        if t0 is None:
            self.pts.append(first)
            raise _Stop(6, f"r_x singular at the start point p={self.p_start:g} (start exactly at a fold?)")
        if np.sign(t0[n]) != self.opt.direction * self.span_sign:
            t0 = -t0
            t0.flags.writeable = False
            first.t = t0
        self.ds = float(self.opt.step)
        self.last_sign = float(np.sign(t0[n]))
        if not self.emit(first, False, self.ds):
            raise _Stop(3)

    def resume(self, start: ContinuationState) -> None:
        """Continue from ``start``: its point (not returned again), tangent, step, folds, scales, counters."""
        self.set_scales(np.array(start.x_scale), start.p_scale)
        self.sys.n_newton = start.n_newton
        self.n_rejected = start.n_rejected
        self.pts.append(_Pt(y=np.append(start.x, start.p), t=start.tangent, nit=0, rnorm=math.nan, step=0.0))
        self.folds.extend(start.folds)
        self.ds = min(max(start.step, self.opt.min_step), self.opt.max_step)
        self.last_sign = start.dp_sign

    def set_scales(self, x_scale: np.ndarray, p_scale: float) -> None:
        """Fix the arclength scales of the run."""
        x_scale.flags.writeable = False  # shared by the result and every ContinuationState
        self.x_scale, self.p_scale = x_scale, p_scale
        self.sys.set_scales(x_scale, p_scale)

    # -- one step ---------------------------------------------------------- #
    def advance(self) -> None:
        """Predictor, corrector, end and fold tests, step control and emission of one point."""
        n = self.n
        if self.i0 + len(self.pts) >= self.opt.max_points:
            raise _Stop(2, f"{self.i0 + len(self.pts)} points, last p={self.pts[-1].y[n]:g}")
        a = self.pts[-1]
        y_pred = self.predict(a)
        bound = self.crossed(y_pred[n])
        if bound is not None:
            self.try_finish(a, y_pred, bound)
            # the branch may turn back before the boundary: do a regular step
        b = self.correct(a, y_pred)
        bound = self.crossed(b.y[n])
        if bound is not None:
            self.try_finish(a, b.y, bound)
            self.reject(a, f"end point at p={bound:g} could not be computed",
                        failure=f"end point at p={bound:g} could not be computed")
        is_fold_b = self.detect_fold(a, b)
        # step control before emitting b: its state carries the next step
        self.control_step(b)
        if not self.emit(b, is_fold_b, self.ds):
            raise _Stop(3)

    def predict(self, a: _Pt) -> np.ndarray:
        """The predictor of the step ``ds`` from ``a`` (``ContinuationOptions.predictor``); sets
        :attr:`tau`, the phase delay it applied (None for the tangent predictor)."""
        self.tau = None
        if self.phase is not None:
            n, ds = self.n, self.ds
            shift, generator = self.phase
            x, tx, w = a.y[:n], a.t[:n], self.sys.w[:n]
            g = np.asarray(generator(x), dtype=float)
            gg = float(np.sum(w * g * g))
            if gg > 0 and math.isfinite(gg):
                alpha = float(np.sum(w * tx * g)) / gg
                x_pred = np.asarray(shift(x + ds * (tx - alpha * g), ds * alpha), dtype=float)
                if x_pred.shape == (n,) and np.all(np.isfinite(x_pred)):
                    self.tau = ds * alpha
                    return np.append(x_pred, a.y[n] + ds * a.t[n])
        return a.y + self.ds * a.t

    def reference_tangent(self, a: _Pt) -> np.ndarray:
        """``a``'s tangent delayed by the phase of the step's predictor (unit length in the scaled
        norm): what a step that only moved the motion in phase would end with."""
        if self.tau is None:
            return a.t
        n = self.n
        t = np.append(np.asarray(self.phase[0](a.t[:n], self.tau), dtype=float), a.t[n])
        norm = self.sys.norm(t)
        return t / norm if norm > 0 and math.isfinite(norm) else a.t

    def correct(self, a: _Pt, y_pred: np.ndarray) -> _Pt:
        """Corrector from ``y_pred`` on the hyperplane orthogonal to ``a.t``, and the new tangent."""
        n = self.n
        res = self.sys.correct(y_pred, self.sys.w * a.t, self.opt.corrector_deadline)
        if not res.success:
            self.prev_geo = None
            self.reject(a, f"corrector failed: {res.message}",
                        failure=f"at p={a.y[n]:g} (last corrector: {res.message})")
        t_b = self.sys.tangent_from(res.jac)
        if t_b is None:
            self.prev_geo = None
            self.reject(a, "singular bordered system at the new point",
                        failure=f"at p={a.y[n]:g} (singular bordered system)")
        y_b = np.array(res.x)
        angle, dist = self.guard(a, y_pred, y_b, t_b)
        return _Pt(y=y_b, t=t_b, nit=res.nit, rnorm=float(np.max(np.abs(res.fun[:n]))), step=self.ds,
                   angle=angle, dist=dist, theta=_contraction(res.history), tau=self.tau or 0.0)

    def guard(self, a: _Pt, y_pred: np.ndarray, y_b: np.ndarray, t_b: np.ndarray) -> tuple[float, float]:
        """Branch-jumping guard: reject a corrected point too far from the predictor or whose
        tangent turned too much, unless it is a kink of the branch or the step is minimal.
        Returns the turn angle (degrees) and the predictor-corrector distance of an accepted step."""
        opt = self.opt
        dist = self.sys.norm(y_b - y_pred)
        angle = math.degrees(math.acos(max(-1.0, min(1.0, self.sys.dot(self.reference_tangent(a), t_b)))))
        geometric = None
        if dist > opt.max_corrector_distance * self.ds:
            geometric = f"corrector moved {dist:.3g} > {opt.max_corrector_distance:g}*ds from the predictor"
        elif angle > opt.max_turn_angle:
            geometric = f"tangent turned by {angle:.1f} deg"
        else:
            geometric = self.retraced(y_b, t_b)
        if geometric is not None:
            # A kink of a semismooth branch turns the tangent by a fixed angle
            # however small the step, with a predictor distance ~ ds; a smooth
            # turn has angle ~ ds and distance ~ ds**2; a jump to another
            # branch has a distance that does not shrink with ds.
            kink = (
                self.prev_geo is not None
                and angle >= _KINK_RATIO * self.prev_geo[0]
                and dist <= _KINK_RATIO * self.prev_geo[1]
                and dist <= _KINK_MAX_DISTANCE * self.ds
            )
            if kink:
                logger.info("continuation: accepting a kink of the branch at p=%.6g (%s)", y_b[self.n], geometric)
            elif 0.5 * self.ds >= opt.min_step:
                self.prev_geo = (angle, dist)
                self.reject(a, geometric, failure=geometric)  # the halved step stays >= min_step: a retry
            else:
                logger.info("accepting step at minimal step size despite: %s (kink of the branch?)", geometric)
        self.prev_geo = None
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
        m = len(self.pts) - RETRACE_SKIP
        if m < 2:
            return None
        w = self.sys.w
        reach = RETRACE_DISTANCE * self.ds
        # the parameter part of the distance alone bounds it from below: only the segments whose
        # parameter range comes within reach of y_b's are measured in full (no copy of the whole
        # branch per step: 1e5-1e6 unknowns times hundreds of points)
        P = np.array([q.y[self.n] for q in self.pts[:m]])
        lo, hi = np.minimum(P[:-1], P[1:]), np.maximum(P[:-1], P[1:])
        gap = np.maximum(np.maximum(lo - y_b[self.n], y_b[self.n] - hi), 0.0)
        near = np.flatnonzero(math.sqrt(w[self.n]) * gap < reach)
        if not near.size:
            return None
        Y0 = np.array([self.pts[k].y for k in near])
        D = np.array([self.pts[k + 1].y for k in near]) - Y0  # segments k -> k + 1
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
        return (f"corrector landed on the branch already traced (between points {self.i0 + k} and {self.i0 + k + 1}, "
                f"distance {dist[j]:.3g}, same direction)")

    def reject(self, a: _Pt, reason: str, *, failure: str) -> None:
        """Halve the step and retry from ``a`` (raises :class:`_Retry`); below ``min_step`` the run
        fails (status 4, ``failure`` in the message)."""
        self.n_rejected += 1
        self.just_rejected = True
        logger.debug("step ds=%.3g from p=%.6g rejected: %s", self.ds, a.y[self.n], reason)
        self.ds *= 0.5
        if self.ds < self.opt.min_step:
            raise _Stop(4, failure)
        raise _Retry

    def control_step(self, b: _Pt) -> None:
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
        if opt.target_norm_change is not None and self.pts:
            na, nb = self._x_norm(self.pts[-1]), self._x_norm(b)
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

    def _x_norm(self, q: _Pt) -> float:
        """Scaled norm of the unknowns ``x`` of ``q`` (the parameter left out)."""
        return self.sys.norm(np.append(q.y[: self.n], 0.0))

    # -- folds ------------------------------------------------------------- #
    def detect_fold(self, a: _Pt, b: _Pt) -> bool:
        """Handle a sign change of ``dp/ds`` between ``a`` and ``b``; True if ``b`` is the fold point."""
        sign_b = float(np.sign(b.t[self.n]))
        is_fold_b = False
        if sign_b != 0 and self.last_sign != 0 and sign_b != self.last_sign:
            is_fold_b = self.record_fold(a, b)
        if sign_b != 0:
            self.last_sign = sign_b
        return is_fold_b

    def record_fold(self, a: _Pt, b: _Pt) -> bool:
        """Locate the fold between ``a`` and ``b`` and emit it, or (not located) mark the nearer of
        the two; True if that is ``b``.  A located fold beyond the span ends the run there."""
        n, opt = self.n, self.opt
        located = None
        tried = opt.locate_folds and self.i0 + len(self.pts) + 2 <= opt.max_points
        if tried:
            located = self.locate_fold(a, self.ds, b)
        if located is None and tried and self.ds > _FOLD_RETRY_STEP * opt.step and 0.5 * self.ds >= opt.min_step:
            self.reject(a, "fold not located: a shorter step", failure="fold not located")
        if located is not None and self.crossed(located.y[n]) is not None:
            # the branch left the span between a and b (excursion through the
            # fold): stop on the boundary before the fold
            bound = self.crossed(located.y[n])
            logger.info("continuation: branch leaves the span through p=%g before a fold", bound)
            self.try_finish(a, located.y, bound)
            self.reject(a, f"fold beyond p={bound:g}, but the end point could not be computed",
                        failure=f"end point at p={bound:g} could not be computed")
        if located is not None:
            logger.info("continuation: fold located at p=%.8g", located.y[n])
            self.located.append(self.i0 + len(self.pts))  # the index emit gives it
            if not self.emit(located, True, None):
                raise _Stop(3)
            return False
        here = self.i0 + len(self.pts) - 1  # index of a
        is_fold_b = bool(abs(b.t[n]) <= abs(a.t[n]) or (self.folds and self.folds[-1] == here))
        if not is_fold_b:
            self.folds.append(here)
        logger.info("continuation: fold detected near p=%.8g", (b if is_fold_b else a).y[n])
        return is_fold_b

    def locate_fold(self, a: _Pt, ds: float, b: _Pt) -> _Pt | None:
        """Regula falsi (Illinois) on s -> dp/ds along the step family from ``a``."""
        n = self.n
        c = self.sys.w * a.t
        found: list[_Pt] = []

        def dp_ds(s: float) -> float | None:
            res = self.sys.correct(a.y + s * a.t, c)
            if not res.success:
                return None
            t = self.sys.tangent_from(res.jac)
            if t is None:
                return None
            found.append(_Pt(y=np.array(res.x), t=t, nit=res.nit, rnorm=float(np.max(np.abs(res.fun[:n]))), step=s))
            return t[n]

        def best() -> _Pt | None:
            q = min(found, key=lambda q: abs(q.t[n])) if found else None
            return None if q is None or abs(q.t[n]) > _FOLD_ACCEPT * max(abs(a.t[n]), abs(b.t[n])) else q

        br = illinois(dp_ds, 0.0, ds, a.t[n], b.t[n], max_iter=_FOLD_MAX_ITER, ftol=_FOLD_TOL, xtol=1e-12 * ds)
        if best() is None and br.nfev == _FOLD_MAX_ITER and len(found) == br.nfev:
            # a sharp fold: dp/ds turns within a small part of the step and looks like a jump on its
            # scale, where regula falsi crawls; bisection narrows the bracket down to where it turns
            illinois(dp_ds, br.lo, br.hi, br.f_lo, br.f_hi, max_iter=_FOLD_SHARP_ITER, ftol=_FOLD_TOL,
                     xtol=1e-12 * ds, bisect_if_slow=True)
        return best()

    # -- span end ---------------------------------------------------------- #
    def crossed(self, p: float) -> float | None:
        """The span boundary that ``p`` lies beyond, if any."""
        if self.span_sign * (p - self.p_end) > 0:
            return self.p_end
        if self.span_sign * (p - self.p_start) < 0:
            return self.p_start
        return None

    def try_finish(self, a: _Pt, y_far: np.ndarray, bound: float) -> None:
        """End the run (status 0 at ``p_end``, 1 at ``p_start``) with a point exactly at ``p = bound``
        between ``a`` and ``y_far``; return if that point cannot be computed."""
        n = self.n
        if a.y[n] == bound:  # already on the boundary (e.g. direction=-1 at the start)
            raise _Stop(0 if bound == self.p_end else 1)
        got = self.end_point(a, y_far, bound)
        if got is None:
            return
        q, fold = got
        if fold:
            # record the point nearest to the fold (smaller |dp/ds|)
            if abs(q.t[n]) >= abs(a.t[n]):
                fold = False
                if not (self.folds and self.folds[-1] == self.i0 + len(self.pts) - 1):
                    self.folds.append(self.i0 + len(self.pts) - 1)
        self.emit(q, fold, None)
        raise _Stop(0 if bound == self.p_end else 1)

    def end_point(self, a: _Pt, y_far: np.ndarray, bound: float) -> tuple[_Pt, bool] | None:
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
        return _Pt(y=y_end, t=t_end, nit=res.nit, rnorm=res.residual_norm, step=self.sys.norm(y_end - a.y)), fold

    # -- output ------------------------------------------------------------ #
    def emit(self, q: _Pt, is_fold: bool, next_step: float | None) -> bool:
        """Append an accepted point; return False if the callback asks to stop.

        ``next_step``: the step the run takes from ``q``, or ``None`` if the
        run does not continue from ``q`` (inserted fold point, end point).
        """
        n = self.n
        self.pts.append(q)
        idx = self.i0 + len(self.pts) - 1
        if is_fold:
            self.folds.append(idx)
        if idx % _LOG_EVERY == 0:
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

    def state(self, xv: np.ndarray, q: _Pt, idx: int, next_step: float) -> ContinuationState:
        """What a resumed run needs to continue from point ``idx`` (``q``, unknowns ``xv``)."""
        return ContinuationState(
            x=xv, p=float(q.y[self.n]), tangent=q.t, step=next_step, index=idx, folds=tuple(self.folds),
            dp_sign=self.last_sign, x_scale=self.x_scale, p_scale=self.p_scale, n_newton=self.sys.n_newton,
            n_rejected=self.n_rejected,
        )

    def result(self, status: int, extra: str = "") -> ContinuationResult:
        """The points after ``start`` (all points of a new run) as read-only arrays, and the outcome."""
        n = self.n
        msg = STATUS_MESSAGES[status] + (f": {extra}" if extra else "")
        out = self.pts[self.skip:]
        store = self.opt.store_tangents
        if out:
            X = np.array([q.y[:n] for q in out])
            P = np.array([q.y[n] for q in out])
            T = np.array([q.t for q in out]) if store else None
        else:
            X = np.empty((0, n))
            P = np.empty(0)
            T = np.empty((0, n + 1)) if store else None
        arrays = dict(
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
            msg, self.i0 + len(self.pts), len(self.folds), self.sys.n_newton, self.n_rejected,
        )
        return ContinuationResult(
            folds=tuple(self.folds),
            success=success,
            status=status,
            message=msg,
            n_newton=self.sys.n_newton,
            n_rejected=self.n_rejected,
            p_scale=self.p_scale,
            first_index=self.i0 + self.skip,
            located=tuple(self.located),
            **arrays,
        )
