r"""Discretise layer: the HBM Jacobian kept as harmonic blocks, a nonlinear part and dense borders.

The Jacobian of the harmonic balance equations (:class:`~femodes.hbm.system.HBMSystem`) is

.. math::

    J = \begin{bmatrix} s\,(S(\omega) \oplus 0 + N) & U \\ V & D \end{bmatrix},

with ``S(w)`` the dynamic stiffness on the coefficients (block diagonal over harmonics,
:class:`~femodes.dynamic_stiffness.CoefficientStiffness`), ``N`` the generalized Jacobian of the
contact and nonlinear terms, which lives only on the rows and columns of the ``n_b`` nonlinear
DOFs (all harmonics) and of the contact-force unknowns, ``s`` the equation scale of the problem
and ``U, V, D`` dense borders (the extra unknowns of a nonlinear mode, the arclength equation of
the continuation). In complex form the block of harmonic ``k`` (frequency ``f = k w / nu``) is
``Z_k = K - f^2 M + i f (C - xi M)`` acting on ``a - i b`` for the coefficients ``a cos + b sin``
(``xi`` the EPMC damping). :class:`HarmonicBlockJacobian` keeps this structure instead of
assembling one sparse matrix; its :meth:`~HarmonicBlockJacobian.factorize` asks the system's
solver strategy (``BlockSolver`` or ``AssembledSolver``).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import scipy.sparse as sp

__all__ = ["BlockStructure", "HarmonicBlockJacobian"]


class BlockStructure(Protocol):
    """What the Jacobian operator and its factorisations need from the harmonic balance system
    (:class:`~femodes.hbm.HBMSystem` provides it): sizes, the dynamic stiffness on the
    coefficients, the linear part (its per-harmonic factors), the solver strategy and its options. Nothing else of
    the system is read by the block solver.
    """

    h: Any            # Harmonics: layout of the coefficient rows
    n: int            # DOFs of the model
    nq: int           # displacement unknowns, n_coef * n
    np: int           # contact-force unknowns
    n_uc: int         # complementarity contacts (np = n_coef * n_uc)
    size: int         # nq + np
    solver: Any       # BlockSolver() or AssembledSolver()
    solver_options: Any  # BlockSolverOptions of the pattern and factors
    stiffness: Any    # CoefficientStiffness S(w) (femodes.dynamic_stiffness)

    linear: Any       # LinearPart: block_pattern(), factors(omega, xi, threads) (cached)


def _assemble(J: HarmonicBlockJacobian, lowrank: bool = True) -> sp.csr_matrix:
    """``J`` assembled with its linear operator ``S(w) - xi w (D x M)`` (``lowrank=False``: without
    the low-rank damping, :meth:`HarmonicBlockJacobian.augmented`), contact-force rows, scale,
    nonlinear part and borders."""
    s = J.system
    S = s.stiffness.operator(J.omega, J.xi, lowrank=lowrank)
    if s.np:
        S = sp.block_diag([S, sp.csr_matrix((s.np, s.np))], format="csr")
    core = (J.scale * (S + J.N)).tocsr()
    if not J.n_border:
        return core
    return sp.bmat([[core, sp.csr_matrix(J.U)], [sp.csr_matrix(J.V), sp.csr_matrix(J.D)]], format="csr")


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

    def __mul__(self, f):
        if not np.isscalar(f):
            return NotImplemented
        f = float(f)
        return HarmonicBlockJacobian(self.system, self.omega, self.xi, self.N, scale=self.scale * f, U=self.U * f,
                                     V=self.V * f, D=self.D * f)

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
        return HarmonicBlockJacobian(self.system, self.omega, self.xi, self.N, scale=self.scale, U=U, V=V, D=D)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.ndim == 2:
            return np.column_stack([self.matvec(x[:, j]) for j in range(x.shape[1])])
        s = self.system
        n0 = s.size
        y = np.empty(self.shape[0])
        y[:n0] = self.scale * (self.N @ x[:n0])
        y[: s.nq] += self.scale * s.stiffness.apply(x[: s.nq].reshape(s.h.n_coef, s.n), self.omega, self.xi).ravel()
        y[:n0] += self.U @ x[n0:]
        y[n0:] = self.V @ x[:n0] + self.D @ x[n0:]
        return y

    __matmul__ = dot = matvec

    def abs_matvec(self, v: np.ndarray) -> np.ndarray:
        """An upper bound of ``|J| |v|`` (for backward-error tolerances)."""
        s = self.system
        v = np.abs(np.asarray(v, dtype=float))
        n0 = s.size
        y = np.empty(self.shape[0])
        y[:n0] = abs(self.scale) * (abs(self.N) @ v[:n0])
        y[: s.nq] += abs(self.scale) * s.stiffness.apply(v[: s.nq].reshape(s.h.n_coef, s.n), self.omega, self.xi,
                                                          absolute=True).ravel()
        y[:n0] += np.abs(self.U) @ v[n0:]
        y[n0:] = np.abs(self.V) @ v[:n0] + np.abs(self.D) @ v[n0:]
        return y

    def all_finite(self) -> bool:
        return bool(np.all(np.isfinite(self.N.data)) and np.isfinite(self.omega) and np.isfinite(self.xi)
                    and np.all(np.isfinite(self.U)) and np.all(np.isfinite(self.V)) and np.all(np.isfinite(self.D)))

    def tocsr(self) -> sp.csr_matrix:
        """The assembled sparse matrix (generic fallback and checks)."""
        return _assemble(self)

    def tocsc(self) -> sp.csc_matrix:
        return self.tocsr().tocsc()

    def augmented(self) -> sp.csr_matrix | None:
        """With modal damping ``U diag(d) U^T``: the sparse matrix ``[[J_sparse, s B], [I x U^T,
        -I]]`` (``B = w (D1 x U diag(d))``, :meth:`CoefficientStiffness.lowrank_border`) whose
        leading block of the solution of ``[b; 0]`` solves ``J x = b``; None without a low-rank part."""
        s = self.system
        border = s.stiffness.lowrank_border(self.omega)
        if border is None:
            return None
        Bc, Ur = border
        r, m = Ur.shape[0], self.n_border
        pad_r = sp.csr_matrix((m, r))
        cols = sp.vstack([self.scale * Bc, sp.csr_matrix((s.np, r)), pad_r], format="csr")
        rows = sp.hstack([Ur, sp.csr_matrix((r, s.np + m))], format="csr")
        return sp.bmat([[_assemble(self, lowrank=False), cols], [rows, -sp.identity(r, format="csr")]], format="csr")

    @property
    def nnz(self) -> int:
        """Stored entries: of the assembled matrix, or with modal damping of its sparse part plus
        the low-rank factors ``U, d`` (what the solvers use; :meth:`tocsr` would be dense)."""
        lr = self.system.stiffness.Z.lowrank
        if lr is None:
            return int(self.tocsr().nnz)
        return int(_assemble(self, lowrank=False).nnz + lr.nnz)

    def toarray(self) -> np.ndarray:
        """The assembled dense matrix (up to ``BlockSolverOptions.dense_operators_max``
        displacement coefficients: from the system's cached dense operators, no sparse matrix)."""
        s = self.system
        if s.nq > s.solver_options.dense_operators_max:
            return self.tocsr().toarray()
        n0, nq = s.size, s.nq
        A = np.zeros(self.shape)
        A[:nq, :nq] = s.stiffness.dense_operator(self.omega, self.xi)
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
