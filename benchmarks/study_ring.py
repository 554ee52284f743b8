"""A curved 3-D beam against a stop, built for checking femodes on a structure nobody tuned it for:
a quarter ring (mean radius 0.1 m, 10 x 6 mm section, steel) meshed with gmsh in P1 tetrahedra
(4 mm) and solved at ``order=2`` (6192 DOFs), clamped at one end, its free end face 0.2 mm under
a stop along +z (43 contact nodes), Craig-Bampton with 10 modes (53 DOFs), 1 % modal damping and
2 N along z at the tip for the forced response. For each H given: the backbone of mode 1 over
0.5-20 E_g, its largest frequency, where its energy ends (``branch.meta["ends_in"]``), and the
forced response's peak against it (``fm.compare_resonance``). Needs gmsh (``pip install -e
".[meshes]"``). Measured 2026-12-01 (with other jobs on the 2 cores):

    H = 5:  backbone 19 orbits, 5 s, up to 1.265 w1, ends in mode 3 (100 %, 4:1); forced 98 points,
            24 s, peak 1.288 w1 at 11.1 E_g (+6.5 % from the backbone at that energy)
    H = 10: backbone 51 orbits, 146 s, up to 1.251 w1, ends in mode 3 (100 %, 4:1); forced 166
            points, 122 s, peak 1.267 w1 at 8.3 E_g (+3.8 %)
    H = 15: backbone 14 orbits, 22 s, 1.046-1.048 w1 from 1.8 to 20 E_g, ends in mode 5 (97 %,
            14:1); forced 489 points, 1334 s, 12 folds, peak 1.447 w1 at 33 E_g

The harmonic balance does not converge in H on this model. The time domain (``--time``: a
stepped sine up from 1.00 w1 by 0.02, ``fm.steady_state`` of the same reduced model, restitution 0,
6400 steps a period, theta = 0.55, at most 400 periods each from the previous state; about 40 s a
frequency):

    w / w1      1.00  1.04  1.08  1.12  1.16  1.20  1.22  1.24  1.30  1.44
    E / E_g     1.74  2.06  2.25  2.69  3.74  3.64  4.26  0.38  0.24  0.12
    (touching the stop up to 1.22, where no period repeats to steady_state's tolerance in 400;
    periodic without contact from 1.24 on; the contacts' work negative throughout)

The structure leaves the stop between 1.22 and 1.24 w1, 3-5 % below the harmonic balance's peaks
at H = 5 and 10 (Hill's method calls the upper branch at H = 5 stable up to its fold, a verdict
that changes with 75 % of the harmonics at 18 of 22 points checked); nothing of the H = 15 branch
beyond 1.24 w1 is seen. Theta = 1/2 at 6400 steps a period gives the same energies within 11 % but
puts energy in at some frequencies (+1.5 % of the energy a period at 1.00 w1) and never settles
without contact: the reduced model's constraint modes (damping ratios 3e-6 and less: the modal damping
acts on 20 modes) ring on. At 400 steps a period it gave 8-22x the harmonic balance's energy at
0.96 w1, energy that the contact impulses put in, which ``steady_state`` now reports
(``SteadyState.contact_work``).

    python benchmarks/study_ring.py 5 10 [15]
    python benchmarks/study_ring.py --time
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import femodes as fm


def ring_mesh(path: Path) -> Path:
    """The quarter ring's gmsh mesh: physical volume ``ring``, surfaces ``root``, ``tip``, ``top``."""
    import gmsh
    R, w, h = 0.1, 0.010, 0.006
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        occ = gmsh.model.occ
        r = occ.addRectangle(R - w / 2, 0, 0, w, h)
        occ.rotate([(2, r)], 0, 0, 0, 1, 0, 0, math.pi / 2)  # into the xz plane
        occ.revolve([(2, r)], 0, 0, 0, 0, 0, 1, math.pi / 2, numElements=[24])  # 24 layers along the arc
        occ.synchronize()
        faces = [t for _, t in gmsh.model.getEntities(2)]

        def at(axis, value):
            return [t for t in faces if abs(occ.getCenterOfMass(2, t)[axis] - value) < 1e-9]

        gmsh.model.addPhysicalGroup(3, [t for _, t in gmsh.model.getEntities(3)], name="ring")
        gmsh.model.addPhysicalGroup(2, at(1, 0.0), name="root")
        gmsh.model.addPhysicalGroup(2, at(0, 0.0), name="tip")
        gmsh.model.addPhysicalGroup(2, at(2, h), name="top")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.004)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def models():
    """The ring with its stop reduced by Craig-Bampton (10 modes), free and forced; ``w1``, ``E_g``."""
    with tempfile.TemporaryDirectory() as tmp:
        mesh = fm.load_mesh(ring_mesh(Path(tmp) / "ring.msh"))
    model = fm.solid(mesh, fm.Material(E=210e9, rho=7800.0, nu=0.3), clamped="root", order=2)
    contact = model.with_contact(fm.UnilateralContact(at="tip", gap=2e-4, direction=(0, 0, 1)))
    rom = fm.craig_bampton(contact, 10)
    forced = fm.craig_bampton(contact.with_damping(modal=0.01).with_forcing(
        fm.HarmonicForce(at=("tip", "u_z"), amplitude=2.0)), 10)
    return model, rom, forced, float(fm.linear_modes(rom, 1).omega[0]), fm.grazing_energy(rom, 1)


def time_sweep(steps: int = 6400, theta: float = 0.55) -> None:
    """The stepped sine in the time domain (module docstring), with the contact impulses' net work
    a period against the orbit's largest energy (positive: energy the steps put in)."""
    _, _, forced, w1, eg = models()
    u = v = None
    print("| w / w1 | mean E / E_g | periodic | min gap [um] | contact work a period / max E |\n|---|---|---|---|---|")
    for r in np.round(np.arange(1.0, 1.45, 0.02), 2):
        w = float(r) * w1
        ss = fm.steady_state(forced, w, dt=2 * math.pi / w / steps, u0=u, v0=v, restitution=0.0,
                             options=fm.TimeSteppingOptions(n_periods_max=400, theta=theta))
        u, v = ss.u[-1], ss.v[-1]
        print(f"| {r:.2f} | {np.mean(ss.energy) / eg:.2f} | {ss.converged} | {1e6 * np.min(ss.gap):.1f} | "
              f"{ss.contact_work / ss.n_periods / np.max(ss.energy):+.1e} |", flush=True)


def main(harmonics: list[int]) -> None:
    model, rom, forced, w1, eg = models()
    print(f"{model.n_dofs} DOFs, {len(rom.contacts)} contacts, reduced to {rom.n_dofs}; w1 = {w1:.1f} rad/s")
    for H in harmonics:
        t = time.perf_counter()
        bb = fm.nonlinear_mode(rom, 1, energy=(0.5 * eg, 20 * eg), harmonics=H)
        tb = time.perf_counter() - t
        t = time.perf_counter()
        frc = fm.frequency_response(forced, (0.8 * w1, 1.5 * w1), H)
        tf = time.perf_counter() - t
        peak, = fm.compare_resonance(bb, frc)
        print(f"H = {H}: backbone {len(bb)} orbits, {tb:.1f} s, up to {np.max(bb.omega) / w1:.4f} w1; "
              f"ends in: {bb.meta.get('ends_in', 'its own mode')}")
        print(f"   forced {len(frc)} points, {tf:.1f} s, {len(frc.folds)} folds, peak {peak.omega / w1:.4f} w1 at "
              f"{peak.energy / eg:.2f} E_g: {peak.predicted}")


if __name__ == "__main__":
    if sys.argv[1:] == ["--time"]:
        time_sweep()
    else:
        main([int(a) for a in sys.argv[1:]] or [5, 10])
