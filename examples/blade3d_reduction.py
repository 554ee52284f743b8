"""The 3D blade with a tip stop, reduced by Craig-Bampton: linear modes, nonlinear mode 1, a full check.

``meshes/blade3d.msh``: a steel plate blade 1 m x 0.2 m x 30 mm (length x, chord y, thickness z;
574 tetrahedra, one through the thickness) clamped at its root, with quadratic tetrahedra
(``order=2``, 3690 DOFs: the P1 mesh locks, its first frequency is 2.4 times too high). Every node
of the tip face is stopped in the flapwise direction +z at ``G0 = 2`` mm (a tip patch against a
rigid stop: one complementarity law per node, 43 contacts).

Computed at import (tests/test_examples_solids.py asserts the numbers):

1. linear frequencies of the full model and of a Craig-Bampton model keeping the 43 contact DOFs
   and 10 fixed-interface modes (53 DOFs);
2. the backbone of mode 1 (first flap bending) on the reduced model, H = 7, from half to 20 times
   the grazing energy, against the same backbone of an Euler-Bernoulli cantilever (40 Hermite
   elements, same E, rho, A, I) with a stop at its tip. Normalised by the linear frequency and the
   grazing energy, the two backbones agree within 0.5 %: above ~2 grazing energies both run along
   w2 / 6 (6:1 internal resonance with the second flap mode), so they differ by about the
   difference of their w2 / w1 (-0.41 %; the backbones at 5 and 10 grazing energies: -0.43 %);
3. the last point of the reduced backbone checked on the full model: the expanded reduced
   solution is corrected by semismooth Newton on the full 3690-DOF harmonic balance at the same
   energy.
"""

from pathlib import Path

import numpy as np

import femodes as fm

HERE = Path(__file__).resolve().parent
LENGTH, CHORD, THICK = 1.0, 0.2, 0.03   # the box of meshes/make_meshes.py (m)
STEEL = fm.Material(E=210e9, rho=7800.0, nu=0.3)
G0 = 2e-3                               # stop clearance of the tip face (m)
H = fm.Harmonics(7)
N_MODES = 10
E_RATIOS = np.array([2.0, 5.0, 10.0])   # energies (in grazing energies) where the backbones are compared

mesh = fm.load_mesh(HERE.parent / "meshes" / "blade3d.msh")
bare = fm.solid(mesh, STEEL, clamped="root", order=2)
model = bare.with_contact(fm.UnilateralContact(at="tip", gap=G0, direction=(0.0, 0.0, 1.0)))
rom = fm.craig_bampton(model, N_MODES)
full_linear = fm.linear_modes(model, 4)
reduced_linear = fm.linear_modes(rom, 4)
cb_error = reduced_linear.omega / full_linear.omega - 1
W1 = float(full_linear.omega[0])
# Euler-Bernoulli flap bending: w1 = 1.87510^2 sqrt(E I / (rho A L^4)), I = b h^3 / 12; a plate
# strip bends between the beam (free anticlastic curvature) and cylindrical bending (1/(1 - nu^2)
# stiffer): w1 lies in [1, 1/sqrt(1 - nu^2)] times the beam value
W1_BEAM = 1.8751040687**2 * np.sqrt(STEEL.E * THICK**2 / 12 / STEEL.rho) / LENGTH**2


def grazing_energy(m):
    """Energy of linear mode 1 whose largest contact displacement equals its gap (E = a^2 w^2 / 2)."""
    modes = fm.linear_modes(m, 1)
    dofs = [a.dof for a in m.contacts]
    gaps = np.array([a.item.gap for a in m.contacts])
    return float(np.min(gaps / np.abs(modes.shapes[dofs, 0])) ** 2 * modes.omega[0] ** 2 / 2)


OPTIONS = fm.ContinuationOptions(step=0.05, max_step=0.1, newton=fm.NewtonOptions(atol=1e-9, max_iter=20))
E_GRAZE = grazing_energy(rom)
backbone = fm.nonlinear_mode(rom, 1, energy=(0.5 * E_GRAZE, 20 * E_GRAZE), harmonics=H, options=OPTIONS)

# the Euler-Bernoulli beam with a tip stop, same H
beam = fm.beam(fm.line_mesh(LENGTH, 40, boundaries={"root": 0.0, "tip": LENGTH}),
               fm.Material(E=STEEL.E, rho=STEEL.rho), fm.Section(area=CHORD * THICK, inertia=CHORD * THICK**3 / 12),
               clamped="root").with_contact(fm.UnilateralContact(at="tip", gap=G0))
E_GRAZE_BEAM = grazing_energy(beam)
W1_BEAM_FE, W2_BEAM_FE = fm.linear_modes(beam, 2).omega
beam_backbone = fm.nonlinear_mode(beam, 1, energy=(0.5 * E_GRAZE_BEAM, 20 * E_GRAZE_BEAM), harmonics=H,
                                  options=OPTIONS)


def normalised_frequency(branch, e_graze, w_lin, ratios):
    """``w / w_lin`` at ``E = ratios * e_graze`` (interpolated in log E along the branch)."""
    order = np.argsort(branch.energy)
    return np.interp(np.log(ratios * e_graze), np.log(branch.energy[order]), branch.omega[order]) / w_lin


blade_ratio = normalised_frequency(backbone, E_GRAZE, W1, E_RATIOS)
beam_ratio = normalised_frequency(beam_backbone, E_GRAZE_BEAM, W1_BEAM_FE, E_RATIOS)

# -- one point on the full model ------------------------------------------------------------------
# The reduced backbone ends exactly at 20 grazing energies (the continuation stops on the end of
# its span); that orbit, expanded to the 3690 DOFs, starts semismooth Newton on the full model's
# harmonic balance at the same energy (the unknowns by name: pack/unpack, never by slicing).
reduced_point = backbone[len(backbone) - 1]
full_problem = fm.NonlinearModeProblem(model, H, 1, reference_energy=reduced_point.energy)
start = full_problem.pack(rom.expand(backbone.Q[-1]), backbone.P[-1], backbone.omega[-1], backbone.xi[-1])
log_energy = float(backbone.parameter[-1])
full_check = fm.semismooth_newton(lambda x: full_problem.residual(x, log_energy)[:2], start,
                                  options=fm.NewtonOptions(atol=1e-9, max_iter=20))
full_point = full_problem.unpack(full_check.x, log_energy)
check_error = full_point.omega / reduced_point.omega - 1


def animated_point():
    """The backbone orbit nearest 2 grazing energies, near the top of the backbone (at 20 the 6:1
    internal resonance has put so much of mode 2 into the orbit that it no longer looks like mode 1)."""
    return backbone[int(np.argmin(np.abs(np.log(backbone.energy / (2 * E_GRAZE)))))]


def main(out="out"):
    """Save the figures into ``out``: blade3d_reduction.png (linear modes and backbones, returned),
    blade3d_pressure.png (tip-face pressure over a period) and blade3d_mode1.gif (a contacting orbit)."""
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11.5, 4.4))
    n = np.arange(1, full_linear.omega.size + 1)
    ax1.plot(n, full_linear.omega / (2 * np.pi), "o", ms=9, mfc="none", label=f"full P2 model ({model.n_dofs} DOFs)")
    ax1.plot(n, reduced_linear.omega / (2 * np.pi), "k+", ms=9, label=f"Craig-Bampton ({rom.n_dofs} DOFs)")
    for j in range(n.size):
        f_j = full_linear.omega[j] / (2 * np.pi)
        ax1.annotate(f"{f_j:.2f} Hz\nCB error {cb_error[j]:.1e}", (n[j], f_j), textcoords="offset points",
                     xytext=(8, -12), fontsize=7.5)
    ax1.axhline(W1_BEAM / (2 * np.pi), color="grey", lw=0.8, ls="-.", label="Euler-Bernoulli flap mode 1")
    ax1.set_xticks(n)
    ax1.set_xlim(0.5, n.size + 0.9)
    ax1.set_xlabel("mode")
    ax1.set_ylabel("linear frequency [Hz]")
    ax1.set_title("3D blade with tip contacts: linear modes")
    ax1.legend(fontsize=7.5, loc="upper left")

    ax2.plot(backbone.omega / W1, backbone.energy / E_GRAZE, "C0-", lw=2.5,
             label=f"3D blade, Craig-Bampton (w1 = {W1:.2f} rad/s)")
    ax2.plot(beam_backbone.omega / W1_BEAM_FE, beam_backbone.energy / E_GRAZE_BEAM, "k--", lw=1,
             label=f"Euler-Bernoulli beam, tip stop (w1 = {W1_BEAM_FE:.2f} rad/s)")
    ax2.plot(full_point.omega / W1, reduced_point.energy / E_GRAZE, "C3s", mfc="none", ms=9,
             label=f"full model ({model.n_dofs} DOFs), one point")
    ax2.axvline(1.0, color="grey", lw=0.8, label="linear frequency")
    ax2.axvline(full_linear.omega[1] / 6 / W1, color="C0", lw=0.8, ls=":",
                label="w2 / 6, blade (6:1 internal resonance)")
    ax2.axvline(W2_BEAM_FE / 6 / W1_BEAM_FE, color="k", lw=0.8, ls=":", label="w2 / 6, beam")
    ax2.axhline(1.0, color="grey", lw=0.8, ls="-.", label="grazing energy")
    ax2.set_yscale("log")
    ax2.set_xlabel("w / w1 (linear)")
    ax2.set_ylabel(f"energy / grazing energy ({E_GRAZE:.2f} J for the blade)")
    ax2.set_title(f"mode 1 backbone, stop {1e3 * G0:g} mm (H = {H.n_harmonics})")
    ax2.legend(fontsize=7.5, loc="upper left")
    fig.tight_layout()
    path = out / "blade3d_reduction.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)

    sol = animated_point()
    fig = fm.plot.contact_pressure(sol, rom, boundary="tip", n_frames=160)
    fig.axes[0].set_title(f"tip face on the stop, backbone at {sol.energy / E_GRAZE:.1f} grazing energies", fontsize=10)
    fig.axes[0].set_xlabel("s: position along the tip face (chord) [m]")
    fig.axes[1].set_xlabel("total force [N]")
    fig.axes[2].set_ylabel("contact pressure, max across the thickness [Pa]")
    fig.savefig(out / "blade3d_pressure.png", dpi=110)
    plt.close(fig)
    style = fm.viz.AnimationStyle(unit="m",
                                  title="3D blade, nonlinear mode 1 against the tip stop (Craig-Bampton, expanded)")
    fm.viz.animate(sol, rom, out / "blade3d_mode1.gif", n_frames=24, style=style)
    return path


def write_paraview(out="out"):
    """The animated orbit as a ParaView series (open the .pvd), expanded to the 3690 DOFs."""
    return fm.io.write_animation(animated_point(), rom, Path(out) / "blade3d_mode1", n_frames=36)


if __name__ == "__main__":
    print(f"linear w = {np.round(full_linear.omega, 3)} rad/s (beam theory flap {W1_BEAM:.3f}); Craig-Bampton "
          f"({rom.n_dofs} DOFs) errors {cb_error}")
    print(f"grazing energy {E_GRAZE:.4f} J; w/w1 at E/E_g = {E_RATIOS}: blade {np.round(blade_ratio, 5)}, "
          f"beam {np.round(beam_ratio, 5)}; max |xi| {np.abs(backbone.xi).max():.1e}, "
          f"max penetration {1e3 * backbone.penetration.max():.4f} mm")
    print(f"full-model check at {reduced_point.energy / E_GRAZE:g} E_g: Newton {full_check.message} "
          f"in {full_check.nit} iterations, "
          f"w full {full_point.omega:.6f}, reduced {reduced_point.omega:.6f} rad/s (difference {check_error:.1e})")
    print("saved", main(), write_paraview())
