"""Discretise layer: the exact elimination of the algebraic unknowns of Hill's problem.

The contact forces, and the kept DOFs of a free-interface reduction (massless there), have no
row or column in ``J1`` and ``J2``: their equations ``J0_aa v_a + J0_ad v_d = 0`` hold at every
exponent ``s``, so :func:`femodes.hbm.hill_dense.pencil_on_dynamic` eliminates them through ``X = J0_aa^-1 J0_ad``
(:func:`eliminate`) before the dense eigen-solve.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .linsolve.options import DEFAULT_OPTIONS

__all__ = ["algebraic_unknowns", "eliminate", "dense_array", "SPARSE_ELIMINATION_DENSITY", "SPARSE_ELIMINATION_MIN"]

#: An algebraic block with at most this fraction of nonzeros is factorised sparse (:func:`eliminate`).
SPARSE_ELIMINATION_DENSITY = 0.1

#: ... when it has more than this many rows: below, a dense LU is cheaper than SuperLU and its
#: condition estimate (measured, one BLAS thread: 150 rows at 4 % nonzeros, the 11-DOF blade of
#: examples/blade_casing.py at H = 7, 0.7 ms dense against 1.7 ms sparse; 594 rows at 3 %, 8.9
#: against 3.8 ms; X the same to 1e-12).
SPARSE_ELIMINATION_MIN = 300


def dense_array(A) -> np.ndarray:
    """``A`` as a dense array (sparse or not)."""
    return A.toarray() if sp.issparse(A) else np.asarray(A)


def _equilibrate(A):
    """``(r A c, r, c)``: rows, then columns, scaled by their largest entry (an empty row or
    column by 1); ``A`` dense or sparse, the result of the same kind (sparse as CSC)."""
    absA = abs(A)
    with np.errstate(divide="ignore"):
        r = 1.0 / dense_array(absA.max(axis=1)).ravel()
        r[~np.isfinite(r)] = 1.0
        c = 1.0 / dense_array((sp.diags(r) @ absA).max(axis=0)).ravel()
        c[~np.isfinite(c)] = 1.0
    if sp.issparse(A):
        return (sp.diags(r) @ A @ sp.diags(c)).tocsc(), r, c
    return r[:, None] * A * c[None, :], r, c


def eliminate(Aaa, Aad) -> np.ndarray | None:
    """``X = Aaa^-1 Aad`` (dense), or None when ``Aaa`` is singular to working precision.

    ``Aaa`` is equilibrated first (:func:`_equilibrate`): the kept DOFs' residual stiffness and
    the contact rows differ by many orders of magnitude, which is scaling, not singularity. Its
    reciprocal condition number (1-norm, LAPACK's ``dgecon`` on a dense LU, Hager's estimate
    ``onenormest`` on a sparse one) must exceed ``1e3 eps``. A sparse block (the harmonics of the
    kept DOFs and contacts couple only through the laws: 3 % nonzeros on a blade with 27 contacts
    at H = 5) takes SuperLU with the block solver's settings for structurally symmetric blocks
    (minimum degree on ``A + A^T``, threshold pivoting): the whole elimination in 4 ms there,
    against 8 ms dense."""
    n = Aaa.shape[0]
    floor = 1e3 * np.finfo(float).eps
    sparse = n > SPARSE_ELIMINATION_MIN and (np.count_nonzero(Aaa) if not sp.issparse(Aaa)
                                             else sp.csr_matrix(Aaa).nnz) <= SPARSE_ELIMINATION_DENSITY * n * n
    As, r, c = _equilibrate(sp.csr_matrix(Aaa) if sparse else dense_array(Aaa))
    B = r[:, None] * dense_array(Aad)
    if not sparse:
        return _dense_solve(As, B, c, floor)
    try:
        lu = spla.splu(As, **DEFAULT_OPTIONS.superlu_options)
    except RuntimeError:  # exactly singular
        return None
    norm1 = float(abs(As).sum(axis=0).max())
    inv = spla.LinearOperator((n, n), matvec=lu.solve, rmatvec=lambda y: lu.solve(y, trans="T"), dtype=float)
    rcond = 1.0 / (norm1 * spla.onenormest(inv)) if norm1 else 0.0
    if not rcond > floor:
        return None
    return c[:, None] * lu.solve(B)


def _dense_solve(As: np.ndarray, B: np.ndarray, c: np.ndarray, floor: float) -> np.ndarray | None:
    """``c * As^-1 B`` by LAPACK, None when ``rcond(As) <= floor``."""
    try:
        lu = sla.lu_factor(As, check_finite=False)
        rcond = sla.lapack.dgecon(lu[0], float(np.abs(As).sum(axis=0).max()), norm="1")[0]
    except (sla.LinAlgError, ValueError):
        return None
    if not rcond > floor:
        return None
    return c[:, None] * sla.lu_solve(lu, B, check_finite=False)


def algebraic_unknowns(J1, J2) -> np.ndarray:
    """Unknowns whose rows and columns of ``J1`` and ``J2`` vanish: their equations hold at every
    ``s`` without derivatives (contact forces; massless, undamped DOFs)."""
    nz = np.zeros(J1.shape[0], dtype=bool)
    for A in (J1, J2):
        if not sp.issparse(A):
            hit = np.asarray(A) != 0
            nz |= hit.any(axis=1) | hit.any(axis=0)
            continue
        A = A.tocoo()
        hit = A.data != 0
        nz[A.row[hit]] = True
        nz[A.col[hit]] = True
    return ~nz
