#!/usr/bin/env python
"""BLAS threads (issue 16, item 3): the bar curve per point with and without femodes' thread limit,
on an idle and on a busy machine; whether two threads pay for the dense Schur LU; the limit's cost.

Run from the repository root::

    python benchmarks/bench_threads.py                      # all parts (16 min at load 5 on 2 cores)
    python benchmarks/bench_threads.py --part curve --sizes 2000 --rounds 3
    python benchmarks/bench_threads.py --part schur         # dense LU, 1 vs 2 threads, idle and busy
    python benchmarks/bench_threads.py --part overhead      # cost of entering/leaving the limit
    python benchmarks/bench_threads.py --tree /tmp/threads_new --base /tmp/threads_base
    python benchmarks/bench_threads.py --json out/threads.json

This is a script, not a pytest test. Results and their discussion: ``benchmarks/README.md``,
section "BLAS threads (issue 16)".

Curve (``--part curve``). The bar of ``bench_scale.py`` (clamped P1 bar, N DOFs, Rayleigh
``alpha = 0.2, beta = 1e-4``, tip force ``0.01 cos(w t)``, 10 unilateral stops with gap 0.02 at
x = 0.05 ... 0.95), ``fm.frequency_response(model, (1.0, 1.8), H, options=...)`` with
``frequency_response``'s default options capped at ``--points`` points. Time per point = wall
time between the first and the last accepted point (``options.callback`` timestamps) divided by
the points in between: the start (linear response, forcing homotopy) and first-call costs are
left out. CPU per point likewise from ``time.process_time`` (all threads of the process).

Every run is a fresh child process in *the default environment*: ``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` removed, so OpenBLAS starts as many threads as there are
cores. Variants, alternated within each round (one child each):

``limit``  ``FEMODES_BLAS_THREADS`` unset: femodes' default, one BLAS thread inside the analyses;
``off``    ``FEMODES_BLAS_THREADS=off``: femodes leaves the thread pools alone (what the code did
           before the limit);
``base``   (with ``--base TREE``) another source tree, e.g. the committed code
           (``git worktree add /tmp/threads_base HEAD``), to check that ``off`` is the old code.

Loads: ``idle`` (nothing started by the script; other users of the machine are reported by the
load average) and ``busy``: the script starts 2 busy-loop processes (``while True: pass``) before
the runs of that load and stops them after (by process id). The child checks from inside the
loop (first callback, ``threadpoolctl.threadpool_info``) how many BLAS threads it runs on.

Schur (``--part schur``): ``scipy.linalg.lu_factor`` + ``lu_solve`` (one right-hand side) of a
dense real matrix of the sizes of femodes' Schur complement (``n_b (2H+1)`` displacement and as
many contact-force coefficients plus one border: 10 contacts at H = 10, 20, 40 give 421, 821, 1621;
3241 is 20 contacts at H = 40), in one child, under ``limit_blas_threads(1)`` and ``(2)``
alternated, idle and busy. Overhead (``--part overhead``): enter + leave ``limit_blas_threads()``
when it changes the count, and when it is already in place (nested), in microseconds.

``--tree TREE`` runs the children on another source tree (``PYTHONPATH``), e.g. a copy of the
working tree taken before the run so that concurrent edits cannot change the code measured.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _machine import cpu_model  # noqa: E402 - benchmarks/ is on sys.path when run as a script

HERE = Path(__file__).resolve().parent
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "GOTO_NUM_THREADS",
               "FEMODES_BLAS_THREADS")
W_SPAN = (1.0, 1.8)
SCHUR_SIZES = (421, 821, 1621, 3241)
BUSY = "while True:\n    pass\n"


# ================================================================================================
# children
# ================================================================================================
def child_curve(N: int, H: int, points: int) -> dict:
    sys.path.insert(0, str(HERE))
    import bench_scale
    import femodes as fm
    from threadpoolctl import threadpool_info

    model = bench_scale.build_model(N)
    stamps: list[tuple[float, float]] = []
    inside: dict = {}

    def callback(point):
        stamps.append((time.perf_counter(), time.process_time()))
        if len(stamps) == 2:  # inside the loop, once (threadpool_info costs ~3 ms)
            inside["blas_threads"] = [d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"]
            stamps[-1] = (time.perf_counter(), time.process_time())

    opts = fm.ContinuationOptions(step=0.05, max_step=0.5, max_points=points, callback=callback,
                                  newton=fm.NewtonOptions(atol=1e-9, max_iter=20))
    t0 = time.perf_counter()
    br = fm.frequency_response(model, W_SPAN, H, options=opts)
    total = time.perf_counter() - t0
    n = len(stamps) - 1
    return {"N": N, "H": H, "points": len(br), "w_end": float(br.omega[-1]), "success": bool(br.success),
            "nit": float(br.nit[1:].mean()), "ms_per_point": 1e3 * (stamps[-1][0] - stamps[0][0]) / n,
            "cpu_ms_per_point": 1e3 * (stamps[-1][1] - stamps[0][1]) / n, "total_s": total,
            "blas_threads_inside": inside.get("blas_threads"),
            "blas_threads_outside": [d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"]}


def child_schur(sizes: list[int], rounds: int) -> dict:
    import numpy as np
    import scipy.linalg as sla
    from femodes.solvers.threads import limit_blas_threads

    rng = np.random.default_rng(0)
    out = {}
    for n in sizes:
        A = rng.standard_normal((n, n)) + n * np.eye(n)
        b = rng.standard_normal(n)
        reps = max(1, int(3e8 / n ** 3))
        times = {1: [], 2: []}
        for _ in range(rounds):
            for t in (1, 2):
                with limit_blas_threads(t):
                    sla.lu_factor(A, check_finite=False)  # wake the threads
                    t0 = time.perf_counter()
                    for _ in range(reps):
                        sla.lu_solve(sla.lu_factor(A, check_finite=False), b, check_finite=False)
                    times[t].append(1e3 * (time.perf_counter() - t0) / reps)
        out[n] = {t: statistics.median(v) for t, v in times.items()} | {"reps": reps}
        out[n] |= {f"min{t}": min(v) for t, v in times.items()}
    return out


def child_overhead(calls: int) -> dict:
    import numpy  # noqa: F401 - load the BLAS libraries
    import scipy.linalg  # noqa: F401
    from femodes.solvers.threads import limit_blas_threads
    from threadpoolctl import threadpool_limits

    def per_call(fn) -> float:
        fn()
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        return 1e6 * (time.perf_counter() - t0) / calls

    def enter_leave():
        with limit_blas_threads(1):
            pass

    def plain_threadpoolctl():
        with threadpool_limits(1):
            pass

    with threadpool_limits(2, user_api="blas"):
        change = per_call(enter_leave)
        with limit_blas_threads(1):
            nested = per_call(enter_leave)
        bare = per_call(plain_threadpoolctl)
    return {"change_us": change, "in_place_us": nested, "threadpool_limits_us": bare}


# ================================================================================================
# parent
# ================================================================================================
def _env(tree: str | None, femodes_threads: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARS}
    if femodes_threads is not None:
        env["FEMODES_BLAS_THREADS"] = femodes_threads
    if tree is not None:
        env["PYTHONPATH"] = str(Path(tree).resolve())
    return env


def _run_child(args: list[str], env: dict) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", *args]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd="/")
    if proc.returncode:
        sys.stderr.write(proc.stderr[-3000:])
        raise SystemExit(f"child {args} failed")
    return json.loads(proc.stdout.strip().splitlines()[-1])


class Load:
    """``n`` busy-loop processes for the duration of a ``with`` block (stopped by their ids)."""

    def __init__(self, n: int):
        self.n, self.procs = n, []

    def __enter__(self):
        self.procs = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(self.n)]
        time.sleep(1.0)
        return self

    def __exit__(self, *exc):
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            p.wait()
        return False


def _loadavg() -> float:
    return os.getloadavg()[0]


def part_curve(args) -> list[dict]:
    variants = [("limit", args.tree, None), ("off", args.tree, "off")]
    if args.base:
        variants.append(("base", args.base, None))
    rows = []
    for load in args.loads:
        with Load(2 if load == "busy" else 0):
            for N in args.sizes:
                points = args.points if N <= 5000 else args.points_large
                for r in range(args.rounds):
                    order = variants if r % 2 == 0 else variants[::-1]
                    for name, tree, ft in order:
                        la = _loadavg()
                        res = _run_child(["curve", str(N), str(args.H), str(points)], _env(tree, ft))
                        res.update(variant=name, load=load, round=r, loadavg_before=la)
                        rows.append(res)
                        print(f"  {load:5s} N={N:6d} {name:5s} round {r}: {res['ms_per_point']:8.1f} ms/pt "
                              f"(cpu {res['cpu_ms_per_point']:.1f}), {res['points']} pts to w={res['w_end']:.3f}, "
                              f"BLAS threads inside {res['blas_threads_inside']}, load {la:.2f}",
                              file=sys.stderr, flush=True)
    return rows


def part_schur(args) -> dict:
    out = {}
    for load in args.loads:
        with Load(2 if load == "busy" else 0):
            la = _loadavg()
            out[load] = _run_child(["schur", ",".join(map(str, SCHUR_SIZES)), str(args.rounds_schur)],
                                   _env(args.tree, None))
            out[load]["loadavg_before"] = la
            print(f"  schur {load}: {out[load]}", file=sys.stderr, flush=True)
    return out


def report(curve: list[dict], schur: dict, overhead: dict | None) -> None:
    if curve:
        print("\n### Bar curve per point (medians over rounds; ms)\n")
        names = sorted({r["variant"] for r in curve}, key=["limit", "off", "base"].index)
        print("| N | load | " + " | ".join(f"{n}: wall | {n}: CPU" for n in names)
              + " | off / limit | BLAS threads inside (" + ", ".join(names) + ") | points | Newton its/pt |")
        print("|---|---|" + "---|---|" * len(names) + "---|---|---|---|")
        for N in sorted({r["N"] for r in curve}):
            for load in ("idle", "busy"):
                sel = [r for r in curve if r["N"] == N and r["load"] == load]
                if not sel:
                    continue
                med = {n: (statistics.median(r["ms_per_point"] for r in sel if r["variant"] == n),
                           statistics.median(r["cpu_ms_per_point"] for r in sel if r["variant"] == n)) for n in names}
                inside = ", ".join(str(next(r["blas_threads_inside"] for r in sel if r["variant"] == n)) for n in names)
                print(f"| {N} | {load} | " + " | ".join(f"{med[n][0]:.0f} | {med[n][1]:.0f}" for n in names)
                      + f" | {med['off'][0] / med['limit'][0]:.2f} | {inside} | {sel[0]['points']} | "
                      f"{statistics.median(r['nit'] for r in sel):.2f} |")
        print("\nAll runs (ms per point, wall):\n")
        for r in curve:
            print(f"- {r['load']} N={r['N']} {r['variant']} round {r['round']}: {r['ms_per_point']:.1f} "
                  f"(CPU {r['cpu_ms_per_point']:.1f}; load avg before {r['loadavg_before']:.2f})")
    if schur:
        print("\n### Dense LU + solve of the Schur complement (medians, ms)\n")
        print("| size | load | 1 thread | 2 threads | speed-up (1 / 2) | min 1 thread | min 2 threads | speed-up of the mins |")
        print("|---|---|---|---|---|---|---|---|")
        for n in SCHUR_SIZES:
            for load, res in schur.items():
                r = res[str(n)]
                print(f"| {n} | {load} | {r['1']:.2f} | {r['2']:.2f} | {r['1'] / r['2']:.2f} | {r['min1']:.2f} | "
                      f"{r['min2']:.2f} | {r['min1'] / r['min2']:.2f} |")
    if overhead:
        print("\n### Cost of the limit (us per enter + leave)\n")
        print(f"- changing the count (2 -> 1 -> 2): {overhead['change_us']:.1f} us")
        print(f"- already in place (nested): {overhead['in_place_us']:.1f} us")
        print(f"- bare `threadpoolctl.threadpool_limits(1)` (re-scans the libraries): "
              f"{overhead['threadpool_limits_us']:.0f} us")


def machine() -> str:
    import numpy
    import scipy

    return (f"- CPU: {cpu_model()}; logical CPUs: {os.cpu_count()}; python {platform.python_version()}, "
            f"numpy {numpy.__version__}, scipy {scipy.__version__}; load average at start "
            f"{' / '.join(f'{x:.2f}' for x in os.getloadavg())}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", choices=["all", "curve", "schur", "overhead"], default="all")
    ap.add_argument("--sizes", type=int, nargs="+", default=[2000, 20000], help="bar DOFs (default 2000 20000)")
    ap.add_argument("--H", type=int, default=10, help="harmonics (default 10)")
    ap.add_argument("--points", type=int, default=12, help="points of the curve at N <= 5000 (default 12)")
    ap.add_argument("--points-large", type=int, default=6, help="points above 5000 DOFs (default 6)")
    ap.add_argument("--rounds", type=int, default=3, help="alternated rounds per load and size (default 3)")
    ap.add_argument("--rounds-schur", type=int, default=5, help="alternations per size in the Schur part")
    ap.add_argument("--loads", nargs="+", choices=["idle", "busy"], default=["idle", "busy"])
    ap.add_argument("--tree", help="source tree of the children (PYTHONPATH; default: the installed femodes)")
    ap.add_argument("--base", help="a second source tree run as variant 'base' (e.g. the committed code)")
    ap.add_argument("--json", help="also write the raw numbers here")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        kind, *rest = args.child
        if kind == "curve":
            res = child_curve(*map(int, rest))
        elif kind == "schur":
            res = child_schur([int(s) for s in rest[0].split(",")], int(rest[1]))
        else:
            res = child_overhead(int(rest[0]))
        print(json.dumps(res))
        return 0
    print("## femodes benchmark: BLAS threads (issue 16, item 3)\n")
    print(machine())
    curve, schur, overhead = [], {}, None
    if args.part in ("all", "overhead"):
        overhead = _run_child(["overhead", "2000"], _env(args.tree, None))
    if args.part in ("all", "schur"):
        schur = part_schur(args)
    if args.part in ("all", "curve"):
        curve = part_curve(args)
    print(f"- load average at end {' / '.join(f'{x:.2f}' for x in os.getloadavg())}")
    report(curve, schur, overhead)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"curve": curve, "schur": schur, "overhead": overhead}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
