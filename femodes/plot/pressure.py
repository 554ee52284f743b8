"""Outputs layer: the space-time map of the contact pressure along a contact boundary of a
meshed solid (:func:`contact_pressure`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..solvers.checks import InputTypeError, InputValueError, entry_point
from ..results import PeriodicSolution
from .common import axes, check_solution, pyplot

__all__ = ["contact_pressure"]


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




@entry_point("contact_pressure")
def contact_pressure(solution: PeriodicSolution, model: Any = None, *, boundary: str | None = None,
                     n_frames: int = 64, ax: Any = None, cmap: str = "YlOrRd"):
    """Space-time map of the contact pressure along a contact boundary over one period.

    The nodal contact pressure ``p_k / a_k`` (:meth:`femodes.fields.MeshFields.contact_pressure`)
    on ``boundary`` against the coordinate ``s`` along it (x) and ``t / T`` (y, one full period),
    with the boundary's total contact force against ``t / T`` in a narrow panel on the right.

    Parameters
    ----------
    solution : PeriodicSolution
        Of a meshed solid (:func:`femodes.solid`, or its reduction) with contacts on a named boundary.
    model : StructuralModel, optional
        The model the solution was solved on (default ``solution.model``).
    boundary : str, optional
        Named boundary of the mesh. Default: the boundary carrying the most contacts.
    n_frames : int, default 64
        Samples over the period (>= 2), at ``t_j = j T / n_frames``.
    ax : matplotlib Axes, optional
        Axes of the map, narrowed to 64 % of its box for the force panel and the colour bar.
        Default: a new figure.
    cmap : str, default "YlOrRd"
        Colormap (zero pressure pale). Negative pressures (truncation leaks) are drawn as zero; a
        line under the map says how low they go and how far the motion penetrates the obstacle.

    Returns
    -------
    matplotlib Figure
        ``fig.axes[0]``: the map (a QuadMesh, x ``s``, y ``t/T``); ``fig.axes[1]``: the total force
        (line 0, titled "total force"); ``fig.axes[2]``: the colour bar. 2-D: ``s`` is the arc length
        along the boundary; 3-D: the distance along its principal axis, each column the largest
        pressure across the width.

    Raises
    ------
    ValueError
        A model without a solid mesh (bars, beams, discrete systems) or without contacts on
        a named boundary; an unknown ``boundary`` (the message lists the mesh's boundaries) or
        one without contacts (the message lists those with contacts); bad ``n_frames``.
    TypeError
        ``solution`` not a PeriodicSolution; ``boundary`` not a str; ``ax`` not an Axes.
    """
    from ..fields import sample_fields
    from ..solvers.checks import check_int

    solution = check_solution(solution)
    n_frames = check_int("n_frames", n_frames, 2)
    if boundary is not None and not isinstance(boundary, str):
        raise InputTypeError(f"boundary must be the name of a boundary of the mesh (str) or None, "
                        f"got {type(boundary).__name__}")
    if not isinstance(cmap, str):
        raise InputTypeError(f"cmap must be a colormap name (str), got {type(cmap).__name__}")
    f = sample_fields(solution, model, n_frames=n_frames)
    if f.dim == 1:
        raise InputValueError(f"the contact pressure needs a meshed solid (femodes.solid); this is a {f.kind} "
                         "model, whose contact forces femodes.plot.time_history draws")
    counts: dict = {}
    for b in f.contact_boundary:
        if b:
            counts[b] = counts.get(b, 0) + 1
    if not counts:
        raise InputValueError("the model has no contacts on a named boundary of its mesh; add some with "
                         "model.with_contact(fm.UnilateralContact(at=<boundary>, gap=..., direction=...))")
    carrying = ", ".join(repr(b) for b in sorted(counts))
    if boundary is None:
        boundary = max(sorted(counts), key=lambda b: counts[b])
    elif boundary not in f.boundaries:
        known = ", ".join(repr(b) for b in sorted(f.boundaries))
        raise InputValueError(f"unknown boundary {boundary!r}; the mesh has {known} (contacts on {carrying})")
    elif boundary not in counts:
        raise InputValueError(f"boundary {boundary!r} carries no contacts; contacts are on {carrying}")
    mine = np.array([c for c, b in enumerate(f.contact_boundary) if b == boundary])
    pressure = np.zeros((f.t.size, f.n_nodes))
    for c in mine:
        assert f.contact_measure is not None  # a solid's fields (dim > 1 checked above) have it
        pressure[:, f.contact_nodes[c]] += f.contact_force[:, c] / f.contact_measure[c]
    total = f.contact_force[:, mine].sum(axis=1)
    nodes, s = f.boundary_coordinate(boundary)
    values = pressure[:, nodes]
    if f.dim == 3:
        assert f.coordinates is not None  # MeshFields.__post_init__ fills it
        s, values = _columns(s, values, float(np.ptp(f.coordinates, axis=0).max()))
    # close the period: the row t/T = 1 is the row t = 0
    tau = np.append(np.arange(n_frames) / n_frames, 1.0)
    values = np.vstack([values, values[:1]])
    total = np.append(total, total[0])

    plt = pyplot()
    if ax is None:
        fig, ax = plt.subplots(figsize=(8.0, 4.5))
        fig.subplots_adjust(left=0.09, right=0.9, bottom=0.12, top=0.9)
    else:
        ax = axes(ax)
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
