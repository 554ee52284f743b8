"""Outputs layer: the nodal fields of a periodic motion on the FE mesh, shared by all outputs.

:func:`mesh_fields` samples a :class:`~femodes.results.PeriodicSolution` (or a linear mode,
``q(t) = phi cos(w t)``) at given times on the mesh of the model that owns it (reduced models
are expanded to the full mesh of their parent) and returns :class:`MeshFields`, which the
ParaView writer (:mod:`femodes.io`), the plots (:mod:`femodes.plot`) and the renderer
(:mod:`femodes.viz`) all use.

Bars and beams carry a scalar nodal motion (along resp. across the axis); meshed solids
(:func:`femodes.solid`) carry displacement vectors on every Lagrange node, with VTK cells
(quadratic ones for order 2), the direction and named boundary of each contact and the
tributary measure of each contact node, from which the nodal contact pressure is
``force / measure`` (:meth:`MeshFields.contact_pressure`, :func:`tributary_measure`). The cells
and boundaries of meshed solids behind these fields are in :mod:`femodes.solid_cells`
(:func:`tributary_measure` and :data:`VTK_QUADRATIC_NODES` are re-exported here).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Mapping

import numpy as np

from .linear import LinearModes
from .model import StructuralModel
from .results import PeriodicSolution, contact_differences
from .store import model_signature, signature_differences
from .solid_cells import (VTK_QUADRATIC_NODES, boundary_facets, contact_boundaries, polyline_order, solid_cells,
                          tributary_measure)
from .solvers.checks import InputTypeError, InputValueError, check_int, entry_point, user_stacklevel

__all__ = ["MeshFields", "mesh_fields", "sample_fields", "periodic_source", "resolve_model", "check_scale", "tributary_measure",
           "VTK_QUADRATIC_NODES"]


# --------------------------------------------------------------------------------------------
# Validation helpers
# --------------------------------------------------------------------------------------------
def check_scale(scale: Any) -> float | None:
    """``None`` or a finite non-zero real number."""
    if scale is None:
        return None
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"scale must be a real number or None, got {type(scale).__name__}")
    if not math.isfinite(scale) or scale == 0:
        raise InputValueError(f"scale must be finite and non-zero, got {scale!r}")
    return float(scale)


def resolve_model(source: Any, model: Any) -> StructuralModel:
    """The model a solution / modes live on: ``model`` or, if None, ``solution.model``."""
    if model is None:
        model = getattr(source, "model", None)
        if model is None:
            what = "linear modes" if isinstance(source, LinearModes) else "this solution (loaded from a file?)"
            raise InputValueError(
                f"model is required for {what}; pass the model it was solved on "
                "(or re-attach it with branch.attach(model))"
            )
    if not isinstance(model, StructuralModel):
        raise InputTypeError(f"model must be a StructuralModel (the model the result lives on), got {type(model).__name__}")
    n = source.n_dofs if isinstance(source, PeriodicSolution) else np.asarray(source.shapes).shape[0]
    if model.n_dofs != n:
        raise InputValueError(
            f"model has {model.n_dofs} DOFs but the result has {n}; pass the model the result was computed on "
            "(for a Craig-Bampton result, the ReducedModel, not its parent)"
        )
    own = getattr(source, "model", None)
    if isinstance(source, PeriodicSolution) and model is not own:
        diff = contact_differences(source.contacts, model)
        if own is not None:
            diff += [d for d in signature_differences(model_signature(own), model_signature(model))
                     if not (d == "contact laws" and diff)]
        if diff:
            raise InputValueError(f"model differs from the one the solution was solved on ({'; '.join(diff)}); "
                             "pass the model the solution was computed on (or leave model=None)")
    return model


# --------------------------------------------------------------------------------------------
# Nodal fields on the mesh
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MeshFields:
    """Nodal fields of a periodic motion sampled at times ``t`` on the FE mesh, for every mesh.

    Attributes
    ----------
    kind : str
        ``"bar"`` (``displacement`` is the axial ``u``), ``"beam"`` (transverse ``w``) or ``"solid"``.
    dim : int
        1 (bars, beams: scalar nodal motion), 2 or 3 (solids: displacement vectors).
    x, coordinates : ndarray (n_nodes,), ndarray (n_nodes, 3)
        First coordinate of the nodes (along the axis of bars and beams); undeformed coordinates.
    cells, cell_type : ndarray (n_cells, n_cell_nodes), str
        Connectivity in VTK node order and its meshio type (``"line"``, ``"triangle"``... or the order-2
        ``"triangle6"``, ``"quad9"``, ``"tetra10"``, ``"hexahedron27"``). Bars and beams: the vertices;
        solids: every Lagrange node (P2 mid-side contact nodes included).
    t, period, omega : ndarray (n_t,), float, float
        Sample times, period and angular frequency.
    displacement, velocity : ndarray
        ``(n_t, n_nodes)`` for bars and beams, ``(n_t, n_nodes, 3)`` for solids (zero third component
        in 2-D); :meth:`displacement_vectors` gives vectors for every kind.
    rotation : ndarray (n_t, n_nodes) or None
        Beam rotation ``theta`` (None otherwise).
    contact_nodes, contact_gaps : ndarray of int (n_contacts,), ndarray (n_contacts,)
        Node of each contact (``-1`` if not on the mesh) and its initial gap; the obstacle is at
        ``x_node + gap * direction``.
    contact_force : ndarray (n_t, n_contacts)
        Contact force ``p`` (compression positive; zeros for linear modes).
    contact_direction : ndarray (n_contacts, 3)
        Unit vector of each contact (``g_N = gap - direction . u``): its normal for a rotated node of a
        solid (``model.dofmap.frames``), ``e_x`` for bars, ``e_y`` for beams.
    contact_boundary : tuple of str
        Named boundary of each contact (the one holding the most contact nodes with the same
        direction); ``""`` for a contact on a named point or a 1-D model.
    contact_measure : ndarray (n_contacts,) or None
        Tributary measure of each contact node on its boundary (:func:`tributary_measure`), zero off
        named boundaries; None for bars and beams.
    boundaries : mapping str -> ndarray of int
        Nodes of every named boundary of a solid (every Lagrange node).
    boundary_facets : mapping str -> ndarray (n_facets, n_facet_vertices)
        Vertex nodes of the facets of every named boundary (edges in 2-D, cyclic polygons in 3-D).
    """

    kind: str
    x: np.ndarray
    cells: np.ndarray
    t: np.ndarray
    period: float
    omega: float
    displacement: np.ndarray
    velocity: np.ndarray
    rotation: np.ndarray | None
    contact_nodes: np.ndarray
    contact_gaps: np.ndarray
    contact_force: np.ndarray
    dim: int = 1
    cell_type: str = "line"
    coordinates: np.ndarray | None = None
    contact_direction: np.ndarray | None = None
    contact_boundary: tuple = ()
    contact_measure: np.ndarray | None = None
    boundaries: Mapping[str, np.ndarray] = field(default_factory=dict)
    boundary_facets: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        if self.coordinates is None:
            p = np.zeros((np.asarray(self.x).size, 3))
            p[:, 0] = self.x
            object.__setattr__(self, "coordinates", p)
        if self.contact_direction is None:
            d = np.zeros((np.asarray(self.contact_nodes).size, 3))
            d[:, 0 if self.kind == "bar" else 1] = 1.0
            object.__setattr__(self, "contact_direction", d)
        if not self.contact_boundary:
            object.__setattr__(self, "contact_boundary", ("",) * np.asarray(self.contact_nodes).size)

    @property
    def n_nodes(self) -> int:
        return self.x.size

    def nodal_contact_force(self) -> np.ndarray:
        """Contact force ``p`` per node, ``(n_t, n_nodes)``, nonzero only at contact nodes
        (summed over the contacts of a node)."""
        out = np.zeros((self.t.size, self.n_nodes))
        for j, node in enumerate(self.contact_nodes):
            if node >= 0:
                out[:, node] += self.contact_force[:, j]
        return out

    def contact_force_vectors(self) -> np.ndarray:
        """Force of the obstacles on the structure per node, ``(n_t, n_nodes, 3)``:
        ``-p direction`` summed over the contacts of a node (it points away from the obstacle,
        into the body; its length is the compression-positive ``p``)."""
        out = np.zeros((self.t.size, self.n_nodes, 3))
        for j, node in enumerate(self.contact_nodes):
            if node >= 0:
                assert self.contact_direction is not None  # __post_init__ fills it
                out[:, node, :] -= self.contact_force[:, j, None] * self.contact_direction[j][None, :]
        return out

    def contact_pressure(self) -> np.ndarray:
        """Nodal contact pressure ``p / a`` (compression positive), ``(n_t, n_nodes)``.

        ``a`` is the tributary measure of the contact node (``contact_measure``), so that
        ``sum_k pressure_k a_k`` is the total contact force of the boundary; summed over the
        contacts of a node; zero off the contact boundaries and for contacts with no tributary
        measure (named points, bars and beams).
        """
        out = np.zeros((self.t.size, self.n_nodes))
        if self.contact_measure is None:
            return out
        for j, node in enumerate(self.contact_nodes):
            a = self.contact_measure[j]
            if node >= 0 and a > 0:
                out[:, node] += self.contact_force[:, j] / a
        return out

    def vector(self, values: np.ndarray) -> np.ndarray:
        """Nodal scalars ``(..., n_nodes)`` of a bar or beam as 3-D vectors ``(..., n_nodes, 3)`` in
        the motion direction (bars ``x``, beams ``y``)."""
        if self.dim != 1:
            raise ValueError(f"MeshFields.vector: nodal scalars have no direction on a {self.dim}-D solid; "
                             "use displacement_vectors() / velocity_vectors()")
        out = np.zeros(values.shape + (3,))
        out[..., 0 if self.kind == "bar" else 1] = values
        return out

    def displacement_vectors(self) -> np.ndarray:
        """Displacement vectors ``(n_t, n_nodes, 3)`` for every kind."""
        return self.vector(self.displacement) if self.dim == 1 else self.displacement

    def velocity_vectors(self) -> np.ndarray:
        """Velocity vectors ``(n_t, n_nodes, 3)`` for every kind."""
        return self.vector(self.velocity) if self.dim == 1 else self.velocity

    def points(self) -> np.ndarray:
        """Undeformed node coordinates in 3-D, ``(n_nodes, 3)`` (a copy)."""
        return np.array(self.coordinates, dtype=float)

    def obstacle_points(self, scale: float = 1.0) -> np.ndarray:
        """Obstacle point of each contact, ``x_node + scale * gap * direction``, ``(n_contacts, 3)``
        (NaN for contacts not on a mesh node). With the displacement drawn ``scale`` times
        magnified, the obstacle drawn at ``scale * gap`` is touched exactly when the contact closes."""
        out = np.full((self.contact_nodes.size, 3), np.nan)
        ok = self.contact_nodes >= 0
        assert self.coordinates is not None and self.contact_direction is not None  # __post_init__ fills them
        out[ok] = self.coordinates[self.contact_nodes[ok]] + scale * (self.contact_gaps[ok, None]
                                                                       * self.contact_direction[ok])
        return out

    def boundary_coordinate(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Nodes of a named boundary of a solid ordered along it, with their coordinate ``s``.

        2-D: the arc length along the boundary curve (its edges chained from one end; the
        P2 mid-side nodes projected onto it; separate pieces follow each other). 3-D (a
        surface has no arc length): the distance along the boundary's principal axis (largest
        extent), measured from its first node.

        Returns
        -------
        nodes : ndarray of int
            The boundary's nodes, sorted by ``s``.
        s : ndarray
        """
        if name not in self.boundaries:
            known = ", ".join(repr(k) for k in sorted(self.boundaries)) or "none"
            raise ValueError(f"MeshFields.boundary_coordinate: unknown boundary {name!r}; the mesh has {known}")
        nodes = np.asarray(self.boundaries[name], dtype=np.int64)
        assert self.coordinates is not None  # __post_init__ fills it
        X = self.coordinates[nodes]
        if self.dim == 2:
            chains = polyline_order(self.boundary_facets[name][:, :2])
            s, best = np.zeros(nodes.size), np.full(nodes.size, np.inf)
            offset = 0.0
            for chain in chains:
                P = self.coordinates[chain]
                seg = P[1:] - P[:-1]
                lengths = np.linalg.norm(seg, axis=1)
                start = offset + np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
                # projection of every node onto every segment of the chain; the nearest one wins
                r = X[:, None, :] - P[None, :-1, :]
                tau = np.clip(np.einsum("nsd,sd->ns", r, seg) / np.maximum(lengths**2, 1e-300), 0.0, 1.0)
                dist = np.linalg.norm(r - tau[..., None] * seg[None], axis=2)
                k = np.argmin(dist, axis=1)
                rows = np.arange(nodes.size)
                take = dist[rows, k] < best
                s[take] = start[k[take]] + tau[rows, k][take] * lengths[k[take]]
                best[take] = dist[rows, k][take]
                offset += float(lengths.sum())
        else:
            centred = X - X.mean(axis=0)
            axis = np.linalg.svd(centred, full_matrices=False)[2][0]
            axis = axis if axis[np.argmax(np.abs(axis))] > 0 else -axis  # along the positive coordinate axis
            s = centred @ axis
            s -= s.min()
        order = np.argsort(s, kind="stable")
        return nodes[order], s[order]


def periodic_source(source: Any, mode: Any):
    """``(source, None)`` for a PeriodicSolution; ``(modes, j)`` for LinearModes and the mode number
    ``mode`` (1-based: ``mode=1`` is the first mode, column ``j = mode - 1`` of ``modes.shapes``)."""
    if isinstance(source, PeriodicSolution):
        return source, None
    if isinstance(source, LinearModes):
        number = check_int("mode", mode, 1)  # mode numbers are 1-based everywhere (mode=1: the first)
        if number > len(source):
            raise InputValueError(f"mode={number} is out of range; the modes hold {len(source)} shapes "
                             f"(mode=1 .. {len(source)})")
        j = number - 1
        if not source.omega[j] > 0:
            raise InputValueError(f"mode {number} has zero frequency (rigid-body mode); it has no period to animate")
        return source, j
    raise InputTypeError(
        f"expected a PeriodicSolution (e.g. branch[i]) or LinearModes (femodes.linear_modes), "
        f"got {type(source).__name__}"
    )


@entry_point("mesh_fields")
def mesh_fields(source: Any, model: Any, t: Any = None, *, n_frames: int = 36, mode: int | None = None,
                owner: str | None = None) -> MeshFields:
    """Sample a periodic motion on the FE mesh.

    Parameters
    ----------
    source : PeriodicSolution or LinearModes
        A periodic solution, or linear modes (then ``mode`` selects the shape and the motion is
        ``phi cos(w t)``).
    model : StructuralModel or None
        The model the result lives on (None: ``solution.model``). Reduced models are expanded to
        the full mesh of their parent.
    t : array_like, optional
        Sample times; default ``j T / n_frames``, ``j = 0 .. n_frames - 1``.
    n_frames : int
        Number of samples over one period when ``t`` is not given.
    mode : int, optional
        Mode number for ``LinearModes`` (1 = the first mode, as in ``nonlinear_mode(mode=1)``).
    owner : str, optional
        Deprecated and ignored (a DeprecationWarning): error messages name the public function
        called, here ``mesh_fields``.

    Returns
    -------
    MeshFields

    Raises
    ------
    ValueError
        Discrete model without a mesh, model not matching the result, bad ``n_frames``/``mode``.
    TypeError
        ``source`` or ``model`` of the wrong type.
    """
    if owner is not None:
        warnings.warn("mesh_fields(..., owner=...) is deprecated and ignored: error messages name the public "
                      "function called", DeprecationWarning, stacklevel=user_stacklevel())
    return sample_fields(source, model, t, n_frames=n_frames, mode=mode)


def sample_fields(source: Any, model: Any, t: Any = None, *, n_frames: int = 36, mode: int | None = None) -> MeshFields:
    """:func:`mesh_fields` for the public functions built on it (``animate``, the VTK writers,
    the plots): its errors are left for the function called to name."""
    source, j = periodic_source(source, mode)
    model = resolve_model(source, model)
    mesh_model = model.mesh_map.owner
    if mesh_model is None:
        raise InputValueError(
            "the model has no mesh (a discrete StructuralModel); only FE models built with femodes.bar, "
            "femodes.beam or femodes.solid (or Craig-Bampton reductions of them) can be exported on a mesh. For discrete systems plot "
            "time histories instead (femodes.plot.time_history, femodes.plot.mode_shape)"
        )
    fe = mesh_model.fe
    if j is None:
        omega, period = float(source.omega), float(source.period)
    else:
        omega = float(source.omega[j])
        period = 2.0 * math.pi / omega
    if t is None:
        n_frames = check_int("n_frames", n_frames, 1)
        t = np.arange(n_frames) * period / n_frames  # exactly j * T / n_frames
    else:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if t.ndim != 1 or not np.all(np.isfinite(t)):
            raise InputValueError(f"t must be a 1-D array of finite times, got shape {t.shape}")
    if j is None:
        q, v = source.displacement(t), source.velocity(t)
        force = source.contact_force(t)
        dofs, gaps = list(source.contacts.dofs), list(source.contacts.gaps)
    else:
        phi = np.asarray(source.shapes)[:, j]
        q = np.cos(omega * t)[:, None] * phi[None, :]
        v = -omega * np.sin(omega * t)[:, None] * phi[None, :]
        dofs = [a.dof for a in model.contacts]
        gaps = [float(a.item.gap) for a in model.contacts]
        force = np.zeros((t.size, len(dofs)))
    uq, uv = model.mesh_map.full_field(q), model.mesh_map.full_field(v)
    nodal = np.asarray(fe.nodal)
    node_list: list[int] = []
    comps: list[int] = []
    for d in dofs:
        full = model.mesh_map.fe_dof(int(d))
        hit = np.argwhere(nodal == full) if full is not None else np.zeros((0, 2))
        node_list.append(int(hit[0, 1]) if hit.size else -1)
        comps.append(int(hit[0, 0]) if hit.size else 0)
    nodes = np.asarray(node_list, dtype=int)
    force = np.asarray(force, dtype=float).reshape(t.size, len(dofs))
    common = dict(t=t, period=period, omega=omega, contact_nodes=nodes, contact_gaps=np.asarray(gaps, dtype=float),
                  contact_force=force)
    if fe.kind != "solid":
        mesh = fe.mesh
        return MeshFields(
            kind=str(fe.kind),
            x=np.asarray(mesh.p[0], dtype=float),
            cells=np.asarray(mesh.t[:2].T, dtype=int),
            displacement=uq[:, nodal[0]],
            velocity=uv[:, nodal[0]],
            rotation=uq[:, nodal[1]] if fe.kind == "beam" and nodal.shape[0] > 1 else None,
            **common,
        )
    dim = nodal.shape[0]
    coords = np.zeros((nodal.shape[1], 3))
    coords[:, :dim] = np.asarray(fe.node_coordinates, dtype=float).T
    disp = np.zeros((t.size, nodal.shape[1], 3))
    vel = np.zeros_like(disp)
    disp[..., :dim] = np.moveaxis(uq[:, nodal], 1, 2)
    vel[..., :dim] = np.moveaxis(uv[:, nodal], 1, 2)
    direction = np.zeros((nodes.size, 3))
    for j, (node, comp) in enumerate(zip(nodes, comps)):
        if node >= 0:  # e_comp, or the nodal-frame axis of a rotated node (inclined or negative normal)
            direction[j, :dim] = mesh_model.dofmap.axis(int(node), int(comp))
        else:
            direction[j, comp] = 1.0
    groups = {name: np.asarray(g, dtype=np.int64) for name, g in mesh_model.dofmap.groups.items()}
    boundary = contact_boundaries(groups, nodes, np.asarray(comps))
    measure = np.zeros(nodes.size)
    for name in sorted(set(boundary) - {""}):
        bnodes, a = tributary_measure(mesh_model, name)
        lookup = dict(zip(bnodes.tolist(), a.tolist()))
        for j, b in enumerate(boundary):
            if b == name:
                measure[j] = lookup[int(nodes[j])]
    cell_type, cells = solid_cells(fe)
    return MeshFields(
        kind="solid",
        x=coords[:, 0].copy(),
        cells=cells,
        displacement=disp,
        velocity=vel,
        rotation=None,
        dim=dim,
        cell_type=cell_type,
        coordinates=coords,
        contact_direction=direction,
        contact_boundary=tuple(boundary),
        contact_measure=measure,
        boundaries=groups,
        boundary_facets=boundary_facets(fe),
        **common,
    )
