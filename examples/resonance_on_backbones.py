"""Does the backbone predict the forced resonance? Forced peaks at decreasing damping against the
nonlinear mode of the free structure, on four structures with a stop.

For each structure: the backbone of mode 1 (``fm.nonlinear_mode``, default past grazing), then
forced responses with the same force and damping halved twice, and
:func:`femodes.compare_resonance`: the distance, in frequency at equal energy, between each
forced peak and the backbone. As damping falls, the peak climbs in energy along the backbone.
Where a tongue of internal resonance that the backbone steps over catches the peaks (the 2-D
blade), the tongue's own branch (:func:`femodes.tongue_branch`) is traced and the peaks are
measured against it too.

- ``bar``: clamped P1 bar, E = rho = A = L = 1, 20 elements, stop 0.01 at the tip, stiffness
  proportional damping (``beta``), tip force 0.004, H = 10 (its backbone is the period-driven
  contact-phase family, `examples/bar_contact_refinement.py`);
- ``beam``: the Euler-Bernoulli cantilever of `meshes/cantilever.msh` (40 Hermite elements) with a
  tip stop 0.01, Craig-Bampton with 10 modes, mass-proportional damping (``alpha``), tip force
  0.004, H = 10 (its backbone rides the 6:1 internal resonance with mode 2 above ~2 grazing
  energies, and so does the forced response);
- ``blade2d``: a 2-D steel blade (plane stress, 0.5 m x 40 mm x 10 mm, 12 x 2 Q2 elements) whose
  tip edge meets a straight stop 0.5 mm away, Craig-Bampton with 6 modes, modal damping, force at
  the tip corner, H = 7;
- ``blade3d``: the user's tapered plate of `examples/user_blade_3d.py` (Q2 hexahedra, 27 pad
  contacts), Craig-Bampton with 10 modes, modal damping, 1 N on the pad, H = 5.

``python examples/resonance_on_backbones.py`` prints the table; ``run(name, quick=True)`` is the
test's version (two damping levels).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import femodes as fm

HERE = Path(__file__).resolve().parent


def _bar():
    mesh = fm.line_mesh(1.0, 20, boundaries={"clamp": 0.0, "tip": 1.0})
    bare = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    model = bare.with_contact(fm.UnilateralContact(at="tip", gap=0.01))

    def forced(d):
        return model.with_damping(beta=d).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004))

    w1 = float(fm.linear_modes(model, 1).omega[0])
    return dict(free=model, forced=forced, damping=0.02, H=10, span=(0.95 * w1, 1.45 * w1), energy=(0.5, 25.0))


def _beam():
    mesh = fm.load_mesh(HERE.parent / "meshes" / "cantilever.msh")
    bare = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = bare.with_contact(fm.UnilateralContact(at="tip", gap=0.01))

    def forced(d):
        return fm.craig_bampton(model.with_damping(alpha=d).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)),
                                10)

    w1 = float(fm.linear_modes(model, 1).omega[0])
    return dict(free=fm.craig_bampton(model, 10), forced=forced, damping=0.02, H=10, span=(0.9 * w1, 1.2 * w1),
                energy=(0.5, 40.0))


def _blade2d():
    mesh = fm.rectangle_mesh(0.5, 0.04, 12, 2, quadrilaterals=True).translated([0.0, -0.02])
    bare = fm.solid(mesh, fm.Material(E=210e9, rho=7800.0, nu=0.3), clamped="left", order=2, plane="stress",
                    thickness=0.01, points={"corner": (0.5, 0.02)})
    model = bare.with_contact(fm.UnilateralContact(at="right", gap=0.5e-3, direction=(0.0, 1.0)))

    def forced(d):
        return fm.craig_bampton(model.with_damping(modal=d).with_forcing(fm.HarmonicForce(at=("corner", "u_y"),
                                                                                            amplitude=20.0)), 6)

    w1 = float(fm.linear_modes(model, 1).omega[0])
    return dict(free=fm.craig_bampton(model, 6), forced=forced, damping=0.01, H=7, span=(0.9 * w1, 1.3 * w1),
                energy=(0.5, 20.0))


def _blade3d():
    sys.path.insert(0, str(HERE))
    import user_blade_3d as ub

    solid = fm.solid(fm.load_mesh(ub.MESHES[False]), ub.STEEL, clamped="root", order=2)
    model = ub.with_stop(solid, zeta=None, force=None)

    def forced(d):
        return fm.craig_bampton(ub.with_stop(solid, zeta=d), 10)

    w1 = float(fm.linear_modes(model, 1).omega[0])
    return dict(free=fm.craig_bampton(model, 10), forced=forced, damping=0.01, H=5, span=(0.9 * w1, 1.25 * w1),
                energy=(0.5, 20.0))


STRUCTURES = {"bar": _bar, "beam": _beam, "blade2d": _blade2d, "blade3d": _blade3d}


def run(name: str, quick: bool = False, echo: bool = True) -> dict:
    """Backbone, forced responses at ``damping * (1, 1/2[, 1/4])`` and their peaks' distances."""
    t0 = time.perf_counter()
    s = STRUCTURES[name]()
    free = s["free"]
    e_g = fm.grazing_energy(free, 1)
    backbone = fm.nonlinear_mode(free, 1, energy=(s["energy"][0] * e_g, s["energy"][1] * e_g), harmonics=s["H"])
    levels = s["damping"] * np.array([1.0, 0.5] if quick else [1.0, 0.5, 0.25])
    opts = fm.ContinuationOptions(max_points=2000)
    forced = [fm.frequency_response(s["forced"](d), s["span"], s["H"], options=opts) for d in levels]
    peaks = fm.compare_resonance(backbone, forced)
    # a peak that a tongue of internal resonance caught: the tongue's own branch, and the peaks
    # measured against it too
    held = sorted({p.tongue for p in peaks if p.tongue is not None and p.captured_by is not None})
    tongues = [fm.tongue_branch(backbone, k) for k in held]
    if tongues:
        peaks = fm.compare_resonance(backbone, forced, tongues=tongues)
    out = {"name": name, "backbone": backbone, "forced": forced, "peaks": peaks, "damping": levels, "tongues": tongues,
           "grazing_energy": e_g, "family": backbone.meta.get("family"), "seconds": time.perf_counter() - t0}
    if echo:
        for d, p in zip(levels, peaks):
            print(f"{name:8s} damping {d:8.4g}  peak w = {p.omega:10.5g}  E/E_g = {p.energy / e_g:6.2f}  "
                  f"backbone w = {p.omega_backbone:10.5g}  {p.predicted}")
    return out


if __name__ == "__main__":
    for key in STRUCTURES:
        r = run(key)
        print(f"{key}: backbone family {r['family']!r}, {r['seconds']:.0f} s")
