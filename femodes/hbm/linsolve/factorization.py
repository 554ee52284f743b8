"""Discretise layer: the structured factorisation of an HBM Jacobian and its refined solve.

Interior blocks per harmonic (:mod:`.factors`), the dense Schur complement on the boundary
(:mod:`.schur`), one elimination pass (:mod:`.elimination`), then iterative refinement against
the true ``J`` (one matrix-vector product) if the residual is not at round-off; a block that
cannot be factorised (singular ``K`` of a free structure at harmonic 0, ``k w`` at an
eigenfrequency of the structure with its nonlinear DOFs held) raises :class:`~.blocks.StructureFailure`,
and an inaccurate solve falls back to a sparse direct LU of the assembled matrix.
"""

from __future__ import annotations

import logging

import numpy as np

from ...dynamic_stiffness import DynamicStiffness
from .assembled import AssembledFactorization, refinement_tolerance
from .elimination import BlockElimination
from .factors import LinearFactors
from .jacobian import HarmonicBlockJacobian
from .schur import SchurComplement, SchurLayout

__all__ = ["StructuredFactorization", "norm_bound"]

log = logging.getLogger(__name__)


def norm_bound(J: HarmonicBlockJacobian, F: LinearFactors) -> float:
    """``||J||_inf`` bound for the refinement test: the row sums of ``|K|, |M|, |C - xi M|`` in
    the dynamic stiffness at the top harmonic, the nonlinear part and the borders."""
    s = J.system
    h = s.h
    s_max = h.n_harmonics * J.omega / h.subharmonic
    pat = F.pat
    if pat.abs_row_sums is None:  # once per system (the pattern is cached there)
        pat.abs_row_sums = tuple(s.stiffness.abs_row_sums())
    lin = DynamicStiffness(*pat.abs_row_sums).abs_bound(s_max, J.xi)
    rN = float(abs(J.N).sum(axis=1).max()) if J.N.nnz else 0.0
    return (abs(J.scale) * (lin + rN) + float(np.abs(J.U).sum(axis=1).max(initial=0.0))
            + float(np.abs(np.hstack([J.V, J.D])).sum(axis=1).max(initial=0.0)))


class StructuredFactorization:
    """Structured LU of a :class:`HarmonicBlockJacobian` (interior blocks + dense Schur complement).

    ``F`` (default: the system's factors at ``(J.omega, J.xi)``) may be factors at another
    frequency ``w0``: this is then the exact factorisation of ``P``, ``J`` with its linear part
    ``S(w0)`` instead of ``S(w)`` (``exact`` False), which :class:`~.reuse.ReusedFactorization`
    iterates on; :meth:`solve` here refines against ``J`` either way.
    """

    def __init__(self, J: HarmonicBlockJacobian, threads: int | None = None, F: LinearFactors | None = None):
        self.J = J
        self.threads = threads
        self.F = F = J.system.linear.factors(J.omega, J.xi, threads) if F is None else F
        self.exact = F.omega == J.omega and F.xi == J.xi
        # the exact factorisation, once a reused solve's safeguard built it
        self.refactored: StructuredFactorization | None = None
        self.layout = layout = SchurLayout.of(J, F)
        # the leaner solve path (the interior solutions of the border columns kept, W = Z_II^-1
        # Z_Ib used where kept): without modal damping, and with it when every harmonic kept W and
        # the pieces of Z_II^-1 U_I (LowRankSplit.apply_x)
        self.lean = not layout.mr or bool(F.pat.perm.size and all(blk.Xm is not None for blk in F.blocks))
        self.schur = SchurComplement(J, F, layout, self.lean)
        self.norm_bound = norm_bound(J, F)
        self._solve = BlockElimination(J, F, layout, self.schur, self.lean)

    @property
    def ymodal(self):
        """The elimination of the modal coordinates (``lowrank.ModalElimination``), or None."""
        return self.schur.ymodal

    def solve(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=float)
        one_d = b.ndim == 1
        B = b.reshape(b.shape[0], -1)
        x = self.refactored.solve(B) if self.refactored is not None else self._solve_to_tolerance(B)
        return x[:, 0] if one_d else x

    def _tolerance(self, x: np.ndarray, scale_b: float) -> float:
        return refinement_tolerance(self.norm_bound, x, scale_b)

    def _solve_to_tolerance(self, B: np.ndarray) -> np.ndarray:
        x = self._solve(B)
        # iterative refinement against the true J: the interior blocks can be ill-conditioned near
        # an eigenfrequency of the structure with its nonlinear DOFs held (Higham 2002, ch. 12)
        J = self.J
        scale_b = np.max(np.abs(B)) or 1.0
        for _ in range(3):
            res = B - J.matvec(x)
            tol = self._tolerance(x, scale_b)
            if np.max(np.abs(res)) <= tol:
                break
            x = x + self._solve(res)
        else:
            res = B - J.matvec(x)
            if not np.all(np.isfinite(x)) or np.max(np.abs(res)) > 1e6 * tol:
                log.debug("structured solve inaccurate (|res| = %.2e); the assembled matrix",
                          float(np.max(np.abs(res))))
                x = AssembledFactorization(J).solve(B)
        return x
