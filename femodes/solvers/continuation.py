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
a method ``residual(x, p) -> (r, dr_dx, dr_dp)``
(:class:`~femodes.solvers.protocols.ContinuationProblem`).

Layout: this module holds :func:`continuation` (checks its input and starts a
:class:`~femodes.solvers.tracing.Tracer`). The tracer runs the steps with small collaborating
parts: the predictor (:mod:`~femodes.solvers.predictors`), the step size
(:mod:`~femodes.solvers.step_control`), the branch-jumping guard (:mod:`~femodes.solvers.guard`),
the folds (:mod:`~femodes.solvers.folds`) and the exact end on the span boundary
(:mod:`~femodes.solvers.span_ends`), which share the run's record
(:mod:`~femodes.solvers.trace_record`). What a problem provides, including the optional hook of
the phase predictor, is stated by the protocols of :mod:`femodes.solvers.protocols`. The options
and result types are in :mod:`femodes.solvers.continuation_types`, the bordered linear algebra in
:mod:`femodes.solvers.bordered`, the problem's evaluation and scaled geometry in
:mod:`femodes.solvers.arclength`; all public names are importable from here.

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

import math
from typing import Any

import numpy as np

from .arclength import ArclengthSystem
from .bordered import bordered_matrix, bordered_solver
from .checks import is_real_number, show, start_vector
from .continuation_types import (
    STATUS_MESSAGES,
    ContinuationOptions,
    ContinuationPoint,
    ContinuationResult,
    ContinuationState,
)
from .guard import RETRACE_ANGLE, RETRACE_DISTANCE, RETRACE_SKIP
from .protocols import ContinuationProblem, SupportsPhaseShift
from .tracing import Tracer

__all__ = [
    "ContinuationOptions",
    "ContinuationPoint",
    "ContinuationResult",
    "ContinuationState",
    "continuation",
    "STATUS_MESSAGES",
    "bordered_matrix",
    "bordered_solver",
    "ContinuationProblem",
    "SupportsPhaseShift",
    "RETRACE_DISTANCE",
    "RETRACE_SKIP",
    "RETRACE_ANGLE",
]


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
    3. Predictor ``y + ds t`` (``predictor=Phase()`` with a problem that has
       the optional hook :class:`~femodes.solvers.protocols.SupportsPhaseShift`,
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
       (:meth:`~femodes.solvers.guard.BranchGuard.retraced`), is also rejected (branch-jumping guard)
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
    return Tracer(system, options, (p_start, p_end), start).trace(x_init)


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
