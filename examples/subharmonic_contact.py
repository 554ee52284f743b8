r"""Sub-harmonic (period-2) resonance of an impact oscillator: HBM branch vs event-driven integration.

System (one DOF, unit mass and stiffness, rigid stop at ``u = GAP``)::

    u'' + DAMPING u' + u = FORCE cos(w t) - p,    g_N = GAP - u >= 0,  p >= 0,  p g_N = 0

Parameters: ``DAMPING = 0.02``, ``FORCE = 0.5``, ``GAP = 1``; sub-harmonic index ``NU = 2``
(response period ``2 * 2 pi / w``); harmonic balance with ``N_HARMONICS = 20`` harmonics of
``w/2`` (up to ``10 w``), exact projection of the contact law, complementarity parameter
``C_CONTACT = 100`` (see "Contact parameter" below).

What it shows
-------------
1. *Find* the orbit in the time domain: an event-driven integration (``solve_ivp`` with an
   event at ``u = GAP``, velocity reversed ``v -> -v`` at impact, i.e. Newton's restitution
   coefficient 1, the time-domain counterpart of the energy-conserving Signorini law of the
   HBM) started from a large amplitude settles, at ``w = OMEGA0 = 2.8``, on a period-2 orbit
   with one impact per two forcing periods; its stroboscopic (Poincare) section at
   ``t = k 2 pi / w`` repeats every 2 periods and not every period, and it is refined by a
   Newton shooting on the 2-period map, whose Floquet multipliers (finite differences) lie
   inside the unit circle (attracting).
2. Sample one period (two forcing periods) on the HBM grid, ``Q0 = h.grid.from_time(u)``, start the
   contact force from the dynamic equilibrium ``P0 = F - S(w) Q0`` (the truncated Fourier
   series of the impulses; ``P0 = 0`` makes Newton fall onto the non-impacting 1-periodic
   solution at once) and correct with ``semismooth_newton``.
3. Continue in ``w`` both ways with ``fm.frequency_response``.  The sub-harmonic branch is an
   *isola*: both runs go around a closed curve with two folds (near ``w = 2.07`` and
   ``w = 3.61``) and come back to ``OMEGA0`` on the other (lower) part; it does not
   bifurcate from the primary branch, which is the small non-impacting linear response
   ``F/|1 - w^2|`` there (computed with ordinary ``fm.Harmonics(20)`` for the plot).
4. Validate points of both parts of the isola by shooting the time integration from the HBM
   state at ``t = 0``: the upper part is attracting (complex Floquet pair of modulus
   ``exp(-DAMPING T/2)``, since ``det`` of the monodromy is ``exp(-DAMPING T)`` and the
   elastic impact preserves area), the lower part is a saddle (a real multiplier > 1).
   Compared: amplitude of the ``w/2`` component, extreme displacement, impact phase.

Accuracy of the HBM (measured, see ``__main__`` output and tests/test_subharmonic.py)
----------------------------------------------------------------------------------------
The exact motion has a velocity jump at every impact, so its Fourier coefficients decay
like ``1/k^2`` and the truncated HBM converges algebraically: at ``w = 2.8`` the error of the
``w/2`` amplitude is about 0.16, 0.09, 0.05 for ``H = 10, 20, 40`` (~ ``1/H``), a few percent
of penetration ``max(u) - GAP`` and a contact force with negative lobes ("tension", the
Gibbs oscillations of an impulse approximated by ``2H+1`` terms).

Contact parameter
-----------------
The truncated complementarity equation ``P = proj[max(0, P + c (U - g))]`` is *not*
independent of ``c`` (only its infinite-``H`` limit is).  With the default ``c`` (static
stiffness 1) Newton stalls at a residual 1e-4..1e-3 on this impact problem (H = 20, 40); ``c = 100`` (about the
dynamic stiffness ``(k w/2)^2`` of harmonic ``k ~ 7``) converges in a few iterations.  The
spread of the results over ``c in [10, 300]`` is of the order of the truncation error.

References
----------
* Free impact oscillator (``u'' + u = 0`` with a stop at ``g``, restitution 1): the motion
  is an arc of ``A cos`` between ``u = g`` crossings, so the period is
  ``2 (pi - arccos(g/A))`` and ``w_free(A) = pi / (pi - arccos(g/A))`` for ``A > g``
  (e.g. Shaw & Holmes, J. Sound Vib. 90 (1983) 129-155; di Bernardo et al., *Piecewise-smooth
  Dynamical Systems*, Springer 2008, ch. 1).  A 1/2 sub-harmonic needs ``w ~ 2 w_free``:
  ``w = 2.8`` gives ``A ~ 1.6``, which is the measured ``-min u ~ 1.79`` (the forced part adds).
* Harmonic balance with complementarity contact and the exact positive part: see
  ``femodes/hbm/system.py`` and ``femodes/hbm/harmonics.py``.
* Shooting and Floquet multipliers of non-smooth periodic orbits: Leine & Nijmeijer,
  *Dynamics and Bifurcations of Non-Smooth Mechanical Systems*, Springer 2004, ch. 7.

Everything is computed at import (about 10 s); run as a script to print and plot
(``out/subharmonic_contact.png``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

import femodes as fm
from femodes.results import ContactInfo

DAMPING = 0.02
FORCE = 0.5
GAP = 1.0
NU = 2
OMEGA0 = 2.8
N_HARMONICS = 20
C_CONTACT = 100.0
N_TRANSIENT = 60  # forcing periods of transient before shooting
RTOL, ATOL = 1e-10, 1e-12


# --------------------------------------------------------------------------- time domain
def simulate(y0, t0, t1, omega, *, dense=False):
    """Event-driven integration from ``t0`` to ``t1``; impact at ``u = GAP`` with ``v -> -v``.

    Returns ``(y(t1), impacts, segments)``: ``impacts`` an array of ``(t_impact, v_before)``,
    ``segments`` the dense ``solve_ivp`` solutions between impacts (with ``dense=True``).
    """

    def rhs(t, y):
        return [y[1], -DAMPING * y[1] - y[0] + FORCE * np.cos(omega * t)]

    def hit(t, y):
        return y[0] - GAP

    hit.terminal, hit.direction = True, 1
    t, y = float(t0), np.array(y0, dtype=float)
    impacts, segments = [], []
    while t < t1:
        sol = solve_ivp(rhs, (t, t1), y, method="DOP853", events=hit, rtol=RTOL, atol=ATOL, dense_output=dense)
        if dense:
            segments.append(sol)
        if sol.status == 1:  # impact: restitution coefficient 1
            t, v = float(sol.t_events[0][0]), float(sol.y_events[0][0][1])
            impacts.append((t, v))
            y = np.array([GAP, -abs(v)])
        else:
            t, y = t1, sol.y[:, -1]
    return y, np.array(impacts).reshape(-1, 2), segments


def strobe(y0, omega, n_periods):
    """Poincare (stroboscopic) section ``y(k 2pi/w)``, ``k = 0..n_periods``."""
    T = 2 * np.pi / omega
    pts = [np.array(y0, dtype=float)]
    for k in range(n_periods):
        pts.append(simulate(pts[-1], k * T, (k + 1) * T, omega)[0])
    return np.array(pts)


def shoot(y0, omega, nu=NU, tol=1e-10, max_iter=30, fd=1e-7):
    """Newton on ``Phi_nu(y) - y = 0`` (``Phi_nu``: flow over ``nu`` forcing periods).

    Returns ``(y, residual, multipliers, impacts)``; multipliers are the eigenvalues of the
    finite-difference monodromy matrix ``dPhi_nu/dy``.
    """
    T = nu * 2 * np.pi / omega
    flow = lambda y: simulate(y, 0.0, T, omega)[0]  # noqa: E731

    def monodromy(y):
        Mj = np.empty((2, 2))
        for j in range(2):
            e = np.zeros(2)
            e[j] = fd * max(1.0, abs(y[j]))
            Mj[:, j] = (flow(y + e) - flow(y - e)) / (2 * e[j])
        return Mj

    y = np.array(y0, dtype=float)
    for _ in range(max_iter):
        f = flow(y) - y
        if np.max(np.abs(f)) < tol:
            break
        y = y - np.linalg.solve(monodromy(y) - np.eye(2), f)
    f = flow(y) - y
    return y, float(np.max(np.abs(f))), np.linalg.eigvals(monodromy(y)), simulate(y, 0.0, T, omega)[1]


def orbit(y0, omega, t, nu=NU):
    """Displacement of the time-domain orbit starting at ``y0`` (t = 0), at times ``t`` in one period."""
    _, _, segs = simulate(y0, 0.0, nu * 2 * np.pi / omega, omega, dense=True)
    u = np.full(np.shape(t), np.nan)
    for s in segs:
        sel = (t >= s.t[0]) & (t <= s.t[-1])
        u[sel] = s.sol(t[sel])[0]
    return u


_FINE = fm.Harmonics(1, n_time=4096, subharmonic=NU)


def subharmonic_amplitude_td(y0, omega):
    """Amplitude ``sqrt(c1^2 + s1^2)`` of the ``w/NU`` component of a time-domain orbit (4096 samples)."""
    c = _FINE.grid.from_time(orbit(y0, omega, _FINE.grid.times(omega)))
    return float(np.hypot(c[1], c[2]))


# --------------------------------------------------------------------------- HBM helpers
def make_model(c_contact=C_CONTACT):
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[DAMPING]])
            .with_contact(fm.UnilateralContact(at=0, gap=GAP, c=c_contact))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=FORCE)))


def hbm_from_orbit(y0, omega, n_harmonics, c_contact=C_CONTACT):
    """HBM solution corrected from the time-domain orbit through ``y0``; returns (NewtonResult, problem)."""
    h = fm.Harmonics(n_harmonics, subharmonic=NU)
    pr = fm.ForcedResponseProblem(make_model(c_contact), h)
    s = pr.system
    Q0 = h.grid.from_time(orbit(y0, omega, h.grid.times(omega))[:, None])
    P0 = (s.linear.force() - s.stiffness.operator(omega) @ Q0.ravel()).reshape(-1, 1)  # equilibrium: impulses
    res = fm.semismooth_newton(lambda x: pr.residual(x, omega)[:2], s.join(Q0, P0),
                               options=fm.NewtonOptions(max_iter=50))
    return res, pr


def solution(pr, x, omega):
    Q, P = pr.system.split(np.asarray(x))
    return fm.PeriodicSolution(omega=omega, Q=Q, P=P, harmonics=pr.system.h,
                               contacts=ContactInfo.from_system(pr.system))


def subharmonic_amplitude(Q):
    """Amplitude of the ``w/NU`` (first-harmonic of the base frequency) component."""
    return float(np.hypot(Q[1, 0], Q[2, 0]))


def contact_phase(sol):
    """Phase ``theta = w t / NU`` of the maximum of the HBM contact force."""
    th = 2 * np.pi * np.arange(4096) / 4096
    p = sol.contact_force(th * NU / sol.omega)[:, 0]
    return float(th[np.argmax(p)])


def contact_work_ratio(sol):
    """Period-averaged contact power ``<p u'>`` over the damping dissipation ``<c u'^2>`` (Parseval)."""
    h = sol.harmonics
    V = h.operators.derivative(sol.omega) @ sol.Q[:, 0]
    wts = h.galerkin.norm_weights()
    return float(np.sum(wts * sol.P[:, 0] * V) / (DAMPING * np.sum(wts * V * V)))


def state0(sol):
    """``(u(0), u'(0))`` of an HBM solution (start of the shooting)."""
    return np.array([sol.displacement(0.0)[0, 0], sol.velocity(0.0)[0, 0]])


# --------------------------------------------------------------------------- 1. find
strobe_transient = strobe([-6.0, 0.0], OMEGA0, N_TRANSIENT)  # from a large amplitude
y_td, shoot_residual, multipliers, impacts_td = shoot(strobe_transient[-1], OMEGA0)
strobe_settled = strobe(y_td, OMEGA0, 4)  # period-2 check
period1_mismatch = float(np.max(np.abs(strobe_settled[1] - strobe_settled[0])))
period2_mismatch = float(np.max(np.abs(strobe_settled[2] - strobe_settled[0])))
transient_distance = float(np.max(np.abs(strobe_transient[-1] - y_td)))  # reached by attraction
n_impacts_td = len(impacts_td)
impact_phase_td = float(np.mod(OMEGA0 * impacts_td[0, 0] / NU, 2 * np.pi))
impact_velocity_td = float(abs(impacts_td[0, 1]))
t_fine = np.linspace(0.0, NU * 2 * np.pi / OMEGA0, 2001)
u_td = orbit(y_td, OMEGA0, t_fine)
min_u_td = float(u_td.min())
sub_td = subharmonic_amplitude_td(y_td, OMEGA0)

# --------------------------------------------------------------------------- 2. HBM point
newton0, problem = hbm_from_orbit(y_td, OMEGA0, N_HARMONICS)
sol0 = solution(problem, newton0.x, OMEGA0)
sub_hbm = subharmonic_amplitude(sol0.Q)
min_u_hbm = float(sol0.displacement(t_fine)[:, 0].min())
impact_phase_hbm = contact_phase(sol0)
contact_work0 = contact_work_ratio(sol0)

# convergence in H at OMEGA0 (each corrected from the same time-domain orbit)
H_STUDY = (10, 20, 40)
sub_vs_H = {}
for _H in H_STUDY:
    _r, _pr = hbm_from_orbit(y_td, OMEGA0, _H)
    sub_vs_H[_H] = (bool(_r.success), subharmonic_amplitude(_pr.system.split(_r.x)[0]))

# --------------------------------------------------------------------------- 3. branch
model = make_model()
harm = problem.system.h
branch_down = fm.frequency_response(model, (OMEGA0, 1.5), harm, x0=newton0.x)
branch_up = fm.frequency_response(model, (OMEGA0, 4.5), harm, x0=newton0.x)
branches = (branch_down, branch_up)
fold_omegas = sorted(float(b.omega[i]) for b in branches for i in b.folds)
omega_range = (min(b.omega.min() for b in branches), max(b.omega.max() for b in branches))
# both runs come back to OMEGA0 on the lower part: the branch is a closed curve (isola)
closure_gap = float(np.max(np.abs(branch_down.Q[-1] - branch_up.Q[-1])))
primary = fm.frequency_response(model, (1.5, 4.5), fm.Harmonics(20))


def _parts(b):
    """Indices of the branch before (upper part) and after (lower part) its fold."""
    f = b.folds[0]
    return np.arange(0, f + 1), np.arange(f, len(b))


# --------------------------------------------------------------------------- 4. validation
CHECK_OMEGAS = (2.3, 2.6, 3.2, 3.5)
checks = []  # dicts per (omega, part)
for b in branches:
    up, low = _parts(b)
    for part, idx in (("upper", up), ("lower", low)):
        for wc in CHECK_OMEGAS:
            if not b.omega[idx].min() < wc < b.omega[idx].max():
                continue
            i = int(idx[np.argmin(np.abs(b.omega[idx] - wc))])
            s = b[i]
            y, resid, mu, imp = shoot(state0(s), s.omega)
            u = orbit(y, s.omega, np.linspace(0, s.period, 2001))
            checks.append(dict(
                omega=s.omega, part=part, y=y, found=bool(resid < 1e-8 and len(imp) == 1), shoot_residual=resid, multipliers=mu,
                stable=bool(np.all(np.abs(mu) < 1)), n_impacts=len(imp),
                sub_td=subharmonic_amplitude_td(y, s.omega), sub_hbm=subharmonic_amplitude(s.Q),
                min_td=float(u.min()), max_abs_td=float(np.max(np.abs(u))), min_hbm=float(s.displacement(np.linspace(0, s.period, 2001))[:, 0].min()),
                phase_td=float(np.mod(s.omega * imp[0, 0] / NU, 2 * np.pi)) if len(imp) else np.nan,
                phase_hbm=contact_phase(s), penetration=s.penetration, tension=s.tension,
                max_force=float(np.max(s.contact_force(np.linspace(0, s.period, 4096)))),
            ))




def td_fold_bracket(y, omega, step):
    """Natural continuation of the shooting solution in ``w`` by ``step`` until it is lost.

    Returns ``(last w with a period-2 impacting orbit, first w without)``: brackets the fold.
    """
    while True:
        y2, resid, _, imp = shoot(y, omega + step)
        if resid > 1e-8 or len(imp) != 1:
            return omega, omega + step
        y, omega = y2, omega + step


# time-domain folds, continued from the validated upper-part orbits nearest to each fold
_up = [c for c in checks if c["part"] == "upper" and c["found"]]
_lo, _hi = min(_up, key=lambda c: c["omega"]), max(_up, key=lambda c: c["omega"])
td_fold_low = td_fold_bracket(_lo["y"], _lo["omega"], -0.025)
td_fold_high = td_fold_bracket(_hi["y"], _hi["omega"], +0.025)

# --------------------------------------------------------------------------- report / plot
def report() -> str:
    lines = [
        f"time integration at w = {OMEGA0}: shooting residual {shoot_residual:.1e}, Poincare |P(y)-y| = "
        f"{period1_mismatch:.3f} (1 period), {period2_mismatch:.1e} (2 periods); transient of {N_TRANSIENT} periods "
        f"ends {transient_distance:.1e} from the orbit",
        f"  Floquet multipliers {np.round(multipliers, 4)} |mu| = {np.abs(multipliers).round(4)} "
        f"(exp(-c T/2) = {np.exp(-DAMPING * NU * np.pi / OMEGA0):.4f}); {n_impacts_td} impact per period, "
        f"v = {impact_velocity_td:.4f}",
        f"HBM H={N_HARMONICS}: Newton {newton0.nit} it, |r| = {newton0.residual_norm:.1e}",
        f"  w/2 amplitude: HBM {sub_hbm:.4f}, time integration {sub_td:.4f} (error {sub_hbm - sub_td:+.4f})",
        f"  min u: HBM {min_u_hbm:.4f}, TI {min_u_td:.4f};  impact phase: HBM {impact_phase_hbm:.4f}, TI {impact_phase_td:.4f}",
        f"  penetration {sol0.penetration:.4f}, tension {sol0.tension:.4f} (max contact force "
        f"{np.max(sol0.contact_force(t_fine)):.3f}); contact power / damping power {contact_work0:+.4f}",
        "  convergence in H of the w/2 amplitude error: "
        + ", ".join(f"H={k}: {v[1] - sub_td:+.4f}{'' if v[0] else ' (not converged)'}" for k, v in sub_vs_H.items()),
        f"branch: {branch_down!r} / {branch_up!r}",
        f"  w range [{omega_range[0]:.4f}, {omega_range[1]:.4f}], folds at w = {np.round(fold_omegas, 4)}, "
        f"closure |dQ| = {closure_gap:.1e}, max Newton it {max(b.nit.max() for b in branches)}",
        f"primary branch (Harmonics(20)): {primary!r}, max amplitude {primary.amplitude(0).max():.4f}",
        f"time-domain folds (natural continuation of shooting, step 0.025): w in {np.round(td_fold_low, 4)} "
        f"and {np.round(td_fold_high, 4)}",
        "validation (shooting from HBM points):",
    ]
    for c in checks:
        if not c["found"]:
            lines.append(f"  w={c['omega']:.4f} {c['part']:5s} shooting from the HBM state did not find a period-2 impacting orbit")
            continue
        lines.append(
            f"  w={c['omega']:.4f} {c['part']:5s} {'stable' if c['stable'] else 'UNSTABLE'} mu={np.round(c['multipliers'], 3)} "
            f"sub HBM/TI {c['sub_hbm']:.4f}/{c['sub_td']:.4f} min u {c['min_hbm']:.4f}/{c['min_td']:.4f} "
            f"phase {c['phase_hbm']:.3f}/{c['phase_td']:.3f} pen {c['penetration']:.4f} tension {c['tension']:.3f}/{c['max_force']:.2f}"
        )
    return "\n".join(lines)


def main(out: Path = Path("out")) -> Path:
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 5))
    T = NU * 2 * np.pi / OMEGA0
    ax1.plot(t_fine / T, u_td, "k-", lw=2.2, label="time integration (restitution 1)")
    ax1.plot(t_fine / T, sol0.displacement(t_fine)[:, 0], "C1--", lw=1.5, label=f"HBM, H = {N_HARMONICS} harmonics of w/2")
    ax1.axhline(GAP, color="0.4", lw=3, alpha=0.5, label="stop u = 1")
    ax1.plot(t_fine / T, FORCE * np.cos(OMEGA0 * t_fine), ":", color="0.5", label="forcing F cos(wt)")
    for ti in impacts_td[:, 0]:
        ax1.axvline(ti / T, color="k", lw=0.6, ls=":")
    axp = ax1.twinx()
    axp.plot(t_fine / T, sol0.contact_force(t_fine)[:, 0], "C3-", lw=0.8, alpha=0.7)
    axp.set_ylabel("HBM contact force p(t)", color="C3")
    axp.tick_params(axis="y", colors="C3")
    ax1.set_xlabel("t / (2 * 2pi/w)   (one sub-harmonic period = two forcing periods)")
    ax1.set_ylabel("u")
    ax1.set_title(f"period-2 orbit at w = {OMEGA0}: w/2 amplitude HBM {sub_hbm:.3f}, TI {sub_td:.3f}")
    ax1.set_ylim(-2.1, 2.0)
    ax1.legend(loc="upper right", fontsize=7, ncol=2)

    for k, b in enumerate(branches):
        ax2.plot(b.omega, b.amplitude(0), "C0-", lw=1.8, label="1/2 sub-harmonic isola (HBM)" if k == 0 else None)
        ax2.plot(b.omega[list(b.folds)], b.amplitude(0)[list(b.folds)], "C0s", ms=7, label="folds" if k == 0 else None)
    ax2.plot(primary.omega, primary.amplitude(0), "C2-", lw=1.8, label="primary (1-periodic) branch, Harmonics(20)")
    for c in (c for c in checks if c["found"]):
        y = c["max_abs_td"]
        ax2.plot(c["omega"], y, "ko" if c["stable"] else "kx", ms=8, mfc="none" if c["stable"] else None,
                 label=None)
    ax2.plot([], [], "ko", mfc="none", label="shooting: stable (max |u|)")
    ax2.plot([], [], "kx", label="shooting: unstable (saddle)")
    for k, (a, b_) in enumerate((td_fold_low, td_fold_high)):
        ax2.axvspan(min(a, b_), max(a, b_), color="0.6", alpha=0.5, label="fold of the time integration (bracket)" if k == 0 else None)
    ax2.axhline(GAP, color="0.4", lw=1, ls="--")
    ax2.set_xlabel("forcing frequency w")
    ax2.set_ylabel("max |u|")
    ax2.set_title(f"c = {DAMPING}, F = {FORCE}, gap = {GAP}")
    ax2.legend(fontsize=8, loc="upper left")
    ax2.set_xlim(1.5, 4.5)
    fig.tight_layout()
    path = out / "subharmonic_contact.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print(report())
    print("saved", main())
