"""Application layer: ``femodes demo``, the flagship demonstration.

A cantilever (``meshes/cantilever.msh``) with a stop at the tip, in dimensionless units
(``E = I = rho = A = L = 1``: frequencies in rad/s of the unit beam, lengths in ``L``, energies in
``E I / L``): linear modes, Craig-Bampton reduction, the nonlinear mode 1 (backbone) and a forced
response by harmonic balance; plots, branches, a ParaView series and a rendered animation in one
folder, and a summary that says what the pictures show:

- below the *grazing energy* (the tip just reaches the stop) mode 1 is linear;
- above it, contact stiffens the mode: the backbone frequency rises;
- where a harmonic ``k`` of the motion meets a linear frequency (``k w ~ w_j``) energy flows into
  mode ``j``: a ``k:1`` *internal resonance*, detected from the spectrum of the contact DOF and
  labelled on the plot; the damped forced response climbs it and folds (jumps, hysteresis);
- the truncated Fourier series lets the tip pass the stop slightly: the penetration is reported;
- stability: the seed's impact oscillator loses stability past grazing and regains it at a
  period doubling (Floquet multipliers by shooting), from which the period-2 branch is switched
  onto (``stability.png``).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

#: Internal-resonance detection: harmonic ``k >= 2`` of the contact DOF holds more than this share of
#: the fundamental's amplitude ...
IR_SHARE = 0.10
#: ... while ``k w`` lies within this relative distance of a linear frequency ``w_j``.
IR_TOLERANCE = 0.02
#: Animation frames: at least ``FRAMES_PER_PERIOD`` per period of the highest harmonic that holds
#: more than ``FRAME_SHARE`` of the contact DOF's amplitude (and at least ``MIN_FRAMES``).
FRAMES_PER_PERIOD = 8
FRAME_SHARE = 0.01
MIN_FRAMES = 24
#: Backbone continuation: the default step bound (0.25 in the scaled arclength norm) jumps across
#: the contact onset in one straight segment (11 points in all); 0.005 puts ~140 points on the
#: branch (steps <= 0.01 rad/s) in ~1.5 s.
BACKBONE_MAX_STEP = 0.005
#: Forced response: max step 0.2 (default 0.5) resolves the folds of the internal resonance.
FORCED_MAX_STEP = 0.2
#: Energy span of the backbone in units of the grazing energy: the linear part, the contact
#: stiffening (up to ~1.55) and the beginning of the 6:1 internal resonance that bends it back.
ENERGY_SPAN = (0.5, 2.5)

UNITS = "EI = rho A = L = 1"


def _find_mesh(name: str) -> Path | None:
    here = Path(__file__).resolve()
    for base in (Path.cwd(), *here.parents):
        p = base / "meshes" / name
        if p.is_file():
            return p
    return None


def harmonic_amplitudes(sol, dof: int) -> np.ndarray:
    """Amplitudes ``a_k = sqrt(c_k^2 + s_k^2)`` of the harmonics ``k = 0 .. H`` of one DOF (``a_0 = |c_0|``)."""
    h = sol.harmonics
    q = np.asarray(sol.Q)[:, dof]
    k = np.arange(1, h.n_harmonics + 1)
    return np.concatenate([[abs(q[h.layout.cos_index(0)])], np.hypot(q[h.layout.cos_rows(k)], q[h.layout.sin_rows(k)])])


def frames_for(sol, dof: int, *, share: float = FRAME_SHARE, per_period: int = FRAMES_PER_PERIOD,
               minimum: int = MIN_FRAMES) -> tuple[int, int]:
    """Frames per period so that the highest harmonic that matters is drawn smoothly.

    Returns ``(n_frames, k)``: ``k`` is the highest harmonic of ``dof`` whose amplitude exceeds
    ``share`` of ``max_t |q_dof(t)|``, and ``n_frames = max(minimum, per_period * k)``.
    """
    a = harmonic_amplitudes(sol, dof)
    big = np.flatnonzero(a[1:] > share * sol.amplitude(dof)) + 1
    k = int(big.max()) if big.size else 1
    return max(minimum, per_period * k), k


@dataclasses.dataclass(frozen=True)
class InternalResonance:
    """A ``k:1`` internal resonance with linear mode ``mode`` (1-based) at the points ``indices``."""

    k: int
    mode: int
    omega_mode: float
    indices: tuple[int, ...]
    max_share: float

    @property
    def omega_line(self) -> float:
        return self.omega_mode / self.k

    @property
    def label(self) -> str:
        return (f"{self.k}:1 internal resonance with mode {self.mode} "
                f"(w{self.mode}/{self.k} = {self.omega_line:.4f} rad/s)")


def internal_resonances(branch, dof: int, omega_lin, *, share: float = IR_SHARE,
                        tol: float = IR_TOLERANCE) -> list[InternalResonance]:
    """Points of ``branch`` where harmonic ``k >= 2`` of ``dof`` exceeds ``share`` of the fundamental
    and ``k w`` lies within ``tol`` (relative) of a linear frequency ``omega_lin[j]``; grouped by ``(k, j)``."""
    nu = branch.harmonics.subharmonic
    found: dict[tuple[int, int], list[tuple[int, float]]] = {}
    for i, sol in enumerate(branch):
        a = harmonic_amplitudes(sol, dof)
        if nu >= a.size or not a[nu] > 0:
            continue
        for k in range(2 * nu, a.size, nu):  # multiples of the base frequency only
            ratio = a[k] / a[nu]
            if ratio <= share:
                continue
            wk = k / nu * sol.omega_truncated
            for j, wj in enumerate(omega_lin):
                if abs(wk / wj - 1.0) < tol:
                    found.setdefault((k // nu, j + 1), []).append((i, ratio))
    out = []
    for (k, mode), hits in sorted(found.items()):
        out.append(InternalResonance(k=k, mode=mode, omega_mode=float(omega_lin[mode - 1]),
                                     indices=tuple(i for i, _ in hits), max_share=max(r for _, r in hits)))
    return out


def _modes_figure(plt, model, rom, full, red, png: Path) -> None:
    x = model.fe.coordinates
    fig, ax = plt.subplots(figsize=(9.5, 4))
    for j in range(3):
        wf = model.mesh_map.full_field(full.shapes[:, j])[model.fe.nodal[0]]
        wr = rom.mesh_map.full_field(red.shapes[:, j])[model.fe.nodal[0]]
        ax.plot(x, wf, lw=2, label=f"mode {j + 1}: {full.omega[j]:.4f} rad/s (full)")
        ax.plot(x, np.sign(wf[-1] * wr[-1]) * wr, "k--", lw=1, label=f"CB: {red.omega[j]:.4f} rad/s")
    ax.plot([1.0], [0.0], "rs", label="tip contact node (the stop is 0.01 L above it)")
    ax.set_xlabel(f"x [L]   ({UNITS})")
    ax.set_ylabel(r"mass-normalised deflection [$1/\sqrt{\rho A L}$]")
    ax.set_title("femodes demo: cantilever modes, full FE vs Craig-Bampton")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def _band(ax, branch, indices, color, label):
    """A translucent band under the points ``indices`` of ``branch`` (NaN breaks between runs)."""
    y = np.full(len(branch), np.nan)
    y[list(indices)] = branch.energy[list(indices)]
    ax.plot(branch.omega, y, "-", lw=7, alpha=0.3, color=color, solid_capstyle="round", zorder=1, label=label)


def _plot_branches(fm, ax, backbone, forced) -> None:
    """Backbone and forced curve with points; the backbone on top, the folds as black markers."""
    fm.plot.frequency_energy([backbone, forced], ax=ax, show_points=True,
                             labels=[f"backbone: nonlinear mode 1 (free, undamped; CB model, H = "
                                     f"{backbone.harmonics.n_harmonics})",
                                     "forced response (tip force 0.004 cos wt, damped; computed on 3.0 .. 4.2 rad/s)"])
    lines = ax.get_lines()
    lines[0].set_linewidth(2.4)
    lines[0].set_zorder(4)
    for ln in lines[2:]:  # fold markers of plot.frequency_energy (hidden from its legend)
        ln.set_color("k")
        ln.set_markersize(10)
        ln.set_zorder(6)
        ln.set_label("fold of the forced response (turning point: jump, hysteresis)")


def _resonance_bands(ax, key, color, ir, backbone, irs, forced, forced_irs) -> None:
    """Bands under the points of both branches flagged with the internal resonance ``key = (k, mode)``."""
    first = True
    for br, found in ((backbone, irs), (forced, forced_irs)):
        for r in found:
            if (r.k, r.mode) == key:
                _band(ax, br, r.indices, color, f"harmonic {ir.k} of the tip > {IR_SHARE:.0%} of the fundamental"
                      if first else "_")
                first = False


def _mark_internal_resonances(ax, backbone, forced, irs, forced_irs) -> None:
    """One colour per internal resonance: a line at ``w_j / k`` and bands on the flagged points."""
    colors = ["tab:red", "tab:purple", "tab:brown", "tab:pink"]
    keys = list(dict.fromkeys([(r.k, r.mode) for r in irs + forced_irs]))
    for n, key in enumerate(keys):
        c = colors[n % len(colors)]
        ir = next(r for r in irs + forced_irs if (r.k, r.mode) == key)
        ax.axvline(ir.omega_line, color=c, ls=":", lw=1.5, label=ir.label)
        _resonance_bands(ax, key, c, ir, backbone, irs, forced, forced_irs)


def _annotate_backbone(ax, backbone, *, e_graze, w1, shown) -> None:
    """Contact stiffening and linear part in words, and the animated orbit as a star."""
    i_top = int(np.argmax(backbone.omega))
    gain = 100 * (backbone.omega[i_top] / w1 - 1)
    ax.annotate(f"contact stiffening\n{w1:.3f} -> {backbone.omega[i_top]:.3f} rad/s (+{gain:.1f} %)",
                xy=(0.5 * (w1 + backbone.omega[i_top]), 1.25 * e_graze), xytext=(w1 - 0.105, 2.3 * e_graze),
                fontsize=9, color="C0", arrowprops={"arrowstyle": "->", "color": "C0"})
    ax.annotate("linear: below E_g the tip\nnever touches the stop", xy=(w1, 0.7 * e_graze),
                xytext=(w1 + 0.03, 0.45 * e_graze), fontsize=8, color="0.3",
                arrowprops={"arrowstyle": "->", "color": "0.4"})
    ax.plot([shown.omega], [shown.energy], "*", ms=15, color="gold", mec="k", zorder=7,
            label="orbit animated in mode1.gif / mode1.pvd")


def _frame_branch_axes(ax, backbone, forced, *, e_graze, w1) -> None:
    """Zoom on the backbone (the forced curve continues to both sides), labels, no own legend."""
    ax.set_xlim(w1 - 0.12, max([backbone.omega.max(), *forced.omega[list(forced.folds)]]) + 0.1)
    ax.set_ylim(0.3 * e_graze, 1.5 * max(backbone.energy.max(), forced.energy.max()))
    ax.set_xlabel(f"w [rad/s]   (dimensionless: {UNITS})")
    ax.set_ylabel("energy [EI/L]   (period average of kinetic + strain energy)")
    ax.set_title("cantilever with a tip stop (gap 0.01 L): contact stiffens mode 1", fontsize=11)
    ax.get_legend().remove()


def _spectrum_panel(axh, backbone, *, tip, irs, e_graze) -> None:
    """Right panel: the spectrum of the tip motion along the backbone (explains the resonance labels)."""
    amps = np.array([harmonic_amplitudes(s, tip) for s in backbone])
    shares = amps[:, 2:] / amps[:, [1]]
    top = sorted(np.argsort(shares.max(axis=0))[::-1][:3] + 2)
    ir_k = {r.k for r in irs}
    others = iter(["tab:green", "tab:olive", "tab:cyan"])  # not C0/C1: those are the branches on the left
    for k in top:
        axh.plot(np.maximum(shares[:, k - 2], 1e-9), backbone.energy, "-", lw=2 if k in ir_k else 1.2,
                 color="tab:red" if k in ir_k else next(others), label=f"harmonic {k}")
    axh.axvline(IR_SHARE, color="tab:red", ls=":", lw=1.2, label=f"{IR_SHARE:.0%}: resonance flag")
    axh.axhline(e_graze, color="grey", ls="-.", lw=0.9)
    axh.set_xscale("log")
    axh.set_xlim(1e-4, 1.0)
    axh.set_xlabel("tip: amplitude of harmonic k /\namplitude of the fundamental [-]")
    axh.set_title("backbone: spectrum of the tip motion", fontsize=10)
    axh.grid(True, which="both", alpha=0.3)
    axh.legend(fontsize=7, loc="upper left")


def _energy_ratio_axis(axh, e_graze) -> None:
    """Secondary axis on the right: energy in units of the grazing energy."""
    from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullLocator

    sec = axh.secondary_yaxis("right", functions=(lambda e: e / e_graze, lambda r: r * e_graze))
    sec.set_ylabel("E / E_g  (energy / grazing energy)")
    sec.yaxis.set_major_locator(FixedLocator([0.5, 1, 1.5, 2, 3, 5, 10, 20]))
    sec.yaxis.set_minor_locator(NullLocator())
    sec.yaxis.set_major_formatter(FormatStrFormatter("%g"))


def _frequency_energy_figure(plt, fm, backbone, forced, *, e_graze, w1, irs, forced_irs, tip, shown, png: Path):
    """The headline picture: backbone and forced curve (zoomed on the backbone), with the grazing
    energy, folds, internal resonances and the animated orbit; the tip spectrum on the right."""
    fig, (ax, axh) = plt.subplots(1, 2, figsize=(11, 6.2), sharey=True, gridspec_kw={"width_ratios": [3, 1.1]})
    _plot_branches(fm, ax, backbone, forced)
    ax.axhline(e_graze, color="grey", ls="-.", lw=0.9,
               label=f"grazing energy E_g = {e_graze:.3e} EI/L (tip reaches the stop)")
    ax.axvline(w1, color="grey", ls="--", lw=0.8, label=f"linear w1 = {w1:.4f} rad/s")
    _mark_internal_resonances(ax, backbone, forced, irs, forced_irs)
    _annotate_backbone(ax, backbone, e_graze=e_graze, w1=w1, shown=shown)
    _frame_branch_axes(ax, backbone, forced, e_graze=e_graze, w1=w1)
    _spectrum_panel(axh, backbone, tip=tip, irs=irs, e_graze=e_graze)
    _energy_ratio_axis(axh, e_graze)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=7.5, frameon=False)
    fig.tight_layout(rect=(0, 0.13, 1, 1))
    fig.savefig(png, dpi=120)
    plt.close(fig)


@dataclasses.dataclass(frozen=True)
class _LinearPart:
    """The cantilever, its contact model, the Craig-Bampton reduction and their linear modes."""

    mesh: object
    source: str
    bare_omega: np.ndarray  # the beam without the contact node
    gap: float
    model: object
    full: object            # linear modes of the full model with the contact node
    rom: object
    red: object             # linear modes of the reduced model


@dataclasses.dataclass(frozen=True)
class _NonlinearPart:
    """Backbone of mode 1 and forced response of the reduced model, and what the demo reads off them."""

    H: object
    tip: int                # contact DOF of the reduced model
    e_graze: float
    backbone: object
    forced: object
    forced_rom: object
    w1: float
    irs: list
    forced_irs: list
    i_top: int              # the stiffest backbone point: the animated orbit
    n_frames: int
    k_max: int

    @property
    def shown(self):
        return self.backbone[self.i_top]

    @property
    def flagged(self) -> list[int]:
        return sorted({i for r in self.irs for i in r.indices})


def _cantilever_mesh(fm):
    path = _find_mesh("cantilever.msh")
    if path is not None:
        return fm.load_mesh(path), str(path)
    # installed without the repository's meshes/: the same mesh built in code
    return fm.line_mesh(1.0, 40, boundaries={"clamp": 0.0, "tip": 1.0}), "line_mesh(1.0, 40)"


def _linear_part(fm) -> _LinearPart:
    mesh, source = _cantilever_mesh(fm)
    bare = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    bare_omega = fm.linear_modes(bare, n=4).omega
    gap = 0.01
    model = bare.with_contact(fm.UnilateralContact(at="tip", gap=gap))  # tip mass redistributed
    full = fm.linear_modes(model, n=4)
    rom = fm.craig_bampton(model, n_modes=10)
    red = fm.linear_modes(rom, n=6)
    return _LinearPart(mesh=mesh, source=source, bare_omega=bare_omega, gap=gap, model=model, full=full, rom=rom,
                       red=red)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _linear_lines(lin: _LinearPart) -> list[str]:
    """The mesh and model sizes, and the table of linear frequencies (analytic, full, Craig-Bampton)."""
    exact = np.array([1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349]) ** 2
    bare_omega, full, red = lin.bare_omega, lin.full, lin.red
    lines = [
        f"mesh: {lin.source} ({lin.mesh.t.shape[1]} elements), model: {lin.model.n_dofs} DOFs, reduced: "
        f"{lin.rom.n_dofs} DOFs; units: {UNITS} (w in rad/s, lengths in L, energy in EI/L)",
        "mode  beam w [rad/s]   analytic err   with contact node w   CB w [rad/s]   CB err",
    ]
    for j in range(4):
        lines.append(
            f"{j + 1:4d}  {bare_omega[j]:14.8f}   {bare_omega[j] / exact[j] - 1:12.2e}   {full.omega[j]:19.8f}   "
            f"{red.omega[j]:12.8f}   {red.omega[j] / full.omega[j] - 1:8.2e}"
        )
    return lines


def _nonlinear_part(fm, lin: _LinearPart, out: Path) -> _NonlinearPart:
    """Backbone of mode 1 of the reduced model (H = 10) and a forced response (saved to ``out``), both
    with small continuation steps so that the drawn curves are the solution, not straight chords."""
    model, rom, full, red = lin.model, lin.rom, lin.full, lin.red
    tip = rom.dof("tip")
    e_graze = (lin.gap / full.shapes[model.dof("tip"), 0]) ** 2 * full.omega[0] ** 2 / 2
    H = fm.Harmonics(10)
    newton = fm.NewtonOptions(atol=1e-9, max_iter=20)
    backbone = fm.nonlinear_mode(rom, 1, energy=(ENERGY_SPAN[0] * e_graze, ENERGY_SPAN[1] * e_graze), harmonics=H,
                                 options=fm.ContinuationOptions(step=BACKBONE_MAX_STEP, max_step=BACKBONE_MAX_STEP,
                                                                newton=newton))
    forced_rom = fm.craig_bampton(model.with_damping(alpha=0.02).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)), 10)
    forced = fm.frequency_response(forced_rom, (3.0, 4.2), H,
                                   options=fm.ContinuationOptions(step=0.05, max_step=FORCED_MAX_STEP, newton=newton))
    backbone.save(out / "backbone.npz")
    forced.save(out / "forced.npz")
    # The animated orbit: the stiffest one (top of the stiffening, mode 1 still dominates).
    i_top = int(np.argmax(backbone.omega))
    n_frames, k_max = frames_for(backbone[i_top], tip)
    return _NonlinearPart(H=H, tip=tip, e_graze=e_graze, backbone=backbone, forced=forced, forced_rom=forced_rom,
                          w1=float(red.omega[0]), irs=internal_resonances(backbone, tip, red.omega),
                          forced_irs=internal_resonances(forced, forced_rom.dof("tip"), red.omega), i_top=i_top,
                          n_frames=n_frames, k_max=k_max)


def _backbone_lines(nl: _NonlinearPart, gap: float) -> list[str]:
    """The backbone in plain words: linear part, contact stiffening, internal resonances."""
    backbone, e_graze, w1, i_top = nl.backbone, nl.e_graze, nl.w1, nl.i_top
    lines = [
        f"backbone (nonlinear mode 1, H = {nl.H.n_harmonics}): {len(backbone)} points from {ENERGY_SPAN[0]:g} to "
        f"{ENERGY_SPAN[1]:g} E_g; E_g = {e_graze:.4g} EI/L is the grazing energy (the tip just reaches the stop, "
        f"gap {gap:g} L)",
        f"  below E_g: linear, w = w1 = {w1:.4f} rad/s",
        f"  above E_g: contact stiffens mode 1, w rises to {backbone.omega[i_top]:.4f} rad/s "
        f"(+{100 * (backbone.omega[i_top] / w1 - 1):.1f} %) at E = {backbone.energy[i_top] / e_graze:.2f} E_g",
    ]
    for r in nl.irs:
        lines.append(
            f"  {r.label} from E = {backbone.energy[r.indices[0]] / e_graze:.2f} E_g: harmonic {r.k} of the tip "
            f"motion reaches {r.max_share:.0%} of the fundamental, energy flows into mode {r.mode} and the backbone "
            f"bends back towards w{r.mode}/{r.k}"
        )
    if not nl.irs:
        lines.append(f"  no internal resonance (no harmonic k >= 2 above {IR_SHARE:.0%} of the fundamental "
                     f"with k w within {IR_TOLERANCE:.0%} of a linear frequency)")
    return lines


def _forced_lines(nl: _NonlinearPart, gap: float) -> list[str]:
    """The forced response (folds, internal resonance) and the contact quality of both branches."""
    backbone, forced, e_graze, flagged = nl.backbone, nl.forced, nl.e_graze, nl.flagged
    pen_bb = backbone.penetration
    fold_w = " and ".join(f"{w:.4f}" for w in forced.omega[list(forced.folds)])
    before = f" ({100 * pen_bb[:flagged[0]].max() / gap:.1f} % before the internal resonance)" if flagged else ""
    return [
        f"forced response (tip force 0.004 cos wt, mass-proportional damping 0.02): {len(forced)} points; "
        + (f"folds at w = {fold_w} rad/s (it jumps between them: hysteresis)" if forced.folds else "no folds")
        + "".join(f"; it climbs the {r.k}:1 internal resonance up to {forced.energy[list(r.indices)].max() / e_graze:.1f} E_g"
                  for r in nl.forced_irs[:1]),
        f"contact quality (Fourier series truncated at H = {nl.H.n_harmonics}): max penetration "
        f"{pen_bb.max():.1e} = {100 * pen_bb.max() / gap:.1f} % of the gap on the backbone{before}, "
        f"{forced.penetration.max():.1e} = {100 * forced.penetration.max() / gap:.0f} % on the forced response",
    ]


def _animations(fm, nl: _NonlinearPart, rom, gap: float, out: Path, lines: list[str]):
    """ParaView series and rendered GIF of the stiffest backbone orbit; appends their lines, returns ``(pvd, gif)``
    (``gif`` None when the optional rendering stack is missing)."""
    sol, e_graze, n_frames = nl.shown, nl.e_graze, nl.n_frames
    pvd = fm.io.write_animation(sol, rom, out / "mode1", n_frames=n_frames)
    lines.append(
        f"animated orbit (the stiffest, star on the plot): w = {sol.omega:.4f} rad/s, E = {sol.energy / e_graze:.2f} E_g, "
        f"max penetration {sol.penetration:.1e} = {100 * sol.penetration / gap:.1f} % of the gap; {n_frames} frames "
        f"per period (>= {FRAMES_PER_PERIOD} per period of harmonic {nl.k_max}, the highest above {FRAME_SHARE:.0%} of the "
        f"tip amplitude)"
    )
    lines.append(f"ParaView time series: {pvd.name} (+ {pvd.stem}_*.vtu)")
    gif = None
    try:
        style = fm.viz.AnimationStyle(
            unit="L", title=f"nonlinear mode 1 with tip contact (stiffest orbit, E = {sol.energy / e_graze:.2f} E_g)")
        gif = fm.viz.animate(sol, rom, out / "mode1.gif", n_frames=n_frames, style=style)
        lines.append(f"rendered animation: {gif.name} (the contact node turns red while it is inside the stop)")
    except (ImportError, RuntimeError) as exc:  # optional rendering stack (pyvista + EGL)
        lines.append(f"rendered animation skipped: {exc}")
    return pvd, gif


#: The impact oscillator of the stability part: u'' + 0.1 u' + u = 0.2 cos(w t), stop at u = 1.
#: H = 20: at H = 10 the truncated series shows no period doubling of its own to switch from
#: (the true orbit's, found by shooting, is at w = 0.996204); the span holds grazing, the
#: doubling and the lower fold.
OSCILLATOR = dict(damping=0.1, force=0.2, gap=1.0, harmonics=20, span=(0.88, 1.12))


def _stability_part(fm, plt, out: Path) -> tuple[list[str], Path]:
    """The seed's impact oscillator with stability (shooting) and its period-doubled branch."""
    c = OSCILLATOR
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[c["damping"]]])
             .with_contact(fm.UnilateralContact(at=0, gap=c["gap"]))
             .with_forcing(fm.HarmonicForce(at=0, amplitude=c["force"])))
    branch = fm.frequency_response(model, c["span"], c["harmonics"], stability=True)
    branch.save(out / "oscillator.npz")
    pd = [b for b in branch.bifurcations if b.kind == "period_doubling"]
    doubled = None
    if pd:
        try:
            doubled = fm.switch_branch(branch, pd[0], omega=(c["span"][0], pd[0].omega))
        except RuntimeError as exc:  # the HBM does not resolve its own doubling: say so, keep the rest
            log.warning("demo: %s", exc)
    fig, ax = plt.subplots(figsize=(7, 4.6))
    fm.plot.frequency_amplitude(branch, 0, ax=ax, label="period 1")
    if doubled is not None:
        ax.plot(doubled.omega, doubled.amplitude(0), "-", color="C3", label="period 2 (switch_branch)")
    ax.axhline(c["gap"], color="0.5", lw=0.8, ls=":")
    ax.set_title(f"impact oscillator u'' + 0.1u' + u = 0.2 cos wt, stop at 1 (H = {c['harmonics']}): stability")
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    png = out / "stability.png"
    fig.savefig(png, dpi=90)
    plt.close(fig)
    lines = [f"impact oscillator (u'' + 0.1 u' + u = 0.2 cos wt, rigid stop at u = 1, H = {c['harmonics']}): "
             f"{int(branch.stable.sum())} of {len(branch)} orbits stable (Floquet multipliers by shooting from each "
             f"HBM orbit; dashed in stability.png)"]
    for b in branch.bifurcations:
        lines.append(f"  {b.kind.replace('_', ' ')} at w = {b.omega:.6f} (multiplier {complex(b.multiplier).real:+.4f})")
    if doubled is not None:
        lines.append(f"  period-2 branch (switch_branch, harmonics of w/2): {len(doubled)} points from the HBM's own "
                     f"doubling at w = {doubled.meta['switched_from']['omega_hbm']:.5f} down to "
                     f"{doubled.omega.min():.4f} (the truncated series puts the doubling below the true one)")
    return lines, png


def run_demo(out: Path) -> dict:
    """The demo: cantilever, tip contact node, linear modes, Craig-Bampton, backbone and forced
    response; returns ``{"lines", "plot", "out", "files"}`` (printed lines, the mode plot, the
    folder and the files actually written)."""
    import femodes as fm

    t_start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    lin = _linear_part(fm)
    plt = _pyplot()
    png = out / "cantilever_modes.png"
    _modes_figure(plt, lin.model, lin.rom, lin.full, lin.red, png)
    lines = _linear_lines(lin)

    nl = _nonlinear_part(fm, lin, out)
    png2 = out / "frequency_energy.png"
    _frequency_energy_figure(plt, fm, nl.backbone, nl.forced, e_graze=nl.e_graze, w1=nl.w1, irs=nl.irs,
                             forced_irs=nl.forced_irs, tip=nl.tip, shown=nl.shown, png=png2)
    # What the pictures show, in plain words.
    lines += _backbone_lines(nl, lin.gap)
    lines += _forced_lines(nl, lin.gap)
    pvd, gif = _animations(fm, nl, lin.rom, lin.gap, out, lines)
    stab_lines, png3 = _stability_part(fm, plt, out)
    lines += stab_lines

    lines.append(f"run time {time.perf_counter() - t_start:.1f} s")
    (out / "summary.txt").write_text("\n".join(lines) + "\n")
    files = [png, png2, pvd, *([gif] if gif is not None else []), png3, out / "summary.txt", out / "backbone.npz",
             out / "forced.npz", out / "oscillator.npz"]
    return {"lines": lines, "plot": png, "out": out, "files": files}
