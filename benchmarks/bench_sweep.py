#!/usr/bin/env python
"""Parameter sweep on Dask workers against running the cases one after another.

Run from the repository root::

    python benchmarks/bench_sweep.py                # FE bar, 8 cases, 3 repeats (about 2 min)
    python benchmarks/bench_sweep.py --cases oscillator     # 1-DOF oscillator instead
    python benchmarks/bench_sweep.py --repeat 5 --write     # also update benchmarks/README_sweep.md
    python benchmarks/bench_sweep.py --json out/bench_sweep.json

This is a script, not a pytest test. Results and their discussion: ``benchmarks/README_sweep.md``.

Cases (``--cases``): ``bar`` (default), a fixed-free P1 bar of 1000 elements (unit properties,
Rayleigh ``alpha = 0.05``, tip force 0.01) against a tip stop, forced response with ``H = 10`` from
w = 1.45 through the first resonance (pi/2), 10 continuation points, for 8 gaps 0.01 ... 0.1 (the
smaller ones in contact); ``oscillator``: ``examples/cases/oscillator_frc.toml`` (1-DOF) with
``H = 20``, 25 points, gaps 1.3 ... 2.0. About 0.6 s (bar) and 0.25 s (oscillator) per case. Every
variant runs the very same tasks through :func:`femodes.app.sweep.run_sweep` (which also writes
each branch and the study file), so the variants differ only in where the tasks run:

``sequential``
    one case after another in a fresh process with one BLAS thread, like a worker (an executor
    that runs each task at submission);
``sequential, MALLOC_TRIM_THRESHOLD_=65536``
    the same with the nanny's malloc setting, without Dask: the pitfall in isolation;
``dask, fixed env``
    a started :func:`femodes.app.sweep.local_cluster` of 2 single-threaded worker processes
    (no ``MALLOC_TRIM_THRESHOLD_``, one BLAS thread), reused across repeats;
``dask, nanny default``
    a started ``distributed.LocalCluster(n_workers=2, threads_per_worker=1)`` with Dask's default
    ``distributed.nanny.pre-spawn-environ`` (``MALLOC_TRIM_THRESHOLD_=65536``, one BLAS thread);
``dask, embedded``
    ``run_sweep(..., n_workers=2)`` as a user calls it: cluster start, tasks, cluster shutdown;
``process pool (fork)``
    ``ProcessPoolExecutor(2)`` with the ``fork`` start method, created and shut down inside the
    timing, in a fresh process (one BLAS thread) that has imported femodes (the workers start warm).

Both started clusters are warmed up (femodes imported, one case run in each worker) before the
first repeat. The sequential and process-pool variants run in a fresh child process (no Dask
threads in it; forking a process with threads is unsafe), warmed up by one case before timing.
The repeats interleave the variants (all variants in repeat 1, then in repeat 2, ...), so a change
of machine load hits all of them. Reported: the median and the minimum over repeats of the sweep's
wall time and their ratios to sequential (the fastest run is the least disturbed by other jobs on
a shared machine), and the median over all tasks of the task's wall and CPU time
(``CaseRecord.wall_time``, ``cpu_time``: measured inside the worker; CPU time is the thread's, so
it shows what a task costs even when other jobs share the cores).
"""

from __future__ import annotations

import argparse
import atexit
import concurrent.futures as cf
import json
import os
import platform
import re
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "benchmarks" / "README_sweep.md"

# The default cases: a P1 bar of 1000 elements (1000 DOFs, 21 000 unknowns with H = 10) against a
# tip stop; the arrays of one Newton step exceed glibc's 128 KiB mmap threshold.
BAR_CASE = """\
[mesh]
length = 1.0
n_elements = 1000
boundaries = { clamp = 0.0, tip = 1.0 }

[model]
kind = "bar"
E = 1.0
rho = 1.0
area = 1.0
clamped = ["clamp"]

[damping]
alpha = 0.05

[[contact]]
at = "tip"
gap = 0.02

[[force]]
at = "tip"
amplitude = 0.01

[analysis]
type = "frequency_response"
omega = [1.45, 1.75]      # around w1 = pi/2
harmonics = 10
max_points = 10

[outputs]
branch = false
"""
SETS = {
    # gaps 0.01 ... 0.05 hit the stop (contact force up to 0.009), 0.07 barely, 0.1 not
    "bar": ("contact.0.gap", [0.01, 0.015, 0.02, 0.03, 0.04, 0.05, 0.07, 0.1], {}),
    # 1-DOF oscillator with H = 20: small arrays (a few KiB)
    "oscillator": ("contact.0.gap", [1.3, 1.4, 1.5, 1.6, 1.7, 1.8, 1.9, 2.0],
                   {"analysis.harmonics": 20, "analysis.max_points": 25}),
}
CASE_SET = "bar"
CASE = None  # path of the base case file, set by _setup()


def _setup(name: str) -> None:
    global CASE, CASE_SET
    CASE_SET = name
    if name == "bar":
        folder = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
        atexit.register(shutil.rmtree, folder, True)
        CASE = folder / "bar_stop.toml"
        CASE.write_text(BAR_CASE)
    else:
        CASE = ROOT / "examples" / "cases" / "oscillator_frc.toml"


def params(values=None):
    path, default, fixed = SETS[CASE_SET]
    return [{path: v, **fixed} for v in (default if values is None else values)]


class InlineExecutor(cf.Executor):
    """Runs each task at submission, in this process: the sequential baseline."""

    def submit(self, fn, /, *args, **kwargs):
        fut = cf.Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001
            fut.set_exception(exc)
        return fut


def machine() -> dict:
    import dask
    import distributed
    import numpy
    import scipy

    cpu = "unknown"
    try:
        m = re.search(r"^model name\s*:\s*(.+)$", Path("/proc/cpuinfo").read_text(), re.M)
        cpu = m.group(1).strip() if m else cpu
    except OSError:
        pass
    blas = "unknown"
    try:
        cfg = numpy.show_config(mode="dicts")
        b = cfg["Build Dependencies"]["blas"]
        blas = f"{b.get('name')} {b.get('version')}"
    except Exception:  # noqa: BLE001
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "numpy": numpy.__version__,
            "scipy": scipy.__version__, "dask": dask.__version__, "distributed": distributed.__version__,
            "blas": blas, "glibc": "-".join(platform.libc_ver()), "load": os.getloadavg()}


def timed_sweep(executor=None, **kw):
    from femodes.app.sweep import run_sweep

    with tempfile.TemporaryDirectory() as out:
        t = time.perf_counter()
        res = run_sweep(CASE, params(), out=out, executor=executor, **kw)
        wall = time.perf_counter() - t
    bad = [r for r in res if not r.ok]
    if bad:
        raise RuntimeError(f"benchmark case failed: {bad[0].id} {bad[0].status}: {bad[0].message}")
    return wall, res


def default_cluster(n_workers):
    """LocalCluster with Dask's default nanny environment; our os.environ restored afterwards."""
    from distributed import LocalCluster

    from femodes.app.sweep.executors import restored_environ

    with restored_environ():
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                            dashboard_address="127.0.0.1:0")


def warm_up(client):
    from femodes.app.sweep import run_sweep

    with tempfile.TemporaryDirectory() as out:  # one case per worker: imports, first-call costs
        n = len(client.scheduler_info()["workers"])
        run_sweep(CASE, params(SETS[CASE_SET][1][:n]), out=out, executor=client)


def child(kind: str, n_workers: int) -> dict:
    """A variant that must not share a process with Dask's threads: timed in a fresh process."""
    timed_sweep(InlineExecutor())  # warm-up: imports, first-call costs
    if kind == "sequential":
        wall, res = timed_sweep(InlineExecutor())
    else:  # fork start: the workers inherit this warm process (no imports), created inside the timing
        import multiprocessing

        t = time.perf_counter()
        with cf.ProcessPoolExecutor(n_workers, mp_context=multiprocessing.get_context("fork")) as ex:
            _, res = timed_sweep(ex)
        wall = time.perf_counter() - t
    return {"wall": wall, "tasks": [(r.wall_time, r.cpu_time) for r in res]}


def in_child(kind: str, n_workers: int, env: dict | None = None) -> tuple[float, list]:
    import subprocess

    r = subprocess.run([sys.executable, __file__, "--child", kind, "--workers", str(n_workers), "--cases", CASE_SET],
                       capture_output=True, text=True, check=True, cwd=ROOT,
                       env={**os.environ, **ONE_BLAS_THREAD, **(env or {})})
    d = json.loads(r.stdout.strip().splitlines()[-1])
    return d["wall"], [tuple(x) for x in d["tasks"]]


def _med(tasks, i):
    return statistics.median(t[i] for t in tasks)


TRIM = {"MALLOC_TRIM_THRESHOLD_": "65536"}  # what Dask's nanny exports by default
# Like the workers: a multithreaded BLAS in the sequential run would borrow the second core (and,
# on a shared machine, spin against other jobs: task wall time 3x its CPU time in a first run).
ONE_BLAS_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
VARIANTS = ("sequential", "sequential, MALLOC_TRIM_THRESHOLD_=65536", "dask, fixed env", "dask, nanny default",
            "dask, embedded", "process pool (fork)")


def run(repeat: int, n_workers: int) -> dict:
    import logging

    from distributed import Client

    from femodes.app.sweep import local_cluster

    logging.getLogger("distributed").setLevel(logging.ERROR)  # start/stop chatter of four clusters
    info = machine()
    print(f"machine: {info['cpu']}, {info['cores']} cores, load {info['load']}", flush=True)
    t = time.perf_counter()
    fixed = local_cluster(n_workers)
    t_start = time.perf_counter() - t
    default = default_cluster(n_workers)
    times: dict[str, list] = {k: [] for k in VARIANTS}
    task: dict[str, list] = {k: [] for k in VARIANTS}
    with Client(fixed) as cf_, Client(default) as cd:
        envs = {"fixed": cf_.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_")),
                "default": cd.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))}
        print(f"MALLOC_TRIM_THRESHOLD_ in the workers: {envs}", flush=True)
        warm_up(cf_)
        warm_up(cd)

        def sweep(executor=None, **kw):
            wall, res = timed_sweep(executor, **kw)
            return wall, [(r.wall_time, r.cpu_time) for r in res]

        for k in range(repeat):
            for name, call in (("sequential", lambda: in_child("sequential", n_workers)),
                               (VARIANTS[1], lambda: in_child("sequential", n_workers, TRIM)),
                               ("dask, fixed env", lambda: sweep(cf_)),
                               ("dask, nanny default", lambda: sweep(cd)),
                               ("dask, embedded", lambda: sweep(None, n_workers=n_workers)),
                               ("process pool (fork)", lambda: in_child("processpool", n_workers))):
                wall, tasks = call()
                times[name].append(wall)
                task[name].extend(tasks)
                print(f"repeat {k + 1}: {name:42s} {wall:6.2f} s (median task: wall {_med(tasks, 0):.3f} s, "
                      f"cpu {_med(tasks, 1):.3f} s)", flush=True)
    fixed.close()
    default.close()
    seq = statistics.median(times["sequential"])
    seq_min = min(times["sequential"])
    rows = []
    info["load_end"] = os.getloadavg()
    for name in times:
        m = statistics.median(times[name])
        rows.append({"variant": name, "median_s": m, "speedup": seq / m, "min_s": min(times[name]),
                     "speedup_min": seq_min / min(times[name]), "task_wall_s": _med(task[name], 0),
                     "task_cpu_s": _med(task[name], 1), "runs_s": times[name]})
    return {"machine": info, "repeat": repeat, "n_workers": n_workers, "n_cases": len(SETS[CASE_SET][1]), "cases": CASE_SET,
            "cluster_start_s": t_start, "rows": rows}


def markdown(res: dict) -> str:
    m = res["machine"]
    lines = [
        f"Measured {time.strftime('%Y-%m-%d %H:%M')}: `--cases {res['cases']}`, {res['n_cases']} cases, "
        f"{res['n_workers']} workers, "
        f"{res['repeat']} repeats, medians.",
        "",
        f"* Machine: {m['cpu']}, {m['cores']} cores (shared), load average {m['load'][0]:.1f} at the start, "
        f"{m['load_end'][0]:.1f} at the end.",
        f"* Versions: Python {m['python']}, numpy {m['numpy']} ({m['blas']}), scipy {m['scipy']}, dask {m['dask']}, "
        f"distributed {m['distributed']}, {m['glibc']}.",
        f"* Start of a `local_cluster(2)` (in the embedded variant's time): {res['cluster_start_s']:.2f} s.",
        "",
        "| variant | sweep wall time [s] | vs sequential | fastest run [s] | vs sequential | task wall [s] "
        "| task CPU [s] | runs [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in res["rows"]:
        lines.append(f"| {r['variant']} | {r['median_s']:.2f} | {r['speedup']:.2f}x | {r['min_s']:.2f} | "
                     f"{r['speedup_min']:.2f}x | {r['task_wall_s']:.3f} | "
                     f"{r['task_cpu_s']:.3f} | "
                     f"{', '.join(f'{x:.2f}' for x in r['runs_s'])} |")
    return "\n".join(lines) + "\n"


def write_readme(block: str, cases: str) -> None:
    text = README.read_text()
    start, end = f"<!-- results: bench_sweep.py --cases {cases} -->", f"<!-- end results {cases} -->"
    i, j = text.index(start) + len(start), text.index(end)
    README.write_text(text[:i] + "\n" + block + text[j:])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cases", choices=sorted(SETS), default="bar", help="the sweep (default: bar)")
    ap.add_argument("--write", action="store_true", help="update the results block of benchmarks/README_sweep.md")
    ap.add_argument("--json", type=Path, default=None, help="dump the raw numbers")
    ap.add_argument("--child", choices=("sequential", "processpool"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    _setup(args.cases)
    if args.child:
        print(json.dumps(child(args.child, args.workers)))
        return 0
    res = run(args.repeat, args.workers)
    block = markdown(res)
    print(block)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1))
    if args.write:
        write_readme(block, args.cases)
    return 0


if __name__ == "__main__":  # the Dask workers and process pools re-import this file: keep the guard
    sys.exit(main())
