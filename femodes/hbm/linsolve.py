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
   reverse Cuthill-McKee ordering when the band is narrow (line meshes: bandwidth 1-3), SuperLU
   otherwise; the ``H + 1`` factorisations are independent and can run in threads
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

The per-harmonic factorisations and condensed stiffnesses depend only on ``(w, xi)``: they are
cached on the system: Newton at a fixed frequency (the start of a frequency response, the forcing
homotopy, sweeps at fixed ``w``) reuses them at every iteration; inside a continuation ``w`` is an
unknown and changes at every iteration, so there they are rebuilt. Cost per Newton iteration: ``O(N H bw^2)`` for the band LUs,
``O(N H (n_b + m))`` for the condensation solves and ``O((n_b (2H+1))^3)`` for the dense LU.
"""

from __future__ import annotations

import logging
import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack
from scipy.sparse.csgraph import reverse_cuthill_mckee

__all__ = ["HarmonicBlockJacobian", "StructureFailure", "BlockSolver", "AssembledSolver", "BlockStructure"]

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

    def apply_linear(self, q, omega: float, xi: float = 0.0, *, absolute: bool = False): ...
    def abs_row_sums(self) -> tuple: ...
    def block_pattern(self): ...
    def linear_factors(self, omega: float, xi: float = 0.0, threads: int | None = None): ...
    def linear_operator(self, omega: float): ...


class StructureFailure(RuntimeError):
    """The structured factorisation is not applicable (a singular interior block)."""


#: Systems smaller than this are solved by SuperLU on the assembled matrix: below ~2000 unknowns
#: the per-harmonic bookkeeping costs more than it saves (measured per bordered Newton step on a
#: clamped bar with a tip stop: 231 unknowns 4.8 ms structured vs 3.3 ms SuperLU; 2211: 4.9 vs
#: 5.9 ms; 11011: 7.7 vs 16.7 ms; 205041: 69 vs 222 ms).
STRUCTURED_MIN_SIZE = 2000

#: Interior size below which the harmonic blocks are factorised in one thread: starting a pool
#: costs ~0.1-1 ms, more than a band LU of a few thousand DOFs.
THREAD_MIN_SIZE = 20000


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
    # band storage (3 kl + 1) x nI against the sparse factors' ~ a few x nnz: a narrow band is
    # always cheaper (line meshes: kl = 1..3 after RCM); a wide one (reduced models with dense
    # modal coupling, 2-D meshes) goes to SuperLU.
    banded = nI > 0 and (3 * kl + 1) * nI <= 50 * max(U.nnz, 1)
    # the interior-boundary couplings touch only the neighbours of the boundary DOFs: keep them as
    # small dense blocks on those rows (sparse matrices cost ~50 us per operation in scipy)
    ib = [A[interior][:, bdofs].tocsr() for A in (K, M, C)]
    bi = [A[bdofs][:, interior].tocsc() for A in (K, M, C)]
    R = np.unique(np.concatenate([A.tocoo().row for A in ib] + [A.tocoo().col for A in bi] + [np.zeros(0, int)]))
    return _Pattern(
        interior=interior, bdofs=bdofs, perm=perm, rows=r, cols=c, kv=kv, mv=mv, cv=cv, kl=kl, banded=banded,
        identity=bool(np.array_equal(perm, np.arange(nI))), R=R,
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
            ab = np.zeros((ld, n), dtype=vals.dtype, order="F")
            ab[2 * kl + pat.rows - pat.cols, pat.cols] = vals
            gbtrf = lapack.zgbtrf if self.complex else lapack.dgbtrf
            self.lu, self.piv, info = gbtrf(ab, kl, kl, overwrite_ab=True)
            if info != 0:
                raise StructureFailure(f"interior block singular (gbtrf info {info})")
            self._gbtrs = lapack.zgbtrs if self.complex else lapack.dgbtrs
        else:
            A = sp.csc_matrix((vals, (pat.rows, pat.cols)), shape=(n, n))
            try:
                self.slu = spla.splu(A)
            except RuntimeError as exc:
                raise StructureFailure(f"interior block singular ({exc})") from None

    def _solve_real_or_complex(self, R: np.ndarray, trans: bool) -> np.ndarray:
        if self.pat.banded:
            kl = self.pat.kl
            x, info = self._gbtrs(self.lu, kl, kl, R, self.piv, trans=1 if trans else 0)
            if info != 0:  # pragma: no cover - argument error
                raise StructureFailure(f"gbtrs info {info}")
            return x
        return self.slu.solve(R, trans="T" if trans else "N")

    def solve(self, R: np.ndarray, trans: bool = False) -> np.ndarray:
        R = np.asarray(R)
        perm = self.pat.perm
        identity = self.pat.identity
        Rp = R if identity else R[perm]
        if self.complex:
            Xp = self._solve_real_or_complex(np.asfortranarray(Rp, dtype=complex), trans)
        elif np.iscomplexobj(Rp):
            k = Rp.shape[1]
            both = np.concatenate([Rp.real, Rp.imag], axis=1)
            Y = self._solve_real_or_complex(np.asfortranarray(both), trans)
            Xp = Y[:, :k] + 1j * Y[:, k:]
        else:
            Xp = self._solve_real_or_complex(np.asfortranarray(Rp, dtype=float), trans)
        if identity:
            return Xp
        X = np.empty_like(Xp)
        X[perm] = Xp
        return X


@dataclass
class _Harmonic:
    k: int                 # coefficient row of the cosine (0 for the mean)
    s: int | None          # coefficient row of the sine (None for the mean)
    a: float               # (k w / nu)^2
    b: float               # k w / nu
    lu: BlockLU | None
    Zc: np.ndarray         # condensed dynamic stiffness on the boundary DOFs (complex n_b x n_b)
    Zib: np.ndarray        # Z[I, b] on the coupled rows R (complex len(R) x n_b)
    Zbi: np.ndarray        # Z[b, I] on the coupled columns R (complex n_b x len(R))


class LinearFactors:
    """Per-harmonic interior LUs and condensed stiffnesses at one ``(w, xi)`` (cached on the system)."""

    def __init__(self, system: BlockStructure, omega: float, xi: float, threads: int | None = None):
        self.omega, self.xi = float(omega), float(xi)
        h = system.h
        pat = system.block_pattern()
        self.pat = pat
        nb = pat.bdofs.size
        jobs = [(0, None, 0.0)]
        for k in range(1, h.n_harmonics + 1):
            f = k * self.omega / h.subharmonic
            jobs.append((int(h.cos_index(k)), int(h.sin_index(k)), f))

        def one(job):
            row_c, row_s, f = job
            a, b = f * f, f
            lu = BlockLU(pat, a, b, self.xi) if pat.perm.size else None
            Cb = pat.Cbb - self.xi * pat.Mbb
            Zbb = pat.Kbb - a * pat.Mbb + 1j * b * Cb
            Zib = pat.Kib - a * pat.Mib + 1j * b * (pat.Cib - self.xi * pat.Mib)
            Zbi = pat.Kbi - a * pat.Mbi + 1j * b * (pat.Cbi - self.xi * pat.Mbi)
            if lu is not None and nb:
                full = np.zeros((pat.perm.size, nb), dtype=complex)
                full[pat.R] = Zib
                W = lu.solve(full)
                Zc = Zbb - Zbi @ W[pat.R]
            else:
                Zc = Zbb
            return _Harmonic(row_c, row_s, a, b, lu, np.asarray(Zc, dtype=complex), Zib, Zbi)

        nt = _threads(len(jobs), threads, pat.perm.size)
        if nt > 1:
            with ThreadPoolExecutor(nt) as ex:
                self.blocks = list(ex.map(one, jobs))
        else:
            self.blocks = [one(j) for j in jobs]
        self.threads = nt

    def map(self, fun):
        """Apply ``fun(block)`` to all harmonics (threaded like the factorisation)."""
        if self.threads > 1:
            with ThreadPoolExecutor(self.threads) as ex:
                return list(ex.map(fun, self.blocks))
        return [fun(b) for b in self.blocks]


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

    def _replace(self, **kw) -> "HarmonicBlockJacobian":
        d = dict(scale=self.scale, U=self.U, V=self.V, D=self.D)
        d.update(kw)
        return HarmonicBlockJacobian(self.system, self.omega, self.xi, self.N, **d)

    def __mul__(self, f):
        if not np.isscalar(f):
            return NotImplemented
        f = float(f)
        return self._replace(scale=self.scale * f, U=self.U * f, V=self.V * f, D=self.D * f)

    __rmul__ = __mul__

    def bordered(self, cols, rows, corner) -> "HarmonicBlockJacobian":
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
        s = self.system
        S = s.linear_operator(self.omega)
        if self.xi:
            S = S - (self.xi * self.omega) * s.AM
        if s.np:
            S = sp.block_diag([S, sp.csr_matrix((s.np, s.np))], format="csr")
        core = (self.scale * (S + self.N)).tocsr()
        if not self.n_border:
            return core
        return sp.bmat([[core, sp.csr_matrix(self.U)], [sp.csr_matrix(self.V), sp.csr_matrix(self.D)]], format="csr")

    def tocsc(self) -> sp.csc_matrix:
        return self.tocsr().tocsc()

    def toarray(self) -> np.ndarray:
        return self.tocsr().toarray()

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


class BlockSolver:
    """Linear solver strategy of the harmonic balance (the default): per-harmonic band LU of the
    linear DOFs and a dense Schur complement on the nonlinear DOFs and borders (module
    docstring); systems below :data:`STRUCTURED_MIN_SIZE` unknowns, and blocks that cannot be
    factorised (an interior resonance), go to SuperLU on the assembled matrix."""

    def factorize(self, J: HarmonicBlockJacobian, *, threads: int | None = None):
        if J.shape[0] < STRUCTURED_MIN_SIZE:
            return _Generic(J)
        try:
            return _Factorization(J, threads)
        except StructureFailure as exc:
            log.debug("structured HBM factorisation not applicable (%s); SuperLU on the assembled matrix", exc)
            return _Generic(J)

    def __repr__(self) -> str:
        return "BlockSolver()"


class AssembledSolver:
    """Linear solver strategy: SuperLU on the assembled sparse Jacobian, whatever its size (for
    checks and comparisons with :class:`BlockSolver`)."""

    def factorize(self, J: HarmonicBlockJacobian, *, threads: int | None = None):
        return _Generic(J)

    def __repr__(self) -> str:
        return "AssembledSolver()"


class _Generic:
    def __init__(self, J: HarmonicBlockJacobian):
        self.lu = spla.splu(J.tocsc())

    def solve(self, b):
        return self.lu.solve(np.asarray(b, dtype=float))


class _Factorization:
    """Structured LU of a :class:`HarmonicBlockJacobian` (interior blocks + dense Schur complement)."""

    def __init__(self, J: HarmonicBlockJacobian, threads: int | None):
        self.J = J
        s = J.system
        self.s = s
        self.F = F = s.linear_factors(J.omega, J.xi, threads)
        pat = F.pat
        h, n = s.h, s.n
        nc, nb, npv, m = h.n_coef, pat.bdofs.size, s.np, J.n_border
        self.nc, self.nb, self.m = nc, nb, m
        # global indices of the boundary unknowns: q of nonlinear DOFs (coef-major), p, border
        self.gq = (np.arange(nc)[:, None] * n + pat.bdofs[None, :]).ravel()
        self.gB = np.concatenate([self.gq, s.nq + np.arange(npv)])
        nB = self.gB.size + m
        self.nB = nB
        T = self._boundary_block()
        self._add_condensed_stiffness(T)
        if m and pat.perm.size:
            self._add_border_coupling(T)
        if not np.all(np.isfinite(T)):
            raise StructureFailure("non-finite Schur complement")
        self.norm_bound = self._norm_bound()
        self.T = T
        if nB:
            self._factor_schur(T)

    # -- Schur complement assembly ------------------------------------------------------------
    def _qpos(self, row: int) -> np.ndarray:
        """Positions in the Schur complement of the nonlinear DOFs at coefficient row ``row``."""
        return row * self.nb + np.arange(self.nb)

    def _boundary_block(self) -> np.ndarray:
        """``J[B, B]`` without its linear part: the nonlinear part and the border entries."""
        J, nB, nG = self.J, self.nB, self.gB.size
        T = np.zeros((nB, nB))
        # nonlinear part on the boundary (N is zero elsewhere by construction)
        NB = J.N[self.gB][:, self.gB]
        T[:nG, :nG] = J.scale * NB.toarray()
        # border entries on the boundary
        if self.m:
            T[:nG, nG:] = J.U[self.gB]
            T[nG:, :nG] = J.V[:, self.gB]
            T[nG:, nG:] = J.D
        return T

    def _add_condensed_stiffness(self, T: np.ndarray) -> None:
        """Linear condensed stiffness per harmonic, real form ``[[X, Y], [-Y, X]]`` on ``(a, b)``."""
        sc, qpos = self.J.scale, self._qpos
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
        return blk, out

    def _add_border_coupling(self, T: np.ndarray) -> None:
        """Border coupling through the interior: ``-J_BI J_II^-1 J_IB`` for the border rows/columns."""
        J, s, qpos = self.J, self.s, self._qpos
        nc, n, m = self.nc, s.n, self.m
        I = self.F.pat.interior
        Ui = J.U[: s.nq].reshape(nc, n, m)[:, I, :]       # (nc, nI, m)
        Vi = J.V[:, : s.nq].reshape(m, nc, n)[:, :, I]    # (m, nc, nI)
        off = self.gB.size
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

    def _norm_bound(self) -> float:
        """``||J||_inf`` bound for the refinement test (row sums of ``|K|, |M|, |C - xi M|`` at the
        top harmonic)."""
        J, s = self.J, self.s
        h = s.h
        s_max = h.n_harmonics * J.omega / h.subharmonic
        rK, rM, rC = s.abs_row_sums()
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
        x = self._solve(B)
        # iterative refinement against the true J: the interior blocks can be ill-conditioned near
        # an eigenfrequency of the structure with its nonlinear DOFs held (Higham 2002, ch. 12)
        J = self.J
        scale_b = np.max(np.abs(B)) or 1.0
        for _ in range(3):
            res = B - J.matvec(x)
            tol = 64 * np.finfo(float).eps * (self.norm_bound * float(np.max(np.abs(x))) + scale_b)
            if np.max(np.abs(res)) <= tol:
                break
            x = x + self._solve(res)
        else:
            res = B - J.matvec(x)
            if not np.all(np.isfinite(x)) or np.max(np.abs(res)) > 1e6 * tol:
                log.debug("structured solve inaccurate (|res| = %.2e); SuperLU on the assembled matrix",
                          float(np.max(np.abs(res))))
                x = spla.splu(J.tocsc()).solve(B)
        return x[:, 0] if one_d else x

    def _solve(self, B: np.ndarray) -> np.ndarray:
        J, s, pat = self.J, self.s, self.F.pat
        nc, n, m, k = self.nc, s.n, self.m, B.shape[1]
        n0 = s.size
        sc = J.scale
        I = pat.interior
        nI = I.size
        x = np.zeros_like(B)
        rhsB = np.concatenate([B[self.gB], B[n0:]], axis=0)  # (nB, k)
        if nI:
            bI = B[: s.nq].reshape(nc, n, k)[:, I, :] / sc
            yI = self._interior_solve(bI)
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
                rhsB[self.gB.size:] -= np.einsum("mci,cik->mk", Vi, yI)
        xB = sla.lu_solve(self.lu, rhsB, check_finite=False) if self.nB else rhsB
        x[self.gB] = xB[: self.gB.size]
        x[n0:] = xB[self.gB.size:]
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
            if m:
                Ui = J.U[: s.nq].reshape(nc, n, m)[:, I, :]
                c += np.einsum("cim,mk->cik", Ui, xB[self.gB.size:]) / sc
            xI = yI - self._interior_solve(c)
            xq_all = x[: s.nq].reshape(nc, n, k)
            xq_all[:, I, :] = xI
        return x
