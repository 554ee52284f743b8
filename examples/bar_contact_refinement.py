"""First nonsmooth mode of a clamped bar hitting a stop: mesh refinement against the continuum.

Fixed-free bar (EA = rho A = L = 1, P1 elements), rigid stop at the free end with gap 0.01, the
backbone of mode 1 (``fm.nonlinear_mode``: past grazing, the family with a contact phase in each
period, traced by frequency) for 20, 40 and 80 elements with H = 10, 20 and 20 harmonics, with
and without mass redistribution at the contact node (Khenous, Laborde & Renard 2008). (At H = 40
on 80 elements the sweep loses the family above 5 E_g in a dense cluster of internal-resonance
tongues: left open.)

The continuum's first nonsmooth mode has a closed form (d'Alembert's solution with the Signorini
end; Yoong, Thorin & Legrand, Nonlinear Dynamics 91, 2018): the bar leaves the stop with a
uniform strain, and ``w / w1 = 4 / T``, ``T = 3 + 2 sqrt(2) / (pi sqrt(E / E_g))``, from ``w1``
at ``E = 0.81 E_g`` to ``4 w1 / 3`` as the energy grows (``E_g = pi^2 g^2 / 16``: the linear mode
touching the stop). We report ``w`` at ``E = 2, 5, 20 E_g`` on each mesh, its error against the
continuum and the observed order.
"""

import math

import numpy as np

import femodes as fm

GAP = 0.01
N_ELEMENTS = (20, 40, 80)
HARMONICS = {20: 10, 40: 20, 80: 20}
ENERGY_FACTORS = np.array([2.0, 5.0, 20.0])
W1 = math.pi / 2


def continuum_omega(energy_ratio):
    """The continuum's first nonsmooth mode at ``E / E_g`` (module docstring)."""
    T = 3.0 + 2.0 * math.sqrt(2.0) / (math.pi * np.sqrt(energy_ratio))
    return 4.0 * W1 / T


def omega_at_energy(branch, energy):
    """The backbone's frequency at ``energy``, linear in ``log E`` between its two orbits around it
    (orbits 0.5-1 % apart in frequency: the interpolation error is below 1e-4)."""
    return float(np.interp(np.log(energy), np.log(branch.energy), branch.omega, left=np.nan, right=np.nan))


def backbone_frequencies(n_elements, redistribute):
    mesh = fm.line_mesh(1.0, n_elements, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    mass = fm.RedistributeMass() if redistribute else fm.ConsistentMass()
    model = model.with_contact(fm.UnilateralContact(at="tip", gap=GAP), contact_mass=mass)
    eg = fm.grazing_energy(model)
    br = fm.nonlinear_mode(model, 1, energy=(0.5 * eg, 25 * eg), harmonics=HARMONICS[n_elements])
    # the sweep may stop short of 25 E_g (NaN beyond, the branch's message says why): in a cluster
    # of internal-resonance tongues, or with a massful contact node, whose semi-discrete problem is
    # ill-posed (impacts of a point mass; Thorin & Legrand 2018)
    # the continuum's energy unit, so that every mesh is compared at the same energies
    eg_continuum = math.pi ** 2 * GAP ** 2 / 16
    w = np.array([omega_at_energy(br, f * eg_continuum) for f in ENERGY_FACTORS])
    return w, br


reference = continuum_omega(ENERGY_FACTORS)
results, branches = {}, {}
for redistribute in (True, False):
    rows = []
    for ne in N_ELEMENTS:
        w, br = backbone_frequencies(ne, redistribute)
        rows.append(w)
        branches[(redistribute, ne)] = br
    results[redistribute] = np.array(rows)  # (len(N_ELEMENTS), len(ENERGY_FACTORS))
#: relative error against the continuum, per mesh and energy
errors = {k: v / reference - 1 for k, v in results.items()}
#: observed order of the error in h per energy (least squares on log |error| against log h)
order = {k: np.array([-np.polyfit(np.log(N_ELEMENTS), np.log(np.abs(e[:, j])), 1)[0] if np.all(np.isfinite(e[:, j]))
                      else np.nan for j in range(len(ENERGY_FACTORS))]) for k, e in errors.items()}


def figure(path="bar_contact_refinement.png"):
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    rho = np.linspace(0.82, 25, 400)
    ax.plot(continuum_omega(rho) / W1, rho, "k-", lw=2, label="continuum (d'Alembert)")
    eg = math.pi ** 2 * GAP ** 2 / 16
    for ne in N_ELEMENTS:
        br = branches[(True, ne)]
        ax.plot(br.omega / W1, br.energy / eg, ".-", ms=3, label=f"femodes, {ne} elements, H = {HARMONICS[ne]}")
    ax.set(xlabel="w / w1", ylabel="E / E_g", yscale="log", title="first nonsmooth mode")
    ax.legend(fontsize=8)
    for j, f in enumerate(ENERGY_FACTORS):
        for redistribute, style in ((True, "o-"), (False, "s--")):
            ax2.loglog(N_ELEMENTS, np.abs(errors[redistribute][:, j]), style,
                       label=f"E = {f:g} E_g, {'redistributed' if redistribute else 'consistent'} mass")
    ax2.set(xlabel="elements", ylabel="|w / w_continuum - 1|", title="error against the continuum")
    ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path


if __name__ == "__main__":
    for redistribute, label in ((True, "with mass redistribution"), (False, "without (massful contact node)")):
        print(label)
        for ne, w, e in zip(N_ELEMENTS, results[redistribute], errors[redistribute]):
            print(f"  {ne:3d} elements: w at E/E_g = {ENERGY_FACTORS} -> {np.round(w, 6)}, error {np.round(e, 5)}")
        print(f"  observed order in h: {np.round(order[redistribute], 2)}")
    print(f"continuum: {np.round(reference, 6)}")
    print("figure:", figure())
