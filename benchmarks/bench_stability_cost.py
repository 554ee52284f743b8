"""The cost of stability along a branch, against the branch itself (issue 36, item 1): CPU time of
each branch alone and with ``stability=True`` (bifurcations located) or
``StabilityOptions(locate=False)`` (bracketed), side by side in one run, BLAS on one thread;
medians of 3 warm repeats, and the first (cold) run of each apart (:func:`measure`). Writes
benchmarks/results_stability_cost.json.

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
def measure(name, fn, variants, reps=3):
    """The branch alone and with each stability variant. The first call of each pays one-off caches
    (the Hill reduction's modes and static solves are kept per model): it is timed apart, and
    ``first`` is the first variant's ratio on those cold runs (a user's single run). ``ratio``
    comes from the medians of the ``reps`` warm repeats after it, the variants in rotated order."""
    first_b = cpu(lambda: fn(False))[1]
    first = {v: cpu(lambda: fn(st))[1] for v, st in variants.items()}
    tb = []; ts = {v: [] for v in variants}; last = {}
    items = list(variants.items())
    for rep in range(reps):
        b, t = cpu(lambda: fn(False)); tb.append(t)
        for v, st in items[rep % len(items):] + items[:rep % len(items)]:
            s, t = cpu(lambda: fn(st)); ts[v].append(t); last[v] = s
    mb = statistics.median(tb)
    for j, v in enumerate(variants):
        ms = statistics.median(ts[v]); s = last[v]
        cold = (first[v] - first_b) / first_b if j == 0 else None
        rows[f"{name} [{v}]"] = dict(branch=mb, stability=ms - mb, ratio=(ms - mb) / mb, points=len(s),
                                     first_branch=first_b if j == 0 else None, first_ratio=cold,
                                     bifurcations=[x.kind for x in s.bifurcations])
        tail = f"  first run {cold:5.2f}" if cold is not None else ""
        print(f"{name:30s} {v:8s} branch {mb:6.2f}  stab {ms-mb:6.2f}  ratio {(ms-mb)/mb:5.2f}{tail}  pts {len(s)} {[x.kind[:4] for x in s.bifurcations]}", flush=True)

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
            {"located": True})
    measure("casing backbone H7", lambda st: fm.nonlinear_mode(bc.rom, 1, energy=bc.ENERGY, harmonics=bc.H, options=bc.NNM_OPTIONS, stability=st),
            {"located": True})
    # structures outside the ones item 1 names (eleventh session): an FE cantilever with a tip stop
    # (meshes/cantilever.msh, 40 Hermite elements, examples/cantilever_tip_stop.py) whole and reduced,
    # and the user's blade with its stop under the tip edge instead of the pad
    GAP = 0.01
    beam = fm.beam(fm.load_mesh(HERE.parent / "meshes" / "cantilever.msh"), fm.Material(E=1.0, rho=1.0),
                   fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    cant = beam.with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    lin = fm.linear_modes(cant, 1)
    EG = (GAP / lin.shapes[cant.dof("tip"), 0]) ** 2 * lin.omega[0] ** 2 / 2
    OPT = fm.ContinuationOptions(step=0.05, max_step=0.1, newton=fm.NewtonOptions(atol=1e-9, max_iter=20))
    for nm in (4, 10):
        cb = fm.craig_bampton(cant, nm)
        measure(f"cantilever CB{nm} ({cb.n_dofs} DOFs) backbone H10", lambda st: fm.nonlinear_mode(cb, 1, energy=(0.5 * EG, 20 * EG), harmonics=10, options=OPT, stability=st),
                {"located": True, "bracket": BR})
    crom = fm.craig_bampton(cant.with_damping(alpha=0.02).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)), 10)
    measure("cantilever CB10 forced H10", lambda st: fm.frequency_response(crom, (3.0, 4.2), 10, stability=st), {"located": True})
    measure(f"cantilever whole ({cant.n_dofs} DOFs) backbone H10", lambda st: fm.nonlinear_mode(cant, 1, energy=(0.5 * EG, 20 * EG), harmonics=10, options=OPT, stability=st),
            {"located": True})
    tip = solid.with_contact(fm.UnilateralContact(at="tip", gap=ub.GAP, direction=(0.0, 0.0, 1.0)))
    trom = fm.craig_bampton(tip, 10)
    tw1 = float(fm.linear_modes(trom, 1).omega[0]); teg = fm.grazing_energy(trom, 1)
    measure(f"user blade, stop at the tip ({trom.n_dofs} DOFs) backbone H7", lambda st: fm.nonlinear_mode(trom, 1, energy=(0.5 * teg, 20 * teg), harmonics=7, stability=st),
            {"located": True, "bracket": BR})
    tforced = fm.craig_bampton(tip.with_forcing(fm.HarmonicForce(at=("tip", "u_z"), amplitude=1.0)).with_damping(modal=0.01), 10)
    measure("user blade, stop at the tip forced H7", lambda st: fm.frequency_response(tforced, (0.9 * tw1, 1.3 * tw1), 7, stability=st),
            {"located": True})
head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=HERE, capture_output=True, text=True).stdout.strip()
meta = {"cpu": cpu_model(), "load_average": open("/proc/loadavg").read().split()[:3], "commit": head}
(HERE / "results_stability_cost.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
