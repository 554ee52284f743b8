r"""Models layer (leaf): sparse direct factorisations behind one small interface.

Every place of femodes that factorises a large sparse matrix (Craig-Bampton constraint modes,
shift-invert eigen-solves, linear responses, time stepping, the per-harmonic blocks of the
harmonic balance solver and Hill's method) calls :func:`factorize` and uses the returned
:class:`Factor`'s ``solve`` (:func:`femodes.sparse_schur.schur_complement` condenses onto chosen
rows through the same back-ends). Four back-ends:

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
``pardiso``
    oneMKL PARDISO (supernodal, threaded) through :mod:`.sparse_pardiso`: the same kinds as MUMPS.

The environment variable ``FEMODES_SPARSE_BACKEND`` (``auto`` by default, or ``superlu``,
``cholmod``, ``mumps``, ``pardiso``) chooses. ``auto`` takes, by the measurement of
``benchmarks/bench_backends.py`` on P2 tetrahedra (:data:`AUTO_POSITIVE_DEFINITE`), CHOLMOD for
positive definite matrices, MUMPS for the others (PARDISO when it may use two threads or more,
:func:`auto_order`), each when installed, and SuperLU below :data:`AUTO_MIN_SIZE` rows (as fast
there, and the tests' reference). A named
back-end is used at every size for the matrices it takes (CHOLMOD: positive definite only; the
others go to SuperLU); one that is not installed falls back to SuperLU with one log record.
:func:`sparse_backend_info` says what is in use. Matrices of one sparsity pattern (the harmonic
blocks ``K - f^2 M + i f C``) go through a :class:`PatternFactorizer`, which reuses the analysis.

A factorisation that fails (singular, or not positive definite) raises
:class:`SingularMatrixError`, a :class:`RuntimeError` like SuperLU's own. A positive definite
factorisation that CHOLMOD rejects is retried as a symmetric indefinite one first, so that
"singular" means what it meant with SuperLU (an exactly zero or numerically null pivot).
"""

from __future__ import annotations

import logging
import os
import threading
import weakref
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .solvers.threads import refresh_blas_limit
from .sparse_pardiso import pardiso_threads

__all__ = ["BACKENDS", "ENV_VAR", "AUTO_MIN_SIZE", "Factor", "PatternFactorizer", "SingularMatrixError",
           "SparseBackendInfo", "available_backends", "auto_order", "backend_module", "chosen_backend", "factorize",
           "is_symmetric", "sparse_backend_info"]

log = logging.getLogger(__name__)

#: The environment variable that selects the back-end.
ENV_VAR = "FEMODES_SPARSE_BACKEND"
#: The back-ends, SuperLU first (always installed), and the value that picks by measurement.
BACKENDS = ("superlu", "cholmod", "mumps", "pardiso")
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
#: ``auto``'s preference, the first installed of each list. ``benchmarks/bench_backends.py`` on one
#: thread (CPU s at 1.9e4 / 6.1e4 DOFs, P2 box): ``K_II`` and its constraint-mode solves SuperLU
#: 0.88 / 22.6, CHOLMOD 0.46 / 3.51, MUMPS 0.47 / 2.69, PARDISO 0.55 / 3.28; a complex block and
#: its condensation columns SuperLU 6.93 / 30.5, MUMPS 0.94 / 6.56, PARDISO 1.00 / 7.34; a whole
#: Craig-Bampton SuperLU 1.97 / 30.8, the others 1.34-1.60 / 7.34-7.54. So on one thread PARDISO
#: comes last; it is the one fast back-end that installs from a wheel alone (``pip install mkl``).
AUTO_POSITIVE_DEFINITE = ("cholmod", "mumps", "pardiso")
AUTO_INDEFINITE = ("mumps", "pardiso")
#: The order for complex and indefinite matrices when PARDISO may use two threads or more
#: (:func:`.sparse_pardiso.pardiso_threads`; MUMPS is sequential here): a Newton iteration of a
#: 6.1e4-DOF 3-D HBM continuation took 12.5 s with MUMPS against 8.2 s of wall time with PARDISO
#: on two threads, both with the default solver options (``benchmarks/README_solids_scale.md``).
AUTO_INDEFINITE_THREADED = ("pardiso", "mumps")

_logged: set[str] = set()
_imported: set[str] = set()


class SingularMatrixError(RuntimeError):
    """The matrix could not be factorised (singular, or not positive definite where required)."""


def _log_once(key: str, level: int, msg: str, *args) -> None:
    if key not in _logged:
        _logged.add(key)
        log.log(level, msg, *args)


def backend_module(name: str):
    """The back-end's module (``name`` one of :data:`BACKENDS`), or None if it is not installed."""
    try:
        if name == "cholmod":
            from sksparse import cholmod as module
        elif name == "mumps":
            import mumps as module
        elif name == "pardiso":
            from . import sparse_pardiso as module
            if module.load_library() is None:
                raise ImportError("libmkl_rt not found (pip install mkl)")
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
    return tuple(b for b in BACKENDS if backend_module(b) is not None)


def requested_backend() -> str:
    """The value of ``FEMODES_SPARSE_BACKEND`` (``auto`` when unset), validated.

    Raises
    ------
    ValueError
        If the value is not one of ``auto, superlu, cholmod, mumps, pardiso``; the message names the
        variable and the valid values.
    """
    raw = os.environ.get(ENV_VAR, "")
    value = raw.strip().lower() or "auto"
    if value not in _CHOICES:
        raise ValueError(f"{ENV_VAR}={raw!r} is not a sparse back-end; valid values: {', '.join(_CHOICES)}")
    return value


def auto_order(positive_definite: bool) -> tuple[str, ...]:
    """``auto``'s back-ends for this kind of matrix, in order of preference (those installed first
    win): :data:`AUTO_POSITIVE_DEFINITE`, or for the others :data:`AUTO_INDEFINITE_THREADED` when
    PARDISO may use two threads or more (``FEMODES_PARDISO_THREADS``), else :data:`AUTO_INDEFINITE`."""
    if positive_definite:
        return AUTO_POSITIVE_DEFINITE
    return AUTO_INDEFINITE_THREADED if pardiso_threads() >= 2 else AUTO_INDEFINITE


def chosen_backend(n: int, positive_definite: bool) -> str:
    """The back-end :func:`factorize` takes for an ``n x n`` matrix of this kind under the current request."""
    req = requested_backend()
    if req == "superlu":
        return "superlu"
    if req == "auto":
        if n < AUTO_MIN_SIZE:
            return "superlu"
        for name in auto_order(positive_definite):
            if backend_module(name) is not None:
                return name
        _log_once("auto-missing", logging.INFO,
                  "%s=auto: none of CHOLMOD (scikit-sparse), MUMPS (python-mumps) and PARDISO (mkl) is installed; "
                  "sparse factorisations use SuperLU (make venv installs them where it can)", ENV_VAR)
        return "superlu"
    if backend_module(req) is None:
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
                             positive_definite=chosen_backend(max(n, 1), True), indefinite=chosen_backend(max(n, 1), False),
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
    complex ``b`` with a real factor is solved as its real and imaginary parts), dense or a
    scipy sparse matrix (MUMPS then prunes the forward substitution to the rows that are
    nonzero: the ``n_b`` condensation columns of a 3-D harmonic block, nonzero on 640 of 1.9e4
    rows, solve in 0.15 instead of 0.28 s; the others solve it as a dense array);
    ``solve(b, trans=True)`` solves with ``A^T`` (not conjugated). ``backend`` names the library
    that factorised. Built by :func:`factorize`.
    """

    def __init__(self, backend: str, n: int, dtype, solve, solve_t=None, nnz: int | None = None,
                 solve_sparse=None):
        self.backend = backend
        self.n = n
        self.dtype = np.dtype(dtype)
        self._solve = solve
        self._solve_t = solve_t
        self._solve_sparse = solve_sparse
        #: entries stored by the factors, where the back-end says (SuperLU: ``L + U``)
        self.nnz = nnz
        self.shape = (n, n)

    def solve(self, b, trans: bool = False) -> np.ndarray:
        if sp.issparse(b):
            if (self._solve_sparse is not None and not trans and b.ndim == 2
                    and np.can_cast(b.dtype, self.dtype, casting="same_kind")):
                return self._solve_sparse(b)
            b = b.toarray()
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
    cholmod = backend_module("cholmod")
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
    mumps = backend_module("mumps")
    ctx = mumps.Context()
    ctx.set_matrix(sp.triu(A, format="coo") if symmetric else A.tocoo(), symmetric=symmetric)
    try:
        ctx.factor(ordering=MUMPS_ORDERING)
    except mumps.MUMPSError as exc:
        raise SingularMatrixError(str(exc)) from None
    return ctx


#: MUMPS's blocking of multiple right-hand sides (ICNTL(27)) is set to the number of columns from
#: this many on (default -32: automatic, at most 32); the 81 condensation columns of a 1.9e4-DOF
#: harmonic block: 0.28 s at the default, 0.24 s at 81, 0.235 s at 128 (dense right-hand sides).
MUMPS_BLOCKING_MIN = 32


def _mumps_solvers(ctx, dtype):
    """Dense and sparse solves with an analysed and factorised python-mumps ``Context``."""
    inst = ctx.mumps_instance
    dtype = np.dtype(dtype)

    def blocking(k: int) -> None:
        inst.icntl[27] = k if k > MUMPS_BLOCKING_MIN else -MUMPS_BLOCKING_MIN

    def solve(b):
        blocking(b.shape[1] if b.ndim == 2 else 1)
        return ctx.solve(b)

    def solve_sparse(b):
        blocking(b.shape[1])
        try:
            return ctx.solve(sp.csc_matrix(b, dtype=dtype))
        finally:
            inst.icntl[20] = 0  # python-mumps leaves the sparse right-hand side switched on
    return solve, solve_sparse


def _mumps(A, symmetric: bool) -> Factor:
    ctx = _mumps_context(A, symmetric)
    if symmetric:
        solve, solve_sparse = _mumps_solvers(ctx, A.dtype)
        return Factor("mumps", A.shape[0], A.dtype, solve, solve, solve_sparse=solve_sparse)
    transposed: list = []

    def solve_t(b):  # A^T factorised on first use (unsymmetric matrices are rare here)
        if not transposed:
            transposed.append(_mumps_context(A.T.tocsc(), False))
        return transposed[0].solve(b)
    return Factor("mumps", A.shape[0], A.dtype, ctx.solve, solve_t)


def _pardiso_factor(handle) -> Factor:
    """The factor of a factorised PARDISO handle; SingularMatrixError if pivots stayed perturbed."""
    if handle.perturbed:
        raise SingularMatrixError(f"PARDISO perturbed {handle.perturbed} pivot(s) even with scaling and matching: "
                                  f"the matrix is numerically singular")
    return Factor("pardiso", handle.n, handle.dtype, handle.solve, lambda b: handle.solve(b, trans=True), nnz=handle.nnz)


def _pardiso(A, symmetric: bool, positive_definite: bool) -> Factor:
    mod = backend_module("pardiso")
    A = A.astype(np.result_type(A.dtype, np.float64), copy=False)
    mtype = mod.matrix_type(A.dtype, symmetric, positive_definite)
    try:
        handle = mod.PardisoHandle(A, mtype)
    except mod.PardisoError as exc:
        if exc.code == -4 and mtype == 2:  # not positive definite: symmetric indefinite, as CHOLMOD's fallback
            log.debug("PARDISO's Cholesky rejected the matrix (%s); symmetric indefinite factorisation instead", exc)
            return _pardiso(A, True, False)
        raise SingularMatrixError(str(exc)) from None
    return _pardiso_factor(handle)


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
    backend = chosen_backend(n, positive_definite)
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
        backend = chosen_backend(max(n, AUTO_MIN_SIZE), False)
        if backend in ("superlu", "cholmod"):
            return _superlu(A, superlu_options)
    if backend == "pardiso":
        return _pardiso(A, bool(symmetric), positive_definite)
    return _mumps(A, bool(symmetric))


class PatternFactorizer:
    r"""Factorisations of square matrices that share one sparsity pattern, given by their values on it.

    ``rows, cols`` (no duplicates) is the pattern of an ``n x n`` matrix; :meth:`factorize` takes
    the values on it (real or complex) and returns what :func:`factorize` would for that matrix,
    with the back-end chosen the same way. What is shared between the matrices:

    - the conversion to CSC: a permutation of the values computed once (no sort per matrix);
    - with MUMPS and a symmetric pattern (``LDL^T``), the symbolic analysis: ordering, elimination
      tree, memory estimates. A MUMPS instance analysed for this pattern whose factor has been
      released (the :class:`Factor` was garbage-collected) goes back to a pool, and the next
      matrix of the same kind (real or complex) is factorised in it numerically only
      (``Context.factor(reuse_analysis=True)``). The PORD analysis is about a quarter of a 3-D
      harmonic block's factorisation (0.56 of 2.3 s at 3.6e4 DOFs,
      ``benchmarks/README_solids_scale.md``);
    - with PARDISO and a symmetric pattern whose diagonal is stored, the same: an analysed
      handle whose factor was released takes the next matrix of its type by a numerical
      factorisation alone (:meth:`.sparse_pardiso.PardisoHandle.refactor`).

    The numerical factorisation with a reused analysis is MUMPS's own threshold-pivoting ``LDL^T``
    (``CNTL(1)`` as a fresh one; pivots that fail the threshold are delayed, at the cost of fill),
    so its backward error is bounded as a fresh factorisation's: solutions agree to ``cond(A)``
    times eps. The idle instances keep their factors' memory until they are reused or
    :meth:`release` is called: a Newton iteration that builds a new set of blocks while the last
    set is alive holds both sets anyway (its peak), and that many instances stay pooled.

    Attributes
    ----------
    analyses, reused : int
        MUMPS or PARDISO factorisations with a fresh analysis, and with a reused one.
    """

    def __init__(self, rows, cols, n: int, *, symmetric: bool | None = None):
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        if rows.shape != cols.shape or rows.ndim != 1:
            raise ValueError(f"PatternFactorizer: rows and cols must be 1-D of one length, got {rows.shape}, {cols.shape}")
        self.n = n = int(n)
        self.nnz = rows.size
        order = np.lexsort((rows, cols))  # CSC: by column, then row
        self._csc_order = order
        self._indices = rows[order].astype(np.int32)
        self._indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=n))]).astype(np.int32)
        if symmetric is None:
            symmetric = is_symmetric(sp.csc_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))) if rows.size else True
        self.symmetric = bool(symmetric)
        # upper triangle (what MUMPS reads of a symmetric matrix), in a fixed order
        self._upper = np.flatnonzero(rows <= cols) if self.symmetric else None
        self._upper_rc = (rows[self._upper], cols[self._upper]) if self.symmetric else None
        # PARDISO's order of the upper triangle (CSR: by row, then column); its symmetric types
        # need the whole diagonal stored, which the harmonic blocks' patterns have
        self._csr_upper: np.ndarray | None = None
        self._full_diagonal = False
        if self._upper is not None and self._upper_rc is not None:
            ru, cu = self._upper_rc
            self._csr_upper = self._upper[np.lexsort((cu, ru))]
            self._full_diagonal = int(np.count_nonzero(ru == cu)) == n
        self._idle: dict = {}
        self._lock = threading.Lock()
        self.analyses = 0
        self.reused = 0

    def matrix(self, values) -> sp.csc_matrix:
        """The CSC matrix of ``values`` on the pattern (canonical: sorted, no duplicates)."""
        values = np.asarray(values)
        A = sp.csc_matrix((values[self._csc_order], self._indices, self._indptr), shape=(self.n, self.n))
        A.has_sorted_indices = True
        return A

    def factorize(self, values, *, positive_definite: bool = False, superlu_options: dict | None = None) -> Factor:
        """The factorisation of the matrix of ``values`` (:func:`factorize`'s contract)."""
        values = np.asarray(values)
        if values.shape != (self.nnz,):
            raise ValueError(f"PatternFactorizer: {self.nnz} values expected, got shape {values.shape}")
        positive_definite = bool(positive_definite) and not np.iscomplexobj(values)
        backend = chosen_backend(self.n, positive_definite)
        if self.symmetric and backend == "mumps":
            return self._mumps(values)
        if self.symmetric and backend == "pardiso" and self._full_diagonal:
            return self._pardiso(values, positive_definite)
        if backend == "cholmod" and self.symmetric:
            try:
                return _cholmod(self.matrix(values))
            except SingularMatrixError as exc:
                log.debug("CHOLMOD rejected the matrix (%s); symmetric indefinite factorisation instead", exc)
            if chosen_backend(max(self.n, AUTO_MIN_SIZE), False) == "mumps":
                return self._mumps(values)
        return factorize(self.matrix(values), positive_definite=positive_definite, symmetric=self.symmetric,
                         superlu_options=superlu_options)

    def _mumps(self, values) -> Factor:
        mumps = backend_module("mumps")
        data = np.ascontiguousarray(values[self._upper])
        key = data.dtype.char
        A = sp.coo_matrix((data, self._upper_rc), shape=(self.n, self.n))
        with self._lock:
            idle = self._idle.get(key)
            ctx = idle.pop() if idle else None
        if ctx is None:
            ctx = _mumps_context(A, True)
            self.analyses += 1
        else:
            ctx.set_matrix(A, symmetric=True)  # same kind: the analysed instance is kept
            try:
                ctx.factor(ordering=MUMPS_ORDERING, reuse_analysis=True)
            except mumps.MUMPSError as exc:
                raise SingularMatrixError(str(exc)) from None  # the instance is dropped
            self.reused += 1
        solve, solve_sparse = _mumps_solvers(ctx, data.dtype)
        fac = Factor("mumps", self.n, data.dtype, solve, solve, solve_sparse=solve_sparse)
        weakref.finalize(fac, self._give_back, key, ctx)
        return fac

    def _pardiso(self, values, positive_definite: bool) -> Factor:
        mod = backend_module("pardiso")
        assert self._csr_upper is not None
        data = np.ascontiguousarray(values[self._csr_upper], dtype=np.result_type(values.dtype, np.float64))
        mtype = mod.matrix_type(data.dtype, True, positive_definite)
        key = ("pardiso", mtype)
        with self._lock:
            idle = self._idle.get(key)
            handle = idle.pop() if idle else None
        try:
            if handle is None:
                assert self._upper_rc is not None  # a symmetric pattern (the caller's test)
                rows, cols = self._upper_rc
                A = sp.csr_matrix((values[self._upper].astype(data.dtype), (rows, cols)), shape=(self.n, self.n))
                handle = mod.PardisoHandle(A, mtype)
                self.analyses += 1
            else:
                handle.refactor(data)
                self.reused += 1
        except mod.PardisoError as exc:
            if exc.code == -4 and mtype == 2:  # not positive definite: symmetric indefinite, unpooled
                return _pardiso(self.matrix(values), True, False)
            raise SingularMatrixError(str(exc)) from None  # the handle is dropped
        fac = _pardiso_factor(handle)  # perturbed pivots raise before the handle could be pooled
        weakref.finalize(fac, self._give_back, key, handle)
        return fac

    def _give_back(self, key, ctx) -> None:
        with self._lock:
            self._idle.setdefault(key, []).append(ctx)

    def release(self) -> None:
        """Free the pooled MUMPS instances (their factors' memory); the next factorisations analyse anew."""
        with self._lock:
            self._idle = {}  # python-mumps frees an instance's memory (JOB = -2) when it is collected
