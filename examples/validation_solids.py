"""Nonlinear verification of meshed solids with contact against 1-D bars and beams (issue 15).

Three studies, all with harmonic balance at H = 10, computed at import; ``main(out)`` draws them
into ``validation_solids.png``; ``python examples/validation_solids.py`` prints the tables.

1. **Axial strip against the bar** (``axial``, ``vertical_family``). Plane-stress strip, L = 1,
   height 0.1, thickness 1, E = rho = 1, nu = 0, Q1 quadrilaterals, ny = 2, rollers
   (``u_y = 0``) on "top" and "bottom" and ``u_x = 0`` on "left"; a rigid stop on the whole end
   face "right" (gap 0.01, one contact per node). The bar: P1, EA = rho A = 0.1, stop at its tip.
   With nu = 0 the y-uniform axial motion of the Q1 strip *is* the P1 bar (tensor-product mass
   and stiffness), so the two are one discrete problem when (i) the face keeps its consistent
   mass and (ii) each face node has the bar's complementarity parameter ``c`` times its
   consistent weight ``w_j`` (the truncated-Fourier solution depends on ``c``, see
   ``fm.UnilateralContact``; ``face_contacts`` below). Then every point of the strip's branches,
   restricted to one row of nodes (contact forces summed), satisfies the bar's HBM equations to
   the continuation's tolerance (largest scaled residual 3.2e-10 on the backbone, 9.9e-10 on the
   forced response) and the folds of the forced response agree to 9 digits (1.697505 and
   1.6303587 at 20 elements). With femodes' default ``c`` (the point stiffness ``1/(K^-1)_jj`` of
   each node) the upper fold moves by -0.56 % (1.70240 instead of 1.71199): that is the HBM's
   dependence on ``c``, not the solid (``c/4`` and ``4c`` move the bar's upper fold by +0.65 %
   and -0.72 %). With the default mass redistribution the face is made massless differently in 2-D
   (point masses on two rings of interior nodes) and 1-D (two nodal masses): the folds differ by
   1.8e-3 (upper) and 4e-6 (lower), 0.16 and 0.012 of the bar's own change from 20 to 40
   elements, and the difference vanishes under refinement (3.4e-3, 1.8e-3, 7.1e-4, 6.7e-5 at
   10, 20, 40, 80 elements).

   The nonlinear mode of the uniform bar with a stop is degenerate. Its linear frequencies are
   1:3:5..., and above the grazing energy ``E_g`` there is a family of motions in modes 1 and 2 at
   frequency w1 whose tip barely touches the stop (the third harmonic flattens the tip motion):
   the backbone is vertical at w1 (bar with 40 elements at 5 E_g: w = 1.570921, 8e-5 above
   pi/2; tip at 1.004 of the gap; peak contact force 9.5e-7 = 1e-3 EA g / L). A family with
   impacts (peak force 1.3 EA g / L) branches off near grazing, and which one a continuation
   follows is decided by details: at 20 elements the redistributed strip takes the impacting
   family, the bar the vertical one (figure, top left). So backbones of this model cannot be
   compared at fixed energy beyond grazing by an energy continuation; ``fm.nonlinear_mode`` now
   traces the impacting family past grazing by frequency (``examples/bar_contact_refinement.py``
   compares it with the continuum). This study compares the folds of the damped forced response,
   which is well posed.

2. **Bending blade against the Euler-Bernoulli beam** (``bending``, ``bending_table``).
   Cantilever strips with L/h = 20, 40, 80 (Q2 quadrilaterals, one element through the height,
   nx = L/h; nu = 0, so there is no corner singularity at the clamp and Q2 keeps its h^4 rate),
   E = 12/h^3, rho = 1/h (EI = rho A = 1), a stop on the whole tip edge along +y with
   ``c_j = 3 w_j`` (3 EI / L^3: the beam's default); the beam: 80 Hermite elements, EI = rho A =
   L = 1, stop at the tip. Backbone of mode 1 at 2, 3, 5 grazing energies (each model's own
   ``E_g``). The blade's backbone is lower by 1.10/1.05/1.03 % (L/h = 20), 0.28/0.27/0.27 %
   (40), 0.078/0.074/0.073 % (80): it falls like (h/L)^2 (orders 1.94, 1.87) as thickness
   effects do, but it is 7.3-8.3 times the difference of the linear mode 1 (-0.141 %,
   -0.036 %, -0.0094 %). In this energy range the backbone runs just above w2/6 (the 6:1
   internal resonance with mode 2) and carries the thickness correction of mode 2 (-0.97 %,
   -0.25 %, -0.069 %), to within 6-13 % of it. The beam's own mesh dependence shows the same
   coupling: from 20 to 80 elements its massless-tip w2 falls by 0.46 % and its backbone at
   5 E_g by 0.49 %, while w1 falls by 0.04 %.

3. **Refinement with the surface mass redistribution** (``refinement``, ``changes``,
   ``orders``), nx = 10, 20, 40, 80. Blade (L/h = 20) backbone at 2, 3, 5 E_g: changes
   1.7e-2, 1.2e-3, 7.5e-5, observed orders 3.80 and 3.99 (Q2's h^4); with the consistent face
   mass the same limit (6e-7 apart at nx = 80, orders 3.6 and 3.9). The 1-D beam with its nodal
   tip redistribution converges at order 3.0 (changes 1.3e-1, 1.6e-2, 2.0e-3; the order of its
   massless-tip w1) to the limit of the consistent-mass beam, which converges at order 4.0
   (changes 1.3e-4, 8.4e-6, 5.3e-7): Richardson extrapolation at order 3 meets it to 1e-6. So at
   fixed H the surface redistribution costs the 2-D model no accuracy, where the 1-D one costs an
   order (errors 1.8e-2 against 8e-6 at 20 elements). Axial strip and bar, upper fold of the
   forced response: changes 4.2e-2, 1.0e-2, 6.1e-4 (strip) and 3.7e-2, 1.1e-2, 1.2e-3 (bar),
   orders 2.0-4.1 and 1.7-3.2 (irregular: the 1:3 internal resonance again); lower fold: orders
   3.6 and 8.6 for both.
"""

import time
from pathlib import Path

import numpy as np

import femodes as fm

GAP = 0.01
H = fm.Harmonics(10)
_timings = {}

# -- shared helpers ---------------------------------------------------------------------------------


def face_contacts(model, boundary, component, c_face):
    """One stop per node of ``boundary`` on ``component``, with ``c = c_face * w_j`` (``w_j``: the
    node's consistent weight, ``sum w_j = 1``), so that a face moving as one is the 1-D contact."""
    nodes = model.dofmap.groups[boundary]
    weights = model.dofmap.group_weights[boundary]
    k = model.dofmap.components.index(component)
    dofs = model.dofmap.node_dof[nodes, k]
    return [fm.UnilateralContact(at=int(d), gap=GAP, c=c_face * float(w)) for d, w in zip(dofs, weights)]


def grazing_energy(model, dof):
    """Energy of linear mode 1 whose amplitude at ``dof`` is the gap (mass-normalised shape)."""
    modes = fm.linear_modes(model, 1)
    return float((GAP / modes.shapes[dof, 0]) ** 2 * modes.omega[0] ** 2 / 2)


def frequency_at(model, branch, energies):
    """Backbone frequency at exactly these energies: Newton on the nonlinear-mode equations at
    fixed energy from the nearest branch point (no interpolation error)."""
    problem = fm.NonlinearModeProblem(model, branch.harmonics, 1,
                                      reference_energy=float(np.sqrt(branch.energy[0] * branch.energy[-1])))
    out = []
    for E in np.atleast_1d(energies):
        i = int(np.argmin(np.abs(np.log(branch.energy / E))))
        x0 = problem.pack(branch.Q[i], branch.P[i], branch.omega[i], branch.xi[i])
        p = float(np.log10(E))
        res = fm.semismooth_newton(lambda x: problem.residual(x, p)[:2], x0)
        if not res.success:
            raise RuntimeError(f"frequency_at: no solution at E = {E:g}: {res.message}")
        out.append(problem.unpack(res.x, p).omega)
    return np.array(out)


def upper_lower_folds(branch):
    w = np.sort(branch.omega[list(branch.folds)])
    if w.size != 2:
        raise RuntimeError(f"expected two folds, got {w}")
    return w[1], w[0]


# -- 1. axial strip and bar -------------------------------------------------------------------------
HEIGHT = 0.1
AREA = HEIGHT  # thickness 1
FORCE, BETA = 1e-4, 0.0127  # tip force; stiffness-proportional damping, 1 % of critical in mode 1
OMEGA_SPAN = (1.45, 1.85)
AXIAL_NX = 20
C_BAR = AREA  # 1 / (K^-1)_tip of the fixed-free bar, EA / L: femodes' default c for the bar


def axial_bar(nx, mass=None):
    bar = fm.bar(fm.line_mesh(1.0, nx), fm.Material(E=1.0, rho=1.0), fm.Section(area=AREA), clamped="left")
    return bar.with_contact(fm.UnilateralContact(at="right", gap=GAP), contact_mass=mass)


def axial_strip(nx, mass=None, c_face=C_BAR, ny=2):
    strip = fm.solid(fm.rectangle_mesh(1.0, HEIGHT, nx, ny, quadrilaterals=True), fm.Material(E=1.0, rho=1.0, nu=0.0),
                     supports={"left": ("u_x",), "bottom": ("u_y",), "top": ("u_y",)})
    if c_face is None:  # femodes' default: c_j = 1 / (K^-1)_jj at every node
        return strip.with_contact(fm.UnilateralContact(at="right", gap=GAP, direction=(1.0, 0.0)), contact_mass=mass)
    return strip.with_contact(*face_contacts(strip, "right", "u_x", c_face), contact_mass=mass)


def forced(model):
    at = "right" if model.fe.kind != "solid" else ("right", "u_x")
    return model.with_damping(beta=BETA).with_forcing(fm.HarmonicForce(at=at, amplitude=FORCE))


def on_bar(strip, bar, Q, P):
    """The strip's coefficients restricted to its bottom row of nodes (u_x), contact forces summed."""
    X = strip.fe.node_coordinates
    Qb = np.zeros((Q.shape[0], bar.n_dofs))
    for k, x in enumerate(bar.fe.node_coordinates[0]):
        d = bar.dofmap.node_dof[k, 0]
        if d >= 0:
            j = np.flatnonzero(np.isclose(X[0], x) & np.isclose(X[1], 0.0))[0]
            Qb[:, d] = Q[:, strip.dofmap.node_dof[j, 0]]
    return Qb, P.sum(axis=1, keepdims=True)


def residual_on_bar(strip, bar, branch, problem):
    """Largest scaled residual of the bar's HBM equations at the strip's points (projected)."""
    worst = 0.0
    for i in range(len(branch)):
        Q, P = on_bar(strip, bar, branch.Q[i], branch.P[i])
        if branch.kind == "forced":
            r = problem.residual(problem.pack(Q, P, branch.omega[i]), branch.omega[i])[0]
        else:
            r = problem.residual(problem.pack(Q, P, branch.omega[i], branch.xi[i]), np.log10(branch.energy[i]))[0]
        worst = max(worst, float(np.max(np.abs(r))))
    return worst


_t = time.perf_counter()
axial = {}
E_G_AXIAL = grazing_energy(axial_bar(AXIAL_NX), axial_bar(AXIAL_NX).dof("right"))
for label, mass in (("consistent", fm.ConsistentMass()), ("redistributed", fm.RedistributeMass())):
    strip, bar = axial_strip(AXIAL_NX, mass), axial_bar(AXIAL_NX, mass)
    span = (0.5 * E_G_AXIAL, 5 * E_G_AXIAL)
    nnm = {"strip": fm.nonlinear_mode(strip, 1, energy=span, harmonics=H),
           "bar": fm.nonlinear_mode(bar, 1, energy=span, harmonics=H)}
    fs, fb = forced(strip), forced(bar)
    frc = {"strip": fm.frequency_response(fs, omega=OMEGA_SPAN, harmonics=H),
           "bar": fm.frequency_response(fb, omega=OMEGA_SPAN, harmonics=H)}
    axial[label] = {"nnm": nnm, "frc": frc, "folds": {k: upper_lower_folds(b) for k, b in frc.items()}}
    if label == "consistent":
        ref = float(np.sqrt(span[0] * span[1]))
        axial[label]["nnm_residual"] = residual_on_bar(
            strip, bar, nnm["strip"], fm.NonlinearModeProblem(bar, H, 1, reference_energy=ref))
        axial[label]["frc_residual"] = residual_on_bar(fs, fb, frc["strip"], fm.ForcedResponseProblem(fb, H))
# the vertical (non-contacting) family of the bar: last point of the 40-element bar's backbone
_bar40 = axial_bar(40)
# the energy continuation's own (grazing) family, which this study documents: past_grazing=None
# (by default nonlinear_mode traces the impacting family past grazing instead)
_sol = fm.nonlinear_mode(_bar40, 1, energy=(0.5 * E_G_AXIAL, 5 * E_G_AXIAL), harmonics=H, past_grazing=None)[-1]
_t_fine = np.linspace(0.0, _sol.period, 2001)
vertical_family = {
    "omega": _sol.omega, "energy_ratio": _sol.energy / E_G_AXIAL,
    "tip_max_over_gap": float(_sol.displacement(_t_fine)[:, _bar40.dof("right")].max() / GAP),
    "contact_force_max": float(_sol.contact_force(_t_fine).max()),  # in units of EA g / L = 1e-3
}
# femodes' default c (point stiffness at every node) instead of c_j = c w_j
axial["default_c_folds"] = upper_lower_folds(
    fm.frequency_response(forced(axial_strip(AXIAL_NX, c_face=None)), omega=OMEGA_SPAN, harmonics=H))
_timings["axial"] = time.perf_counter() - _t

# -- 2. bending blade and beam ----------------------------------------------------------------------
SLENDERNESS = (20, 40, 80)
BEAM_NX = 80
ENERGY_FACTORS = np.array([2.0, 3.0, 5.0])
C_BEAM = 3.0  # 1 / (K^-1)_tip of the cantilever: 3 EI / L^3
BACKBONE_OPTIONS = fm.ContinuationOptions(max_step=0.1)


def beam(nx, mass=None):
    mesh = fm.line_mesh(1.0, nx, boundaries={"clamp": 0.0, "tip": 1.0})
    b = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    return b.with_contact(fm.UnilateralContact(at="tip", gap=GAP), contact_mass=mass)


def blade(slenderness, nx, mass=None):
    h = 1.0 / slenderness
    b = fm.solid(fm.rectangle_mesh(1.0, h, nx, 1, quadrilaterals=True), fm.Material(E=12.0 / h**3, rho=1.0 / h, nu=0.0),
                 clamped="left", order=2)
    return b.with_contact(*face_contacts(b, "right", "u_y", C_BEAM), contact_mass=mass)


def backbone(model):
    """(branch, grazing energy, linear w1 and w2, w at ENERGY_FACTORS * E_g) of nonlinear mode 1."""
    dof = model.contacts[len(model.contacts) // 2].dof  # the tip (mid-height node of a blade's tip edge)
    Eg = grazing_energy(model, dof)
    br = fm.nonlinear_mode(model, 1, energy=(0.5 * Eg, 6 * Eg), harmonics=H, options=BACKBONE_OPTIONS)
    if not br.success:
        raise RuntimeError(f"backbone failed: {br.message}")
    return {"branch": br, "E_g": Eg, "linear": fm.linear_modes(model, 2).omega,
            "omega": frequency_at(model, br, ENERGY_FACTORS * Eg)}


_t = time.perf_counter()
bending = {"beam": backbone(beam(BEAM_NX))}
for s in SLENDERNESS:
    bending[s] = backbone(blade(s, s))
_ref = bending["beam"]
#: relative differences blade/beam - 1: backbone at ENERGY_FACTORS, linear w1, linear w2
bending_table = {s: {"backbone": bending[s]["omega"] / _ref["omega"] - 1,
                     "w1": bending[s]["linear"][0] / _ref["linear"][0] - 1,
                     "w2": bending[s]["linear"][1] / _ref["linear"][1] - 1} for s in SLENDERNESS}
_timings["bending"] = time.perf_counter() - _t

# -- 3. refinement ----------------------------------------------------------------------------------
REFINE_NX = (10, 20, 40, 80)
_t = time.perf_counter()
_blades = {nx: bending[20] if nx == 20 else backbone(blade(20, nx)) for nx in REFINE_NX}
_beams = {nx: bending["beam"] if nx == BEAM_NX else backbone(beam(nx)) for nx in REFINE_NX}
refinement = {"blade": np.array([_blades[nx]["omega"] for nx in REFINE_NX]),
              "beam": np.array([_beams[nx]["omega"] for nx in REFINE_NX]),
              "blade, consistent face mass": np.array([backbone(blade(20, nx, fm.ConsistentMass()))["omega"]
                                                       for nx in REFINE_NX]),
              "beam, consistent tip mass": np.array([backbone(beam(nx, fm.ConsistentMass()))["omega"]
                                                     for nx in REFINE_NX])}
#: linear w1, w2 (massless tip) of the beams of the refinement: the backbone follows w2
beam_linear = np.array([_beams[nx]["linear"] for nx in REFINE_NX])


def _folds(kind, nx):
    if nx == AXIAL_NX:
        return axial["redistributed"]["folds"][kind]
    model = axial_strip(nx) if kind == "strip" else axial_bar(nx)
    return upper_lower_folds(fm.frequency_response(forced(model), omega=OMEGA_SPAN, harmonics=H))


refinement["strip folds"] = np.array([_folds("strip", nx) for nx in REFINE_NX])
refinement["bar folds"] = np.array([_folds("bar", nx) for nx in REFINE_NX])
#: |change| per refinement (rows: 10->20, 20->40, 40->80) and the observed orders log2(ratio)
changes = {k: np.abs(np.diff(v, axis=0)) for k, v in refinement.items()}
orders = {k: np.log2(v[:-1] / v[1:]) for k, v in changes.items()}
_timings["refinement"] = time.perf_counter() - _t


def main(out="out"):
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 2, figsize=(13, 10.5))

    ax = axes[0, 0]
    for label, style in (("consistent", "-"), ("redistributed", "--")):
        for name, color in (("strip", "C0"), ("bar", "C3")):
            b = axial[label]["nnm"][name]
            ax.plot(b.omega, b.energy / E_G_AXIAL, style, color=color, marker="o" if name == "strip" else "x",
                    ms=7 if name == "strip" else 5, mfc="none", label=f"{name}, {label} face mass")
    ax.axvline(np.pi / 2, color="k", lw=0.5)
    ax.set(yscale="log", xlabel="omega (rad/s)", ylabel="E / E_g",
           title=f"1a. axial nonlinear mode 1, strip (nu = 0) vs bar, {AXIAL_NX} elements, H = {H.n_harmonics}")
    ax.legend(fontsize=8)

    ax = axes[0, 1]
    for label, style in (("consistent", "-"), ("redistributed", "--")):
        for name, color in (("strip", "C0"), ("bar", "C3")):
            b = axial[label]["frc"][name]
            tip = b.model.contacts[0].dof
            a = b.amplitude(tip) / GAP
            ax.plot(b.omega, a, style, color=color, label=f"{name}, {label}")
            f = list(b.folds)
            ax.plot(b.omega[f], a[f], "k^" if name == "strip" else "kv", ms=6)
    ax.set(xlabel="omega (rad/s)", ylabel="max |u_tip| / gap",
           title="1b. forced response (tip force, 1 % damping), folds marked")
    ax.legend(fontsize=8)

    ax = axes[1, 0]
    b = bending["beam"]
    ax.plot(b["branch"].omega / b["linear"][0], b["branch"].energy / b["E_g"], "k-", lw=2,
            label=f"Euler-Bernoulli beam, {BEAM_NX} elements")
    for s, color in zip(SLENDERNESS, ("C0", "C1", "C2")):
        d = bending[s]
        ax.plot(d["branch"].omega / b["linear"][0], d["branch"].energy / d["E_g"], "-", color=color,
                label=f"Q2 blade L/h = {s}: backbone {100 * bending_table[s]['backbone'][0]:+.2f} %, "
                      f"w1 {100 * bending_table[s]['w1']:+.3f} %, w2 {100 * bending_table[s]['w2']:+.2f} %")
    ax.axvline(b["linear"][1] / 6 / b["linear"][0], color="k", ls=":", lw=1, label="beam w2 / 6")
    ax.set(yscale="log", xlabel="omega / w1 (beam)", ylabel="E / E_g",
           title="2. bending nonlinear mode 1 with a tip stop, blade vs beam")
    ax.legend(fontsize=7)

    ax = axes[1, 1]
    nx = np.array(REFINE_NX[1:])
    for key, marker, color, fill in (("blade", "o", "C0", None), ("blade, consistent face mass", "o", "C0", "none"),
                                     ("beam", "s", "C1", None), ("beam, consistent tip mass", "s", "C1", "none")):
        ax.loglog(nx, changes[key][:, -1], marker + ("-" if fill is None else ":"), color=color, mfc=fill,
                  label=f"{key}, w at 5 E_g (orders {np.round(orders[key][:, -1], 1)})")
    for key, label, marker, color in (("strip folds", "axial strip", "^", "C2"), ("bar folds", "bar", "v", "C3")):
        ax.loglog(nx, changes[key][:, 0], marker + "--", color=color,
                  label=f"{label}, upper fold, forced (orders {np.round(orders[key][:, 0], 1)})")
    ax.loglog(nx, 2e-2 * (nx / nx[0]) ** -2.0, "k:", lw=1, label="slope -2")
    ax.loglog(nx, 1e-2 * (nx / nx[0]) ** -4.0, "k-.", lw=1, label="slope -4")
    ax.set(xlabel="elements along the length (finer mesh of the pair)", ylabel="|change| per refinement",
           title=f"3. refinement with surface mass redistribution (H = {H.n_harmonics})")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2)
    fig.tight_layout()
    fig.savefig(out / "validation_solids.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out / "validation_solids.png"


if __name__ == "__main__":
    np.set_printoptions(precision=7, linewidth=120)
    print("timings (s):", {k: round(v, 1) for k, v in _timings.items()})
    print("beam linear w1, w2 per refinement:\n", beam_linear)
    print("1. axial, nx =", AXIAL_NX)
    for label in ("consistent", "redistributed"):
        print(f"  {label}: folds (upper, lower) strip {np.array(axial[label]['folds']['strip'])} "
              f"bar {np.array(axial[label]['folds']['bar'])}")
    print(f"  consistent: bar residual at the strip's points: nnm {axial['consistent']['nnm_residual']:.2e}, "
          f"forced {axial['consistent']['frc_residual']:.2e}")
    print("  default c: strip folds", np.array(axial["default_c_folds"]))
    print("  vertical family of the bar (40 elements):", vertical_family)
    print("2. bending: blade/beam - 1 at E/E_g =", ENERGY_FACTORS)
    for s in SLENDERNESS:
        t = bending_table[s]
        print(f"  L/h = {s}: backbone {t['backbone']}, w1 {t['w1']:.3e}, w2 {t['w2']:.3e}")
    print("3. refinement, nx =", REFINE_NX)
    for k, v in refinement.items():
        print(f"  {k}:\n{v}\n  changes:\n{changes[k]}\n  orders:\n{orders[k]}")
    print("figure:", main("out"))
