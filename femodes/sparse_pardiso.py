r"""Models layer (leaf): Intel MKL PARDISO through ctypes, the ``pardiso`` back-end of :mod:`.sparse_direct`.

PARDISO (parallel supernodal direct solver of oneMKL) factorises real symmetric positive definite
(``LL^T``), real symmetric indefinite and **complex symmetric** (``LDL^T`` with Bunch-Kaufman
pivoting, not Hermitian) and unsymmetric (``LU``) matrices. Complex symmetric is what the harmonic
blocks ``K - f^2 M + i f C`` of the HBM solver are; the ``pypardiso`` package binds the real
matrix types only, so femodes calls ``libmkl_rt`` itself. The library comes with the ``mkl``
wheel from PyPI (x86-64; about 0.9 GB installed; proprietary licence, free to use and to
redistribute); ``make venv`` installs it where it can (``tools/fast_backends.sh``). What this
module does with it, from the oneMKL reference (``pardiso``, ``pardisoinit``, ``iparm``):

- ``pardisoinit`` sets the defaults of a matrix type; on top of them: zero-based indices
  (``iparm[34] = 1``), METIS nested dissection (``iparm[1] = 2``), and no iterative refinement
  unless pivots were perturbed (``iparm[7] = 0``; the default refines twice on every solve, which
  tripled the cost of 81 right-hand sides on a 1.9e4-DOF block);
- analysis (phase 11) once per handle, numerical factorisation (phase 22), solve (phase 33,
  ``iparm[11] = 2`` for ``A^T``), release (phase -1) when the handle is collected. A handle
  analysed for one pattern takes the next matrix of that pattern by phase 22 alone
  (:meth:`PardisoHandle.refactor`; the analysis is about a quarter of a 3-D complex block's
  factorisation, 1.0 of 4.2 s at 6.1e4 DOFs);
- a zero pivot of a positive definite factorisation (error -4) and perturbed pivots of an
  indefinite one (``iparm[13] > 0``: PARDISO replaces a tiny pivot by ``eps_p ||A||`` instead of
  failing) are retried once with scaling and weighted matching (``iparm[10] = iparm[12] = 1``);
  pivots still perturbed raise :class:`~.sparse_direct.SingularMatrixError` through the caller,
  so that "singular" means what it means for SuperLU and MUMPS.

Threads: PARDISO's factorisations are large (``auto`` sends it nothing below 5000 rows) and pay on
several cores, unlike the small dense operations that femodes' BLAS limit
(:mod:`femodes.solvers.threads`, one thread by default) is for. Each PARDISO call therefore runs
with its own thread count, set thread-locally around the call (``mkl_set_num_threads_local``):
``FEMODES_PARDISO_THREADS``, else ``MKL_NUM_THREADS``, else the cores this process may use
(:func:`pardiso_threads`). On the 2-core machine, a Newton iteration of a 6.1e4-DOF 3-D HBM
continuation took 8.2 s of wall time on two threads against 12.5 s with the sequential MUMPS
(``benchmarks/README_solids_scale.md``).

Only the LP64 interface (32-bit indices) is used: matrices up to 2^31 stored entries.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import glob
import os
import sys
import threading
import weakref

import numpy as np
import scipy.sparse as sp

__all__ = ["ENV_VAR", "PardisoError", "PardisoHandle", "load_library", "matrix_type", "pardiso_threads", "schur"]

#: The environment variable of PARDISO's thread count (module docstring).
ENV_VAR = "FEMODES_PARDISO_THREADS"

_I = ctypes.c_int32
_P = ctypes.POINTER(_I)
_lock = threading.Lock()
_lib: list = []  # [CDLL] once loaded, [None] once tried and failed

#: What PARDISO's error codes mean (oneMKL reference, ``pardiso``).
ERRORS = {-1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
          -4: "zero pivot, numerical factorization or iterative refinement problem",
          -5: "unclassified (internal) error", -6: "reordering failed", -7: "diagonal matrix is singular",
          -8: "32-bit integer overflow problem", -9: "not enough memory for out-of-core solver",
          -10: "error opening out-of-core files", -11: "read/write error with out-of-core files",
          -12: "pardiso_64 called from a 32-bit library", -13: "interrupted by the mkl_progress function",
          -15: "internal error during the Schur complement or partial solve"}


class PardisoError(RuntimeError):
    """A PARDISO phase returned an error (``code`` is PARDISO's error number)."""

    def __init__(self, phase: int, code: int):
        super().__init__(f"PARDISO phase {phase}: error {code} ({ERRORS.get(code, 'unknown')})")
        self.phase, self.code = phase, code


def _candidates() -> list[str]:
    names = []
    for prefix in dict.fromkeys([sys.prefix, sys.base_prefix]):
        for pattern in ("lib/libmkl_rt.so*", "lib/libmkl_rt*.dylib", "Library/bin/mkl_rt*.dll"):
            names += sorted(glob.glob(os.path.join(prefix, pattern)))
    found = ctypes.util.find_library("mkl_rt")
    if found:
        names.append(found)
    return names


def load_library():
    """``libmkl_rt`` loaded (the ``mkl`` wheel in this environment, or a system MKL), or None."""
    with _lock:
        if _lib:
            return _lib[0]
        lib = None
        for name in _candidates():
            try:
                lib = ctypes.CDLL(name)
                lib.pardiso  # noqa: B018 (the symbol must exist)
            except (OSError, AttributeError):
                lib = None
                continue
            break
        if lib is not None:
            lib.pardisoinit.argtypes = [ctypes.c_void_p, _P, ctypes.c_void_p]
            lib.pardisoinit.restype = None
            lib.pardiso.argtypes = [ctypes.c_void_p, _P, _P, _P, _P, _P, ctypes.c_void_p, ctypes.c_void_p,
                                    ctypes.c_void_p, ctypes.c_void_p, _P, ctypes.c_void_p, _P, ctypes.c_void_p,
                                    ctypes.c_void_p, _P]
            lib.pardiso.restype = None
            lib.MKL_Set_Num_Threads_Local.argtypes = [ctypes.c_int]
            lib.MKL_Set_Num_Threads_Local.restype = ctypes.c_int
        _lib.append(lib)
        return lib


def pardiso_threads() -> int:
    """PARDISO's thread count: ``FEMODES_PARDISO_THREADS``, else ``MKL_NUM_THREADS``, else the
    cores available to this process.

    Raises
    ------
    ValueError
        If the variable that is set does not hold a positive integer; the message names it.
    """
    for var in (ENV_VAR, "MKL_NUM_THREADS"):
        raw = os.environ.get(var, "").strip()
        if raw:
            try:
                n = int(raw)
            except ValueError:
                n = 0
            if n < 1:
                raise ValueError(f"{var} must be a positive integer (PARDISO's threads), got {raw!r}")
            return n
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def matrix_type(dtype, symmetric: bool, positive_definite: bool) -> int:
    """PARDISO's ``mtype``: 2 real SPD, -2 real symmetric indefinite, 6 complex symmetric,
    11 real unsymmetric, 13 complex unsymmetric."""
    complex_ = np.dtype(dtype).kind == "c"
    if symmetric:
        return 6 if complex_ else (2 if positive_definite else -2)
    return 13 if complex_ else 11


def _with_diagonal(S: sp.csr_matrix) -> sp.csr_matrix:
    """``S`` with an explicit zero on every diagonal position it does not store."""
    C = S.tocoo()
    stored = np.zeros(S.shape[0], dtype=bool)
    stored[C.row[C.row == C.col]] = True
    if stored.all():
        return S
    miss = np.flatnonzero(~stored)
    return sp.csr_matrix((np.concatenate([C.data, np.zeros(miss.size, C.data.dtype)]),
                          (np.concatenate([C.row, miss]), np.concatenate([C.col, miss]))), shape=S.shape)


def _csr(A, mtype: int) -> sp.csr_matrix:
    """What PARDISO reads of ``A``: CSR with sorted columns, the upper triangle with every diagonal
    entry stored (explicit zeros where ``A`` has none) for the symmetric types."""
    S = sp.triu(A, format="csr") if mtype in (2, -2, 6) else sp.csr_matrix(A)
    S.sum_duplicates()
    if mtype in (2, -2, 6):
        S = _with_diagonal(S)
    S.sort_indices()
    return S


def _release(lib, pt, mtype, n) -> None:
    err = _I(0)
    dummy = np.zeros(1)
    iparm = np.zeros(64, dtype=np.int32)
    iparm[0] = 1
    iparm[34] = 1
    lib.pardiso(pt.ctypes.data, ctypes.byref(_I(1)), ctypes.byref(_I(1)), ctypes.byref(_I(mtype)),
                ctypes.byref(_I(-1)), ctypes.byref(_I(n)), dummy.ctypes.data, None, None, None,
                ctypes.byref(_I(1)), iparm.ctypes.data, ctypes.byref(_I(0)), dummy.ctypes.data,
                dummy.ctypes.data, ctypes.byref(err))


class PardisoHandle:
    """One PARDISO instance: a matrix of one sparsity pattern, analysed once, factorised numerically.

    ``A`` is a square scipy sparse matrix; for a symmetric ``mtype`` (2, -2, 6) PARDISO reads
    its upper triangle. :meth:`refactor` factorises new values on the same pattern without a new
    analysis; :meth:`solve` solves with one or many right-hand sides (``trans``: with ``A^T``).
    The handle's memory is released when it is collected.

    Raises
    ------
    PardisoError
        From the analysis or the factorisation (``code == -4``: a zero pivot of a positive
        definite factorisation); ``perturbed`` counts the pivots PARDISO perturbed otherwise.
    """

    def __init__(self, A, mtype: int):
        lib = load_library()
        if lib is None:
            raise RuntimeError("PARDISO: libmkl_rt not found (pip install mkl)")
        self._lib = lib
        self.mtype = int(mtype)
        S = _csr(A, self.mtype)
        self.n = int(S.shape[0])
        self._ia = S.indptr.astype(np.int32)
        self._ja = S.indices.astype(np.int32)
        self._a = np.ascontiguousarray(S.data)
        self.pt = np.zeros(64, dtype=np.int64)
        self.iparm = np.zeros(64, dtype=np.int32)
        lib.pardisoinit(self.pt.ctypes.data, ctypes.byref(_I(self.mtype)), self.iparm.ctypes.data)
        self.iparm[0] = 1    # iparm given, not defaults
        self.iparm[1] = 2    # METIS nested dissection
        self.iparm[7] = 0    # iterative refinement only after perturbed pivots
        self.iparm[34] = 1   # zero-based indices
        weakref.finalize(self, _release, lib, self.pt, self.mtype, self.n)
        self._call(11)
        self.perturbed = 0
        self._factor()

    def _call(self, phase: int, b=None, x=None, nrhs: int = 1) -> None:
        err = _I(0)
        dummy = np.zeros(1, dtype=self._a.dtype)
        previous = self._lib.MKL_Set_Num_Threads_Local(pardiso_threads())
        try:
            self._pardiso(phase, b, x, nrhs, dummy, err)
        finally:
            self._lib.MKL_Set_Num_Threads_Local(previous)
        if err.value:
            raise PardisoError(phase, int(err.value))

    def _pardiso(self, phase, b, x, nrhs, dummy, err) -> None:
        self._lib.pardiso(self.pt.ctypes.data, ctypes.byref(_I(1)), ctypes.byref(_I(1)), ctypes.byref(_I(self.mtype)),
                          ctypes.byref(_I(phase)), ctypes.byref(_I(self.n)), self._a.ctypes.data,
                          self._ia.ctypes.data, self._ja.ctypes.data, None, ctypes.byref(_I(nrhs)),
                          self.iparm.ctypes.data, ctypes.byref(_I(0)),
                          (dummy if b is None else b).ctypes.data, (dummy if x is None else x).ctypes.data,
                          ctypes.byref(err))

    def _factor(self) -> None:
        self._call(22)
        self.perturbed = int(self.iparm[13])
        if self.perturbed and not self.iparm[12] and self.mtype != 2:
            # perturbed pivots: once more with scaling and weighted matching (a new analysis)
            self.iparm[10] = self.iparm[12] = 1
            self._call(11)
            self._call(22)
            self.perturbed = int(self.iparm[13])

    def refactor(self, values) -> None:
        """Factorise the matrix with these values on the same pattern (stored entries of
        ``S``, the upper triangle for a symmetric type, in CSR order)."""
        values = np.asarray(values, dtype=self._a.dtype)
        if values.shape != self._a.shape:
            raise ValueError(f"PardisoHandle.refactor: {self._a.size} values expected, got shape {values.shape}")
        self._a = np.ascontiguousarray(values)
        self._factor()

    @property
    def dtype(self) -> np.dtype:
        return self._a.dtype

    @property
    def nnz(self) -> int:
        """Entries of the factors (``iparm[17]``)."""
        return int(self.iparm[17])

    def solve(self, b, trans: bool = False) -> np.ndarray:
        b = np.asarray(b)
        one = b.ndim == 1
        B = np.asfortranarray(b.reshape(self.n, -1), dtype=self._a.dtype)
        X = np.empty_like(B, order="F")
        self.iparm[11] = 2 if (trans and self.mtype in (11, 13)) else 0
        self._call(33, B, X, B.shape[1])
        return X[:, 0] if one else X


def schur(A, keep: np.ndarray, mtype: int) -> tuple[np.ndarray, int]:
    """PARDISO's own Schur complement of ``A`` on the rows and columns ``keep`` (``iparm[35] = 1``,
    the kept rows marked in ``perm``, phase 12; dense, row-major in the order of increasing index)
    and the number of pivots PARDISO perturbed; the instance is released before returning."""
    lib = load_library()
    if lib is None:
        raise RuntimeError("PARDISO: libmkl_rt not found (pip install mkl)")
    S = _csr(A, mtype)
    n = int(S.shape[0])
    a = np.ascontiguousarray(S.data)
    ia, ja = S.indptr.astype(np.int32), S.indices.astype(np.int32)
    pt, iparm = np.zeros(64, dtype=np.int64), np.zeros(64, dtype=np.int32)
    lib.pardisoinit(pt.ctypes.data, ctypes.byref(_I(mtype)), iparm.ctypes.data)
    iparm[0], iparm[1], iparm[7], iparm[34], iparm[35] = 1, 2, 0, 1, 1
    perm = np.zeros(n, dtype=np.int32)
    perm[keep] = 1
    k = int(np.count_nonzero(perm))
    x = np.zeros(k * k, dtype=a.dtype)
    b = np.zeros(n, dtype=a.dtype)
    err = _I(0)
    previous = lib.MKL_Set_Num_Threads_Local(pardiso_threads())
    try:
        lib.pardiso(pt.ctypes.data, ctypes.byref(_I(1)), ctypes.byref(_I(1)), ctypes.byref(_I(mtype)),
                    ctypes.byref(_I(12)), ctypes.byref(_I(n)), a.ctypes.data, ia.ctypes.data, ja.ctypes.data,
                    perm.ctypes.data, ctypes.byref(_I(1)), iparm.ctypes.data, ctypes.byref(_I(0)), b.ctypes.data,
                    x.ctypes.data, ctypes.byref(err))
    finally:
        lib.MKL_Set_Num_Threads_Local(previous)
        _release(lib, pt, mtype, n)
    if err.value:
        raise PardisoError(12, int(err.value))
    return x.reshape(k, k), int(iparm[13])
