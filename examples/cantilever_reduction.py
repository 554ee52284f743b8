"""Cantilever with a tip contact node: linear modes of the full FE model and its Craig-Bampton model.

Reads ``meshes/cantilever.msh`` (40 Hermite elements, named points ``clamp`` and ``tip``),
declares a unilateral stop at the tip (gap 0.01) and reduces the model keeping the tip DOF.
Computed at import (tests assert the numbers); run as a script to save a plot.
"""

from pathlib import Path

import numpy as np

import femodes as fm

HERE = Path(__file__).resolve().parent
MESH = HERE.parent / "meshes" / "cantilever.msh"

# Unit properties: w_n = (beta_n L)^2 (Blevins 1979, Table 8-1)
BETA_L = np.array([1.8751040687, 4.6940911330, 7.8547574382])

mesh = fm.load_mesh(MESH)
bare = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
error_vs_analytic = fm.linear_modes(bare, n=3).omega / BETA_L**2 - 1
# The contact declaration moves the tip mass to its neighbours (mass redistribution, on by
# default for complementarity contacts of FE models): the linear frequencies shift by O(h).
model = bare.with_contact(fm.UnilateralContact(at="tip", gap=0.01))
full = fm.linear_modes(model, n=3)
rom = fm.craig_bampton(model, n_modes=10)
reduced = fm.linear_modes(rom, n=3)
redistribution_shift = full.omega / fm.linear_modes(bare, n=3).omega - 1
error_cb = reduced.omega / full.omega - 1


def main(out: Path = Path("out")) -> Path:
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    x = model.fe.coordinates
    fig, ax = plt.subplots(figsize=(7, 4))
    for j in range(3):
        w_full = model.mesh_map.full_field(full.shapes[:, j])[model.fe.nodal[0]]
        w_rom = rom.mesh_map.full_field(reduced.shapes[:, j])[model.fe.nodal[0]]
        s = np.sign(w_full[-1]) * np.sign(w_rom[-1])
        ax.plot(x, w_full, "-", lw=2, label=f"mode {j + 1} full: {full.omega[j]:.4f} rad/s")
        ax.plot(x, s * w_rom, "k--", lw=1, label=f"mode {j + 1} CB(10): {reduced.omega[j]:.4f} rad/s")
    ax.plot([1.0], [0.0], "rs", ms=8, label="tip contact node (gap 0.01)")
    ax.set_xlabel("x")
    ax.set_ylabel("mass-normalised w")
    ax.set_title("Cantilever: full FE (40 Hermite elements) vs Craig-Bampton (tip + 10 modes)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    path = out / "cantilever_modes.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


if __name__ == "__main__":
    for j in range(3):
        print(f"mode {j + 1}: full {full.omega[j]:.8f} rad/s (bare beam analytic error {error_vs_analytic[j]:.2e}, "
              f"mass redistribution shift {redistribution_shift[j]:.2e}), "
              f"CB {reduced.omega[j]:.8f} rad/s (error {error_cb[j]:.2e})")
    print("saved", main())
