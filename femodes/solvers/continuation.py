r"""Pseudo-arclength continuation of solution branches of :math:`r(x, p) = 0`.

The branch :math:`\{y = (x, p) \in \mathbb{R}^{n+1} : r(x, p) = 0\}` is traced
by a tangent predictor and a corrector on the hyperplane orthogonal (in a
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

References
----------
.. [AG03] E. L. Allgower and K. Georg, *Introduction to Numerical
   Continuation Methods*, SIAM Classics in Applied Mathematics 45 (2003).
.. [K77] H. B. Keller, "Numerical solution of bifurcation and nonlinear
   eigenvalue problems", in *Applications of Bifurcation Theory*, Academic
   Press (1977) 359-384.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .newton import (
    _LINSOLVE_ERRORS,
    NewtonOptions,
    NewtonResult,
    _check_bool,
    _check_callable,
    _check_int,
    _check_positive,
    _is_real_number,
    _show,
    _is_operator,
    _start_vector,
    default_linear_solver,
    semismooth_newton,
)

__all__ = [
    "ContinuationOptions",
    "ContinuationPoint",
    "ContinuationResult",
    "ContinuationState",
    "continuation",
    "STATUS_MESSAGES",
    "bordered_solver",
]

logger = logging.getLogger(__name__)

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

#: Minimal number of Newton iterations allowed for the initial correction of x0.
_INITIAL_MAX_ITER = 50
#: Iterations and tolerance of the fold localisation (regula falsi on dp/ds).
_FOLD_MAX_ITER = 12
_FOLD_TOL = 1e-9
#: Kink acceptance (see ContinuationOptions.max_turn_angle): after a geometric
#: rejection, the halved step is accepted as crossing a kink when the turn angle
#: kept >= 75 % of its value, the predictor distance shrank to <= 75 % and is
#: at most 2 ds.
_KINK_RATIO = 0.75
_KINK_MAX_DISTANCE = 2.0
#: Log progress at INFO level every this many accepted points.
_LOG_EVERY = 10


def _default_newton() -> NewtonOptions:
    return NewtonOptions(atol=1e-9, max_iter=12)


@dataclass(frozen=True, kw_only=True)
class ContinuationOptions:
    """Options of :func:`continuation`.

    Parameters
    ----------
    step : float, default 0.05
        Initial pseudo-arclength step in the scaled norm (see module docstring).
    min_step, max_step : float, default 1e-6, 0.5
        Bounds of the step; ``min_step <= step <= max_step``.  The run stops
        (status 4, failure) when repeated rejections halve the step below
        ``min_step``.
    max_points : int, default 2000
        Maximum number of points of the branch, *including* the start point
        and inserted fold points (>= 2).  Reaching it stops the run with
        ``success=True``, ``status=2``.
    target_iterations : int, default 4
        Step control: after an accepted step with ``nit`` corrector
        iterations the step is multiplied by ``target/max(nit, 1)`` clipped to
        ``[0.5, max_growth]`` (no growth right after a rejection).
    max_growth : float, default 2.0
        Maximal step growth factor per step (>= 1).
    direction : {+1, -1}, default +1
        Initial direction of travel *relative to the span*: ``+1`` starts
        from ``p_span[0]`` towards ``p_span[1]`` (i.e. increasing ``p`` for an
        increasing span, decreasing ``p`` for a decreasing one); ``-1`` starts
        the other way, which leaves the span immediately through
        ``p_span[0]`` unless the branch turns back at once; it is kept for
        symmetry and yields a 1-point result with status 1 otherwise.
    x_scale : float or ndarray of shape (n,) or None
        Scale ``s_x`` of the unknowns in the arclength norm.  ``None``: the
        root-mean-square of the corrected start point ``x0``, or 1.0 if that
        is zero (pass ``x_scale`` explicitly when starting from the trivial
        solution).  The scale is fixed for the whole run.
    p_scale : float or None
        Scale ``s_p`` of the parameter.  ``None``: ``|p_span[1] - p_span[0]|``.
    newton : NewtonOptions
        Corrector options (default ``NewtonOptions(atol=1e-9, max_iter=12)``).
        The initial correction of ``x0`` uses the same options with
        ``max_iter`` raised to at least 50.  ``newton.linear_solver``, if
        given, receives the ``(n+1) x (n+1)`` bordered matrices of the
        corrector and tangent systems (sparse CSC if ``dr_dx`` is sparse) as
        well as the ``n x n`` ``dr_dx`` of the fixed-``p`` solves (start and
        end points); if ``None``, bordered systems use
        :func:`bordered_solver` and fixed-``p`` systems
        :func:`~femodes.solvers.newton.default_linear_solver`.  ``atol``
        applies to the inf-norm of ``r(x, p)`` (and of the arclength
        equation).
    callback : callable or None
        ``callback(point: ContinuationPoint)`` called for every accepted point
        (start, regular, fold and end points).  If it returns ``False`` (the
        object ``False``, not merely falsy), the run stops cleanly after that
        point with ``status=3`` and ``success=True``.  ``point.state`` holds
        what :func:`continuation` needs to continue the run from that point
        later (``start=point.state``), e.g. after saving it to a file.
    locate_folds : bool, default True
        When a fold is detected between two points, locate it by regula falsi
        (Illinois variant) on the p-component of the tangent along the
        corrector hyperplane family of the step, and insert the located point
        (``is_fold=True``) into the branch.
    store_tangents : bool, default False
        Keep the tangents of all points in :attr:`ContinuationResult.tangents`
        (memory ``n_points * (n+1)``).
    max_corrector_distance : float, default 1.0
        Branch-jumping guard: a converged corrector point farther than
        ``max_corrector_distance * ds`` (scaled norm) from the predictor is
        rejected and the step halved.  For a smooth branch the distance is
        ``O(curvature * ds**2)``.
    max_turn_angle : float, default 60.0
        Branch-jumping guard (degrees): a step whose tangent turns by more
        than this angle (scaled inner product) is rejected and halved.
        Kinks of a semismooth branch (e.g. contact onset), where the tangent
        jumps by a fixed angle however small the step, are recognised and
        accepted: after a geometric rejection, the halved step is accepted if
        its turn angle is still >= 75 % of the previous one while its
        predictor distance shrank to <= 75 % (and is <= 2 ds); a jump to a
        different branch does not show this distance scaling.  Both guards
        are also waived once halving would take the step below ``min_step``.
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

    def __post_init__(self) -> None:
        for name in ("step", "min_step", "max_step"):
            _check_positive(name, getattr(self, name))
        if self.min_step > self.max_step:
            raise ValueError(
                f"min_step must be <= max_step, got min_step={_show(self.min_step)}, max_step={_show(self.max_step)}"
            )
        if not self.min_step <= self.step <= self.max_step:
            raise ValueError(
                f"step must satisfy min_step <= step <= max_step, got step={_show(self.step)} "
                f"(min_step={_show(self.min_step)}, max_step={_show(self.max_step)})"
            )
        _check_int("max_points", self.max_points, 2)
        _check_int("target_iterations", self.target_iterations, 1)
        _check_positive("max_growth", self.max_growth)
        if self.max_growth < 1:
            raise ValueError(f"max_growth must be >= 1, got {_show(self.max_growth)}")
        if (isinstance(self.direction, (bool, np.bool_)) or not isinstance(self.direction, (int, np.integer))
                or self.direction not in (1, -1)):
            raise ValueError(f"direction must be +1 or -1, got {_show(self.direction)}")
        if self.x_scale is not None:
            if _is_real_number(self.x_scale):
                _check_positive("x_scale", self.x_scale)
            else:
                try:
                    xs = np.asarray(self.x_scale, dtype=float)
                except (TypeError, ValueError) as exc:
                    raise ValueError(
                        f"x_scale must be a positive number, a 1-D array of positive numbers or None, "
                        f"got {_show(self.x_scale)}"
                    ) from exc
                if xs.ndim != 1 or xs.size == 0 or not np.all(np.isfinite(xs)) or np.any(xs <= 0):
                    raise ValueError(
                        "x_scale must be a positive number, a 1-D array of positive finite numbers or None, "
                        f"got {_show(self.x_scale)}"
                    )
        if self.p_scale is not None:
            _check_positive("p_scale", self.p_scale)
        if not isinstance(self.newton, NewtonOptions):
            raise TypeError(f"newton must be a NewtonOptions instance, got {_show(self.newton)}")
        _check_callable("callback", self.callback)
        _check_bool("locate_folds", self.locate_folds)
        _check_bool("store_tangents", self.store_tangents)
        _check_positive("max_corrector_distance", self.max_corrector_distance)
        _check_positive("max_turn_angle", self.max_turn_angle)
        if self.max_turn_angle >= 180:
            raise ValueError(f"max_turn_angle must be in (0, 180) degrees, got {_show(self.max_turn_angle)}")


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
        def vector(name: str, size: int | None) -> np.ndarray:
            value = getattr(self, name)
            try:
                a = np.asarray(value, dtype=float)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"ContinuationState: {name} must be a real 1-D array, got {_show(value)}") from exc
            if a.ndim != 1 or a.size == 0 or (size is not None and a.size != size):
                want = f"({size},)" if size is not None else "a non-empty 1-D array"
                raise ValueError(f"ContinuationState: {name} has shape {a.shape}, expected {want}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"ContinuationState: {name} contains non-finite values (nan or inf)")
            if a.flags.writeable:
                a = a.copy()
                a.flags.writeable = False
            object.__setattr__(self, name, a)
            return a

        n = vector("x", None).size
        vector("tangent", n + 1)
        xs = vector("x_scale", n)
        if np.any(xs <= 0):
            raise ValueError(f"ContinuationState: x_scale must be positive, got {_show(self.x_scale)}")
        if not _is_real_number(self.p) or not math.isfinite(self.p):
            raise ValueError(f"ContinuationState: p must be a finite real number, got {_show(self.p)}")
        object.__setattr__(self, "p", float(self.p))
        for name in ("step", "p_scale"):
            _check_positive(f"ContinuationState.{name}", getattr(self, name))
            object.__setattr__(self, name, float(getattr(self, name)))
        for name in ("index", "n_newton", "n_rejected"):
            _check_int(f"ContinuationState.{name}", getattr(self, name), 0)
            object.__setattr__(self, name, int(getattr(self, name)))
        try:
            folds = tuple(int(i) for i in self.folds)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"ContinuationState: folds must be a sequence of point indices, got {_show(self.folds)}") from exc
        if any(not 0 <= i <= self.index for i in folds):
            raise ValueError(f"ContinuationState: folds must be indices in [0, index={self.index}], got {folds}")
        object.__setattr__(self, "folds", folds)
        if self.dp_sign not in (1, -1) or isinstance(self.dp_sign, (bool, np.bool_)):
            raise ValueError(f"ContinuationState: dp_sign must be +1 or -1, got {_show(self.dp_sign)}")
        object.__setattr__(self, "dp_sign", float(self.dp_sign))


@dataclass(frozen=True, kw_only=True, eq=False)
class ContinuationResult:
    """Traced branch returned by :func:`continuation`.

    Attributes
    ----------
    x : ndarray, shape (n_points, n)
    p : ndarray, shape (n_points,)
    nit : ndarray of int, shape (n_points,)
        Newton iterations per point (start point: initial correction).
    residual_norm : ndarray, shape (n_points,)
        ``norm(r(x_i, p_i), inf)``.
    converged : ndarray of bool, shape (n_points,)
        All ``True``: only converged points are accepted (kept for
        compatibility with callers that store rejected points).
    step : ndarray, shape (n_points,)
        Step that produced each point (0 for the start point).
    folds : tuple of int
        Indices of fold points (see :attr:`ContinuationPoint.is_fold`).
    tangents : ndarray of shape (n_points, n+1) or None
        Only with ``store_tangents=True``.
    success : bool
        ``True`` for statuses 0-3 (all returned points are valid solutions;
        the run ended at the span boundary, at ``max_points`` or by the
        callback), ``False`` for 4-6.
    status : int
        See :data:`STATUS_MESSAGES`: 0 reached ``p_span[1]``; 1 left through
        ``p_span[0]``; 2 ``max_points`` reached; 3 stopped by callback;
        4 step below ``min_step``; 5 initial correction failed; 6 initial
        tangent failed.
    message : str
    n_newton : int
        Total Newton iterations, including rejected steps, the initial
        correction, fold localisation and the end point.
    n_rejected : int
        Number of rejected steps.
    x_scale : ndarray, shape (n,)
        Scales of the unknowns used in the arclength norm.
    p_scale : float
        Scale of the parameter used in the arclength norm.
    first_index : int
        Branch index of the first returned point: 0, or ``start.index + 1``
        for a run resumed with ``start=`` (whose arrays hold only the new
        points, while ``folds`` and the counters cover the whole branch).
    """

    x: np.ndarray
    p: np.ndarray
    nit: np.ndarray
    residual_norm: np.ndarray
    converged: np.ndarray
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

    @property
    def n_points(self) -> int:
        """Number of points of the branch."""
        return int(self.p.shape[0])


# --------------------------------------------------------------------------- #
# bordered linear solver
# --------------------------------------------------------------------------- #
def bordered_matrix(J: Any, rp: np.ndarray, c: np.ndarray) -> Any:
    """``[[J, rp], [c^T]]`` as CSC if ``J`` is sparse, else dense (``c`` has length n + 1)."""
    n = J.shape[0]
    if _is_operator(J):  # a structured Jacobian borders itself
        return J.bordered(np.asarray(rp, dtype=float).reshape(n, 1), np.asarray(c[:n], dtype=float).reshape(1, n),
                          np.asarray(c[n:], dtype=float).reshape(1, 1))
    if sp.issparse(J):
        # assembled from COO triplets: same result as sp.bmat, ~3x cheaper
        Jc = sp.coo_matrix(J)
        ar = np.arange(n)
        rows = np.concatenate([Jc.row, ar, np.full(n + 1, n)])
        cols = np.concatenate([Jc.col, np.full(n, n), np.arange(n + 1)])
        data = np.concatenate([Jc.data.astype(float, copy=False), rp, c])
        return sp.csc_matrix((data, (rows, cols)), shape=(n + 1, n + 1))
    Jb = np.empty((n + 1, n + 1))
    Jb[:n, :n] = J
    Jb[:n, n] = rp
    Jb[n, :] = c
    return Jb


def bordered_solver(M: Any, h: np.ndarray) -> np.ndarray:
    r"""Solve the bordered system :math:`M z = h`, :math:`M = [[A, b], [c^T, d]]`.

    Default linear solver of the continuation corrector and tangent systems
    (used when ``NewtonOptions.linear_solver`` is ``None``).

    Dense ``M``: LAPACK LU of ``M``.  Sparse ``M``: block elimination with
    the sparse LU of ``A`` only,

    .. math::

        w = A^{-1} b,\quad \delta = d - c^{\mathsf T} w,\quad
        x_1 = A^{-1} f,\quad y = (g - c^{\mathsf T} x_1)/\delta,\quad
        x = x_1 - w\,y,

    followed by (up to three) steps of iterative refinement with the same
    block elimination, which makes it accurate near folds where ``A`` is
    nearly singular (Govaerts & Pryce 1990; Govaerts, *Numerical Methods for
    Bifurcations of Dynamical Equilibria*, SIAM 2000, ch. 3).  If ``A`` is
    exactly singular or the refined residual stays large, it falls back to a
    sparse LU of the whole ``M``.

    Why not always factorise ``M``: its last row ``c^T`` is dense, and
    SuperLU's partial pivoting may choose it as a pivot row when a diagonal
    of ``A`` is small, which fills the factors (measured: 50x more
    non-zeros, ``O(n^2)`` memory for large ``n``).
    """
    if _is_operator(M):  # structured: its own factorisation keeps the border in its dense part
        return M.factorize().solve(np.asarray(h, dtype=float))
    if not sp.issparse(M):
        return np.linalg.solve(np.asarray(M, dtype=float), h)
    M = sp.csc_matrix(M)
    n = M.shape[0] - 1
    h = np.asarray(h, dtype=float)
    try:
        lu = spla.splu(M[:n, :n].tocsc())
    except RuntimeError:
        return default_linear_solver(M, h)
    b = M[:n, n].toarray().ravel()
    c = M[n, :n].toarray().ravel()
    d = float(M[n, n])
    w = lu.solve(b)
    delta = d - float(c @ w)
    if not np.isfinite(delta) or delta == 0.0 or not np.all(np.isfinite(w)):
        return default_linear_solver(M, h)

    def eliminate(rhs: np.ndarray) -> np.ndarray:
        x1 = lu.solve(rhs[:n])
        y = (rhs[n] - float(c @ x1)) / delta
        return np.append(x1 - w * y, y)

    z = eliminate(h)
    scale = abs(M).sum(axis=1).max()  # ||M||_inf
    for _ in range(3):
        rho = h - M @ z
        tol = 1e2 * np.finfo(float).eps * (scale * np.max(np.abs(z)) + np.max(np.abs(h)))
        if np.max(np.abs(rho)) <= tol:
            return z
        z = z + eliminate(rho)
    rho = h - M @ z
    if np.all(np.isfinite(z)) and np.max(np.abs(rho)) <= 1e6 * tol:
        return z
    logger.debug("bordered block elimination inaccurate (|res|=%.2e); full LU of the bordered matrix",
                 np.max(np.abs(rho)))
    return default_linear_solver(M, h)


# --------------------------------------------------------------------------- #
# internal machinery
# --------------------------------------------------------------------------- #
class _Branch:
    """Evaluation of the problem, bordered matrices and scaled geometry."""

    def __init__(self, problem: Any, n: int, newton: NewtonOptions) -> None:
        self.problem = problem
        self.n = n
        self.newton = newton
        self.solve = newton.linear_solver if newton.linear_solver is not None else bordered_solver
        # corrector options: bordered systems use bordered_solver by default
        self.bordered_newton = (
            newton if newton.linear_solver is not None else dataclasses.replace(newton, linear_solver=bordered_solver)
        )
        self.w = np.ones(n + 1)  # weights of the scaled inner product, set later
        self.n_newton = 0

    # -- problem evaluation ------------------------------------------------ #
    def evaluate(self, x: np.ndarray, p: float) -> tuple[np.ndarray, Any, np.ndarray]:
        n = self.n
        out = self.problem.residual(x, float(p))
        try:
            r, J, rp = out
        except (TypeError, ValueError):
            raise ValueError("problem.residual(x, p) must return a triple (r, dr_dx, dr_dp)") from None
        r = np.asarray(r, dtype=float)
        if r.shape != (n,):
            raise ValueError(f"problem.residual returned r of shape {r.shape}, expected ({n},)")
        if sp.issparse(J) or _is_operator(J):
            if tuple(J.shape) != (n, n):
                raise ValueError(f"problem.residual returned dr_dx of shape {J.shape}, expected ({n}, {n})")
        else:
            J = np.asarray(J, dtype=float)
            if J.shape != (n, n):
                raise ValueError(f"problem.residual returned dr_dx of shape {J.shape}, expected ({n}, {n})")
        rp = rp.toarray() if sp.issparse(rp) else np.asarray(rp, dtype=float)
        if rp.size != n or (rp.ndim == 2 and 1 not in rp.shape) or rp.ndim > 2:
            raise ValueError(f"problem.residual returned dr_dp of shape {rp.shape}, expected ({n},)")
        return r, J, rp.reshape(n).astype(float, copy=False)

    # -- geometry ---------------------------------------------------------- #
    def dot(self, u: np.ndarray, v: np.ndarray) -> float:
        return float(np.sum(self.w * u * v))

    def norm(self, u: np.ndarray) -> float:
        return math.sqrt(max(self.dot(u, u), 0.0))

    # -- bordered systems -------------------------------------------------- #
    def border(self, J: Any, rp: np.ndarray, c: np.ndarray) -> Any:
        """``[[J, rp], [c^T]]`` (see :func:`bordered_matrix`)."""
        return bordered_matrix(J, rp, c)

    def tangent_from(self, Jb: Any) -> np.ndarray | None:
        """Unit tangent from a bordered matrix whose last row is ``c^T``.

        Solves ``Jb t = e_{n+1}`` (so ``c^T t = 1``), normalises in the scaled
        norm.  Returns ``None`` if the system is singular.
        """
        e = np.zeros(self.n + 1)
        e[-1] = 1.0
        try:
            t = np.asarray(self.solve(Jb, e), dtype=float).reshape(-1)
        except _LINSOLVE_ERRORS as exc:
            logger.debug("tangent solve failed: %s", exc)
            return None
        if t.shape != (self.n + 1,) or not np.all(np.isfinite(t)):
            return None
        nt = self.norm(t)
        if not np.isfinite(nt) or nt == 0.0:
            return None
        t = t / nt
        t.flags.writeable = False
        return t

    def tangent_at(self, x: np.ndarray, p: float, c: np.ndarray) -> np.ndarray | None:
        _, J, rp = self.evaluate(x, p)
        return self.tangent_from(self.border(J, rp, c))

    # -- solves ------------------------------------------------------------ #
    def solve_fixed_p(self, x_init: np.ndarray, p: float, options: NewtonOptions | None = None) -> NewtonResult:
        def fun(x: np.ndarray) -> tuple[np.ndarray, Any]:
            r, J, _ = self.evaluate(x, p)
            return r, J

        res = semismooth_newton(fun, x_init, options=options or self.newton)
        self.n_newton += res.nit
        return res

    def correct(self, y_pred: np.ndarray, c: np.ndarray) -> NewtonResult:
        """Corrector on the hyperplane ``c^T (y - y_pred) = 0``."""
        n = self.n

        def fun(y: np.ndarray) -> tuple[np.ndarray, Any]:
            r, J, rp = self.evaluate(y[:n], y[n])
            rb = np.empty(n + 1)
            rb[:n] = r
            rb[n] = float(c @ (y - y_pred))
            return rb, self.border(J, rp, c)

        res = semismooth_newton(fun, y_pred, options=self.bordered_newton)
        self.n_newton += res.nit
        return res


@dataclass
class _Pt:
    """Record of an accepted point (internal): y = (x, p), unit tangent t."""

    y: np.ndarray
    t: np.ndarray
    nit: int
    rnorm: float
    step: float


def _validate_span(p_span: Any) -> tuple[float, float]:
    try:
        p0, p1 = (float(v) for v in p_span)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"p_span must be a pair of finite numbers (p_start, p_end), got {_show(p_span)}") from exc
    if not (math.isfinite(p0) and math.isfinite(p1)) or p0 == p1:
        raise ValueError(
            f"p_span must be a pair of distinct finite numbers (p_start, p_end), got {_show(p_span)}"
        )
    if not math.isfinite((p1 - p0) ** 2) or (p1 - p0) ** 2 == 0.0:
        raise ValueError(f"p_span {_show(p_span)}: its width squared under- or overflows; rescale the parameter")
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
    3. Predictor ``y + ds t``; corrector: semismooth Newton on the bordered
       system ``[r(x, p); t^T S (y - y_pred)] = 0`` (sparse ``bmat`` if
       ``r_x`` is sparse, dense otherwise).
    4. Step control from the corrector iteration count; on corrector failure
       the step is halved and retried from the same point.  A converged
       point farther than ``max_corrector_distance * ds`` from the predictor,
       or whose tangent turns by more than ``max_turn_angle``, is also
       rejected (branch-jumping guard) unless the step is already minimal.
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
    span_sign = 1.0 if p_end > p_start else -1.0
    if start is not None:
        if not isinstance(start, ContinuationState):
            raise TypeError(f"start must be a ContinuationState (point.state of a callback) or None, got {type(start).__name__}")
        if x0 is not None:
            raise ValueError("continuation: pass either x0= (a new run) or start= (a resumed run), not both")
        if span_sign * (start.p - p_start) < 0 or span_sign * (start.p - p_end) > 0:
            raise ValueError(f"start.p = {start.p:g} lies outside p_span = ({p_start:g}, {p_end:g})")
        n = start.x.size
    else:
        if x0 is None:
            guess = getattr(problem, "initial_guess", None)
            if not callable(guess):
                raise TypeError("continuation: pass x0=, or give the problem a method initial_guess(p)")
            x0 = guess(p_start)
        x_init = _start_vector(x0)
        n = x_init.size
        if options.x_scale is not None and not _is_real_number(options.x_scale):
            if np.shape(options.x_scale) != (n,):
                raise ValueError(f"x_scale has shape {np.shape(options.x_scale)}, expected ({n},) matching x0")

    opt = options
    br = _Branch(problem, n, opt.newton)

    pts: list[_Pt] = []
    folds: list[int] = []
    n_rejected = 0
    # A resumed run keeps its start point as pts[0] (the previous point of the
    # first step) but does not return it: branch index of pts[k] is i0 + k.
    i0 = start.index if start is not None else 0
    skip = 1 if start is not None else 0

    def build(status: int, extra: str = "") -> ContinuationResult:
        msg = STATUS_MESSAGES[status] + (f": {extra}" if extra else "")
        out = pts[skip:]
        if out:
            X = np.array([q.y[:n] for q in out])
            P = np.array([q.y[n] for q in out])
            T = np.array([q.t for q in out]) if opt.store_tangents else None
        else:
            X = np.empty((0, n))
            P = np.empty(0)
            T = np.empty((0, n + 1)) if opt.store_tangents else None
        arrays = dict(
            x=X,
            p=P,
            nit=np.array([q.nit for q in out], dtype=int),
            residual_norm=np.array([q.rnorm for q in out], dtype=float),
            converged=np.ones(len(out), dtype=bool),
            step=np.array([q.step for q in out], dtype=float),
            tangents=T,
            x_scale=xs_arr,
        )
        for a in arrays.values():
            if a is not None:
                a.flags.writeable = False
        success = status <= 3
        (logger.info if success else logger.warning)(
            "continuation finished: %s (%d points, %d folds, %d Newton iterations, %d rejected steps)",
            msg, i0 + len(pts), len(folds), br.n_newton, n_rejected,
        )
        return ContinuationResult(
            folds=tuple(folds),
            success=success,
            status=status,
            message=msg,
            n_newton=br.n_newton,
            n_rejected=n_rejected,
            p_scale=ps,
            first_index=i0 + skip,
            **arrays,
        )

    # ---- 1. initial correction (or the state of a resumed run) ------------ #
    if start is None:
        init_opts = dataclasses.replace(opt.newton, max_iter=max(opt.newton.max_iter, _INITIAL_MAX_ITER))
        res0 = br.solve_fixed_p(x_init, p_start, init_opts)
        ps = float(opt.p_scale) if opt.p_scale is not None else abs(p_end - p_start)
        if not res0.success:
            xs_arr = np.ones(n) if opt.x_scale is None else np.broadcast_to(np.asarray(opt.x_scale, float), (n,)).copy()
            return build(5, f"Newton at p={p_start:g}: {res0.message}")
        x_start = np.array(res0.x)

        # ---- scaling ------------------------------------------------------- #
        if opt.x_scale is None:
            rms = float(np.sqrt(np.mean(x_start**2)))
            xs_arr = np.full(n, rms if rms > 0 and np.isfinite(rms) else 1.0)
        else:
            xs_arr = np.broadcast_to(np.asarray(opt.x_scale, dtype=float), (n,)).copy()
    else:
        xs_arr = np.array(start.x_scale)
        ps = start.p_scale
        br.n_newton = start.n_newton
        n_rejected = start.n_rejected
    xs_arr.flags.writeable = False  # shared by the result and every ContinuationState
    br.w = np.concatenate([1.0 / (n * xs_arr**2), [1.0 / ps**2]])
    last_sign = 0.0  # sign of dp/ds at the last point where it was non-zero (fold detection)

    def emit(q: _Pt, is_fold: bool, next_step: float | None) -> bool:
        """Append an accepted point; return False if the callback asks to stop.

        ``next_step``: the step the run takes from ``q``, or ``None`` if the
        run does not continue from ``q`` (inserted fold point, end point).
        """
        pts.append(q)
        idx = i0 + len(pts) - 1
        if is_fold:
            folds.append(idx)
        if idx % _LOG_EVERY == 0:
            logger.info("continuation: point %d p=%.6g step=%.3g nit=%d |r|=%.2e",
                        idx, q.y[n], q.step, q.nit, q.rnorm)
        if opt.callback is not None:
            xv = q.y[:n].copy()
            xv.flags.writeable = False
            state = None
            if next_step is not None:
                state = ContinuationState(
                    x=xv, p=float(q.y[n]), tangent=q.t, step=next_step, index=idx, folds=tuple(folds),
                    dp_sign=last_sign, x_scale=xs_arr, p_scale=ps, n_newton=br.n_newton, n_rejected=n_rejected,
                )
            cp = ContinuationPoint(x=xv, p=float(q.y[n]), tangent=q.t, nit=q.nit, residual_norm=q.rnorm,
                                   step=q.step, is_fold=is_fold, index=idx, state=state)
            if opt.callback(cp) is False:
                return False
        return True

    # ---- 2. initial tangent (or the start point of a resumed run) --------- #
    if start is None:
        e_p = np.zeros(n + 1)
        e_p[n] = 1.0
        y0 = np.append(x_start, p_start)
        t0 = br.tangent_at(x_start, p_start, e_p)
        first = _Pt(y=y0, t=t0 if t0 is not None else np.full(n + 1, np.nan), nit=res0.nit,
                    rnorm=res0.residual_norm, step=0.0)
        if t0 is None:
            pts.append(first)
            return build(6, f"r_x singular at the start point p={p_start:g} (start exactly at a fold?)")
        if np.sign(t0[n]) != opt.direction * span_sign:
            t0 = -t0
            t0.flags.writeable = False
            first.t = t0
        ds = float(opt.step)
        last_sign = float(np.sign(t0[n]))
        if not emit(first, False, ds):
            return build(3)
    else:
        pts.append(_Pt(y=np.append(start.x, start.p), t=start.tangent, nit=0, rnorm=math.nan, step=0.0))
        folds.extend(start.folds)
        ds = min(max(start.step, opt.min_step), opt.max_step)
        last_sign = start.dp_sign

    # ---- helpers for the main loop ---------------------------------------- #
    def crossed(p: float) -> float | None:
        """The span boundary that ``p`` lies beyond, if any."""
        if span_sign * (p - p_end) > 0:
            return p_end
        if span_sign * (p - p_start) < 0:
            return p_start
        return None

    def end_point(a: _Pt, y_far: np.ndarray, bound: float) -> tuple[_Pt, bool] | None:
        """Point exactly at ``p = bound`` from linear interpolation between ``a`` and ``y_far``."""
        pa, pf = a.y[n], y_far[n]
        theta = (bound - pa) / (pf - pa)
        y_lin = a.y + theta * (y_far - a.y)
        res = br.solve_fixed_p(y_lin[:n], bound)
        if not res.success:
            logger.debug("end point at p=%g failed: %s", bound, res.message)
            return None
        y_end = np.append(res.x, bound)
        chord = br.norm(y_far - a.y)
        if br.norm(y_end - y_lin) > opt.max_corrector_distance * max(chord, opt.min_step):
            logger.debug("end point at p=%g rejected: too far from the interpolation", bound)
            return None
        t_end = br.tangent_at(res.x, bound, br.w * a.t)
        if t_end is None:
            logger.warning("tangent at the end point p=%g is singular; using the previous tangent", bound)
            t_end = a.t
        fold = bool(np.sign(t_end[n]) * np.sign(a.t[n]) < 0)
        return _Pt(y=y_end, t=t_end, nit=res.nit, rnorm=res.residual_norm, step=br.norm(y_end - a.y)), fold

    def finish_at(a: _Pt, y_far: np.ndarray, bound: float) -> ContinuationResult | None:
        if a.y[n] == bound:  # already on the boundary (e.g. direction=-1 at the start)
            return build(0 if bound == p_end else 1)
        got = end_point(a, y_far, bound)
        if got is None:
            return None
        q, fold = got
        if fold:
            # record the point nearest to the fold (smaller |dp/ds|)
            if abs(q.t[n]) >= abs(a.t[n]):
                fold = False
                if not (folds and folds[-1] == i0 + len(pts) - 1):
                    folds.append(i0 + len(pts) - 1)
        emit(q, fold, None)
        return build(0 if bound == p_end else 1)

    def locate_fold(a: _Pt, ds: float, b: _Pt) -> _Pt | None:
        """Regula falsi (Illinois) on s -> dp/ds along the step family from ``a``."""
        c = br.w * a.t
        s_lo, g_lo = 0.0, a.t[n]
        s_hi, g_hi = ds, b.t[n]
        best: _Pt | None = None
        side = 0
        for _ in range(_FOLD_MAX_ITER):
            s = (s_lo * g_hi - s_hi * g_lo) / (g_hi - g_lo)
            if not (s_lo < s < s_hi):
                s = 0.5 * (s_lo + s_hi)
            res = br.correct(a.y + s * a.t, c)
            if not res.success:
                break
            t = br.tangent_from(res.jac)
            if t is None:
                break
            q = _Pt(y=np.array(res.x), t=t, nit=res.nit, rnorm=float(np.max(np.abs(res.fun[:n]))), step=s)
            if best is None or abs(t[n]) < abs(best.t[n]):
                best = q
            g = t[n]
            if abs(g) <= _FOLD_TOL or (s_hi - s_lo) <= 1e-12 * ds:
                break
            if np.sign(g) == np.sign(g_lo):
                s_lo, g_lo = s, g
                if side == -1:
                    g_hi *= 0.5
                side = -1
            else:
                s_hi, g_hi = s, g
                if side == 1:
                    g_lo *= 0.5
                side = 1
        return best

    # ---- 3. main loop ----------------------------------------------------- #
    just_rejected = False
    prev_geo: tuple[float, float] | None = None  # (angle, distance) of the last geometric rejection

    while True:
        if i0 + len(pts) >= opt.max_points:
            return build(2, f"{i0 + len(pts)} points, last p={pts[-1].y[n]:g}")
        a = pts[-1]

        def reject(reason: str) -> bool:
            """Halve the step; return False when it falls below min_step."""
            nonlocal ds, n_rejected, just_rejected
            n_rejected += 1
            just_rejected = True
            logger.debug("step ds=%.3g from p=%.6g rejected: %s", ds, a.y[n], reason)
            ds *= 0.5
            return ds >= opt.min_step

        y_pred = a.y + ds * a.t
        bound = crossed(y_pred[n])
        if bound is not None:
            out = finish_at(a, y_pred, bound)
            if out is not None:
                return out
            # the branch may turn back before the boundary: do a regular step

        c = br.w * a.t
        res = br.correct(y_pred, c)
        if not res.success:
            prev_geo = None
            if not reject(f"corrector failed: {res.message}"):
                return build(4, f"at p={a.y[n]:g} (last corrector: {res.message})")
            continue
        t_b = br.tangent_from(res.jac)
        if t_b is None:
            prev_geo = None
            if not reject("singular bordered system at the new point"):
                return build(4, f"at p={a.y[n]:g} (singular bordered system)")
            continue
        y_b = np.array(res.x)
        dist = br.norm(y_b - y_pred)
        angle = math.degrees(math.acos(max(-1.0, min(1.0, br.dot(a.t, t_b)))))
        geometric = None
        if dist > opt.max_corrector_distance * ds:
            geometric = f"corrector moved {dist:.3g} > {opt.max_corrector_distance:g}*ds from the predictor"
        elif angle > opt.max_turn_angle:
            geometric = f"tangent turned by {angle:.1f} deg"
        if geometric is not None:
            # A kink of a semismooth branch turns the tangent by a fixed angle
            # however small the step, with a predictor distance ~ ds; a smooth
            # turn has angle ~ ds and distance ~ ds**2; a jump to another
            # branch has a distance that does not shrink with ds.
            kink = (
                prev_geo is not None
                and angle >= _KINK_RATIO * prev_geo[0]
                and dist <= _KINK_RATIO * prev_geo[1]
                and dist <= _KINK_MAX_DISTANCE * ds
            )
            if kink:
                logger.info("continuation: accepting a kink of the branch at p=%.6g (%s)", y_b[n], geometric)
            elif 0.5 * ds >= opt.min_step:
                prev_geo = (angle, dist)
                reject(geometric)
                continue
            else:
                logger.info("accepting step at minimal step size despite: %s (kink of the branch?)", geometric)
        prev_geo = None

        b = _Pt(y=y_b, t=t_b, nit=res.nit, rnorm=float(np.max(np.abs(res.fun[:n]))), step=ds)
        bound = crossed(y_b[n])
        if bound is not None:
            out = finish_at(a, y_b, bound)
            if out is not None:
                return out
            if not reject(f"end point at p={bound:g} could not be computed"):
                return build(4, f"end point at p={bound:g} could not be computed")
            continue

        # ---- fold detection ----------------------------------------------- #
        sign_b = float(np.sign(t_b[n]))
        is_fold_b = False
        if sign_b != 0 and last_sign != 0 and sign_b != last_sign:
            located = None
            if opt.locate_folds and i0 + len(pts) + 2 <= opt.max_points:
                located = locate_fold(a, ds, b)
            if located is not None and crossed(located.y[n]) is not None:
                # the branch left the span between a and b (excursion through the
                # fold): stop on the boundary before the fold
                bound = crossed(located.y[n])
                logger.info("continuation: branch leaves the span through p=%g before a fold", bound)
                out = finish_at(a, located.y, bound)
                if out is not None:
                    return out
                if not reject(f"fold beyond p={bound:g}, but the end point could not be computed"):
                    return build(4, f"end point at p={bound:g} could not be computed")
                continue
            if located is not None:
                logger.info("continuation: fold located at p=%.8g", located.y[n])
                if not emit(located, True, None):
                    return build(3)
            elif abs(t_b[n]) <= abs(a.t[n]) or (folds and folds[-1] == i0 + len(pts) - 1):
                is_fold_b = True
            else:
                folds.append(i0 + len(pts) - 1)
            if located is None:
                logger.info("continuation: fold detected near p=%.8g", (b if is_fold_b else a).y[n])
        if sign_b != 0:
            last_sign = sign_b

        # ---- step control (before emitting b: its state carries the next step)
        nit = res.nit
        if nit < opt.target_iterations:
            factor = min(opt.max_growth, opt.target_iterations / max(nit, 1))
        elif nit > opt.target_iterations:
            factor = max(0.5, opt.target_iterations / nit)
        else:
            factor = 1.0
        if just_rejected:
            factor = min(factor, 1.0)
        just_rejected = False
        ds = min(max(ds * factor, opt.min_step), opt.max_step)
        if not emit(b, is_fold_b, ds):
            return build(3)
