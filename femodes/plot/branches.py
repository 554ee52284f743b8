"""Outputs layer: plots of branches: frequency against energy (backbones, forced curves) and
amplitude against frequency, with folds, bifurcations, stability and error bars."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from ..solvers.checks import InputTypeError, InputValueError, entry_point
from ..results import Branch
from .common import axes, freq, freq_label, positional_deprecated, reader, to_keywords

__all__ = ["frequency_energy", "frequency_amplitude", "frequency_response"]


@positional_deprecated(1, "ax")
@entry_point("frequency_energy")
def frequency_energy(branches: Any, *, ax: Any = None, labels: Any = None, hz: bool = False,
                     mark_folds: bool = True, show_points: bool = False):
    """Frequency-energy plot: backbones and forced curves on the same axes.

    Parameters
    ----------
    branches : Branch or sequence of Branch
        Nonlinear modes (solid lines) and forced responses (dashed lines); with stability
        computed, unstable parts are dotted and bifurcations marked by kind.
    ax : matplotlib Axes, optional
    labels : sequence of str, optional
        One legend label per branch (default: the branch kind, with the mode number).
    hz : bool
        Frequency in Hz instead of rad/s.
    mark_folds : bool
        Mark ``branch.folds`` (turning points in frequency, located by the continuation) with
        ``x`` markers in the branch colour: one extra line per branch with folds, hidden from
        the legend (its label starts with ``_fold``). Default on.
    show_points : bool
        Also draw a small dot at every computed point. Between points the curve is a straight
        segment; the dots show where the continuation actually solved, so a long segment (e.g.
        across a contact onset) is not mistaken for a feature of the solution.

    Returns
    -------
    matplotlib Axes
        Frequency on the x-axis, energy on a log y-axis (as in the examples); one line per
        branch (in order, data ``(omega, energy)``), followed by the fold markers.
    """
    if isinstance(branches, Branch):
        branches = [branches]
    if not isinstance(branches, (list, tuple)) or not branches or not all(isinstance(b, Branch) for b in branches):
        raise InputTypeError("branches must be a Branch or a non-empty list of Branch objects")
    if labels is not None:
        labels = list(labels)
        if len(labels) != len(branches):
            raise InputValueError(f"labels has {len(labels)} entries for {len(branches)} branches")
    ax = axes(ax)
    folds = []
    for i, br in enumerate(branches):
        if labels is not None:
            label = labels[i]
        elif br.kind == "nonlinear mode" and "mode" in br.meta:
            label = f"nonlinear mode {br.meta['mode']}"
        else:
            label = br.kind
        ls = "-" if br.kind == "nonlinear mode" else "--"
        energy = br.energy if br.stable is None else _split_by_stability(br.energy, br.stable)[0]
        (line,) = ax.plot(freq(br.omega, hz), energy, ls, label=label,
                          **({"marker": ".", "ms": 3} if show_points else {}))
        if br.stable is not None and not br.stable.all():
            ax.plot(freq(br.omega, hz), _split_by_stability(br.energy, br.stable)[1], ":", color=line.get_color(),
                    label=f"{label}, unstable")
        if mark_folds and br.folds:
            folds.append((br, line.get_color()))
        _mark_bifurcations(ax, br, lambda b: b.energy, hz)
    for br, color in folds:
        idx = list(br.folds)
        ax.plot(freq(br.omega[idx], hz), br.energy[idx], "x", color=color, ms=8, mew=2, label="_fold")
    ax.set_yscale("log")
    ax.set_ylabel("energy")
    ax.set_xlabel(freq_label(hz))
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    return ax


@positional_deprecated(2, "ax")
@entry_point("frequency_amplitude")
def frequency_amplitude(branch: Branch, dof: Any, *, ax: Any = None, label: str | None = None, hz: bool = False,
                        mark_folds: bool = True, how: str = "mean"):
    """Amplitude ``max_t |q_dof(t)|`` against frequency, folds marked.

    Parameters
    ----------
    branch : Branch
    dof : int or location
        Model DOF index, or a location name (``"tip"``, ``("tip", "theta")``) when the branch
        carries its model; a named boundary of a solid (``("pad", "u_z")``) reads its mean or
        max (``how``), also on a Craig-Bampton model that does not keep it
        (:meth:`femodes.model.MeshMap.probe`).
    ax : matplotlib Axes, optional
    label : str, optional
        Legend label of the curve.
    hz : bool
        Frequency in Hz instead of rad/s.
    mark_folds : bool
        Add a second line with ``x`` markers at ``branch.folds`` (only if there are folds).
    how : {"mean", "max"}
        On a boundary: the amplitude of its mean displacement, or the largest of its nodes'.

    Notes
    -----
    The frequencies are the branch's answer (:attr:`femodes.Branch.omega`, converged where an
    error estimate gives it), with error bars when it has one. A single DOF reads
    :meth:`femodes.Branch.amplitude` (the exact orbits' amplitudes where shooting answered); a
    boundary's mean or max reads the truncated series'.

    Returns
    -------
    matplotlib Axes
        Line 0: ``(omega, amplitude)``; line 1 (if folds): the fold points. With stability
        computed (``stability=True``): line 0 the stable parts (NaN elsewhere), line 1 the
        unstable parts dashed, then the folds, then one marker line per bifurcation kind other
        than folds (period doubling squares, Neimark-Sacker diamonds, branch points circles,
        nonsmooth triangles).
    """
    if not isinstance(branch, Branch):
        raise InputTypeError(f"branch must be a Branch, got {type(branch).__name__}")
    W, dof_label = reader(branch, dof, branch.Q.shape[2], how)
    ax = axes(ax)

    def amplitude(Q):  # max over the rows of W of max_t |W q(t)| of the series Q
        QW = np.asarray(Q) @ W.T
        return np.max([branch.amplitude(j, QW) for j in range(W.shape[0])], axis=0)

    single = W.shape[0] == 1 and np.count_nonzero(W[0]) == 1 and W[0][np.flatnonzero(W[0])[0]] == 1.0
    series = amplitude(branch.Q)
    # one DOF: the branch's answer (the exact orbits' amplitudes where its error estimate has them)
    amp = branch.amplitude(int(np.flatnonzero(W[0])[0])) if single else series
    w = freq(branch.omega, hz)
    if branch.stable is None:
        ax.plot(w, amp, "-", label=label or branch.kind)
    else:
        solid, dashed = _split_by_stability(amp, branch.stable)
        (line,) = ax.plot(w, solid, "-", label=f"{label or branch.kind}, stable")
        ax.plot(w, dashed, "--", color=line.get_color(), label=f"{label or branch.kind}, unstable")
    if mark_folds and branch.folds:
        f = list(branch.folds)
        ax.plot(w[f], amp[f], "x", color="k", ms=8, mew=2, label="fold")
    _error_bars(ax, branch, w, amp)
    # a bifurcation is a point of the series: moved by its point's amplitude correction, as its frequency
    _mark_bifurcations(ax, branch, lambda b: float(amplitude(b.Q[None])[0]) + float(amp[b.index] - series[b.index]), hz)
    ax.set_xlabel(freq_label(hz))
    ax.set_ylabel(f"amplitude ({dof_label})")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return ax


#: Marker and legend label of each bifurcation kind (folds have their own ``x`` markers).
_BIFURCATION_STYLE = {"period_doubling": ("s", "period doubling"), "neimark_sacker": ("D", "Neimark-Sacker"),
                      "branch_point": ("o", "branch point"), "nonsmooth": ("^", "nonsmooth (grazing)")}


def _split_by_stability(y: np.ndarray, stable: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``y`` where stable and where unstable (NaN elsewhere); a point where stability changes is in
    both, so that the two lines join."""
    stable = np.asarray(stable, dtype=bool)
    unstable = ~stable
    edge = np.zeros_like(stable)
    edge[:-1] |= stable[:-1] != stable[1:]
    edge[1:] |= stable[:-1] != stable[1:]
    solid = np.where(stable | edge, y, np.nan)
    dashed = np.where(unstable | edge, y, np.nan)
    return solid, dashed


def _error_bars(ax, branch: Branch, w: np.ndarray, y: np.ndarray) -> None:
    """With an error estimate: the error bars of the points' frequency (``branch.omega_error``)
    and of their amplitude (``branch.amplitude_error``), grey, no line of their own in
    ``ax.lines``; nothing where the errors are unknown."""
    if branch.omega_error is None or branch.amplitude_error is None:
        return
    xerr, yerr = np.abs(w) * branch.omega_error, np.abs(y) * branch.amplitude_error
    ok = np.isfinite(xerr) & np.isfinite(yerr)
    if ok.any():
        ax.errorbar(w[ok], y[ok], xerr=xerr[ok], yerr=yerr[ok], fmt="none", ecolor="0.5", elinewidth=0.8,
                    label="error bars (frequency, amplitude)")


def _mark_bifurcations(ax, branch: Branch, value, hz: bool) -> None:
    """One marker line per bifurcation kind (folds aside), black, labelled by kind (at the
    frequency the branch reports: :attr:`~femodes.Branch.bifurcations`)."""
    for kind, (marker, text) in _BIFURCATION_STYLE.items():
        bifs = [b for b in branch.bifurcations if b.kind == kind]
        if bifs:
            ax.plot(freq(np.array([b.omega for b in bifs]), hz), [value(b) for b in bifs], marker, color="k",
                    mfc="none", ms=9, mew=1.5, ls="none", label=text)


def frequency_response(*args, **kwargs):
    """Deprecated alias of :func:`frequency_amplitude` (the plot shared its name with the analysis
    :func:`femodes.frequency_response`); a DeprecationWarning, removed in a later release."""
    warnings.warn("femodes.plot.frequency_response is deprecated; use femodes.plot.frequency_amplitude (same "
                  "arguments)", DeprecationWarning, stacklevel=2)
    n_positional, names = frequency_amplitude.positional
    args, kwargs = to_keywords(frequency_amplitude, n_positional, names, args, kwargs, stacklevel=2)
    return frequency_amplitude.__wrapped__(*args, **kwargs)
