"""The cost of stability along a branch, against the branch itself (issue 36, item 1): CPU time of
each branch alone and with ``stability=True`` (bifurcations located) or
``StabilityOptions(locate=False)`` (bracketed), side by side in one run, BLAS on one thread;
medians of 2-3 repeats. Writes benchmarks/results_stability_cost.json.

    python benchmarks/bench_stability_cost.py
"""
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "examples"))
from threadpoolctl import threadpool_limits  # noqa: E402

import femodes as fm  # noqa: E402
from _machine import cpu_model  # noqa: E402
import user_blade_3d as ub  # noqa: E402

def cpu(fn):
    c = time.process_time(); out = fn(); return out, time.process_time() - c

BR = fm.StabilityOptions(locate=False)
rows = {}
def measure(name, fn, variants, reps=2):
    tb = []; ts = {v: [] for v in variants}; last = {}
    for rep in range(reps):
        b, t = cpu(lambda: fn(False)); tb.append(t)
        for v, st in variants.items():
            s, t = cpu(lambda: fn(st)); ts[v].append(t); last[v] = s
    mb = statistics.median(tb)
    for v in variants:
        ms = statistics.median(ts[v]); s = last[v]
        rows[f"{name} [{v}]"] = dict(branch=mb, stability=ms - mb, ratio=(ms - mb) / mb, points=len(s),
                                     bifurcations=[x.kind for x in s.bifurcations])
        print(f"{name:30s} {v:8s} branch {mb:6.2f}  stab {ms-mb:6.2f}  ratio {(ms-mb)/mb:5.2f}  pts {len(s)} {[x.kind[:4] for x in s.bifurcations]}", flush=True)

with threadpool_limits(1):
    solid = fm.solid(fm.load_mesh(ub.MESHES[False]), ub.STEEL, clamped="root", order=2)
    rom = fm.craig_bampton(ub.with_stop(solid), 10)
    w1 = float(fm.linear_modes(rom, 1).omega[0]); eg = fm.grazing_energy(rom, 1)
    und = fm.craig_bampton(ub.with_stop(solid, None, None), 10)
    measure("user blade forced H5", lambda st: fm.frequency_response(rom, (0.9*w1, 1.25*w1), 5, stability=fm.stability_methods.Hill() if st is True else st),
            {"located": True})
    measure("user blade backbone damped H5", lambda st: fm.nonlinear_mode(rom, 1, energy=(0.5*eg, 20*eg), harmonics=5, stability=st),
            {"located": True, "bracket": BR})
    measure("user blade undamped H5", lambda st: fm.nonlinear_mode(und, 1, energy=(0.5*eg, 20*eg), harmonics=5, stability=st),
            {"located": True})
    measure("user blade undamped H10", lambda st: fm.nonlinear_mode(und, 1, energy=(0.5*eg, 20*eg), harmonics=10, stability=st),
            {"located": True, "bracket": BR})
    import blade3d_reduction as b3  # noqa: E402 (computes its example at import)
    measure("blade3d backbone H7", lambda st: fm.nonlinear_mode(b3.rom, 1, energy=(0.5 * b3.E_GRAZE, 20 * b3.E_GRAZE), harmonics=b3.H, options=b3.OPTIONS, stability=st),
            {"located": True, "bracket": BR})
    import blade_casing as bc  # noqa: E402
    measure("casing forced H7", lambda st: fm.frequency_response(bc.forced_rom, bc.SPAN, bc.H, stability=fm.stability_methods.Hill() if st is True else st),
            {"located": True}, reps=3)
    measure("casing backbone H7", lambda st: fm.nonlinear_mode(bc.rom, 1, energy=bc.ENERGY, harmonics=bc.H, options=bc.NNM_OPTIONS, stability=st),
            {"located": True}, reps=3)
head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=HERE, capture_output=True, text=True).stdout.strip()
meta = {"cpu": cpu_model(), "load_average": open("/proc/loadavg").read().split()[:3], "commit": head}
(HERE / "results_stability_cost.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
