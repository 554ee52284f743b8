"""A user's own 3-D structure, end to end: gmsh mesh, model, Craig-Bampton, backbone with
stability, forced response with rtol, ParaView series, with the time of each stage.

The structure is one nobody tuned femodes for: a tapered steel plate 150 mm long, chord 50 -> 30
mm, 4 mm thick, 15 x 4 x 1 hexahedra of order 2 (27-node, 2430 DOFs once the root is clamped).
Its physical groups are ``root`` (clamped), ``tip``, ``pad`` (the top face of the last 10 mm, 27
nodes) and ``blade``. A rigid stop sits ``GAP`` = 0.3 mm above the pad (``direction=(0, 0, 1)``,
one complementarity law per pad node); the forced case has a 1 N resultant on the pad and 1 %
modal damping.

Run ``python examples/user_blade_3d.py [out_dir]``. The mesh is written by the ``gmsh`` Python
package when it is installed (``pip install "femodes[meshes]"``); otherwise the same mesh is read
from ``meshes/user_blade.msh`` (written by this script's :func:`write_mesh`; ``python
examples/user_blade_3d.py --write-meshes`` writes both committed meshes again). ``run(quick=True)``
is the small version the tests run (a coarser mesh and fewer harmonics).

Measured on the reference machine (2 cores, one BLAS thread, H = 5), wall time per stage:

=========================  ======  ==================================================
stage                      s       result
=========================  ======  ==================================================
mesh (gmsh)                0.04    60 hexahedra
model (``fm.solid``, Q2)   0.59    2430 DOFs, 27 contacts (45-60 s before the element
                                   quadrature fix)
linear modes               0.04    w1 = 1109.8 rad/s
Craig-Bampton, 10 modes    0.08    37 DOFs, w1 error 4.6e-6
backbone + stability       2.0     11 points, up to 1.149 w1; the backbone alone 0.3 s
                                   (did not return before the Hill reduction)
forced response + rtol     69      38 points; the plain curve 1.2 s; rtol = 1e-2 is
                                   not met: the estimate stops at its 60 s limit
                                   (level H = 10 in 6 s, level 20 unfinished) and says so
ParaView series            0.18    36 frames
total                      72
=========================  ======  ==================================================

The forced peak (1 % modal damping, 1 N) lies 0.03 % from the backbone at its energy (w = 1241.7 rad/s).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import femodes as fm

HERE = Path(__file__).resolve().parent
MESHES = {False: HERE.parent / "meshes" / "user_blade.msh",       # 15 x 4 x 1 (the study)
          True: HERE.parent / "meshes" / "user_blade_quick.msh"}  # 6 x 2 x 1 (the test's version)
SIZES = {False: (15, 4), True: (6, 2)}
STEEL = fm.Material(E=210e9, rho=7800.0, nu=0.3)
LENGTH, CHORD_ROOT, CHORD_TIP, THICK, PAD = 0.15, 0.05, 0.03, 0.004, 0.01   # m
GAP = 0.3e-3          # stop clearance above the pad (m)
FORCE = 1.0           # resultant on the pad (N)
ZETA = 0.01           # modal damping ratio


def write_mesh(path: Path, n_length: int = 15, n_chord: int = 4) -> Path:
    """The blade's hexahedral mesh with named groups, by the gmsh API (first order; femodes makes
    the 27-node elements with ``order=2``). ``n_length`` elements along the span, the last one
    under the pad when ``n_length = 15``."""
    import gmsh

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("user_blade")
        geo = gmsh.model.geo
        xs = LENGTH - PAD

        def half_chord(x):
            return 0.5 * (CHORD_ROOT + (CHORD_TIP - CHORD_ROOT) * x / LENGTH)

        p = [geo.addPoint(0, -half_chord(0), 0), geo.addPoint(xs, -half_chord(xs), 0),
             geo.addPoint(LENGTH, -half_chord(LENGTH), 0), geo.addPoint(LENGTH, half_chord(LENGTH), 0),
             geo.addPoint(xs, half_chord(xs), 0), geo.addPoint(0, half_chord(0), 0)]
        lines = [geo.addLine(p[0], p[1]), geo.addLine(p[1], p[4]), geo.addLine(p[4], p[5]), geo.addLine(p[5], p[0]),
                 geo.addLine(p[1], p[2]), geo.addLine(p[2], p[3]), geo.addLine(p[3], p[4])]
        blade = geo.addPlaneSurface([geo.addCurveLoop([lines[0], lines[1], lines[2], lines[3]])])
        pad = geo.addPlaneSurface([geo.addCurveLoop([lines[4], lines[5], lines[6], -lines[1]])])
        n_pad = max(1, round(n_length * PAD / LENGTH))
        for c in (lines[0], lines[2]):
            geo.mesh.setTransfiniteCurve(c, n_length - n_pad + 1)
        for c in (lines[4], lines[6]):
            geo.mesh.setTransfiniteCurve(c, n_pad + 1)
        for c in (lines[1], lines[3], lines[5]):
            geo.mesh.setTransfiniteCurve(c, n_chord + 1)
        for s in (blade, pad):
            geo.mesh.setTransfiniteSurface(s)
            geo.mesh.setRecombine(2, s)
        v1 = geo.extrude([(2, blade)], 0, 0, THICK, numElements=[1], recombine=True)[1][1]
        v2 = geo.extrude([(2, pad)], 0, 0, THICK, numElements=[1], recombine=True)[1][1]
        geo.synchronize()
        eps, h = 1e-6, CHORD_ROOT

        def faces(x0, z0, x1, z1):
            box = gmsh.model.getEntitiesInBoundingBox(x0 - eps, -h, z0 - eps, x1 + eps, h, z1 + eps, 2)
            return [tag for _, tag in box]

        gmsh.model.addPhysicalGroup(2, faces(0, 0, 0, THICK), name="root")
        gmsh.model.addPhysicalGroup(2, faces(LENGTH, 0, LENGTH, THICK), name="tip")
        gmsh.model.addPhysicalGroup(2, faces(xs, THICK, LENGTH, THICK), name="pad")
        gmsh.model.addPhysicalGroup(3, [v1, v2], name="blade")
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def with_stop(solid: fm.StructuralModel, zeta: float | None = ZETA, force: float | None = FORCE) -> fm.StructuralModel:
    """The blade's loads on its solid model: the stop ``GAP`` above every pad node, and unless None
    the resultant ``force`` on the pad and modal damping ``zeta`` (None, None: the free structure of
    a backbone)."""
    model = solid.with_contact(fm.UnilateralContact(at="pad", gap=GAP, direction=(0.0, 0.0, 1.0)))
    if force is not None:
        model = model.with_forcing(fm.HarmonicForce(at=("pad", "u_z"), amplitude=force))
    if zeta is not None:
        model = model.with_damping(modal=zeta)
    return model


class Stages:
    """Wall time of each stage, printed as it ends."""

    def __init__(self, echo: bool = True):
        self.times: dict[str, float] = {}
        self.echo = echo
        self._t = time.perf_counter()

    def done(self, name: str, what: str = "") -> None:
        t = time.perf_counter()
        self.times[name] = t - self._t
        self._t = t
        if self.echo:
            print(f"{name:28s} {self.times[name]:7.2f} s  {what}", flush=True)


def run(out: Path | str = "out/user_blade_3d", quick: bool = False, echo: bool = True) -> dict:
    """The whole study; returns the stages' times and the results (``quick``: 6 x 2 elements,
    H = 3, the test's version)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    st = Stages(echo)
    H_bb, H_frc = (3, 3) if quick else (5, 5)
    try:
        mesh_path = write_mesh(out / MESHES[quick].name, *SIZES[quick])
        made = "gmsh"
    except ImportError:
        mesh_path, made = MESHES[quick], "read (gmsh not installed)"
    mesh = fm.load_mesh(mesh_path)
    st.done("mesh", f"{made}: {mesh_path.name}")
    model = with_stop(fm.solid(mesh, STEEL, clamped="root", order=2))
    st.done("model", f"{model.n_dofs} DOFs, {len(model.contacts)} contacts")
    linear = fm.linear_modes(model, 3)
    w1 = float(linear.omega[0])
    st.done("linear modes", f"w = {np.round(linear.omega, 1)} rad/s")
    rom = fm.craig_bampton(model, 10)
    rom_w1 = float(fm.linear_modes(rom, 1).omega[0])
    st.done("Craig-Bampton", f"{rom.n_dofs} DOFs, w1 error {rom_w1 / w1 - 1:.1e}")
    e_g = fm.grazing_energy(rom, 1)
    backbone = fm.nonlinear_mode(rom, 1, energy=(0.5 * e_g, 20 * e_g), harmonics=H_bb, stability=True)
    n_unstable = int(np.count_nonzero(~np.asarray(backbone.stable)))
    st.done("backbone + stability", f"{len(backbone)} points, w/w1 up to {backbone.omega.max() / w1:.4f}, "
            f"{n_unstable} unstable, {len(backbone.bifurcations)} bifurcations")
    span = (0.9 * w1, 1.25 * w1)
    forced = fm.frequency_response(rom, span, H_frc, rtol=1e-2)
    acc = forced.accuracy
    st.done("forced response + rtol", f"{len(forced)} points, peak at w/w1 = "
            f"{forced.omega[np.argmax(forced.amplitude(0))] / w1:.4f}, rtol met at {int(acc.met.sum())} of "
            f"{len(forced)} points")
    compare = fm.compare_resonance(backbone, [forced])
    if echo:
        print(f"{'':28s}          forced peak {compare[0].distance:+.2%} from the backbone at its energy")
    series = fm.io.write_animation(backbone[len(backbone) - 1], rom, out / "user_blade_mode1", n_frames=12 if quick else 36)
    st.done("ParaView series", str(series))
    total = sum(st.times.values())
    if echo:
        print(f"{'total':28s} {total:7.2f} s")
    return {"times": st.times, "total": total, "model": model, "rom": rom, "w1": w1, "backbone": backbone,
            "forced": forced, "compare": compare, "series": series}


def main(argv=None) -> None:
    """The command line: ``[out_dir]`` or ``--write-meshes``; ``--help`` explains both."""
    import argparse

    parser = argparse.ArgumentParser(description="A user's own 3-D blade, end to end, with the time of "
                                     "each stage.")
    parser.add_argument("out_dir", nargs="?", default="out/user_blade_3d",
                        help="folder for the ParaView series (default: out/user_blade_3d)")
    parser.add_argument("--write-meshes", action="store_true",
                        help="write meshes/user_blade.msh and meshes/user_blade_quick.msh with gmsh")
    args = parser.parse_args(argv)
    if args.write_meshes:
        for q, path in MESHES.items():
            print(write_mesh(path, *SIZES[q]))
    else:
        run(args.out_dir)


if __name__ == "__main__":
    main()
