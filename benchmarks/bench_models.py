#!/usr/bin/env python
"""Scaling benchmark of femodes model building, linear modes and Craig-Bampton reduction.

Run from the repository root::

    python benchmarks/bench_models.py                  # sizes 1e3 1e4 1e5, 5 repeats (3 at 1e5)
    python benchmarks/bench_models.py --quick          # sizes 1e3 1e4, 2 repeats (< 1 minute)
    python benchmarks/bench_models.py --sizes 1e3 3e3 1e4 --repeat 7 --cases bar-P1 beam
    python benchmarks/bench_models.py --json out/bench.json   # also dump the raw numbers

This is a script, not a pytest test. For every (case, size) the parent process starts a fresh
child process (same interpreter, ``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1``)
that measures four steps on a fixed-free structure of unit properties (E = rho = A = I = 1,
L = 1) with a unilateral contact declared at the free tip:

``assembly``
    ``fm.bar(mesh, ..., order=1|2, clamped="clamp")`` or ``fm.beam(mesh, ..., clamped="clamp")``.
    A fresh ``fm.line_mesh`` is built before every call, outside the timed region.
``with_contact``
    ``model.with_contact(fm.UnilateralContact(at="tip", gap=0.01))`` with femodes' defaults
    (which, for FE models, include redistributing the mass of the contact DOF).
``modes``
    ``fm.linear_modes(model, n=20)``.
``craig_bampton``
    ``fm.craig_bampton(model, n_modes=20)`` (the contact DOF at the tip is kept physical).

Per step the child makes (in this order) one call for the process memory, one call under
``tracemalloc``, then R timed calls (``time.perf_counter``; the median and the minimum are
reported). Memory numbers:

``RSS peak incr.``
    Increase of the process resident set during the step's first call: ``ru_maxrss`` (from
    ``resource.getrusage(RUSAGE_SELF)``) after the call minus the RSS just before it. Before the
    call the garbage collector runs, glibc's ``malloc_trim(0)`` hands free heap pages back to the
    OS and the kernel's high-water mark is reset (``echo 5 > /proc/self/clear_refs``), so the
    number is the peak of *this* step, including memory allocated by C/Fortran code (SuperLU
    factors, ARPACK, OpenBLAS buffers) and the result the step returns. Page granularity (4 KiB)
    and allocator caching make values below ~1 MiB noise.
``tracemalloc peak``
    Peak of the Python-visible heap allocated during one call (``tracemalloc`` peak minus the
    traced size at the start): Python objects and numpy/scipy array buffers (numpy reports its
    buffers to tracemalloc). It does NOT see memory that compiled libraries allocate with their
    own ``malloc`` (SuperLU's L and U, ARPACK/LAPACK internals), hence RSS can exceed it.

Accuracy: the first angular frequency is compared with the analytic fixed-free values,
``pi/2`` for the bar and ``1.8751040687**2`` for the cantilever beam (unit properties).
``w1 err (omega)`` is ``omega[0]/w1 - 1`` with ``omega[0]`` as femodes returns it (for
Craig-Bampton: ``linear_modes(rom, n=1)``); ``w1 err (RQ)`` is the same error for the Rayleigh
quotient ``sqrt(phi^T K phi / phi^T M phi)`` of the returned first shape ``phi``, an independent
check of the eigenvector. The Craig-Bampton error includes the truncation error of the
reduction (20 fixed-interface modes).

Times: wall-clock median and minimum of the R calls, and the median process CPU time
(``time.process_time``; with one BLAS thread it equals the wall time on an idle machine and is
less inflated when other processes compete for the cores).

Exponents: ``np.polyfit(log N, log t, 1)`` per (case, step) over the sizes at which the step did
not raise, for the median wall time (and, as a robustness check, the minimum and the CPU time).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _machine import cpu_model  # noqa: E402 - benchmarks/ is on sys.path when run as a script

CHILD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
CASES = {
    # name: (kind, order, DOFs per element)
    "bar-P1": ("bar", 1, 1),
    "bar-P2": ("bar", 2, 2),
    "beam": ("beam", None, 2),
}
W1 = {"bar": math.pi / 2, "beam": 1.8751040687**2}
STEPS = ("assembly", "with_contact", "modes", "craig_bampton")
N_MODES = 20
REPO = Path(__file__).resolve().parent.parent
MARK = "@@BENCH-JSON@@"


# ============================================================================================
# child side
# ============================================================================================
def _rss_kib() -> int:
    """Current resident set size (KiB) from /proc/self/status, or -1."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return -1


def _maxrss_kib() -> int:
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r // 1024 if sys.platform == "darwin" else r  # bytes on macOS, KiB on Linux


def _reset_hwm() -> bool:
    """Reset the kernel's peak-RSS mark of this process (Linux >= 4.0); False if impossible."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


_libc = None


def _malloc_trim() -> None:
    global _libc
    try:
        if _libc is None:
            import ctypes

            _libc = ctypes.CDLL("libc.so.6")
        _libc.malloc_trim(0)
    except (OSError, AttributeError):
        _libc = False


def _short_warning(w) -> str:
    msg = str(w.message)
    m = re.search(r"cond_1\(K\) ~ ([0-9.e+-]+)", msg)
    extra = f" cond~{m.group(1)}" if m else ""
    where = msg.split(":", 1)[0] if ":" in msg[:40] else ""
    return f"{w.category.__name__}{'(' + where + extra + ')' if where or extra else ''}"


def _short_error(exc: BaseException) -> str:
    msg = str(exc)
    m = re.search(r"cond_1 ~ ([0-9.e+-]+)", msg)
    detail = f"K_II numerically singular, cond~{m.group(1)}" if m else msg[:70]
    return f"{type(exc).__name__}: {detail}"


def _checked(rec: dict, check, result) -> None:
    """Run an accuracy check on a step's result; a failure is reported, not raised."""
    if result is None:
        return
    try:
        check(rec, result)
    except Exception as exc:
        rec["warnings"].append(f"accuracy check failed: {type(exc).__name__}: {str(exc)[:60]}")


def _child(case: str, n_target: int, repeat: int) -> dict:
    import gc
    import tracemalloc
    import warnings

    import numpy as np

    import femodes as fm

    kind, order, per_el = CASES[case]
    n_el = max(1, round(n_target / per_el))
    w1_exact = W1[kind]
    material = fm.Material(E=1.0, rho=1.0)
    section = fm.Section(area=1.0, inertia=1.0) if kind == "beam" else fm.Section(area=1.0)

    def mesh():
        return fm.line_mesh(length=1.0, n_elements=n_el, boundaries={"clamp": 0.0, "tip": 1.0})

    def assemble(m):
        if kind == "bar":
            model = fm.bar(m, material, section, order=order, clamped="clamp")
        else:
            model = fm.beam(m, material, section, clamped="clamp")
        return model

    def contact(model):
        return model.with_contact(fm.UnilateralContact(at="tip", gap=0.01))

    def rq_err(K, M, phi):
        q = float(phi @ (K @ phi)) / float(phi @ (M @ phi))
        return float(math.sqrt(q) / w1_exact - 1.0) if q >= 0 else float("nan")  # q < 0: round-off garbage

    gc.collect()
    _malloc_trim()
    hwm_ok = _reset_hwm()
    out = {
        "case": case,
        "kind": kind,
        "n_target": n_target,
        "n_elements": n_el,
        "repeat": repeat,
        "baseline_rss_mib": _rss_kib() / 1024,
        "hwm_reset": hwm_ok,
        "steps": [],
    }

    def measure(step: str, make_args, fn) -> tuple[dict, object]:
        rec: dict = {"step": step, "status": "ok", "warnings": []}
        # 1) first call: process memory (the high-water mark is reset just before it)
        args = make_args()
        gc.collect()
        _malloc_trim()
        _reset_hwm()
        rss0, hwm0 = _rss_kib(), _maxrss_kib()
        result, error = None, None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            t0 = time.perf_counter()
            try:
                result = fn(*args)
            except Exception as exc:  # reported in the table, not raised
                error = exc
            rec["first_s"] = time.perf_counter() - t0
        hwm1 = _maxrss_kib()
        base = rss0 if hwm_ok and rss0 >= 0 else hwm0
        rec["rss_peak_mib"] = max(hwm1 - base, 0) / 1024
        for w in caught:
            s = _short_warning(w)
            if s not in rec["warnings"]:
                rec["warnings"].append(s)
        rec["raised"] = error is not None
        if error is not None:
            rec["status"] = _short_error(error)
        del args
        # 2) one call under tracemalloc (not timed: tracing slows Python code down)
        args = make_args()
        gc.collect()
        tracemalloc.start()
        start = tracemalloc.get_traced_memory()[0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                r = fn(*args)
            except Exception:
                r = None
        rec["tm_peak_mib"] = (tracemalloc.get_traced_memory()[1] - start) / 2**20
        tracemalloc.stop()
        del r, args
        # 3) R timed calls
        times, cpu = [], []
        for _ in range(repeat):
            args = make_args()
            gc.collect()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                c0, t0 = time.process_time(), time.perf_counter()
                try:
                    r = fn(*args)
                except Exception:
                    r = None
                times.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            del r, args
        rec["times_s"] = times
        rec["cpu_s"] = cpu
        rec["median_s"] = statistics.median(times)
        rec["min_s"] = min(times)
        rec["cpu_median_s"] = statistics.median(cpu)
        out["steps"].append(rec)
        return rec, result

    # -- assembly
    rec, bare = measure("assembly", lambda: (mesh(),), assemble)
    if bare is not None:
        out["n_dofs"] = int(bare.n_dofs)
        rec["n_dofs"] = int(bare.n_dofs)
        rec["nnz_K"] = int(bare.K.nnz)
        # -- contact declaration (since femodes c9c93d6 it also redistributes the tip mass)
        # the lambda runs inside measure, before the del below (which is what F821 sees)
        rec, model = measure("with_contact", lambda: (bare,), contact)  # noqa: F821
        if model is not None:
            reports = getattr(model, "mass_redistribution", ())
            if reports:
                rec["warnings"].append(f"tip mass redistributed to DOFs {list(reports[0].get('targets', []))}")
    else:
        model = None
    if model is None:
        done = {s["step"] for s in out["steps"]}
        for step in STEPS:
            if step not in done:
                out["steps"].append({"step": step, "status": "skipped (no model)", "warnings": [], "raised": True})
        return out
    del bare
    n = min(N_MODES, model.n_dofs)

    # -- linear modes
    def modes_accuracy(rec, modes):
        om = np.asarray(modes.omega)
        rec["w1"] = float(om[0])
        rec["w1_err"] = float(om[0] / w1_exact - 1.0)
        rec["w1_rq_err"] = rq_err(model.K, model.M, modes.shapes[:, 0])
        rec["n_zero_omega"] = int(np.sum(om == 0.0))

    rec, modes = measure("modes", lambda: (model,), lambda m: fm.linear_modes(m, n=n))
    _checked(rec, modes_accuracy, modes)
    del modes

    # -- Craig-Bampton
    def rom_accuracy(rec, rom):
        rec["rom_n_dofs"] = int(rom.n_dofs)
        rec["tip_kept"] = bool(rom.n_kept == 1 and rom.dof("tip") == 0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rm = fm.linear_modes(rom, n=1)
        rec["w1"] = float(rm.omega[0])
        rec["w1_err"] = float(rm.omega[0] / w1_exact - 1.0)
        rec["w1_rq_err"] = rq_err(rom.K.toarray(), rom.M.toarray(), rm.shapes[:, 0])
        rec["n_zero_omega"] = int(rm.omega[0] == 0.0)

    rec, rom = measure("craig_bampton", lambda: (model,), lambda m: fm.craig_bampton(m, n_modes=min(N_MODES, m.n_dofs - 1)))
    _checked(rec, rom_accuracy, rom)
    return out


def _child_info() -> dict:
    import numpy as np
    import scipy

    import femodes

    info = {"env": {k: os.environ.get(k, "") for k in CHILD_ENV}}
    try:
        import skfem

        info["skfem"] = skfem.__version__
    except Exception as exc:  # pragma: no cover
        info["skfem"] = f"unavailable ({exc})"
    info["numpy"], info["scipy"], info["femodes"] = np.__version__, scipy.__version__, femodes.__version__
    blas = []
    try:
        import threadpoolctl

        for p in threadpoolctl.threadpool_info():
            blas.append(
                f"threadpoolctl: {p.get('internal_api')} {p.get('version')} {p.get('architecture', '')} "
                f"num_threads={p.get('num_threads')} ({os.path.basename(p.get('filepath', ''))})"
            )
    except ImportError:
        for name, mod in (("numpy", np), ("scipy", scipy)):
            try:
                dep = mod.show_config(mode="dicts")["Build Dependencies"]["blas"]
                blas.append(f"{name}: {dep.get('name')} {dep.get('version')} ({dep.get('openblas configuration', '').strip()})")
            except Exception as exc:
                blas.append(f"{name}: BLAS info unavailable ({exc})")
        blas.append("threadpoolctl not installed: thread counts not verified at run time")
    info["blas"] = blas
    return info


# ============================================================================================
# parent side
# ============================================================================================
def _run_child(argv: list[str], timeout: float) -> tuple[dict | None, str]:
    env = dict(os.environ, **CHILD_ENV)
    cmd = [sys.executable, str(Path(__file__).resolve()), *argv]
    try:
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=str(REPO))
    except subprocess.TimeoutExpired:
        return None, f"child timed out after {timeout:.0f} s"
    for line in p.stdout.splitlines():
        if line.startswith(MARK):
            return json.loads(line[len(MARK):]), p.stderr
    tail = (p.stderr or p.stdout).strip().splitlines()[-1:] or [""]
    return None, f"child failed (exit {p.returncode}): {tail[0][:120]}"


def _loadavg() -> str:
    try:
        return " / ".join(f"{x:.2f}" for x in os.getloadavg())
    except (AttributeError, OSError):
        return "unavailable"


def _machine_info(child: dict | None, load_start: str) -> list[str]:
    cpu = cpu_model("unknown")
    mem = ""
    try:
        with open("/proc/meminfo") as f:
            kib = int(f.readline().split()[1])
        mem = f"{kib / 2**20:.1f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    try:
        aff = len(os.sched_getaffinity(0))
    except AttributeError:
        aff = os.cpu_count()
    commit = "unknown"
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "femodes"], cwd=REPO, capture_output=True, text=True).stdout.strip()
        commit += " (uncommitted changes in femodes/)" if dirty else " (femodes/ clean)"
    except OSError:
        pass
    c = child or {}
    lines = [
        f"- date: {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}",
        f"- CPU: {cpu}; logical CPUs: {os.cpu_count()} (usable: {aff}); memory: {mem}",
        f"- OS: {platform.platform()}",
        f"- python {platform.python_version()} ({platform.python_implementation()}), numpy {c.get('numpy', '?')}, "
        f"scipy {c.get('scipy', '?')}, scikit-fem {c.get('skfem', '?')}, femodes {c.get('femodes', '?')} at git {commit}",
    ]
    for b in c.get("blas", ["BLAS info unavailable (info child failed)"]):
        lines.append(f"- BLAS: {b}")
    env = c.get("env", CHILD_ENV)
    lines.append("- child processes run with " + ", ".join(f"{k}={v}" for k, v in env.items()) + " (one fresh process per case and size)")
    lines.append(f"- load average (1/5/15 min) at start: {load_start}; at end: {_loadavg()} (other processes share the machine)")
    return lines


def _fmt_t(x) -> str:
    if x is None:
        return "-"
    return f"{x:.4f}" if x < 10 else f"{x:.1f}"


def _fmt_m(x) -> str:
    return "-" if x is None else f"{x:.1f}"


def _fmt_e(x) -> str:
    return "-" if x is None else f"{x:+.1e}"


def _table(results: list[dict]) -> list[str]:
    head = (
        "| case | N dofs | step | median [s] | min [s] | CPU median [s] | R | tracemalloc peak [MiB] | RSS peak incr. [MiB] "
        "| w1 err (omega) | w1 err (RQ) | status / warnings |"
    )
    lines = [head, "|" + "---|" * 12]
    for r in results:
        if "error" in r:
            lines.append(f"| {r['case']} | ~{r['n_target']:.0e} | - | - | - | - | - | - | - | - | - | {r['error']} |")
            continue
        nd = r.get("n_dofs", r["n_target"])
        for s in r["steps"]:
            status = s["status"]
            notes = list(s.get("warnings", []))
            if s.get("n_zero_omega"):
                notes.append(f"{s['n_zero_omega']} omega returned as 0")
            if s["step"] == "craig_bampton" and "rom_n_dofs" in s:
                notes.append(f"ROM {s['rom_n_dofs']} DOFs, tip kept: {'yes' if s.get('tip_kept') else 'NO'}")
            if s["step"] == "assembly" and "nnz_K" in s:
                notes.append(f"nnz(K)={s['nnz_K']}")
            text = status if not notes else (status + "; " + "; ".join(notes))
            lines.append(
                f"| {r['case']} | {nd} | {s['step']} | {_fmt_t(s.get('median_s'))} | {_fmt_t(s.get('min_s'))} | {_fmt_t(s.get('cpu_median_s'))} "
                f"| {len(s.get('times_s', [])) or '-'} | {_fmt_m(s.get('tm_peak_mib'))} | {_fmt_m(s.get('rss_peak_mib'))} "
                f"| {_fmt_e(s.get('w1_err'))} | {_fmt_e(s.get('w1_rq_err'))} | {text} |"
            )
    return lines


def _exponents(results: list[dict]) -> list[str]:
    import numpy as np

    lines = [
        "| case | step | sizes (N dofs) used | exponent: median time | min time | CPU median | tracemalloc peak |",
        "|---|---|---|---|---|---|---|",
    ]
    for case in dict.fromkeys(r["case"] for r in results):
        for step in STEPS:
            pts = []
            for r in results:
                if r["case"] != case or "error" in r:
                    continue
                for s in r["steps"]:
                    if s["step"] == step and not s.get("raised", True) and s.get("median_s"):
                        pts.append((r.get("n_dofs", r["n_target"]), s["median_s"], s["min_s"], s["cpu_median_s"], s.get("tm_peak_mib")))
            if len(pts) < 2:
                lines.append(f"| {case} | {step} | {', '.join(str(p[0]) for p in pts) or '-'} | n/a (< 2 sizes) | n/a | n/a | n/a |")
                continue
            n = np.log([p[0] for p in pts])

            def slope(col):
                y = [p[col] for p in pts]
                return f"{np.polyfit(n, np.log(y), 1)[0]:.2f}" if all(v and v > 0 for v in y) else "n/a"

            lines.append(f"| {case} | {step} | {', '.join(str(p[0]) for p in pts)} | {slope(1)} | {slope(2)} | {slope(3)} | {slope(4)} |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", nargs="+", type=lambda s: int(float(s)), help="target numbers of DOFs (default 1e3 1e4 1e5)")
    ap.add_argument("--repeat", type=int, help="timed repeats per step (default 5, and 3 for sizes >= 5e4)")
    ap.add_argument("--quick", action="store_true", help="sizes 1e3 1e4 and 2 repeats")
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES), help="models to run (default: all)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds allowed per child process")
    ap.add_argument("--json", type=Path, help="also write the raw results to this JSON file")
    ap.add_argument("--child", nargs=3, metavar=("CASE", "N", "R"), help=argparse.SUPPRESS)
    ap.add_argument("--child-info", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)

    if a.child_info:
        print(MARK + json.dumps(_child_info()), flush=True)
        return 0
    if a.child:
        res = _child(a.child[0], int(a.child[1]), int(a.child[2]))
        print(MARK + json.dumps(res), flush=True)
        return 0

    sizes = a.sizes or ([1000, 10000] if a.quick else [1000, 10000, 100000])
    if a.repeat is not None and a.repeat < 1:
        ap.error("--repeat must be >= 1")

    def repeats(n):
        if a.repeat is not None:
            return a.repeat
        if a.quick:
            return 2
        return 3 if n >= 50000 else 5

    t_start = time.perf_counter()
    load_start = _loadavg()
    info, err = _run_child(["--child-info"], 120)
    if info is None:
        print(f"warning: {err}", file=sys.stderr)
    results = []
    for case in a.cases:
        for n in sizes:
            print(f"[bench] {case} N~{n} R={repeats(n)} ...", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            res, err = _run_child(["--child", case, str(n), str(repeats(n))], a.timeout)
            if res is None:
                res = {"case": case, "n_target": n, "error": err}
            print(f"[bench]   done in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
            results.append(res)

    out = ["## femodes benchmark: model assembly, 20 linear modes, Craig-Bampton (20 modes)", ""]
    out += _machine_info(info, load_start)
    out += ["", "### Results", ""]
    out += _table(results)
    base = [r["baseline_rss_mib"] for r in results if "baseline_rss_mib" in r]
    notes = [
        "",
        f"Median / min of the wall time of R timed calls; CPU = median process CPU time (less sensitive to other load). RSS of a child after importing femodes: {min(base):.0f}-{max(base):.0f} MiB."
        if base
        else "",
    ]
    if any(not r.get("hwm_reset", True) for r in results):
        notes.append("WARNING: /proc/self/clear_refs unavailable: RSS increases are relative to the previous peak.")
    out += [x for x in notes if x is not None]
    out += ["", "### Fitted exponents (log-log least squares, t ~ N^k)", ""]
    out += _exponents(results)
    out += ["", f"Total benchmark wall time: {time.perf_counter() - t_start:.0f} s", ""]
    print("\n".join(out))
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"info": info, "results": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
