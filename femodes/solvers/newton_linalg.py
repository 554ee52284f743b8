"""The linear algebra of a Newton iteration: the default direct solver, cheap norms and Jacobian checks.

:func:`default_linear_solver` solves ``J dx = -r`` (SuperLU for sparse matrices, LAPACK for dense
ones, ``factorize().solve`` for structured operators); :func:`max_abs` and :func:`all_finite` are
the infinity norm and finiteness test of the iterates (in Python floats for the small local
problems of time stepping); :func:`prepare_jacobian` and :func:`jacobian_finite` check what the
residual function returned.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .checks import is_operator

__all__ = ["default_linear_solver", "max_abs", "all_finite", "prepare_jacobian", "jacobian_finite", "F64"]


def default_linear_solver(A: Any, b: np.ndarray) -> np.ndarray:
    """Solve ``A y = b`` with a direct method.

    Sparse ``A`` (any ``scipy.sparse`` format) is converted to CSC and factorised
    with :func:`scipy.sparse.linalg.splu` (SuperLU, COLAMD ordering); dense
    ``A`` uses :func:`numpy.linalg.solve` (LAPACK ``gesv``).  A structured
    operator (an object with ``shape``, ``matvec`` and ``factorize()``, such as
    the harmonic-block Jacobian of the HBM problems) solves itself with
    ``A.factorize().solve(b)``.  Exactly singular matrices raise
    ``RuntimeError`` (SuperLU) or ``numpy.linalg.LinAlgError``.
    """
    if is_operator(A):
        return A.factorize().solve(b)
    if sp.issparse(A):
        A = sp.csc_matrix(A)
        if not np.issubdtype(A.dtype, np.inexact):
            A = A.astype(np.float64)
        return spla.splu(A).solve(np.asarray(b, dtype=np.result_type(A.dtype, b.dtype)))
    return np.linalg.solve(A, b)


#: The dtype of float arrays: a float64 ndarray passes where ``np.asarray(a, dtype=float)`` would
#: return ``a`` itself, without the call.
F64 = np.dtype(np.float64)

#: Arrays up to this size are reduced in Python floats: a numpy reduction costs ~2 us whatever the
#: size, several per iteration, and the local problems of a time step have 1 to a few unknowns.
SMALL = 16


def max_abs(v: np.ndarray) -> float:
    """``max |v_i|`` of a float vector (0 if empty), the value of :func:`inf_norm`: the maximum is
    exact, so the Python reduction of a small vector gives the same float (nan if an entry is)."""
    n = v.size
    if n == 1:
        return abs(v.item())  # nan stays nan, like np.abs(v).max()
    if n > SMALL:
        return float(np.abs(v).max())
    if not n:
        return 0.0
    a = v.tolist()
    if math.isnan(sum(a)):  # a nan entry (or inf - inf): numpy's nan propagation
        return float(np.abs(v).max())
    return max(map(abs, a))


def all_finite(v: np.ndarray) -> bool:
    """All entries finite, ``np.all(np.isfinite(v))`` (in Python floats for small arrays)."""
    n = v.size
    if n == 1:
        return math.isfinite(v.item())
    if n <= SMALL:
        return all(map(math.isfinite, v.ravel().tolist()))
    return bool(np.isfinite(v).all())


def prepare_jacobian(J: Any, n: int) -> Any:
    """Validate shape; return dense ndarray or sparse matrix unchanged otherwise."""
    if type(J) is np.ndarray and J.dtype is F64 and J.shape == (n, n):
        return J  # what np.asarray(J, dtype=float) would return, checked
    if sp.issparse(J) or is_operator(J):
        if J.shape != (n, n):
            raise ValueError(
                f"fun returned a Jacobian of shape {J.shape}, expected ({n}, {n}) for x of shape ({n},)"
            )
        return J
    Jd = np.asarray(J, dtype=float)
    if Jd.shape != (n, n):
        raise ValueError(
            f"fun returned a Jacobian of shape {Jd.shape}, expected ({n}, {n}) for x of shape ({n},)"
        )
    return Jd


def jacobian_finite(J: Any) -> bool:
    if type(J) is np.ndarray:
        return all_finite(J)
    if is_operator(J):
        return bool(J.all_finite()) if callable(getattr(J, "all_finite", None)) else True
    if sp.issparse(J):
        data = J.data if J.format in ("csr", "csc", "coo", "bsr", "dia") else J.tocoo().data
        return bool(np.all(np.isfinite(data)))
    return bool(np.all(np.isfinite(J)))
