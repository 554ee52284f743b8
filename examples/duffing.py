"""The Duffing oscillator: backbone, hardening frequency responses and coexisting limit cycles.

(a) Free Duffing ``u'' + u + eps u^3 = 0`` with eps = 1: nonlinear mode 1 (backbone) by HBM with
H = 1, 3, 9 harmonics against the exact frequency (shared/references.md)::

    w(A) = pi sqrt(1 + eps A^2) / (2 K(m)),   m = eps A^2 / (2 (1 + eps A^2)),

``K`` the complete elliptic integral of the first kind (``scipy.special.ellipk(m)``), ``A`` the
amplitude ``max |u|``. Reference values (eps = 1): A = 0.5, 1, 2, 5 -> w = 1.089158178779,
1.317776064966, 1.976016364071, 4.357461856523. The HBM error falls fast with H (the motion is
analytic: only odd harmonics, geometric convergence).

(b) Forced Duffing ``u'' + c u' + u + eps u^3 = cos(w t)`` with H = 9, three cases; reference
values (shared/references.md, H = 21 converged):

    c = 0.1, eps = 1:   peak max|u| 3.37896402 at w 3.03809479, folds 3.03905472 / 1.64624961
    c = 0.2, eps = 1:   peak max|u| 2.31894315 at w 2.20760507, folds 2.21316595 / 1.63530555
    c = 0.1, eps = 0.1: peak max|u| 5.62884200 at w 1.81659786, folds 1.81839650 / 1.33474639

The curves bend to the right (hardening) and lean on the backbone of the free system.

(c) Between the folds three periodic solutions coexist. At w = 2.0 (c = 0.1, eps = 1) they are
re-solved with ``fm.semismooth_newton`` on ``fm.ForcedResponseProblem(...).residual`` from the
nearest branch points: max|u| = 2.180126, 1.842510, 0.342901 (shared/references.md). Their
stability is *computed*, by Hill's method and by shooting (``fm.stability``): the resonant and
non-resonant cycles are stable, the middle one is a saddle (a real Floquet multiplier > 1), and
the forced branch traced with ``stability=True`` is unstable exactly between its two folds.
"""

import dataclasses

import numpy as np
from scipy.special import ellipk

import femodes as fm

EPS = 1.0
H_BACKBONE = (1, 3, 9)
A_CHECK = np.array([0.5, 1.0, 2.0, 5.0])
W_CHECK_REF = np.array([1.089158178779, 1.317776064966, 1.976016364071, 4.357461856523])


def exact_frequency(A, eps=EPS):
    """Exact frequency of the free Duffing oscillator at amplitude A (elliptic integral)."""
    A2 = eps * np.asarray(A, dtype=float) ** 2
    return np.pi * np.sqrt(1.0 + A2) / (2.0 * ellipk(A2 / (2.0 * (1.0 + A2))))


def duffing(c=0.0, eps=EPS, force=None):
    model = fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[c]] if c else None)
    model = model.with_nonlinearity(fm.CubicSpring(at=0, k3=eps))
    return model.with_forcing(fm.HarmonicForce(at=0, amplitude=force)) if force else model


# (a) backbones: energy E = A^2/2 + eps A^4/4 up to ~400 (A ~ 6.2)
backbones = {H: fm.nonlinear_mode(duffing(), 1, energy=(1e-3, 400.0), harmonics=H) for H in H_BACKBONE}
# pointwise relative error w_HBM / w_exact(A) - 1 along each branch, for A <= 5
backbone_error = {H: float(np.max(np.abs(bb.omega / exact_frequency(bb.amplitude(0)) - 1)[bb.amplitude(0) <= 5.0]))
                  for H, bb in backbones.items()}
# HBM frequency at the reference amplitudes (interpolating the smooth ratio w_HBM / w_exact)
backbone_omega = {H: W_CHECK_REF * np.interp(A_CHECK, bb.amplitude(0), bb.omega / exact_frequency(bb.amplitude(0)))
                  for H, bb in backbones.items()}
backbone_eps01 = fm.nonlinear_mode(duffing(eps=0.1), 1, energy=(1e-3, 400.0), harmonics=9)

# (b) forced responses, H = 9
H_FORCED = fm.Harmonics(9)
CASES = {(0.1, 1.0): dict(peak=3.37896402, w_peak=3.03809479, folds=(3.03905472, 1.64624961)),
         (0.2, 1.0): dict(peak=2.31894315, w_peak=2.20760507, folds=(2.21316595, 1.63530555)),
         (0.1, 0.1): dict(peak=5.62884200, w_peak=1.81659786, folds=(1.81839650, 1.33474639))}
FORCED_OPTIONS = fm.ContinuationOptions(step=0.05, max_step=0.1, newton=fm.NewtonOptions(atol=1e-9, max_iter=20))
forced = {key: fm.frequency_response(duffing(*key, force=1.0), (0.5, 4.0), H_FORCED, options=FORCED_OPTIONS,
                                     stability=True)
          for key in CASES}
folds = {key: br.omega[list(br.folds)] for key, br in forced.items()}
peaks = {key: float(br.amplitude(0).max()) for key, br in forced.items()}

# (c) the three coexisting solutions at w = 2.0 (c = 0.1, eps = 1)
W_COEXIST = 2.0
COEXIST_REF = np.array([2.180126, 1.842510, 0.342901])
_branch = forced[(0.1, 1.0)]
_problem = fm.ForcedResponseProblem(duffing(0.1, 1.0, force=1.0), H_FORCED)


def solve_at(branch, problem, omega):
    """All solutions of ``branch`` at frequency ``omega``: Newton from the nearest points."""
    s = branch.omega - omega
    crossings = np.nonzero(np.sign(s[:-1]) != np.sign(s[1:]))[0]
    sols = []
    for i in crossings:
        j = i if abs(s[i]) < abs(s[i + 1]) else i + 1
        x0 = problem.system.join(branch.Q[j], branch.P[j])
        res = fm.semismooth_newton(lambda x: problem.residual(x, omega)[:2], x0,
                                   options=fm.NewtonOptions(atol=1e-12, max_iter=30))
        assert res.success, res.message
        Q, P = problem.system.split(res.x)
        sols.append(dataclasses.replace(branch[j], omega=float(omega), Q=Q, P=P, energy=np.nan,
                                        residual_norm=float(np.max(np.abs(problem.residual(res.x, omega)[0])))))
    return sols


coexisting = solve_at(_branch, _problem, W_COEXIST)  # in branch order: resonant, unstable, non-resonant
coexisting_amplitude = np.array([sol.amplitude(0) for sol in coexisting])
# their stability, by both methods (Floquet multipliers, largest modulus first)
coexisting_stability = [{m.name: fm.stability(sol, method=m) for m in (fm.stability_methods.Hill(), fm.stability_methods.Shooting())}
                        for sol in coexisting]
coexisting_stable = [st["hill"].stable for st in coexisting_stability]


def main(out="out"):
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(15, 4.4))
    A = np.linspace(1e-3, 6.2, 400)
    ax1.plot(exact_frequency(A), A**2 / 2 + EPS * A**4 / 4, "k:", lw=2, label="exact (elliptic)")
    fm.plot.frequency_energy([backbones[H] for H in H_BACKBONE], ax=ax1, labels=[f"HBM, H = {H}" for H in H_BACKBONE])
    ax1.set_title("free Duffing (eps = 1): backbone")
    ax1.legend(fontsize=8, loc="upper left")
    inset = ax1.inset_axes([0.5, 0.12, 0.45, 0.4])
    for H in H_BACKBONE:
        bb = backbones[H]
        inset.semilogy(bb.amplitude(0), np.abs(bb.omega / exact_frequency(bb.amplitude(0)) - 1), lw=1)
    inset.set_xlim(0, 6)
    inset.set_xlabel("A = max|u|", fontsize=7)
    inset.set_ylabel("|w/w_exact - 1|", fontsize=7)
    inset.tick_params(labelsize=7)

    ax2.plot(backbones[9].omega, backbones[9].amplitude(0), "k:", lw=1.2, label="backbone eps = 1")
    ax2.plot(backbone_eps01.omega, backbone_eps01.amplitude(0), "k--", lw=1.0, label="backbone eps = 0.1")
    for key, br in forced.items():
        a = br.amplitude(0)
        solid = np.where(br.stable, a, np.nan)
        (line,) = ax2.plot(br.omega, solid, lw=1.5, label=f"c = {key[0]}, eps = {key[1]}")
        ax2.plot(br.omega, np.where(br.stable, np.nan, a), "--", lw=1.5, color=line.get_color())
        ax2.plot(br.omega[list(br.folds)], a[list(br.folds)], "kx")
    ax2.plot([W_COEXIST] * 3, coexisting_amplitude, "o", mfc="none", color="C3", label="w = 2.0 (panel 3)")
    ax2.set_xlim(0.5, 4.0)
    ax2.set_ylim(0, 6.5)
    ax2.set_xlabel("w [rad/s]")
    ax2.set_ylabel("max |u|")
    ax2.set_title("forced Duffing, F = 1, H = 9 (folds x, unstable dashed)")
    ax2.legend(fontsize=8)

    for sol, st, name in zip(coexisting, coexisting_stability, ("resonant", "middle", "non-resonant")):
        mu = st["hill"].multipliers[0]
        word = "stable" if st["hill"].stable else "unstable"
        fm.plot.phase_portrait(sol, 0, ax=ax3, label=f"{name} ({word}, |mu| = {abs(mu):.3f}): max|u| = {sol.amplitude(0):.4f}")
    ax3.set_title("three coexisting cycles at w = 2.0 (c = 0.1, eps = 1)")
    ax3.legend(fontsize=8)
    fig.tight_layout()
    path = out / "duffing.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print("free Duffing eps = 1, w at A =", A_CHECK, "exact", W_CHECK_REF)
    for H in H_BACKBONE:
        print(f"  H = {H}: {np.round(backbone_omega[H], 9)}  max rel. error (A <= 5) {backbone_error[H]:.2e}")
    for key, br in forced.items():
        ref = CASES[key]
        print(f"c = {key[0]}, eps = {key[1]}: folds {np.round(folds[key], 8)} (ref {ref['folds']}), "
              f"max|u| on branch {peaks[key]:.6f} (ref peak {ref['peak']}), {len(br)} points")
    print(f"coexisting at w = {W_COEXIST}: max|u| = {np.round(coexisting_amplitude, 6)} (ref {COEXIST_REF})")
    for st in coexisting_stability:
        print("   ", "stable  " if st["hill"].stable else "UNSTABLE",
              "largest |mu|: Hill", f"{abs(st['hill'].multipliers[0]):.8f}", "shooting",
              f"{abs(st['shooting'].multipliers[0]):.8f}")
    print("saved", main())
