"""A shallow pinned arch with a stop under its crown, end to end (a structure nobody tuned femodes
for; tests/test_nonsmooth_modes.py builds the same one): the forced response alone and with the
default stability (``stability=True``: ``Auto``, which shoots small models), with Hill's method,
and the backbones against its peak at H = 7 (a truncation artefact, which ``rtol`` finds
unconverged) and H = 15, side by side in one run (CPU and wall time, one BLAS
thread). ``--before`` also times the default stability as it was before ``Auto`` bounded its
shootings (30 Newton iterations each, no budget: about 11 minutes). Writes
benchmarks/results_arch.json.

    python benchmarks/bench_arch.py [--before]
    python benchmarks/bench_arch.py --time      # the stepped sine in the time domain (about 1 min)
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import skfem
from threadpoolctl import threadpool_limits

import femodes as fm
import femodes.stability_methods as methods

HERE = Path(__file__).resolve().parent


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def arch():
    """The arch: R = 1 m, 40 deg, 20 mm thick, 50 mm wide, steel, plane stress, 40 x 2 Q2
    quadrilaterals, pinned corners, a stop 1 mm under the crown."""
    R, half, th = 1.0, math.radians(20), 0.02
    base = fm.rectangle_mesh(1.0, 1.0, nx=40, ny=2, quadrilaterals=True)
    ang, rad = (base.p[0] - 0.5) * 2 * half, R - th / 2 + base.p[1] * th
    mesh = skfem.MeshQuad(np.vstack([rad * np.sin(ang), rad * np.cos(ang) - R * math.cos(half)]), base.t)
    ends = {f"{side}{k}": (sgn * rr * math.sin(half), rr * math.cos(half) - R * math.cos(half))
            for side, sgn in (("l", -1), ("r", 1)) for k, rr in enumerate((R - th / 2, R + th / 2))}
    model = fm.solid(mesh, fm.Material(E=210e9, rho=7800.0, nu=0.3), clamped=list(ends), plane="stress",
                     thickness=0.05, order=2, points={**ends, "crown": (0.0, R - th / 2 - R * math.cos(half))})
    return model.with_contact(fm.UnilateralContact(at="crown", gap=1e-3, direction=(0, -1)))


def forced_rom(model):
    """The forced case of ``arch()``'s model reduced by Craig-Bampton with 10 modes: 1 % modal
    damping, 2 kN at the crown toward the stop."""
    return fm.craig_bampton(model.with_damping(modal=0.01).with_forcing(
        fm.HarmonicForce(at=("crown", "u_y"), amplitude=-2000.0)), 10)


def time_sweep() -> None:
    """A stepped sine in the time domain (``--time``): ``fm.steady_state`` of the reduced forced arch
    at w / w2 = 0.95, 0.96, ... 1.12, each from the previous one's last state (restitution 0, 800
    steps a period), against the largest energy of the harmonic balance branches at H = 7 and 15
    within 0.5 % of each frequency. Writes benchmarks/results_arch_time.json."""
    forced = forced_rom(arch())
    w2 = float(fm.linear_modes(forced, 2).omega[1])
    hbm = {H: fm.frequency_response(forced, (0.9 * w2, 1.3 * w2), H) for H in (7, 15)}
    u = v = None
    out = []
    print("| w / w2 | time: mean energy | periodic | min gap [um] | HBM H = 7 | HBM H = 15 |\n|---|---|---|---|---|---|")
    for r in np.round(np.arange(0.95, 1.125, 0.01), 2):
        w = float(r) * w2
        with threadpool_limits(1):
            ss = fm.steady_state(forced, w, dt=2 * math.pi / w / 800, u0=u, v0=v, restitution=0.0)
        U, V = np.asarray(ss.u), np.asarray(ss.v)
        u, v = (U[-1], V[-1]) if U.shape[0] == ss.t.size else (U[:, -1], V[:, -1])
        near = {H: b.energy[np.abs(b.omega / w - 1.0) <= 5e-3] for H, b in hbm.items()}
        row = dict(ratio=float(r), energy=float(np.mean(ss.energy)), periodic=bool(ss.converged),
                   min_gap=float(np.min(ss.gap)), **{f"hbm_H{H}": float(e.max()) if e.size else None for H, e in near.items()})
        out.append(row)
        print(f"| {r:.2f} | {row['energy']:.2f} | {row['periodic']} | {1e6 * row['min_gap']:.1f} | "
              + " | ".join("-" if row[f"hbm_H{H}"] is None else f"{row[f'hbm_H{H}']:.2f}" for H in (7, 15)) + " |")
    (HERE / "results_arch_time.json").write_text(json.dumps(out, indent=1))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", action="store_true", help="also the default stability without the shooting budget")
    ap.add_argument("--time", action="store_true", help="only the stepped sine in the time domain (time_sweep)")
    args = ap.parse_args()
    if args.time:
        time_sweep()
        return
    before = args.before
    rows: dict = {}
    with threadpool_limits(1):
        model, *t = timed(arch)
        rows["model (fm.solid, Q2, 802 DOFs)"] = t
        free, *t = timed(lambda: fm.craig_bampton(model, 10))
        rows["Craig-Bampton, 10 modes"] = t
        forced = forced_rom(model)
        w2, eg = float(fm.linear_modes(free, 2).omega[1]), fm.grazing_energy(free, 2)
        span = (0.9 * w2, 1.3 * w2)
        frc, *t = timed(lambda: fm.frequency_response(forced, span, 7))
        rows["forced response, H = 7"] = t
        variants = {"stability=True (Auto)": True, "stability=Hill()": methods.Hill()}
        for name, st in variants.items():
            s, *t = timed(lambda: fm.frequency_response(forced, span, 7, stability=st))
            rows[f"forced response + {name}"] = t + [sorted(set(map(str, s.stability_method)))]
        if before:
            iters, budget = methods.AUTO_MAX_ITER, methods.AUTO_MAX_FAILED_TIME
            methods.AUTO_MAX_ITER, methods.AUTO_MAX_FAILED_TIME = 30, math.inf
            try:
                s, *t = timed(lambda: fm.frequency_response(forced, span, 7, stability=True))
            finally:
                methods.AUTO_MAX_ITER, methods.AUTO_MAX_FAILED_TIME = iters, budget
            rows["forced response + stability=True, before (30 iterations, no budget)"] = t + [
                sorted(set(map(str, s.stability_method)))]
        energy = (0.5 * eg, 10 * eg)
        bb, *t = timed(lambda: fm.nonlinear_mode(free, 2, energy=energy, harmonics=7))
        rows["backbone, mode 2 (default)"] = t
        fam, *t = timed(lambda: fm.nonlinear_mode(free, 2, energy=energy, harmonics=7,
                                                   past_grazing=fm.PeriodDriven(always=True)))
        rows["backbone, mode 2, PeriodDriven(always=True)"] = t
        peaks = {name: fm.compare_resonance(b, frc)[0] for name, b in (("default", bb), ("contact phase", fam))}
        # the H = 7 peak is a truncation artefact: at H = 15 the forced branch peaks on the default backbone
        frc15, *t = timed(lambda: fm.frequency_response(forced, span, 15))
        rows["forced response, H = 15"] = t
        bb15, *t = timed(lambda: fm.nonlinear_mode(free, 2, energy=energy, harmonics=15))
        rows["backbone, mode 2 (default), H = 15"] = t
        peaks["default, H = 15"] = fm.compare_resonance(bb15, frc15)[0]
        est, *t = timed(lambda: fm.frequency_response(forced, span, 7, rtol=1e-2))
        rows["forced response, H = 7, rtol=1e-2"] = t + [[f"peak converged: {bool(est.accuracy.met[np.argmax(est.energy)])}"]]
    print("| stage | wall [s] | CPU [s] | note |\n|---|---|---|---|")
    for k, v in rows.items():
        print(f"| {k} | {v[0]:.2f} | {v[1]:.2f} | {', '.join(v[2]) if len(v) > 2 else ''} |")
    for name, p in peaks.items():
        print(f"peak at {p.omega / w2:.4f} w2 against the {name} backbone: {p.predicted}")
    out = {"rows": rows, "peaks": {k: dict(omega_over_w2=p.omega / w2, distance=p.distance, predicted=p.predicted)
                                   for k, p in peaks.items()}}
    (HERE / "results_arch.json").write_text(json.dumps(out, indent=1, default=str))


if __name__ == "__main__":
    main()
