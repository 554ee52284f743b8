r"""Models layer (leaf): sparse direct factorisations behind one small interface.

Every place of femodes that factorises a large sparse matrix (Craig-Bampton constraint modes,
shift-invert eigen-solves, linear responses, time stepping, the per-harmonic blocks of the
harmonic balance solver and Hill's method) calls :func:`factorize` and uses the returned
:class:`Factor`'s ``solve``. Three back-ends:

``superlu``
    scipy's SuperLU (:func:`scipy.sparse.linalg.splu`), with the caller's ordering options. It
    always installs and is the fallback.
``cholmod``
    CHOLMOD (supernodal Cholesky, SuiteSparse) through scikit-sparse, for real symmetric positive
    definite matrices (``positive_definite=True``): stiffnesses ``K_II``, ``K - sigma M`` with
    ``sigma <= 0``, the iteration matrix of time stepping.
``mumps``
    MUMPS (multifrontal, sequential) through python-mumps: real or complex, symmetric (``LDL^T``,
    also complex symmetric, not Hermitian) or unsymmetric (``LU``), with the PORD ordering (the
    fastest of its orderings on femodes' 3-D blocks, ``benchmarks/README_backends.md``).

The environment variable ``FEMODES_SPARSE_BACKEND`` (``auto`` by default, or ``superlu``,
``cholmod``, ``mumps``) chooses. ``auto`` takes, by the measurement of
``benchmarks/bench_backends.py`` on P2 tetrahedra (CPU time at 1.9e4 / 6.1e4 DOFs: ``K_II`` and
its constraint-mode solves 2.2x / 6.8x faster with CHOLMOD than with SuperLU, 1.9x / 8.2x with
MUMPS; a complex harmonic block 7x / 4.5x with MUMPS), CHOLMOD for positive definite
matrices, MUMPS for the others, each when installed, and SuperLU for matrices below
:data:`AUTO_MIN_SIZE` rows (where SuperLU is as fast and its results are the ones the tests
were written against). A named back-end is used at every size, for the matrices it can take
(CHOLMOD only the positive definite ones; the others then go to SuperLU). A back-end that is
requested but not installed falls back to SuperLU with one log record.
:func:`sparse_backend_info` says what is in use.

A factorisation that fails (singular, or not positive definite) raises
:class:`SingularMatrixError`, a :class:`RuntimeError` like SuperLU's own. A positive definite
factorisation that CHOLMOD rejects is retried as a symmetric indefinite one first, so that
"singular" means what it meant with SuperLU (an exactly zero or numerically null pivot).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .solvers.threads import refresh_blas_limit

__all__ = ["BACKENDS", "ENV_VAR", "AUTO_MIN_SIZE", "Factor", "SingularMatrixError", "SparseBackendInfo",
           "available_backends", "factorize", "is_symmetric", "sparse_backend_info"]

log = logging.getLogger(__name__)

#: The environment variable that selects the back-end.
ENV_VAR = "FEMODES_SPARSE_BACKEND"
#: The back-ends, SuperLU first (always installed), and the value that picks by measurement.
BACKENDS = ("superlu", "cholmod", "mumps")
_CHOICES = ("auto",) + BACKENDS
#: ``auto`` keeps SuperLU below this many rows: for positive definite matrices it is as fast there
#: (P2 box, 3e3 DOFs: K 22 ms SuperLU, 23 ms CHOLMOD, 39 ms MUMPS; 8.8e3 DOFs: K_II and its
#: solves 0.17, 0.17, 0.15 s; ``benchmarks/README_backends.md``), and the small models of the tests
#: and examples keep SuperLU's results. Complex blocks would gain below it too (3e3 DOFs: 1.4 s
#: SuperLU, 59 ms MUMPS); a lower limit for them is left open.
AUTO_MIN_SIZE = 5000
#: MUMPS ordering (ICNTL(7)): PORD; on the 6.1e4-DOF P2 box, analysis + factorisation of K_II
#: 1.7 s against 2.1 s (AMD), 4.0 s (automatic: SCOTCH) and 4.2 s (SCOTCH), of the complex block
#: 4.3 s against 7.5-7.7 s (exploratory run, ``benchmarks/README_backends.md``).
MUMPS_ORDERING = "pord"

_logged: set[str] = set()
_imported: set[str] = set()


class SingularMatrixError(RuntimeError):
    """The matrix could not be factorised (singular, or not positive definite where required)."""


def _log_once(key: str, level: int, msg: str, *args) -> None:
    if key not in _logged:
        _logged.add(key)
        log.log(level, msg, *args)


def _import(name: str):
    """The back-end's module, or None if it is not installed."""
    try:
        if name == "cholmod":
            from sksparse import cholmod as module
        elif name == "mumps":
            import mumps as module
        else:
            return spla
    except Exception as exc:  # ImportError, or a shared library that does not load
        _log_once(f"import:{name}", logging.DEBUG, "sparse back-end %s not importable: %s", name, exc)
        return None
    if name not in _imported:
        # the back-end brings the system's BLAS: under femodes' BLAS thread limit (an analysis),
        # that library gets the limit too (solvers.threads.refresh_blas_limit)
        _imported.add(name)
        refresh_blas_limit()
    return module


def available_backends() -> tuple[str, ...]:
    """The back-ends that import on this machine (SuperLU always)."""
    return tuple(b for b in BACKENDS if _import(b) is not None)


def requested_backend() -> str:
    """The value of ``FEMODES_SPARSE_BACKEND`` (``auto`` when unset), validated.

    Raises
    ------
    ValueError
        If the value is not one of ``auto, superlu, cholmod, mumps``; the message names the
        variable and the valid values.
    """
    raw = os.environ.get(ENV_VAR, "")
    value = raw.strip().lower() or "auto"
    if value not in _CHOICES:
        raise ValueError(f"{ENV_VAR}={raw!r} is not a sparse back-end; valid values: {', '.join(_CHOICES)}")
    return value


def _choose(n: int, positive_definite: bool) -> str:
    """The back-end for an ``n x n`` matrix of this kind under the current request."""
    req = requested_backend()
    if req == "superlu":
        return "superlu"
    if req == "auto":
        if n < AUTO_MIN_SIZE:
            return "superlu"
        order = ("cholmod", "mumps") if positive_definite else ("mumps",)
        for name in order:
            if _import(name) is not None:
                return name
        _log_once("auto-missing", logging.INFO,
                  "%s=auto: neither CHOLMOD (scikit-sparse) nor MUMPS (python-mumps) is installed; "
                  "sparse factorisations use SuperLU (make venv-fast installs them)", ENV_VAR)
        return "superlu"
    if _import(req) is None:
        _log_once(f"missing:{req}", logging.WARNING,
                  "%s=%s but that back-end is not installed; sparse factorisations use SuperLU", ENV_VAR, req)
        return "superlu"
    if req == "cholmod" and not positive_definite:
        return "superlu"  # CHOLMOD takes only symmetric positive definite matrices
    return req


@dataclass(frozen=True)
class SparseBackendInfo:
    """What :func:`factorize` uses now.

    Attributes
    ----------
    requested : str
        ``FEMODES_SPARSE_BACKEND`` (``auto`` when unset).
    available : tuple of str
        The back-ends installed on this machine.
    positive_definite, indefinite : str
        The back-end for real symmetric positive definite matrices, and for all others
        (complex, indefinite, unsymmetric), at or above ``min_size`` rows.
    min_size : int
        Below this many rows ``auto`` uses SuperLU (0 when a back-end is named).
    """

    requested: str
    available: tuple
    positive_definite: str
    indefinite: str
    min_size: int


def sparse_backend_info() -> SparseBackendInfo:
    """The sparse direct back-ends in use (module docstring: ``FEMODES_SPARSE_BACKEND``)."""
    req = requested_backend()
    n = AUTO_MIN_SIZE if req == "auto" else 0
    return SparseBackendInfo(requested=req, available=available_backends(),
                             positive_definite=_choose(max(n, 1), True), indefinite=_choose(max(n, 1), False),
                             min_size=n)


def is_symmetric(A) -> bool:
    """``A == A^T`` entry by entry (exactly: a decision of structure, not of round-off)."""
    A = sp.csr_matrix(A)
    D = A - A.T
    D.eliminate_zeros()
    return D.nnz == 0


class Factor:
    """A factorisation of a square sparse matrix ``A``: ``solve(b)`` returns ``A^-1 b``.

    ``b`` is a vector ``(n,)`` or a block of right-hand sides ``(n, k)``, real or complex (a
    complex ``b`` with a real factor is solved as its real and imaginary parts);
    ``solve(b, trans=True)`` solves with ``A^T`` (not conjugated). ``backend`` names the library
    that factorised. Built by :func:`factorize`.
    """

    def __init__(self, backend: str, n: int, dtype, solve, solve_t=None, nnz: int | None = None):
        self.backend = backend
        self.n = n
        self.dtype = np.dtype(dtype)
        self._solve = solve
        self._solve_t = solve_t
        #: entries stored by the factors, where the back-end says (SuperLU: ``L + U``)
        self.nnz = nnz
        self.shape = (n, n)

    def solve(self, b, trans: bool = False) -> np.ndarray:
        b = np.asarray(b)
        f = self._solve_t if trans else self._solve
        if f is None:
            raise NotImplementedError(f"{self.backend}: transposed solve not available")
        if np.iscomplexobj(b) and self.dtype.kind != "c":
            # real factor, complex right-hand sides: one solve with [Re b, Im b]
            B = b.reshape(self.n, -1)
            k = B.shape[1]
            X = f(np.ascontiguousarray(np.concatenate([B.real, B.imag], axis=1)))
            return (X[:, :k] + 1j * X[:, k:]).reshape(b.shape)
        b = b.astype(np.result_type(b.dtype, self.dtype), copy=False)
        return f(b)

    __call__ = solve


def _superlu(A, options: dict | None) -> Factor:
    try:
        lu = spla.splu(A, **(options or {}))
    except RuntimeError as exc:
        raise SingularMatrixError(str(exc)) from None
    return Factor("superlu", A.shape[0], A.dtype, lu.solve,
                  lambda b: lu.solve(b, trans="T"), nnz=int(lu.nnz))


def _cholmod(A) -> Factor:
    cholmod = _import("cholmod")
    try:
        f = cholmod.cholesky(A.tocsc())
    except cholmod.CholmodNotPositiveDefiniteError as exc:
        raise SingularMatrixError(f"not positive definite ({exc})") from None
    except cholmod.CholmodError as exc:
        raise SingularMatrixError(str(exc)) from None

    def solve(b):
        return f(np.asfortranarray(b))
    return Factor("cholmod", A.shape[0], A.dtype, solve, solve)


def _mumps_context(A, symmetric: bool):
    mumps = _import("mumps")
    ctx = mumps.Context()
    ctx.set_matrix(sp.triu(A, format="coo") if symmetric else A.tocoo(), symmetric=symmetric)
    try:
        ctx.factor(ordering=MUMPS_ORDERING)
    except mumps.MUMPSError as exc:
        raise SingularMatrixError(str(exc)) from None
    return ctx


def _mumps(A, symmetric: bool) -> Factor:
    ctx = _mumps_context(A, symmetric)
    if symmetric:
        return Factor("mumps", A.shape[0], A.dtype, ctx.solve, ctx.solve)
    transposed = []

    def solve_t(b):  # A^T factorised on first use (unsymmetric matrices are rare here)
        if not transposed:
            transposed.append(_mumps_context(A.T.tocsc(), False))
        return transposed[0].solve(b)
    return Factor("mumps", A.shape[0], A.dtype, ctx.solve, solve_t)


def factorize(A, *, positive_definite: bool = False, symmetric: bool | None = None,
              superlu_options: dict | None = None) -> Factor:
    """Factorise the square sparse matrix ``A`` with the back-end in use (module docstring).

    Parameters
    ----------
    A : sparse matrix (n, n), real or complex
    positive_definite : bool
        ``A`` is real symmetric and expected positive definite (CHOLMOD may take it). If the
        Cholesky factorisation fails, a symmetric indefinite one is tried before
        :class:`SingularMatrixError` is raised.
    symmetric : bool, optional
        ``A == A^T`` (complex symmetric, not Hermitian, for complex ``A``); checked exactly when
        not given, and only when a back-end other than SuperLU would take the matrix.
    superlu_options : dict, optional
        Keyword arguments of :func:`scipy.sparse.linalg.splu` (ordering, pivoting) when SuperLU
        factorises.

    Raises
    ------
    SingularMatrixError
        The matrix is singular (or numerically so, by the back-end's own pivot test).
    ValueError
        ``FEMODES_SPARSE_BACKEND`` has a value that is not a back-end.
    """
    A = sp.csc_matrix(A)
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError(f"factorize: A must be square, got shape {A.shape}")
    positive_definite = bool(positive_definite) and not np.iscomplexobj(A.data)
    backend = _choose(n, positive_definite)
    if backend == "superlu":
        return _superlu(A, superlu_options)
    if symmetric is None:
        symmetric = is_symmetric(A)
    if backend == "cholmod":
        if symmetric:
            try:
                return _cholmod(A)
            except SingularMatrixError as exc:
                log.debug("CHOLMOD rejected the matrix (%s); symmetric indefinite factorisation instead", exc)
        backend = _choose(max(n, AUTO_MIN_SIZE), False)
        if backend in ("superlu", "cholmod"):
            return _superlu(A, superlu_options)
    return _mumps(A, bool(symmetric))
