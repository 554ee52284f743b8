"""Models layer (leaf): the Schur complement of a sparse matrix on chosen rows, through the
sparse direct back-end in use (:mod:`femodes.sparse_direct`).

MUMPS and PARDISO compute it in their own partial factorisation, which never forms the
``len(keep)`` interior solutions: MUMPS with ``ICNTL(19)`` (python-mumps returns the lower triangle
of a symmetric Schur complement, completed here), PARDISO with ``iparm[35] = 1``
(:func:`femodes.sparse_pardiso.schur`; its rows come in increasing index order and are put back in
the caller's). SuperLU and CHOLMOD factorise the rest and solve for the kept columns.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .sparse_direct import (MUMPS_ORDERING, SingularMatrixError, backend_module, chosen_backend, factorize,
                            is_symmetric)

__all__ = ["schur_complement"]


def schur_complement(A, keep, *, positive_definite: bool = False, symmetric: bool | None = None) -> np.ndarray:
    """The Schur complement ``S = A_kk - A_ki A_ii^-1 A_ik`` of ``A`` on the rows and columns ``keep``.

    ``i`` are the other indices; ``S`` is dense, in the order of ``keep``. With MUMPS or PARDISO
    (chosen as :func:`factorize` chooses) it comes from the library's own partial factorisation
    (MUMPS ``ICNTL(19)``, PARDISO ``iparm[35]``), which never forms ``A_ii^-1 A_ik``; SuperLU and
    CHOLMOD factorise ``A_ii`` and solve for the ``len(keep)`` columns of ``A_ik``.
    ``positive_definite`` and ``symmetric`` describe ``A``, as for :func:`factorize`.

    Raises
    ------
    ValueError
        ``keep`` is empty, has repeated or out-of-range indices, or keeps every index.
    SingularMatrixError
        ``A_ii`` is singular.
    """
    A = sp.csc_matrix(A)
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError(f"schur_complement: A must be square, got shape {A.shape}")
    k = np.asarray(keep, dtype=np.int64).ravel()
    if k.size == 0 or k.size >= n or np.unique(k).size != k.size or k.min() < 0 or k.max() >= n:
        raise ValueError(f"schur_complement: keep must hold between 1 and {n - 1} distinct indices in [0, {n}), "
                         f"got {k.size} (min {k.min() if k.size else None}, max {k.max() if k.size else None})")
    positive_definite = bool(positive_definite) and not np.iscomplexobj(A.data)
    if symmetric is None:
        symmetric = is_symmetric(A)
    backend = chosen_backend(n, positive_definite)
    if backend == "pardiso":
        mod = backend_module("pardiso")
        A = A.astype(np.result_type(A.dtype, np.float64), copy=False)
        order = np.argsort(k)  # PARDISO returns the kept rows in increasing order
        mtype = mod.matrix_type(A.dtype, bool(symmetric), positive_definite)
        try:
            try:
                S, perturbed = mod.schur(A, k, mtype)
            except mod.PardisoError as exc:
                if not (exc.code == -4 and mtype == 2):
                    raise
                S, perturbed = mod.schur(A, k, -2)  # not positive definite: LDL^T, as factorize does
        except mod.PardisoError as exc:
            raise SingularMatrixError(str(exc)) from None
        if perturbed:
            raise SingularMatrixError(f"PARDISO perturbed {perturbed} pivot(s) of A_ii: numerically singular")
        inverse = np.empty_like(order)
        inverse[order] = np.arange(k.size)
        return S[np.ix_(inverse, inverse)]
    if backend == "mumps":
        mumps = backend_module("mumps")
        ctx = mumps.Context()
        ctx.set_matrix(sp.triu(A, format="coo") if symmetric else A.tocoo(), symmetric=bool(symmetric))
        try:
            S = np.array(ctx.schur(k, ordering=MUMPS_ORDERING))
        except mumps.MUMPSError as exc:
            raise SingularMatrixError(str(exc)) from None
        if symmetric:  # MUMPS returns the lower triangle of a symmetric Schur complement
            S = np.tril(S) + np.tril(S, -1).T
        return S
    mask = np.ones(n, dtype=bool)
    mask[k] = False
    i = np.flatnonzero(mask)
    Ar = A.tocsr()
    f = factorize(Ar[i][:, i], positive_definite=positive_definite, symmetric=symmetric)
    return Ar[k][:, k].toarray() - Ar[k][:, i] @ f.solve(Ar[i][:, k].toarray())
