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
        converge at the precision the data allow. 0 disables it. The product
        ``|J| |x|`` costs about a residual's linear part; within one solve it
        is formed again only when ``norm(r, inf)`` is within
        :data:`TOLERANCE_RECHECK` times the last tolerance computed or
        ``norm(x, inf)`` has more than doubled since.
    rtol_x : float, default 0.0
        Relative-to-the-iterate convergence: also converged when
        ``norm(r, inf) <= rtol_x * norm(x, inf)``, for residuals in the units
        of ``x`` (e.g. the impulse balance of a time step, whose unknowns are
        the impulses: :mod:`femodes.time` uses 1e-13).  Cheaper than the
        ``rtol`` backward-error test (no ``|J| |x|`` product), which matters
        for thousands of tiny systems.  0 disables it.
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
    accept_factor : float, default 0.0
        Tolerance of last resort: when the iteration stops without convergence
        (status 1, ``max_iter`` reached, or 2, no progress), the returned
        iterate still counts as converged (status 0; the message says so and
        why the iteration stopped) if ``norm(r, inf) <= accept_factor * tol``
        with the convergence tolerance ``tol = max(atol, rtol_x * norm(x,
        inf), rtol * norm(|J| |x|, inf))``.  For callers whose tight
        tolerance sits near the round-off floor of some of their problems and
        who accept a looser residual there rather than a failure (the local
        problems of :mod:`femodes.time`, 1e4: converged to 1e-13, accepted at
        1e-9).  ``0`` disables it.
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
