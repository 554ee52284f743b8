"""A 2D blade whose tip rubs a curved casing: nonlinear mode 1, forced response and its stability.

A steel blade (length 1 m, chord 80 mm, plane stress, 10 mm thick) is clamped at its root; x is
radial, y circumferential. Its tip edge faces a rigid casing of radius ``R_C = R_HUB + L + G0``
about the rotor axis at ``x = -R_HUB``: the radial clearance is ``G0 = 1`` mm at mid-chord and
``sqrt(R_C^2 - y^2) - R_HUB - L`` at chord offset ``y`` (0.47 mm at the corners). Contact is
along +x (the casing normal within 1.5 degrees at the corners), one complementarity law per tip
node. In first bending the tip section rotates by ``theta`` and its corners move radially by
``-/+ y theta``: once the corner clearance is used up the corners strike the casing alternately,
twice per period, which blocks the rotation of the tip and stiffens the blade.

Computed at import (tests/test_examples_solids.py asserts the numbers):

1. the linear modes of the full model (Q2 quadrilaterals, 25 x 2, 500 DOFs);
2. a Craig-Bampton model keeping the 5 contact DOFs and the forced DOF (6 fixed-interface
   modes), on which everything nonlinear runs, and the backbone (H = 7) of mode 1 from half to
   20 times the grazing energy, on the reduced model and, as a check, on the full model;
3. the forced response to a tip force (modal damping ratio 0.5 % on mode 1) through the resonance
   and its folds, with the stability of every point by Hill's method.

Why not ``meshes/blade2d.msh``: its taper puts the second bending mode at 4.97 times the first,
so the fifth harmonic of mode 1 is in 1:5 internal resonance with mode 2 right at the linear
frequency. With H >= 5 the mode-1 backbone of that blade is entangled with mode 2 from grazing on
(measured at H = 7: the energy falls to 0.94 of the grazing energy while the frequency rises,
then the branch turns back to the linear mode at 3.1 times it); at H = 4 it is a clean
stiffening curve. A straight blade (ratio 6.1) keeps this example about mode 1.
"""

from pathlib import Path

import numpy as np

import femodes as fm

# geometry (m), material (SI), casing
L, CHORD, THICKNESS = 1.0, 0.08, 0.01
NX, NY = 25, 2                      # Q2 quadrilaterals: no shear locking at 2 elements across
R_HUB, G0 = 0.5, 1e-3               # hub radius, tip clearance at mid-chord
R_C = R_HUB + L + G0                # casing radius
STEEL = fm.Material(E=210e9, rho=7800.0, nu=0.3)
H = fm.Harmonics(7)
N_MODES = 6                         # fixed-interface modes of the Craig-Bampton model
ZETA = 0.005                        # modal damping ratio of mode 1 (stiffness-proportional)
FORCE = 50.0                        # tip force amplitude (N)


def casing_gap(x):
    """Radial clearance between a tip node at ``x = (x, y)`` and the casing circle."""
    return np.sqrt(R_C**2 - x[1] ** 2) - R_HUB - x[0]


mesh = fm.rectangle_mesh(L, CHORD, NX, NY, quadrilaterals=True).translated([0.0, -CHORD / 2])
bare = fm.solid(mesh, STEEL, clamped="left", order=2, plane="stress", thickness=THICKNESS,
                points={"tip_mid": (L, 0.0)})
model = bare.with_contact(fm.UnilateralContact(at="right", gap=casing_gap, direction=(1.0, 0.0)))
linear = fm.linear_modes(model, 3)
W1 = float(linear.omega[0])
CONTACT_DOFS = [a.dof for a in model.contacts]
gaps = np.array([a.item.gap for a in model.contacts])
# grazing energy of linear mode 1 (mass-normalised shape): the corner reaches the casing when the
# modal amplitude is a = min(g_k / |phi_k|), and E = a^2 w^2 / 2
E_GRAZE = float(np.min(gaps / np.abs(linear.shapes[CONTACT_DOFS, 0])) ** 2 * W1**2 / 2)

# -- backbone: reduced model, and the full model as a check ----------------------------------------
ENERGY = (0.5 * E_GRAZE, 20.0 * E_GRAZE)
NNM_OPTIONS = fm.ContinuationOptions(step=0.05, max_step=0.1, newton=fm.NewtonOptions(atol=1e-9, max_iter=20))
rom = fm.craig_bampton(model, N_MODES)
reduced_linear = fm.linear_modes(rom, 3)
backbone = fm.nonlinear_mode(rom, 1, energy=ENERGY, harmonics=H, options=NNM_OPTIONS)
backbone_full = fm.nonlinear_mode(model, 1, energy=ENERGY, harmonics=H, options=NNM_OPTIONS)

# -- forced response ---------------------------------------------------------------------------------
forced_model = (model.with_damping(beta=2 * ZETA / W1)
                .with_forcing(fm.HarmonicForce(at=("tip_mid", "u_y"), amplitude=FORCE)))
forced_rom = fm.craig_bampton(forced_model, N_MODES)
SPAN = (0.95 * W1, 1.2 * W1)


# Hill's method (what "auto" chooses here too: the reduced model's fastest natural frequency is
# 3764 w1, and one shooting of the stiff orbit takes ~3 minutes against 0.14 s for Hill)
forced = fm.frequency_response(forced_rom, SPAN, H, stability=fm.stability_methods.Hill())
TIP = forced_rom.dof(("tip_mid", "u_y"))
folds = np.array(forced.folds)
peak = int(np.argmax(forced.energy))
# the backbone's frequency at the energy of the forced peak (log-energy interpolation)
order = np.argsort(backbone.energy)
omega_backbone_at_peak = float(np.interp(np.log(forced.energy[peak]), np.log(backbone.energy[order]),
                                         backbone.omega[order]))
E_RATIOS = np.array([1.0, 2.0, 5.0, 20.0])
backbone_ratio = np.interp(np.log(E_RATIOS * E_GRAZE), np.log(backbone.energy[order]), backbone.omega[order]) / W1


def main(out="out"):
    """Save the figures into ``out``: blade_casing.png (backbone and forced response, returned),
    blade_casing_pressure.png (tip pressure over a period) and blade_casing.gif (the peak orbit)."""
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11.5, 4.4))
    ax1.plot(backbone.omega, backbone.energy, "C0-", lw=2.5, label=f"backbone, Craig-Bampton ({rom.n_dofs} DOFs)")
    ax1.plot(backbone_full.omega, backbone_full.energy, "k--", lw=1,
             label=f"backbone, full model ({model.n_dofs} DOFs)")
    e = np.where(forced.stable, forced.energy, np.nan)
    ax1.plot(forced.omega, e, "C3-", lw=1.2, label=f"forced, tip force {FORCE:g} N: stable")
    ax1.plot(forced.omega, np.where(~forced.stable, forced.energy, np.nan), "C1--", lw=1.5, label="forced: unstable")
    ax1.axvline(W1, color="grey", lw=0.8, label=f"linear w1 = {W1:.2f} rad/s")
    ax1.axhline(E_GRAZE, color="grey", lw=0.8, ls="-.", label=f"grazing energy {E_GRAZE:.2f} J")
    ax1.set_yscale("log")
    ax1.set_xlim(0.98 * W1, 1.2 * W1)
    ax1.set_ylim(0.1 * E_GRAZE, 25 * E_GRAZE)
    ax1.set_xlabel("w [rad/s]")
    ax1.set_ylabel("energy [J]")
    ax1.set_title(f"blade tip against the casing: mode 1 (H = {H.n_harmonics})")
    ax1.legend(fontsize=7.5, loc="lower right")

    a = forced.amplitude(TIP) * 1e3
    ax2.plot(forced.omega, np.where(forced.stable, a, np.nan), "C3-", lw=1.5, label="stable")
    ax2.plot(forced.omega, np.where(~forced.stable, a, np.nan), "C1--", lw=1.5, label="unstable (Hill's method)")
    ax2.plot(forced.omega[folds], a[folds], "kx", ms=8, label="folds")
    sol = forced[peak]
    ax2.plot(sol.omega, a[peak], "o", mfc="none", color="C2", label="animated orbit")
    graze = np.min(gaps / np.abs(linear.shapes[CONTACT_DOFS, 0])) * abs(linear.shapes[model.dof(("tip_mid", "u_y")), 0])
    ax2.axhline(graze * 1e3, color="grey", lw=0.8, ls="-.", label="tip deflection at grazing (mode 1)")
    ax2.set_xlabel("w [rad/s]")
    ax2.set_ylabel("max |tip deflection u_y| [mm]")
    ax2.set_title(f"forced response, damping {100 * ZETA:g} % (Craig-Bampton)")
    ax2.legend(fontsize=7.5, loc="upper left")
    fig.tight_layout()
    path = out / "blade_casing.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)

    fig = fm.plot.contact_pressure(sol, forced_rom, boundary="right", n_frames=160)
    fig.axes[0].set_title(f"pressure of the tip on the casing at the forced peak, w = {sol.omega:.2f} rad/s",
                          fontsize=10)
    fig.axes[0].set_xlabel("s: position along the tip edge, from the corner y = -40 mm [m]")
    fig.axes[1].set_xlabel("total force [N]")
    fig.axes[2].set_ylabel("contact pressure [Pa]")
    fig.savefig(out / "blade_casing_pressure.png", dpi=110)
    plt.close(fig)
    style = fm.viz.AnimationStyle(unit="m", title="blade tip against the casing, forced peak (Craig-Bampton, expanded)")
    fm.viz.animate(sol, forced_rom, out / "blade_casing.gif", n_frames=24, style=style)
    return path


def write_paraview(out="out"):
    """One period of the peak orbit as a ParaView series (open the .pvd; displacement, contact
    force and pressure as point data), expanded from the reduced model to the mesh."""
    return fm.io.write_animation(forced[peak], forced_rom, Path(out) / "blade_casing_peak", n_frames=36)


if __name__ == "__main__":
    print(f"linear: w = {np.round(linear.omega, 3)} rad/s, Craig-Bampton ({rom.n_dofs} DOFs) error "
          f"{reduced_linear.omega / linear.omega - 1}")
    print(f"grazing energy {E_GRAZE:.4f} J; backbone w/w1 at E/E_g = {E_RATIOS}: {np.round(backbone_ratio, 5)}")
    print(f"backbone at 20 E_g: reduced {backbone.omega[-1]:.6f}, full {backbone_full.omega[-1]:.6f} rad/s; "
          f"max |xi| {np.abs(backbone.xi).max():.1e}; max penetration {backbone.penetration.max() * 1e3:.4f} mm")
    print(f"forced: {len(forced)} points, folds at w = {np.round(forced.omega[folds], 3)} rad/s, peak at "
          f"{forced.omega[peak]:.3f} rad/s (backbone at that energy {omega_backbone_at_peak:.3f}); "
          f"unstable points {np.flatnonzero(~forced.stable)}; bifurcations {forced.bifurcations}")
    print("saved", main(), write_paraview())
