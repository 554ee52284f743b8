r"""Discretise layer: Newton steps of the HBM equations by harmonic blocks and a Schur complement.

The Jacobian of the harmonic balance equations (:class:`~femodes.hbm.system.HBMSystem`) is

.. math::

    J = \begin{bmatrix} s\,(S(\omega) \oplus 0 + N) & U \\ V & D \end{bmatrix},

with ``S(w)`` block diagonal over harmonics, ``N`` the generalized Jacobian of the contact and
nonlinear terms, which lives only on the rows and columns of the ``n_b`` nonlinear DOFs (all
harmonics) and of the contact-force unknowns, ``s`` the equation scale of the problem and
``U, V, D`` dense borders (the extra unknowns of a nonlinear mode, the arclength equation of the
continuation). In complex form the block of harmonic ``k`` (frequency ``k w / nu``) is the
dynamic stiffness

.. math::

    Z_k = K - (k\omega/\nu)^2 M + i\,(k\omega/\nu)\,(C - \xi M),

acting on ``a - i b`` for the coefficients ``a cos + b sin`` (``xi`` the EPMC damping).

:class:`HarmonicBlockJacobian` keeps this structure instead of assembling one sparse matrix, and
its :meth:`~HarmonicBlockJacobian.factorize` solves Newton steps by

1. splitting the unknowns into the *interior* ``I`` (the coefficients of the linear DOFs) and the
   *boundary* ``B`` (coefficients of the nonlinear DOFs, contact forces, border unknowns);
2. factorising ``Z_k[I, I]`` for each harmonic independently: LAPACK band LU (``?gbtrf``) after a
   reverse Cuthill-McKee ordering when the band is narrow (its storage at most
   :data:`BAND_MAX_FILL` times the block's nonzeros: line meshes, bandwidth 1-3, and the small
   dense interiors of reduced models), otherwise (2-D and 3-D meshes) the sparse direct back-end
   in use (:mod:`femodes.sparse_direct`: MUMPS's complex symmetric ``LDL^T`` where installed,
   6x faster than SuperLU on a 6.1e4-DOF P2 block), or SuperLU with a minimum-degree ordering of
   ``Z + Z^T`` and diagonal pivoting preferred (:data:`SUPERLU_OPTIONS`);
   the ``H + 1`` factorisations are independent and can run in threads
   (``HBMSystem(threads=...)``; LAPACK and SuperLU release the GIL). Default one thread: on the
   2-core test machine two threads were slower (1e5-DOF bar, H = 20: 1283 ms vs 1118 ms per
   Newton iteration, ``benchmarks/README.md``), the band solves being memory-bound;
3. condensing onto ``B``: a dense Schur complement of size ``n_b (2H+1) + n_p + m`` whose linear
   part is the condensed dynamic stiffness ``Z_k[b,b] - Z_k[b,I] Z_k[I,I]^{-1} Z_k[I,b]``,
   factorised by dense LU with partial pivoting (the borders are inside it, so the solve stays
   accurate at folds, where ``J`` without its border is singular);
4. back substitution, then iterative refinement against the true ``J`` (one matrix-vector
   product) if the residual is not at round-off; a block that cannot be factorised (singular
   ``K`` of a free structure at harmonic 0, ``k w`` at an eigenfrequency of the structure with its
   nonlinear DOFs held) falls back to SuperLU on the assembled matrix.

Modal damping (``with_damping(modal=...)``) adds a low-rank part ``U diag(d) U^T`` (``U = M Phi``,
``n x m``) to ``C``: it couples all DOFs within each harmonic, so it is kept out of ``Z_k[I, I]``
(whose band LU stays that of the sparse part) and handled through the Schur complement: the
``m`` modal coordinates ``y_k = U^T z_k`` of each harmonic join the boundary, with the equations
``Z_k z + i (k w / nu) U diag(d) y = r`` and ``U^T z - y = 0``. The condensation needs
``Z_k[I, I]^{-1} U_I``; when ``Phi`` are modes of the structure (``K Phi = M Phi diag(w^2)``,
checked), ``Z_k Phi = U diag(w^2 - a - i b xi)`` gives it from the ``n_b`` columns
``Z_k[I, I]^{-1} Z_k[I, b]`` already solved, so a Newton iteration costs about what it costs
with Rayleigh damping (``benchmarks/README.md``, "Modal damping"). The modal coordinates couple
only within their harmonic and to the borders, so they are eliminated harmonic by harmonic
(``2m x 2m`` blocks) before the dense LU, which keeps the size it has with Rayleigh damping.
Woodbury on each block (``(Z_s + i b U d U^T)^{-1}``) is the same algebra in another order: it
needs the same ``Z_s^{-1} U`` plus ``d^{-1}`` (zero ratios are allowed here) and a
capacitance solve that must be threaded through the Schur complement on the contact DOFs
anyway; the bordered form keeps the refinement and fallback paths unchanged. The assembled fallback (:class:`AssembledSolver`, small systems) solves
the sparse augmented matrix ``[[J_sparse, B], [I x U^T, -I]]`` instead of a dense ``J``.

The per-harmonic factorisations and condensed stiffnesses depend only on ``(w, xi)``: they are
cached on the system: Newton at a fixed frequency (the start of a frequency response, the forcing
homotopy, sweeps at fixed ``w``) reuses them at every iteration; inside a continuation ``w`` is an
unknown and changes at every iteration, so there they are rebuilt (but see "Reused factors").
The columns ``W = Z_II^-1 Z_Ib`` of the condensation are kept (:data:`KEEP_W_MAX_BYTES`), and so
are the interior solutions of the border columns: a solve then costs one band solve per harmonic
(the back substitution is ``W x_b`` plus those columns times the border unknowns) and the border
coupling one, instead of two each. With modal damping through the modes of the structure this
holds too: ``Z_II^-1 U_I = (Phi_I + W Phi_b + c Z_II^-1 E_I) diag(1/mu)`` (above) is applied by
products from ``W`` and the few extra columns kept with it (:meth:`LinearFactors.apply_x`), and
the modal rows of the border coupling use the symmetry of ``Z`` (issue 38 item 5: a point of the
1e3-1e5-DOF bar with a stop at H = 5 went from 1.5-1.8x to 1.3-1.5x the Rayleigh-damped point,
``benchmarks/bench_damping_cpu.py``); a sparse damping part besides the modal one keeps the
general path (two band solves per harmonic). Cost per Newton iteration:
``O(N H bw^2)`` for the band LUs, ``O(N H (n_b + m))`` for the condensation solves and
``O((n_b (2H+1))^3)`` for the dense LU.

Reused factors (``BlockSolver(reuse=True)``, off by default). A Jacobian at ``w`` close to the
frequency ``w0`` of the last factors (``|w - w0| <= reuse_window |w0|``) is solved with them:
they are the exact factorisation of ``P``, the Jacobian with its linear part ``S(w0)`` instead of
``S(w)`` (nonlinear part, borders and Schur complement at the current point), and ``x <- x +
P^-1 (b - J x)`` is iterated, the residual of a pass being ``(P - J) d = s (S(w0) - S(w)) d``
(two sparse products). A solve is accepted by the backward-error test of the exact path and a
forward test (the next correction, predicted from the contraction of the last two, below
:data:`REUSE_FORWARD_TOL`); when the passes this predicts exceed what a refactorisation costs
(:func:`_budget_from_factors`), or the contraction is slower than 1/2 (``k w`` crossing an
eigenfrequency of the interior), the factors are rebuilt at ``w`` and become the new base; the
contraction per unit frequency offset is remembered to skip attempts predicted to fail. The
Jacobian used is thus the exact one to the refinement tolerance: Newton's iterations and the
branch do not change (``tests/test_linsolve.py``). It is off by default because it did not pay
on the bars of ``benchmarks/README_corrector.md``: a band LU of a line mesh costs only 2-3
single-column band solves, and near the resonance a corrector traces ``P^-1 J`` departs from the
identity by ``q ~ 10-4000 |w - w0| / w0`` (typically 100), so the offsets of a corrector
(1e-5-1e-3) need 3-8 passes; only the last corrector iterations and the tangent, whose offsets
are below 1e-6, are served in 2-3 passes.
"""

from __future__ import annotations

import logging
import math
import os
import weakref
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ..sparse_direct import factorize, is_symmetric, sparse_backend_info

__all__ = ["HarmonicBlockJacobian", "StructureFailure", "BlockSolver", "AssembledSolver", "BlockStructure",
           "solver_memory"]

log = logging.getLogger(__name__)


class BlockStructure(Protocol):
    """What the Jacobian operator and its factorisations need from the harmonic balance system
    (:class:`~femodes.hbm.HBMSystem` provides it): sizes, the linear block operator and its
    per-harmonic factors, and the solver strategy. Nothing else of the system is read here.
    """

    h: Any            # Harmonics: layout of the coefficient rows
    n: int            # DOFs of the model
    nq: int           # displacement unknowns, n_coef * n
    np: int           # contact-force unknowns
    size: int         # nq + np
    solver: Any       # BlockSolver() or AssembledSolver()
    AM: Any           # kron(D1, M), the artificial-damping operator of nonlinear modes (assembled path)
    C_lr: Any         # LowRankDamping U diag(d) U^T of modal damping, or None (module docstring)

    def apply_linear(self, q, omega: float, xi: float = 0.0, *, absolute: bool = False): ...
    def abs_row_sums(self) -> tuple: ...
    def block_pattern(self): ...
    def linear_factors(self, omega: float, xi: float = 0.0, threads: int | None = None): ...
    def linear_operator(self, omega: float): ...
    def lowrank_border(self, omega: float): ...


class StructureFailure(RuntimeError):
    """The structured factorisation is not applicable (a singular interior block)."""


#: Systems smaller than this are solved by SuperLU on the assembled matrix: below ~2000 unknowns
#: the per-harmonic bookkeeping costs more than it saves (measured per bordered Newton step on a
#: clamped bar with a tip stop: 231 unknowns 4.8 ms structured vs 3.3 ms SuperLU; 2211: 4.9 vs
#: 5.9 ms; 11011: 7.7 vs 16.7 ms; 205041: 69 vs 222 ms).
STRUCTURED_MIN_SIZE = 2000

#: Systems up to this many unknowns are assembled densely and factorised by LAPACK. Measured per
#: factorisation and solve of a bordered HBM Jacobian, one core (dense / SuperLU, ms): 1-DOF
#: contact 43, 83, 163, 323 unknowns: 0.21/1.3, 0.31/1.7, 0.88/1.3, 2.9/1.6; 5-10-element
#: cantilever with a stop 122, 232, 442: 0.35/1.5, 0.8/1.6, 3.8/2.0.
DENSE_MAX_SIZE = 250

#: Below STRUCTURED_MIN_SIZE, a system whose nonlinear block alone fills at least this fraction
#: of the matrix is factorised densely too: a contact DOF couples all its harmonics (two dense
#: ``n_coef x n_coef`` blocks per complementarity contact), so a 1-DOF contact model at high H is
#: half full. Measured (factorisation and solve of the bordered Jacobian at an in-contact point of
#: the seed's forced case, one core, ms, LAPACK dense / SuperLU): 323 unknowns (H = 80) 2.3 / 5.0,
#: 483 (H = 120) 4.3 / 5.7, 643 (H = 160) 8.3 / 9.4.
DENSE_FILL = 0.25

#: A dense matrix (:meth:`HarmonicBlockJacobian.toarray`, the LAPACK path) is assembled from the
#: system's cached dense linear operators when it has at most this many displacement coefficients
#: (four ``nq x nq`` arrays, at most 32 MB), else from the sparse matrix. Measured on level
#: H = 80 of the seed's forced case (323 unknowns, :data:`DENSE_FILL`): the CSR matrix and its
#: conversion took 3.0 of the 4.3 ms of a factorisation, the LU itself 1.1 ms.
DENSE_OPERATORS_MAX = 1000

#: Dense systems from this size on eliminate the displacements first when they can
#: (:class:`_ForceSchur`). Measured per factorisation and two solves of the bordered 1-DOF
#: contact Jacobian (one core, ms, elimination / whole LU): 323 unknowns (H = 80) 1.9 / 1.3,
#: 483 (H = 120) 2.4 / 3.4, 643 (H = 160) 4.3 / 7.5.
SCHUR_MIN_SIZE = 400

#: Largest growth of the entries that :class:`_ForceSchur` accepts from eliminating the
#: displacements without pivoting across blocks: the Schur complement's largest entry over the
#: largest entry of the blocks it comes from (a harmonic block near singular, ``k w`` at an
#: eigenfrequency of the undamped structure, makes it large; the whole matrix is then pivoted).
#: Growth ``g`` costs up to ``g eps`` of relative accuracy before refinement.
SCHUR_MAX_GROWTH = 1e6

#: Memory allowed for keeping the condensation columns ``W = Z_II^-1 Z_Ib`` of all harmonics
#: (``16 n_I n_b (H + 1)`` bytes; 18 MB for a 1e4-DOF bar with 10 contacts at H = 10, 176 MB at
#: 1e5). With them a solve needs one band solve per harmonic instead of two, and the border
#: coupling one instead of two: a single-column ``?gbtrs`` of a tridiagonal 1e4-DOF block takes
#: 0.29 ms, the product ``W x`` with 10 columns 0.07 ms (1e5: 3.0 and 1.4 ms).
KEEP_W_MAX_BYTES = 256 * 2 ** 20

#: Cost model of the reuse of factors (:func:`_budget_from_factors`), in single-column band solves
#: of one harmonic block: a band LU with its assembly, a SuperLU factorisation, the residual
#: product ``J x`` of the refinement test.
REUSE_LU_COST = 4.0
REUSE_LU_COST_SPARSE = 10.0
REUSE_PASS_OVERHEAD = 1.9
REUSE_MATVEC_COST = 1.3

#: Forward-error target of a solve with reused factors: the predicted next correction must be below
#: this times ``max |x|`` (:meth:`_Factorization._solve_reused`).
REUSE_FORWARD_TOL = 1e-12

#: The interior block is factorised by LAPACK band LU when its band storage ``(3 kl + 1) n_I`` (``kl``
#: the bandwidth after reverse Cuthill-McKee) is at most this many times its nonzeros, by SuperLU
#: otherwise. Measured per harmonic block at ``k w = 1.5``, factorisation plus the ``n_b``
#: condensation columns, band / SuperLU (``benchmarks/README_solids_scale.md``; ratio in brackets):
#: line meshes (1e4 DOFs; 1.3-1.8) 1.4 / 4.6 ms (P1 bar), 2.3 / 6.5 ms (Hermite beam); 2-D Q1 strip
#: 1.3 / 2.9 ms (4.5), 13.5 / 26 ms (6.8), 63 / 74 ms (8.8), 0.71 / 0.68 s (15.5), 15.6 / 7.0 s (29);
#: 2-D Q2 strip 12 / 8 ms (7.8), 0.22 / 0.067 s (15.3); 3-D P1 box 2.1 / 1.9 ms (6.1), 89 / 44 ms
#: (13.2); 3-D P2 box 2.3 / 2.2 ms (4.7), 138 / 50 ms (13.3), 2.0 / 0.53 s (29.5). Break-even is
#: at a ratio of about 6 except on Q1 quadrilaterals (about 15), and the band also takes 1.5-4x
#: the memory of the sparse factors there; a dense block (modal coordinates of a reduced model)
#: has a ratio of about 3 and stays banded. The old limit (50) sent 3-D blocks with 45x their
#: nonzeros to the band (out of 10 GiB at 1.9e4 DOFs).
BAND_MAX_FILL = 7.0

#: SuperLU options of a wide interior block. ``Z = K - a M + i b C`` is complex symmetric: a
#: minimum-degree ordering of ``Z^T + Z`` with the diagonal pivots kept (``SymmetricMode``, a pivot
#: is taken off the diagonal only when the diagonal is below 0.1 of the column's largest entry)
#: gives less fill than COLAMD on the larger meshes (2-D Q1 strip, 2.6e5 DOFs: 11.9 vs 17.4 x
#: nnz; 3-D P2 box, 6.1e4 DOFs: 14.9 vs 25.0, factorisation 26 vs 72 s; at 1.4e5 only this one
#: ran) and a few tens of % more on mid-size 3-D blocks (5.8 vs 4.5 at 8.8e3 DOFs). Thresholds 0
#: to 1 gave the same fill and backward errors ``|Z x - r| / (|Z| |x| + |r|)`` of 1e-16..5e-16,
#: between eigenfrequencies and far above them (``k w`` = 0.3 to 40). Each SuperLU factorisation
#: keeps the ~30 x nnz entries SuperLU reserved for L and U: address space, mostly untouched (a
#: 3.3e4-DOF strip block: 656 MiB virtual, 72 MiB resident), which matters under ``ulimit -v``.
SUPERLU_OPTIONS = dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options=dict(SymmetricMode=True))

#: Interior size below which the harmonic blocks are factorised in one thread: starting a pool
#: costs ~0.1-1 ms, more than a band LU of a few thousand DOFs.
THREAD_MIN_SIZE = 20000


def solver_memory(n_coef: int, n_time: int, n_boundary: int, n_p: int, rank: int = 0, n_border: int = 2,
                  n_aft: int = 0, block: bool = True) -> float:
    """Bytes of the dense arrays of a Newton step that grow with H and the contacts, estimated
    before the first solve (the system refuses a problem that cannot fit, :func:`check_memory`).

    The dense Schur complement ``T`` of :class:`_Factorization`, of size
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


def _threads(n_tasks: int, threads: int | None, size: int) -> int:
    if threads is None or size < THREAD_MIN_SIZE:
        return 1
    if threads == 0:  # all CPUs
        threads = os.cpu_count() or 1
    return max(1, min(int(threads), n_tasks))


# --------------------------------------------------------------------------------------------
# interior pattern and per-harmonic factorisations
# --------------------------------------------------------------------------------------------
@dataclass
class _Pattern:
    """Interior/boundary split of the DOFs and the union sparsity pattern of ``K, M, C`` on ``I``."""

    interior: np.ndarray   # interior DOFs
    bdofs: np.ndarray      # nonlinear DOFs (boundary)
    perm: np.ndarray       # RCM ordering of the interior (position -> interior index)
    rows: np.ndarray       # COO pattern of the permuted interior block
    cols: np.ndarray
    kv: np.ndarray         # K, M, C values on that pattern (zeros where absent)
    mv: np.ndarray
    cv: np.ndarray
    kl: int                # bandwidth after RCM
    banded: bool
    identity: bool         # perm is the identity
    R: np.ndarray          # interior positions coupled to the boundary DOFs
    Kib: np.ndarray        # couplings Z[I, b] on the rows R (dense, len(R) x n_b)
    Mib: np.ndarray
    Cib: np.ndarray
    Kbi: np.ndarray        # couplings Z[b, I] on the columns R (dense, n_b x len(R))
    Mbi: np.ndarray
    Cbi: np.ndarray
    Kbb: np.ndarray
    Mbb: np.ndarray
    Cbb: np.ndarray
    lowrank: dict = field(default_factory=dict)  # modal damping's split of U, Phi (LinearFactors)
    band_flat: np.ndarray | None = None            # rows/cols in the band storage (BlockLU)
    abs_row_sums: tuple | None = None              # the system's abs_row_sums() (refinement test)
    symmetric: bool = False                        # K, M, C symmetric on I: the blocks are (complex) symmetric


def build_pattern(M: sp.spmatrix, K: sp.spmatrix, C: sp.spmatrix, bdofs: np.ndarray) -> _Pattern:
    n = M.shape[0]
    bdofs = np.unique(np.asarray(bdofs, dtype=int))
    mask = np.ones(n, dtype=bool)
    mask[bdofs] = False
    interior = np.flatnonzero(mask)
    M, K, C = (sp.csr_matrix(A, dtype=float) for A in (M, K, C))
    MII, KII, CII = (A[interior][:, interior] for A in (M, K, C))
    nI = interior.size
    # union pattern of the interior block with aligned values: one linear combination per
    # harmonic, no sparse adds
    U = (abs(MII) + abs(KII) + abs(CII)).tocoo()
    perm = np.arange(nI)
    if U.nnz:
        natural = int(np.max(np.abs(U.row - U.col)))
        rcm = np.asarray(reverse_cuthill_mckee(U.tocsr(), symmetric_mode=True), dtype=int)
        inv = np.empty(nI, dtype=int)
        inv[rcm] = np.arange(nI)
        if int(np.max(np.abs(inv[U.row] - inv[U.col]))) < natural:
            perm = rcm  # keep the natural order when it is as narrow (no permutation copies)
    inv = np.empty(nI, dtype=int)
    inv[perm] = np.arange(nI)
    r, c = inv[U.row], inv[U.col]

    def vals(A):
        return np.asarray(A[U.row, U.col]).ravel() if U.nnz else np.zeros(0)
    kv, mv, cv = vals(KII), vals(MII), vals(CII)
    kl = int(np.max(np.abs(r - c))) if U.nnz else 0
    # band storage (3 kl + 1) x nI against the sparse factors' ~ a few x nnz (BAND_MAX_FILL): line
    # meshes (kl = 1..3 after RCM) and dense reduced interiors stay banded, 2-D/3-D meshes go to
    # SuperLU
    banded = nI > 0 and (3 * kl + 1) * nI <= BAND_MAX_FILL * max(U.nnz, 1)
    # the interior-boundary couplings touch only the neighbours of the boundary DOFs: keep them as
    # small dense blocks on those rows (sparse matrices cost ~50 us per operation in scipy)
    ib = [A[interior][:, bdofs].tocsr() for A in (K, M, C)]
    bi = [A[bdofs][:, interior].tocsc() for A in (K, M, C)]
    R = np.unique(np.concatenate([A.tocoo().row for A in ib] + [A.tocoo().col for A in bi] + [np.zeros(0, int)]))
    return _Pattern(
        interior=interior, bdofs=bdofs, perm=perm, rows=r, cols=c, kv=kv, mv=mv, cv=cv, kl=kl, banded=banded,
        identity=bool(np.array_equal(perm, np.arange(nI))), R=R,
        symmetric=not banded and all(is_symmetric(A) for A in (KII, MII, CII)),
        Kib=ib[0][R].toarray(), Mib=ib[1][R].toarray(), Cib=ib[2][R].toarray(),
        Kbi=bi[0][:, R].toarray(), Mbi=bi[1][:, R].toarray(), Cbi=bi[2][:, R].toarray(),
        Kbb=K[bdofs][:, bdofs].toarray(), Mbb=M[bdofs][:, bdofs].toarray(), Cbb=C[bdofs][:, bdofs].toarray(),
    )


class BlockLU:
    """LU of the interior block ``Z = K - a M + i b C_eff`` of one harmonic (band LAPACK or SuperLU).

    ``solve(R, trans)`` takes and returns complex arrays ``(nI, k)`` in the *original* interior
    order; ``trans=True`` solves with ``Z^T`` (not conjugated).
    """

    def __init__(self, pat: _Pattern, a: float, b: float, xi: float):
        self.pat = pat
        vals = pat.kv - a * pat.mv
        cv = pat.cv - xi * pat.mv
        self.complex = bool(b != 0.0 and np.any(cv != 0.0))
        if self.complex:
            vals = vals + 1j * b * cv
        n = pat.perm.size
        self.n = n
        if pat.banded:
            kl = pat.kl
            ld = 2 * kl + kl + 1
            if pat.band_flat is None:  # positions in the column-major band storage, once per pattern
                pat.band_flat = (2 * kl + pat.rows - pat.cols) + pat.cols * ld
            ab = np.zeros(ld * n, dtype=vals.dtype)
            ab[pat.band_flat] = vals
            ab = ab.reshape((ld, n), order="F")
            gbtrf = lapack.zgbtrf if self.complex else lapack.dgbtrf
            self.lu, self.piv, info = gbtrf(ab, kl, kl, overwrite_ab=True)
            if info != 0:
                raise StructureFailure(f"interior block singular (gbtrf info {info})")
            self._gbtrs = lapack.zgbtrs if self.complex else lapack.dgbtrs
            self._lu_complex = None  # a real band LU cast to complex, for complex right-hand sides
        else:
            A = sp.csc_matrix((vals, (pat.rows, pat.cols)), shape=(n, n))
            try:
                # the back-end in use (femodes.sparse_direct): MUMPS on the large complex symmetric
                # blocks of 2-D/3-D meshes where installed, SuperLU with SUPERLU_OPTIONS otherwise
                self.factor = factorize(A, symmetric=pat.symmetric, positive_definite=not self.complex and a <= 0.0,
                                        superlu_options=SUPERLU_OPTIONS)
            except RuntimeError as exc:
                raise StructureFailure(f"interior block singular ({exc})") from None

    def _solve_real_or_complex(self, R: np.ndarray, trans: bool, own: bool = False) -> np.ndarray:
        """``own``: ``R`` is a scratch array of the caller's (the band solve may overwrite it)."""
        if self.pat.banded:
            kl = self.pat.kl
            x, info = self._gbtrs(self.lu, kl, kl, R, self.piv, trans=1 if trans else 0, overwrite_b=own)
            if info != 0:  # pragma: no cover - argument error
                raise StructureFailure(f"gbtrs info {info}")
            return x
        return self.factor.solve(R, trans=trans)

    def solve_columns(self, R: np.ndarray) -> np.ndarray:
        """:meth:`solve` for many right-hand sides (the ``n_b + m`` columns of the modal-damping
        condensation): a narrow band LU solves them one column at a time. ``?gbtrs`` sweeps all
        right-hand sides row by row, striding across the columns (measured, 1e4-DOF bar, 42 real
        columns: 28 ms at once, a few ms column by column)."""
        R = np.asarray(R)
        if not self.pat.banded or R.ndim != 2 or R.shape[1] <= 2:
            return self.solve(R)
        out = np.empty(R.shape, dtype=np.result_type(R, complex if self.complex else float))
        for j in range(R.shape[1]):
            out[:, j] = self.solve(R[:, j:j + 1])[:, 0]
        return out

    def solve(self, R: np.ndarray, trans: bool = False) -> np.ndarray:
        R = np.asarray(R)
        perm = self.pat.perm
        identity = self.pat.identity
        Rp = R if identity else R[perm]
        if self.complex:
            Xp = self._solve_real_or_complex(np.asfortranarray(Rp, dtype=complex), trans)
        elif np.iscomplexobj(Rp) and self.pat.banded:
            # real band factor (modal damping: K - a M), complex right-hand sides: zgbtrs on a
            # complex copy of the LU (made once) sweeps the band once, where dgbtrs on [Re R, Im R]
            # strides across the two columns (1e5 rows, kl = 1: 2.4 vs 3.8 ms; issue 38 item 5)
            if self._lu_complex is None:
                self._lu_complex = self.lu.astype(complex)
            kl = self.pat.kl
            Xp, info = lapack.zgbtrs(self._lu_complex, kl, kl, np.array(Rp, dtype=complex, order="F"), self.piv,
                                     trans=1 if trans else 0, overwrite_b=True)
            if info != 0:  # pragma: no cover - argument error
                raise StructureFailure(f"zgbtrs info {info}")
        elif np.iscomplexobj(Rp):
            # real factor (modal damping: K - a M), complex right-hand sides: one real solve with
            # [Re R, Im R], written straight into Fortran order and read back into a complex array
            # (no concatenate + copy, no complex temporaries: a third of the cost of a kl = 1 band
            # solve of 1e3 rows)
            k = Rp.shape[1]
            both = np.empty((Rp.shape[0], 2 * k), order="F")
            both[:, :k] = Rp.real
            both[:, k:] = Rp.imag
            Y = self._solve_real_or_complex(both, trans, own=True)
            Xp = np.empty((Rp.shape[0], k), dtype=complex)
            Xp.real = Y[:, :k]
            Xp.imag = Y[:, k:]
        else:
            Xp = self._solve_real_or_complex(np.asfortranarray(Rp, dtype=float), trans)
        if identity:
            return Xp
        X = np.empty_like(Xp)
        X[perm] = Xp
        return X


def _real_times_complex(A: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """``A @ Z`` for real ``A`` (p, n) and complex ``Z`` (n, k) as one real product on the
    interleaved view of ``Z`` (numpy would copy ``A`` to complex first)."""
    Z = np.ascontiguousarray(Z, dtype=complex)
    if Z.ndim == 1:
        return _real_times_complex(A, Z[:, None])[:, 0]
    return np.ascontiguousarray(A @ Z.view(float).reshape(Z.shape[0], 2 * Z.shape[1])).view(complex)


@dataclass
class _Harmonic:
    k: int                 # coefficient row of the cosine (0 for the mean)
    s: int | None          # coefficient row of the sine (None for the mean)
    a: float               # (k w / nu)^2
    b: float               # k w / nu
    lu: BlockLU | None
    Zc: np.ndarray         # condensed dynamic stiffness on the boundary DOFs and modal coordinates
                           # (complex (n_b + m_lr) x (n_b + m_lr); n_b x n_b without modal damping)
    Zib: np.ndarray        # Z[I, b] on the coupled rows R (complex len(R) x n_b)
    Zbi: np.ndarray        # Z[b, I] on the coupled columns R (complex n_b x len(R))
    W: np.ndarray | None = None  # Z[I, I]^-1 Z[I, b], all interior rows (complex n_I x n_b), kept when
                                 # LinearFactors.keep_w (back substitution by a product, no solve)
    Xm: tuple | None = None      # modal damping through the modes: what Z[I, I]^-1 U_I is made of
                                 # (LinearFactors.apply_x), kept with W


class LinearFactors:
    """Per-harmonic interior LUs and condensed stiffnesses at one ``(w, xi)`` (cached on the system)."""

    def __init__(self, system: BlockStructure, omega: float, xi: float, threads: int | None = None):
        self.omega, self.xi = float(omega), float(xi)
        h = system.h
        pat = system.block_pattern()
        self.pat = pat
        nb = pat.bdofs.size
        # modal damping U diag(d) U^T: the modal coordinates y = U^T z join the boundary (module
        # docstring); U_I, U_b are its rows on the interior and boundary DOFs
        lr = getattr(system, "C_lr", None)
        self.rank = 0 if lr is None else lr.rank
        if self.rank:
            if "UI" not in pat.lowrank:  # once per system (the pattern is cached there)
                pat.lowrank["UI"] = np.ascontiguousarray(lr.U[pat.interior])
                pat.lowrank["Ub"] = lr.U[pat.bdofs]
                # modes of the structure: Z_II^-1 U_I from Z_II^-1 Z_Ib (no extra solves, below)
                em = system.lowrank_modes() if hasattr(system, "lowrank_modes") else None
                if em is not None:
                    Phi, lam, rows, Erows = em
                    PhiI = Phi[pat.interior]
                    # the changed mass rows that are interior: their positions in the interior order
                    pos = np.searchsorted(pat.interior, rows)
                    inner = (pos < pat.interior.size) & (pat.interior[np.minimum(pos, pat.interior.size - 1)] == rows)
                    pat.lowrank["modes"] = (PhiI, Phi[pat.bdofs], lam, pat.lowrank["UI"].T @ PhiI,
                                            pos[inner], Erows[inner])
            self.UI, self.Ub, self.d = pat.lowrank["UI"], pat.lowrank["Ub"], lr.d
            self.modes = pat.lowrank.get("modes")
        jobs = [(0, None, 0.0)]
        for k in range(1, h.n_harmonics + 1):
            f = k * self.omega / h.subharmonic
            jobs.append((int(h.cos_index(k)), int(h.sin_index(k)), f))
        # keep the condensation columns W = Z_II^-1 Z_Ib (computed anyway): the back substitution
        # and the border rows then cost a product instead of a band solve (KEEP_W_MAX_BYTES)
        # With modal damping through the modes of the structure (_condense_modes), W and the few
        # columns that make up Z_II^-1 U_I are kept too: the solve then takes the lean path
        # (one band solve per harmonic, issue 38 item 5)
        self.keep_w = bool((not self.rank or self.modes is not None) and nb and pat.perm.size
                           and 16 * pat.perm.size * nb * len(jobs) <= KEEP_W_MAX_BYTES)

        def one(job):
            row_c, row_s, f = job
            a, b = f * f, f
            lu = BlockLU(pat, a, b, self.xi) if pat.perm.size else None
            Cb = pat.Cbb - self.xi * pat.Mbb
            Zbb = pat.Kbb - a * pat.Mbb + 1j * b * Cb
            Zib = pat.Kib - a * pat.Mib + 1j * b * (pat.Cib - self.xi * pat.Mib)
            Zbi = pat.Kbi - a * pat.Mbi + 1j * b * (pat.Cbi - self.xi * pat.Mbi)
            W = Xm = None
            if self.rank:
                Zc = self._condense_lowrank(lu, Zbb, Zib, Zbi, a, b)
                if isinstance(Zc, tuple):
                    Zc, W, Xm = Zc
            elif lu is not None and nb:
                full = np.zeros((pat.perm.size, nb), dtype=complex, order="F")  # gbtrs takes it as is
                full[pat.R] = Zib
                W = lu.solve(full)
                Zc = Zbb - Zbi @ W[pat.R]
            else:
                Zc, W = Zbb, None
            keep = self.keep_w and W is not None
            return _Harmonic(row_c, row_s, a, b, lu, np.asarray(Zc, dtype=complex), Zib, Zbi,
                             np.asarray(W, dtype=complex) if keep else None, Xm if keep else None)

        nt = _threads(len(jobs), threads, pat.perm.size)
        if nt > 1 and not pat.banded and sparse_backend_info().indefinite != "superlu":
            nt = 1  # MUMPS instances are not used from several Python threads (not tested for it)
        if nt > 1:
            with ThreadPoolExecutor(nt) as ex:
                self.blocks = list(ex.map(one, jobs))
        else:
            self.blocks = [one(j) for j in jobs]
        self.threads = nt

    def _condense_lowrank(self, lu, Zbb, Zib, Zbi, a: float, b: float) -> np.ndarray:
        """Condensed block of one harmonic on ``[z_b; y]`` with modal coordinates ``y = U^T z``:

        ``[[Z_bb, i b U_b d], [U_b^T, -I]] - [[Z_bI], [U_I^T]] Z_II^-1 [Z_Ib, i b U_I d]``

        (the equations ``Z_s z + i b U diag(d) y = r`` and ``U^T z - y = 0``; ``Z_s`` the sparse
        part, so ``Z_II`` keeps its band LU). One interior solve with ``n_b + m`` columns and
        one real ``m x n_I`` product per harmonic; when ``U = M Phi`` with modes ``Phi`` of the
        structure (``with_damping(modal=...)``), ``Z_s Phi = U diag(mu)``, ``mu = w^2 - a - i b
        xi``, gives ``Z_II^-1 U_I = (Phi_I + Z_II^-1 Z_Ib Phi_b) diag(1/mu)`` from the ``n_b``
        columns already solved, and only the modes with ``|mu|`` small (``k w`` at their
        frequency) are solved for."""
        if self.modes is not None and lu is not None:
            return self._condense_modes(lu, Zbb, Zib, Zbi, a, b)
        pat, m = self.pat, self.rank
        nb = pat.bdofs.size
        gd = 1j * b * self.d
        top = np.hstack([Zbb, self.Ub * gd])
        bottom = np.hstack([self.Ub.T.astype(complex), -np.eye(m, dtype=complex)])
        Zc = np.vstack([top, bottom])
        if lu is None:
            return Zc
        nI = pat.perm.size
        full = np.zeros((nI, nb + m), dtype=complex)
        full[pat.R, :nb] = Zib
        full[:, nb:] = self.UI * gd
        W = np.ascontiguousarray(lu.solve_columns(full), dtype=complex)
        Zc[:nb] -= Zbi @ W[pat.R]
        # U_I^T W as one real product on the interleaved (re, im) view of W
        UW = (self.UI.T @ W.view(float).reshape(nI, 2 * (nb + m))).view(complex)
        Zc[nb:] -= UW
        return Zc

    def _condense_modes(self, lu, Zbb, Zib, Zbi, a: float, b: float) -> np.ndarray:
        """:meth:`_condense_lowrank` through the modes of the structure (its docstring)."""
        pat, m = self.pat, self.rank
        nb, nI = pat.bdofs.size, pat.perm.size
        PhiI, Phib, lam, G, sI, ES = self.modes
        c = a + 1j * b * self.xi
        mu = lam - c
        bad = np.flatnonzero(np.abs(mu) <= 1e-6 * max(float(lam.max()), a, 1e-300))
        gd = 1j * b * self.d
        ns = sI.size
        full = np.zeros((nI, nb + ns + bad.size), dtype=complex)
        full[pat.R, :nb] = Zib
        full[sI, nb + np.arange(ns)] = 1.0   # unit columns on the changed mass rows
        full[:, nb + ns:] = self.UI[:, bad]
        W = lu.solve_columns(full) if full.shape[1] else full
        Wb = np.ascontiguousarray(W[:, :nb], dtype=complex)
        UWb = _real_times_complex(self.UI.T, Wb) if nb else np.zeros((m, 0), complex)
        # X = Z_II^-1 U_I = (Phi_I + W_b Phi_b + c Z_II^-1 E_I) / mu with E = M Phi - U on the rows
        # sI (lowrank_modes): U_I^T X. The modes' residual K Phi - U diag(w^2) is round-off
        # (checked there); what it leaves is for the refinement.
        mu_ok = mu.copy()
        mu_ok[bad] = 1.0  # those columns are overwritten below
        UX = G + UWb @ Phib
        if ns:
            WS = np.ascontiguousarray(W[:, nb:nb + ns], dtype=complex)
            UX = UX + c * (_real_times_complex(self.UI.T, WS) @ ES)
        UX = UX / mu_ok
        if bad.size:
            Xbad = np.ascontiguousarray(W[:, nb + ns:], dtype=complex)
            UX[:, bad] = _real_times_complex(self.UI.T, Xbad)
        # Z_bI X = Z_bI Z_II^-1 U_I = W_b^T U_I (Z is complex symmetric here: no sparse damping
        # part): exact, where (Phi_I + W_b Phi_b) / mu cancels near the held boundary DOFs (measured:
        # the first solve of a 1e5-DOF bar missed the refinement test by 30x that way)
        ZX = UWb.T
        Zc = np.empty((nb + m, nb + m), dtype=complex)
        Zc[:nb, :nb] = Zbb - Zbi @ Wb[pat.R] if nb else Zbb
        Zc[:nb, nb:] = (self.Ub - ZX) * gd
        Zc[nb:, :nb] = self.Ub.T - UWb
        Zc[nb:, nb:] = -np.eye(m) - UX * gd
        if not self.keep_w:
            return Zc
        inv_mu = 1.0 / mu_ok
        inv_mu[bad] = 0.0
        Xbad = np.ascontiguousarray(W[:, nb + ns:], dtype=complex) if bad.size else None
        WS = np.ascontiguousarray(W[:, nb:nb + ns], dtype=complex) if ns else None
        return Zc, Wb, (inv_mu, bad, Xbad, WS, c)

    def apply_x(self, blk: _Harmonic, V: np.ndarray) -> np.ndarray:
        """``Z_II^-1 U_I V`` (complex ``V``, ``m x k``) of one harmonic from the modes relation
        of :meth:`_condense_modes`, ``Z_II^-1 U_I = (Phi_I + W_b Phi_b + c Z_II^-1 E_I) diag(1/mu)``
        (the columns at ``k w`` near a mode's frequency solved directly): products, no solve."""
        PhiI, Phib, _, _, _, ES = self.modes
        inv_mu, bad, Xbad, WS, c = blk.Xm
        Vm = np.ascontiguousarray(V * inv_mu[:, None], dtype=complex)
        X = _real_times_complex(PhiI, Vm)
        if blk.W is not None and blk.W.shape[1]:
            X += blk.W @ (Phib @ Vm)
        if WS is not None:
            X += WS @ (c * (ES @ Vm))
        if Xbad is not None:
            X += Xbad @ V[bad]
        return X

    def rows_x(self, blk: _Harmonic, L: np.ndarray) -> np.ndarray:
        """``L Z_II^-1 U_I`` (complex ``L``, ``r x n_I``) by the relation of :meth:`apply_x`."""
        PhiI, Phib, _, _, _, ES = self.modes
        inv_mu, bad, Xbad, WS, c = blk.Xm
        out = _real_times_complex(PhiI.T, np.ascontiguousarray(L.T, dtype=complex)).T
        if blk.W is not None and blk.W.shape[1]:
            out = out + (L @ blk.W) @ Phib
        if WS is not None:
            out = out + c * ((L @ WS) @ ES)
        out = out * inv_mu
        if Xbad is not None:
            out[:, bad] = L @ Xbad
        return out

    def map(self, fun):
        """Apply ``fun(block)`` to all harmonics (threaded like the factorisation)."""
        if self.threads > 1:
            with ThreadPoolExecutor(self.threads) as ex:
                return list(ex.map(fun, self.blocks))
        return [fun(b) for b in self.blocks]

    def map_index(self, fun):
        """Apply ``fun(i)`` for the index ``i`` of every harmonic block (threaded like :meth:`map`)."""
        idx = range(len(self.blocks))
        if self.threads > 1:
            with ThreadPoolExecutor(self.threads) as ex:
                return list(ex.map(fun, idx))
        return [fun(i) for i in idx]


# --------------------------------------------------------------------------------------------
# the structured Jacobian
# --------------------------------------------------------------------------------------------
class HarmonicBlockJacobian:
    """HBM Jacobian kept as harmonic blocks + nonlinear part + dense borders (see module doc).

    Behaves like a square matrix for the solvers: ``shape``, ``J @ x``, ``scalar * J``,
    :meth:`tocsr` / :meth:`toarray` (the assembled matrix: fallback and checks),
    :meth:`bordered` (append rows and columns), :meth:`factorize` (the structured solve).
    """

    def __init__(self, system: BlockStructure, omega: float, xi: float, N: sp.csr_matrix, *, scale: float = 1.0,
                 U: np.ndarray | None = None, V: np.ndarray | None = None, D: np.ndarray | None = None):
        self.system = system
        self.omega = float(omega)
        self.xi = float(xi)
        self.N = N
        self.scale = float(scale)
        n = system.size
        self.U = np.zeros((n, 0)) if U is None else np.asarray(U, dtype=float)
        self.V = np.zeros((0, n)) if V is None else np.asarray(V, dtype=float)
        m = self.U.shape[1]
        self.D = np.zeros((0, 0)) if D is None else np.asarray(D, dtype=float).reshape(m, m)
        self.shape = (n + m, n + m)
        self.dtype = np.dtype(float)

    # -- matrix-like behaviour -----------------------------------------------------------------
    @property
    def n_border(self) -> int:
        return self.U.shape[1]

    def _replace(self, **kw) -> HarmonicBlockJacobian:
        d = dict(scale=self.scale, U=self.U, V=self.V, D=self.D)
        d.update(kw)
        return HarmonicBlockJacobian(self.system, self.omega, self.xi, self.N, **d)

    def __mul__(self, f):
        if not np.isscalar(f):
            return NotImplemented
        f = float(f)
        return self._replace(scale=self.scale * f, U=self.U * f, V=self.V * f, D=self.D * f)

    __rmul__ = __mul__

    def bordered(self, cols, rows, corner) -> HarmonicBlockJacobian:
        """``[[J, cols], [rows, corner]]`` with ``cols`` of shape ``(n, k)``, ``rows`` ``(k, n)``."""
        n0, m0 = self.system.size, self.n_border
        cols = np.asarray(cols, dtype=float).reshape(self.shape[0], -1)
        k = cols.shape[1]
        rows = np.asarray(rows, dtype=float).reshape(k, self.shape[0])
        corner = np.asarray(corner, dtype=float).reshape(k, k)
        U = np.hstack([self.U, cols[:n0]])
        V = np.vstack([self.V, rows[:, :n0]])
        D = np.block([[self.D, cols[n0:]], [rows[:, n0:], corner]]) if m0 else corner
        return self._replace(U=U, V=V, D=D)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.ndim == 2:
            return np.column_stack([self.matvec(x[:, j]) for j in range(x.shape[1])])
        s = self.system
        n0 = s.size
        y = np.empty(self.shape[0])
        y[:n0] = self.scale * (self.N @ x[:n0])
        y[: s.nq] += self.scale * s.apply_linear(x[: s.nq], self.omega, self.xi)
        y[:n0] += self.U @ x[n0:]
        y[n0:] = self.V @ x[:n0] + self.D @ x[n0:]
        return y

    def __matmul__(self, x):
        return self.matvec(x)

    def dot(self, x):
        return self.matvec(x)

    def abs_matvec(self, v: np.ndarray) -> np.ndarray:
        """An upper bound of ``|J| |v|`` (for backward-error tolerances)."""
        s = self.system
        v = np.abs(np.asarray(v, dtype=float))
        n0 = s.size
        y = np.empty(self.shape[0])
        y[:n0] = abs(self.scale) * (abs(self.N) @ v[:n0])
        y[: s.nq] += abs(self.scale) * s.apply_linear(v[: s.nq], self.omega, self.xi, absolute=True)
        y[:n0] += np.abs(self.U) @ v[n0:]
        y[n0:] = np.abs(self.V) @ v[:n0] + np.abs(self.D) @ v[n0:]
        return y

    def all_finite(self) -> bool:
        return bool(np.all(np.isfinite(self.N.data)) and np.isfinite(self.omega) and np.isfinite(self.xi)
                    and np.all(np.isfinite(self.U)) and np.all(np.isfinite(self.V)) and np.all(np.isfinite(self.D)))

    def tocsr(self) -> sp.csr_matrix:
        """The assembled sparse matrix (generic fallback and checks)."""
        return self._assemble(self.system.linear_operator(self.omega))

    def tocsc(self) -> sp.csc_matrix:
        return self.tocsr().tocsc()

    def _sparse_core(self) -> sp.csr_matrix:
        """``J`` (with its borders) without the low-rank damping: the sparse part of ``S(w)``."""
        s = self.system
        return self._assemble((self.omega * self.omega) * s.A2 + self.omega * s._kron("A1s", s.D1, s.C) + s.A0)

    def _assemble(self, S: sp.spmatrix) -> sp.csr_matrix:
        """``J`` with the linear operator ``S`` (its artificial damping, contact-force rows, scale,
        nonlinear part and borders added)."""
        s = self.system
        if self.xi:
            S = S - (self.xi * self.omega) * s.AM
        if s.np:
            S = sp.block_diag([S, sp.csr_matrix((s.np, s.np))], format="csr")
        core = (self.scale * (S + self.N)).tocsr()
        if not self.n_border:
            return core
        return sp.bmat([[core, sp.csr_matrix(self.U)], [sp.csr_matrix(self.V), sp.csr_matrix(self.D)]], format="csr")

    def augmented(self) -> sp.csr_matrix | None:
        """With modal damping ``U diag(d) U^T``: the sparse matrix ``[[J_sparse, s B], [I x U^T,
        -I]]`` (``B = w (D1 x U diag(d))``, :meth:`HBMSystem.lowrank_border`) whose leading block
        of the solution of ``[b; 0]`` solves ``J x = b``; None without a low-rank part."""
        s = self.system
        border = s.lowrank_border(self.omega) if getattr(s, "C_lr", None) is not None else None
        if border is None:
            return None
        Bc, Ur = border
        r, m = Ur.shape[0], self.n_border
        pad_r = sp.csr_matrix((m, r))
        cols = sp.vstack([self.scale * Bc, sp.csr_matrix((s.np, r)), pad_r], format="csr")
        rows = sp.hstack([Ur, sp.csr_matrix((r, s.np + m))], format="csr")
        return sp.bmat([[self._sparse_core(), cols], [rows, -sp.identity(r, format="csr")]], format="csr")

    @property
    def nnz(self) -> int:
        """Stored entries: of the assembled matrix, or with modal damping of its sparse part plus
        the low-rank factors ``U, d`` (what the solvers use; :meth:`tocsr` would be dense)."""
        lr = getattr(self.system, "C_lr", None)
        if lr is None:
            return int(self.tocsr().nnz)
        return int(self._sparse_core().nnz + lr.nnz)

    def toarray(self) -> np.ndarray:
        """The assembled dense matrix (up to :data:`DENSE_OPERATORS_MAX` displacement coefficients:
        from the system's cached dense operators, no sparse matrix built)."""
        s = self.system
        if getattr(s, "nq", math.inf) > DENSE_OPERATORS_MAX or not hasattr(s, "dense_linear_operator"):
            return self.tocsr().toarray()
        n0, nq = s.size, s.nq
        A = np.zeros(self.shape)
        A[:nq, :nq] = s.dense_linear_operator(self.omega, self.xi)
        A[:n0, :n0] += self.N.toarray()
        if self.scale != 1.0:
            A[:n0, :n0] *= self.scale
        if self.n_border:
            A[:n0, n0:] = self.U
            A[n0:, :n0] = self.V
            A[n0:, n0:] = self.D
        return A

    def __repr__(self) -> str:
        return (f"HarmonicBlockJacobian(size={self.shape[0]}, omega={self.omega:.6g}, xi={self.xi:.3g}, "
                f"border={self.n_border})")

    # -- solve ------------------------------------------------------------------------------------
    def factorize(self, *, threads: int | None = None):
        """Factorisation with a ``solve(b)`` method, by the system's solver strategy
        (:class:`BlockSolver` or :class:`AssembledSolver`).

        Raises ``RuntimeError`` if the matrix is singular.
        """
        return self.system.solver.factorize(self, threads=threads)

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.factorize().solve(b)


class _ReuseState:
    """What a :class:`BlockSolver` remembers of one system: the factors it used last and the
    contraction per unit relative frequency offset measured by the last reused solve."""

    __slots__ = ("F", "rate", "__weakref__")

    def __init__(self):
        self.F = None
        self.rate = None


#: Counters of :attr:`BlockSolver.stats`.
STAT_KEYS = ("factorizations", "reused", "solves_reused", "passes", "refactorized")


class BlockSolver:
    """Linear solver strategy of the harmonic balance (the default): per-harmonic band LU of the
    linear DOFs and a dense Schur complement on the nonlinear DOFs and borders (module
    docstring); systems up to :data:`DENSE_MAX_SIZE` unknowns (or below
    :data:`STRUCTURED_MIN_SIZE` and at least :data:`DENSE_FILL` full) are assembled densely for LAPACK,
    larger ones below :data:`STRUCTURED_MIN_SIZE`, and blocks that cannot be factorised (an
    interior resonance), go to SuperLU on the assembled matrix.

    Parameters
    ----------
    reuse : bool, default False
        Reuse the per-harmonic factors of a nearby frequency (module docstring, "Reused
        factors"): a Jacobian at ``w`` within ``reuse_window`` (relative) of the frequency ``w0``
        of the factors this solver used last for the same system (and at the same ``xi``: the
        damping unknown of nonlinear modes changes them too) is solved with them as a
        preconditioner, refined against the true Jacobian to the backward-error test of a fresh
        factorisation (and a forward one), and factorised at ``w`` when the refinement would need
        more passes than a factorisation costs. The continuation corrector changes ``w`` at every
        iteration; at a fixed ``w`` (cache hit) nothing changes. Off by default: on the bars of
        ``benchmarks/README_corrector.md`` (1e4-1e5 DOFs, H = 10) it saved 2-33 % of the
        factorisations but no time (+2 % to +11 % per point against ``False``).
    reuse_window : float, default 0.05
        Largest ``|w - w0| / |w0|`` tried.
    max_passes : int, optional
        Passes (solves with the reused factors) allowed per solve; default from the cost model
        of :meth:`passes_budget`.

    Attributes
    ----------
    stats : dict
        Counters since construction (or :meth:`reset_stats`): ``factorizations`` (per-harmonic
        factor sets built through this solver), ``reused`` (factorisations served by factors of
        another frequency), ``solves_reused`` and ``passes`` (solves with them and their passes),
        ``refactorized`` (solves whose refinement did not contract fast enough: factorised
        afresh).
    """

    def __init__(self, *, reuse: bool = False, reuse_window: float = 0.05, max_passes: int | None = None):
        if not isinstance(reuse, (bool, np.bool_)):
            raise TypeError(f"reuse must be True or False, got {reuse!r}")
        if not (isinstance(reuse_window, (int, float)) and 0.0 <= float(reuse_window) < 1.0):
            raise ValueError(f"reuse_window must be in [0, 1), got {reuse_window!r}")
        if max_passes is not None and (not isinstance(max_passes, (int, np.integer)) or max_passes < 1):
            raise ValueError(f"max_passes must be a positive integer or None, got {max_passes!r}")
        self.reuse = bool(reuse)
        self.reuse_window = float(reuse_window)
        self.max_passes = None if max_passes is None else int(max_passes)
        self._states: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self.stats = dict.fromkeys(STAT_KEYS, 0)

    def reset_stats(self) -> None:
        self.stats = dict.fromkeys(STAT_KEYS, 0)

    def __getstate__(self):
        d = dict(self.__dict__)
        d["_states"] = None  # factors are not pickled
        return d

    def __setstate__(self, d):
        self.__dict__.update(d)
        self._states = weakref.WeakKeyDictionary()

    def factorize(self, J: HarmonicBlockJacobian, *, threads: int | None = None):
        n = J.shape[0]
        if n <= DENSE_MAX_SIZE or (n < STRUCTURED_MIN_SIZE and J.N.nnz >= DENSE_FILL * n * n):
            return _Dense(J)
        if n < STRUCTURED_MIN_SIZE:
            return _Generic(J)
        try:
            state = self._state(J.system)
            F = self._reusable(J, state)
            if F is not None:
                try:
                    fac = _Factorization(J, threads, F, reuse=(self, state))
                except (StructureFailure, RuntimeError) as exc:  # P singular where J need not be
                    log.debug("reused factors not applicable (%s); factorising at w", exc)
                else:
                    if not fac.exact:
                        self.stats["reused"] += 1
                    return fac
            return self._fresh(J, threads, state)
        except StructureFailure as exc:
            log.debug("structured HBM factorisation not applicable (%s); SuperLU on the assembled matrix", exc)
            return _Generic(J)

    # -- reuse ------------------------------------------------------------------------------
    def _state(self, system) -> _ReuseState | None:
        try:
            st = self._states.get(system)
            if st is None:
                st = self._states[system] = _ReuseState()
            return st
        except TypeError:  # not weak-referenceable / hashable: no reuse
            return None

    def _fresh(self, J: HarmonicBlockJacobian, threads: int | None, state: _ReuseState | None) -> _Factorization:
        """The exact factorisation at ``(J.omega, J.xi)`` (the system's cached factors if they are
        at that frequency); they become the base of later reuse."""
        F = J.system.linear_factors(J.omega, J.xi, threads)
        if state is not None and F is not state.F:
            self.stats["factorizations"] += 1
            state.F = F
        return _Factorization(J, threads, F)

    def _reusable(self, J: HarmonicBlockJacobian, state: _ReuseState | None):
        """The factors to solve ``J`` with if they are at another, close frequency and the last
        measured contraction predicts a refinement within budget; else None."""
        if not self.reuse or state is None or state.F is None:
            return None
        F0 = state.F
        if F0.xi != J.xi or F0.pat is not J.system.block_pattern():
            return None
        if F0.omega == J.omega:
            return F0
        if F0.omega == 0.0:
            return None
        dw = abs(J.omega - F0.omega) / abs(F0.omega)
        if not dw <= self.reuse_window:
            return None
        if state.rate is not None:  # passes predicted from the last measured contraction
            q = state.rate * dw
            budget = self.max_passes if self.max_passes is not None else _budget_from_factors(F0, J)
            if q >= 0.5 or max(2, math.ceil(math.log(REUSE_FORWARD_TOL) / math.log(q))) > budget:
                return None
        return F0

    def passes_budget(self, fac: _Factorization) -> int:
        """Passes a reused solve may take before it refactorises: ``max_passes``, or the cost
        model of :func:`_budget_from_factors`."""
        if self.max_passes is not None:
            return self.max_passes
        return _budget_from_factors(fac.F, fac.J)

    def _record(self, state: _ReuseState, fac: _Factorization, passes: int, worst: float, ok: bool) -> None:
        self.stats["solves_reused"] += 1
        self.stats["passes"] += passes
        dw = abs(fac.J.omega - fac.F.omega) / abs(fac.F.omega)
        if dw > 0 and worst > 0:
            state.rate = worst / dw  # contraction per unit relative offset, for the next prediction
        if not ok:
            self.stats["refactorized"] += 1

    def __repr__(self) -> str:
        args = []
        if self.reuse:
            args.append("reuse=True")
        if self.reuse_window != 0.05:
            args.append(f"reuse_window={self.reuse_window!r}")
        if self.max_passes is not None:
            args.append(f"max_passes={self.max_passes!r}")
        return f"BlockSolver({', '.join(args)})"


def _budget_from_factors(F: LinearFactors, J: HarmonicBlockJacobian) -> int:
    """Passes of a reused solve that cost what refactorising and one exact pass cost.

    Cost per harmonic block in single-column band solves (measured on tridiagonal blocks of 1e4
    DOFs, ``benchmarks/README_corrector.md``): refactorising ``REUSE_LU_COST`` (band assembly,
    ``?gbtrf``, condensed stiffness) plus the condensation columns, ``0.45 + 0.55 n_b`` (one
    multi-column call); a pass one solve with ``W`` kept, two without, plus
    ``REUSE_PASS_OVERHEAD`` (products, Schur solve, residual update); the exact path's pass
    also checks ``J x`` (``REUSE_MATVEC_COST``)."""
    pat = F.pat
    nb = pat.bdofs.size
    lu = REUSE_LU_COST if pat.banded else REUSE_LU_COST_SPARSE
    per_pass = (1.0 if F.keep_w else 2.0) + REUSE_PASS_OVERHEAD
    exact = lu + (0.45 + 0.55 * nb if nb else 0.0) + per_pass + REUSE_MATVEC_COST
    return max(1, int(exact // per_pass))


class AssembledSolver:
    """Linear solver strategy: SuperLU on the assembled sparse Jacobian, whatever its size (for
    checks and comparisons with :class:`BlockSolver`)."""

    def factorize(self, J: HarmonicBlockJacobian, *, threads: int | None = None):
        return _Generic(J)

    def __repr__(self) -> str:
        return "AssembledSolver()"


def _refinement_tolerance(norm: float, x: np.ndarray, scale_b: float) -> float:
    """The backward-error test of the refined solves (:class:`_Factorization`,
    :class:`_ForceSchur`): ``64 eps (||J|| max|x| + max|b|)`` with a bound ``norm`` of ``||J||``."""
    return 64 * np.finfo(float).eps * (norm * float(np.max(np.abs(x))) + scale_b)


class _Dense:
    """LAPACK LU (partial pivoting) of the densely assembled matrix: for small systems the sparse
    machinery's per-call overhead (building CSR matrices, SuperLU's symbolic phase) is what a
    Newton step costs (measured: seed contact case, 83 unknowns, 4.3 of 5.0 ms per factorisation
    in assembling the sparse matrix). From :data:`SCHUR_MIN_SIZE` unknowns on (half-full
    systems, :data:`DENSE_FILL`) the displacements are eliminated first when they can be
    (:class:`_ForceSchur`)."""

    def __init__(self, J: HarmonicBlockJacobian):
        A = J.toarray()
        if not np.all(np.isfinite(A)):
            raise RuntimeError("matrix has non-finite entries")
        self.A = A
        self.schur = _ForceSchur.build(J, A) if A.shape[0] >= SCHUR_MIN_SIZE else None
        self.lu = None
        if self.schur is None:
            self._factor()

    def _factor(self) -> None:
        self.lu = sla.lu_factor(self.A, check_finite=False)
        if np.any(np.diagonal(self.lu[0]) == 0.0):
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


class _ForceSchur:
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
    elimination and the LU of the forces (:data:`SCHUR_MIN_SIZE`).

    Pivoting is only within the harmonic blocks and within the Schur complement, so no block may
    be near singular (``k w`` on an eigenfrequency of the undamped structure, as for an undamped
    nonlinear mode at low energy): if the Schur complement's entries grow by more than
    :data:`SCHUR_MAX_GROWTH` over those of the blocks, nothing is eliminated (:meth:`build`
    returns None), and a solve whose backward error after two refinement steps still exceeds
    the test of :class:`_Factorization` is redone by the plain LU (:meth:`solve` returns None).
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
    def build(cls, J: HarmonicBlockJacobian, A: np.ndarray) -> _ForceSchur | None:
        s = J.system
        nq, n, n_uc = getattr(s, "nq", 0), getattr(s, "n", 0), getattr(s, "n_uc", 0)
        h = getattr(s, "h", None)
        if not (n_uc and nq and h is not None and h.n_harmonics):
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
        rows = np.stack([h.cos_rows(k), h.sin_rows(k)], axis=1)             # (H, 2)
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
        if not float(np.abs(T).max()) <= SCHUR_MAX_GROWTH * scale:  # also catches non-finite entries
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
            tol = _refinement_tolerance(self.norm, x, scale_b)
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


class _Generic:
    """SuperLU on the assembled matrix; with modal damping on the sparse augmented matrix
    ``[[J_sparse, s B], [I x U^T, -I]]`` (:meth:`HarmonicBlockJacobian.augmented`), whose extra
    unknowns are the modal coordinates: the dense ``U diag(d) U^T`` is never assembled."""

    def __init__(self, J: HarmonicBlockJacobian):
        A = J.augmented()
        self.n = J.shape[0]
        self.extra = 0 if A is None else A.shape[0] - self.n
        self.lu = spla.splu(J.tocsc() if A is None else A.tocsc())

    def solve(self, b):
        b = np.asarray(b, dtype=float)
        if not self.extra:
            return self.lu.solve(b)
        pad = np.zeros((self.extra,) + b.shape[1:])
        return self.lu.solve(np.concatenate([b, pad], axis=0))[: self.n]


class _Factorization:
    """Structured LU of a :class:`HarmonicBlockJacobian` (interior blocks + dense Schur complement).

    ``F`` (default: the system's factors at ``(J.omega, J.xi)``) may be factors at another
    frequency ``w0`` (:class:`BlockSolver` ``reuse``): this is then the exact factorisation of
    ``P = J`` with its linear part ``S(w0)`` instead of ``S(w)``, and :meth:`solve` iterates
    ``x <- x + P^-1 (b - J x)`` to the same backward-error test as the exact path (module
    docstring, "Reused factors"); ``reuse`` is then the ``(solver, state)`` pair that records the
    contraction and refactorises when it is too slow.
    """

    def __init__(self, J: HarmonicBlockJacobian, threads: int | None, F: LinearFactors | None = None,
                 reuse: tuple | None = None):
        self.J = J
        s = J.system
        self.s = s
        self.threads = threads
        self.F = F = s.linear_factors(J.omega, J.xi, threads) if F is None else F
        self.exact = F.omega == J.omega and F.xi == J.xi
        self.reuse = None if self.exact else reuse
        self.refactored = None  # the exact factorisation, once the safeguard has built it
        pat = F.pat
        h, n = s.h, s.n
        nc, nb, npv, m = h.n_coef, pat.bdofs.size, s.np, J.n_border
        self.nc, self.nb, self.m = nc, nb, m
        # global indices of the boundary unknowns: q of nonlinear DOFs (coef-major), p, border
        self.gq = (np.arange(nc)[:, None] * n + pat.bdofs[None, :]).ravel()
        self.gB = np.concatenate([self.gq, s.nq + np.arange(npv)])
        # Schur complement layout: [q_b | p | modal coordinates (nc x rank, coef-major) | border]
        self.mr = F.rank
        self.off_y = self.gB.size
        self.off_m = self.off_y + nc * self.mr
        nB = self.off_m + m
        self.nB = nB
        T = self._boundary_block()
        self._add_condensed_stiffness(T)
        # the leaner solve path (the interior solutions of the border columns kept, W = Z_II^-1
        # Z_Ib used where kept): without modal damping, and with it when every harmonic kept W and
        # the pieces of Z_II^-1 U_I (LinearFactors.apply_x)
        self.lean = not self.mr or bool(pat.perm.size and all(blk.Xm is not None for blk in F.blocks))
        self._Zu = self._vc = None
        if m and pat.perm.size:
            if self.lean:
                self._add_border_coupling_lean(T)
            else:
                self._add_border_coupling(T)
        if not np.all(np.isfinite(T)):
            raise StructureFailure("non-finite Schur complement")
        self.norm_bound = self._norm_bound()
        self.T = T
        self.ymodal = self._eliminate_modal(T) if self.mr else None
        if self.ymodal is not None:
            self._factor_schur(self.ymodal[0])
        elif nB:
            self._factor_schur(T)

    # -- Schur complement assembly ------------------------------------------------------------
    def _qpos(self, row: int) -> np.ndarray:
        """Positions in the Schur complement of the nonlinear DOFs at coefficient row ``row``."""
        return row * self.nb + np.arange(self.nb)

    def _ypos(self, row: int) -> np.ndarray:
        """Positions of the modal coordinates (modal damping) at coefficient row ``row``."""
        return self.off_y + row * self.mr + np.arange(self.mr)

    def _hpos(self, row: int) -> np.ndarray:
        """Positions of the condensed block of one coefficient row: nonlinear DOFs, then modal
        coordinates (the rows and columns of ``_Harmonic.Zc``)."""
        if not self.mr:
            return self._qpos(row)
        return np.concatenate([self._qpos(row), self._ypos(row)])

    def _boundary_block(self) -> np.ndarray:
        """``J[B, B]`` without its linear part: the nonlinear part and the border entries."""
        J, nB, nG, om = self.J, self.nB, self.gB.size, self.off_m
        T = np.zeros((nB, nB))
        # nonlinear part on the boundary (N is zero elsewhere by construction)
        NB = J.N[self.gB][:, self.gB]
        T[:nG, :nG] = J.scale * NB.toarray()
        # border entries on the boundary (the modal coordinates have none)
        if self.m:
            T[:nG, om:] = J.U[self.gB]
            T[om:, :nG] = J.V[:, self.gB]
            T[om:, om:] = J.D
        return T

    def _add_condensed_stiffness(self, T: np.ndarray) -> None:
        """Linear condensed stiffness per harmonic, real form ``[[X, Y], [-Y, X]]`` on ``(a, b)``."""
        sc, qpos = self.J.scale, self._hpos
        for blk in self.F.blocks:
            Zc = sc * blk.Zc
            ic = qpos(blk.k)
            T[np.ix_(ic, ic)] += Zc.real
            if blk.s is not None:
                is_ = qpos(blk.s)
                T[np.ix_(ic, is_)] += Zc.imag
                T[np.ix_(is_, ic)] -= Zc.imag
                T[np.ix_(is_, is_)] += Zc.real

    def _border_solves(self, blk: _Harmonic, Ui: np.ndarray, Vi: np.ndarray):
        """Interior solves of one harmonic against the border columns ``Ui`` and rows ``Vi``."""
        R = self.F.pat.R
        # columns: z = Z^-1 (u_c - i u_s); interior solution (Re z, -Im z)
        rho = Ui[blk.k] - (1j * Ui[blk.s] if blk.s is not None else 0.0)
        z = blk.lu.solve(rho)
        # rows: y = Z^-T (v_c + i v_s); v^T R^-1 = (Re, Im) of y^T
        mu = Vi[:, blk.k, :].T + (1j * Vi[:, blk.s, :].T if blk.s is not None else 0.0)
        y = blk.lu.solve(mu, trans=True)
        out = {}
        # T[q_b rows, border cols] -= real form of Z_bI z  (scale: s * (1/s))
        Wz = blk.Zbi @ z[R]
        out["qb_m"] = Wz
        # T[border rows, q_b cols] -= (Re, Im) of y^T Z_Ib
        yZ = (blk.Zib.T @ y[R]).T  # (m, nb)
        out["m_qb"] = yZ
        # T[border, border] -= v_I . (interior solution) / s
        vu = Vi[:, blk.k, :] @ z.real
        if blk.s is not None:
            vu = vu + Vi[:, blk.s, :] @ (-z.imag)
        out["m_m"] = vu
        if self.mr:
            F = self.F
            # modal rows: T[y, border] -= U_I^T z; modal columns: T[border, y] -= y^T (i b U_I d)
            out["y_m"] = _real_times_complex(F.UI.T, z)
            out["m_y"] = _real_times_complex(F.UI.T, y).T * (1j * blk.b * F.d)
        return blk, out

    def _add_border_coupling(self, T: np.ndarray) -> None:
        """Border coupling through the interior: ``-J_BI J_II^-1 J_IB`` for the border rows/columns."""
        J, s, qpos = self.J, self.s, self._qpos
        nc, n, m = self.nc, s.n, self.m
        I = self.F.pat.interior
        Ui = J.U[: s.nq].reshape(nc, n, m)[:, I, :]       # (nc, nI, m)
        Vi = J.V[:, : s.nq].reshape(m, nc, n)[:, :, I]    # (m, nc, nI)
        off = self.off_m
        for blk, out in self.F.map(lambda blk: self._border_solves(blk, Ui, Vi)):
            Wz = out["qb_m"]
            T[np.ix_(qpos(blk.k), off + np.arange(m))] -= Wz.real
            if blk.s is not None:
                T[np.ix_(qpos(blk.s), off + np.arange(m))] -= -Wz.imag
            yZ = out["m_qb"]
            T[np.ix_(off + np.arange(m), qpos(blk.k))] -= yZ.real
            if blk.s is not None:
                T[np.ix_(off + np.arange(m), qpos(blk.s))] -= yZ.imag
            T[off:, off:] -= out["m_m"] / J.scale
            if self.mr:
                yk, ym = self._ypos(blk.k), off + np.arange(m)
                T[np.ix_(yk, ym)] -= out["y_m"].real
                T[np.ix_(ym, yk)] -= out["m_y"].real
                if blk.s is not None:
                    ys = self._ypos(blk.s)
                    T[np.ix_(ys, ym)] -= -out["y_m"].imag
                    T[np.ix_(ym, ys)] -= out["m_y"].imag

    def _add_border_coupling_lean(self, T: np.ndarray) -> None:
        """:meth:`_add_border_coupling` without modal damping, keeping the interior solutions
        ``Z_II^-1 (u_c - i u_s)`` of the border columns for the back substitution of :meth:`_solve`
        and, where ``W = Z_II^-1 Z_Ib`` is kept, the border rows ``v^T Z_II^-1 Z_Ib = v^T W`` by a
        product instead of a transposed solve."""
        J, s, qpos, pat = self.J, self.s, self._qpos, self.F.pat
        nc, n, m = self.nc, s.n, self.m
        I, R = pat.interior, pat.R
        Ui = J.U[: s.nq].reshape(nc, n, m)[:, I, :]       # (nc, nI, m)
        Vi = J.V[:, : s.nq].reshape(m, nc, n)[:, :, I]    # (m, nc, nI)

        def one(blk: _Harmonic):
            rho = Ui[blk.k] - (1j * Ui[blk.s] if blk.s is not None else 0.0)
            z = blk.lu.solve(rho)                                          # (nI, m)
            vc = Vi[:, blk.k, :] + (1j * Vi[:, blk.s, :] if blk.s is not None else 0.0)  # (m, nI)
            if not self.nb:
                yZ = np.zeros((m, 0))
            elif blk.W is not None:
                yZ = vc @ blk.W                                            # v^T Z^-1 Z_Ib
            else:
                y = blk.lu.solve(vc.T, trans=True)
                yZ = (blk.Zib.T @ y[R]).T
            if not self.mr:
                return z, vc, blk.Zbi @ z[R], yZ, (vc @ z).real, None, None
            # modal rows U_I^T z; modal columns v^T Z_II^-1 (i b U_I d) = (Z_II^-1 U_I)^T v ... by
            # the symmetry of Z (no sparse damping part, as in _condense_modes): products only
            F = self.F
            ym = _real_times_complex(F.UI.T, z)
            my = F.rows_x(blk, vc) * (1j * blk.b * F.d)
            return z, vc, blk.Zbi @ z[R], yZ, (vc @ z).real, ym, my

        out = self.F.map(one)
        self._Zu = [o[0] for o in out]
        self._vc = [o[1] for o in out]
        off = self.off_m
        bm = off + np.arange(m)
        for blk, (_, _, Wz, yZ, vu, ym, my) in zip(self.F.blocks, out):
            T[np.ix_(qpos(blk.k), bm)] -= Wz.real
            T[np.ix_(bm, qpos(blk.k))] -= yZ.real
            if blk.s is not None:
                T[np.ix_(qpos(blk.s), bm)] += Wz.imag
                T[np.ix_(bm, qpos(blk.s))] -= yZ.imag
            T[off:, off:] -= vu / J.scale
            if ym is not None:  # as in _add_border_coupling
                yk = self._ypos(blk.k)
                T[np.ix_(yk, bm)] -= ym.real
                T[np.ix_(bm, yk)] -= my.real
                if blk.s is not None:
                    ys = self._ypos(blk.s)
                    T[np.ix_(ys, bm)] += ym.imag
                    T[np.ix_(bm, ys)] -= my.imag

    def _eliminate_modal(self, T: np.ndarray):
        """Eliminate the modal coordinates from ``T`` harmonic by harmonic: they couple only to the
        nonlinear DOFs of their harmonic and to the borders, so ``T_yy`` is block diagonal and
        the dense LU works on ``T_rr - T_ry T_yy^-1 T_yr``, the size it has with Rayleigh damping
        (at H = 10 the modal coordinates of 20 modes would make it 21x larger). The ``2m x 2m``
        blocks are inverted in one batched call. None (the full ``T`` is factorised, with its
        pivoting) if a block is ill-conditioned (condition number above 1e10)."""
        nB, oy, om = self.nB, self.off_y, self.off_m
        r = np.r_[0:oy, om:nB]
        # local indices of each harmonic's modal coordinates: the mean alone, then (cos, sin) pairs
        groups = [self._ypos(blk.k) - oy if blk.s is None else
                  np.concatenate([self._ypos(blk.k), self._ypos(blk.s)]) - oy for blk in self.F.blocks]
        Tyy = T[oy:om, oy:om]
        Tyr = T[oy:om][:, r]
        Y = np.empty((om - oy, r.size))
        invs = []
        for size in sorted({g.size for g in groups}):
            gs = np.array([g for g in groups if g.size == size])          # (n_blocks, size)
            B = Tyy[gs[:, :, None], gs[:, None, :]]                      # (n_blocks, size, size)
            try:
                inv = np.linalg.inv(B)
            except np.linalg.LinAlgError:
                return None
            cond = np.abs(B).sum(axis=2).max(axis=1) * np.abs(inv).sum(axis=2).max(axis=1)
            if not np.all(np.isfinite(inv)) or np.any(cond > 1e10):
                return None
            Y[gs] = inv @ Tyr[gs]
            invs.append((gs, inv))
        Try = T[r][:, oy:om]
        Tr = T[np.ix_(r, r)] - Try @ Y
        return Tr, r, invs, Try, Y

    def _solve_schur(self, rhsB: np.ndarray) -> np.ndarray:
        """``T^-1 rhsB`` (with the modal coordinates eliminated first when they are)."""
        if self.ymodal is None:
            return sla.lu_solve(self.lu, rhsB, check_finite=False) if self.nB else rhsB
        _, r, invs, Try, Y = self.ymodal
        oy, om = self.off_y, self.off_m
        ry = rhsB[oy:om]
        zy = np.empty_like(ry)
        for gs, inv in invs:
            zy[gs] = inv @ ry[gs]
        xr = sla.lu_solve(self.lu, rhsB[r] - Try @ zy, check_finite=False)
        x = np.empty_like(rhsB)
        x[r] = xr
        x[oy:om] = zy - Y @ xr
        return x

    def _norm_bound(self) -> float:
        """``||J||_inf`` bound for the refinement test (row sums of ``|K|, |M|, |C - xi M|`` at the
        top harmonic)."""
        J, s = self.J, self.s
        h = s.h
        s_max = h.n_harmonics * J.omega / h.subharmonic
        pat = self.F.pat
        if pat.abs_row_sums is None:  # once per system (the pattern is cached there)
            pat.abs_row_sums = tuple(s.abs_row_sums())
        rK, rM, rC = pat.abs_row_sums
        lin = rK + s_max ** 2 * rM + s_max * (rC + abs(J.xi) * rM)
        rN = float(abs(J.N).sum(axis=1).max()) if J.N.nnz else 0.0
        return (abs(J.scale) * (lin + rN) + float(np.abs(J.U).sum(axis=1).max(initial=0.0))
                + float(np.abs(np.hstack([J.V, J.D])).sum(axis=1).max(initial=0.0)))

    def _factor_schur(self, T: np.ndarray) -> None:
        """Dense LU with partial pivoting of the Schur complement ``T``."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)  # zero pivots are checked below
            lu, piv = sla.lu_factor(T, check_finite=False)
        d = np.abs(np.diag(lu))
        if np.any(d == 0.0):
            raise RuntimeError("singular Jacobian (zero pivot in the condensed system)")
        self.lu = (lu, piv)
        self.rcond_est = float(d.min() / max(d.max(), 1e-300))

    # -- helpers on interior vectors -----------------------------------------------------------
    def _interior_solve(self, X: np.ndarray) -> np.ndarray:
        """``S_II^{-1}`` on real interior coefficient arrays ``X`` of shape (nc, nI, k)."""
        out = np.empty_like(X)

        def one(blk: _Harmonic):
            rho = X[blk.k] - (1j * X[blk.s] if blk.s is not None else 0.0)
            z = blk.lu.solve(rho)
            return blk, z

        for blk, z in self.F.map(one):
            out[blk.k] = z.real
            if blk.s is not None:
                out[blk.s] = -z.imag
        return out

    def solve(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=float)
        one_d = b.ndim == 1
        B = b.reshape(b.shape[0], -1)
        if self.refactored is not None:
            x = self.refactored.solve(B)
        elif self.exact:
            x = self._solve_refined(B)
        else:
            x = self._solve_reused(B)
        return x[:, 0] if one_d else x

    def _tolerance(self, x: np.ndarray, scale_b: float) -> float:
        return _refinement_tolerance(self.norm_bound, x, scale_b)

    def _solve_refined(self, B: np.ndarray) -> np.ndarray:
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
                log.debug("structured solve inaccurate (|res| = %.2e); SuperLU on the assembled matrix",
                          float(np.max(np.abs(res))))
                x = _Generic(J).solve(B)
        return x

    def _solve_reused(self, B: np.ndarray) -> np.ndarray:
        """``J x = B`` with the factors of ``P`` (linear part at ``w0``): ``x <- x + P^-1 (B - J x)``.

        Converged when the backward-error test of :meth:`_solve_refined` holds *and* the next
        correction, predicted from the contraction ``q = |d_j| / |d_(j-1)|`` of the last two,
        is below ``REUSE_FORWARD_TOL |x|``, or the corrections stopped shrinking (``q >= 1/2``
        after two of them: the round-off floor of an ill-conditioned ``J``, where the exact path's
        solution is no more accurate; Higham 2002, sec. 12.1). The residual test alone stops while
        the error in the directions that ``J`` nearly annihilates (the resonance being traced,
        where ``P^-1 J`` also departs most from the identity) is still ``~ q^j`` (measured:
        branch points off by 2.5e-8 in ``w`` on a 1e4-DOF bar, against 1e-10 between this solver
        and SuperLU). The residual of a pass is
        ``(P - J) d_j``, a product with the frequency-dependent part of ``S`` (no Jacobian
        product); the accepted ``x`` is checked once against the true ``J``. When the passes
        predicted for convergence exceed the solver's budget, or ``q >= 1/2`` (``k w`` near an
        eigenfrequency of the interior, where ``Z_II(w)^-1`` changes fast), the factors are
        rebuilt at ``w`` and the exact path solves ``B`` from scratch."""
        solver, state = self.reuse
        J = self.J
        scale_b = float(np.max(np.abs(B))) or 1.0
        budget = solver.passes_budget(self)
        eta = REUSE_FORWARD_TOL
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
                    solver._record(state, self, passes, max(worst, q if converged else 0.0), ok=True)
                    return x
                res = true  # drift of the cheap residual: continue with the true one
            if q >= 0.5:
                break
            worst = max(worst, q)
            if q > 0 and passes + math.log(eta * xn / max(q * dn, 1e-300)) / math.log(q) > budget:
                break
            d_prev = dn
        solver._record(state, self, passes, worst, ok=False)
        log.debug("reused factors (w0 = %.9g, w = %.9g): contraction %.2e after %d passes; refactorising",
                  self.F.omega, J.omega, worst, passes)
        self.refactored = solver._fresh(J, self.threads, state)
        return self.refactored.solve(B)

    def _residual_after(self, B: np.ndarray, x: np.ndarray, d: np.ndarray) -> np.ndarray:
        """``B - J x`` after the pass that solved ``P d = r`` (``r`` the previous residual) and set
        ``x <- x + d``: ``(P - J) d = s (S(w0) - S(w)) d`` on the displacement rows, up to the
        round-off of the solve with ``P`` (two sparse products, no Jacobian product). With modal
        damping, or without the system's ``M, C, D1``: ``B - J x`` itself."""
        J, s = self.J, self.s
        if self.mr or not all(hasattr(s, a) for a in ("M", "C", "D1")):
            return B - J.matvec(x)
        nc, n, k = self.nc, s.n, d.shape[1]
        w0, w, xi = self.F.omega, J.omega, J.xi
        ops = self.__dict__.get("_dense_d1")
        if ops is None:
            D1 = s.D1.toarray() if sp.issparse(s.D1) else np.asarray(s.D1, dtype=float)
            ops = self._dense_d1 = (D1.T, (D1 @ D1).T)
        D1T, D2T = ops
        QT = np.ascontiguousarray(d[: s.nq].reshape(nc, n, k).transpose(1, 0, 2)).reshape(n, nc * k)
        MQ = s.M @ QT
        CQ = s.C @ QT if s.C.nnz else np.zeros_like(MQ)
        if xi:
            CQ -= xi * MQ

        def rows(A):  # (n, nc k) -> (n k, nc): one GEMM with D1^T over the coefficient index
            return A.reshape(n, nc, k).transpose(0, 2, 1).reshape(n * k, nc)

        diff = rows(MQ) @ ((w0 * w0 - w * w) * D2T) + rows(CQ) @ ((w0 - w) * D1T)   # (n k, nc)
        out = np.zeros_like(d)
        out[: s.nq] = (J.scale * diff).reshape(n, k, nc).transpose(2, 0, 1).reshape(nc * n, k)
        return out

    def _solve(self, B: np.ndarray) -> np.ndarray:
        """One pass of the block elimination (no refinement)."""
        return self._solve_lean(B) if self.lean else self._solve_general(B)

    def _solve_lean(self, B: np.ndarray) -> np.ndarray:
        """:meth:`_solve_general` without modal damping, harmonic by harmonic in complex form: one
        band solve per harmonic where ``W = Z_II^-1 Z_Ib`` is kept (the back substitution is
        ``W x_b`` plus the kept interior solutions of the border columns), two otherwise."""
        J, s, pat = self.J, self.s, self.F.pat
        nc, n, m, k = self.nc, s.n, self.m, B.shape[1]
        n0, nb, sc = s.size, self.nb, J.scale
        I, R = pat.interior, pat.R
        nI = I.size
        x = np.zeros_like(B)
        mr, F = self.mr, self.F
        # (nB, k): q_b, p, modal coordinates (modal damping), border
        rhsB = np.concatenate([B[self.gB], np.zeros((nc * mr, k)), B[n0:]], axis=0)
        blocks = self.F.blocks
        if nI:
            bq = B[: s.nq].reshape(nc, n, k)
            inv_sc = 1.0 / sc
            vc = self._vc

            def forward(i: int):
                blk = blocks[i]
                rho = bq[blk.k][I] if blk.s is None else bq[blk.k][I] - 1j * bq[blk.s][I]
                z = blk.lu.solve(rho * inv_sc)
                w = (blk.Zbi @ z[R]) * sc if nb else None
                v = (vc[i] @ z).real if m else None
                ym = _real_times_complex(F.UI.T, np.ascontiguousarray(z, dtype=complex)) * sc if mr else None
                return z, w, v, ym

            fw = self.F.map_index(forward)
            for blk, (z, w, v, ym) in zip(blocks, fw):
                if mr:  # modal rows y = U^T q (real form): rhs_y -= s U_I^T y_I
                    rhsB[self._ypos(blk.k)] -= ym.real
                    if blk.s is not None:
                        rhsB[self._ypos(blk.s)] += ym.imag
                if nb:
                    rhsB[blk.k * nb + np.arange(nb)] -= w.real
                    if blk.s is not None:
                        rhsB[blk.s * nb + np.arange(nb)] += w.imag
                if m:
                    rhsB[self.off_m:] -= v
        xB = self._solve_schur(rhsB)
        x[self.gB] = xB[: self.gB.size]
        x[n0:] = xB[self.off_m:]
        if nI:
            xq = xB[: self.gq.size].reshape(nc, nb, k)
            xm = xB[self.off_m:] * inv_sc if m else None
            xy = xB[self.off_y:self.off_m].reshape(nc, mr, k) if mr else None
            Zu = self._Zu

            def back(i: int):
                blk = blocks[i]
                z = fw[i][0]
                if nb:
                    zc = xq[blk.k] if blk.s is None else xq[blk.k] - 1j * xq[blk.s]
                    if blk.W is not None:
                        z = z - blk.W @ zc
                    else:
                        full = np.zeros((nI, k), dtype=complex)
                        full[R] = blk.Zib @ zc
                        z = z - blk.lu.solve(full)
                if m:
                    z = z - Zu[i] @ xm
                if mr and blk.s is not None and blk.b != 0.0:
                    # Z_II^-1 (i b U_I d y) with y = y_c - i y_s, by products (LinearFactors.apply_x)
                    yc = xy[blk.k] - 1j * xy[blk.s]
                    z = z - F.apply_x(blk, (1j * blk.b * F.d)[:, None] * yc)
                return z

            bw = self.F.map_index(back)
            xq_all = x[: s.nq].reshape(nc, n, k)
            for blk, z in zip(blocks, bw):
                if np.iscomplexobj(z):
                    xq_all[blk.k, I] = z.real
                    if blk.s is not None:
                        xq_all[blk.s, I] = -z.imag
                else:
                    xq_all[blk.k, I] = z
        return x

    def _solve_general(self, B: np.ndarray) -> np.ndarray:
        """One pass of the block elimination, any damping (modal coordinates included)."""
        J, s, pat = self.J, self.s, self.F.pat
        nc, n, m, k = self.nc, s.n, self.m, B.shape[1]
        n0 = s.size
        sc = J.scale
        I = pat.interior
        nI = I.size
        x = np.zeros_like(B)
        rhsB = np.concatenate([B[self.gB], np.zeros((nc * self.mr, k)), B[n0:]], axis=0)  # (nB, k)
        mr, F = self.mr, self.F
        if nI:
            bI = B[: s.nq].reshape(nc, n, k)[:, I, :] / sc
            yI = self._interior_solve(bI)
            if mr:  # modal rows (real form y_c = U^T q_c on every coefficient row): rhs_y -= s U_I^T y_I
                rhsB[self.off_y:self.off_m] -= sc * np.matmul(F.UI.T, yI).reshape(nc * mr, k)
            # rhs_B -= J_BI y_I: q_b rows get s * S_bI y_I, border rows V_I y_I
            if self.nb:
                for blk in self.F.blocks:
                    yc = yI[blk.k] - (1j * yI[blk.s] if blk.s is not None else 0.0)
                    w = (blk.Zbi @ yc[pat.R]) * sc
                    rhsB[blk.k * self.nb + np.arange(self.nb)] -= w.real
                    if blk.s is not None:
                        rhsB[blk.s * self.nb + np.arange(self.nb)] -= -w.imag
            if m:
                Vi = J.V[:, : s.nq].reshape(m, nc, n)[:, :, I]
                rhsB[self.off_m:] -= np.einsum("mci,cik->mk", Vi, yI)
        xB = self._solve_schur(rhsB)
        x[self.gB] = xB[: self.gB.size]
        x[n0:] = xB[self.off_m:]
        if nI:
            # x_I = y_I - S_II^{-1} (S_Ib x_qb + U_I x_m / s)
            c = np.zeros((nc, nI, k))
            if self.nb:
                xq = xB[: self.gq.size].reshape(nc, self.nb, k)
                for blk in self.F.blocks:
                    zc = xq[blk.k] - (1j * xq[blk.s] if blk.s is not None else 0.0)
                    w = blk.Zib @ zc
                    c[blk.k, pat.R] += w.real
                    if blk.s is not None:
                        c[blk.s, pat.R] += -w.imag
            if mr:  # x_I -= Z_II^-1 (i b U_I d y): real form b U_I d y_s on cos rows, -b U_I d y_c on sin rows
                dy = F.d[None, :, None] * xB[self.off_y:self.off_m].reshape(nc, mr, k)
                for blk in F.blocks:
                    if blk.b == 0.0 or blk.s is None:
                        continue
                    c[blk.k] += F.UI @ (blk.b * dy[blk.s])
                    c[blk.s] -= F.UI @ (blk.b * dy[blk.k])
            if m:
                Ui = J.U[: s.nq].reshape(nc, n, m)[:, I, :]
                c += np.einsum("cim,mk->cik", Ui, xB[self.off_m:]) / sc
            xI = yI - self._interior_solve(c)
            xq_all = x[: s.nq].reshape(nc, n, k)
            xq_all[:, I, :] = xI
        return x
