"""Discretise layer: factorisations of the assembled HBM Jacobian (small systems, fallbacks, checks).

:class:`DenseFactorization`: LAPACK LU of the dense matrix, for small systems (and half-full ones,
``BlockSolverOptions.dense_fill``), with the displacements eliminated first where that is exact
and cheaper (:class:`ForceSchur`); :class:`AssembledFactorization`: SuperLU on the sparse matrix
(mid-size systems, the fallback of the structured solve, :class:`AssembledSolver`).
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
import scipy.linalg as sla

from ...sparse_direct import factorize
from .jacobian import HarmonicBlockJacobian
from .options import DEFAULT_OPTIONS, BlockSolverOptions

__all__ = ["refinement_tolerance", "DenseFactorization", "ForceSchur", "AssembledFactorization", "AssembledSolver"]

log = logging.getLogger(__name__)


def refinement_tolerance(norm: float, x: np.ndarray, scale_b: float) -> float:
    """The backward-error test of the refined solves (the structured factorisation,
    :class:`ForceSchur`): ``64 eps (||J|| max|x| + max|b|)`` with a bound ``norm`` of ``||J||``."""
    return 64 * np.finfo(float).eps * (norm * float(np.max(np.abs(x))) + scale_b)


class DenseFactorization:
    """LAPACK LU (partial pivoting) of the densely assembled matrix: for small systems the sparse
    machinery's per-call overhead (building CSR matrices, SuperLU's symbolic phase) is what a
    Newton step costs (measured: seed contact case, 83 unknowns, 4.3 of 5.0 ms per factorisation
    in assembling the sparse matrix). From ``options.schur_min_size`` unknowns on (half-full
    systems) the displacements are eliminated first when they can be (:class:`ForceSchur`)."""

    def __init__(self, J: HarmonicBlockJacobian, options: BlockSolverOptions = DEFAULT_OPTIONS):
        A = J.toarray()
        if not np.all(np.isfinite(A)):
            raise RuntimeError("matrix has non-finite entries")
        self.A = A
        self.schur = (ForceSchur.build(J, A, max_growth=options.schur_max_growth)
                      if A.shape[0] >= options.schur_min_size else None)
        self.lu: tuple | None = None
        if self.schur is None:
            self._factor()

    def _factor(self) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)  # zero pivots are checked below (and said)
            self.lu = lu = sla.lu_factor(self.A, check_finite=False)
        if np.any(np.diagonal(lu[0]) == 0.0):
            raise RuntimeError("Factor is exactly singular")

    def solve(self, b):
        b = np.asarray(b, dtype=float)
        if self.schur is not None:
            x = self.schur.solve(b)
            if x is not None:
                return x
            self.schur = None  # not accurate enough here: the plain LU from now on
            self._factor()
        return sla.lu_solve(self.lu, b, check_finite=False)


class ForceSchur:
    r"""Solve of a dense HBM Jacobian by eliminating the displacement coefficients first.

    Without nonlinear displacement-displacement terms (complementarity contacts only: the
    contact forces are unknowns of their own and the displacements enter only their rows), the
    displacement block of ``J`` is ``s S(w)``, block diagonal over harmonics (``n x n`` for the
    mean, ``2n x 2n`` for each ``(cos, sin)`` pair; Rayleigh, modal and EPMC damping all stay
    within a harmonic). With ``J = [[A, B], [C, D]]`` (``q`` first; forces and borders second),
    ``A^{-1}`` costs ``H`` small inverses, and the forces act on the displacements of their own
    coefficient only (``B = s (I x B_c)`` on the force columns), so the Schur complement
    ``D - C A^{-1} B`` needs ``O(H n^2 n_p)`` work for them plus one product for the border
    columns: the LU is of size ``n_p (2H + 1) + m`` instead of ``(n + n_p)(2H + 1) + m`` (a 1-DOF
    contact: half the size, an eighth of the work). Measured on the seed's 1-DOF contact at
    H = 160 (643 unknowns with the border): 5.9 ms per LU of the whole matrix, 2.3 ms for the
    elimination and the LU of the forces.

    Pivoting is only within the harmonic blocks and within the Schur complement, so no block may
    be near singular (``k w`` on an eigenfrequency of the undamped structure, as for an undamped
    nonlinear mode at low energy): if the Schur complement's entries grow by more than
    ``max_growth`` over those of the blocks, nothing is eliminated (:meth:`build` returns None),
    and a solve whose backward error after two refinement steps still exceeds the test of the
    structured solve is redone by the plain LU (:meth:`solve` returns None).
    """

    def __init__(self, A, nq, G0, G, Ainv0, Ainv, T):
        self.A, self.nq, self.G0, self.G = A, nq, G0, G
        self.Ainv0, self.Ainv = Ainv0, Ainv
        self._norm = None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)  # zero pivots are checked below
            self.lu = sla.lu_factor(T, check_finite=False)
        if np.any(np.diagonal(self.lu[0]) == 0.0):
            raise RuntimeError("Factor is exactly singular")

    @property
    def norm(self) -> float:
        """``||J||_inf`` (for the backward-error test; on first use)."""
        if self._norm is None:
            self._norm = float(np.abs(self.A).sum(axis=1).max())
        return self._norm

    @classmethod
    def build(cls, J: HarmonicBlockJacobian, A: np.ndarray, *,
              max_growth: float = DEFAULT_OPTIONS.schur_max_growth) -> ForceSchur | None:
        s = J.system
        nq, n, n_uc, h = s.nq, s.n, s.n_uc, s.h
        if not (n_uc and nq and h.n_harmonics):
            return None
        # rows of the displacements in N: only the forces of their own coefficient row (no
        # cubic or penalty terms, which couple displacements; B_c = the contacts' DOFs)
        N = J.N
        end = int(N.indptr[nq])
        cols = N.indices[:end]
        if end and (np.any(cols < nq) or np.any(np.repeat(np.arange(nq) // n, np.diff(N.indptr[: nq + 1]))
                                                   != (cols - nq) // n_uc)):
            return None
        H = h.n_harmonics
        k = np.arange(1, H + 1)
        rows = np.stack([h.layout.cos_rows(k), h.layout.sin_rows(k)], axis=1)  # (H, 2)
        G = (rows[:, :, None] * n + np.arange(n)).reshape(H, 2 * n)          # q positions
        P = (rows[:, :, None] * n_uc + np.arange(n_uc)).reshape(H, 2 * n_uc)  # force positions (- nq)
        G0, P0 = np.arange(n), np.arange(n_uc)
        A11 = A[G[:, :, None], G[:, None, :]]
        A0 = A[np.ix_(G0, G0)]
        try:
            Ainv, Ainv0 = np.linalg.inv(A11), np.linalg.inv(A0)
        except np.linalg.LinAlgError:
            return None
        C = A[nq:, :nq]
        T = A[nq:, nq:].copy()
        scale = max(float(np.abs(A11).max()), float(np.abs(A0).max()), float(np.abs(T).max()))
        # force columns, harmonic by harmonic: T[:, P_k] -= C[:, G_k] A_k^-1 B[G_k, P_k]
        Xk = Ainv @ A[G[:, :, None], nq + P[:, None, :]]                     # (H, 2n, 2n_uc)
        T[:, P] -= np.matmul(C[:, G].transpose(1, 0, 2), Xk).transpose(1, 0, 2)
        T[:, P0] -= C[:, G0] @ (Ainv0 @ A[np.ix_(G0, nq + P0)])
        if A.shape[1] > nq + s.np:  # border columns: dense
            T[:, s.np:] -= C @ cls._apply(Ainv0, Ainv, G0, G, A[:nq, nq + s.np:])
        if not float(np.abs(T).max()) <= max_growth * scale:  # also catches non-finite entries
            return None
        return cls(A, nq, G0, G, Ainv0, Ainv, T)

    @staticmethod
    def _apply(Ainv0, Ainv, G0, G, R: np.ndarray) -> np.ndarray:
        """``A^{-1} R`` for the displacement rows ``R`` (``(nq, k)``), block by block."""
        out = np.empty_like(R)
        out[G] = Ainv @ R[G]
        out[G0] = Ainv0 @ R[G0]
        return out

    def solve(self, b: np.ndarray) -> np.ndarray | None:
        B = b.reshape(b.shape[0], -1)
        x = self._solve(B)
        scale_b = float(np.max(np.abs(B))) or 1.0
        for step in range(3):  # the solve, then up to two refinement steps
            res = B - self.A @ x
            tol = refinement_tolerance(self.norm, x, scale_b)
            if np.max(np.abs(res)) <= tol:
                return x.reshape(b.shape)
            if step < 2:
                x = x + self._solve(res)
        log.debug("displacement elimination inaccurate (|res| = %.2e > %.2e); plain LU", float(np.max(np.abs(res))),
                  tol)
        return None

    def _solve(self, B: np.ndarray) -> np.ndarray:
        nq = self.nq
        A = self.A
        y = self._apply(self.Ainv0, self.Ainv, self.G0, self.G, B[:nq])
        x2 = sla.lu_solve(self.lu, B[nq:] - A[nq:, :nq] @ y, check_finite=False)
        x1 = self._apply(self.Ainv0, self.Ainv, self.G0, self.G, B[:nq] - A[:nq, nq:] @ x2)
        return np.concatenate([x1, x2])


class AssembledFactorization:
    """The sparse direct back-end in use (:func:`femodes.sparse_direct.factorize`: SuperLU below
    its 5000 rows, an unsymmetric MUMPS or PARDISO ``LU`` above) on the assembled matrix; with
    modal damping on the sparse augmented matrix ``[[J_sparse, s B], [I x U^T, -I]]``
    (:meth:`HarmonicBlockJacobian.augmented`), whose extra unknowns are the modal coordinates: the
    dense ``U diag(d) U^T`` is never assembled."""

    def __init__(self, J: HarmonicBlockJacobian):
        A = J.augmented()
        self.n = J.shape[0]
        self.extra = 0 if A is None else A.shape[0] - self.n
        self.lu = factorize(J.tocsc() if A is None else A.tocsc(), symmetric=False)

    def solve(self, b):
        b = np.asarray(b, dtype=float)
        if not self.extra:
            return self.lu.solve(b)
        pad = np.zeros((self.extra,) + b.shape[1:])
        return self.lu.solve(np.concatenate([b, pad], axis=0))[: self.n]


class AssembledSolver:
    """Linear solver strategy: a sparse direct factorisation of the assembled Jacobian, whatever
    its size (:class:`AssembledFactorization`; for checks and comparisons with
    :class:`~femodes.hbm.BlockSolver`)."""

    def factorize(self, J: HarmonicBlockJacobian, *, threads: int | None = None):
        return AssembledFactorization(J)

    def __repr__(self) -> str:
        return "AssembledSolver()"
