"""Energy-frequency curves of the 1-DOF contact oscillator for different numbers of harmonics.

Free system ``u'' + u = -p``, rigid stop at gap 1 (complementarity contact, restitution-1 exact
reference ``w = pi / (pi - arccos(g/A))``, ``A = sqrt(2E)``, grazing at E = 0.5). Backbones
(nonlinear mode 1) for H = 1, 5, 10, 20, 40 and the convergence of the HBM frequency at E = 2
and E = 8 with H: the error decreases algebraically (velocity jump at the impact, Gibbs) with a
rate fitted on log-log axes over H = 5..40, and the truncated orbit's penetration of the stop
decreases with H too.

Each backbone is one continuation problem run in chained segments 0.45 -> 2 -> 8 -> 20, so the
solutions at E = 2 and E = 8 are converged points exactly at those energies (no interpolation).
The branch starts just below grazing (E = 0.45; below grazing w = 1 exactly) because the
non-impacting segment is costly at H = 40; the plotted curves add the exact w = 1 below.
"""

import math
import time

import numpy as np

import femodes as fm
from femodes.analyses import branch_from_continuation, nonlinear_mode_options

HS = (1, 5, 10, 20, 40)
GAP = 1.0
E_START, E_CHECK, E_END = 0.45, (2.0, 8.0), 20.0

free = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=GAP))


def impact_frequency(energy, gap=GAP):
    A = np.sqrt(2.0 * np.asarray(energy, dtype=float))
    return np.where(A > gap, np.pi / (np.pi - np.arccos(np.minimum(gap / A, 1.0))), 1.0)


def backbone_segments(H, energies, e_start=E_START):
    """Chained continuation of one NonlinearModeProblem (same scaling as fm.nonlinear_mode)."""
    pr = fm.NonlinearModeProblem(free, fm.Harmonics(H), 1, reference_energy=math.sqrt(e_start * max(energies)))
    x = pr.linear_guess(e_start)
    opts = nonlinear_mode_options(pr, x)
    out, e0 = [], e_start
    for E in energies:
        res = fm.continuation(pr, (math.log10(e0), math.log10(E)), x0=x, options=opts)
        out.append(branch_from_continuation(pr, res, kind="nonlinear mode", model=free))
        x, e0 = res.x[-1], E
    return out


timings = {}
backbones = {}  # H -> dict(omega, energy, xi, success)
at_energy = {}  # H -> [PeriodicSolution at E_CHECK[0], E_CHECK[1]]
for H in HS:
    _t = time.perf_counter()
    segs = backbone_segments(H, (*E_CHECK, E_END))
    backbones[H] = {
        "omega": np.concatenate([segs[0].omega] + [s.omega[1:] for s in segs[1:]]),
        "energy": np.concatenate([segs[0].energy] + [s.energy[1:] for s in segs[1:]]),
        "xi": np.concatenate([s.xi for s in segs]),
        "success": all(s.success for s in segs),
    }
    at_energy[H] = [segs[0][-1], segs[1][-1]]
    timings[H] = time.perf_counter() - _t

omega_exact = np.array([float(impact_frequency(E)) for E in E_CHECK])
omega_hbm = np.array([[at_energy[H][j].omega for j in range(len(E_CHECK))] for H in HS])  # (H, E)
error = omega_hbm / omega_exact[None, :] - 1  # negative: HBM underestimates the frequency
penetration = np.array([[at_energy[H][j].penetration for j in range(len(E_CHECK))] for H in HS])
xi_max = np.array([np.max(np.abs(backbones[H]["xi"])) for H in HS])
FIT = np.array(HS) >= 5
rate = np.array([np.polyfit(np.log(np.array(HS)[FIT]), np.log(np.abs(error[FIT, j])), 1)[0] for j in range(len(E_CHECK))])
rate_penetration = np.array([np.polyfit(np.log(np.array(HS)[FIT]), np.log(penetration[FIT, j]), 1)[0]
                             for j in range(len(E_CHECK))])


def main(out="out"):
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.6))
    E = np.logspace(-1, np.log10(E_END), 400)
    ax1.plot(impact_frequency(E), E, "k-", lw=3, alpha=0.35, label="exact impact oscillator (e = 1)")
    for H, c in zip(HS, ("C3", "C1", "C2", "C4", "C0")):
        b = backbones[H]
        ax1.plot(np.r_[1.0, 1.0, b["omega"]], np.r_[0.1, E_START, b["energy"]], "-", color=c, lw=1.3, label=f"HBM H = {H}")
    for Ec in E_CHECK:
        ax1.axhline(Ec, color="0.6", lw=0.6, ls=":")
    ax1.axhline(0.5, color="0.4", lw=0.6, ls="-.", label="grazing E = 0.5")
    ax1.set_yscale("log")
    ax1.set_xlabel("w [rad/s]")
    ax1.set_ylabel("energy")
    ax1.set_title("energy-frequency backbones vs number of harmonics")
    ax1.legend(fontsize=8, loc="upper left")
    for j, (Ec, mk) in enumerate(zip(E_CHECK, ("o", "s"))):
        ax2.loglog(HS, np.abs(error[:, j]), mk + "-", color="C0", label=f"E = {Ec:g}: |w_HBM/w_exact - 1| ~ H^{rate[j]:.2f} (H >= 5)")
        ax2.loglog(HS, penetration[:, j], mk + "--", color="C3", mfc="none",
                   label=f"E = {Ec:g}: max penetration ~ H^{rate_penetration[j]:.2f}")
    ax2.set_xlabel("H (harmonics)")
    ax2.set_title("convergence with H")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    path = out / "energy_frequency_harmonics.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print("time per backbone [s]:", {H: round(t, 2) for H, t in timings.items()})
    print("exact w at E =", E_CHECK, ":", np.round(omega_exact, 6))
    print("   H   " + "   ".join(f"w(E={E:g})   error      penetr.  " for E in E_CHECK) + " max|xi|   points")
    for i, H in enumerate(HS):
        row = "   ".join(f"{omega_hbm[i, j]:.6f}  {error[i, j]:+.3e}  {penetration[i, j]:.3e}" for j in range(len(E_CHECK)))
        print(f"  {H:3d}  {row}    {xi_max[i]:.0e}   {backbones[H]['omega'].size}")
    print("fitted rate (H = 5..40): frequency error", np.round(rate, 3), " penetration", np.round(rate_penetration, 3))
    print("saved", main())
