"""Application layer: ``femodes demo``, the flagship demonstration.

A cantilever (``meshes/cantilever.msh``) with a tip stop: linear modes, Craig-Bampton reduction,
the nonlinear mode 1 (backbone) and a forced response by harmonic balance; plots, branches,
a ParaView series and a rendered animation in one folder.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

def _find_mesh(name: str) -> Path | None:
    here = Path(__file__).resolve()
    for base in (Path.cwd(), *here.parents):
        p = base / "meshes" / name
        if p.is_file():
            return p
    return None


def run_demo(out: Path) -> dict:
    """The demo: cantilever, tip contact node, linear modes, Craig-Bampton; returns a summary."""
    import femodes as fm

    out.mkdir(parents=True, exist_ok=True)
    path = _find_mesh("cantilever.msh")
    if path is not None:
        mesh = fm.load_mesh(path)
        source = str(path)
    else:  # installed without the repository's meshes/: the same mesh built in code
        mesh = fm.line_mesh(1.0, 40, boundaries={"clamp": 0.0, "tip": 1.0})
        source = "line_mesh(1.0, 40)"
    bare = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    bare_omega = fm.linear_modes(bare, n=4).omega
    model = bare.with_contact(fm.UnilateralContact(at="tip", gap=0.01))  # tip mass redistributed
    full = fm.linear_modes(model, n=4)
    rom = fm.craig_bampton(model, n_modes=10)
    red = fm.linear_modes(rom, n=4)
    exact = np.array([1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349]) ** 2

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = model.fe.coordinates
    fig, ax = plt.subplots(figsize=(7, 4))
    for j in range(3):
        wf = model.full_field(full.shapes[:, j])[model.fe.nodal[0]]
        wr = rom.full_field(red.shapes[:, j])[model.fe.nodal[0]]
        ax.plot(x, wf, lw=2, label=f"mode {j + 1}: {full.omega[j]:.4f} rad/s (full)")
        ax.plot(x, np.sign(wf[-1] * wr[-1]) * wr, "k--", lw=1, label=f"CB: {red.omega[j]:.4f} rad/s")
    ax.plot([1.0], [0.0], "rs", label="tip contact node")
    ax.set_xlabel("x")
    ax.set_ylabel("mass-normalised deflection")
    ax.set_title("femodes demo: cantilever modes, full FE vs Craig-Bampton")
    ax.legend(fontsize=7)
    fig.tight_layout()
    png = out / "cantilever_modes.png"
    fig.savefig(png, dpi=120)
    plt.close(fig)
    lines = [
        f"mesh: {source} ({mesh.t.shape[1]} elements), model: {model.n_dofs} DOFs, reduced: {rom.n_dofs} DOFs",
        "mode  beam w [rad/s]   analytic err   with contact node w   CB w [rad/s]   CB err",
    ]
    for j in range(4):
        lines.append(
            f"{j + 1:4d}  {bare_omega[j]:14.8f}   {bare_omega[j] / exact[j] - 1:12.2e}   {full.omega[j]:19.8f}   "
            f"{red.omega[j]:12.8f}   {red.omega[j] / full.omega[j] - 1:8.2e}"
        )
    # Nonlinear: backbone of mode 1 of the reduced model (H = 10) and a forced response.
    gap = 0.01
    e_graze = (gap / full.shapes[model.dof("tip"), 0]) ** 2 * full.omega[0] ** 2 / 2
    H = fm.Harmonics(10)
    backbone = fm.nonlinear_mode(rom, 1, energy=(0.5 * e_graze, 20 * e_graze), harmonics=H)
    forced_rom = fm.craig_bampton(model.with_damping(alpha=0.02).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)), 10)
    forced = fm.frequency_response(forced_rom, (3.0, 4.2), H)
    backbone.save(out / "backbone.npz")
    forced.save(out / "forced.npz")
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(backbone.omega, backbone.energy, lw=2, label="backbone, mode 1 (CB, H = 10)")
    ax.plot(forced.omega, forced.energy, lw=1, label="forced response, tip force 0.004")
    ax.axhline(e_graze, color="grey", ls="-.", lw=0.8, label="grazing energy")
    ax.set_yscale("log")
    ax.set_xlabel("w [rad/s]")
    ax.set_ylabel("energy")
    ax.set_title("femodes demo: cantilever with a tip stop (gap 0.01)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    png2 = out / "frequency_energy.png"
    fig.savefig(png2, dpi=120)
    plt.close(fig)
    lines.append(
        f"backbone: {len(backbone)} points, w from {backbone.omega[0]:.5f} to {backbone.omega.max():.5f} rad/s, "
        f"max |xi| {abs(backbone.xi).max():.1e}; forced: {len(forced)} points, folds at w = "
        f"{', '.join(f'{w:.4f}' for w in forced.omega[list(forced.folds)])}, max penetration {forced.penetration.max():.1e}"
    )
    # Animations of the highest-energy backbone orbit: ParaView series and a rendered GIF.
    sol = backbone[len(backbone) - 1]
    pvd = fm.io.write_animation(sol, rom, out / "mode1", n_frames=24)
    lines.append(f"ParaView time series: {pvd.name} (+ {pvd.stem}_*.vtu), one period of the nonlinear mode at w = {sol.omega:.5f}")
    gif = None
    try:
        gif = fm.viz.animate(sol, rom, out / "mode1.gif", n_frames=24)
        lines.append(f"rendered animation: {gif.name}")
    except (ImportError, RuntimeError) as exc:  # optional rendering stack (pyvista + EGL)
        lines.append(f"rendered animation skipped: {exc}")
    (out / "summary.txt").write_text("\n".join(lines) + "\n")
    files = [png, png2, pvd, *([gif] if gif is not None else []), out / "summary.txt", out / "backbone.npz",
             out / "forced.npz"]
    return {"lines": lines, "plot": png, "out": out, "files": files}
