"""Application layer: where the tasks of a sweep run, and the guard of the embedded cluster.

An embedded :class:`distributed.LocalCluster` (``n_workers`` single-threaded worker processes,
:func:`local_cluster`) by default, an existing Dask cluster (``executor="tcp://host:8786"``, the
scheduler's address), a :class:`distributed.Client`, or any :class:`concurrent.futures.Executor`
(thread or process pool): :func:`open_executor` turns each into a ``concurrent.futures.Executor``.

Worker environment of the embedded cluster (:func:`local_cluster`), measured in
``benchmarks/README_sweep.md``:

* Dask's nanny exports ``MALLOC_TRIM_THRESHOLD_=65536`` to its workers (config
  ``distributed.nanny.pre-spawn-environ``) so that they hand freed memory back to the OS. Setting
  any glibc malloc threshold explicitly also switches off glibc's *dynamic* mmap threshold
  (mallopt(3), "M_MMAP_THRESHOLD"), so every numpy temporary above 128 KiB is mmap'ed, page-faulted
  and unmapped again. Harmonic balance of FE models allocates such temporaries at every Newton
  step: a 1000-DOF bar (H = 10) needed 1.9x the CPU time per task (1.4 million page faults instead
  of a few hundred per case); a 1-DOF oscillator, whose arrays are a few KiB, 1.15x. The sweep
  cluster leaves the variable unset.
* The start of an embedded cluster costs about 2 s (processes, imports, shutdown): for short or
  repeated sweeps, keep one (``with local_cluster() as c, Client(c) as client:``) and pass it.
* One BLAS thread per worker (``OMP/MKL/OPENBLAS_NUM_THREADS=1``): the workers already use the
  cores, a multithreaded BLAS in each would oversubscribe them.

The embedded cluster starts its workers with the ``spawn`` method, which imports the main script
again in every worker: :func:`check_main_guarded` stops a script that calls the sweep outside
``if __name__ == "__main__":`` with one sentence instead of recursive cluster starts.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import logging
import os
import re
from pathlib import Path

__all__ = ["WORKER_ENVIRON", "local_cluster", "restored_environ", "check_where", "open_executor",
           "check_main_guarded"]

log = logging.getLogger(__name__)

# Environment of the embedded cluster's worker processes, set before they start (see the module
# docstring). ``None`` removes a variable from Dask's default ``pre-spawn-environ``.
WORKER_ENVIRON: dict[str, str | None] = {
    "MALLOC_TRIM_THRESHOLD_": None,  # keep glibc's dynamic mmap threshold (1.9x faster FE HBM tasks)
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
}


# ---------------------------------------------------------------------------------------------
# The embedded cluster
# ---------------------------------------------------------------------------------------------
@contextlib.contextmanager
def restored_environ():
    """Undo changes to ``os.environ``: the nanny exports its pre-spawn variables into the process
    that starts it (ours), where they would leak into every later subprocess of the user."""
    saved = dict(os.environ)
    try:
        yield
    finally:
        for k in [k for k in os.environ if k not in saved]:
            del os.environ[k]
        for k, v in saved.items():
            if os.environ.get(k) != v:
                os.environ[k] = v


def local_cluster(n_workers: int = 2, **kwargs):
    """A :class:`distributed.LocalCluster` for sweeps: ``n_workers`` single-threaded processes.

    The workers start with :data:`WORKER_ENVIRON` (no ``MALLOC_TRIM_THRESHOLD_``, one BLAS thread;
    see the module docstring), with the scheduler and its HTTP server on free local ports (no fixed
    port to collide with other clusters on the machine). ``kwargs`` go to ``LocalCluster`` and
    override these defaults. Close it (``with local_cluster() as cluster:``) when done.
    """
    import dask
    from distributed import LocalCluster

    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
        raise ValueError(f"local_cluster: n_workers must be an integer >= 1, got {n_workers!r}")
    # dashboard_address=None would still bind Dask's HTTP server to the fixed port 8787 (with a
    # warning when another cluster has it): a free local port instead.
    opts = dict(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0")
    opts.update(kwargs)
    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    env.update(WORKER_ENVIRON)
    with restored_environ(), dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
        # A value already in os.environ wins over the config and is inherited by the spawned
        # workers (e.g. exported by an earlier default cluster's nanny, or OPENBLAS_NUM_THREADS=2
        # exported by the user): replace it while they start (restored_environ puts it back).
        for k, v in WORKER_ENVIRON.items():
            if k in os.environ and os.environ[k] != v:
                log.info("sweep workers start with %s=%s instead of %s (single-threaded workers)", k, v, os.environ[k])
                if v is None:
                    del os.environ[k]
                else:
                    os.environ[k] = v
        return LocalCluster(**opts)


# ---------------------------------------------------------------------------------------------
# The executor of a sweep
# ---------------------------------------------------------------------------------------------
def _is_client(obj) -> bool:
    try:
        from distributed import Client
    except ImportError:
        return False
    return isinstance(obj, Client)


#: A Dask scheduler address: ``protocol://rest`` (``tcp://host:8786``, ``tls://...``) or ``host:port``.
_ADDRESS = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*://\S+|(\[[0-9A-Fa-f:.]+\]|[^\s:/\[\]]+):\d+")


def check_where(executor, n_workers) -> None:
    """Check ``run_sweep``'s ``executor`` (None, an executor, a client or a scheduler address) and
    ``n_workers``; errors name the argument and quote the value."""
    if isinstance(executor, str):
        if not _ADDRESS.fullmatch(executor):
            raise ValueError(f"run_sweep: executor={executor!r} is not a Dask scheduler address; an address looks "
                             "like 'tcp://host:8786'")
    elif executor is not None and not (_is_client(executor) or isinstance(executor, cf.Executor)):
        raise TypeError(f"run_sweep: executor must be a concurrent.futures.Executor, a distributed.Client or a "
                        f"scheduler address like 'tcp://host:8786', got {executor!r}")
    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
        raise ValueError(f"run_sweep: n_workers must be an integer >= 1, got {n_workers!r}")


@contextlib.contextmanager
def open_executor(executor, n_workers):
    """``(executor, description)``: the concurrent.futures.Executor to submit to and where it runs;
    creates and closes what the sweep owns (a client of a scheduler address, or the embedded
    cluster of ``n_workers`` when ``executor`` is None)."""
    check_where(executor, n_workers)
    if executor is not None and not isinstance(executor, str):
        if _is_client(executor):
            from distributed.cfexecutor import ClientExecutor

            yield ClientExecutor(executor, pure=False), f"Dask client of {executor.scheduler.address}"
        else:
            yield executor, type(executor).__name__
        return
    try:
        from distributed import Client
        from distributed.cfexecutor import ClientExecutor
    except ImportError as exc:
        raise ImportError("run_sweep needs dask.distributed for its default cluster and for scheduler addresses "
                          "(pip install 'femodes[sweep]'), "
                          "or pass executor=concurrent.futures.ProcessPoolExecutor()") from exc
    if executor is not None:  # a scheduler address
        with Client(executor) as client:
            yield ClientExecutor(client, pure=False), f"Dask scheduler {executor}"
        return
    with local_cluster(n_workers) as cluster, Client(cluster) as client:
        yield ClientExecutor(client, pure=False), f"local Dask cluster, {n_workers} workers"


# ---------------------------------------------------------------------------------------------
# The main guard
# ---------------------------------------------------------------------------------------------
def _unguarded_main_call() -> str | None:
    """The script whose top-level code is calling us outside ``if __name__ == "__main__":``, or None.

    The embedded cluster starts its workers with the ``spawn`` method, which imports the main
    script again in every worker: an unguarded call there starts clusters recursively and dies
    in hundreds of lines of Dask traceback ("Nanny failed to start").
    """
    import ast
    import inspect
    import multiprocessing

    if getattr(multiprocessing.current_process(), "_inheriting", False):
        return "a worker process"  # the re-import itself: the spawn has already gone wrong
    frame = inspect.currentframe()
    top = None
    while frame is not None:  # the outermost frame running the main script's module-level code
        if frame.f_globals.get("__name__") == "__main__" and frame.f_code.co_name == "<module>":
            top = frame
        frame = frame.f_back
    path = top.f_globals.get("__file__") if top is not None else None
    if not path or not Path(path).is_file():
        return None  # interactive session, python -c, notebooks: nothing is re-imported
    try:
        tree = ast.parse(Path(path).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, UnicodeDecodeError):
        return None
    line = top.f_lineno
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "__main__" in ast.unparse(node.test) and "__name__" in ast.unparse(node.test):
            if node.lineno <= line <= (node.end_lineno or node.lineno):
                return None
    return str(path)


def check_main_guarded(function: str) -> None:
    """RuntimeError naming the script if ``function`` (e.g. ``"run_sweep"``) is called from a main
    script's top-level code outside ``if __name__ == "__main__":``."""
    script = _unguarded_main_call()
    if script is not None:
        raise RuntimeError(f"{function} starts worker processes that import {script} again: put the code that runs the "
                           "sweep under `if __name__ == \"__main__\":` (or pass executor=..., e.g. a scheduler "
                           "address)")
