r"""Globalised semismooth Newton method for square nonlinear systems.

Solves :math:`r(x) = 0`, :math:`r:\mathbb{R}^n\to\mathbb{R}^n`, where ``r`` may
be only piecewise smooth (semismooth), e.g. because it contains the contact
complementarity function :math:`\lambda - \max(0, \lambda - c\,g) = 0`.  The
caller supplies, at every point, the residual and *one element* of the
generalized (Clarke / B-) Jacobian; the iteration is

.. math::

    J_k\,\Delta x_k = -r(x_k), \qquad x_{k+1} = x_k + \alpha_k\,\Delta x_k,

with :math:`\alpha_k` from a non-monotone backtracking line search on the
merit function :math:`\phi(x) = \tfrac12\|r(x)\|_2^2`.  Locally, for a
semismooth ``r`` with nonsingular generalized Jacobians, the full step is
accepted and convergence is superlinear (quadratic for strongly semismooth /
piecewise smooth ``r``; finite for piecewise linear ``r``) [QS93]_.

References
----------
.. [QS93] L. Qi and J. Sun, "A nonsmooth version of Newton's method",
   Math. Programming 58 (1993) 353-367.
.. [GLL86] L. Grippo, F. Lampariello and S. Lucidi, "A nonmonotone line search
   technique for Newton's method", SIAM J. Numer. Anal. 23 (1986) 707-716.
.. [GLL91] L. Grippo, F. Lampariello and S. Lucidi, "A class of nonmonotone
   stabilization methods in unconstrained optimization", Numer. Math. 59
   (1991) 779-805.
.. [CPLP82] R. M. Chamberlain, M. J. D. Powell, C. Lemarechal and H. C.
   Pedersen, "The watchdog technique for forcing convergence in algorithms
   for constrained optimization", Math. Programming Study 16 (1982) 1-17.
.. [DS96] J. E. Dennis and R. B. Schnabel, *Numerical Methods for
   Unconstrained Optimization and Nonlinear Equations*, SIAM (1996),
   section 6.3 (backtracking line search, Armijo constant 1e-4).
"""

from __future__ import annotations

import logging
import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = [
    "NewtonOptions",
    "NewtonResult",
    "semismooth_newton",
    "default_linear_solver",
]

logger = logging.getLogger(__name__)

#: Armijo sufficient-decrease constant (Dennis & Schnabel recommend 1e-4).
_ARMIJO_SIGMA = 1e-4

#: Stagnation test: progress means reducing the smallest residual norm by 1 %.
_NO_PROGRESS_FACTOR = 0.99

#: Exceptions of a linear solve that mean "singular / failed factorisation".
_LINSOLVE_ERRORS = (np.linalg.LinAlgError, RuntimeError, ArithmeticError)


# --------------------------------------------------------------------------- #
# option validation helpers (shared with continuation.py)
# --------------------------------------------------------------------------- #
def _show(value: Any) -> str:
    """Representation of ``value`` for error messages (numpy scalars unwrapped)."""
    if isinstance(value, np.generic):
        value = value.item()
    return repr(value)


def _is_real_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _check_positive(name: str, value: Any) -> None:
    if not _is_real_number(value) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {_show(value)}")


def _check_int(name: str, value: Any, minimum: int) -> None:
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be an integer >= {minimum}, got {_show(value)}")
    if value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {_show(value)}")


def _check_bool(name: str, value: Any) -> None:
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, got {_show(value)}")


def _check_callable(name: str, value: Any) -> None:
    if value is not None and not callable(value):
        raise TypeError(f"{name} must be callable or None, got {_show(value)}")


# --------------------------------------------------------------------------- #
# options / result
# --------------------------------------------------------------------------- #
def _tolerance(atol: float, rtol: float, J, x) -> float:
    """``max(atol, rtol * || |J| |x| ||_inf)``: absolute or backward-error tolerance."""
    if not rtol:
        return atol
    try:
        ax = np.abs(x)
        if _is_operator(J):
            ref = J.abs_matvec(ax)
        else:
            ref = (abs(J) @ ax) if sp.issparse(J) else (np.abs(J) @ ax)
        ref = float(np.max(np.abs(ref))) if np.size(ref) else 0.0
    except Exception:  # pragma: no cover - advisory only
        return atol
    return max(atol, rtol * ref) if math.isfinite(ref) else atol


@dataclass(frozen=True, kw_only=True)
class NewtonOptions:
    """Options of :func:`semismooth_newton`.

    Parameters
    ----------
    atol : float, default 1e-10
        Convergence when ``norm(r, inf) <= atol``.  The test is absolute: the
        residual is assumed to be scaled by the caller (e.g. nondimensional or
        divided by a reference force) so that ``atol`` is meaningful.
    rtol : float, default 1e-14
        Relative (backward-error) convergence: also converged when
        ``norm(r, inf) <= rtol * norm(|J| |x|, inf)``, i.e. the residual is
        round-off compared with the terms that make it up. Large, badly
        conditioned FE systems (a 1e4-DOF Hermite beam has stiffness entries
        ~1e11) cannot reach an absolute ``atol``; this test (Oettli-Prager style
        componentwise backward error, bounded by its max norm) lets them
        converge at the precision the data allow. 0 disables it.
    xtol : float, default 1e-12
        Secondary, round-off-floor convergence test: the iteration also stops
        with success when a *full* step (``alpha == 1``) was accepted with
        ``norm(dx, inf) <= xtol * (1 + norm(x, inf))`` **and** the new residual
        satisfies ``norm(r, inf) <= sqrt(atol)``.  This catches problems whose
        attainable residual is limited by round-off (large, badly conditioned
        systems) while still requiring a reasonably small residual.  A
        negligible step with a residual above ``sqrt(atol)`` counts as "no
        progress" (see ``max_stall``).
    max_iter : int, default 30
        Maximum number of iterations; each iteration performs one linear
        solve (a relaxed watchdog step that is later discarded counts).
    line_search : bool, default True
        Globalisation by non-monotone backtracking (Armijo) on the merit
        ``phi = 0.5 * ||r||_2^2`` [GLL86]_ with watchdog stabilisation
        (see ``watchdog``): a trial step ``alpha`` is accepted if
        ``phi(x + alpha dx) <= max(phi of the last nonmonotone_memory watch
        points) - 1e-4 * alpha * ||r(x)||_2^2`` (Armijo constant from
        [DS96]_).  The reference value is a maximum over recent iterates, so steps
        that cross a kink of a semismooth residual (where the merit may
        increase temporarily) are not rejected needlessly.  Trial steps are
        ``1, 1/2, 1/4, ...`` down to ``min_alpha`` (the last trial is exactly
        ``min_alpha``; a non-finite trial residual cuts the step by 10).
        Quadratic interpolation [DS96]_ is deliberately not used: the kinks
        of a semismooth merit mislead it (measured: up to 3x more iterations
        on a contact law).
        If no trial down to ``min_alpha`` satisfies the test, the trial with
        the *smallest merit* among those tried is accepted anyway and the
        iteration continues (at kinks, the generalized Newton direction need
        not be a descent direction, and a small step to the next smooth piece
        usually restores progress); this is counted as a stall.  With
        ``line_search=False`` the full step is always taken.
    min_alpha : float, default 1e-4
        Smallest trial step length, ``0 < min_alpha <= 1``.
    nonmonotone_memory : int, default 1 (monotone Armijo: with memory 5 the forced Duffing start at w = 0.5, H = 9, cycled; tests/test_hbm.py::test_monotone_line_search_default_starts_forced_duffing)
        Number of previous merit values over which the non-monotone reference
        is taken (1 gives the classical monotone Armijo rule).
    watchdog : int, default 3
        Non-monotone stabilisation by the watchdog technique (Chamberlain et
        al. 1982, combined with the non-monotone line search as in Grippo,
        Lampariello & Lucidi 1991): from a "watch point" (an iterate that
        passed the sufficient-decrease test) up to ``watchdog`` full Newton
        steps are taken without testing; the first iterate that satisfies the
        non-monotone Armijo test relative to the watch point becomes the new
        watch point.  If none does, the iteration returns to the watch point
        and backtracks along its Newton direction (from ``alpha = 1/2``);
        relaxed steps are then suspended until a full step passes the
        ordinary line search again.  Rationale: for contact laws the
        undamped semismooth Newton iteration is an active-set method that
        usually converges in a few steps, while the merit function
        ``0.5 ||r||^2`` (dominated by ``c * gap`` terms when the penalty-like
        constant ``c`` is large) can force tiny steps; measured on a spring
        chain with obstacles and ``c`` up to 1e3: 21/300 failures and up to
        30 iterations with ``watchdog=0``, 0/300 and at most 5 with
        ``watchdog=3``.  ``0`` gives the plain non-monotone line search.
    max_stall : int, default 3
        Number of *consecutive* stalled iterations (failed line search, or a
        negligible step without convergence) after which the iteration stops
        with status 2.
    stagnation_window : int, default 10
        The iteration also stops with status 2 when the smallest residual norm
        seen has not decreased by at least 1 % during this many iterations
        (e.g. convergence to a non-zero local minimum of ``||r||``, or
        cycling).  ``0`` disables the test (globalisation from far away on a
        very flat merit, e.g. ``arctan`` from ``x0 = 100``, may need it off).
    linear_solver : callable or None
        Strategy ``linear_solver(A, b) -> y`` returning the solution of
        ``A y = b`` for a dense ``ndarray`` or ``scipy.sparse`` ``A``.  Newton
        calls it as ``dx = -linear_solver(J, r)``.  It may raise
        ``numpy.linalg.LinAlgError``, ``RuntimeError`` or ``ArithmeticError``
        (or return non-finite values) to signal a singular matrix; this is
        reported as status 3.  ``None`` selects :func:`default_linear_solver`.
    callback : callable or None
        ``callback(iteration, x, residual_norm)`` called after the initial
        evaluation (``iteration == 0``) and after every Newton step; its
        return value is ignored.  ``x`` is a copy.
    """

    atol: float = 1e-10
    rtol: float = 1e-14
    xtol: float = 1e-12
    max_iter: int = 30
    line_search: bool = True
    min_alpha: float = 1e-4
    nonmonotone_memory: int = 1
    watchdog: int = 3
    max_stall: int = 3
    stagnation_window: int = 10
    linear_solver: Callable[[Any, np.ndarray], np.ndarray] | None = None
    callback: Callable[[int, np.ndarray, float], Any] | None = None

    def __post_init__(self) -> None:
        _check_positive("atol", self.atol)
        if not _is_real_number(self.rtol) or not math.isfinite(self.rtol) or self.rtol < 0:
            raise ValueError(f"rtol must be a finite number >= 0, got {self.rtol!r}")
        _check_positive("xtol", self.xtol)
        _check_int("max_iter", self.max_iter, 1)
        _check_bool("line_search", self.line_search)
        _check_positive("min_alpha", self.min_alpha)
        if self.min_alpha > 1:
            raise ValueError(f"min_alpha must be in (0, 1], got {_show(self.min_alpha)}")
        _check_int("nonmonotone_memory", self.nonmonotone_memory, 1)
        _check_int("watchdog", self.watchdog, 0)
        _check_int("max_stall", self.max_stall, 1)
        _check_int("stagnation_window", self.stagnation_window, 0)
        _check_callable("linear_solver", self.linear_solver)
        _check_callable("callback", self.callback)


@dataclass(frozen=True, kw_only=True, eq=False)
class NewtonResult:
    """Outcome of :func:`semismooth_newton` (field names follow ``scipy.optimize.OptimizeResult``).

    Attributes
    ----------
    x : ndarray, shape (n,)
        Final iterate.  On success, the converged point; on failure, the
        iterate with the smallest residual norm encountered.
    success : bool
        ``status == 0``.
    status : int
        0 converged; 1 ``max_iter`` reached; 2 line search stalled / no
        progress; 3 singular or non-finite linear solve, or non-finite
        residual / Jacobian.
    message : str
        Human-readable reason.
    nit : int
        Number of Newton steps taken (linear solves that led to a step).
    fun : ndarray, shape (n,)
        Residual ``r(x)``.
    residual_norm : float
        ``norm(fun, inf)``.
    nfev : int
        Number of calls of ``fun`` (including line-search trials).
    history : tuple of float
        Residual inf-norms of the accepted iterates, ``history[0]`` at ``x0``;
        ``len(history) == nit + 1``.
    jac : ndarray or sparse matrix or None
        The generalized Jacobian returned by ``fun`` at ``x`` (not part of the
        ``OptimizeResult`` convention; lets callers reuse it, e.g. for
        tangents in continuation).  ``None`` only if unavailable.
    """

    x: np.ndarray
    success: bool
    status: int
    message: str
    nit: int
    fun: np.ndarray
    residual_norm: float
    nfev: int
    history: tuple[float, ...]
    jac: Any = field(default=None, repr=False)


# --------------------------------------------------------------------------- #
# linear algebra
# --------------------------------------------------------------------------- #
def default_linear_solver(A: Any, b: np.ndarray) -> np.ndarray:
    """Solve ``A y = b`` with a direct method.

    Sparse ``A`` (any ``scipy.sparse`` format) is converted to CSC and factorised
    with :func:`scipy.sparse.linalg.splu` (SuperLU, COLAMD ordering); dense
    ``A`` uses :func:`numpy.linalg.solve` (LAPACK ``gesv``).  A structured
    operator (an object with ``shape``, ``matvec`` and ``factorize()``, such as
    the harmonic-block Jacobian of the HBM problems) solves itself with
    ``A.factorize().solve(b)``.  Exactly singular matrices raise
    ``RuntimeError`` (SuperLU) or ``numpy.linalg.LinAlgError``.
    """
    if _is_operator(A):
        return A.factorize().solve(b)
    if sp.issparse(A):
        A = sp.csc_matrix(A)
        if not np.issubdtype(A.dtype, np.inexact):
            A = A.astype(np.float64)
        return spla.splu(A).solve(np.asarray(b, dtype=np.result_type(A.dtype, b.dtype)))
    return np.linalg.solve(A, b)


def _start_vector(x0: Any) -> np.ndarray:
    """``x0`` as a fresh finite 1-D float array, or a ValueError naming ``x0``."""
    try:
        x = np.array(x0, dtype=float)  # copy
    except (TypeError, ValueError) as exc:
        raise ValueError(f"x0 must be a real 1-D array, got {_show(x0)}") from exc
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"x0 must be a non-empty 1-D array, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("x0 contains non-finite values (nan or inf)")
    return x


def _is_operator(J: Any) -> bool:
    """A structured Jacobian that factorises itself (duck typing: no import of femodes here)."""
    return callable(getattr(J, "factorize", None)) and callable(getattr(J, "matvec", None))


def _prepare_jacobian(J: Any, n: int) -> Any:
    """Validate shape; return dense ndarray or sparse matrix unchanged otherwise."""
    if sp.issparse(J) or _is_operator(J):
        if J.shape != (n, n):
            raise ValueError(
                f"fun returned a Jacobian of shape {J.shape}, expected ({n}, {n}) for x of shape ({n},)"
            )
        return J
    Jd = np.asarray(J, dtype=float)
    if Jd.shape != (n, n):
        raise ValueError(
            f"fun returned a Jacobian of shape {Jd.shape}, expected ({n}, {n}) for x of shape ({n},)"
        )
    return Jd


def _jacobian_finite(J: Any) -> bool:
    if _is_operator(J):
        return bool(J.all_finite()) if callable(getattr(J, "all_finite", None)) else True
    if sp.issparse(J):
        data = J.data if J.format in ("csr", "csc", "coo", "bsr", "dia") else J.tocoo().data
        return bool(np.all(np.isfinite(data)))
    return bool(np.all(np.isfinite(J)))


def _inf_norm(v: np.ndarray) -> float:
    return float(np.max(np.abs(v))) if v.size else 0.0


# --------------------------------------------------------------------------- #
# main routine
# --------------------------------------------------------------------------- #
def semismooth_newton(
    fun: Callable[[np.ndarray], tuple[np.ndarray, Any]],
    x0: Any,
    *,
    options: NewtonOptions | None = None,
) -> NewtonResult:
    r"""Solve :math:`r(x) = 0` by a globalised semismooth Newton method.

    Iteration :math:`J_k \Delta x_k = -r(x_k)`, :math:`x_{k+1} = x_k +
    \alpha_k \Delta x_k` with :math:`J_k \in \partial r(x_k)` (any element of
    the generalized Jacobian) and :math:`\alpha_k` from the non-monotone
    Armijo line search of Grippo, Lampariello & Lucidi (1986) on
    :math:`\tfrac12\|r\|_2^2`, stabilised by the watchdog technique
    (Chamberlain et al. 1982; Grippo, Lampariello & Lucidi 1991) so that
    undamped steps, which make semismooth Newton an active-set method for
    contact laws, are tried first (see :class:`NewtonOptions`).

    Parameters
    ----------
    fun : callable
        ``fun(x) -> (r, J)`` with ``r`` of shape ``(n,)`` and ``J`` of shape
        ``(n, n)``, a dense ``ndarray`` or any ``scipy.sparse`` matrix/array.
        ``J`` must be evaluated at the same ``x`` as ``r``.
    x0 : array_like, shape (n,)
        Finite real starting point.
    options : NewtonOptions, optional
        Defaults to ``NewtonOptions()``.

    Returns
    -------
    NewtonResult
        Never raises on non-convergence: ``success``/``status``/``message``
        report it (status 0 converged, 1 ``max_iter`` reached, 2 line search
        stalled / no progress, 3 singular or non-finite linear solve /
        non-finite residual).

    Raises
    ------
    ValueError
        If ``x0`` is not a finite, non-empty 1-D array, or if ``fun`` returns
        arrays of the wrong shape (the message names the shapes).
    TypeError
        If ``options`` is not a :class:`NewtonOptions`.
    """
    if options is None:
        options = NewtonOptions()
    elif not isinstance(options, NewtonOptions):
        raise TypeError(f"options must be a NewtonOptions instance or None, got {type(options).__name__}")

    x = _start_vector(x0)
    n = x.size

    solve = options.linear_solver if options.linear_solver is not None else default_linear_solver
    atol = float(options.atol)
    loose_atol = math.sqrt(atol)
    nfev = 0

    def evaluate(xv: np.ndarray) -> tuple[np.ndarray, Any]:
        nonlocal nfev
        nfev += 1
        out = fun(xv)
        try:
            r_raw, J_raw = out
        except (TypeError, ValueError):
            raise ValueError("fun must return a pair (r, J)") from None
        r = np.asarray(r_raw, dtype=float)
        if r.shape != (n,):
            raise ValueError(
                f"fun returned a residual of shape {r.shape}, expected ({n},) matching x of shape ({n},)"
            )
        return r, _prepare_jacobian(J_raw, n)

    r, J = evaluate(x)
    rnorm = _inf_norm(r)
    history = [rnorm]
    # best (smallest residual) finite iterate, returned on failure
    best = (x.copy(), r, J, rnorm)

    def finish(status: int, message: str, nit: int, use_best: bool) -> NewtonResult:
        if use_best and best[3] < rnorm:
            xb, rb, Jb, nb = best
            message += f"; returning the iterate with the smallest residual norm ({nb:.3e})"
        else:
            xb, rb, Jb, nb = x, r, J, rnorm
        xb = np.array(xb, dtype=float)
        rb = np.array(rb, dtype=float)
        xb.flags.writeable = False
        rb.flags.writeable = False
        logger.debug("semismooth_newton: %s (nit=%d, |r|=%.3e, nfev=%d)", message, nit, nb, nfev)
        return NewtonResult(
            x=xb,
            success=status == 0,
            status=status,
            message=message,
            nit=nit,
            fun=rb,
            residual_norm=float(nb),
            nfev=nfev,
            history=tuple(history),
            jac=Jb,
        )

    if options.callback is not None:
        options.callback(0, x.copy(), rnorm)
    logger.debug("newton it=0 |r|=%.3e", rnorm)

    if not np.isfinite(rnorm):
        return finish(3, "non-finite residual at x0", 0, use_best=False)
    if not _jacobian_finite(J) and rnorm > atol:
        return finish(3, "non-finite Jacobian at x0", 0, use_best=False)
    if rnorm <= _tolerance(atol, options.rtol, J, x):
        return finish(0, f"converged: residual norm {rnorm:.3e} <= max(atol, rtol |J||x|)", 0, use_best=False)

    # Non-monotone stabilisation (Grippo, Lampariello & Lucidi 1991): "watch
    # points" are iterates that passed the sufficient-decrease test; from a
    # watch point up to ``watchdog`` full Newton steps are taken without any
    # test.  As soon as an iterate passes the non-monotone Armijo test relative
    # to the watch point, it becomes the new watch point; if none does, the
    # iteration returns to the watch point and backtracks along its direction.
    watch_merits = [0.5 * float(r @ r)]  # merit values of the watch points
    watch = (x, r, J)  # current watch point
    watch_dx: np.ndarray | None = None  # Newton direction at the watch point
    relaxed = 0  # relaxed steps taken since the watch point
    watch_on = options.watchdog > 0  # off after a failed relaxed phase until a full step passes the test
    stall = 0
    best_it = 0  # iteration at which ``best`` last improved by >= 1 %

    def backtrack(x0_: np.ndarray, dx_: np.ndarray, phi0: float, phi_ref: float, alpha: float):
        """Non-monotone Armijo backtracking; returns (accepted?, alpha, x, r, J) or None if all non-finite."""
        slope = -2.0 * phi0  # d/dalpha phi(x + alpha dx) at 0 for an exact Newton step
        trial_best = None
        while True:
            x_try = x0_ + alpha * dx_
            r_try, J_try = evaluate(x_try)
            phi_try = 0.5 * float(r_try @ r_try) if np.all(np.isfinite(r_try)) else math.inf
            if np.isfinite(phi_try):
                if trial_best is None or phi_try < trial_best[0]:
                    trial_best = (phi_try, alpha, x_try, r_try, J_try)
                if phi_try <= phi_ref + _ARMIJO_SIGMA * alpha * slope:
                    return True, alpha, x_try, r_try, J_try
            if alpha <= options.min_alpha:
                break
            # plain halving: quadratic interpolation of phi(alpha) is misled by
            # the kinks of a semismooth merit; a non-finite trial is cut harder.
            alpha = max(0.5 * alpha if np.isfinite(phi_try) else 0.1 * alpha, options.min_alpha)
        if trial_best is None:
            return None
        return (False,) + trial_best[1:]

    for it in range(1, options.max_iter + 1):
        # ---- Newton direction -------------------------------------------- #
        try:
            sol = solve(J, r)
        except _LINSOLVE_ERRORS as exc:
            return finish(3, f"singular or failed linear solve at iteration {it}: {exc}", it - 1, True)
        dx = -np.asarray(sol, dtype=float).reshape(-1)
        if dx.shape != (n,):
            raise ValueError(f"linear_solver returned shape {np.shape(sol)}, expected ({n},)")
        if not np.all(np.isfinite(dx)):
            return finish(3, f"non-finite Newton step at iteration {it} (singular Jacobian?)", it - 1, True)
        if relaxed == 0:
            watch_dx = dx

        # ---- step ---------------------------------------------------------- #
        alpha = 1.0
        ls_ok = True
        kind = "full"
        if not options.line_search:
            x_new = x + dx
            r_new, J_new = evaluate(x_new)
            if not np.all(np.isfinite(r_new)):
                return finish(3, f"non-finite residual after step {it}", it - 1, True)
        else:
            phi_w = watch_merits[-1]
            phi_ref = max(watch_merits[-options.nonmonotone_memory:])
            back_to_watch = True
            if watch_on and relaxed < options.watchdog:
                # relaxed (unchecked) full step
                x_new = x + dx
                r_new, J_new = evaluate(x_new)
                if np.all(np.isfinite(r_new)):
                    back_to_watch = False
                    relaxed += 1
                    kind = "relaxed"
                    phi_new = 0.5 * float(r_new @ r_new)
                    if phi_new <= phi_ref - _ARMIJO_SIGMA * 2.0 * phi_w:
                        # sufficient decrease w.r.t. the watch point: new watch point
                        watch, relaxed = (x_new, r_new, J_new), 0
                        watch_merits.append(phi_new)
                        kind = "full"
                    elif relaxed >= options.watchdog:
                        back_to_watch = True  # budget exhausted
                if back_to_watch:
                    watch_on = False  # until a full step passes the line search again
                alpha0 = 0.5  # the full step from the watch point has been tried
            else:
                alpha0 = 1.0  # ordinary line search from the current (watch) point
            if back_to_watch:
                xw = watch[0]
                out = backtrack(xw, watch_dx, phi_w, phi_ref, alpha0)
                if out is None:
                    return finish(3, f"non-finite residual at all line-search trials of step {it}", it - 1, True)
                ls_ok, alpha, x_new, r_new, J_new = out
                if ls_ok and alpha == 1.0 and options.watchdog > 0:
                    watch_on = True  # full Newton steps work again: re-enable relaxed steps
                dx = watch_dx
                watch, relaxed = (x_new, r_new, J_new), 0
                watch_merits.append(0.5 * float(r_new @ r_new))
                kind = "backtracked" if ls_ok else "line search failed"

        step_norm = alpha * _inf_norm(dx)
        x, r, J = x_new, r_new, J_new
        rnorm = _inf_norm(r)
        history.append(rnorm)
        if rnorm < best[3]:
            if rnorm <= _NO_PROGRESS_FACTOR * best[3]:
                best_it = it
            best = (x, r, J, rnorm)
        logger.debug("newton it=%d |r|=%.3e alpha=%.3g |dx|=%.3e (%s)", it, rnorm, alpha, step_norm, kind)
        if options.callback is not None:
            options.callback(it, x.copy(), rnorm)

        # ---- convergence / failure tests --------------------------------- #
        if not _jacobian_finite(J) and rnorm > atol:
            return finish(3, f"non-finite Jacobian after step {it}", it, True)
        if rnorm <= _tolerance(atol, options.rtol, J, x):
            return finish(0, f"converged: residual norm {rnorm:.3e} <= max(atol, rtol |J||x|)", it, False)
        small_step = step_norm <= options.xtol * (1.0 + _inf_norm(x))
        if small_step and alpha == 1.0 and rnorm <= loose_atol:
            return finish(
                0,
                f"converged: full step {step_norm:.3e} below xtol*(1+|x|) with residual "
                f"{rnorm:.3e} <= sqrt(atol)",
                it,
                False,
            )
        if small_step or not ls_ok:
            stall += 1
        else:
            stall = 0
        if stall >= options.max_stall:
            why = "negligible steps" if small_step else "line search failed down to min_alpha"
            return finish(
                2,
                f"no progress: {why} in {stall} consecutive iterations (residual norm {rnorm:.3e})",
                it,
                True,
            )

        if options.stagnation_window and it - best_it >= options.stagnation_window:
            return finish(
                2,
                f"no progress: smallest residual norm {best[3]:.3e} not reduced by 1 % in "
                f"{options.stagnation_window} iterations (local minimum of ||r|| or cycling?)",
                it,
                True,
            )

    return finish(
        1,
        f"max_iter={options.max_iter} reached without convergence (residual norm {rnorm:.3e} > atol={atol:g})",
        options.max_iter,
        True,
    )
