"""The user's 3-D blade of examples/user_blade_3d.py, stage by stage, with stability and rtol on:
the branch alone and with each option, side by side in one run (CPU and wall time; BLAS on one
thread). Writes benchmarks/results_user_blade.json.

    python benchmarks/bench_user_blade.py [--H 5]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from threadpoolctl import threadpool_limits

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "examples"))
import femodes as fm  # noqa: E402
import user_blade_3d as ex  # noqa: E402


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--H", type=int, default=5)
    H = ap.parse_args().H
    rows = {}
    with threadpool_limits(1):
        mesh = fm.load_mesh(ex.MESHES[False])
        model, *t = timed(lambda: fm.solid(mesh, ex.STEEL, clamped="root", order=2))
        rows["model (fm.solid, Q2)"] = t
        model = ex.with_stop(model)
        rom, *t = timed(lambda: fm.craig_bampton(model, 10))
        rows["Craig-Bampton (10 modes)"] = t
        w1 = float(fm.linear_modes(rom, 1).omega[0])
        e_g = fm.grazing_energy(rom, 1)
        span_e, span_w = (0.5 * e_g, 20 * e_g), (0.9 * w1, 1.25 * w1)
        bb, *t = timed(lambda: fm.nonlinear_mode(rom, 1, energy=span_e, harmonics=H))
        rows["backbone"] = t + [len(bb)]
        bbs, *t = timed(lambda: fm.nonlinear_mode(rom, 1, energy=span_e, harmonics=H, stability=True))
        rows["backbone + stability"] = t + [len(bbs), len(bbs.bifurcations)]
        fr, *t = timed(lambda: fm.frequency_response(rom, span_w, H))
        rows["forced response"] = t + [len(fr)]
        frs, *t = timed(lambda: fm.frequency_response(rom, span_w, H, stability=fm.stability_methods.Hill()))
        rows["forced response + stability (hill)"] = t + [len(frs), len(frs.bifurcations)]
        frr, *t = timed(lambda: fm.frequency_response(rom, span_w, H, rtol=1e-2))
        rows["forced response + rtol 1e-2"] = t + [len(frr), int(frr.accuracy.met.sum())]
    head = f"stage (H = {H})"
    print(f"{head:40s} {'wall s':>8s} {'CPU s':>8s}  notes")
    for k, v in rows.items():
        print(f"{k:40s} {v[0]:8.2f} {v[1]:8.2f}  {v[2:] if len(v) > 2 else ''}")
    for a, b in (("backbone + stability", "backbone"), ("forced response + stability (hill)", "forced response"),
                 ("forced response + rtol 1e-2", "forced response")):
        print(f"{a} / {b}: {rows[a][1] / rows[b][1]:.2f} (CPU)")
    out = HERE / "results_user_blade.json"
    out.write_text(json.dumps({"H": H, "rows": {k: [float(x) for x in v] for k, v in rows.items()}}, indent=1))
    print("wrote", out)


if __name__ == "__main__":
    main()
