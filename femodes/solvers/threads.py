"""Solvers layer: how many threads BLAS (and OpenMP) may use inside femodes' hot loops.

femodes' Newton steps are made of many *small* dense operations (Schur complements of a few
hundred unknowns, band LUs, matrix-vector products). A multithreaded BLAS gains nothing on them
and loses much when the cores are shared: OpenBLAS's threads wait for each other, so on the
2-core development machine with other sessions running, a point of the 2e3-DOF, 10-contact bar
curve (H = 10) took 2.4 s with OpenBLAS's default two threads against 0.53 s with one, and even
the largest Schur LUs measured (up to 3241 unknowns) were not faster on two threads
(``benchmarks/README.md``, section "BLAS threads"; issue 16). The public analyses therefore run
their loops under :func:`limit_blas_threads`, which sets the thread count of every BLAS and OpenMP
library loaded in the process (``threadpoolctl``) for the duration of the call and restores it
afterwards.

The number comes from the environment variable ``FEMODES_BLAS_THREADS``, read at every call:

* unset or empty: 1 (the default);
* a positive integer ``n``: ``n`` threads;
* ``off``: femodes leaves the thread pools alone (the libraries' own settings apply, e.g.
  ``OPENBLAS_NUM_THREADS``).

Anything else raises ``ValueError`` naming the variable. The limit is process-wide (OpenBLAS has
one thread count per process): nested limits and limits entered by several Python threads are
kept on one stack; leaving a limit restores the one entered before it that is still active, or
the libraries' original setting when none is left. Entering a limit that is already in place
changes nothing (no call into the libraries, so Python threads already inside BLAS are not
disturbed) and costs 10-50 us; changing the count and back 25-90 us (the first call scans the
loaded libraries, ~3 ms, repeated only after new modules have been imported).

Nothing of femodes is imported here (solvers layer); ``threadpoolctl`` is imported at the first
limit, so ``import femodes`` does not need it. Without it the limit is skipped with one warning.
"""

from __future__ import annotations

import contextlib
import logging
import numbers
import os
import sys
import threading
from collections.abc import Iterator

__all__ = ["ENV_VAR", "blas_threads", "current_blas_threads", "limit_blas_threads", "refresh_blas_limit"]

log = logging.getLogger(__name__)

#: The environment variable that chooses the thread count (module docstring).
ENV_VAR = "FEMODES_BLAS_THREADS"

#: Value of :data:`ENV_VAR` that turns the limit off.
OFF = "off"

_lock = threading.RLock()
_stack: list[tuple[object, int]] = []   # active limits: (token, threads), most recent last
_original: dict[str, int] = {}          # library path -> its thread count before the first active limit
_controller = None                      # threadpoolctl.ThreadpoolController, cached
_controller_modules = -1                # len(sys.modules) when it was built
_warned = False


def blas_threads() -> int | None:
    """The thread count chosen by :data:`ENV_VAR`: ``1`` if unset, ``None`` for ``off``.

    Raises
    ------
    ValueError
        If the variable holds anything but a positive integer or ``off``.
    """
    raw = os.environ.get(ENV_VAR, "").strip()
    if not raw:
        return 1
    if raw.lower() == OFF:
        return None
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{ENV_VAR} must be a positive integer (BLAS threads inside femodes' loops) or "
                         f"'{OFF}' (leave the libraries' settings alone), got {raw!r}")
    return n


def _libraries():
    """Controllers of the loaded BLAS/OpenMP libraries (re-scanned after new imports), or None."""
    global _controller, _controller_modules, _warned
    n_modules = len(sys.modules)
    if _controller is None or n_modules != _controller_modules:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:
            if not _warned:
                _warned = True
                log.warning("threadpoolctl is not installed: BLAS threads are not limited inside femodes "
                            "(pip install threadpoolctl)")
            return None
        _controller = ThreadpoolController()
        _controller_modules = n_modules
    return _controller.lib_controllers


def current_blas_threads() -> list[int]:
    """Thread counts of the loaded BLAS and OpenMP libraries now (one per library)."""
    with _lock:
        libs = _libraries() or []
        return [lib.get_num_threads() for lib in libs]


def _apply(libs, threads: int | dict[str, int]) -> None:
    """Set ``threads`` (one count, or one per library path) where it is not already in place."""
    for lib in libs:
        n = threads.get(lib.filepath) if isinstance(threads, dict) else threads
        if n is not None and lib.get_num_threads() != n:
            lib.set_num_threads(n)


@contextlib.contextmanager
def limit_blas_threads(threads: int | None = None) -> Iterator[None]:
    """Run a block (``with``) or a function (decorator) with ``threads`` BLAS/OpenMP threads.

    Parameters
    ----------
    threads : int, optional
        Thread count; by default :func:`blas_threads` (``FEMODES_BLAS_THREADS``, 1 if unset,
        no limit for ``off``), read when the block is entered (each call of a decorated
        function).

    A limit already in place costs nothing; nested limits restore the enclosing one on exit,
    also when the block raises.
    """
    n = blas_threads() if threads is None else threads
    if n is not None and (isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 1):
        raise ValueError(f"limit_blas_threads: threads must be a positive integer or None, got {n!r}")
    if n is None:
        yield
        return
    n = int(n)
    global _original
    token = object()
    with _lock:
        libs = _libraries()
        if libs is not None:
            if not _stack:
                _original = {}
            for lib in libs:  # first sight of each library, also of those loaded under a limit
                _original.setdefault(lib.filepath, lib.get_num_threads())
            _stack.append((token, n))
            _apply(libs, n)
    if libs is None:
        yield
        return
    try:
        yield
    finally:
        with _lock:
            _stack[:] = [e for e in _stack if e[0] is not token]
            libs = _controller.lib_controllers
            _apply(libs, _stack[-1][1] if _stack else _original)


def refresh_blas_limit() -> None:
    """Apply the active limit, if any, to the BLAS/OpenMP libraries loaded since it was entered.

    A sparse direct back-end imported inside an analysis (CHOLMOD and MUMPS link the system's
    OpenBLAS, loaded at their first use) would otherwise run with that library's default thread
    count until the next limit: on the shared 2-core machine, 20 linear modes of a 1.9e4-DOF solid
    on CHOLMOD took 8.2 s instead of 0.9 s that way. Leaving the limit restores those libraries
    too."""
    with _lock:
        if not _stack:
            return
        libs = _libraries()
        if libs is None:
            return
        for lib in libs:
            _original.setdefault(lib.filepath, lib.get_num_threads())
        _apply(libs, _stack[-1][1])
