"""Checks of a model's matrices and fields: square, real, finite, symmetric, positive
semidefinite (:func:`as_sparse_matrix`, :func:`check_fields`), with messages that quote the bad value."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from .damping import LowRankDamping
from .dofs import DofMap

__all__ = ["as_sparse_matrix", "check_symmetric", "check_semidefinite", "check_fields"]


def as_sparse_matrix(A: Any, name: str, n: int | None = None) -> sp.csr_matrix:
    """Validate a square real finite matrix (dense or sparse) and return it as CSR."""
    if A is None:
        raise ValueError(f"{name} is required")
    if sp.issparse(A):
        if np.iscomplexobj(A.data):
            raise TypeError(f"{name} must be a real matrix, got complex entries (dtype {A.dtype})")
        A = sp.csr_matrix(A, dtype=float)
    else:
        try:
            raw = np.asarray(A)
            if raw.dtype.kind == "c":
                raise TypeError(f"{name} must be a real matrix, got complex entries (dtype {raw.dtype})")
            if raw.dtype.kind in "SUV" or isinstance(A, (str, bytes)):
                raise TypeError(f"{name} must be a square real matrix, got entries of type {raw.dtype} ({A!r:.60})")
            arr = np.asarray(raw, dtype=float)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, TypeError) and str(exc).startswith(name):
                raise
            raise TypeError(
                f"{name} must be a square real matrix (numpy array or scipy.sparse) with rows of equal length, "
                f"got {type(A).__name__} ({exc})"
            ) from exc
        if arr.ndim == 0 and n == 1:
            arr = arr.reshape(1, 1)
        if arr.ndim != 2:
            raise ValueError(f"{name} must be a 2-D square matrix, got shape {arr.shape}")
        A = sp.csr_matrix(arr)
    if A.shape[0] != A.shape[1]:
        raise ValueError(f"{name} must be square, got shape {A.shape}")
    if n is not None and A.shape[0] != n:
        raise ValueError(f"{name} has shape {A.shape} but the model has {n} DOFs (M is {n}x{n})")
    if not np.all(np.isfinite(A.data)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    return A


def check_symmetric(A: sp.csr_matrix, name: str) -> None:
    scale = abs(A).max() if A.nnz else 0.0
    asym = abs(A - A.T).max() if A.nnz else 0.0
    if asym > 1e-10 * max(scale, 1e-300):
        raise ValueError(f"{name} must be symmetric: max |{name} - {name}^T| = {asym:.3e} (max |{name}| = {scale:.3e})")


def check_semidefinite(A: sp.csr_matrix, name: str, *, definite: bool) -> None:
    """Reject matrices with a clearly negative eigenvalue (or a non-positive diagonal for M)."""
    d = A.diagonal()
    scale = float(abs(A).max()) if A.nnz else 0.0
    # Zero diagonal entries are legitimate (mass redistributed away from a contact node).
    if np.any(d < -1e-12 * max(scale, 1e-300)):
        i = int(np.argmin(d))
        raise ValueError(f"{name} must be positive semidefinite; diagonal entry {name}[{i},{i}] = {d[i]:.6g} < 0")
    n = A.shape[0]
    if n <= 400:
        lam = np.linalg.eigvalsh(A.toarray())
        if lam[0] < -1e-9 * max(abs(lam[-1]), 1e-300):
            raise ValueError(f"{name} must be positive semidefinite; its smallest eigenvalue is {lam[0]:.6g}")
        if definite and lam[-1] <= 0:
            raise ValueError(f"{name} must not be zero")
    # Large sparse matrices: the diagonal test above; a full eigenvalue test would cost a factorization.


def check_fields(model) -> None:
    """Validate the fields of a new model and store them normalised (``M``, ``K``, ``C`` as CSR,
    the ``dofmap`` of a discrete model, ``frame`` as CSR); ``damping_info`` says ``"matrix C"``
    for a damping matrix given directly."""
    M = as_sparse_matrix(model.M, "M")
    n = M.shape[0]
    if n == 0:
        raise ValueError("M must have at least one DOF")
    K = as_sparse_matrix(model.K, "K", n)
    C = sp.csr_matrix((n, n)) if model.C is None else as_sparse_matrix(model.C, "C", n)
    check_symmetric(M, "M")
    check_symmetric(K, "K")
    check_symmetric(C, "C")
    if M.nnz == 0 or not np.any(M.diagonal() > 0):
        raise ValueError("M must have positive mass on at least one DOF")
    check_semidefinite(M, "M", definite=True)
    check_semidefinite(K, "K", definite=False)
    check_semidefinite(C, "C", definite=False)
    object.__setattr__(model, "M", M)
    object.__setattr__(model, "K", K)
    object.__setattr__(model, "C", C)
    if model.C_lowrank is not None:
        if not isinstance(model.C_lowrank, LowRankDamping):
            raise TypeError(f"C_lowrank must be a LowRankDamping or None, got {type(model.C_lowrank).__name__}")
        if model.C_lowrank.n != n:
            raise ValueError(f"C_lowrank has {model.C_lowrank.n} rows but the model has {n} DOFs")
    if model.damping_info == "none" and C.nnz and np.any(C.data != 0):
        object.__setattr__(model, "damping_info", "matrix C")  # given directly (StructuralModel(C=...))
    dm = model.dofmap
    if dm is None:
        dm = DofMap.discrete(n, model.dof_names)
    elif dm.n_dofs != n:
        raise ValueError(f"dofmap has {dm.n_dofs} DOFs but M is {n}x{n}")
    object.__setattr__(model, "dofmap", dm)
    if model.frame is not None:
        if not sp.issparse(model.frame) or model.frame.shape != (n, n):
            raise ValueError(f"frame must be a sparse {n}x{n} matrix (u = frame @ q) or None")
        if model.fe is None:
            raise ValueError("frame (nodal rotations) needs an FE model (fe=...)")
        object.__setattr__(model, "frame", sp.csr_matrix(model.frame))
