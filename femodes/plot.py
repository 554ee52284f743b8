"""Outputs layer: matplotlib figures of branches and periodic solutions.

Every function draws on the keyword ``ax=`` (a new figure if ``ax`` is None; passing it by
position is deprecated) and returns the Axes, except
:func:`contact_pressure`, which draws a map, a side panel and a colour bar and returns the Figure.
matplotlib is imported only when a function is called (``pip install 'femodes[plot]'``).

- :func:`frequency_energy`: backbones (nonlinear modes) and forced curves, frequency against
  energy (log axis).
- :func:`frequency_amplitude`: amplitude of one DOF against frequency, folds marked (was
  ``frequency_response``, the name of the analysis: a deprecated alias).
- :func:`time_history`: one DOF over time, contact forces on a twin axis.
- :func:`phase_portrait`: velocity against displacement of one DOF.
- :func:`mode_shape`: deflection snapshots along the mesh (reduced models expanded).
- :func:`contact_pressure`: space-time map of the contact pressure along a contact boundary
  of a meshed solid, with the total contact force over the period.
"""

from __future__ import annotations

import functools
import logging
import warnings
from typing import Any

import numpy as np

from .results import Branch, PeriodicSolution

__all__ = ["frequency_energy", "frequency_amplitude", "time_history", "phase_portrait", "mode_shape",
           "contact_pressure", "frequency_response"]

log = logging.getLogger(__name__)


def _plt():
    try:
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("femodes.plot needs matplotlib: pip install 'femodes[plot]'") from exc
    return plt


def _to_keywords(f, n_positional: int, names: tuple[str, ...], args: tuple, kwargs: dict, stacklevel: int):
    """Move the arguments past the first ``n_positional`` to the keywords ``names`` they used to
    fill by position, with a DeprecationWarning (``ax`` and those after it are keyword-only)."""
    if len(args) <= n_positional:
        return args, kwargs
    extra = args[n_positional:]
    if len(extra) > len(names):
        raise TypeError(f"{f.__name__}() takes at most {n_positional + len(names)} positional arguments "
                        f"({n_positional} without deprecation), got {len(args)}")
    given = names[:len(extra)]
    for name in given:
        if name in kwargs:
            raise TypeError(f"{f.__name__}() got multiple values for argument {name!r}")
    keywords = ", ".join(f"{n}=..." for n in given)
    warnings.warn(f"femodes.plot.{f.__name__}: passing {', '.join(given)} by position is deprecated; pass "
                  f"{keywords}", DeprecationWarning, stacklevel=stacklevel + 1)
    return args[:n_positional], {**kwargs, **dict(zip(given, extra))}


def _positional_deprecated(n_positional: int, *names: str):
    """Decorator: ``names`` (keyword-only now) are still accepted by position after the first
    ``n_positional`` arguments, with a DeprecationWarning naming the keywords."""
    def decorate(f):
        @functools.wraps(f)
        def wrapper(*args, **kwargs):
            args, kwargs = _to_keywords(f, n_positional, names, args, kwargs, stacklevel=2)
            return f(*args, **kwargs)
        wrapper.positional = (n_positional, names)
        return wrapper
    return decorate


def _axes(ax: Any, owner: str):
    plt = _plt()
    if ax is None:
        _, ax = plt.subplots(layout="constrained")
        return ax
    from matplotlib.axes import Axes

    if not isinstance(ax, Axes):
        raise TypeError(f"{owner}: ax must be a matplotlib Axes or None, got {type(ax).__name__}")
    return ax


def _freq(omega: np.ndarray, hz: bool) -> np.ndarray:
    return np.asarray(omega) / (2 * np.pi) if hz else np.asarray(omega)


def _freq_label(hz: bool) -> str:
    return "frequency [Hz]" if hz else r"$\omega$ [rad/s]"


def _dof(obj: Any, dof: Any, owner: str, n_dofs: int) -> tuple[int, str]:
    """Resolve ``dof`` (index or location name) to a model DOF index and a label."""
    model = getattr(obj, "model", None)
    if isinstance(dof, (str, tuple)):
        if model is None:
            raise ValueError(f"{owner}: dof={dof!r} is a name but no model is attached; pass an integer DOF index")
        idx = model.dof(dof)
        return idx, model.dofmap.label(idx) if model.dofmap.labels else str(dof)
    if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)):
        raise TypeError(f"{owner}: dof must be an integer index or a location name, got {type(dof).__name__}")
    if not -n_dofs <= dof < n_dofs:
        raise ValueError(f"{owner}: dof={dof} is out of range for {n_dofs} DOFs")
    idx = int(dof) % n_dofs
    label = model.dofmap.label(idx) if model is not None else f"dof {idx}"
    return idx, label


def _reader(obj: Any, dof: Any, owner: str, n_dofs: int, how: str) -> tuple[np.ndarray, str]:
    """Weights ``W`` (rows: responses, the largest amplitude taken) and a label: a DOF, or a
    named boundary read through :meth:`femodes.StructuralModel.probe` (mean or max over its
    nodes; for a reduced model also boundaries it does not keep)."""
    model = getattr(obj, "model", None)
    if isinstance(dof, (str, tuple)) and model is not None:
        try:
            W = np.atleast_2d(model.probe(dof, how, owner))
        except ValueError:
            W = None
        if W is not None and not (W.shape[0] == 1 and np.count_nonzero(W) == 1):
            return W, f"{dof}, {how} over its nodes" if not isinstance(dof, tuple) else f"{dof[0]} {dof[1]}, {how}"
    idx, label = _dof(obj, dof, owner, n_dofs)
    W = np.zeros((1, n_dofs))
    W[0, idx] = 1.0
    return W, label


def _check_solution(solution: Any, owner: str) -> PeriodicSolution:
    if not isinstance(solution, PeriodicSolution):
        raise TypeError(f"{owner}: solution must be a PeriodicSolution (e.g. branch[i]), got {type(solution).__name__}")
    return solution


@_positional_deprecated(1, "ax")
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
    owner = "frequency_energy"
    if isinstance(branches, Branch):
        branches = [branches]
    if not isinstance(branches, (list, tuple)) or not branches or not all(isinstance(b, Branch) for b in branches):
        raise TypeError(f"{owner}: branches must be a Branch or a non-empty list of Branch objects")
    if labels is not None:
        labels = list(labels)
        if len(labels) != len(branches):
            raise ValueError(f"{owner}: labels has {len(labels)} entries for {len(branches)} branches")
    ax = _axes(ax, owner)
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
        (line,) = ax.plot(_freq(br.omega, hz), energy, ls, label=label,
                          **({"marker": ".", "ms": 3} if show_points else {}))
        if br.stable is not None and not br.stable.all():
            ax.plot(_freq(br.omega, hz), _split_by_stability(br.energy, br.stable)[1], ":", color=line.get_color(),
                    label=f"{label}, unstable")
        if mark_folds and br.folds:
            folds.append((br, line.get_color()))
        _mark_bifurcations(ax, br, lambda b: b.energy, hz)
    for br, color in folds:
        idx = list(br.folds)
        ax.plot(_freq(br.omega[idx], hz), br.energy[idx], "x", color=color, ms=8, mew=2, label="_fold")
    ax.set_yscale("log")
    ax.set_ylabel("energy")
    ax.set_xlabel(_freq_label(hz))
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    return ax


@_positional_deprecated(2, "ax")
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
        (:meth:`femodes.StructuralModel.probe`).
    ax : matplotlib Axes, optional
    label : str, optional
        Legend label of the curve.
    hz : bool
        Frequency in Hz instead of rad/s.
    mark_folds : bool
        Add a second line with ``x`` markers at ``branch.folds`` (only if there are folds).
    how : {"mean", "max"}
        On a boundary: the amplitude of its mean displacement, or the largest of its nodes'.

    Returns
    -------
    matplotlib Axes
        Line 0: ``(omega, amplitude)``; line 1 (if folds): the fold points. With stability
        computed (``stability=True``): line 0 the stable parts (NaN elsewhere), line 1 the
        unstable parts dashed, then the folds, then one marker line per bifurcation kind other
        than folds (period doubling squares, Neimark-Sacker diamonds, branch points circles,
        nonsmooth triangles).
    """
    owner = "frequency_amplitude"
    if not isinstance(branch, Branch):
        raise TypeError(f"{owner}: branch must be a Branch, got {type(branch).__name__}")
    W, dof_label = _reader(branch, dof, owner, branch.Q.shape[2], how)
    ax = _axes(ax, owner)

    def amplitude(Q):  # max over the rows of W of max_t |W q(t)|
        QW = np.asarray(Q) @ W.T
        return np.max([branch.amplitude(j, QW) for j in range(W.shape[0])], axis=0)

    amp = amplitude(branch.Q)
    w = _freq(branch.omega, hz)
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
    _mark_bifurcations(ax, branch, lambda b: float(amplitude(b.Q[None])[0]), hz)
    ax.set_xlabel(_freq_label(hz))
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
            ax.plot(_freq(np.array([b.omega for b in bifs]), hz), [value(b) for b in bifs], marker, color="k",
                    mfc="none", ms=9, mew=1.5, ls="none", label=text)


def _default_dof(solution: PeriodicSolution) -> int:
    return int(solution.contacts.dofs[0]) if solution.contacts.dofs else 0


@_positional_deprecated(2, "ax", "n_periods")
def time_history(solution: PeriodicSolution, dof: Any = None, *, ax: Any = None, n_periods: float = 1,
                 n_points: int = 400, contact: bool = True, how: str = "mean"):
    """Displacement of one DOF over time, contact forces on a twin axis.

    Parameters
    ----------
    solution : PeriodicSolution
    dof : int or location, optional
        Default: the first contact DOF, or DOF 0 without contacts. A named boundary of a solid
        reads its mean displacement (``how="mean"``) or its node of largest amplitude
        (``how="max"``), also on a Craig-Bampton model that does not keep it.
    ax : matplotlib Axes, optional
    n_periods : float
        Number of periods shown (> 0).
    n_points : int
        Samples per period.
    contact : bool
        Draw the contact forces (all contacts) on a twin y-axis and the gap (dotted) if ``dof``
        is a contact DOF.

    Returns
    -------
    matplotlib Axes
        The displacement axes (line 0 is ``q_dof(t)``). The contact-force twin, when drawn, is
        ``[a for a in ax.figure.axes if a is not ax and a.bbox.bounds == ax.bbox.bounds]``.
    """
    owner = "time_history"
    solution = _check_solution(solution, owner)
    W, dof_label = _reader(solution, _default_dof(solution) if dof is None else dof, owner, solution.n_dofs, how)
    idx = int(np.flatnonzero(W[0])[0]) if W.shape[0] == 1 and np.count_nonzero(W[0]) == 1 else None
    if isinstance(n_periods, bool) or not isinstance(n_periods, (int, float, np.integer, np.floating)) or not (
        0 < n_periods < 1e6
    ):
        raise ValueError(f"{owner}: n_periods must be a positive number, got {n_periods!r}")
    from .solvers.checks import check_int

    n_points = check_int("n_points", n_points, 2, owner=owner)
    ax = _axes(ax, owner)
    T = solution.period
    t = np.linspace(0.0, n_periods * T, max(2, int(round(n_points * n_periods))) + 1)
    q = solution.displacement(t) @ W.T
    q = q[:, int(np.argmax(np.abs(q).max(axis=0)))]  # the row of largest amplitude (one unless how="max")
    ax.plot(t, q, "-", color="C0", label=f"q ({dof_label})")
    ci = solution.contacts
    if contact and ci.kinds:
        for j, d in enumerate(ci.dofs):
            if d == idx:
                ax.axhline(ci.gaps[j], color="0.4", ls=":", lw=1, label="gap")
        twin = ax.twinx()
        p = solution.contact_force(t)
        for j in range(p.shape[1]):
            twin.plot(t, p[:, j], "-", color=f"C{j + 1}", alpha=0.8, label=f"contact force {j}")
        twin.set_ylabel("contact force")
        twin.legend(loc="lower right")
    ax.set_xlabel("t [s]")
    ax.set_ylabel(f"displacement ({dof_label})")
    ax.legend(loc="lower left")
    ax.grid(True, alpha=0.3)
    return ax


@_positional_deprecated(2, "ax")
def phase_portrait(solution: PeriodicSolution, dof: Any, *, ax: Any = None, n_points: int = 400,
                   label: str | None = None):
    """Phase portrait ``(q_dof, q'_dof)`` over one period.

    Parameters
    ----------
    solution : PeriodicSolution
    dof : int or location
    ax : matplotlib Axes, optional
    n_points : int
        Samples over the period (the curve is closed).
    label : str, optional

    Returns
    -------
    matplotlib Axes
        Line 0 is the closed orbit; a dotted vertical line marks the gap if ``dof`` is a contact DOF.
    """
    owner = "phase_portrait"
    solution = _check_solution(solution, owner)
    idx, dof_label = _dof(solution, dof, owner, solution.n_dofs)
    from .solvers.checks import check_int

    n_points = check_int("n_points", n_points, 3, owner=owner)
    ax = _axes(ax, owner)
    t = np.linspace(0.0, solution.period, n_points + 1)
    q = solution.displacement(t)[:, idx]
    v = solution.velocity(t)[:, idx]
    ax.plot(q, v, "-", label=label or f"$\\omega$ = {solution.omega:.4g} rad/s")
    for j, d in enumerate(solution.contacts.dofs):
        if d == idx:
            ax.axvline(solution.contacts.gaps[j], color="0.4", ls=":", lw=1, label="gap")
    ax.set_xlabel(f"q ({dof_label})")
    ax.set_ylabel(f"dq/dt ({dof_label})")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return ax


@_positional_deprecated(2, "ax", "n_snapshots")
def mode_shape(source: Any, model: Any = None, *, ax: Any = None, n_snapshots: int = 8, mode: int = 1,
               cmap: str = "viridis", show_obstacle: bool = True):
    """Deflection snapshots along the structure over one period.

    Parameters
    ----------
    source : PeriodicSolution or LinearModes
        A periodic solution, or linear modes (``mode`` selects the shape; motion ``phi cos(w t)``).
    model : StructuralModel, optional
        The model the result lives on (default ``solution.model``; required for linear modes).
        Reduced models are expanded to the full mesh. Discrete models (no mesh) are drawn as
        markers against the DOF index.
    ax : matplotlib Axes, optional
    n_snapshots : int
        Snapshots at ``t_j = j T / n_snapshots`` (>= 1), coloured by ``t / T``.
    mode : int
        Mode number (1 = the first mode) for ``LinearModes``.
    cmap : str
        Colormap of the snapshots.
    show_obstacle : bool
        Mark the obstacle (the gap, in the motion direction) at each contact node.

    Returns
    -------
    matplotlib Axes
        Lines 0 .. n_snapshots-1 are the snapshots (``x``, deflection); then one marker line
        per contact if ``show_obstacle``.
    """
    owner = "mode_shape"
    from .fields import mesh_fields, periodic_source, resolve_model
    from .solvers.checks import check_int

    n_snapshots = check_int("n_snapshots", n_snapshots, 1, owner=owner)
    src, j = periodic_source(source, mode, owner)
    model = resolve_model(src, model, owner)
    ax = _axes(ax, owner)
    plt = _plt()
    colors = plt.get_cmap(cmap)(np.linspace(0.0, 0.9, n_snapshots))
    if model.mesh_owner is None:
        # Discrete model: no geometry; plot the DOF values against the DOF index.
        if j is None:
            T = src.period
            t = np.arange(n_snapshots) * (T / n_snapshots)
            q = src.displacement(t)
        else:
            t = np.arange(n_snapshots) * (2 * np.pi / src.omega[j] / n_snapshots)
            q = np.cos(src.omega[j] * t)[:, None] * np.asarray(src.shapes)[:, j][None, :]
        x = np.arange(model.n_dofs)
        for k in range(n_snapshots):
            ax.plot(x, q[k], "o-", color=colors[k], label=f"t/T = {k / n_snapshots:.2f}" if k in (0, n_snapshots - 1) else None)
        ax.set_xticks(x)
        ax.set_xticklabels([model.dofmap.label(i) for i in x])
        ax.set_xlabel("DOF")
        ax.set_ylabel("displacement")
        ax.grid(True, alpha=0.3)
        ax.legend()
        return ax
    f = mesh_fields(src, model, n_frames=n_snapshots, mode=mode, owner=owner)
    if f.dim != 1:
        raise ValueError(f"{owner}: draws bars and beams (deflection along the axis); for a {f.dim}-D solid use "
                         "femodes.viz.animate or femodes.io.write_animation (ParaView), and "
                         "femodes.plot.contact_pressure for the contact boundary")
    order = np.argsort(f.x)
    for k in range(n_snapshots):
        ax.plot(f.x[order], f.displacement[k, order], "-", color=colors[k],
                label=f"t/T = {k / n_snapshots:.2f}" if k in (0, n_snapshots - 1) else None)
    if show_obstacle:
        for node, gap in zip(f.contact_nodes, f.contact_gaps):
            if node >= 0:
                ax.plot([f.x[node]], [gap], marker="_", ms=22, mew=3, color="crimson", ls="none", label="obstacle")
    ax.set_xlabel("x")
    ax.set_ylabel("u (axial)" if f.kind == "bar" else "w (transverse)")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return ax


def _columns(s: np.ndarray, values: np.ndarray, extent: float) -> tuple[np.ndarray, np.ndarray]:
    """3-D boundaries: nodes at the same coordinate ``s`` (a column across the width) merged
    into one column holding their maximum; unstructured surfaces binned into about sqrt(n) bins."""
    key = np.round(s / max(extent, 1e-300) * 1e9)
    uniq, inverse = np.unique(key, return_inverse=True)
    if uniq.size > max(8, s.size // 2):  # not column-structured: equal bins
        n_bins = max(8, int(round(np.sqrt(s.size))))
        edges = np.linspace(s.min(), s.max(), n_bins + 1)
        inverse = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, n_bins - 1)
        used = np.unique(inverse)
        centres = 0.5 * (edges[:-1] + edges[1:])[used]
        inverse = np.searchsorted(used, inverse)
    else:
        centres = np.array([s[inverse == k].mean() for k in range(uniq.size)])
    out = np.full((values.shape[0], centres.size), -np.inf)
    for k in range(centres.size):
        out[:, k] = values[:, inverse == k].max(axis=1)
    return centres, out


def contact_pressure(solution: PeriodicSolution, model: Any = None, *, boundary: str | None = None,
                     n_frames: int = 64, ax: Any = None, cmap: str = "YlOrRd"):
    """Space-time map of the contact pressure along a contact boundary over one period.

    The nodal contact pressure ``p_k / a_k`` (contact force over the tributary measure of the
    node, :meth:`femodes.fields.MeshFields.contact_pressure`) of the contacts on ``boundary``,
    against the coordinate ``s`` along the boundary (x) and ``t / T`` (y, one full period: the
    row at ``t/T = 1`` repeats ``t = 0``), with the total contact force of the boundary against
    ``t / T`` in a narrow panel on the right.

    Parameters
    ----------
    solution : PeriodicSolution
        A solution of a meshed solid (:func:`femodes.solid`) with contacts on a named boundary,
        or of a Craig-Bampton reduction of one.
    model : StructuralModel, optional
        The model the solution was solved on (default ``solution.model``).
    boundary : str, optional
        Named boundary of the mesh. Default: the boundary carrying the most contacts.
    n_frames : int
        Samples over the period (>= 2), at ``t_j = j T / n_frames``.
    ax : matplotlib Axes, optional
        Axes of the map; it is narrowed to 64 % of its box and the force panel and the colour
        bar fill the rest (as ``fig.colorbar(ax=...)`` takes room from its axes). Default: a
        new figure.
    cmap : str
        Colormap (zero pressure pale). Colours start at zero; the small negative pressures a
        truncated Fourier series leaks while a node is open are drawn as zero (the colour bar
        then has a triangle at its lower end), and a line under the map says how low they go
        and how far the motion penetrates the obstacle (truncation artefacts).

    Returns
    -------
    matplotlib Figure
        ``fig.axes[0]``: the map (a QuadMesh, x ``s``, y ``t/T``); ``fig.axes[1]``: the total
        force (line 0, x force, y ``t/T``; titled "total force"); ``fig.axes[2]``: the colour bar. 2-D: ``s`` is the
        arc length along the boundary curve (P2 mid-side nodes included). 3-D (a surface has
        no arc length): ``s`` is the distance along the boundary's principal axis and each
        column shows the largest pressure across the width.

    Raises
    ------
    ValueError
        A model without a solid mesh (bars, beams, discrete systems) or without contacts on
        a named boundary; an unknown ``boundary`` (the message lists the mesh's boundaries) or
        one without contacts (the message lists those with contacts); bad ``n_frames``.
    TypeError
        ``solution`` not a PeriodicSolution; ``boundary`` not a str; ``ax`` not an Axes.
    """
    owner = "contact_pressure"
    from .fields import mesh_fields
    from .solvers.checks import check_int

    solution = _check_solution(solution, owner)
    n_frames = check_int("n_frames", n_frames, 2, owner=owner)
    if boundary is not None and not isinstance(boundary, str):
        raise TypeError(f"{owner}: boundary must be the name of a boundary of the mesh (str) or None, "
                        f"got {type(boundary).__name__}")
    if not isinstance(cmap, str):
        raise TypeError(f"{owner}: cmap must be a colormap name (str), got {type(cmap).__name__}")
    f = mesh_fields(solution, model, n_frames=n_frames, owner=owner)
    if f.dim == 1:
        raise ValueError(f"{owner}: the contact pressure needs a meshed solid (femodes.solid); this is a {f.kind} "
                         "model, whose contact forces femodes.plot.time_history draws")
    counts: dict = {}
    for b in f.contact_boundary:
        if b:
            counts[b] = counts.get(b, 0) + 1
    if not counts:
        raise ValueError(f"{owner}: the model has no contacts on a named boundary of its mesh; add some with "
                         "model.with_contact(fm.UnilateralContact(at=<boundary>, gap=..., direction=...))")
    carrying = ", ".join(repr(b) for b in sorted(counts))
    if boundary is None:
        boundary = max(sorted(counts), key=lambda b: counts[b])
    elif boundary not in f.boundaries:
        known = ", ".join(repr(b) for b in sorted(f.boundaries))
        raise ValueError(f"{owner}: unknown boundary {boundary!r}; the mesh has {known} (contacts on {carrying})")
    elif boundary not in counts:
        raise ValueError(f"{owner}: boundary {boundary!r} carries no contacts; contacts are on {carrying}")
    mine = np.array([c for c, b in enumerate(f.contact_boundary) if b == boundary])
    pressure = np.zeros((f.t.size, f.n_nodes))
    for c in mine:
        pressure[:, f.contact_nodes[c]] += f.contact_force[:, c] / f.contact_measure[c]
    total = f.contact_force[:, mine].sum(axis=1)
    nodes, s = f.boundary_coordinate(boundary)
    values = pressure[:, nodes]
    if f.dim == 3:
        s, values = _columns(s, values, float(np.ptp(f.coordinates, axis=0).max()))
    # close the period: the row t/T = 1 is the row t = 0
    tau = np.append(np.arange(n_frames) / n_frames, 1.0)
    values = np.vstack([values, values[:1]])
    total = np.append(total, total[0])

    plt = _plt()
    if ax is None:
        fig, ax = plt.subplots(figsize=(8.0, 4.5))
        fig.subplots_adjust(left=0.09, right=0.9, bottom=0.12, top=0.9)
    else:
        ax = _axes(ax, owner)
        fig = ax.figure
    # the map takes 64 % of the axes' box, then the force panel and the colour bar (as
    # fig.colorbar(ax=...) steals room from its axes)
    box = ax.get_position()
    ax.set_position([box.x0, box.y0, 0.64 * box.width, box.height])
    side = fig.add_axes([box.x0 + 0.69 * box.width, box.y0, 0.2 * box.width, box.height], sharey=ax)
    cax = fig.add_axes([box.x0 + 0.93 * box.width, box.y0, 0.025 * box.width, box.height])
    top = float(values.max())
    # one band per node and frame (edges half-way between nodes and frames, the row of t = 0 split
    # between both ends of the period): interpolating between nodes draws saw-teeth where the
    # pressure drops to zero from one node to the next
    s_edges = np.concatenate([[s[0]], 0.5 * (s[:-1] + s[1:]), [s[-1]]]) if s.size > 1 else np.array([s[0] - 0.5, s[0] + 0.5])
    t_edges = np.concatenate([[0.0], (np.arange(n_frames) + 0.5) / n_frames, [1.0]])
    mesh = ax.pcolormesh(s_edges, t_edges, values, shading="flat", cmap=cmap, vmin=0.0, vmax=top if top > 0 else 1.0)
    ax.set_xlabel(f"s: arc length along {boundary!r}" if f.dim == 2
                  else f"s: along the principal axis of {boundary!r} (max over the width)")
    ax.set_ylabel("t / T")
    ax.set_ylim(0.0, 1.0)
    ax.set_title(f"contact pressure, $\\omega$ = {f.omega:.4g} rad/s")
    side.plot(total, tau, "-", color="C3")
    side.axvline(0.0, color="0.5", lw=0.8)
    side.set_title("total force", fontsize="medium")
    side.tick_params(labelleft=False)
    side.grid(True, alpha=0.3)
    fig.colorbar(mesh, cax=cax, label="contact pressure", extend="min" if values.min() < 0 else "neither")
    low, pen = float(values.min()), solution.penetration
    if low < 0 or pen > 0:
        # what the picture cannot show by colour: the truncated law's artefacts, said on it
        ax.text(0.0, -0.2, f"H = {solution.harmonics.n_harmonics}: Fourier truncation gives pressures down to "
                f"{low:.3g} (drawn as 0) and penetration up to {pen:.3g}; raise the harmonics "
                "to reduce them", transform=ax.transAxes, fontsize="small", color="0.35", va="top")
    return fig


def frequency_response(*args, **kwargs):
    """Deprecated alias of :func:`frequency_amplitude` (the plot shared its name with the analysis
    :func:`femodes.frequency_response`); a DeprecationWarning, removed in a later release."""
    warnings.warn("femodes.plot.frequency_response is deprecated; use femodes.plot.frequency_amplitude (same "
                  "arguments)", DeprecationWarning, stacklevel=2)
    n_positional, names = frequency_amplitude.positional
    args, kwargs = _to_keywords(frequency_amplitude, n_positional, names, args, kwargs, stacklevel=2)
    return frequency_amplitude.__wrapped__(*args, **kwargs)
