r"""Period doubling of the impact oscillator: stability along the resonance, and the switched branch.

System (the seed's forced contact case 1; one DOF, rigid stop at ``u = 1``)::

    u'' + 0.1 u' + u = 0.2 cos(w t) - p,    g_N = 1 - u >= 0,  p >= 0,  p g_N = 0

1. The frequency response by HBM (``H = 20``) with ``stability=True``: ``"auto"`` refines every
   HBM orbit by event-driven shooting (impacts with restitution 1, saltation matrices) and takes
   the Floquet multipliers of the true orbit. On the impacting resonance branch the period-1
   orbit is unstable from just after grazing (``w ~ 0.909``; at grazing the multipliers jump,
   ``-50`` at the first impacting point, the square-root singularity of impact maps; shooting
   cannot converge on the grazing orbits themselves, where Hill's method is used and no
   bifurcation is claimed across the change of method) up to a period doubling at
   ``w = 0.996204`` (a multiplier crosses -1; the same at H = 10, 20 and 40 because shooting
   removes the HBM's truncation error), stable above it up to the upper fold; the middle branch
   between the folds is a saddle.
2. :func:`femodes.switch_branch` continues the period-2 branch (harmonics of ``w/2``) from the
   HBM's own period doubling (at ``w = 0.9596`` for ``H = 20``: the truncated series puts it
   4 % low and it moves up with ``H``; Hill's method on the HBM orbit sees it only roughly).
3. A point of the period-2 branch is shot over two forcing periods from the HBM state: Newton
   converges to a true period-2 orbit of the impact oscillator within 4 % of the HBM one.

``python examples/period_doubling.py`` prints the bifurcations and writes
``out/period_doubling.png``.
"""

import numpy as np

import femodes as fm

DAMPING, FORCE, GAP, H = 0.1, 0.2, 1.0, 20
SPAN = (0.85, 1.45)

model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[DAMPING]])
         .with_contact(fm.UnilateralContact(at=0, gap=GAP))
         .with_forcing(fm.HarmonicForce(at=0, amplitude=FORCE)))

# 1. the period-1 branch with its stability (shooting at every point, Hill where it cannot)
branch = fm.frequency_response(model, SPAN, H, stability=True)
bifurcations = {b.kind: b for b in branch.bifurcations if b.kind != "fold"}
doubling = bifurcations["period_doubling"]

# 2. the period-doubled branch, traced downwards from the HBM's period doubling
doubled = fm.switch_branch(branch, doubling, omega=(SPAN[0], doubling.omega))


def _state(sol, t):
    return np.array([sol.displacement([t])[0, 0], sol.velocity([t])[0, 0]])


def _open_time(sol):
    """The instant of the orbit farthest from the stop (shooting starts away from impacts)."""
    theta = 2 * np.pi * np.arange(512) / 512
    return theta[np.argmin(sol.harmonics.grid.synthesis(theta) @ sol.Q[:, 0])] / (2 * np.pi) * sol.period


# 3. time-domain confirmation of a period-2 orbit
check = doubled[len(doubled) // 2]
t0 = _open_time(check)
x_hbm = _state(check, t0)
shot = fm.time.shoot(model, check.omega, x_hbm, period=check.period, t0=t0)
orbit_correction = float(np.max(np.abs(shot.x - x_hbm)) / np.max(np.abs(x_hbm)))
half_period_gap = float(np.max(np.abs(fm.time.trajectory(model, check.omega, shot.x, [t0 + check.period / 2],
                                                          t0=t0)[0] - shot.x)))


def report() -> str:
    lines = [f"period-1 branch, H = {H}: {len(branch)} points, {int(branch.stable.sum())} stable "
             f"(methods: {', '.join(sorted(set(branch.stability_method)))})"]
    for b in branch.bifurcations:
        lines.append(f"  {b.kind:16s} w = {b.omega:.6f}  multiplier {complex(b.multiplier):.4f}")
    sf = doubled.meta["switched_from"]
    lines.append(f"period-2 branch: {len(doubled)} points, w in [{doubled.omega.min():.4f}, {doubled.omega.max():.4f}], "
                 f"born at the HBM's doubling w = {sf['omega_hbm']:.6f}")
    lines.append(f"shooting over 2T at w = {check.omega:.5f}: {shot.message}; orbit moved by {orbit_correction:.1%}, "
                 f"|x(T) - x(0)| = {half_period_gap:.3f} (period 2), multipliers {np.round(shot.multipliers, 4)}")
    return "\n".join(lines)


def main(out="out"):
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.6))
    fm.plot.frequency_amplitude(branch, 0, ax=ax1, label="period 1")
    amp2 = doubled.amplitude(0)
    ax1.plot(doubled.omega, amp2, "-", color="C3", label="period 2 (switch_branch)")
    ax1.axhline(GAP, color="0.5", lw=0.8, ls=":")
    ax1.set_title(f"impact oscillator, H = {H}: stability by shooting")
    ax1.legend(fontsize=8, loc="upper left")

    t = np.linspace(t0, t0 + check.period, 600)
    u_hbm = check.displacement(t)[:, 0]
    v_hbm = check.velocity(t)[:, 0]
    xs = fm.time.trajectory(model, check.omega, shot.x, t, t0=t0)
    ax2.plot(u_hbm, v_hbm, "-", color="C3", lw=1.5, label=f"HBM, 2H = {2 * H} harmonics of w/2")
    ax2.plot(xs[:, 0], xs[:, 1], "k--", lw=1, label="shooting (event-driven, 2 periods)")
    ax2.axvline(GAP, color="0.5", lw=0.8, ls=":")
    ax2.set_xlabel("u")
    ax2.set_ylabel("u'")
    ax2.set_title(f"period-2 orbit at w = {check.omega:.4f} (two impacts per orbit)")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    path = out / "period_doubling.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print(report())
    print("saved", main())
