r"""Pseudo-arclength continuation of solution branches of :math:`r(x, p) = 0`.

The branch :math:`\{y = (x, p) \in \mathbb{R}^{n+1} : r(x, p) = 0\}` is traced by a predictor (the
tangent, or for periodic motions that can be delayed in phase one that follows the phase:
``ContinuationOptions.predictor``) and a corrector, solved by
:func:`~femodes.solvers.newton.semismooth_newton`, on the hyperplane orthogonal to the previous
tangent in the scaled inner product
:math:`\langle u, v\rangle_S = \frac1n \sum_i u_i v_i / s_{x,i}^2 + u_p v_p / s_p^2`
(Allgower & Georg [AG03]_, chapters 2 and 6; Keller [K77]_). The tangent comes from a bordered
system, which carries the continuation through folds. The equations: :doc:`/guide/continuation`.

Sparse bordered systems are solved by default with :func:`bordered_solver` (block elimination on
the sparse LU of ``r_x`` plus iterative refinement, no fill-in from the dense last row);
``NewtonOptions.linear_solver`` replaces it. ``problem`` is any object with a method
``residual(x, p) -> (r, dr_dx, dr_dp)`` (:class:`~femodes.solvers.protocols.ContinuationProblem`).

Layout: :func:`continuation` checks its input and starts a
:class:`~femodes.solvers.tracing.Tracer`, which runs the steps with the predictor
(:mod:`~femodes.solvers.predictors`), the step size (:mod:`~femodes.solvers.step_control`), the
branch-jumping guard (:mod:`~femodes.solvers.guard`), the folds (:mod:`~femodes.solvers.folds`) and
the exact end on the span boundary (:mod:`~femodes.solvers.span_ends`), sharing the run's record
(:mod:`~femodes.solvers.trace_record`). Problem protocols: :mod:`femodes.solvers.protocols`; types:
:mod:`femodes.solvers.continuation_types`; bordered algebra: :mod:`femodes.solvers.bordered`;
evaluation and scaled geometry: :mod:`femodes.solvers.arclength`. All public names are importable
from here.

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

    ``x0`` is corrected at ``p_span[0]``; then each step predicts along the tangent (or the phase),
    corrects on the bordered system, adapts the step and rejects branch jumps (:class:`ContinuationOptions`),
    detects and locates folds (sign change of ``dp/ds``), and ends with a point computed exactly at
    ``p_span[1]`` (status 0) or ``p_span[0]`` after turning back (status 1). The algorithm, step by
    step: :doc:`/guide/continuation`.

    Parameters
    ----------
    problem : object
        Has ``residual(x, p) -> (r, dr_dx, dr_dp)``, shapes ``(n,)``, ``(n, n)`` (dense or
        ``scipy.sparse``, possibly a generalized Jacobian) and ``(n,)``.
    p_span : (float, float)
        Start and end parameter values; may be decreasing.
    x0 : array_like, shape (n,), optional
        Initial guess at ``p_span[0]``. If omitted, the problem must provide ``initial_guess(p)``.
    options : ContinuationOptions, optional
    start : ContinuationState, optional
        Continue from this state (``point.state`` from the callback, possibly saved and rebuilt)
        instead of starting at ``p_span[0]``; ``x0`` must be omitted. The run computes exactly the
        points the original run computed after it, given the same ``problem``, ``p_span`` and options;
        the scales of ``start`` replace ``options.x_scale``/``p_scale``. The arrays hold only the points
        after ``start``; indices, ``folds``, ``max_points`` and the counters count the whole branch.

    Returns
    -------
    ContinuationResult
        Never raises on numerical failure; ``success``, ``status`` and ``message`` report the outcome
        (see :data:`STATUS_MESSAGES`).

    Raises
    ------
    ValueError
        Invalid ``p_span``, ``x0`` or ``x_scale`` length, ``x0`` together with ``start``, ``start.p``
        outside ``p_span``, or wrongly shaped arrays returned by ``problem.residual``.
    TypeError
        ``problem`` has no callable ``residual``, or ``options`` or ``start`` has the wrong type.
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
