"""Validation of HBM nonlinear modes (free, conservative, unilateral contact) by time integration.

The HBM orbit of a nonlinear mode at energy E is compared with a Moreau-Jean time integration
(``fm.simulate``, restitution 1, trapezoidal rule) of the same free model started from the HBM
state, for H = 10, 20, 40 harmonics.

Starting state. The HBM nonlinear-mode solutions are even in time (cosine terms only, the phase
condition removes sin(w t) of the mode): ``t = 0`` is the maximum of the contact DOF, where the
truncated orbit *penetrates* the stop (``sol.penetration > 0`` for every H tested), so it cannot
start the time integration. Instead each run starts at the other turning point ``t = T/2``
(velocities zero by symmetry, far from the stop) with the HBM displacement scaled so that the
potential energy equals the HBM energy E, ``u0 = c u_HBM(T/2)``, ``u0.K u0 / 2 = E``, ``v0 = 0``.
For the 1-DOF oscillator this is the exact state ``u0 = -sqrt(2E)`` of the impact orbit of
energy E. The HBM orbit is compared shifted by T_HBM/2 (same phase origin).

1. 1-DOF contact oscillator ``u'' + u = -p``, gap 1, E = 0.8, 2, 8 (grazing E = 0.5). The
   time-domain frequency comes from the upward zero crossings of u (linear interpolation, away from
   the impacts); exact ``w = pi / (pi - arccos(g/A))``, ``A = sqrt(2E)``. Orbit error
   ``max_t |u_HBM(t + T_HBM/2) - u_TS(t)| / max|u_TS|`` over one time-domain period (it includes
   the phase drift due to the frequency error) and the shape error (same with the HBM time scaled
   to the time-domain period, i.e. at equal phase).
2. 2-DOF chain ``M = I, K = [[2, -1], [-1, 1]]``, stop on mass 2 at gap 0.5, mode 1 at
   E/E_graze = 1.5, 3, 10. The time-domain "period" is the first return time of the state:
   ``d(t) = ||z(t) - z0||_E / sqrt(2E)`` (energy norm, ``z = (u, v)``) minimised over
   ``t in [T/2, 3T/2]``; ``d1`` is that minimum (0 for an exactly periodic orbit through z0).

Findings (see ``__main__``): the time integration is accurate to ~1e-4 in frequency (O(dt)
impact-time error of Moreau-Jean) and conserves the energy to ~1e-11, so it is the reference.
The HBM frequency error vs the time domain decreases like ~H^-0.85 (1-DOF: 6 %, 3.4 %, 1.9 % at
H = 10, 20, 40), the orbit error like ~H^-0.8. In the 2-DOF chain the state returns to within
d1 ~ 0.2, 0.12, 0.07 (H = 10, 20, 40) of the start: the start is only an O(H^-0.8) approximation
of a periodic orbit, so over many periods the time-domain motion is *not* periodic (d at later
returns wanders between ~0 and ~0.5, a quasi-periodic-looking drift), while the first-return
frequency converges to the HBM one as H grows.
"""

import math
import time

import numpy as np

import femodes as fm
from femodes.analyses import branch_from_continuation, nonlinear_mode_options

HS = (10, 20, 40)
DT_1DOF = 5e-4
DT_2DOF = 1e-3
N_PERIODS_1DOF = 10
N_PERIODS_LONG = 20

_timings = {}


def mode_at_energies(model, H, energies, e_start):
    """Nonlinear mode 1 ending exactly at each energy (one problem, chained continuations).

    Same problem, scaling and options as :func:`femodes.nonlinear_mode`, but the continuation is
    restarted from the previous end point, so the H = 40 start-up (the costly part) is paid once.
    Start just below grazing (0.9 E_graze): identical end points, ~4x faster at H = 40 than
    starting at 0.6 E_graze (the non-impacting segment is expensive at H = 40).
    Returns the list of Branch segments; ``segment[-1]`` is the solution at that energy.
    """
    h = fm.Harmonics(H)
    pr = fm.NonlinearModeProblem(model, h, 1, reference_energy=math.sqrt(e_start * max(energies)))
    x = pr.linear_guess(e_start)
    opts = nonlinear_mode_options(pr, x)
    out, e0 = [], e_start
    for E in energies:
        res = fm.continuation(pr, (math.log10(e0), math.log10(E)), x0=x, options=opts)
        out.append(branch_from_continuation(pr, res, kind="nonlinear mode", model=model))
        x, e0 = res.x[-1], E
    return out


def turning_point_state(sol, K):
    """Equal-energy start at the HBM turning point t = T/2 (v = 0): ``u0.K u0 / 2 = E``."""
    u = sol.displacement(0.5 * sol.period)[0]
    return u * math.sqrt(2.0 * sol.energy / float(u @ K @ u)), np.zeros_like(u)


def up_crossings(t, u, level=0.0):
    s = u - level
    i = np.nonzero((s[:-1] < 0) & (s[1:] >= 0))[0]
    return t[i] - s[i] * (t[i + 1] - t[i]) / (s[i + 1] - s[i])


# --------------------------------------------------------------------------------------------
# 1. 1-DOF contact oscillator
# --------------------------------------------------------------------------------------------
GAP1 = 1.0
ENERGIES_1DOF = (0.8, 2.0, 8.0)
free = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=GAP1))


def impact_frequency(energy, gap=GAP1):
    A = np.sqrt(2.0 * np.asarray(energy, dtype=float))
    return np.where(A > gap, np.pi / (np.pi - np.arccos(np.minimum(gap / A, 1.0))), 1.0)


def exact_orbit(t, energy, gap=GAP1):
    """Exact impact orbit started at the turning point u = -A (t = 0)."""
    A = math.sqrt(2.0 * energy)
    T = 2 * np.pi / float(impact_frequency(energy, gap))
    tau = np.mod(t, T)
    return -A * np.cos(np.minimum(tau, T - tau))


_t = time.perf_counter()
hbm1 = {H: [seg[-1] for seg in mode_at_energies(free, H, ENERGIES_1DOF, 0.45)] for H in HS}
_timings["hbm 1-DOF"] = time.perf_counter() - _t

_t = time.perf_counter()
ts1 = {}  # energy -> dict(hist, omega, ...)
for i, E in enumerate(ENERGIES_1DOF):
    A = math.sqrt(2.0 * E)
    T_ex = 2 * np.pi / float(impact_frequency(E))
    hist = fm.simulate(free, N_PERIODS_1DOF * T_ex, DT_1DOF, u0=[-A], v0=[0.0], restitution=1.0)
    tc = up_crossings(hist.t, hist.u[:, 0])
    T_ts = float(np.mean(np.diff(tc)))
    one = hist.t <= T_ts
    u_ts = hist.u[one, 0]
    ts1[E] = {
        "hist": hist, "omega": 2 * np.pi / T_ts, "period_spread": float(np.ptp(np.diff(tc))),
        "energy_drift": float(np.ptp(hist.energy) / E), "penetration": float(max(0.0, -hist.gap.min())),
        "exact_orbit_error": float(np.max(np.abs(u_ts - exact_orbit(hist.t[one], E))) / np.max(np.abs(u_ts))),
    }
_timings["time integration 1-DOF"] = time.perf_counter() - _t

omega_exact_1dof = np.array([float(impact_frequency(E)) for E in ENERGIES_1DOF])
omega_ts_1dof = np.array([ts1[E]["omega"] for E in ENERGIES_1DOF])
omega_hbm_1dof = np.array([[hbm1[H][i].omega for i in range(len(ENERGIES_1DOF))] for H in HS])  # (H, E)
freq_error_ts = omega_hbm_1dof / omega_ts_1dof[None, :] - 1  # HBM vs time domain
freq_error_exact = omega_hbm_1dof / omega_exact_1dof[None, :] - 1
ts_error_exact = omega_ts_1dof / omega_exact_1dof - 1
orbit_error_1dof = np.empty((len(HS), len(ENERGIES_1DOF)))
shape_error_1dof = np.empty_like(orbit_error_1dof)
penetration_1dof = np.empty_like(orbit_error_1dof)
xi_1dof = np.empty_like(orbit_error_1dof)
for a, H in enumerate(HS):
    for b, E in enumerate(ENERGIES_1DOF):
        sol, r = hbm1[H][b], ts1[E]
        T_ts = 2 * np.pi / r["omega"]
        one = r["hist"].t <= T_ts
        t1, u_ts = r["hist"].t[one], r["hist"].u[one, 0]
        scale = np.max(np.abs(u_ts))
        orbit_error_1dof[a, b] = np.max(np.abs(sol.displacement(t1 + sol.period / 2)[:, 0] - u_ts)) / scale
        shape_error_1dof[a, b] = np.max(np.abs(sol.displacement(sol.period * (0.5 + t1 / T_ts))[:, 0] - u_ts)) / scale
        penetration_1dof[a, b] = sol.penetration
        xi_1dof[a, b] = sol.xi
rate_freq_1dof = np.array([np.polyfit(np.log(HS), np.log(np.abs(freq_error_ts[:, b])), 1)[0]
                           for b in range(len(ENERGIES_1DOF))])
rate_orbit_1dof = np.array([np.polyfit(np.log(HS), np.log(orbit_error_1dof[:, b]), 1)[0]
                            for b in range(len(ENERGIES_1DOF))])

# --------------------------------------------------------------------------------------------
# 2. 2-DOF chain, contact on mass 2
# --------------------------------------------------------------------------------------------
GAP2 = 0.5
K2 = np.array([[2.0, -1.0], [-1.0, 1.0]])
chain = fm.StructuralModel(M=np.eye(2), K=K2).with_contact(fm.UnilateralContact(at=1, gap=GAP2))
_lin = fm.linear_modes(chain, 1)
_phi = _lin.shapes[:, 0] / np.sqrt(_lin.shapes[:, 0] @ _lin.shapes[:, 0])  # mass-normalised (M = I)
E_GRAZE_2DOF = float((GAP2 / abs(_phi[1])) ** 2 * _lin.omega[0] ** 2 / 2)
RATIOS_2DOF = (1.5, 3.0, 10.0)
ENERGIES_2DOF = tuple(r * E_GRAZE_2DOF for r in RATIOS_2DOF)


def state_distance(hist, u0, v0, energy):
    du, dv = hist.u - u0, hist.v - v0
    return np.sqrt((np.einsum("ij,jk,ik->i", du, K2, du) + np.sum(dv * dv, axis=1)) / (2.0 * energy))


def first_return(hist, d, T, k=1):
    """(return time, distance) minimising d over t in [(k - 1/2) T, (k + 1/2) T]."""
    m = (hist.t > (k - 0.5) * T) & (hist.t < (k + 0.5) * T)
    i = int(np.argmin(np.where(m, d, np.inf)))
    return float(hist.t[i]), float(d[i])


_t = time.perf_counter()
hbm2 = {H: [seg[-1] for seg in mode_at_energies(chain, H, ENERGIES_2DOF, 0.9 * E_GRAZE_2DOF)] for H in HS}
_timings["hbm 2-DOF"] = time.perf_counter() - _t

_t = time.perf_counter()
omega_hbm_2dof = np.empty((len(HS), len(RATIOS_2DOF)))
omega_ts_2dof = np.empty_like(omega_hbm_2dof)
return_distance_2dof = np.empty_like(omega_hbm_2dof)
penetration_2dof = np.empty_like(omega_hbm_2dof)
xi_2dof = np.empty_like(omega_hbm_2dof)
energy_drift_2dof = np.empty_like(omega_hbm_2dof)
for a, H in enumerate(HS):
    for b in range(len(RATIOS_2DOF)):
        sol = hbm2[H][b]
        u0, v0 = turning_point_state(sol, K2)
        hist = fm.simulate(chain, 1.5 * sol.period, DT_2DOF, u0=u0, v0=v0, restitution=1.0)
        t_ret, d_ret = first_return(hist, state_distance(hist, u0, v0, sol.energy), sol.period)
        omega_hbm_2dof[a, b], omega_ts_2dof[a, b] = sol.omega, 2 * np.pi / t_ret
        return_distance_2dof[a, b] = d_ret
        penetration_2dof[a, b], xi_2dof[a, b] = sol.penetration, sol.xi
        energy_drift_2dof[a, b] = np.ptp(hist.energy) / sol.energy
freq_error_2dof = omega_hbm_2dof / omega_ts_2dof - 1

# long run from the H = 40 state at E = 3 E_graze: is the time-domain motion periodic?
LONG_H, LONG_IDX = HS[-1], 1
_sol = hbm2[LONG_H][LONG_IDX]
_u0, _v0 = turning_point_state(_sol, K2)
long_hist = fm.simulate(chain, (N_PERIODS_LONG + 0.5) * _sol.period, DT_2DOF, u0=_u0, v0=_v0, restitution=1.0)
long_distance = state_distance(long_hist, _u0, _v0, _sol.energy)
long_returns = np.array([first_return(long_hist, long_distance, _sol.period, k) for k in range(1, N_PERIODS_LONG + 1)])
_timings["time integration 2-DOF"] = time.perf_counter() - _t


def main(out="out"):
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 2, figsize=(13, 8.5))
    # (a) 1-DOF orbit at E = 2
    ax = axes[0, 0]
    b = ENERGIES_1DOF.index(2.0)
    r = ts1[2.0]
    T_ts = 2 * np.pi / r["omega"]
    k = r["hist"].t <= 1.2 * T_ts
    t = r["hist"].t[k]
    ax.plot(t, r["hist"].u[k, 0], "k-", lw=2.5, label=f"Moreau-Jean, dt = {DT_1DOF:g}")
    for H, c in zip(HS, ("C3", "C1", "C0")):
        sol = hbm1[H][b]
        ax.plot(t, sol.displacement(t + sol.period / 2)[:, 0], c, lw=1, label=f"HBM H = {H}")
    ax.axhline(GAP1, color="0.5", ls=":", label="stop")
    ax.set_xlabel("t")
    ax.set_ylabel("u")
    ax.set_title("1-DOF, E = 2: free orbit from the turning point")
    ax.legend(fontsize=7, loc="lower right")
    # (b) 1-DOF errors vs H
    ax = axes[0, 1]
    for b, (E, c) in enumerate(zip(ENERGIES_1DOF, ("C0", "C1", "C2"))):
        ax.loglog(HS, np.abs(freq_error_ts[:, b]), "o-", color=c,
                  label=f"E = {E}: |w_HBM/w_TS - 1| ~ H^{rate_freq_1dof[b]:.2f}")
        ax.loglog(HS, orbit_error_1dof[:, b], "s--", color=c, mfc="none",
                  label=f"E = {E}: orbit error ~ H^{rate_orbit_1dof[b]:.2f}")
        ax.loglog(HS, penetration_1dof[:, b], "^:", color=c, label=f"E = {E}: HBM penetration")
    ax.set_xlabel("H")
    ax.set_title("1-DOF: HBM vs time integration")
    ax.legend(fontsize=6)
    # (c) 2-DOF, long run
    ax = axes[1, 0]
    k = long_hist.t <= 4 * _sol.period
    t = long_hist.t[k]
    ax.plot(t, long_hist.u[k, 1], "k-", lw=2, label="Moreau-Jean, mass 2")
    ax.plot(t, _sol.displacement(t + _sol.period / 2)[:, 1], "C0-", lw=1, label=f"HBM H = {LONG_H}, mass 2")
    ax.plot(t, long_hist.u[k, 0], "0.4", lw=2, label="Moreau-Jean, mass 1")
    ax.plot(t, _sol.displacement(t + _sol.period / 2)[:, 0], "C1-", lw=1, label=f"HBM H = {LONG_H}, mass 1")
    ax.axhline(GAP2, color="0.5", ls=":", label="stop")
    ax.set_xlabel("t")
    ax.set_ylabel("u")
    ax.set_title(f"2-DOF chain, E = {RATIOS_2DOF[LONG_IDX]:g} E_graze: 4 HBM periods")
    ax.legend(fontsize=7, loc="lower left")
    # (d) 2-DOF returns
    ax = axes[1, 1]
    ax.plot(long_hist.t / _sol.period, long_distance, "0.6", lw=0.8, label="d(t) (H = 40 start)")
    ax.plot(long_returns[:, 0] / _sol.period, long_returns[:, 1], "ko", ms=4, label="min of d near each period")
    ax.set_xlabel("t / T_HBM")
    ax.set_ylabel("||z(t) - z0||_E / sqrt(2E)")
    ax.set_title("2-DOF: state return distance (not periodic over many periods)")
    txt = "first-return d1 (H = 10, 20, 40):\n" + "\n".join(
        f"E/Eg = {ratio:g}: " + ", ".join(f"{v:.3f}" for v in return_distance_2dof[:, b]) for b, ratio in enumerate(RATIOS_2DOF))
    ax.text(0.02, 0.97, txt, transform=ax.transAxes, va="top", fontsize=7, family="monospace",
            bbox=dict(facecolor="white", alpha=0.8))
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path = out / "validation_free_orbits.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print("timings [s]:", {k: round(v, 2) for k, v in _timings.items()})
    print("1-DOF contact oscillator (gap 1), time integration from u0 = -sqrt(2E), v0 = 0, dt =", DT_1DOF)
    print("   E     w_exact     w_TS       TS err     E drift    TS pen    TS orbit err vs exact")
    for b, E in enumerate(ENERGIES_1DOF):
        r = ts1[E]
        print(f"  {E:4.1f}  {omega_exact_1dof[b]:.6f}  {omega_ts_1dof[b]:.6f}  {ts_error_exact[b]:+.2e}  "
              f"{r['energy_drift']:.1e}   {r['penetration']:.1e}   {r['exact_orbit_error']:.2e}")
    print("   H    E    w_HBM      w_HBM/w_TS-1  w_HBM/w_ex-1  orbit err  shape err  HBM pen    xi")
    for a, H in enumerate(HS):
        for b, E in enumerate(ENERGIES_1DOF):
            print(f"  {H:3d}  {E:4.1f}  {omega_hbm_1dof[a, b]:.6f}  {freq_error_ts[a, b]:+.3e}    {freq_error_exact[a, b]:+.3e}"
                  f"    {orbit_error_1dof[a, b]:.3e}  {shape_error_1dof[a, b]:.3e}  {penetration_1dof[a, b]:.3e}  {xi_1dof[a, b]:.0e}")
    print("  fitted rates (H = 10..40): frequency", np.round(rate_freq_1dof, 3), " orbit", np.round(rate_orbit_1dof, 3))
    print(f"2-DOF chain (gap 0.5 on mass 2), E_graze = {E_GRAZE_2DOF:.6f}, dt = {DT_2DOF}")
    print("   H   E/Eg   w_HBM      w_TS(return)  w_HBM/w_TS-1  d1 (return)  HBM pen    E drift   xi")
    for a, H in enumerate(HS):
        for b, ratio in enumerate(RATIOS_2DOF):
            print(f"  {H:3d}  {ratio:4.1f}  {omega_hbm_2dof[a, b]:.6f}  {omega_ts_2dof[a, b]:.6f}      {freq_error_2dof[a, b]:+.3e}"
                  f"    {return_distance_2dof[a, b]:.3e}    {penetration_2dof[a, b]:.3e}  {energy_drift_2dof[a, b]:.0e}  {xi_2dof[a, b]:.0e}")
    print(f"  long run from H = {LONG_H}, E = {RATIOS_2DOF[LONG_IDX]} E_graze: return distance at periods 1..{N_PERIODS_LONG}:")
    print("   ", np.round(long_returns[:, 1], 3))
    print("saved", main())
