"""First nonsmooth mode of a clamped bar hitting a stop: convergence to the continuum, with rates.

Fixed-free bar (EA = rho A = L = 1, P1 elements), rigid stop at the free end with gap 0.01, the
backbone of mode 1 (``fm.nonlinear_mode``: past grazing, the family with a contact phase in each
period, traced by frequency).

The continuum's first nonsmooth mode has a closed form (d'Alembert's solution with the Signorini
end; Yoong, Thorin & Legrand, Nonlinear Dynamics 91, 2018): ``w / w1 = 4 / T``,
``T = 3 + 2 sqrt(2) / (pi sqrt(E / E_g))``, from ``w1`` at ``E = 0.81 E_g`` to ``4 w1 / 3`` as the
energy grows (``E_g = pi^2 g^2 / 16``: the linear mode touching the stop).

The discrete backbone's error has three parts (benchmarks/README_bar_convergence.md):

* harmonic truncation: a bias, the family's frequency too low by 0.4 % (H = 10), 0.3 % (H = 20),
  0.2 % (H = 40) on 160 elements. Measured here as the mean error of the orbits between 2 and
  8 E_g on 160 elements, for H = 10, 20, 40; its rate ``|mean| ~ H^-q``. The rate is weakly
  determined: the study (benchmarks/README_bar_convergence.md), whose runs with H = 15-80 reach
  25 E_g since the sweep is guided by the family with 10 harmonics, finds at most a slow fall over
  H = 10-40 with H = 15 and 30 added (q = 0.5 +- 0.3 on 160 elements, 0.0 +- 0.2 on 320), and
  0.1 % at H = 60-80 on 320 elements; at H = 5 the bias has the other sign.
* the mesh: at a fixed H (10) and fixed frequencies, the orbits converge as the mesh is refined.
  Measured here by the median change of the error at 13 frequencies between a mesh and the one
  twice as fine (20 to 160 elements), with and without mass redistribution at the contact node;
  its rate ``~ N^-p``.
* scatter around the bias from the tongues of internal resonance the sweep steps over (the
  fixed-free bar's spectrum is commensurate, 1:3:5:7...): orbits beside a tongue are pulled by up
  to 1 %, and this scatter does not fall with refinement. A single orbit's error therefore has no
  rate; the family's mean and the orbits at fixed frequency do.

Coarse meshes look better than fine ones at H = 10 (0.1 % against 0.4 %): the mesh error there is
of the other sign and cancels the harmonic one.
"""

import math

import numpy as np

import femodes as fm
from femodes.hbm import PeriodDrivenModeProblem
from femodes.nonsmooth_modes import modal_energy_fractions
from femodes.solvers import NewtonOptions, semismooth_newton

GAP = 0.01
W1 = math.pi / 2
EG = math.pi ** 2 * GAP ** 2 / 16  # the continuum's grazing energy: every mesh compared at the same energies
SPAN = (2.0, 8.0)                  # E / E_g of the family's mean (every run reaches 8 E_g)
N_FINE = 160
HARMONICS = (10, 20, 40)
MESHES = (20, 40, 80, 160)
H_MESH = 10


def continuum_omega(energy_ratio):
    """The continuum's first nonsmooth mode at ``E / E_g`` (module docstring)."""
    return 4.0 * W1 / (3.0 + 2.0 * math.sqrt(2.0) / (math.pi * np.sqrt(energy_ratio)))


def bar(n_elements, redistribute=True):
    mesh = fm.line_mesh(1.0, n_elements, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    mass = fm.RedistributeMass() if redistribute else fm.ConsistentMass()
    return model.with_contact(fm.UnilateralContact(at="tip", gap=GAP), contact_mass=mass)


def backbone(n_elements, H, redistribute=True):
    model = bar(n_elements, redistribute)
    eg = fm.grazing_energy(model)
    return fm.nonlinear_mode(model, 1, energy=(0.5 * eg, 25 * eg), harmonics=H)


def orbit_errors(branch):
    """``(E / E_g, w / w_continuum - 1)`` of the branch's orbits above grazing."""
    r = branch.energy / EG
    keep = r > 1.0
    return r[keep], branch.omega[keep] / continuum_omega(r[keep]) - 1.0


def log_slope(x, y, sigma=None):
    """Least-squares slope of ``log y`` against ``log x`` (weights ``1 / sigma`` of ``log y``) and its
    standard error (from the residuals, at least from the weights)."""
    lx, ly = np.log(x), np.log(y)
    wts = np.ones_like(lx) if sigma is None else 1.0 / np.asarray(sigma)
    A = np.column_stack([lx, np.ones_like(lx)]) * wts[:, None]
    coef, *_ = np.linalg.lstsq(A, ly * wts, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    res = (ly - coef[0] * lx - coef[1]) * wts
    dof = max(lx.size - 2, 1)
    scale = max(float(res @ res) / dof, 1.0 if sigma is not None else 0.0)
    return float(coef[0]), float(math.sqrt(cov[0, 0] * scale))


# --- harmonic truncation: backbones on the fine mesh, H = 10, 20, 40 -----------------------------
branches = {H: backbone(N_FINE, H) for H in HARMONICS}
mean_error, mean_sigma = [], []
for H in HARMONICS:
    r, e = orbit_errors(branches[H])
    e = e[(r >= SPAN[0]) & (r <= SPAN[1])]
    mean_error.append(float(np.mean(e)))
    mean_sigma.append(float(np.std(e, ddof=1) / math.sqrt(e.size)))  # standard error of the mean
mean_error, mean_sigma = np.array(mean_error), np.array(mean_sigma)
#: rate of the harmonic error, |mean| ~ H^-q, and its standard error
q, q_sigma = (lambda s: (-s[0], s[1]))(log_slope(HARMONICS, np.abs(mean_error), mean_sigma / np.abs(mean_error)))


# --- the mesh at H = 10: orbits at fixed frequencies, nested ------------------------------------
def fixed_frequency_errors(redistribute, n_freq=13):
    """Errors at the reference's frequencies for ``E = 2 ... 20 E_g`` (geometric) on each mesh of
    MESHES with H_MESH harmonics: the coarsest mesh's orbits interpolated from its backbone, each finer
    mesh's solved by Newton at the same frequency from the coarser orbit (nodal values interpolated).
    NaN where a solve fails or the orbit left the family (mode 1 with less than 25 % of the energy,
    the rule of ``fm.PeriodDriven``, or below grazing)."""
    ws = continuum_omega(np.geomspace(2.0, 20.0, n_freq))
    br = backbone(MESHES[0], H_MESH, redistribute)
    o = np.argsort(br.omega)
    states = [tuple(np.apply_along_axis(lambda c: np.interp(w, br.omega[o], c), 0, A[o]) for A in (br.Q, br.P))
              for w in ws]
    errors = np.full((len(MESHES), n_freq), np.nan)
    for i, n in enumerate(MESHES):
        model = bar(n, redistribute)
        pd = PeriodDrivenModeProblem(model, fm.Harmonics(n_harmonics=H_MESH), 1, reference_energy=EG)
        lm = fm.linear_modes(model, n=12)
        for k, w in enumerate(ws):
            Q, P = states[k]
            while Q.shape[1] < model.n_dofs:  # to the mesh twice as fine: P1 interpolation from the clamp
                fine = np.zeros((Q.shape[0], 2 * Q.shape[1]))
                fine[:, 1::2] = Q
                fine[:, 0::2] = 0.5 * (np.concatenate([np.zeros((Q.shape[0], 1)), Q[:, :-1]], axis=1) + Q)
                Q = fine
            res = semismooth_newton(lambda z, w=w: pd.residual(z, w)[:2], pd.pack(Q, P, w),
                                    options=NewtonOptions(atol=1e-9, max_iter=40))
            if not res.success:
                continue
            u = pd.unpack(res.x, 0.0)
            states[k] = (u.Q, u.P)
            E = float(pd.system.energy(res.x[: pd.system.size], w)[0]) / EG
            share = modal_energy_fractions(pd, res.x, lm.omega, lm.shapes)[0]
            if share >= 0.25 and E > 1.0:
                errors[i, k] = w / continuum_omega(E) - 1.0
    return ws, errors


mesh_errors, mesh_change, mesh_rate = {}, {}, {}
for redistribute in (True, False):
    ws, err = fixed_frequency_errors(redistribute)
    mesh_errors[redistribute] = err
    ok = np.all(np.isfinite(err), axis=0)           # frequencies on the family on every mesh
    #: median over the frequencies of |error(2N) - error(N)|, for N = 20, 40, 80
    mesh_change[redistribute] = np.median(np.abs(np.diff(err[:, ok], axis=0)), axis=1)
    #: rate p of that change, ~ N^-p, and its standard error
    s, ds = log_slope(MESHES[:-1], mesh_change[redistribute])
    mesh_rate[redistribute] = (-s, ds)


def figure(path="bar_contact_refinement.png"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    ax = axes[0, 0]
    rho = np.geomspace(0.82, 25, 400)
    ax.plot(continuum_omega(rho) / W1, rho, "k-", lw=2, label="continuum (d'Alembert)")
    for H in HARMONICS:
        br = branches[H]
        ax.plot(br.omega / W1, br.energy / EG, ".", ms=4, label=f"femodes, {N_FINE} elements, H = {H}")
    ax.set(xlabel="w / w1", ylabel="E / E_g", yscale="log", title="first nonsmooth mode of the bar")
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    for H, m in zip(HARMONICS, mean_error):
        r, e = orbit_errors(branches[H])
        line, = ax.semilogx(r, 100 * e, ".-", ms=4, lw=0.5, label=f"H = {H} (mean {100 * m:+.2f} % in 2-8 E_g)")
        ax.hlines(100 * m, *SPAN, color=line.get_color(), lw=2)
    ax.axhline(0, color="k", lw=0.8)
    ax.set(xlabel="E / E_g", ylabel="w / w_continuum - 1 (%)", title=f"orbits' errors, {N_FINE} elements",
           ylim=(-1.5, 1.0))
    ax.legend(fontsize=8)
    ax = axes[1, 0]
    ax.errorbar(HARMONICS, 100 * np.abs(mean_error), 100 * mean_sigma, fmt="o", capsize=3,
                label="|mean error| over 2-8 E_g (+- standard error)")
    Hs = np.array([8, 50])
    c = np.exp(np.mean(np.log(np.abs(mean_error)) + q * np.log(HARMONICS)))
    ax.loglog(Hs, 100 * c * Hs ** -q, "k--", label=f"H^-{q:.2f} (+- {q_sigma:.2f})")
    ax.set(xlabel="harmonics H", ylabel="%", title=f"harmonic truncation, {N_FINE} elements")
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    for redistribute, style in ((True, "o-"), (False, "s--")):
        p, dp = mesh_rate[redistribute]
        ax.loglog(MESHES[:-1], 100 * mesh_change[redistribute], style,
                  label=f"{'redistributed' if redistribute else 'consistent'} mass: N^-{p:.2f} (+- {dp:.2f})")
    ax.set(xlabel="elements N", ylabel="median |error(2N) - error(N)| (%)",
           title=f"mesh, H = {H_MESH}, 13 fixed frequencies")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print(f"continuum: w / w1 at E = 2, 5, 20 E_g: {np.round(continuum_omega(np.array([2.0, 5.0, 20.0])) / W1, 6)}")
    for H, m, s in zip(HARMONICS, mean_error, mean_sigma):
        r, e = orbit_errors(branches[H])
        print(f"{N_FINE} elements, H = {H:2d}: mean error over {SPAN[0]:g}-{SPAN[1]:g} E_g {m:+.3%} (+- {s:.3%}), "
              f"orbits within {np.max(np.abs(e[(r >= 2) & (r <= 20)])):.2%}, reached {r.max():.1f} E_g")
    print(f"harmonic rate: |mean error| ~ H^-q, q = {q:.2f} +- {q_sigma:.2f}")
    for redistribute in (True, False):
        p, dp = mesh_rate[redistribute]
        print(f"mesh (H = {H_MESH}), {'redistributed' if redistribute else 'consistent'} mass: median change "
              + ", ".join(f"{n}->{2 * n}: {c:.3%}" for n, c in zip(MESHES, mesh_change[redistribute]))
              + f"; rate p = {p:.2f} +- {dp:.2f}")
    print("figure:", figure())
