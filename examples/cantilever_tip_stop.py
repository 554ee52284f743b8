"""Cantilever with a tip stop: nonlinear mode 1 of the full FE model and of Craig-Bampton models.

``meshes/cantilever.msh`` (40 Hermite elements, unit properties), rigid stop at the tip with gap
0.01 (complementarity contact, tip mass redistributed). Backbones with H = 10 for the full model
(80 DOFs) and for Craig-Bampton models keeping the tip DOF with 4 and 10 fixed-interface modes;
then a forced response of the reduced model near the first resonance (tip force, Rayleigh
damping). Reduced and full backbones agree to the Craig-Bampton error of the linear modes.
"""

from pathlib import Path

import numpy as np

import femodes as fm

HERE = Path(__file__).resolve().parent
GAP = 0.01
H = fm.Harmonics(10)

mesh = fm.load_mesh(HERE.parent / "meshes" / "cantilever.msh")
beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
model = beam.with_contact(fm.UnilateralContact(at="tip", gap=GAP))
linear = fm.linear_modes(model, 1)
# grazing energy of linear mode 1: tip amplitude a*phi_tip = gap, E = a^2 w^2 / 2
E_GRAZE = (GAP / linear.shapes[model.dof("tip"), 0]) ** 2 * linear.omega[0] ** 2 / 2
ENERGIES = np.array([2.0, 5.0, 10.0]) * E_GRAZE
OPTIONS = fm.ContinuationOptions(step=0.05, max_step=0.1, newton=fm.NewtonOptions(atol=1e-9, max_iter=20))

MODELS = {"full": model, "CB 10 modes": fm.craig_bampton(model, 10), "CB 4 modes": fm.craig_bampton(model, 4)}
backbones = {name: fm.nonlinear_mode(m, 1, energy=(0.5 * E_GRAZE, 20 * E_GRAZE), harmonics=H, options=OPTIONS)
             for name, m in MODELS.items()}
# Frequencies at exactly the same energies: the continuation ends exactly on p_span[1], so each
# value is a converged solution at that energy (no interpolation between branch points).
omega_at = {name: np.array([fm.nonlinear_mode(m, 1, energy=(0.5 * E_GRAZE, E), harmonics=H, options=OPTIONS).omega[-1]
                            for E in ENERGIES]) for name, m in MODELS.items()}

rom = fm.craig_bampton(model.with_damping(alpha=0.02).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)), 10)
forced = fm.frequency_response(rom, (3.0, 4.2), H)


def main(out="out"):
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for (name, b), style in zip(backbones.items(), ("-", "--", ":")):
        ax1.plot(b.omega, b.energy, style, lw=2, label=f"{name} ({b.model.n_dofs} DOFs)")
    ax1.plot(forced.omega, forced.energy, "C3-", lw=1, label="forced (CB 10), tip force 0.004")
    ax1.axhline(E_GRAZE, color="grey", lw=0.8, ls="-.", label="grazing energy")
    ax1.set_yscale("log")
    ax1.set_xlabel("w [rad/s]")
    ax1.set_ylabel("energy")
    ax1.set_title("cantilever with tip stop: mode 1 backbone")
    ax1.legend(fontsize=8)
    tip = rom.dof("tip")
    a = forced.amplitude(tip)
    ax2.plot(forced.omega, a, "C3-")
    ax2.plot(forced.omega[list(forced.folds)], a[list(forced.folds)], "kx", label="folds")
    ax2.axhline(GAP, color="grey", lw=0.8, ls="-.", label="gap")
    ax2.set_xlabel("w [rad/s]")
    ax2.set_ylabel("max |tip deflection|")
    ax2.set_title("forced response of the reduced model")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    path = out / "cantilever_tip_stop.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    # ParaView time series of the last backbone point of the full model (open the .pvd, apply
    # "Warp By Vector" on "displacement"), expanded for the reduced model in the same way.
    fm.io.write_animation(backbones["full"][len(backbones["full"]) - 1], model, out / "cantilever_mode1_full", n_frames=36)
    fm.io.write_animation(backbones["CB 10 modes"][len(backbones["CB 10 modes"]) - 1], MODELS["CB 10 modes"],
                          out / "cantilever_mode1_cb10", n_frames=36)
    return path


if __name__ == "__main__":
    for k, w in omega_at.items():
        print(f"{k:12s}: w at E/E_g = 2, 5, 10 -> {np.round(w, 6)}, max |xi| = {np.abs(backbones[k].xi).max():.1e}")
    print(f"forced response: {len(forced)} points, folds at {np.round(forced.omega[list(forced.folds)], 4)}, "
          f"max penetration {forced.penetration.max():.2e}")
    print("saved", main())
