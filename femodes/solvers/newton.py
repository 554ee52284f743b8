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

This module holds :func:`semismooth_newton`, its iteration and line search; the options and
result are in :mod:`femodes.solvers.newton_types`, the default linear solver and the norms in
:mod:`femodes.solvers.newton_linalg` (both re-exported here).

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
from dataclasses import dataclass
from typing import Any
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from .checks import LINSOLVE_ERRORS, is_operator, start_vector
from .newton_linalg import F64, all_finite, default_linear_solver, jacobian_finite, max_abs, prepare_jacobian
from .newton_types import NewtonOptions, NewtonResult

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


#: Within one solve, the tolerance ``max(atol, rtol_x |x|, rtol |J| |x|)`` is computed again only
#: when the residual norm is at most this factor times the last one computed or ``norm(x, inf)``
#: has more than doubled since: otherwise the product cannot have grown enough for the residual to
#: pass (the seed's forced case: the tolerance is atol at every iterate). Skipping it there saved
#: 134 of 260 products on the seed's curve at H = 20. Only a "not converged" is decided without
#: the product.
TOLERANCE_RECHECK = 16.0


def _tolerance(atol: float, rtol: float, J, x, rtol_x: float = 0.0) -> float:
    """``max(atol, rtol_x ||x||max_abs, rtol || |J| |x| ||max_abs)``: absolute, relative to the iterate or
    backward-error tolerance."""
    if rtol_x:
        atol = max(atol, rtol_x * max_abs(x))
    if not rtol:
        return atol
    try:
        ax = np.abs(x)
        if is_operator(J):
            ref = J.abs_matvec(ax)
        else:
            ref = (abs(J) @ ax) if sp.issparse(J) else (np.abs(J) @ ax)
        ref = float(np.max(np.abs(ref))) if np.size(ref) else 0.0
    except Exception:  # pragma: no cover - advisory only
        return atol
    return max(atol, rtol * ref) if math.isfinite(ref) else atol


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
    if type(x0) is np.ndarray and x0.dtype is F64 and x0.ndim == 1 and x0.size and all_finite(x0):
        x = x0.copy()  # what start_vector returns, without its generic conversion
    else:
        x = start_vector(x0)
    return _Iteration(fun, x, options).run()


class _Stop(Exception):
    """End of the iteration with ``status`` after ``nit`` steps (``use_best``: return the iterate
    with the smallest residual if it is better than the last one)."""

    def __init__(self, status: int, message: str, nit: int, use_best: bool) -> None:
        super().__init__(message)
        self.status, self.message, self.nit, self.use_best = status, message, nit, use_best


@dataclass(slots=True)
class _Step:
    """A step taken: ``x = x_from + alpha * dx`` with ``r(x)``, ``J(x)``; ``ok`` is False when the
    line search failed down to ``min_alpha`` (the best trial was taken anyway)."""

    alpha: float
    dx: np.ndarray
    x: np.ndarray
    r: np.ndarray
    J: Any
    ok: bool
    kind: str  # for the log: "full", "relaxed", "backtracked", "line search failed"


class _Watchdog:
    """Watch points of the non-monotone stabilisation (Grippo, Lampariello & Lucidi 1991).

    "Watch points" are iterates that passed the sufficient-decrease test; from a watch point up
    to ``watchdog`` full Newton steps are taken without any test.  As soon as an iterate passes
    the non-monotone Armijo test relative to the watch point, it becomes the new watch point; if
    none does, the iteration returns to the watch point and backtracks along its direction.
    """

    __slots__ = ("merits", "x", "dx", "relaxed", "budget", "memory", "on")

    def __init__(self, x: np.ndarray, r: np.ndarray, options: NewtonOptions) -> None:
        self.merits = [0.5 * float(r @ r)]  # merit values of the watch points
        self.x = x  # current watch point
        self.dx: np.ndarray | None = None  # Newton direction at the watch point
        self.relaxed = 0  # relaxed steps taken since the watch point
        self.budget = options.watchdog
        self.memory = options.nonmonotone_memory
        self.on = options.watchdog > 0  # off after a failed relaxed phase until a full step passes the test

    def new_direction(self, dx: np.ndarray) -> None:
        """Record ``dx`` as the watch point's direction if the iterate is the watch point."""
        if self.relaxed == 0:
            self.dx = dx

    def references(self) -> tuple[float, float]:
        """Merit at the watch point, and the non-monotone reference: the largest merit of the
        last ``nonmonotone_memory`` watch points."""
        phi = self.merits[-1]
        return phi, (phi if self.memory == 1 else max(self.merits[-self.memory:]))

    def may_relax(self) -> bool:
        return self.on and self.relaxed < self.budget

    def move_to(self, x: np.ndarray, phi: float) -> None:
        """``x`` (merit ``phi``) becomes the watch point."""
        self.x, self.relaxed = x, 0
        self.merits.append(phi)


def _backtrack(evaluate: Callable, x0: np.ndarray, dx: np.ndarray, phi0: float, phi_ref: float, alpha: float,
               min_alpha: float):
    """Non-monotone Armijo backtracking [GLL86]_ from ``x0`` along ``dx``, trials ``alpha, alpha/2, ...``
    down to ``min_alpha``.

    Returns ``(accepted, alpha, x, r, J, phi)``: the first trial that passes the test, or
    (``accepted`` False) the trial with the smallest merit, with its merit ``phi``; ``None`` if
    every trial residual was non-finite.
    """
    slope = -2.0 * phi0  # d/dalpha phi(x + alpha dx) at 0 for an exact Newton step
    trial_best = None
    while True:
        x_try = x0 + alpha * dx
        r_try, J_try = evaluate(x_try)
        phi_try = 0.5 * float(r_try @ r_try) if all_finite(r_try) else math.inf
        if math.isfinite(phi_try):  # a Python float
            if phi_try <= phi_ref + _ARMIJO_SIGMA * alpha * slope:
                return True, alpha, x_try, r_try, J_try, phi_try
            if trial_best is None or phi_try < trial_best[0]:
                trial_best = (phi_try, alpha, x_try, r_try, J_try)
        if alpha <= min_alpha:
            break
        # plain halving: quadratic interpolation of phi(alpha) is misled by
        # the kinks of a semismooth merit; a non-finite trial is cut harder.
        alpha = max(0.5 * alpha if math.isfinite(phi_try) else 0.1 * alpha, min_alpha)
    if trial_best is None:
        return None
    return (False,) + trial_best[1:] + trial_best[:1]


def _converged_message(rnorm: float) -> str:
    return f"converged: residual norm {rnorm:.3e} <= max(atol, rtol |J||x|)"


class _Iteration:
    """One run of :func:`semismooth_newton`: current and best iterates, watchdog, stall counters.

    The methods are the parts of an iteration: Newton direction, globalised step (relaxed
    watchdog step or backtracking line search), acceptance, stopping tests; they end the run by
    raising :class:`_Stop`, which :meth:`run` turns into the :class:`NewtonResult`.
    """

    def __init__(self, fun: Callable, x: np.ndarray, options: NewtonOptions) -> None:
        self.fun = fun
        self.options = options
        self.n = x.size
        self.solve = options.linear_solver if options.linear_solver is not None else default_linear_solver
        self.atol = float(options.atol)
        self.nfev = 0
        self.x = x
        self.r, self.J = self.evaluate(x)
        self.rnorm = max_abs(self.r)
        self.history = [self.rnorm]
        self.debug = logger.isEnabledFor(logging.DEBUG)
        # best (smallest residual) finite iterate, returned on failure
        self.best = (x.copy(), self.r, self.J, self.rnorm)
        self.best_it = 0  # iteration at which ``best`` last improved by >= 1 %
        self.stall = 0
        self._watchdog: _Watchdog | None = None
        self.tol_seen = (math.inf, 0.0)  # the last tolerance computed (converged) and |x| there

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, Any]:
        """``fun(x)`` with its output checked (and counted in ``nfev``)."""
        n = self.n
        self.nfev += 1
        out = self.fun(x)
        try:
            r_raw, J_raw = out
        except (TypeError, ValueError):
            raise ValueError("fun must return a pair (r, J)") from None
        r = r_raw if type(r_raw) is np.ndarray and r_raw.dtype is F64 else np.asarray(r_raw, dtype=float)
        if r.shape != (n,):
            raise ValueError(
                f"fun returned a residual of shape {r.shape}, expected ({n},) matching x of shape ({n},)"
            )
        return r, prepare_jacobian(J_raw, n)

    def run(self) -> NewtonResult:
        try:
            self.start()
            for it in range(1, self.options.max_iter + 1):
                step = self.step(it, self.direction(it))
                step_norm = self.accept(it, step)
                self.stopping_tests(it, step, step_norm)
            raise _Stop(
                1,
                f"max_iter={self.options.max_iter} reached without convergence "
                f"(residual norm {self.rnorm:.3e} > atol={self.atol:g})",
                self.options.max_iter,
                True,
            )
        except _Stop as stop:
            return self.result(stop)

    def start(self) -> None:
        """Report ``x0``; stop if it is non-finite or already converged; set up the watchdog."""
        if self.options.callback is not None:
            self.options.callback(0, self.x.copy(), self.rnorm)
        if self.debug:
            logger.debug("newton it=0 |r|=%.3e", self.rnorm)
        if not math.isfinite(self.rnorm):
            raise _Stop(3, "non-finite residual at x0", 0, False)
        if self.rnorm > self.atol and not jacobian_finite(self.J):
            raise _Stop(3, "non-finite Jacobian at x0", 0, False)
        if self.converged(self.rnorm):
            raise _Stop(0, _converged_message(self.rnorm), 0, False)
        self._watchdog = _Watchdog(self.x, self.r, self.options)

    def converged(self, rnorm: float) -> bool:
        """``rnorm <= max(atol, rtol_x |x|, rtol |J||x|)`` at the current iterate (the products only
        when ``atol`` alone does not decide)."""
        opt = self.options
        if rnorm <= self.atol:
            return True
        if not (opt.rtol or opt.rtol_x):
            return False
        xnorm = max_abs(self.x)
        if rnorm > TOLERANCE_RECHECK * self.tol_seen[0] and xnorm <= 2.0 * self.tol_seen[1]:
            return False
        tol = _tolerance(self.atol, opt.rtol, self.J, self.x, opt.rtol_x)
        self.tol_seen = (tol, xnorm)
        return rnorm <= tol

    @property
    def watchdog(self) -> _Watchdog:
        """The watchdog of the run (set up by the start)."""
        if self._watchdog is None:
            raise RuntimeError("semismooth_newton: the run has not started")
        return self._watchdog

    def direction(self, it: int) -> np.ndarray:
        """Newton direction ``dx = -J^{-1} r`` at the current iterate."""
        try:
            sol = self.solve(self.J, self.r)
        except LINSOLVE_ERRORS as exc:
            raise _Stop(3, f"singular or failed linear solve at iteration {it}: {exc}", it - 1, True) from exc
        if type(sol) is np.ndarray and sol.dtype is F64 and sol.ndim == 1:
            dx = -sol
        else:
            dx = -np.asarray(sol, dtype=float).reshape(-1)
        if dx.shape != (self.n,):
            raise ValueError(f"linear_solver returned shape {np.shape(sol)}, expected ({self.n},)")
        if not all_finite(dx):
            raise _Stop(3, f"non-finite Newton step at iteration {it} (singular Jacobian?)", it - 1, True)
        self.watchdog.new_direction(dx)
        return dx

    def step(self, it: int, dx: np.ndarray) -> _Step:
        """The full step (``line_search=False``), a relaxed watchdog step, or a backtracking line
        search from the watch point."""
        if not self.options.line_search:
            x_new = self.x + dx
            r_new, J_new = self.evaluate(x_new)
            if not all_finite(r_new):
                raise _Stop(3, f"non-finite residual after step {it}", it - 1, True)
            return _Step(1.0, dx, x_new, r_new, J_new, ok=True, kind="full")
        phi_w, phi_ref = self.watchdog.references()
        alpha0 = 1.0  # ordinary line search from the current (watch) point
        if self.watchdog.may_relax():
            relaxed = self.relaxed_step(dx, phi_w, phi_ref)
            if relaxed is not None:
                return relaxed
            alpha0 = 0.5  # the full step from the watch point has been tried
        return self.backtrack_from_watch(it, phi_w, phi_ref, alpha0)

    def relaxed_step(self, dx: np.ndarray, phi_w: float, phi_ref: float) -> _Step | None:
        """Unchecked full step; ``None`` when the iteration must return to the watch point."""
        wd = self.watchdog
        x_new = self.x + dx
        r_new, J_new = self.evaluate(x_new)
        if all_finite(r_new):
            wd.relaxed += 1
            phi_new = 0.5 * float(r_new @ r_new)
            if phi_new <= phi_ref - _ARMIJO_SIGMA * 2.0 * phi_w:
                # sufficient decrease w.r.t. the watch point: new watch point
                wd.move_to(x_new, phi_new)
                return _Step(1.0, dx, x_new, r_new, J_new, ok=True, kind="full")
            if wd.relaxed < wd.budget:
                return _Step(1.0, dx, x_new, r_new, J_new, ok=True, kind="relaxed")
            # budget exhausted
        wd.on = False  # until a full step passes the line search again
        return None

    def backtrack_from_watch(self, it: int, phi_w: float, phi_ref: float, alpha0: float) -> _Step:
        """Line search along the watch point's direction; its result is the new watch point."""
        wd = self.watchdog
        dx = wd.dx
        if dx is None:  # a direction is always recorded at the watch point before a step
            raise RuntimeError("semismooth_newton: line search without a direction at the watch point")
        out = _backtrack(self.evaluate, wd.x, dx, phi_w, phi_ref, alpha0, self.options.min_alpha)
        if out is None:
            raise _Stop(3, f"non-finite residual at all line-search trials of step {it}", it - 1, True)
        ok, alpha, x_new, r_new, J_new, phi_new = out
        if ok and alpha == 1.0 and self.options.watchdog > 0:
            wd.on = True  # full Newton steps work again: re-enable relaxed steps
        wd.move_to(x_new, phi_new)
        return _Step(alpha, dx, x_new, r_new, J_new, ok=ok, kind="backtracked" if ok else "line search failed")

    def accept(self, it: int, step: _Step) -> float:
        """Move to the step's point, update the best iterate; return the step length (inf-norm)."""
        step_norm = step.alpha * max_abs(step.dx)
        self.x, self.r, self.J = step.x, step.r, step.J
        self.rnorm = max_abs(self.r)
        self.history.append(self.rnorm)
        if self.rnorm < self.best[3]:
            if self.rnorm <= _NO_PROGRESS_FACTOR * self.best[3]:
                self.best_it = it
            self.best = (self.x, self.r, self.J, self.rnorm)
        if self.debug:
            logger.debug("newton it=%d |r|=%.3e alpha=%.3g |dx|=%.3e (%s)",
                         it, self.rnorm, step.alpha, step_norm, step.kind)
        if self.options.callback is not None:
            self.options.callback(it, self.x.copy(), self.rnorm)
        return step_norm

    def stopping_tests(self, it: int, step: _Step, step_norm: float) -> None:
        """Convergence (residual, or negligible full step on the round-off floor) and failure
        (non-finite Jacobian, stalls, stagnation) tests after step ``it``."""
        opt, rnorm = self.options, self.rnorm
        if rnorm > self.atol and not jacobian_finite(self.J):
            raise _Stop(3, f"non-finite Jacobian after step {it}", it, True)
        if self.converged(rnorm):
            raise _Stop(0, _converged_message(rnorm), it, False)
        small_step = step_norm <= opt.xtol * (1.0 + max_abs(self.x))
        if small_step and step.alpha == 1.0 and rnorm <= math.sqrt(self.atol):
            raise _Stop(0, f"converged: full step {step_norm:.3e} below xtol*(1+|x|) with residual "
                           f"{rnorm:.3e} <= sqrt(atol)", it, False)
        self.stall = self.stall + 1 if small_step or not step.ok else 0
        if self.stall >= opt.max_stall:
            why = "negligible steps" if small_step else "line search failed down to min_alpha"
            raise _Stop(2, f"no progress: {why} in {self.stall} consecutive iterations (residual norm {rnorm:.3e})",
                        it, True)
        if opt.stagnation_window and it - self.best_it >= opt.stagnation_window:
            raise _Stop(2, f"no progress: smallest residual norm {self.best[3]:.3e} not reduced by 1 % in "
                           f"{opt.stagnation_window} iterations (local minimum of ||r|| or cycling?)", it, True)

    def result(self, stop: _Stop) -> NewtonResult:
        """The result of a stopped run: the last iterate, or the best one (``stop.use_best``)."""
        message = stop.message
        if stop.use_best and self.best[3] < self.rnorm:
            xb, rb, Jb, nb = self.best
            message += f"; returning the iterate with the smallest residual norm ({nb:.3e})"
        else:
            xb, rb, Jb, nb = self.x, self.r, self.J, self.rnorm
        status, opt = stop.status, self.options
        if status in (1, 2) and opt.accept_factor > 0:
            tol = _tolerance(self.atol, opt.rtol, Jb, xb, opt.rtol_x)
            if nb <= opt.accept_factor * tol:
                status = 0
                message = (f"converged (accepted): residual norm {nb:.3e} <= accept_factor * max(atol, rtol_x |x|, "
                           f"rtol |J||x|) = {opt.accept_factor * tol:.3e}; the iteration stopped on: {message}")
        xb = np.array(xb, dtype=float)
        rb = np.array(rb, dtype=float)
        xb.flags.writeable = False
        rb.flags.writeable = False
        if self.debug:
            logger.debug("semismooth_newton: %s (nit=%d, |r|=%.3e, nfev=%d)", message, stop.nit, nb, self.nfev)
        return NewtonResult(
            x=xb,
            success=status == 0,
            status=status,
            message=message,
            nit=stop.nit,
            fun=rb,
            residual_norm=float(nb),
            nfev=self.nfev,
            history=tuple(self.history),
            jac=Jb,
        )
