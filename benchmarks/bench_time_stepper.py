#!/usr/bin/env python
"""Per-step cost of the Moreau-Jean time stepper (:func:`femodes.simulate`), old tree against new.

Run from the repository root::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_time_stepper.py            # this tree, 7 repeats
    PYTHONPATH=/tmp/oldtree python benchmarks/bench_time_stepper.py           # another source tree
    python benchmarks/bench_time_stepper.py --compare /tmp/oldtree .          # alternate two trees
    python benchmarks/bench_time_stepper.py --compare /tmp/oldtree /tmp/other . --rounds 9 --json out/ts.json

This is a script, not a pytest test. An old tree to compare with is made by
``git worktree add /tmp/oldtree <commit>`` (remove it with ``git worktree remove --force /tmp/oldtree``).

Cases (``--cases``), 2000 steps each, all driven by ``simulate(model, t_end, dt, u0=, v0=, omega=)``
with the default options (theta = 1/2, restitution 1, every step stored), an API that the trees
before and after the ``time/`` refactor share:

``impact``
    1-DOF forced impact oscillator ``u'' + 0.1 u' + u = 0.5 cos(1.3 t) - p``, rigid stop
    (``UnilateralContact``) at gap 0.5, ``v0 = 1``, ``dt = 0.01`` (free flights and impacts);
``duffing``
    1-DOF forced Duffing oscillator ``u'' + 0.05 u' + u + u^3 = 0.3 cos(1.2 t)`` (``CubicSpring``),
    ``u0 = 0.5``, ``dt = 0.01`` (one local Newton solve per step);
``bar``
    clamped P1 bar of 200 elements (200 DOFs, unit properties, ``fm.bar`` on ``fm.line_mesh``),
    ``UnilateralContact`` at the tip, gap 0.005 (the default mass redistribution makes the tip
    massless: a quasi-static Signorini contact in every step's problem), tip force
    ``0.02 cos(1.5 t)``, ``dt = 1e-3`` (dense propagators, the largest dense model).

Timed: one ``simulate`` call (operators, the 2000 steps and the stored results), reported in ms
per 1000 steps; median and minimum over the repeats, after one untimed warm-up call. Each child
process runs with ``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1``. With ``--compare``
the trees alternate (old, new, old, new, ...; each round is one fresh child per tree running
``--per-child`` repeats of every case) so that a change of machine load hits all of them; the
table gives the medians (over all rounds) and the ratios of the medians and of the minima to the
first tree, and checks that every tree computed the same final state as the first (to round-off,
1e-9 relative).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

N_STEPS = 2000
CASES = ("impact", "duffing", "bar")
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


# --------------------------------------------------------------------------------------------
# Cases (API present in both trees)
# --------------------------------------------------------------------------------------------
def build(case: str):
    """``(model, simulate keyword arguments)`` of a case; ``t_end = N_STEPS * dt``."""
    import femodes as fm

    if case == "impact":
        model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
                 .with_contact(fm.UnilateralContact(at=0, gap=0.5))
                 .with_forcing(fm.HarmonicForce(at=0, amplitude=0.5)))
        return model, dict(dt=0.01, omega=1.3, v0=[1.0])
    if case == "duffing":
        model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.05]])
                 .with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
                 .with_forcing(fm.HarmonicForce(at=0, amplitude=0.3)))
        return model, dict(dt=0.01, omega=1.2, u0=[0.5])
    if case == "bar":
        mesh = fm.line_mesh(1.0, 200, boundaries={"clamp": 0.0, "tip": 1.0})
        bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
        model = (bar.with_contact(fm.UnilateralContact(at="tip", gap=0.005))
                 .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.02)))
        return model, dict(dt=1e-3, omega=1.5)
    raise ValueError(f"unknown case {case!r}")


def simulate(model, dt, **kw):
    """``femodes.simulate`` over ``N_STEPS`` steps of ``dt`` (shim: the keyword arguments used here
    exist with the same meaning and defaults in the old and the new signature)."""
    import femodes as fm

    return fm.simulate(model, N_STEPS * dt, dt, **kw)


def run_child(cases, repeat: int) -> dict:
    """Time ``repeat`` calls per case in this process; seconds per call, and a check value."""
    import femodes

    out = {"femodes": femodes.__file__, "cases": {}}
    for case in cases:
        model, kw = build(case)
        th = simulate(model, **kw)  # warm-up (imports, caches)
        n = th.u.shape[0] - 1
        if n != N_STEPS:
            raise RuntimeError(f"{case}: {n} steps, expected {N_STEPS}")
        times = []
        for _ in range(repeat):
            t = time.perf_counter()
            th = simulate(model, **kw)
            times.append(time.perf_counter() - t)
        out["cases"][case] = {
            "times": times,
            "n_impacting": int(abs(th.impulse).sum(axis=1).astype(bool).sum()) if th.impulse.size else 0,
            "u_end": th.u[-1].tolist(),
            "umax": float(abs(th.u).max()),
        }
    return out


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------
def per_kstep(seconds: float) -> float:
    return 1e3 * seconds * 1000.0 / N_STEPS


def report_one(res: dict) -> None:
    print(f"femodes from {res['femodes']}; {N_STEPS} steps per call; ms per 1000 steps")
    print("| case | median | min | R | steps with impulse |")
    print("|---|---:|---:|---:|---:|")
    for case, c in res["cases"].items():
        t = c["times"]
        print(f"| {case} | {per_kstep(statistics.median(t)):.3f} | {per_kstep(min(t)):.3f} | {len(t)} "
              f"| {c['n_impacting']} |")


def child_env(tree: str | None) -> dict:
    env = dict(os.environ)
    for var in THREAD_VARS:
        env[var] = "1"
    if tree is not None:
        env["PYTHONPATH"] = str(Path(tree).resolve())
    return env


def compare(trees: list[str], cases, rounds: int, per_child: int, json_out: str | None) -> None:
    """Run the trees alternately (one child per tree per round); medians and ratios to the first."""
    labels = [f"{i}:{Path(t).resolve().name}" for i, t in enumerate(trees)]
    samples = {lab: {c: [] for c in cases} for lab in labels}
    last = {}
    for r in range(rounds):
        for lab, tree in zip(labels, trees):
            cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "--repeat", str(per_child),
                   "--cases", *cases]
            proc = subprocess.run(cmd, env=child_env(tree), capture_output=True, text=True, cwd="/")
            if proc.returncode:
                sys.stderr.write(proc.stderr)
                raise SystemExit(f"child for {lab} ({tree}) failed")
            res = json.loads(proc.stdout.strip().splitlines()[-1])
            last[lab] = res
            for c in cases:
                samples[lab][c] += res["cases"][c]["times"]
            print(f"round {r + 1}/{rounds} {lab}: "
                  + ", ".join(f"{c} {per_kstep(statistics.median(res['cases'][c]['times'])):.2f}" for c in cases),
                  file=sys.stderr, flush=True)
    ref = labels[0]
    for lab in labels:
        print(f"{lab}: {last[lab]['femodes']}")
    print(f"\n{rounds} alternating rounds x {per_child} repeats per child ({rounds * per_child} per case and tree); "
          f"ms per 1000 steps; ratios to {ref}\n")
    head = "| case | " + " | ".join(f"{lab} median" for lab in labels) + " | " + " | ".join(
        f"{lab}/{ref} median | {lab}/{ref} min" for lab in labels[1:]) + " | same result |"
    print(head)
    print("|---" * (head.count("|") - 1) + "|")
    table = {}
    for c in cases:
        med = {lab: statistics.median(samples[lab][c]) for lab in labels}
        low = {lab: min(samples[lab][c]) for lab in labels}
        u_ref = last[ref]["cases"][c]["u_end"]
        scale = max(1.0, max(abs(x) for x in u_ref))
        diff = max(max(abs(a - b) for a, b in zip(u_ref, last[lab]["cases"][c]["u_end"])) for lab in labels[1:])
        same = "yes" if diff <= 1e-9 * scale else f"NO (|du| = {diff:.2e})"
        print(f"| {c} | " + " | ".join(f"{per_kstep(med[lab]):.3f}" for lab in labels) + " | " + " | ".join(
            f"{med[lab] / med[ref]:.3f} | {low[lab] / low[ref]:.3f}" for lab in labels[1:]) + f" | {same} |")
        table[c] = {lab: {"median_ms": per_kstep(med[lab]), "min_ms": per_kstep(low[lab]),
                          "ratio_median": med[lab] / med[ref], "ratio_min": low[lab] / low[ref]} for lab in labels}
        table[c]["max_abs_diff_u_end"] = diff
    if json_out:
        Path(json_out).parent.mkdir(parents=True, exist_ok=True)
        Path(json_out).write_text(json.dumps({"trees": dict(zip(labels, trees)), "table": table,
                                              "samples": samples}, indent=1))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--repeat", type=int, default=7, help="timed calls per case (this tree; default 7)")
    ap.add_argument("--compare", nargs="+", metavar="TREE",
                    help="two or more source trees (the first is the reference), run alternately")
    ap.add_argument("--rounds", type=int, default=7, help="alternating rounds with --compare (default 7)")
    ap.add_argument("--per-child", type=int, default=3, help="timed calls per case in each child (default 3)")
    ap.add_argument("--json", help="also write the numbers (all repeats) to this file")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(run_child(args.cases, args.repeat)))
        return
    if args.compare:
        if len(args.compare) < 2:
            ap.error("--compare needs at least two source trees")
        compare(args.compare, args.cases, args.rounds, args.per_child, args.json)
        return
    for var in THREAD_VARS:  # effective only if numpy is not loaded yet (it is not: imported lazily)
        os.environ.setdefault(var, "1")
    res = run_child(args.cases, args.repeat)
    report_one(res)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
