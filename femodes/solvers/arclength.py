r"""The problem as pseudo-arclength continuation sees it: residual, scaled geometry, bordered solves.

:class:`ArclengthSystem` wraps any object with ``residual(x, p) -> (r, dr_dx, dr_dp)`` and gives
the tracer of :mod:`femodes.solvers.continuation` what it needs at a point ``y = (x, p)``:

* the scaled inner product :math:`\langle u, v\rangle_S = \sum_i w_i u_i v_i` with
  :math:`w = (1/(n s_x^2), 1/s_p^2)` (see the module docstring of
  :mod:`~femodes.solvers.continuation`) and its norm;
* the unit tangent from a bordered matrix :math:`[[r_x, r_p], [c^{\mathsf T}]]\,t = e_{n+1}`;
* the corrector, semismooth Newton on :math:`[r(x, p);\ c^{\mathsf T}(y - y_{\mathrm{pred}})] = 0`,
  and Newton in ``x`` at fixed ``p`` (start and end points);

and counts the Newton iterations of all of them.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from .bordered import bordered_matrix
from .checks import LINSOLVE_ERRORS, is_operator
from .newton import NewtonOptions, NewtonResult, semismooth_newton

__all__ = ["ArclengthSystem"]

#: A corrector past its deadline must have reduced the residual of the predictor by this factor.
_DEADLINE_CONTRACTION = 0.5

logger = logging.getLogger(__name__)


class ArclengthSystem:
    """Evaluation of ``problem``, bordered systems and the scaled geometry of ``y = (x, p)``.

    Parameters
    ----------
    problem : object
        Has ``residual(x, p) -> (r, dr_dx, dr_dp)``.
    n : int
        Number of unknowns ``x``.
    newton : NewtonOptions
        Options of every Newton solve.  If ``newton.linear_solver`` is given it also solves the
        bordered systems, otherwise ``bordered_solver`` does.
    bordered_solver : callable
        Default solver ``(M, h) -> z`` of the bordered systems.

    Attributes
    ----------
    w : ndarray, shape (n+1,)
        Weights of the scaled inner product (ones until :meth:`set_scales`).
    n_newton : int
        Newton iterations of all solves so far.
    """

    def __init__(self, problem: Any, n: int, newton: NewtonOptions,
                 bordered_solver: Callable[[Any, np.ndarray], np.ndarray]) -> None:
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
        """``(r, dr_dx, dr_dp)`` at ``(x, p)``, shapes checked (``dr_dx`` kept sparse or structured)."""
        n = self.n
        out = self.problem.residual(x, float(p))
        try:
            r, J, rp = out
        except (TypeError, ValueError):
            raise ValueError("problem.residual(x, p) must return a triple (r, dr_dx, dr_dp)") from None
        r = np.asarray(r, dtype=float)
        if r.shape != (n,):
            raise ValueError(f"problem.residual returned r of shape {r.shape}, expected ({n},)")
        if sp.issparse(J) or is_operator(J):
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
    def set_scales(self, x_scale: np.ndarray, p_scale: float) -> None:
        """Weights ``w = (1/(n x_scale**2), 1/p_scale**2)`` of the scaled inner product."""
        self.w = np.concatenate([1.0 / (self.n * x_scale**2), [1.0 / p_scale**2]])

    def dot(self, u: np.ndarray, v: np.ndarray) -> float:
        return float(np.sum(self.w * u * v))

    def norm(self, u: np.ndarray) -> float:
        return math.sqrt(max(self.dot(u, u), 0.0))

    # -- bordered systems -------------------------------------------------- #
    def border(self, J: Any, rp: np.ndarray, c: np.ndarray) -> Any:
        """``[[J, rp], [c^T]]`` (see :func:`~femodes.solvers.bordered.bordered_matrix`)."""
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
        except LINSOLVE_ERRORS as exc:
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
        """Unit tangent at ``(x, p)`` with the border row ``c`` (``None`` if singular)."""
        _, J, rp = self.evaluate(x, p)
        return self.tangent_from(self.border(J, rp, c))

    # -- solves ------------------------------------------------------------ #
    def solve_fixed_p(self, x_init: np.ndarray, p: float, options: NewtonOptions | None = None) -> NewtonResult:
        """Newton in ``x`` at fixed ``p`` from ``x_init``."""
        def fun(x: np.ndarray) -> tuple[np.ndarray, Any]:
            r, J, _ = self.evaluate(x, p)
            return r, J

        res = semismooth_newton(fun, x_init, options=options or self.newton)
        self.n_newton += res.nit
        return res

    def correct(self, y_pred: np.ndarray, c: np.ndarray, deadline: int | None = None) -> NewtonResult:
        """Corrector on the hyperplane ``c^T (y - y_pred) = 0``.

        ``deadline``: abandon the corrector (a failed result, status 2) when the residual after
        that many iterations, or more, is above half the residual at the predictor (see
        ``ContinuationOptions.corrector_deadline``); ``None``: run to ``max_iter``.
        """
        n = self.n

        def fun(y: np.ndarray) -> tuple[np.ndarray, Any]:
            r, J, rp = self.evaluate(y[:n], y[n])
            rb = np.empty(n + 1)
            rb[:n] = r
            rb[n] = float(c @ (y - y_pred))
            return rb, self.border(J, rp, c)

        options = self.bordered_newton
        if deadline is not None:
            options = dataclasses.replace(options, callback=_Deadline(deadline, options.callback))
        try:
            res = semismooth_newton(fun, y_pred, options=options)
        except _Abandoned as stop:
            res = stop.result()
        self.n_newton += res.nit
        return res


class _Abandoned(Exception):
    """Raised from the corrector's Newton callback to abandon a corrector that does not contract."""

    def __init__(self, it: int, x: np.ndarray, history: list[float]) -> None:
        super().__init__(it)
        self.it, self.x, self.history = it, x, history

    def result(self) -> NewtonResult:
        """The failed :class:`NewtonResult` of the abandoned corrector: its last iterate, whose
        residual vector is not kept (``fun`` is NaN; the tracer only reads the message)."""
        r0, rk = self.history[0], self.history[-1]
        return NewtonResult(
            x=self.x, success=False, status=2,
            message=f"abandoned: residual {rk:.3e} after {self.it} iterations above half of {r0:.3e} at the predictor",
            nit=self.it, fun=np.full(self.x.size, np.nan), residual_norm=rk, nfev=self.it + 1,
            history=tuple(self.history), jac=None,
        )


class _Deadline:
    """Newton callback: raise :class:`_Abandoned` when ``|r_k| > |r_0| / 2`` at an iteration
    ``k >= deadline`` (after calling the user's callback, if any)."""

    def __init__(self, deadline: int, user: Callable | None) -> None:
        self.deadline, self.user = deadline, user
        self.history: list[float] = []

    def __call__(self, it: int, x: np.ndarray, rnorm: float) -> Any:
        if self.user is not None:
            self.user(it, x, rnorm)
        self.history.append(rnorm)
        if it >= self.deadline and not rnorm <= _DEADLINE_CONTRACTION * self.history[0]:
            raise _Abandoned(it, x, self.history)
