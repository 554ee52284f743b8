"""Discretise layer: solves with the per-harmonic factors of a nearby frequency (``BlockSolver(reuse=True)``).

A Jacobian at ``w`` close to the frequency ``w0`` of the last factors (``|w - w0| <=
reuse_window |w0|``) is solved with them: they are the exact factorisation of ``P``, the
Jacobian with its linear part ``S(w0)`` instead of ``S(w)`` (nonlinear part, borders and Schur
complement at the current point), and ``x <- x + P^-1 (b - J x)`` is iterated, the residual of a
pass being ``(P - J) d = s (S(w0) - S(w)) d`` (two sparse products,
:meth:`~femodes.dynamic_stiffness.CoefficientStiffness.change`). A solve is accepted by the
backward-error test of the exact path and a forward test (the next correction, predicted from
the contraction of the last two, below ``BlockSolverOptions.reuse_forward_tol``); when the
passes this predicts exceed what a refactorisation costs (:func:`budget_from_factors`), or the
contraction is slower than 1/2 (``k w`` crossing an eigenfrequency of the interior), the factors
are rebuilt at ``w`` and become the new base; the contraction per unit frequency offset is
remembered to skip attempts predicted to fail. The Jacobian used is thus the exact one to the
refinement tolerance: Newton's iterations and the branch do not change. It is off by default
because it did not pay on the bars of ``benchmarks/README_corrector.md``: a band LU of a line
mesh costs only 2-3 single-column band solves, and near the resonance ``P^-1 J`` departs from the
identity by ``q ~ 10-4000 |w - w0| / w0``, so the offsets of a corrector (1e-5-1e-3) need 3-8
passes; only the last corrector iterations and the tangent (offsets below 1e-6) are served in 2-3.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .factorization import StructuredFactorization
from .factors import LinearFactors
from .jacobian import HarmonicBlockJacobian
from .options import BlockSolverOptions

__all__ = ["ReuseState", "budget_from_factors", "ReusedFactorization"]

log = logging.getLogger(__name__)


class ReuseState:
    """What a ``BlockSolver`` remembers of one system: the factors it used last and the
    contraction per unit relative frequency offset measured by the last reused solve."""

    __slots__ = ("F", "rate", "__weakref__")

    def __init__(self):
        self.F = None
        self.rate = None


def budget_from_factors(F: LinearFactors, options: BlockSolverOptions) -> int:
    """Passes of a reused solve that cost what refactorising and one exact pass cost.

    Cost per harmonic block in single-column band solves (measured on tridiagonal blocks of 1e4
    DOFs, ``benchmarks/README_corrector.md``): refactorising ``reuse_lu_cost`` (band assembly,
    ``?gbtrf``, condensed stiffness) plus the condensation columns, ``0.45 + 0.55 n_b`` (one
    multi-column call); a pass one solve with ``W`` kept, two without, plus
    ``reuse_pass_overhead`` (products, Schur solve, residual update); the exact path's pass
    also checks ``J x`` (``reuse_matvec_cost``)."""
    pat = F.pat
    nb = pat.bdofs.size
    lu = options.reuse_lu_cost if pat.banded else options.reuse_lu_cost_sparse
    per_pass = (1.0 if F.keep_w else 2.0) + options.reuse_pass_overhead
    exact = lu + (0.45 + 0.55 * nb if nb else 0.0) + per_pass + options.reuse_matvec_cost
    return max(1, int(exact // per_pass))


class ReusedFactorization(StructuredFactorization):
    """The factorisation of ``P`` (factors ``F`` at ``w0 != J.omega``) solving ``J x = b`` by
    iteration (module docstring); ``solver`` (a ``BlockSolver``) and its ``state`` for this system
    record the contraction and refactorise when it is too slow."""

    def __init__(self, J: HarmonicBlockJacobian, threads: int | None, F: LinearFactors, solver, state: ReuseState):
        super().__init__(J, threads, F)
        self.solver, self.state = solver, state

    def solve(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=float)
        one_d = b.ndim == 1
        B = b.reshape(b.shape[0], -1)
        x = self.refactored.solve(B) if self.refactored is not None else self._solve_reused(B)
        return x[:, 0] if one_d else x

    def _solve_reused(self, B: np.ndarray) -> np.ndarray:
        """``J x = B`` with the factors of ``P`` (linear part at ``w0``): ``x <- x + P^-1 (B - J x)``.

        Converged when the backward-error test of the exact path holds *and* the next
        correction, predicted from the contraction ``q = |d_j| / |d_(j-1)|`` of the last two,
        is below ``reuse_forward_tol |x|``, or the corrections stopped shrinking (``q >= 1/2``
        after two of them: the round-off floor of an ill-conditioned ``J``, where the exact path's
        solution is no more accurate; Higham 2002, sec. 12.1). The residual test alone stops while
        the error in the directions that ``J`` nearly annihilates (the resonance being traced,
        where ``P^-1 J`` also departs most from the identity) is still ``~ q^j`` (measured:
        branch points off by 2.5e-8 in ``w`` on a 1e4-DOF bar, against 1e-10 between this solver
        and SuperLU). The accepted ``x`` is checked once against the true ``J``. When the passes
        predicted for convergence exceed the solver's budget, or ``q >= 1/2`` (``k w`` near an
        eigenfrequency of the interior, where ``Z_II(w)^-1`` changes fast), the factors are
        rebuilt at ``w`` and the exact path solves ``B`` from scratch."""
        solver, state = self.solver, self.state
        J = self.J
        scale_b = float(np.max(np.abs(B))) or 1.0
        budget = solver.passes_budget(self)
        eta = solver.options.reuse_forward_tol
        x = self._solve(B)
        d_prev = float(np.max(np.abs(x)))
        res = self._residual_after(B, x, x)
        passes, worst = 1, 0.0
        while passes < budget:
            d = self._solve(res)
            x = x + d
            passes += 1
            dn, xn = float(np.max(np.abs(d))), float(np.max(np.abs(x)))
            if not math.isfinite(dn):
                break
            q = dn / d_prev if d_prev > 0 else 0.0
            res = self._residual_after(B, x, d)
            rn = float(np.max(np.abs(res)))
            converged = q < 0.5 and q * dn <= eta * xn
            at_floor = q >= 0.5 and passes >= 3   # the corrections stopped shrinking: round-off
            if (converged or at_floor) and rn <= self._tolerance(x, scale_b):
                true = B - J.matvec(x)
                if float(np.max(np.abs(true))) <= self._tolerance(x, scale_b):
                    solver.record_reuse(state, self, passes, max(worst, q if converged else 0.0), ok=True)
                    return x
                res = true  # drift of the cheap residual: continue with the true one
            if q >= 0.5:
                break
            worst = max(worst, q)
            if q > 0 and passes + math.log(eta * xn / max(q * dn, 1e-300)) / math.log(q) > budget:
                break
            d_prev = dn
        solver.record_reuse(state, self, passes, worst, ok=False)
        log.debug("reused factors (w0 = %.9g, w = %.9g): contraction %.2e after %d passes; refactorising",
                  self.F.omega, J.omega, worst, passes)
        refactored = self.refactored = solver.fresh_factorization(J, self.threads, state)
        return refactored.solve(B)

    def _residual_after(self, B: np.ndarray, x: np.ndarray, d: np.ndarray) -> np.ndarray:
        """``B - J x`` after the pass that solved ``P d = r`` (``r`` the previous residual) and set
        ``x <- x + d``: ``(P - J) d = s (S(w0) - S(w)) d`` on the displacement rows, up to the
        round-off of the solve with ``P`` (two sparse products, no Jacobian product). With modal
        damping: ``B - J x`` itself."""
        J = self.J
        s = J.system
        if self.layout.mr:
            return B - J.matvec(x)
        out = np.zeros_like(d)
        Q = d[: s.nq].reshape(self.layout.nc, s.n, d.shape[1])
        out[: s.nq] = J.scale * s.stiffness.change(Q, self.F.omega, J.omega, J.xi)
        return out
