"""Discretise layer: GMRES preconditioned by the factors of a nearby frequency (``BlockSolver(reuse=True)``
on sparse-direct harmonic blocks).

:class:`~.reuse.ReusedFactorization` iterates ``x <- x + P^-1 (b - J x)``, where ``P`` is the
Jacobian with its linear part at the frequency ``w0`` of the factors. That pays where a
factorisation costs a few solves (band LU of line meshes). On 2-D and 3-D meshes the harmonic
blocks go to a sparse direct back-end and one factorisation costs what tens to hundreds of solves
cost, while ``P^-1 J - I`` has a few large eigenvalues (the modes of the interior near ``k w``,
where ``Z_II(w)^-1`` changes fastest) among many small ones: the stationary iteration then
contracts slowly (1.9e4-DOF P2 box, 1 % frequency offset: 16 passes to 1e-12), and GMRES removes
those few eigenvalues in a few more iterations (Saad 2003, *Iterative Methods for Sparse Linear
Systems*, sec. 6.11 and 9.3: right preconditioning, the residual of the true system minimised).

Each GMRES iteration is one elimination pass with the factors of ``P`` and the product
``J z = v - (P - J) z`` for ``z = P^-1 v`` (``P - J = s (S(w0) - S(w))`` on the displacement rows:
two sparse products, :meth:`~.reuse.ReusedFactorization._residual_after`). A solve is accepted by
the backward-error test of the exact path on the true residual ``b - J x``, after GMRES has
driven its residual to a hundredth of that test (:data:`TARGET`), or to its round-off floor. The budget is measured, not modelled: the
passes that cost what building the factors cost (CPU time, :attr:`LinearFactors.cpu_s`) or
``max_passes``; past it the factors are rebuilt at ``w`` and the exact path solves. A solve that
took more than half the budget makes the next Jacobian be factorised afresh (the next offset
from ``w0`` is likely larger still).
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np
import scipy.linalg as sla

from .reuse import ReusedFactorization

__all__ = ["KrylovReusedFactorization"]

log = logging.getLogger(__name__)

#: Arnoldi vectors kept before GMRES restarts (memory: this many vectors of the system size, twice).
RESTART = 40
#: A GMRES cycle runs until its residual is this fraction of the exact path's backward-error test
#: (``64 eps (||J|| |x| + |b|)``, ``refinement_tolerance``): a backward error below one eps, as
#: small as a direct solve's, so that the solution agrees with the exact path's to its round-off
#: (the stationary iteration needed a forward test for that, ``ReusedFactorization``).
TARGET = 0.01


class KrylovReusedFactorization(ReusedFactorization):
    """The factorisation of ``P`` (factors at ``w0 != J.omega``) solving ``J x = b`` by right-
    preconditioned GMRES (module docstring); refactorises through ``solver`` past its budget."""

    def _budget(self, pass_cpu: float) -> int:
        solver = self.solver
        if solver.max_passes is not None:
            return solver.max_passes
        build = getattr(self.F, "cpu_s", None)
        if not build or pass_cpu <= 0.0:
            return solver.passes_budget(self)
        return max(2, int(build / pass_cpu))

    def _jz(self, v: np.ndarray, z: np.ndarray) -> np.ndarray:
        """``J z`` for ``z = P^-1 v``: ``v - (P - J) z`` (or the product itself with modal damping)."""
        if self.layout.mr:
            return self.J.matvec(z)
        return v - self._residual_after(v, z, z)

    def _solve_reused(self, B: np.ndarray) -> np.ndarray:
        solver, state, J = self.solver, self.state, self.J
        t0 = time.process_time()
        X = self._solve(B)
        budget = self._budget(time.process_time() - t0)
        passes = 1
        for j in range(B.shape[1]):
            x, used = self._gmres(B[:, j:j + 1], X[:, j:j + 1], budget - passes)
            passes += used
            if x is None:
                solver.record_reuse(state, self, passes, 0.0, ok=False)
                log.debug("reused factors (w0 = %.9g, w = %.9g): GMRES not converged in %d passes; refactorising",
                          self.F.omega, J.omega, passes)
                refactored = self.refactored = solver.fresh_factorization(J, self.threads, state)
                return refactored.solve(B)
            X[:, j:j + 1] = x
        solver.record_reuse(state, self, passes, 0.0, ok=True)
        if 2 * passes > budget:
            # the passes grow with the offset from w0 (measured, 1.9e4-DOF box: 13, 17, 20 at 1, 2,
            # 3 %): past half the budget the next Jacobian is factorised afresh and becomes the base
            state.F = None
        return X

    def _gmres(self, b: np.ndarray, x: np.ndarray, budget: int):
        """One column from the first pass ``x``: ``(x, passes)`` accepted, or ``(None, passes)``
        past ``budget`` passes.

        Restarted cycles until the true residual ``b - J x`` passes the exact path's
        backward-error test; each cycle runs to :data:`TARGET` times that test (in the 2-norm, which
        bounds the max-norm of the test) or until the residual estimate stops falling (the
        round-off floor of ``J x``)."""
        J = self.J
        scale_b = float(np.max(np.abs(b))) or 1.0
        passes = 0
        while True:
            r = b - J.matvec(x)
            tol = self._tolerance(x, scale_b)
            if float(np.max(np.abs(r))) <= tol:
                return x, passes
            beta = float(np.linalg.norm(r))
            m = min(RESTART, budget - passes)
            if m < 1 or not math.isfinite(beta):
                return None, passes
            V = np.zeros((r.shape[0], m + 1))
            Z = np.zeros((r.shape[0], m))
            Hs = np.zeros((m + 1, m))
            V[:, 0] = r[:, 0] / beta
            target, prev = TARGET * tol, beta
            for k in range(m):
                z = self._solve(V[:, k:k + 1])
                passes += 1
                Z[:, k] = z[:, 0]
                w = self._jz(V[:, k:k + 1], z)[:, 0]
                for _ in range(2):  # Gram-Schmidt, twice: orthogonal to round-off (Giraud et al. 2005)
                    h = V[:, :k + 1].T @ w
                    Hs[:k + 1, k] += h
                    w -= V[:, :k + 1] @ h
                Hs[k + 1, k] = float(np.linalg.norm(w))
                if Hs[k + 1, k] > 0.0:
                    V[:, k + 1] = w / Hs[k + 1, k]
                e1 = np.zeros(k + 2)
                e1[0] = beta
                y = sla.lstsq(Hs[:k + 2, :k + 1], e1, check_finite=False)[0]
                est = float(np.linalg.norm(e1 - Hs[:k + 2, :k + 1] @ y))
                if est <= target or Hs[k + 1, k] == 0.0 or (est <= tol and est > 0.5 * prev):
                    break
                prev = est
            x = x + Z[:, :k + 1] @ y[:, None]
