"""Travelling along the resonance of the forced contact oscillator: motion and contact force.

The mission's case 1 (Shi & Legrand 2016): ``u'' + 0.1 u' + u = 0.2 cos(w t) - p`` with a rigid
stop at gap 1 (Signorini complementarity ``g = 1 - u >= 0, p >= 0, p g = 0``), H = 20 harmonics,
w from 0.5 to 2.0. The branch bends to the right like a hardening oscillator: the stop adds
stiffness once ``max u`` reaches the gap. Six points are picked along the branch:

1. before contact (w ~ 0.8): the linear response, ``p = 0``;
2. first contact (the first point with ``max u >= 1``, w ~ 0.907): grazing;
3. the upper fold (w ~ 1.385, max u ~ 1.727): one impact per period, the largest contact force;
4. on the unstable branch between the folds (w ~ 1.32);
5. the lower fold (w ~ 1.081, max u ~ 1.0015): grazing again, a tiny contact force;
6. after the resonance (w ~ 1.6 on the lower branch): no contact.

For each, one period of the displacement and of the contact force ``p(t)`` (small multiples).
With truncated Fourier series the contact force is a smoothed impulse and the stop is slightly
penetrated (``max u - 1`` up to 0.04, decreasing slowly with H, see examples/time_vs_hbm.py).
The reference fold frequencies are those of examples/contact_oscillator.py (same model and H).
"""

import numpy as np

import femodes as fm

GAP = 1.0
H = fm.Harmonics(20)
model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
         .with_contact(fm.UnilateralContact(at=0, gap=GAP))
         .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
branch = fm.frequency_response(model, (0.5, 2.0), H)
amplitude = branch.amplitude(0)
upper_fold, lower_fold = branch.folds[0], branch.folds[-1]
first_contact = int(np.argmax(amplitude >= GAP))
before = int(np.argmin(np.abs(branch.omega[:first_contact] - 0.8)))
unstable = int(np.argmin(np.abs(branch.omega[upper_fold:lower_fold] - 1.32))) + upper_fold
after = int(np.argmin(np.abs(branch.omega[lower_fold:] - 1.6))) + lower_fold

PICKS = {"before contact": before, "first contact": first_contact, "upper fold": upper_fold,
         "unstable branch": unstable, "lower fold": lower_fold, "after resonance": after}
solutions = {name: branch[i] for name, i in PICKS.items()}


def _one_period(sol, n=800):
    t = np.linspace(0.0, sol.period, n)
    return t, sol.displacement(t)[:, 0], sol.contact_force(t)[:, 0]


max_contact_force = {name: float(_one_period(sol)[2].max()) for name, sol in solutions.items()}
penetration = {name: sol.penetration for name, sol in solutions.items()}


def main(out="out"):
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig = plt.figure(figsize=(14, 5.6))
    grid = fig.add_gridspec(2, 5, width_ratios=[1.5, 0.08, 1, 1, 1])
    ax0 = fig.add_subplot(grid[:, 0])
    ax0.plot(branch.omega, amplitude, "k-", lw=1.2)
    ax0.axhline(GAP, color="0.6", ls=":", lw=1)
    for k, (name, i) in enumerate(PICKS.items()):
        ax0.plot(branch.omega[i], amplitude[i], "o", color=f"C{k}", ms=7)
        ax0.annotate(str(k + 1), (branch.omega[i], amplitude[i]), textcoords="offset points", xytext=(6, 4))
    ax0.set_xlabel("w [rad/s]")
    ax0.set_ylabel("max u")
    ax0.set_title("case 1, H = 20: points 1-6 along the branch")
    for k, (name, sol) in enumerate(solutions.items()):
        ax = fig.add_subplot(grid[k // 3, 2 + k % 3])
        t, u, p = _one_period(sol)
        ax.plot(t / sol.period, u, color=f"C{k}", lw=1.5)
        ax.axhline(GAP, color="0.6", ls=":", lw=1)
        ax.set_ylim(-1.9, 1.9)
        ax.set_title(f"{k + 1}. {name}, w = {sol.omega:.3f}", fontsize=9)
        twin = ax.twinx()
        twin.fill_between(t / sol.period, 0, p, color="0.3", alpha=0.35, lw=0)
        twin.set_ylim(-1, 15)
        if k % 3 == 2:
            twin.set_ylabel("contact force p", fontsize=8)
        else:
            twin.set_yticklabels([])
        if k % 3 == 0:
            ax.set_ylabel("u", fontsize=8)
        if k >= 3:
            ax.set_xlabel("t / T", fontsize=8)
        ax.tick_params(labelsize=7)
        twin.tick_params(labelsize=7)
    fig.tight_layout()
    path = out / "travelling_resonance.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print(f"{len(branch)} points, folds at w = {np.round(branch.omega[list(branch.folds)], 5)}")
    print("  #  point              w        max u    max p     penetration")
    for k, (name, i) in enumerate(PICKS.items()):
        print(f"  {k + 1}  {name:17s} {branch.omega[i]:.5f}  {amplitude[i]:.5f}  {max_contact_force[name]:8.4f}  "
              f"{penetration[name]:.2e}")
    print("saved", main())
