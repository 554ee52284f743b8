"""Outputs layer: plots of one periodic solution (time history, phase portrait) and of mode
shapes along the mesh."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..solvers.checks import InputValueError, entry_point
from ..results import PeriodicSolution
from .common import axes, check_solution, dof_index, positional_deprecated, pyplot, reader

__all__ = ["time_history", "phase_portrait", "mode_shape"]


def _default_dof(solution: PeriodicSolution) -> int:
    return int(solution.contacts.dofs[0]) if solution.contacts.dofs else 0


@positional_deprecated(2, "ax", "n_periods")
@entry_point("time_history")
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
    solution = check_solution(solution)
    W, dof_label = reader(solution, _default_dof(solution) if dof is None else dof, solution.n_dofs, how)
    idx = int(np.flatnonzero(W[0])[0]) if W.shape[0] == 1 and np.count_nonzero(W[0]) == 1 else None
    if isinstance(n_periods, bool) or not isinstance(n_periods, (int, float, np.integer, np.floating)) or not (
        0 < n_periods < 1e6
    ):
        raise InputValueError(f"n_periods must be a positive number, got {n_periods!r}")
    from ..solvers.checks import check_int

    n_points = check_int("n_points", n_points, 2)
    ax = axes(ax)
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


@positional_deprecated(2, "ax")
@entry_point("phase_portrait")
def phase_portrait(solution: PeriodicSolution, dof: Any, *, ax: Any = None, n_points: int = 400,
                   label: str | None = None):
    """Phase portrait ``(q_dof, q'dof_index)`` over one period.

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
    solution = check_solution(solution)
    idx, dof_label = dof_index(solution, dof, solution.n_dofs)
    from ..solvers.checks import check_int

    n_points = check_int("n_points", n_points, 3)
    ax = axes(ax)
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


@positional_deprecated(2, "ax", "n_snapshots")
@entry_point("mode_shape")
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
    from ..fields import periodic_source, resolve_model, sample_fields
    from ..solvers.checks import check_int

    n_snapshots = check_int("n_snapshots", n_snapshots, 1)
    src, j = periodic_source(source, mode)
    model = resolve_model(src, model)
    ax = axes(ax)
    plt = pyplot()
    colors = plt.get_cmap(cmap)(np.linspace(0.0, 0.9, n_snapshots))
    if model.mesh_map.owner is None:
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
    f = sample_fields(src, model, n_frames=n_snapshots, mode=mode)
    if f.dim != 1:
        raise InputValueError(f"draws bars and beams (deflection along the axis); for a {f.dim}-D solid use "
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
