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

    The measurements behind each default: :doc:`/guide/performance` (Why these defaults).

    Parameters
    ----------
    structured_min_size, structured_min_size_narrow, narrow_band_kl, narrow_boundary_share : default 500, 2000, 3, 0.25
        Smaller systems go to SuperLU on the assembled matrix; the second size (no modal damping) for band
        blocks of width at most ``narrow_band_kl``, none, or more than this share of nonlinear DOFs.
    dense_max_size, dense_fill : int, float, default 250, 0.25
        Systems up to this many unknowns, or below the size above with a nonlinear block this full,
        are assembled densely and factorised by LAPACK.
    dense_operators_max : int, default 1000
        Displacement coefficients up to which a dense ``HarmonicBlockJacobian.toarray`` comes from the
        system's cached dense operators, not from the sparse matrix.
    schur_min_size : int, default 400
        Dense systems from this size on eliminate the displacements first when they can (``ForceSchur``).
    schur_max_growth : float, default 1e6
        Largest entry growth accepted from eliminating the displacements without pivoting across blocks
        (the Schur complement's largest entry over the blocks'); growth ``g`` costs up to ``g eps``.
    keep_w_max_bytes, keep_w_max_bytes_sparse : int, default 256 MiB, 2 GiB
        Memory for keeping the condensation columns ``W = Z_II^-1 Z_Ib`` of all harmonics, band and
        sparse-direct blocks (a solve then needs one block solve per harmonic, not two).
    band_max_fill : float, default 7.0
        The interior block is factorised by LAPACK band LU when its band storage ``(3 kl + 1) n_I`` is
        at most this many times its nonzeros, else by the sparse direct back-end.
    superlu_permc_spec, superlu_diag_pivot_thresh, superlu_symmetric_mode : default "MMD_AT_PLUS_A", 0.1, True
        SuperLU options of a wide interior block (``Z`` is complex symmetric).
    thread_min_size : int, default 20000
        Interior size below which the harmonic blocks are factorised in one thread.
    reuse_lu_cost, reuse_lu_cost_sparse, reuse_pass_overhead, reuse_matvec_cost : float, default 4.0, 10.0, 1.9, 1.3
        Cost model of ``BlockSolver(reuse=True)``, in single-column band solves of one harmonic block:
        a band LU with its assembly, a SuperLU factorisation, the products and Schur solve of a pass,
        the residual product ``J x`` of the refinement test.
    reuse_forward_tol : float, default 1e-12
        Forward-error target of a reused solve: next correction below this times ``max |x|``.
    reuse_auto_min_rows : int, default 10000
        ``BlockSolver(reuse="auto")`` reuses factors on sparse-direct blocks of at least this many
        interior rows (2-D/3-D meshes), never on band blocks.
    """

    structured_min_size: int = 500
    structured_min_size_narrow: int = 2000
    narrow_band_kl: int = 3
    narrow_boundary_share: float = 0.25
    dense_max_size: int = 250
    dense_fill: float = 0.25
    dense_operators_max: int = 1000
    schur_min_size: int = 400
    schur_max_growth: float = 1e6
    keep_w_max_bytes: int = 256 * 2 ** 20
    keep_w_max_bytes_sparse: int = 2 * 2 ** 30
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
    reuse_auto_min_rows: int = 10000

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
