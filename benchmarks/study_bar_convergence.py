"""The clamped bar with a stop: its first nonsmooth mode under mesh and harmonic refinement against
the continuum (issue 35 item 2). Each (elements, H, mass) run's backbone frequency at 2, 5 and 20
grazing energies (the continuum's E_g), its error against the d'Alembert reference
(tests/bar_stop_reference.py) and its time, appended to benchmarks/results_bar_convergence.json as
it finishes (an interrupted study keeps what it computed).

    python benchmarks/study_bar_convergence.py [--runs 20:10,40:20,...] [--consistent]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

import femodes as fm

HERE = Path(__file__).resolve().parent
OUT = HERE / "results_bar_convergence.json"
GAP = 0.01
FACTORS = (2.0, 5.0, 20.0)


def continuum_omega(r):
    return 4.0 * (math.pi / 2) / (3.0 + 2.0 * math.sqrt(2.0) / (math.pi * math.sqrt(r)))


def run(n: int, H: int, redistribute: bool) -> dict:
    mesh = fm.line_mesh(1.0, n, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    model = model.with_contact(fm.UnilateralContact(at="tip", gap=GAP),
                               contact_mass=fm.RedistributeMass() if redistribute else fm.ConsistentMass())
    eg = fm.grazing_energy(model)
    t = time.process_time()
    br = fm.nonlinear_mode(model, 1, energy=(0.5 * eg, 25 * eg), harmonics=H)
    cpu = time.process_time() - t
    eg_c = math.pi ** 2 * GAP ** 2 / 16
    o = np.argsort(br.energy)
    w = [float(np.interp(math.log(f * eg_c), np.log(br.energy[o]), br.omega[o], left=np.nan, right=np.nan))
         for f in FACTORS]
    ref = [continuum_omega(f) for f in FACTORS]
    return {"elements": n, "H": H, "mass": "redistributed" if redistribute else "consistent",
            "omega": w, "reference": ref, "error": [wi / ri - 1 for wi, ri in zip(w, ref)],
            "reached_E_over_Eg": float(br.energy.max() / eg_c), "points": len(br), "cpu_s": cpu,
            "family": br.meta.get("family"), "message": br.message}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", default="20:10,40:10,40:20,80:20,80:40,160:20,160:40,320:40")
    ap.add_argument("--consistent", action="store_true")
    a = ap.parse_args()
    done = json.loads(OUT.read_text()) if OUT.exists() else []
    for item in a.runs.split(","):
        n, H = (int(v) for v in item.split(":"))
        mass = "consistent" if a.consistent else "redistributed"
        if any(r["elements"] == n and r["H"] == H and r["mass"] == mass for r in done):
            continue
        r = run(n, H, not a.consistent)
        done.append(r)
        OUT.write_text(json.dumps(done, indent=1))
        print(f"{n:4d} el H = {H:3d} {mass:13s}: errors at 2/5/20 E_g "
              + " ".join(f"{e:+.3%}" for e in r["error"]) + f"  reached {r['reached_E_over_Eg']:.1f} E_g, "
              f"{r['points']} points, {r['cpu_s']:.0f} s", flush=True)


if __name__ == "__main__":
    main()
