"""Application layer: the report of a run: the lines of summary.txt, the plot and the animations."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...stability_methods import describe_unconverged
from .building import as_location
from .schema import Case

__all__ = ["summary_lines", "stability_lines", "write_plot", "write_animations"]


def summary_lines(case: Case, model, branch) -> list[str]:
    """The first lines of summary.txt: case, model and what the branch found (with the error
    estimate: which sources it covers; a grazing family: that it does not predict the resonance)."""
    from ...nonsmooth_modes import family_caveat
    from ...results import ERROR_SOURCES
    from ...results.error_estimate import largest_text

    lines = [f"case: {case.name}", f"model: {model!r}"]
    if not len(branch):  # an IndexError on omega[0] left no summary at all
        lines.append(f"{branch.kind}: no points, success={branch.success} ({branch.message})")
        return lines
    lines.append(f"{branch.kind}: {len(branch)} points, success={branch.success} ({branch.message}), "
                 f"w from {branch.omega[0]:.6g} to {branch.omega[-1]:.6g} rad/s (min {branch.omega.min():.6g}, "
                 f"max {branch.omega.max():.6g}), energy {branch.energy.min():.4g}..{branch.energy.max():.4g}")
    if branch.kind == "nonlinear mode":
        lines.append(f"max |xi| (artificial damping) = {abs(branch.xi).max():.2e}")
    if len(branch.folds):
        f = list(branch.folds)
        err = branch.omega_error
        bars = "" if err is None else " (" + ", ".join(
            f"+-{e:.1e}" if np.isfinite(e) else "error unknown" for e in err[f]) + " relative)"
        lines.append(f"folds at w = {', '.join(f'{w:.6g}' for w in branch.omega[f])}{bars}")
        if err is not None and np.any(branch.omega[f] != branch.omega_truncated[f]):
            lines.append("  (converged by the error estimate; the truncated series (H = "
                         f"{branch.harmonics.n_harmonics}) has them at w = "
                         f"{', '.join(f'{w:.6g}' for w in branch.omega_truncated[f])}: branch.omega_truncated)")
    if len(branch.contacts.dofs):
        # relative: over the largest contact displacement and force (the absolute values were labelled so)
        pen, ten = branch.contact_quality()
        lines.append(f"contact quality (truncated Fourier series, relative): max penetration {np.max(pen):.3g} of "
                     f"the largest contact displacement ({np.max(branch.penetration):.3g} absolute), max tension "
                     f"{np.max(ten):.3g} of the largest contact force ({np.max(branch.tension):.3g} absolute)")
    if branch.error_estimate is not None:
        acc = branch.accuracy
        met = f", rtol = {acc.rtol:g} met at {int(np.sum(acc.met))} of {len(branch)} points" if acc.rtol else ""
        names = " and ".join(ERROR_SOURCES[k] for k in acc.sources)
        lines.append(f"error estimate ({names}): frequency largest {largest_text(branch.omega_error)}{met}; "
                     f"amplitude largest {largest_text(branch.amplitude_error)} ({_amplitude_source(acc)}); "
                     f"covers {acc.covers}")
    caveat = family_caveat(branch)
    if caveat:
        lines.append(caveat)
    if branch.internal_resonances:
        ws = ", ".join(f"{t['omega'][0]:.5g}" for t in branch.internal_resonances)
        lines.append(f"internal-resonance tongues stepped over at w = {ws} (branch.internal_resonances)")
    if branch.meta.get("ends_in"):
        lines.append(f"at its end: {branch.meta['ends_in']}")
    lines.extend(stability_lines(branch))
    return lines


def _amplitude_source(acc) -> str:
    """Where the amplitudes come from: exact orbits (shooting) and/or the truncated series."""
    n = len(acc.amplitude)
    k = int(acc.converged_amplitude.sum())
    if k == n:
        return "exact orbits at every point"
    if k == 0:
        return "truncated series, not controlled by rtol"
    return f"exact orbits at {k} of {n} points, elsewhere the truncated series, not controlled by rtol"



def _fmt_multiplier(mu: complex) -> str:
    """A Floquet multiplier: a real number, or ``a+bj (|mu| = r)``."""
    mu = complex(mu)
    if abs(mu.imag) <= 1e-9 * max(1.0, abs(mu)):
        return f"{mu.real:.6g}"
    return f"{mu.real:.4g}{mu.imag:+.4g}j (|mu| = {abs(mu):.6g})"


def stability_lines(branch) -> list[str]:
    """summary.txt lines on the stability of a branch, none if it was not computed.

    ``stability (shooting): 2 stable, 4 unstable of 6 points`` (the methods used, with their
    point counts when ``"auto"`` mixed them), then ``bifurcations: none`` or
    ``bifurcations: N`` and one line per bifurcation in branch order:
    ``  period_doubling at w = 0.996204 (between points 3 and 4, multiplier -1)``. Points that
    failed Hill's truncation check (:attr:`~femodes.results.Branch.stability_unconverged`) get a
    line after the first.
    """
    if branch.stable is None:
        return []
    n, n_stable = len(branch), int(sum(bool(s) for s in branch.stable))
    used: dict[str, int] = {}
    for m in branch.stability_method:
        used[str(m)] = used.get(str(m), 0) + 1
    methods = ", ".join(used) if len(used) == 1 else ", ".join(f"{m} at {k} points" for m, k in sorted(used.items()))
    lines = [f"stability ({methods or '-'}): {n_stable} stable, {n - n_stable} unstable of {n} points"]
    bad = branch.meta.get("stability_unconverged", [])
    if bad:
        shown = describe_unconverged(bad, 8)
        lines.append(f"Hill's truncation check: the verdict of {len(bad)} of the "
                     f"{branch.meta.get('stability_checked', len(bad))} points checked changes with fewer "
                     f"harmonics (point (|mu| / with 75 % of the harmonics): {shown}); "
                     f"not converged: raise the harmonics or check them by shooting")
    if not branch.bifurcations:
        return lines + ["bifurcations: none"]
    lines.append(f"bifurcations: {len(branch.bifurcations)}")
    for b in branch.bifurcations:
        where = f"w = {b.omega:.6g}" + (f", energy {b.energy:.4g}" if branch.kind == "nonlinear mode" else "")
        pos = f"point {b.index}" if b.kind == "fold" else f"between points {b.index} and {b.index + 1}"
        lines.append(f"  {b.kind} at {where} ({pos}, multiplier {_fmt_multiplier(b.multiplier)})")
    return lines


def write_plot(case: Case, model, branch, out: Path) -> Path:
    """frequency_energy.png (nonlinear mode) or response.png (frequency response) in ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import femodes as fm

    fig, ax = plt.subplots(figsize=(7, 4))
    if case.data["analysis"]["type"] == "nonlinear_mode":
        fm.plot.frequency_energy(branch, ax=ax)
        png = out / "frequency_energy.png"
    else:
        rd = case.data.get("outputs", {}).get("response_dof")
        dof = model.dof(as_location(rd)) if rd is not None else model.forces[0].dof
        fm.plot.frequency_amplitude(branch, dof, ax=ax)
        png = out / "response.png"
    ax.set_title(f"{case.path.name}: {branch.kind}")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def write_animations(model, branch, out: Path, outs: dict, files: list, lines: list) -> None:
    """Animation of the last point (VTK series and/or gif); appends to ``files`` and ``lines``."""
    import femodes as fm

    last = branch[len(branch) - 1]
    if not (outs["animation"] or outs["gif"]):
        return
    if model.fe is None and not getattr(model, "is_reduced", False):
        lines.append("animation skipped: a discrete model has no mesh")
        return
    if outs["animation"]:
        files.append(fm.io.write_animation(last, model, out / "animation", n_frames=24))
    if outs["gif"]:
        try:
            files.append(fm.viz.animate(last, model, out / "animation.gif", n_frames=24))
        except (ImportError, RuntimeError) as exc:
            lines.append(f"gif skipped: {exc}")
