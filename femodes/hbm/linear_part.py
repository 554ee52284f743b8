"""Discretise layer: the linear structure in the harmonic balance equations (``HBMSystem.linear``).

``S(w) Q = F`` harmonic by harmonic: the Galerkin coefficients ``F`` of the forcing, the product
``S(w) q`` on the coefficients, the solution of the linear problem (no contact), and the
interior/boundary pattern and per-harmonic factorisations that the block solver of the
nonlinear Jacobian reuses (both cached here, the factors of the last ``(w, xi)`` only).
``S(w)`` itself is :class:`~femodes.dynamic_stiffness.CoefficientStiffness` (``HBMSystem.stiffness``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..dynamic_stiffness import CoefficientStiffness
from ..model import StructuralModel, low_rank_solver
from .harmonics import Harmonics
from .linsolve import BlockLU, LinearFactors, StructureFailure, build_pattern
from .linsolve.lowrank import modal_shift, split_lowrank

__all__ = ["LinearPart"]


def _forcing_coefficients(h: Harmonics, model: StructuralModel) -> np.ndarray:
    """Galerkin coefficients ``(n_coef, n_dofs)`` of the forcing of ``model``; the forcing harmonic
    ``k`` sits at Fourier row ``k nu``."""
    F = np.zeros((h.n_coef, model.n_dofs))
    nu, H = h.subharmonic, h.n_harmonics
    for k, vec in model.force_vectors().items():
        kk = k * nu
        if kk > H:
            raise ValueError(
                f"forcing at harmonic {k} needs n_harmonics >= {kk} (subharmonic={nu}), got {H}"
            )
        if kk == 0:
            F[0] += vec.real
        else:
            F[h.layout.cos_index(kk)] += vec.real
            F[h.layout.sin_index(kk)] -= vec.imag  # cos(kwt + phi) = cos phi cos - sin phi sin
    return F


def _solve_linear_lsqr(stiffness: CoefficientStiffness, R: np.ndarray, omega: float) -> np.ndarray:
    """Least-squares ``S(w) q = R`` (a singular harmonic block): on the assembled operator, or
    with a low-rank damping on ``[[S_sparse, B], [I x U^T, -I]] [q; y] = [R; 0]``."""
    border = stiffness.lowrank_border(omega)
    if border is None:
        return spla.lsqr(stiffness.operator(omega), R.ravel())[0].reshape(R.shape)
    B, Ur = border
    S = stiffness.operator(omega, lowrank=False)
    m = Ur.shape[0]
    A = sp.bmat([[S, B], [Ur, -sp.identity(m)]], format="csr")
    rhs = np.concatenate([R.ravel(), np.zeros(m)])
    return spla.lsqr(A, rhs, atol=1e-14, btol=1e-14)[0][: R.size].reshape(R.shape)


class LinearPart:
    """The linear structure of an :class:`~femodes.hbm.HBMSystem` (``system.linear``): forcing,
    ``S(w) q``, the linear solve, and the cached pattern and per-harmonic factors of the block
    solver.

    Parameters
    ----------
    model : StructuralModel
    harmonics : Harmonics
    stiffness : CoefficientStiffness
        ``S(w)`` on the coefficients (sparse parts ``M``, ``K``, ``C`` and the low-rank damping).
    nonlinear_dofs : ndarray of int
        DOFs where the nonlinear terms act (the boundary of the block pattern).
    solver_options : BlockSolverOptions
        Tuning of the pattern and the factors.
    threads : int, optional
        Threads of the per-harmonic factorisations (see :class:`~femodes.hbm.HBMSystem`).
    """

    def __init__(self, model: StructuralModel, harmonics: Harmonics, stiffness: CoefficientStiffness,
                 nonlinear_dofs: np.ndarray, *, solver_options, threads: int | None = None):
        self.model = model
        self.h = harmonics
        self.n = model.n_dofs
        self.stiffness = stiffness
        self.nonlinear_dofs = nonlinear_dofs
        self.solver_options = solver_options
        self.threads = threads
        self._F: np.ndarray | None = None
        self._cache: dict = {}

    def force(self) -> np.ndarray:
        """Galerkin coefficients of the forcing ``sum f cos(k w t + phase)`` (length ``nq``).

        With ``subharmonic = nu`` the forcing harmonic ``k`` sits at Fourier row ``k nu``.
        """
        if self._F is None:
            self._F = _forcing_coefficients(self.h, self.model).ravel()
        return self._F

    def apply(self, q: np.ndarray, omega: float, xi: float = 0.0, *, absolute: bool = False) -> np.ndarray:
        """``S(w) q - xi w (D1 x M) q`` without forming the Kronecker products (``absolute``: an
        upper bound of ``|S| |q|`` for tolerances)."""
        Q = np.asarray(q, dtype=float).reshape(self.h.n_coef, self.n)
        return self.stiffness.apply(Q, omega, xi, absolute=absolute).ravel()

    def solve(self, rhs: np.ndarray, omega: float) -> np.ndarray:
        """Solve ``S(w) q = rhs`` (the linear structure, no contact) harmonic by harmonic.

        Falls back to a least-squares solution of the assembled operator if a harmonic block is
        singular (a rigid-body mode at harmonic 0, ``k w`` exactly at an eigenfrequency).
        """
        h, n, Z = self.h, self.n, self.stiffness.Z
        R = np.asarray(rhs, dtype=float).reshape(h.n_coef, n)
        if "pattern_all" not in self._cache:
            self._cache["pattern_all"] = build_pattern(Z.M, Z.K, Z.C, np.zeros(0, dtype=int),
                                                       band_max_fill=self.solver_options.band_max_fill)
        pat = self._cache["pattern_all"]
        superlu = self.solver_options.superlu_options
        out = np.empty_like(R)
        try:
            out[0] = BlockLU(pat, 0.0, superlu_options=superlu).solve(R[0][:, None]).real[:, 0]
            for k in range(1, h.n_harmonics + 1):
                f = k * omega / h.subharmonic
                c, si = h.layout.cos_index(k), h.layout.sin_index(k)
                lu = BlockLU(pat, f, superlu_options=superlu)
                rhs = (R[c] - 1j * R[si])[:, None]
                if Z.lowrank is None:
                    z = lu.solve(rhs)[:, 0]
                else:  # Z = Z_sparse + U diag(i f d) U^T: Woodbury on the harmonic block
                    U = Z.lowrank.U
                    z = low_rank_solver(lu.solve, U, Z.lowrank_gain(f), U, AinvL=_modes_solve(Z, lu, f))(rhs)[:, 0]
                out[c], out[si] = z.real, -z.imag
        except StructureFailure:
            out = _solve_linear_lsqr(self.stiffness, R, omega)
        return out.ravel()

    def block_pattern(self):
        """Interior/boundary split and sparsity pattern for the structured solver (cached), with
        the split of the modal damping's low-rank part."""
        if "pattern" not in self._cache:
            Z = self.stiffness.Z
            pat = build_pattern(Z.M, Z.K, Z.C, self.nonlinear_dofs, band_max_fill=self.solver_options.band_max_fill)
            pat.lowrank = split_lowrank(pat, Z)
            self._cache["pattern"] = pat
        return self._cache["pattern"]

    def factors(self, omega: float, xi: float = 0.0, threads: int | None = None) -> LinearFactors:
        """Per-harmonic interior factorisations at ``(w, xi)``; the last one is cached and reused."""
        key = (float(omega), float(xi))
        hit = self._cache.get("factors")
        if hit is not None and hit[0] == key:
            return hit[1]
        # the last factors go before the new ones are built (unless a caller holds them): one set
        # of per-harmonic factors alive at a time, not two (3-D blocks: ~1 GiB each at 6e4 DOFs)
        self._cache.pop("factors", None)
        hit = None
        F = LinearFactors(self, omega, xi, self.threads if threads is None else threads)
        self._cache["factors"] = (key, F)
        return F


def _modes_solve(Z, lu: BlockLU, f: float) -> np.ndarray | None:
    """``(K - f^2 M)^{-1} U`` from the modes relation of :meth:`DynamicStiffness.lowrank_modes`
    (None without it): ``(Phi + c (K - c M)^{-1} E) diag(1/mu)``, ``c = f^2``, ``mu = w^2 - c``, with
    one solve per changed mass row of ``E`` and one per mode whose ``mu`` is near zero (solved
    directly), instead of the ``m`` solves of ``U`` (a linear response with modal damping: 4x
    the Rayleigh one's cost on a 1e3-DOF bar)."""
    em = Z.lowrank_modes()
    if em is None:
        return None
    Phi, lam, rows, Erows = em
    c, mu_ok, bad = modal_shift(lam, f)  # the bad modes' columns are solved directly below
    X = Phi / mu_ok
    if rows.size:
        unit = np.zeros((Phi.shape[0], rows.size))
        unit[rows, np.arange(rows.size)] = 1.0
        X = X + lu.solve(unit) @ (c * Erows / mu_ok)
    if bad.size:
        X = np.asarray(X, dtype=np.result_type(X, complex if lu.complex else float))
        X[:, bad] = lu.solve(Z.lowrank.U[:, bad])
    return X
