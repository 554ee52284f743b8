"""Penalty contact against complementarity (Signorini) contact on the forced contact oscillator.

Case 1 of the mission (Shi & Legrand 2016): ``u'' + 0.1 u' + u = 0.2 cos(w t) - p``, obstacle at
``u = 1``, H = 20 harmonics. Two contact laws:

* ``fm.PenaltyContact(stiffness=k)``: ``p = k max(0, u - 1)`` (a stiff spring, penetration of
  order ``p / k``), k = 1e1, 1e2, 1e3, 1e4;
* ``fm.UnilateralContact``: ``g = 1 - u >= 0, p >= 0, p g = 0`` through the complementarity
  function ``p - max(0, p - c g)``; c = None (default: the static stiffness at the contact DOF,
  here 1) for the response curve, and c = k for the point-wise comparison.

Frequency responses over w in [0.95, 2.0] (the k = 1e4 penalty continuation started at 0.5 stalled
at grazing, w ~ 0.9065, without frequency_response's target_norm_change; below 0.95 all curves are
the linear response, max u < 1). At w = 1.05
(a single solution, below the lower fold ~1.081) each model is re-solved with
``fm.semismooth_newton`` for the table. Values measured independently (shared notes): penalty
penetration 0.1705, 0.0440, 0.0103, 0.00225 for k = 1e1..1e4 at w = 1.05, i.e. ~ 1/k^(2/3)
(the contact force and contact duration change with k); the distance between penalty(k) and
complementarity(c = k) falls 4.7-9x per decade. The penalty curve with k = 1e4 is close to the
complementarity one: the Signorini solution is the limit k -> infinity. Runs in about 20 s.
"""

import dataclasses

import numpy as np

import femodes as fm

GAP = 1.0
H = fm.Harmonics(20)
STIFFNESSES = (1e1, 1e2, 1e3, 1e4)
W_TABLE = 1.05
SPAN = (0.95, 2.0)
OPTIONS = fm.ContinuationOptions(step=0.05, max_step=0.2, newton=fm.NewtonOptions(atol=1e-9, max_iter=20))


def case1(law):
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(law)
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


def penalty(k):
    return fm.PenaltyContact(at=0, gap=GAP, stiffness=k)


complementarity = fm.frequency_response(case1(fm.UnilateralContact(at=0, gap=GAP)), SPAN, H, options=OPTIONS)
penalty_branches = {k: fm.frequency_response(case1(penalty(k)), SPAN, H, options=OPTIONS) for k in STIFFNESSES}
branch_success = {k: br.success for k, br in penalty_branches.items()}
peak_amplitude = {k: float(br.amplitude(0).max()) for k, br in penalty_branches.items()}
max_penetration = {k: float(br.penetration.max()) for k, br in penalty_branches.items()}
peak_amplitude_complementarity = float(complementarity.amplitude(0).max())
max_penetration_complementarity = float(complementarity.penetration.max())


def solve_point(model, start, omega=W_TABLE):
    """Re-solve ``model`` at ``omega`` with semismooth Newton from the PeriodicSolution ``start``."""
    problem = fm.ForcedResponseProblem(model, H)
    P = start.P if problem.system.n_uc else None
    res = fm.semismooth_newton(lambda x: problem.residual(x, omega)[:2], problem.system.join(start.Q, P),
                               options=fm.NewtonOptions(atol=1e-11, max_iter=50))
    if not res.success:
        raise RuntimeError(f"no solution at w = {omega}: {res.message}")
    Q, P = problem.system.split(res.x)
    return dataclasses.replace(start, omega=float(omega), Q=Q, P=P, energy=np.nan,
                               residual_norm=float(np.max(np.abs(problem.residual(res.x, omega)[0]))))


def nearest(branch, omega=W_TABLE):
    return branch[int(np.argmin(np.abs(branch.omega - omega)))]


_t = np.linspace(0.0, 2 * np.pi / W_TABLE, 4001)
penalty_at_w = {k: solve_point(case1(penalty(k)), nearest(penalty_branches[k])) for k in STIFFNESSES}
complementarity_at_w = {}
_start = nearest(complementarity)
for k in STIFFNESSES:  # continuation in c: each solve starts from the previous one
    _start = complementarity_at_w[k] = solve_point(case1(fm.UnilateralContact(at=0, gap=GAP, c=k)), _start)
penetration_at_w = {k: float(sol.displacement(_t)[:, 0].max() - GAP) for k, sol in penalty_at_w.items()}
penetration_complementarity_at_w = {k: float(sol.displacement(_t)[:, 0].max() - GAP)
                                    for k, sol in complementarity_at_w.items()}
# max_t |u_penalty(t) - u_complementarity(t)| at w = 1.05, penalty(k) against complementarity(c = k)
distance = {k: float(np.abs(penalty_at_w[k].displacement(_t) - complementarity_at_w[k].displacement(_t)).max())
            for k in STIFFNESSES}


def table():
    lines = ["   k        branch   peak max u   max penetr.   penetr. w=1.05   complem. c=k penetr.   distance",
             f"   complementarity (c = 1)  {peak_amplitude_complementarity:.5f}     {max_penetration_complementarity:.5f}"]
    for k in STIFFNESSES:
        lines.append(f"   {k:7.0e}  {'ok' if branch_success[k] else 'STALLED':7s}  {peak_amplitude[k]:.5f}     "
                     f"{max_penetration[k]:.5f}       {penetration_at_w[k]:.5f}          "
                     f"{penetration_complementarity_at_w[k]:.5f}              {distance[k]:.2e}")
    return "\n".join(lines)


def main(out="out"):
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.4), gridspec_kw={"width_ratios": [1.4, 1]})
    ax1.plot(complementarity.omega, complementarity.amplitude(0), "k-", lw=2.2, label="complementarity (c = 1)")
    for j, (k, br) in enumerate(penalty_branches.items()):
        ax1.plot(br.omega, br.amplitude(0), color=f"C{j}", lw=1.2, label=f"penalty k = {k:.0e}")
    ax1.axhline(GAP, color="0.6", ls=":", lw=1)
    ax1.axvline(W_TABLE, color="0.6", ls="--", lw=0.8)
    ax1.set_xlabel("w [rad/s]")
    ax1.set_ylabel("max u")
    ax1.set_title("case 1, H = 20: response curves")
    ax1.legend(fontsize=8)
    k = np.array(STIFFNESSES)
    ax2.loglog(k, [max_penetration[s] for s in STIFFNESSES], "o-", label="penalty: max penetration on branch")
    ax2.loglog(k, [penetration_at_w[s] for s in STIFFNESSES], "s-", label=f"penalty: penetration at w = {W_TABLE}")
    ax2.loglog(k, [penetration_complementarity_at_w[s] for s in STIFFNESSES], "^-",
               label=f"complementarity c = k: penetration at w = {W_TABLE}")
    ax2.loglog(k, [distance[s] for s in STIFFNESSES], "kd--", label="max|u_pen - u_compl(c = k)| at w = 1.05")
    ax2.set_xlabel("penalty stiffness k (= c)")
    ax2.set_title("convergence with the stiffness")
    ax2.legend(fontsize=7)
    fig.tight_layout()
    path = out / "penalty_vs_complementarity.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print(table())
    ratios = [distance[a] / distance[b] for a, b in zip(STIFFNESSES, STIFFNESSES[1:])]
    print("distance reduction per decade:", np.round(ratios, 2))
    print("saved", main())
