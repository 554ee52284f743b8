"""Options and result of :func:`~femodes.solvers.newton.semismooth_newton`: :class:`NewtonOptions`, :class:`NewtonResult`.

:class:`NewtonOptions` holds the tolerances, the line search, watchdog and stagnation settings and
the linear solver, validated at construction; :class:`NewtonResult` is the scipy-style result
(``x, success, status, message, nit``) with the residual history. Both are re-exported by
:mod:`femodes.solvers.newton` and :mod:`femodes.solvers`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable

import numpy as np

from .checks import check_bool, check_callable, check_int, check_nonnegative, check_positive, show

__all__ = ["NewtonOptions", "NewtonResult"]


@dataclass(frozen=True, kw_only=True)
class NewtonOptions:
    """Options of :func:`semismooth_newton` (defaults and their measurements: :doc:`/guide/contact`).

    Parameters
    ----------
    atol : float, default 1e-10
        Converged when ``norm(r, inf) <= atol``; absolute, so the caller scales the residual.
    rtol : float, default 1e-14
        Also converged when ``norm(r, inf) <= rtol * norm(|J| |x|, inf)`` (componentwise backward
        error, Oettli-Prager style), for badly conditioned FE systems. 0 disables it.
    rtol_x : float, default 0.0
        Also converged when ``norm(r, inf) <= rtol_x * norm(x, inf)`` (:mod:`femodes.time`: 1e-13). 0: off.
    xtol : float, default 1e-12
        Round-off floor: also converged after a full step with ``norm(dx, inf) <= xtol * (1 + norm(x,
        inf))`` and ``norm(r, inf) <= sqrt(atol)``; a negligible step above that counts as a stall.
    max_iter : int, default 30
        Maximum number of iterations, one linear solve each (discarded watchdog steps count).
    line_search : bool, default True
        Armijo backtracking (constant 1e-4 [DS96]_, non-monotone [GLL86]_) on ``0.5 ||r||_2^2``, trials
        ``1, 1/2, ...`` down to ``min_alpha``; if none passes, the smallest merit is taken (a stall).
        ``False``: always the full step.
    min_alpha : float, default 1e-4
        Smallest trial step length, ``0 < min_alpha <= 1``.
    nonmonotone_memory : int, default 1
        Number of previous merit values over which the reference is taken (1: monotone Armijo).
    watchdog : int, default 3
        Untested full steps from a watch point (Chamberlain et al. 1982); if none passes the test
        relative to it, the iteration returns there and backtracks. ``0``: plain line search.
    max_stall : int, default 3
        Stop with status 2 after this many consecutive stalls (failed line search or negligible step).
    stagnation_window : int, default 10
        Stop with status 2 when the smallest residual norm has not dropped by 1 % in this many steps. 0: off.
    accept_factor : float, default 0.0
        On status 1 or 2, still return status 0 (the message says why) if ``norm(r, inf) <=
        accept_factor * tol``, ``tol`` the convergence tolerance. ``0`` disables it.
    linear_solver : callable or None
        ``linear_solver(A, b) -> y`` for a dense or sparse ``A``; raising ``LinAlgError``, ``RuntimeError``
        or ``ArithmeticError`` (or non-finite values) gives status 3. ``None``: :func:`default_linear_solver`.
    callback : callable or None
        ``callback(iteration, x, residual_norm)`` after the start and every step (return value ignored).
    """

    atol: float = 1e-10
    rtol: float = 1e-14
    rtol_x: float = 0.0
    xtol: float = 1e-12
    max_iter: int = 30
    line_search: bool = True
    min_alpha: float = 1e-4
    nonmonotone_memory: int = 1
    watchdog: int = 3
    max_stall: int = 3
    stagnation_window: int = 10
    accept_factor: float = 0.0
    linear_solver: Callable[[Any, np.ndarray], np.ndarray] | None = None
    callback: Callable[[int, np.ndarray, float], Any] | None = None

    def __post_init__(self) -> None:
        check_positive("atol", self.atol)
        check_nonnegative("rtol", self.rtol)
        check_nonnegative("rtol_x", self.rtol_x)
        check_positive("xtol", self.xtol)
        check_int("max_iter", self.max_iter, 1)
        check_bool("line_search", self.line_search)
        check_positive("min_alpha", self.min_alpha)
        if self.min_alpha > 1:
            raise ValueError(f"min_alpha must be in (0, 1], got {show(self.min_alpha)}")
        check_int("nonmonotone_memory", self.nonmonotone_memory, 1)
        check_int("watchdog", self.watchdog, 0)
        check_int("max_stall", self.max_stall, 1)
        check_int("stagnation_window", self.stagnation_window, 0)
        check_nonnegative("accept_factor", self.accept_factor)
        check_callable("linear_solver", self.linear_solver)
        check_callable("callback", self.callback)


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
        0 converged (or accepted by ``NewtonOptions.accept_factor``); 1
        ``max_iter`` reached; 2 line search stalled / no progress; 3 singular
        or non-finite linear solve, or non-finite residual / Jacobian.
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
