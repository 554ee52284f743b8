"""Discretise layer: the dense solve of Hill's problem (:mod:`femodes.hbm.hill`).

The algebraic unknowns are eliminated first, exactly (:func:`pencil_on_dynamic`,
:mod:`femodes.hbm.hill_elimination`); then all finite eigenvalues of the pencil that is left are
computed (:func:`dense_pencil`, a standard dense eigen-solve after a shift-and-invert), among which
:mod:`femodes.hbm.hill` selects the central exponents.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from .hill_elimination import dense_array, eliminate

__all__ = ["Pencil", "pencil_on_dynamic", "dense_pencil", "dense_spectrum", "SMALL"]

log = logging.getLogger(__name__)

#: Hill problems of at most this many unknowns are eliminated with dense arrays
#: (:func:`pencil_on_dynamic`): scipy.sparse's per-call overhead dominates below it (the 11-DOF
#: blade of blade_casing.py, 225 unknowns); above it the algebraic block is sliced sparse (a
#: 27-contact blade: 594 of 660, 3 % nonzeros, which a dense slice and its conversion back to
#: sparse cost 2x the factorisation).
SMALL = 300


@dataclass(frozen=True, eq=False)
class Pencil:
    """Hill's pencil ``A0 + s A1 + s^2 A2`` (dense) on the unknowns ``d`` that carry mass or damping
    (None: all of them, nothing eliminated); ``X`` gives the eliminated unknowns ``a`` of an
    eigenvector, ``v_a = -X v_d``; ``size`` is the number of unknowns of the whole problem."""

    A0: np.ndarray
    A1: np.ndarray
    A2: np.ndarray
    size: int
    d: np.ndarray | None = None
    a: np.ndarray | None = None
    X: np.ndarray | None = None

    def embed(self, Vd: np.ndarray) -> np.ndarray:
        """Eigenvectors on ``d`` in the whole layout, the eliminated rows zero."""
        if self.d is None:
            return Vd
        V = np.zeros((self.size, Vd.shape[1]), dtype=complex)
        V[self.d] = Vd
        return V

    def restrict(self, V: np.ndarray) -> np.ndarray:
        """The rows ``d`` of eigenvectors in the whole layout."""
        return V if self.d is None else V[self.d]

    def fill(self, W: np.ndarray) -> np.ndarray:
        """Eigenvectors in the whole layout with their eliminated rows completed."""
        if self.d is None or self.X is None:
            return W
        W = W.copy()
        W[self.a] = -(self.X @ W[self.d])
        return W


def pencil_on_dynamic(J0, J1, J2, algebraic=None) -> Pencil:
    """Hill's pencil with its algebraic unknowns eliminated, exactly: their rows read
    ``J0_aa v_a + J0_ad v_d = 0`` at every ``s``, so the pencil on the others is
    ``S0 + s J1_dd + s^2 J2_dd`` with ``S0 = J0_dd - J0_da J0_aa^-1 J0_ad``, and
    ``v_a = -J0_aa^-1 J0_ad v_d``. When ``J0_aa`` is singular (a contact closed over the whole
    period) the whole pencil is kept."""
    N = J0.shape[0]
    if algebraic is not None and np.any(algebraic):
        a, d = np.flatnonzero(algebraic), np.flatnonzero(~algebraic)
        if N <= SMALL:  # dense slicing: scipy.sparse's per-call overhead dominates there
            J0, J1, J2 = (dense_array(A) for A in (J0, J1, J2))

            def block(A, r, c):
                return A[np.ix_(r, c)]
        else:
            J0, J1, J2 = (A.tocsr() for A in (J0, J1, J2))

            def block(A, r, c):
                return A[r][:, c]
        X = eliminate(block(J0, a, a), block(J0, a, d)) if d.size else None
        if X is not None:
            S0 = dense_array(block(J0, d, d)) - block(J0, d, a) @ X
            return Pencil(S0, dense_array(block(J1, d, d)), dense_array(block(J2, d, d)), N, d, a, X)
    return Pencil(dense_array(J0), dense_array(J1), dense_array(J2), N)


def dense_spectrum(J0, J1, J2, base, algebraic=None, vectors=True):
    """All finite eigenvalues of Hill's pencil, densely: ``(s, V, fill)``; ``V`` the eigenvectors in
    the whole layout, eliminated rows zero, which ``fill(V[:, idx])`` completes for the columns
    selected (all ``2N`` took a tenth of the user blade's stability run at H = 10, where 20 are
    kept). None for both without ``vectors``."""
    p = pencil_on_dynamic(J0, J1, J2, algebraic)
    s, Vd = dense_pencil(p.A0, p.A1, p.A2, base, vectors)
    if not vectors:
        return s, None, None
    return s, p.embed(Vd), p.fill


def dense_pencil(A0, A1, A2, base, vectors=True):
    """All finite eigenvalues of the pencil ``[[0, I], [-A0, -A1]] - s [[I, 0], [0, A2]]`` (dense
    arrays), by a shift-and-invert of the whole spectrum (standard dense eigenproblem instead of
    QZ; the infinite eigenvalues of algebraic rows map to 0 and are dropped)."""
    N = A0.shape[0]
    sigma = 0.37 * base  # a real shift away from the spectrum near Re s = 0 (any non-eigenvalue works)
    Js = A0 + sigma * A1 + sigma * sigma * A2
    try:
        lu = sla.lu_factor(Js, check_finite=False)
    except (sla.LinAlgError, ValueError):
        sigma = 0.53 * base
        lu = sla.lu_factor(A0 + sigma * A1 + sigma * sigma * A2, check_finite=False)
    # OP = (A - sigma B)^{-1} B on z = [v; w]:  (J(sigma)) z1 = -J2 y2 - (J1 + sigma J2) y1, z2 = y1 + sigma z1
    rhs1 = -(A1 + sigma * A2)
    rhs2 = -A2
    Z1 = sla.lu_solve(lu, np.hstack([rhs1, rhs2]), check_finite=False)
    OP = np.empty((2 * N, 2 * N))
    OP[:N] = Z1
    OP[N:] = sigma * Z1
    OP[N:, :N] += np.eye(N)
    if vectors:
        theta, Zv = sla.eig(OP, check_finite=False)
    else:
        theta, Zv = sla.eigvals(OP, check_finite=False), None
    tol = 1e-10 * max(1.0, float(np.max(np.abs(theta))) if theta.size else 1.0)
    finite = np.abs(theta) > tol
    s = sigma + 1.0 / theta[finite]
    # round-off: theta carries an absolute error of about (2N) eps |OP|, which 1/theta magnifies
    # by |s - sigma|^2; a real part below that bound is not resolved (the stiff constraint modes
    # that the elimination of a contact closed over most of the period leaves, |s| ~ 1e9 on the
    # blade of examples/blade_casing.py, came out with Re s = +-1e5..1e6): it is set to 0
    bound = 2 * N * np.finfo(float).eps * float(np.abs(OP).sum(axis=0).max()) * np.abs(s - sigma) ** 2
    unresolved = np.abs(s.real) <= bound
    if np.any(unresolved):
        log.debug("hill_exponents: %d exponents with real parts below round-off set to 0", np.count_nonzero(unresolved))
        s = np.where(unresolved, 1j * s.imag, s)
    return s, (Zv[:N, finite] if vectors else None)
