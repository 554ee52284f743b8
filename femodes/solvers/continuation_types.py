"""Options, points, resumable states and results of :func:`~femodes.solvers.continuation.continuation`.

Plain frozen dataclasses, validated at construction (messages name the field and quote the bad
value); the algorithm itself is in :mod:`femodes.solvers.continuation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable

import numpy as np

from .checks import check_bool, check_callable, check_int, check_positive, check_vector, is_real_number, named_by, show
from .newton import NewtonOptions
from .predictors import Phase, PredictorStrategy, as_predictor

__all__ = [
    "ContinuationOptions",
    "ContinuationPoint",
    "ContinuationResult",
    "ContinuationState",
    "STATUS_MESSAGES",
]

#: Meaning of :attr:`ContinuationResult.status`.
STATUS_MESSAGES = {
    0: "reached end of span (p_span[1])",
    1: "branch left the span through p_span[0]",
    2: "max_points reached before the end of the span",
    3: "stopped by callback",
    4: "step size fell below min_step (corrector failed repeatedly)",
    5: "initial correction at p_span[0] failed",
    6: "initial tangent could not be computed (singular bordered system)",
}

def _default_newton() -> NewtonOptions:
    return NewtonOptions(atol=1e-9, max_iter=12)


@dataclass(frozen=True, kw_only=True)
class ContinuationOptions:
    """Options of :func:`continuation` (defaults and their measurements: :doc:`/guide/continuation`).

    Parameters
    ----------
    step : float, default 0.05
        Initial pseudo-arclength step in the scaled norm (see the module docstring).
    min_step, max_step : float, default 1e-6, 0.5
        Bounds of the step. The run stops (status 4, failure) when rejections halve it below ``min_step``.
    max_points : int, default 2000
        Maximum number of points (>= 2), start and fold points included; reaching it gives status 2.
    target_iterations : int, default 4
        The step is divided by ``nit/target_iterations`` after ``nit`` corrector iterations; with
        ``target_contraction`` set, only when ``nit > target_iterations`` (a brake).
    max_growth : float, default 2.0
        Largest step growth per step (>= 1); no growth right after a rejection.
    target_angle : float or None, default 10.0
        Nominal turn of the tangent per step (degrees, in (0, ``max_turn_angle``)); the step is divided
        by ``angle/target_angle`` (Allgower & Georg 2003, sec. 6.1). ``None``: not used.
    target_contraction : float or None, default 0.25
        Nominal contraction ``|r_1|/|r_0|`` of the first corrector iteration, in (0, 1); the step is
        divided by ``sqrt(theta/target_contraction)`` (Deuflhard 2004, sec. 5.1). ``None``: not used.
        The step control takes the smallest of the three steps, clipped to ``[min_step, max_step]``.
    corrector_deadline : int or None, default 3
        Abandon the corrector (reject and halve the step) when its residual is still above half its
        predictor value after this many iterations. ``None``: run to ``newton.max_iter``.
    direction : {+1, -1}, default +1
        Initial direction relative to the span: ``+1`` from ``p_span[0]`` towards ``p_span[1]``.
    x_scale, p_scale : float or ndarray of shape (n,) or None; float or None
        Scales of ``x`` and ``p`` in the arclength norm, fixed for the run. ``None``: the RMS of the
        corrected ``x0`` (1.0 if zero); ``|p_span[1] - p_span[0]|``.
    newton : NewtonOptions, default ``NewtonOptions(atol=1e-9, max_iter=12)``
        Corrector options; the initial correction raises ``max_iter`` to at least 50. Its
        ``linear_solver`` also gets the ``(n+1) x (n+1)`` bordered systems (default :func:`bordered_solver`).
    callback : callable or None
        ``callback(point)`` for every accepted point; returning ``False`` stops the run (status 3).
    locate_folds : bool, default True
        Locate a detected fold by regula falsi (Illinois) and insert it (``is_fold=True``).
    store_tangents : bool, default False
        Keep all tangents in :attr:`ContinuationResult.tangents`.
    max_corrector_distance, max_turn_angle : float, default 1.0, 60.0
        Reject and halve a step whose corrector lands farther than ``max_corrector_distance * ds`` from
        the predictor, or whose tangent turns by more than ``max_turn_angle`` degrees. Kinks of a
        semismooth branch (contact onset) are accepted; both guards are waived at ``min_step``.
    predictor : predictor strategy, default ``femodes.predictors.Phase()``
        ``Tangent()``: Euler ``y + ds t``. ``Phase()``: also delays the motion by the predicted phase, for
        problems with :class:`~femodes.solvers.protocols.SupportsPhaseShift`; others get ``Tangent()``.
    target_norm_change : float or None, default None
        Nominal relative change of the scaled norm of ``x`` per step (> 0); the step is divided by
        ``|ln(|x_b|/|x_a|)| / ln(1 + target_norm_change)``. ``None``: not used.
    """

    step: float = 0.05
    min_step: float = 1e-6
    max_step: float = 0.5
    max_points: int = 2000
    target_iterations: int = 4
    max_growth: float = 2.0
    direction: int = 1
    x_scale: float | np.ndarray | None = None
    p_scale: float | None = None
    newton: NewtonOptions = field(default_factory=_default_newton)
    callback: Callable[[ContinuationPoint], Any] | None = None
    locate_folds: bool = True
    store_tangents: bool = False
    max_corrector_distance: float = 1.0
    max_turn_angle: float = 60.0
    target_angle: float | None = 10.0
    target_contraction: float | None = 0.25
    corrector_deadline: int | None = 3
    predictor: PredictorStrategy = field(default_factory=Phase)
    target_norm_change: float | None = None

    def __post_init__(self) -> None:
        _check_steps(self.step, self.min_step, self.max_step)
        check_int("max_points", self.max_points, 2)
        check_int("target_iterations", self.target_iterations, 1)
        check_positive("max_growth", self.max_growth)
        if self.max_growth < 1:
            raise ValueError(f"max_growth must be >= 1, got {show(self.max_growth)}")
        _check_direction(self.direction)
        if self.x_scale is not None:
            _check_x_scale(self.x_scale)
        if self.p_scale is not None:
            check_positive("p_scale", self.p_scale)
        if not isinstance(self.newton, NewtonOptions):
            raise TypeError(f"newton must be a NewtonOptions instance, got {show(self.newton)}")
        check_callable("callback", self.callback)
        check_bool("locate_folds", self.locate_folds)
        check_bool("store_tangents", self.store_tangents)
        check_positive("max_corrector_distance", self.max_corrector_distance)
        check_positive("max_turn_angle", self.max_turn_angle)
        if self.max_turn_angle >= 180:
            raise ValueError(f"max_turn_angle must be in (0, 180) degrees, got {show(self.max_turn_angle)}")
        if self.target_angle is not None:
            check_positive("target_angle", self.target_angle)
            if not self.target_angle < self.max_turn_angle:
                raise ValueError(f"target_angle must be in (0, max_turn_angle={show(self.max_turn_angle)}) degrees "
                                 f"or None, got {show(self.target_angle)}")
        if self.target_contraction is not None:
            check_positive("target_contraction", self.target_contraction)
            if not self.target_contraction < 1:
                raise ValueError(f"target_contraction must be in (0, 1) or None, got {show(self.target_contraction)}")
        if self.corrector_deadline is not None:
            check_int("corrector_deadline", self.corrector_deadline, 1)
        if self.target_norm_change is not None:
            check_positive("target_norm_change", self.target_norm_change)
        with named_by("ContinuationOptions"):
            object.__setattr__(self, "predictor", as_predictor(self.predictor))


def _check_steps(step: Any, min_step: Any, max_step: Any) -> None:
    """Each step bound positive, and ``min_step <= step <= max_step``."""
    for name, value in (("step", step), ("min_step", min_step), ("max_step", max_step)):
        check_positive(name, value)
    if min_step > max_step:
        raise ValueError(f"min_step must be <= max_step, got min_step={show(min_step)}, max_step={show(max_step)}")
    if not min_step <= step <= max_step:
        raise ValueError(
            f"step must satisfy min_step <= step <= max_step, got step={show(step)} "
            f"(min_step={show(min_step)}, max_step={show(max_step)})"
        )


def _check_direction(direction: Any) -> None:
    """The integer +1 or -1 (bools and floats are not)."""
    if (isinstance(direction, (bool, np.bool_)) or not isinstance(direction, (int, np.integer))
            or direction not in (1, -1)):
        raise ValueError(f"direction must be +1 or -1, got {show(direction)}")


def _check_x_scale(x_scale: Any) -> None:
    """A positive number, or a 1-D array of positive finite numbers."""
    if is_real_number(x_scale):
        check_positive("x_scale", x_scale)
        return
    try:
        xs = np.asarray(x_scale, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"x_scale must be a positive number, a 1-D array of positive numbers or None, got {show(x_scale)}"
        ) from exc
    if xs.ndim != 1 or xs.size == 0 or not np.all(np.isfinite(xs)) or np.any(xs <= 0):
        raise ValueError(
            "x_scale must be a positive number, a 1-D array of positive finite numbers or None, "
            f"got {show(x_scale)}"
        )


@dataclass(frozen=True, kw_only=True, eq=False)
class ContinuationPoint:
    """One accepted point of a branch (passed to the callback).

    Attributes
    ----------
    x : ndarray, shape (n,)
        Unknowns (read-only).
    p : float
        Parameter.
    tangent : ndarray, shape (n+1,)
        Unit tangent ``(dx/ds, dp/ds)`` in the scaled norm, oriented along the
        direction of travel (read-only).
    nit : int
        Newton iterations of the (final, accepted) solve that produced the
        point.
    residual_norm : float
        ``norm(r(x, p), inf)``.
    step : float
        Pseudo-arclength step (scaled norm) from the previous regular point
        along its tangent (a point following an inserted fold point still
        counts from the point before the fold); 0 for the start point; the
        scaled chord length for the end point.
    is_fold : bool
        The point is a located fold, or, without localisation, the point
        nearest (smaller ``|dp/ds|``) to a detected fold.
    index : int
        Index of the point in the branch (counting the points before the
        start state of a resumed run).
    state : ContinuationState or None
        The state of the run after this point, from which
        ``continuation(..., start=state)`` continues exactly as this run
        does.  ``None`` for points a run cannot continue from exactly: an
        inserted fold point (the run continues from the point after it) and
        the end point.
    """

    x: np.ndarray
    p: float
    tangent: np.ndarray
    nit: int
    residual_norm: float
    step: float
    is_fold: bool
    index: int
    state: ContinuationState | None = None


@dataclass(frozen=True, kw_only=True, eq=False)
class ContinuationState:
    """State of a run after an accepted point: what ``continuation(start=...)`` needs.

    A run started from the state of point ``k`` (received by the callback as
    ``point.state``) computes the same points ``k+1, k+2, ...`` as the run
    that produced it (same predictor, tangent orientation, step size, fold
    bookkeeping and arclength scaling); the start point itself is not
    repeated in the output.  Arrays are validated and kept read-only.

    Attributes
    ----------
    x : ndarray, shape (n,)
        Unknowns of the point.
    p : float
        Parameter of the point.
    tangent : ndarray, shape (n+1,)
        Unit tangent (scaled norm) at the point, oriented along the direction
        of travel.
    step : float
        Pseudo-arclength step the run takes next (after step control).
    index : int
        Index of the point in the branch (>= 0).
    folds : tuple of int
        Indices of the fold points up to ``index``.
    dp_sign : float
        Sign (+1 or -1) of ``dp/ds`` at the last point where it was non-zero:
        a fold is a change of this sign.
    x_scale : ndarray, shape (n,)
        Scales of the unknowns in the arclength norm (used instead of
        ``ContinuationOptions.x_scale``).
    p_scale : float
        Scale of the parameter (used instead of ``ContinuationOptions.p_scale``).
    n_newton, n_rejected : int, default 0
        Newton iterations and rejected steps so far (the totals of the
        resumed run's result include them).
    """

    x: np.ndarray
    p: float
    tangent: np.ndarray
    step: float
    index: int
    folds: tuple[int, ...]
    dp_sign: float
    x_scale: np.ndarray
    p_scale: float
    n_newton: int = 0
    n_rejected: int = 0

    def __post_init__(self) -> None:
        with named_by("ContinuationState"):
            x = check_vector("x", self.x)
            object.__setattr__(self, "x", x)
            object.__setattr__(self, "tangent", check_vector("tangent", self.tangent, size=x.size + 1))
            object.__setattr__(self, "x_scale", check_vector("x_scale", self.x_scale, size=x.size))
        if np.any(self.x_scale <= 0):
            raise ValueError(f"ContinuationState: x_scale must be positive, got {show(self.x_scale)}")
        if not is_real_number(self.p) or not math.isfinite(self.p):
            raise ValueError(f"ContinuationState: p must be a finite real number, got {show(self.p)}")
        object.__setattr__(self, "p", float(self.p))
        for name in ("step", "p_scale"):
            object.__setattr__(self, name, check_positive(f"ContinuationState.{name}", getattr(self, name)))
        for name in ("index", "n_newton", "n_rejected"):
            object.__setattr__(self, name, check_int(f"ContinuationState.{name}", getattr(self, name), 0))
        object.__setattr__(self, "folds", _fold_indices(self.folds, self.index))
        if self.dp_sign not in (1, -1) or isinstance(self.dp_sign, (bool, np.bool_)):
            raise ValueError(f"ContinuationState: dp_sign must be +1 or -1, got {show(self.dp_sign)}")
        object.__setattr__(self, "dp_sign", float(self.dp_sign))


def _fold_indices(folds: Any, index: int) -> tuple[int, ...]:
    """``folds`` as a tuple of point indices in ``[0, index]``."""
    try:
        out = tuple(int(i) for i in folds)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"ContinuationState: folds must be a sequence of point indices, got {show(folds)}") from exc
    if any(not 0 <= i <= index for i in out):
        raise ValueError(f"ContinuationState: folds must be indices in [0, index={index}], got {out}")
    return out


@dataclass(frozen=True, kw_only=True, eq=False)
class ContinuationResult:
    """Traced branch returned by :func:`continuation`.

    Attributes
    ----------
    x, p : ndarray, shape (n_points, n) and (n_points,)
        Unknowns and parameter of the points.
    nit : ndarray of int, shape (n_points,)
        Newton iterations per point (start point: initial correction).
    residual_norm : ndarray, shape (n_points,)
        ``norm(r(x_i, p_i), inf)``.
    step : ndarray, shape (n_points,)
        Step that produced each point (0 for the start point).
    folds : tuple of int
        Indices of fold points (see :attr:`ContinuationPoint.is_fold`).
    tangents : ndarray of shape (n_points, n+1) or None
        Only with ``store_tangents=True``.
    success : bool
        ``True`` for statuses 0-3 (all returned points are valid solutions), ``False`` for 4-6.
    status : int
        See :data:`STATUS_MESSAGES`: 0 reached ``p_span[1]``; 1 left through ``p_span[0]``;
        2 ``max_points`` reached; 3 stopped by callback; 4 step below ``min_step``; 5 initial
        correction failed; 6 initial tangent failed.
    message : str
    n_newton : int
        Total Newton iterations, including rejected steps, the initial correction, fold localisation
        and the end point.
    n_rejected : int
        Number of rejected steps.
    x_scale, p_scale : ndarray of shape (n,), float
        Scales of the unknowns and of the parameter used in the arclength norm.
    first_index : int
        Branch index of the first returned point: 0, or ``start.index + 1`` for a run resumed with
        ``start=`` (whose arrays hold only the new points; ``folds`` and the counters cover the whole branch).
    located : tuple of int
        The folds of this run (after ``start``) located as turning points (inserted points where
        ``dp/ds`` vanishes, ``locate_folds``); the other folds were only detected: the point nearer to
        the sign change of ``dp/ds``.
    """

    x: np.ndarray
    p: np.ndarray
    nit: np.ndarray
    residual_norm: np.ndarray
    step: np.ndarray
    folds: tuple[int, ...]
    tangents: np.ndarray | None
    success: bool
    status: int
    message: str
    n_newton: int
    n_rejected: int
    x_scale: np.ndarray
    p_scale: float
    first_index: int = 0
    located: tuple[int, ...] = ()

    @property
    def n_points(self) -> int:
        """Number of points of the branch."""
        return int(self.p.shape[0])
