"""Discretise layer: the tuning of the HBM block solver, one frozen options object.

Every number is a measured break-even or a safeguard; the measurements are quoted with each field.
Pass them as ``BlockSolver(options=BlockSolverOptions(...))``; the defaults are those measured.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

__all__ = ["BlockSolverOptions", "DEFAULT_OPTIONS", "solver_memory"]


@dataclass(frozen=True)
class BlockSolverOptions:
    """Tuning of :class:`~femodes.hbm.BlockSolver` (which path solves which system, what it keeps).

    Parameters
    ----------
    structured_min_size : int, default 2000
        Systems smaller than this are solved by SuperLU on the assembled matrix: below ~2000
        unknowns the per-harmonic bookkeeping costs more than it saves (measured per bordered
        Newton step on a clamped bar with a tip stop: 231 unknowns 4.8 ms structured vs 3.3 ms
        SuperLU; 2211: 4.9 vs 5.9 ms; 11011: 7.7 vs 16.7 ms; 205041: 69 vs 222 ms).
    dense_max_size : int, default 250
        Systems up to this many unknowns are assembled densely and factorised by LAPACK (per
        factorisation and solve of a bordered Jacobian, one core, dense / SuperLU, ms: 1-DOF
        contact 43, 83, 163, 323 unknowns: 0.21/1.3, 0.31/1.7, 0.88/1.3, 2.9/1.6; 5-10-element
        cantilever with a stop 122, 232, 442: 0.35/1.5, 0.8/1.6, 3.8/2.0).
    dense_fill : float, default 0.25
        Below ``structured_min_size``, a system whose nonlinear block alone fills at least this
        fraction of the matrix is factorised densely too (a contact DOF couples all its
        harmonics; the seed's forced case at an in-contact point, LAPACK / SuperLU, ms: 323
        unknowns (H = 80) 2.3 / 5.0, 483 (H = 120) 4.3 / 5.7, 643 (H = 160) 8.3 / 9.4).
    dense_operators_max : int, default 1000
        A dense matrix (``HarmonicBlockJacobian.toarray``) is assembled from the system's cached
        dense operators up to this many displacement coefficients (four ``nq x nq`` arrays, at
        most 32 MB), else from the sparse matrix (H = 80 of the seed's case: the CSR matrix and
        its conversion took 3.0 of the 4.3 ms of a factorisation, the LU itself 1.1 ms).
    schur_min_size : int, default 400
        Dense systems from this size on eliminate the displacements first when they can
        (``ForceSchur``; 1-DOF contact, elimination / whole LU, ms: 323 unknowns 1.9 / 1.3, 483
        2.4 / 3.4, 643 4.3 / 7.5).
    schur_max_growth : float, default 1e6
        Largest growth of the entries accepted from eliminating the displacements without
        pivoting across blocks (the Schur complement's largest entry over the blocks'); growth
        ``g`` costs up to ``g eps`` of relative accuracy before refinement.
    keep_w_max_bytes : int, default 256 MiB
        Memory allowed for keeping the condensation columns ``W = Z_II^-1 Z_Ib`` of all
        harmonics (``16 n_I n_b (H + 1)`` bytes; 18 MB for a 1e4-DOF bar with 10 contacts at
        H = 10): a solve then needs one band solve per harmonic instead of two (a single-column
        ``?gbtrs`` of a tridiagonal 1e4-DOF block 0.29 ms, ``W x`` with 10 columns 0.07 ms).
    band_max_fill : float, default 7.0
        The interior block is factorised by LAPACK band LU when its band storage ``(3 kl + 1)
        n_I`` is at most this many times its nonzeros, else by the sparse direct back-end. Per
        harmonic block, band / SuperLU (``benchmarks/README_solids_scale.md``; ratio in
        brackets): line meshes (1.3-1.8) 1.4 / 4.6 ms; 2-D Q1 strip 1.3 / 2.9 ms (4.5), 63 / 74
        ms (8.8), 15.6 / 7.0 s (29); 2-D Q2 strip 0.22 / 0.067 s (15.3); 3-D P2 box 138 / 50 ms
        (13.3). Break-even near 6 (15 on Q1 quadrilaterals, where the band also takes 1.5-4x
        the memory); the old limit (50) sent 3-D blocks to the band (out of 10 GiB at 1.9e4 DOFs).
    superlu_permc_spec, superlu_diag_pivot_thresh, superlu_symmetric_mode
        SuperLU options of a wide interior block: ``Z`` is complex symmetric, and a minimum-degree
        ordering of ``Z^T + Z`` with the diagonal pivots kept gives less fill than COLAMD on the
        larger meshes (2-D Q1 strip, 2.6e5 DOFs: 11.9 vs 17.4 x nnz; 3-D P2 box, 6.1e4 DOFs: 14.9
        vs 25.0, factorisation 26 vs 72 s); thresholds 0 to 1 gave the same fill and backward
        errors 1e-16..5e-16 (``k w`` = 0.3 to 40).
    thread_min_size : int, default 20000
        Interior size below which the harmonic blocks are factorised in one thread (starting a
        pool costs ~0.1-1 ms, more than a band LU of a few thousand DOFs).
    reuse_lu_cost, reuse_lu_cost_sparse, reuse_pass_overhead, reuse_matvec_cost : float
        Cost model of ``BlockSolver(reuse=True)``, in single-column band solves of one harmonic
        block (tridiagonal 1e4-DOF blocks, ``benchmarks/README_corrector.md``): a band LU with its
        assembly (4.0), a SuperLU factorisation (10.0), the products and Schur solve of a pass
        (1.9), the residual product ``J x`` of the refinement test (1.3).
    reuse_forward_tol : float, default 1e-12
        Forward-error target of a solve with reused factors: the predicted next correction must
        be below this times ``max |x|``.
    """

    structured_min_size: int = 2000
    dense_max_size: int = 250
    dense_fill: float = 0.25
    dense_operators_max: int = 1000
    schur_min_size: int = 400
    schur_max_growth: float = 1e6
    keep_w_max_bytes: int = 256 * 2 ** 20
    band_max_fill: float = 7.0
    superlu_permc_spec: str = "MMD_AT_PLUS_A"
    superlu_diag_pivot_thresh: float = 0.1
    superlu_symmetric_mode: bool = True
    thread_min_size: int = 20000
    reuse_lu_cost: float = 4.0
    reuse_lu_cost_sparse: float = 10.0
    reuse_pass_overhead: float = 1.9
    reuse_matvec_cost: float = 1.3
    reuse_forward_tol: float = 1e-12

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.type == "bool":
                if not isinstance(v, bool):
                    raise TypeError(f"BlockSolverOptions: {f.name} must be True or False, got {v!r}")
            elif f.type == "str":
                if not isinstance(v, str):
                    raise TypeError(f"BlockSolverOptions: {f.name} must be a string, got {v!r}")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or v < 0:
                raise ValueError(f"BlockSolverOptions: {f.name} must be a non-negative number, got {v!r}")
        if self.reuse_forward_tol >= 1.0:
            raise ValueError(f"BlockSolverOptions: reuse_forward_tol must be below 1, got {self.reuse_forward_tol!r}")

    @property
    def superlu_options(self) -> dict:
        """The keyword arguments of ``scipy.sparse.linalg.splu`` (a new dict each time)."""
        return dict(permc_spec=self.superlu_permc_spec, diag_pivot_thresh=self.superlu_diag_pivot_thresh,
                    options=dict(SymmetricMode=self.superlu_symmetric_mode))


#: The measured defaults.
DEFAULT_OPTIONS = BlockSolverOptions()


def solver_memory(n_coef: int, n_time: int, n_boundary: int, n_p: int, rank: int = 0, n_border: int = 2,
                  n_aft: int = 0, block: bool = True) -> float:
    """Bytes of the dense arrays of a Newton step that grow with H and the contacts, estimated
    before the first solve (the system refuses a problem that cannot fit, ``check_memory``).

    The dense Schur complement ``T`` of the structured factorisation, of size
    ``nB = n_coef (n_boundary + rank) + n_p + n_border`` (layout: nonlinear DOFs' coefficients,
    contact forces, modal coordinates, border), and its LU (``lu_factor`` copies it): ``2 nB^2``
    floats with the block solver; the dense Fourier operators (synthesis and analysis, ``2 N
    n_coef``) and ``d/dw`` (``n_coef^2``); the AFT Jacobians of the nonlinear DOFs (``n_aft``
    dense ``n_coef x n_coef`` blocks in CSR, 12 bytes per entry). The interior (banded or sparse)
    factorisations are not counted: they grow with the mesh, not with H or the contacts.
    """
    nB = n_coef * (n_boundary + rank) + n_p + n_border
    schur = 2.0 * nB * nB if block else 0.0
    return 8.0 * (schur + 2.0 * n_time * n_coef + n_coef * n_coef) + 12.0 * n_aft * n_coef * n_coef
