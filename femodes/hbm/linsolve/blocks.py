"""Discretise layer: the interior/boundary split of the DOFs and the LU of one harmonic's interior block.

The DOFs split into the *interior* ``I`` (linear DOFs) and the *boundary* (the nonlinear DOFs).
The interior block ``Z_k[I, I]`` of harmonic ``k`` (the dynamic stiffness,
:class:`~femodes.dynamic_stiffness.DynamicStiffness`, at ``f = k w / nu``) is factorised by
LAPACK band LU (``?gbtrf``) after a reverse Cuthill-McKee ordering when the band is narrow (its
storage at most ``BlockSolverOptions.band_max_fill`` times the block's nonzeros: line meshes,
bandwidth 1-3, and the small dense interiors of reduced models), otherwise (2-D and 3-D meshes)
by the sparse direct back-end in use (:mod:`femodes.sparse_direct`: MUMPS's complex symmetric
``LDL^T`` where installed, 6x faster than SuperLU on a 6.1e4-DOF P2 block), or SuperLU with a
minimum-degree ordering of ``Z + Z^T`` and diagonal pivoting preferred.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.linalg import lapack
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ...dynamic_stiffness import DynamicStiffness
from ...sparse_direct import PatternFactorizer, is_symmetric
from .options import DEFAULT_OPTIONS

__all__ = ["StructureFailure", "BlockPattern", "build_pattern", "BlockLU", "real_times_complex"]


class StructureFailure(RuntimeError):
    """The structured factorisation is not applicable (a singular interior block)."""


@dataclass
class BlockPattern:
    """Interior/boundary split of the DOFs and the dynamic stiffness on its pieces.

    ``II`` holds the values of ``K, M, C`` on the union COO pattern ``(rows, cols)`` of the
    interior block in the permuted order (zeros where absent: one linear combination per harmonic,
    no sparse adds); ``Ib`` and ``bI`` the couplings ``Z[I, b]`` on the interior rows ``R``
    coupled to the boundary (dense ``len(R) x n_b``) and ``Z[b, I]`` on those columns; ``bb`` the
    boundary block. ``lowrank`` is the modal damping's split (:func:`~.lowrank.split_lowrank`),
    set by the system.
    """

    interior: np.ndarray   # interior DOFs
    bdofs: np.ndarray      # nonlinear DOFs (boundary)
    perm: np.ndarray       # RCM ordering of the interior (position -> interior index)
    rows: np.ndarray       # COO pattern of the permuted interior block
    cols: np.ndarray
    II: DynamicStiffness   # K, M, C values on that pattern
    kl: int                # bandwidth after RCM
    banded: bool
    identity: bool         # perm is the identity
    R: np.ndarray          # interior positions coupled to the boundary DOFs
    Ib: DynamicStiffness   # couplings Z[I, b] on the rows R (dense, len(R) x n_b)
    bI: DynamicStiffness   # couplings Z[b, I] on the columns R (dense, n_b x len(R))
    bb: DynamicStiffness   # Z[b, b] (dense)
    symmetric: bool = False                        # K, M, C symmetric on I: the blocks are (complex) symmetric
    lowrank: object = None                         # modal damping's split of U, Phi (lowrank.LowRankSplit)
    band_flat: np.ndarray | None = None            # rows/cols in the band storage (BlockLU)
    abs_row_sums: tuple | None = None              # the system's abs_row_sums() (refinement test)
    factorizer: PatternFactorizer | None = None    # sparse factorisations on (rows, cols): CSC structure
                                                   # and MUMPS's analysis shared by all harmonics (BlockLU)
    static: dict | None = None                     # harmonic 0's factors by keep_w (LinearFactors): Z(0) = K

    @property
    def n_interior(self) -> int:
        return self.perm.size

    def __getstate__(self):
        # factorisations (MUMPS instances, SuperLU objects) do not pickle: rebuilt on first use
        return dict(self.__dict__, factorizer=None, static=None)


def build_pattern(M: sp.spmatrix, K: sp.spmatrix, C: sp.spmatrix, bdofs: np.ndarray, *,
                  band_max_fill: float = DEFAULT_OPTIONS.band_max_fill) -> BlockPattern:
    """The split of the DOFs into the interior and the boundary ``bdofs`` (module docstring)."""
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
    kl = int(np.max(np.abs(r - c))) if U.nnz else 0
    # band storage (3 kl + 1) x nI against the sparse factors' ~ a few x nnz (band_max_fill): line
    # meshes (kl = 1..3 after RCM) and dense reduced interiors stay banded, 2-D/3-D meshes go to
    # the sparse back-end
    banded = nI > 0 and (3 * kl + 1) * nI <= band_max_fill * max(U.nnz, 1)
    # the interior-boundary couplings touch only the neighbours of the boundary DOFs: keep them as
    # small dense blocks on those rows (sparse matrices cost ~50 us per operation in scipy)
    ib = [A[interior][:, bdofs].tocsr() for A in (K, M, C)]
    bi = [A[bdofs][:, interior].tocsc() for A in (K, M, C)]
    R = np.unique(np.concatenate([A.tocoo().row for A in ib] + [A.tocoo().col for A in bi] + [np.zeros(0, int)]))
    return BlockPattern(
        interior=interior, bdofs=bdofs, perm=perm, rows=r, cols=c, II=DynamicStiffness(vals(KII), vals(MII), vals(CII)),
        kl=kl, banded=banded, identity=bool(np.array_equal(perm, np.arange(nI))), R=R,
        symmetric=not banded and all(is_symmetric(A) for A in (KII, MII, CII)),
        Ib=DynamicStiffness(*(A[R].toarray() for A in ib)), bI=DynamicStiffness(*(A[:, R].toarray() for A in bi)),
        bb=DynamicStiffness(*(A[bdofs][:, bdofs].toarray() for A in (K, M, C))),
    )


class BlockLU:
    """LU of the interior block ``Z(i f)[I, I] = K - f^2 M + i f (C - xi M)`` of one harmonic
    (band LAPACK or the sparse back-end; its sparse part: modal damping is not in it).

    ``solve(R, trans)`` takes and returns complex arrays ``(nI, k)`` in the *original* interior
    order; ``trans=True`` solves with ``Z^T`` (not conjugated). ``superlu_options``: those of a
    wide block (``BlockSolverOptions.superlu_options``). The former signature ``BlockLU(pat, a,
    b, xi)`` (``a = f^2``, ``b = f``) still works, with a ``DeprecationWarning``.
    """

    def __init__(self, pat: BlockPattern, f: float, xi: float = 0.0, *legacy, superlu_options: dict | None = None):
        if legacy:
            warnings.warn("BlockLU(pat, a, b, xi) is deprecated; use BlockLU(pat, f, xi) with the harmonic's "
                          "frequency f (a = f^2, b = f)", DeprecationWarning, stacklevel=2)
            f, xi = xi, legacy[0]
        self.pat = pat
        re, im = pat.II.parts(f, xi)
        self.complex = bool(f != 0.0 and np.any(im != 0.0))
        vals = re + 1j * im if self.complex else re
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
            if pat.factorizer is None:
                pat.factorizer = PatternFactorizer(pat.rows, pat.cols, n, symmetric=pat.symmetric)
            try:
                # the back-end in use (femodes.sparse_direct): MUMPS on the large complex symmetric
                # blocks of 2-D/3-D meshes where installed (its analysis done once for all harmonics
                # and frequencies, PatternFactorizer), SuperLU with superlu_options otherwise
                self.factor = pat.factorizer.factorize(
                    vals, positive_definite=not self.complex and f * f <= 0.0,
                    superlu_options=DEFAULT_OPTIONS.superlu_options if superlu_options is None else superlu_options)
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

    def solve_rows(self, rows: np.ndarray, V: np.ndarray) -> np.ndarray:
        """:meth:`solve` of the right-hand sides that are ``V`` (complex ``(len(rows), k)``) on the
        interior positions ``rows`` and zero elsewhere (the condensation columns ``Z_II^-1 Z_Ib``,
        nonzero on the rows ``R`` coupled to the boundary): a complex sparse factor takes them as a
        sparse matrix and prunes its forward substitution (:class:`~femodes.sparse_direct.Factor`)."""
        V = np.asarray(V)
        n, k = self.n, V.shape[1]
        if self.pat.banded or not self.complex:
            full = np.zeros((n, k), dtype=np.result_type(V, complex if self.complex else float), order="F")
            full[rows] = V
            return self.solve(full)
        perm = self.pat.perm
        if self.pat.identity:
            pos = np.asarray(rows)
        else:
            inv = np.empty(n, dtype=int)
            inv[perm] = np.arange(n)
            pos = inv[rows]
        B = sp.csc_matrix((V.ravel(order="F"), (np.tile(pos, k), np.repeat(np.arange(k), len(pos)))),
                          shape=(n, k), dtype=complex)
        Xp = self.factor.solve(B)
        if self.pat.identity:
            return Xp
        X = np.empty_like(Xp)
        X[perm] = Xp
        return X

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


def real_times_complex(A: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """``A @ Z`` for real ``A`` (p, n) and complex ``Z`` (n, k) as one real product on the
    interleaved view of ``Z`` (numpy would copy ``A`` to complex first)."""
    Z = np.ascontiguousarray(Z, dtype=complex)
    if Z.ndim == 1:
        return real_times_complex(A, Z[:, None])[:, 0]
    return np.ascontiguousarray(A @ Z.view(float).reshape(Z.shape[0], 2 * Z.shape[1])).view(complex)
