"""The mission's 1-DOF contact oscillator: backbone and forced responses on frequency-energy axes.

Free system ``u'' + u = -p`` with a rigid stop at gap 1 (complementarity contact), and the forced
cases of Shi & Legrand (2016): ``u'' + 0.1 u' + u = 0.2 cos(w t) - p`` (gap 1) and
``u'' + 0.2 u' + u = cos(w t) - p`` (gap 2.5), all with H = 20 harmonics.

Reference for the backbone: with restitution 1 the free impacting oscillator moves on arcs of
``A cos t`` reflected at ``u = g``, so for ``A = sqrt(2 E) > g`` its frequency is
``w = pi / (pi - arccos(g / A))`` (below grazing, ``w = 1``). Harmonic balance with Signorini
conditions converges to it slowly (algebraically in H) because the velocity jumps at impacts.
"""

import numpy as np

import femodes as fm

H = fm.Harmonics(20)
GAP = 1.0

free = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=GAP))
backbone = fm.nonlinear_mode(free, 1, energy=(0.1, 20.0), harmonics=H,
                             options=fm.ContinuationOptions(step=0.05, max_step=0.1,
                                                            newton=fm.NewtonOptions(atol=1e-9, max_iter=20)))


def impact_frequency(energy, gap=GAP):
    """Exact frequency of the free impacting oscillator (restitution 1)."""
    A = np.sqrt(2.0 * np.asarray(energy, dtype=float))
    return np.where(A > gap, np.pi / (np.pi - np.arccos(np.minimum(gap / A, 1.0))), 1.0)


backbone_error = backbone.omega / impact_frequency(backbone.energy) - 1

case1 = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
         .with_contact(fm.UnilateralContact(at=0, gap=1.0))
         .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
case2 = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.2]])
         .with_contact(fm.UnilateralContact(at=0, gap=2.5))
         .with_forcing(fm.HarmonicForce(at=0, amplitude=1.0)))
forced1 = fm.frequency_response(case1, (0.5, 2.0), H)
forced2 = fm.frequency_response(case2, (0.5, 2.0), H)


def main(out="out"):
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    E = np.logspace(-1, np.log10(20), 400)
    ax1.plot(impact_frequency(E), E, "k:", lw=1.5, label="exact impact oscillator (e = 1)")
    ax1.plot(backbone.omega, backbone.energy, "C0-", lw=2, label="HBM backbone, H = 20")
    ax1.plot(forced1.omega, forced1.energy, "C1-", lw=1, label="forced, c = 0.1, F = 0.2")
    ax1.set_yscale("log")
    ax1.set_xlabel("w [rad/s]")
    ax1.set_ylabel("energy")
    ax1.set_title("frequency-energy: backbone (gap 1) and forced curve")
    ax1.legend(fontsize=8)
    for br, label in ((forced1, "case 1: c = 0.1, F = 0.2, gap 1"), (forced2, "case 2: c = 0.2, F = 1, gap 2.5")):
        a = br.amplitude(0)
        ax2.plot(br.omega, a, lw=1.5, label=label)
        ax2.plot(br.omega[list(br.folds)], a[list(br.folds)], "kx")
    ax2.set_xlabel("w [rad/s]")
    ax2.set_ylabel("max |u|")
    ax2.set_title("forced responses (folds marked x)")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    path = out / "contact_oscillator.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


if __name__ == "__main__":
    for E in (0.4, 1.0, 2.0, 8.0):
        w = np.interp(np.log(E), np.log(backbone.energy), backbone.omega)
        print(f"E = {E:4.1f}: HBM w = {w:.5f}, exact impact w = {float(impact_frequency(E)):.5f}")
    for name, br in (("case 1", forced1), ("case 2", forced2)):
        print(f"{name}: {len(br)} points, folds at w = {np.round(br.omega[list(br.folds)], 5)}, "
              f"Newton iterations per point {br.nit.mean():.2f} (max {br.nit.max()})")
    print("saved", main())
