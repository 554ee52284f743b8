"""Step control of the continuation (issue 16 item 1): points, Newton iterations, rejected steps,
residual evaluations, wall time and the main fold, before/after, on the contact cases.

A plain script, not a pytest test.  Results and remarks: ``README_steps.md``.

Cases (models of ``bench_peers.py``, w in rad/s, ``fm.frequency_response`` with its default
options):

* ``seed1`` -- seed forced contact case 1: ``u'' + 0.1 u' + u = 0.2 cos(w t) - p``, stop at
  ``u = 1``, w 0.5 -> 2.0, H = 10, 20, 40;
* ``seed2`` -- seed case 2: ``u'' + 0.2 u' + u = cos(w t) - p``, stop at ``u = 2.5``, same span
  and H;
* ``cant20`` -- 20-DOF Hermite cantilever with a tip stop (gap 0.01), w 3.0 -> 4.2, H = 10;

each with the exact complementarity law (``signorini``: ``fm.UnilateralContact``) and the
penalty law k = 100 (300 for the cantilever: ``fm.PenaltyContact``).

"old" is the code of a source tree given by ``--base`` (default ``/tmp/steps_base``, made with
``git worktree add --detach /tmp/steps_base HEAD`` before the change), "new" the tree this script
lives in; each run is a fresh child process with that tree first on ``PYTHONPATH`` and
``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1``.  Each round runs every case old then
new (alternating, so that the load of the machine hits both alike); ``--repeat`` rounds (default
3), medians and ranges of the wall time reported.  Wall time: model build and the whole
``frequency_response`` (imports excluded).  Points, Newton iterations (all solves, rejected steps
and fold location included), rejected steps and residual evaluations are deterministic (the
script checks that they agree between rounds).  The main fold: of ``branch.folds``, the one with
the largest tip amplitude (the resonance peak); old and new must agree within 1e-6 relative.

Usage::

    python benchmarks/bench_steps.py                     # full run, markdown table on stdout
    python benchmarks/bench_steps.py --repeat 1 --cases seed1 --H 20
    python benchmarks/bench_steps.py --json out/steps.json
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

HERE = Path(__file__).resolve().parent
NEW_TREE = HERE.parent
THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
LAWS = ("signorini", "penalty")
OSC_H = (10, 20, 40)
FOLD_RTOL = 1e-6


def child(spec: dict) -> dict:
    """One run in this process: the case of ``spec`` with the femodes found first on the path."""
    sys.path.insert(0, str(HERE))
    import numpy as np

    import femodes as fm
    import femodes.runs as runs
    from bench_peers import CASES, femodes_model, tip_signal
    from femodes.hbm.problems import ForcedResponseProblem

    counts = {"evaluations": 0}
    residual = ForcedResponseProblem.residual

    def counted(self, x, p):
        counts["evaluations"] += 1
        return residual(self, x, p)

    ForcedResponseProblem.residual = counted
    inner = runs.continuation

    def recorded(*args, **kwargs):
        res = inner(*args, **kwargs)
        counts["newton"] = int(res.n_newton)
        counts["rejected"] = int(res.n_rejected)
        return res

    runs.continuation = recorded
    case, law, H = spec["case"], spec["law"], spec["H"]
    t0 = time.perf_counter()
    model, tip = femodes_model(case, law)
    br = fm.frequency_response(model, CASES[case]["span"], fm.Harmonics(H))
    wall = time.perf_counter() - t0
    amp = np.abs(tip_signal(br.Q[:, :, tip])).max(axis=1)
    main = max(br.folds, key=lambda i: amp[i]) if br.folds else None
    return dict(wall=wall, points=len(br), success=bool(br.success), folds=[float(br.omega[i]) for i in br.folds],
                fold=float(br.omega[main]) if main is not None else float("nan"),
                femodes=str(Path(fm.__file__).parent.parent), **counts)


def spawn(tree: Path, spec: dict, timeout: float) -> dict:
    env = dict(os.environ, **THREAD_ENV, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(spec)],
                         env=env, capture_output=True, text=True, timeout=timeout)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}"}
    rec = json.loads(out.stdout.strip().splitlines()[-1])
    if Path(rec["femodes"]).resolve() != tree.resolve():
        raise RuntimeError(f"child imported femodes from {rec['femodes']}, expected {tree}")
    return rec


def plan(cases: list[str], hs: list[int]) -> list[dict]:
    specs = []
    for case in cases:
        for law in LAWS:
            for H in ((10,) if case == "cant20" else hs):
                specs.append(dict(case=case, law=law, H=H))
    return specs


def summarise(spec: dict, runs: dict[str, list[dict]]) -> dict:
    row = dict(spec)
    for tag, recs in runs.items():
        good = [r for r in recs if "error" not in r]
        if not good:
            row[tag] = {"error": recs[0].get("error", "?")}
            continue
        walls = [r["wall"] for r in good]
        first = good[0]
        stable = all(r[k] == first[k] for r in good for k in ("points", "newton", "rejected", "evaluations"))
        row[tag] = dict(wall=statistics.median(walls), wall_min=min(walls), wall_max=max(walls),
                        points=first["points"], newton=first["newton"], rejected=first["rejected"],
                        evaluations=first["evaluations"], fold=first["fold"], folds=first["folds"],
                        success=first["success"], deterministic=stable)
    return row


def report(rows: list[dict]) -> str:
    head = ("| case | law | H | points old -> new | Newton it. old -> new | rejected old -> new | "
            "residual evals old -> new | wall [s] old: median (range) | wall [s] new: median (range) | "
            "speed-up | main fold old | new - old (rel.) |")
    lines = [head, "|" + "|".join(["---"] * 12) + "|"]
    for r in rows:
        o, n = r["old"], r["new"]
        if "error" in o or "error" in n:
            lines.append(f"| {r['case']} | {r['law']} | {r['H']} | error: {o.get('error', '')} {n.get('error', '')} "
                         + "| " * 9 + "|")
            continue
        rel = (n["fold"] - o["fold"]) / o["fold"]
        flag = "" if abs(rel) <= FOLD_RTOL else " **differs**"
        lines.append(
            f"| {r['case']} | {r['law']} | {r['H']} | {o['points']} -> {n['points']} | {o['newton']} -> {n['newton']} "
            f"| {o['rejected']} -> {n['rejected']} | {o['evaluations']} -> {n['evaluations']} "
            f"| {o['wall']:.2f} ({o['wall_min']:.2f}-{o['wall_max']:.2f}) "
            f"| {n['wall']:.2f} ({n['wall_min']:.2f}-{n['wall_max']:.2f}) | {o['wall'] / n['wall']:.1f}x "
            f"| {o['fold']:.9f} | {rel:.1e}{flag} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--base", default="/tmp/steps_base", help="source tree of the old code")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cases", nargs="+", default=["seed1", "seed2", "cant20"])
    ap.add_argument("--H", nargs="+", type=int, default=list(OSC_H))
    ap.add_argument("--timeout", type=float, default=600.0)
    ap.add_argument("--json", help="also write the raw runs and the summary here")
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(json.loads(args.child))))
        return 0
    trees = {"old": Path(args.base), "new": NEW_TREE}
    if not (trees["old"] / "femodes").is_dir():
        print(f"no femodes source tree at --base {args.base} (git worktree add --detach {args.base} HEAD)",
              file=sys.stderr)
        return 2
    specs = plan(args.cases, args.H)
    raw = {i: {"old": [], "new": []} for i in range(len(specs))}
    for rnd in range(args.repeat):
        for i, spec in enumerate(specs):
            for tag in ("old", "new"):  # alternate within each case and round
                rec = spawn(trees[tag], spec, args.timeout)
                raw[i][tag].append(rec)
                print(f"round {rnd + 1} {spec} {tag}: " + (rec.get("error") or
                      f"{rec['wall']:.2f} s, {rec['points']} points, {rec['newton']} Newton, "
                      f"{rec['rejected']} rejected, fold {rec['fold']:.9f}"), file=sys.stderr, flush=True)
    rows = [summarise(spec, raw[i]) for i, spec in enumerate(specs)]
    print(report(rows))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"rows": rows, "raw": raw}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
