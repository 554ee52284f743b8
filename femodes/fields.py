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
``force / measure`` (:meth:`MeshFields.contact_pressure`, :func:`tributary_measure`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Mapping

import numpy as np
import skfem
from skfem.helpers import dot

from .linear import LinearModes
from .model import StructuralModel
from .results import PeriodicSolution, contact_differences
from .store import model_signature, signature_differences
from .solvers.checks import check_int

__all__ = ["MeshFields", "mesh_fields", "periodic_source", "resolve_model", "check_scale", "tributary_measure",
           "VTK_QUADRATIC_NODES"]


# --------------------------------------------------------------------------------------------
# Validation helpers
# --------------------------------------------------------------------------------------------
def check_scale(scale: Any, owner: str) -> float | None:
    """``None`` or a finite non-zero real number."""
    if scale is None:
        return None
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)):
        raise TypeError(f"{owner}: scale must be a real number or None, got {type(scale).__name__}")
    if not math.isfinite(scale) or scale == 0:
        raise ValueError(f"{owner}: scale must be finite and non-zero, got {scale!r}")
    return float(scale)


def resolve_model(source: Any, model: Any, owner: str) -> StructuralModel:
    """The model a solution / modes live on: ``model`` or, if None, ``solution.model``."""
    if model is None:
        model = getattr(source, "model", None)
        if model is None:
            what = "linear modes" if isinstance(source, LinearModes) else "this solution (loaded from a file?)"
            raise ValueError(
                f"{owner}: model is required for {what}; pass the model it was solved on "
                "(or re-attach it with branch.attach(model))"
            )
    if not isinstance(model, StructuralModel):
        raise TypeError(f"{owner}: model must be a StructuralModel (the model the result lives on), got {type(model).__name__}")
    n = source.n_dofs if isinstance(source, PeriodicSolution) else np.asarray(source.shapes).shape[0]
    if model.n_dofs != n:
        raise ValueError(
            f"{owner}: model has {model.n_dofs} DOFs but the result has {n}; pass the model the result was computed on "
            "(for a Craig-Bampton result, the ReducedModel, not its parent)"
        )
    own = getattr(source, "model", None)
    if isinstance(source, PeriodicSolution) and model is not own:
        diff = contact_differences(source.contacts, model)
        if own is not None:
            diff += [d for d in signature_differences(model_signature(own), model_signature(model))
                     if not (d == "contact laws" and diff)]
        if diff:
            raise ValueError(f"{owner}: model differs from the one the solution was solved on ({'; '.join(diff)}); "
                             "pass the model the solution was computed on (or leave model=None)")
    return model


# --------------------------------------------------------------------------------------------
# Cells and boundaries of meshed solids
# --------------------------------------------------------------------------------------------
#: VTK order of the nodes of quadratic cells after the vertices: each is the mean of these VTK
#: vertices (checked against ``vtkCell.GetParametricCoords`` of vtkQuadraticTriangle,
#: vtkBiQuadraticQuad, vtkQuadraticTetra and vtkTriQuadraticHexahedron in the tests).
_HEX_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7))
_HEX_FACES = ((0, 3, 7, 4), (1, 2, 6, 5), (0, 1, 5, 4), (3, 2, 6, 7), (0, 1, 2, 3), (4, 5, 6, 7))
VTK_QUADRATIC_NODES = {
    "triangle6": ((0, 1), (1, 2), (2, 0)),
    "quad9": ((0, 1), (1, 2), (2, 3), (3, 0), (0, 1, 2, 3)),
    "tetra10": ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)),
    "hexahedron27": _HEX_EDGES + _HEX_FACES + (tuple(range(8)),),
}
#: meshio cell type of each scikit-fem cell (order 1, order 2) and the permutation of
#: ``mesh.t`` into VTK's vertex order (scikit-fem numbers hexahedron vertices differently;
#: the same permutation as ``skfem.io.meshio.HEX_MAPPING[:8]``).
_CELL_TYPES = (
    ("MeshTri1", ("triangle", "triangle6"), (0, 1, 2)),
    ("MeshQuad1", ("quad", "quad9"), (0, 1, 2, 3)),
    ("MeshTet1", ("tetra", "tetra10"), (0, 1, 2, 3)),
    ("MeshHex1", ("hexahedron", "hexahedron27"), (0, 3, 6, 2, 1, 5, 7, 4)),
)


@skfem.BilinearForm
def _boundary_mass(u, v, w):
    # int u . v ds on boundary facets; its diagonal at the first component is the scalar one
    return dot(u, v)


@skfem.Functional
def _boundary_length(w):
    # int 1 ds
    return 1.0 + 0.0 * w.x[0]


def _solid_cells(fe: Any) -> tuple[str, np.ndarray]:
    """meshio cell type and connectivity (node indices, VTK node order) of a solid's mesh.

    Order 1: the vertices (nodes ``0 .. n_vertices - 1`` are the mesh vertices). Order 2: the
    quadratic VTK cell; its edge/face/centre nodes are found among the cell's nodes as the ones
    nearest to the means of the vertices that define them (exact for straight-sided cells).
    """
    mesh, nodal = fe.mesh, np.asarray(fe.nodal)
    for cls, types, perm in _CELL_TYPES:
        if isinstance(mesh, getattr(skfem, cls)):
            break
    else:  # pragma: no cover - fm.solid accepts only these meshes
        raise TypeError(f"mesh_fields: no VTK cell type for a {type(mesh).__name__}")
    vertices = _positively_oriented(np.asarray(mesh.t)[list(perm)].T, np.asarray(mesh.p, dtype=float).T)
    n_vertices = np.asarray(mesh.p).shape[1]
    if nodal.shape[1] == n_vertices:
        return types[0], vertices
    cell_type = types[1]
    node_of_full = np.empty(fe.n_full, dtype=np.int64)
    node_of_full[nodal] = np.arange(nodal.shape[1])[None, :]
    comp_of_full = np.empty(fe.n_full, dtype=np.int64)
    comp_of_full[nodal] = np.arange(nodal.shape[0])[:, None]
    edofs = np.asarray(fe.element_dofs)  # without building the basis (fe.basis: large meshes)
    candidates = node_of_full[edofs[comp_of_full[edofs[:, 0]] == 0]].T  # (n_cells, n_local_nodes)
    X = np.asarray(fe.node_coordinates, dtype=float).T  # (n_nodes, dim)
    higher = np.empty((vertices.shape[0], len(VTK_QUADRATIC_NODES[cell_type])), dtype=np.int64)
    for start in range(0, vertices.shape[0], 4096):  # bounded memory for large meshes
        sl = slice(start, start + 4096)
        target = np.stack([X[vertices[sl][:, list(s)]].mean(axis=1) for s in VTK_QUADRATIC_NODES[cell_type]], axis=1)
        cand = X[candidates[sl]]  # (n, n_local, dim)
        d = np.linalg.norm(target[:, :, None, :] - cand[:, None, :, :], axis=-1)
        higher[sl] = np.take_along_axis(candidates[sl], np.argmin(d, axis=2), axis=1)
    cells = np.hstack([vertices, higher])
    if np.any(np.sort(cells, axis=1)[:, 1:] == np.sort(cells, axis=1)[:, :-1]):  # pragma: no cover
        raise RuntimeError(f"mesh_fields: could not order the nodes of the {cell_type} cells (curved cells?)")
    return cell_type, cells


#: Vertex swap that mirrors a cell of 3 (triangle), 4 (quad in 2-D, tetra) or 8 (hexahedron) vertices.
_MIRROR = {(2, 3): (0, 2, 1), (2, 4): (0, 3, 2, 1), (3, 4): (0, 2, 1, 3), (3, 8): (0, 3, 2, 1, 4, 7, 6, 5)}


def _positively_oriented(vertices: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Cells (VTK vertex order) mirrored where their orientation is negative.

    VTK expects positive volumes (counter-clockwise 2-D cells); scikit-fem's tetrahedra from
    ``init_tensor`` come with both orientations (half of the cells of :func:`femodes.box_mesh`).
    The sign is that of the Jacobian at vertex 0 (edges to vertices 1, last-in-face and 4).
    """
    dim, nv = X.shape[1], vertices.shape[1]
    P = X[vertices]
    if dim == 2:
        a, b = P[:, 1] - P[:, 0], P[:, -1] - P[:, 0]
        sign = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    else:
        third = 3 if nv == 4 else 4  # tetra: vertex 3; hexahedron: vertex 4 (above vertex 0)
        sign = np.einsum("nd,nd->n", np.cross(P[:, 1] - P[:, 0], P[:, 2 if nv == 4 else 3] - P[:, 0]),
                         P[:, third] - P[:, 0])
    flip = sign < 0
    if flip.any():
        vertices = vertices.copy()
        vertices[flip] = vertices[flip][:, list(_MIRROR[dim, nv])]
    return vertices


def _cyclic(facets: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Quadrilateral facets with their vertices in cyclic order (by angle about the centre)."""
    if facets.shape[1] != 4 or X.shape[1] != 3:
        return facets
    P = X[facets]  # (n, 4, 3)
    c = P.mean(axis=1, keepdims=True)
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    e1 = P[:, 0] - c[:, 0]
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(n, e1)
    e2 /= np.maximum(np.linalg.norm(e2, axis=1, keepdims=True), 1e-300)
    ang = np.arctan2(np.einsum("nkd,nd->nk", P - c, e2), np.einsum("nkd,nd->nk", P - c, e1))
    return np.take_along_axis(facets, np.argsort(ang, axis=1), axis=1)


def _boundary_facets(fe: Any) -> dict:
    """Vertex nodes of the facets of every named boundary, ``{name: (n_facets, n_facet_vertices)}``."""
    mesh = fe.mesh
    X = np.asarray(fe.node_coordinates, dtype=float).T
    out = {}
    for name, facets in (mesh.boundaries or {}).items():
        facets = np.asarray(facets, dtype=np.int64)
        if facets.size:
            out[name] = _cyclic(np.asarray(mesh.facets)[:, facets].T, X)
    return out


def tributary_measure(model: StructuralModel, boundary: str) -> tuple[np.ndarray, np.ndarray]:
    """Tributary length (2-D, times the thickness) or area (3-D) of every node of a named boundary.

    ``a_k = |Gamma| t B_kk / sum_j B_jj`` with ``B_ij = int_Gamma N_i N_j ds``: the diagonal
    ("HRZ") lumping of the boundary mass (Hinton, Rock & Zienkiewicz 1976), positive at every
    node and summing to the boundary measure ``|Gamma| t`` (``t`` the thickness of a 2-D
    solid, 1 in 3-D). On straight-sided facets it equals the consistent weight
    ``int_Gamma N_k ds`` (``model.dofmap.group_weights``, normalised to sum 1, times
    ``|Gamma|``) for P1, Q1, Q2 and 2-D P2 elements. The consistent weight of a vertex of a P2
    triangle facet (faces of P2 tetrahedra) is zero, so ``force / weight`` would be no
    pressure there; the lumped measure gives it ``6/114`` of each adjacent facet's area.

    Parameters
    ----------
    model : StructuralModel
        A meshed solid (:func:`femodes.solid`) or a reduction of one.
    boundary : str
        A named boundary of its mesh.

    Returns
    -------
    nodes : ndarray of int
        The nodes of the boundary (``model.dofmap.groups[boundary]`` of the mesh owner).
    measure : ndarray
        Their tributary measure.

    Raises
    ------
    ValueError
        Not a meshed solid; unknown ``boundary`` (the message lists the mesh's boundaries).
    """
    owner = getattr(model, "mesh_owner", None)
    if owner is None or owner.fe.kind != "solid":
        raise ValueError("tributary_measure: model must be a meshed solid (femodes.solid) or a reduction of one")
    fe = owner.fe
    groups = owner.dofmap.groups
    if boundary not in groups or boundary not in (fe.mesh.boundaries or {}):
        known = ", ".join(repr(b) for b in sorted(groups)) or "none"
        raise ValueError(f"tributary_measure: unknown boundary {boundary!r}; the mesh has {known}")
    facets = np.asarray(fe.mesh.boundaries[boundary], dtype=np.int64)
    nodes = np.asarray(groups[boundary], dtype=np.int64)
    fb = skfem.FacetBasis(fe.mesh, fe.element, facets=facets)
    diag = _boundary_mass.assemble(fb).diagonal()[np.asarray(fe.nodal)[0, nodes]]
    total = float(_boundary_length.assemble(fb)) * float(fe.thickness)
    return nodes, diag * (total / diag.sum())


def _contact_boundaries(groups: Mapping, nodes: np.ndarray, comps: np.ndarray) -> list[str]:
    """The named boundary of each contact: among the boundaries holding its node, the one holding
    the most contact nodes of the same component (ties: the smaller boundary, then the name);
    ``""`` for a node on no named boundary (a contact at a named point)."""
    nodes, comps = np.asarray(nodes, dtype=np.int64), np.asarray(comps, dtype=np.int64)
    member = {name: np.isin(nodes, np.asarray(g)) for name, g in groups.items()}
    count = {(name, c): int(np.count_nonzero(m & (comps == c)))
             for name, m in member.items() for c in set(comps.tolist())}
    out = []
    for k, (node, comp) in enumerate(zip(nodes, comps)):
        keys = [(-count[name, int(comp)], np.asarray(groups[name]).size, name)
                for name, m in member.items() if node >= 0 and m[k]]
        out.append(min(keys)[2] if keys else "")
    return out


def _polyline_order(edges: np.ndarray) -> list[np.ndarray]:
    """Vertex chains of a set of edges (each open chain from an end, closed loops from any vertex)."""
    adj: dict = {}
    for a, b in edges:
        adj.setdefault(int(a), []).append(int(b))
        adj.setdefault(int(b), []).append(int(a))
    seen_edges: set = set()
    chains = []
    starts = sorted(v for v, nb in adj.items() if len(nb) == 1) + sorted(adj)
    for s in starts:
        if all(frozenset((s, n)) in seen_edges for n in adj[s]):
            continue
        chain, cur = [s], s
        while True:
            nxt = [n for n in adj[cur] if frozenset((cur, n)) not in seen_edges]
            if not nxt:
                break
            seen_edges.add(frozenset((cur, nxt[0])))
            cur = nxt[0]
            chain.append(cur)
        chains.append(np.asarray(chain))
    return chains


# --------------------------------------------------------------------------------------------
# Nodal fields on the mesh
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MeshFields:
    """Nodal fields of a periodic motion sampled at times ``t`` on the FE mesh.

    One class for every mesh: bars and beams (``dim == 1``: scalar nodal motion along the
    axis, resp. across it) and meshed 2-D/3-D solids (``dim`` 2 or 3: displacement vectors).

    Attributes
    ----------
    kind : str
        ``"bar"`` (``displacement`` is the axial ``u``), ``"beam"`` (transverse ``w``) or
        ``"solid"`` (the displacement vector).
    x : ndarray (n_nodes,)
        First coordinate of the nodes (the position along the axis of bars and beams).
    cells : ndarray (n_cells, n_cell_nodes)
        Connectivity in VTK node order, of type ``cell_type``. Bars and beams: the mesh vertices
        (higher-order interior DOFs are not exported). Solids: every Lagrange node; order-2
        meshes give quadratic cells (all nodes carry data, also the P2 mid-side contact nodes).
    t : ndarray (n_t,)
        Sample times.
    period : float
    omega : float
    displacement, velocity : ndarray
        ``(n_t, n_nodes)`` for bars and beams (``u`` resp. ``w`` and its time derivative),
        ``(n_t, n_nodes, 3)`` vectors for solids (zero third component in 2-D).
        :meth:`displacement_vectors` gives vectors for every kind.
    rotation : ndarray (n_t, n_nodes) or None
        Beam rotation ``theta`` (None otherwise).
    contact_nodes : ndarray of int (n_contacts,)
        Node of each contact (``-1`` if it cannot be located on the mesh).
    contact_gaps : ndarray (n_contacts,)
        Initial gap of each contact; the obstacle is at ``x_node + gap * direction``.
    contact_force : ndarray (n_t, n_contacts)
        Contact force ``p`` (compression positive; zeros for linear modes).
    dim : int
        1 (bars, beams), 2 or 3 (solids).
    cell_type : str
        meshio cell type of ``cells``: ``"line"``; ``"triangle"``, ``"quad"``, ``"tetra"``,
        ``"hexahedron"`` (order 1) or ``"triangle6"``, ``"quad9"``, ``"tetra10"``,
        ``"hexahedron27"`` (order 2).
    coordinates : ndarray (n_nodes, 3)
        Undeformed node coordinates (missing components zero).
    contact_direction : ndarray (n_contacts, 3)
        Unit vector of each contact: the displacement component the contact acts on
        (``g_N = gap - direction . u``), its normal for a rotated node of a solid (inclined or
        negative normals, ``model.dofmap.frames``); ``e_x`` for bars, ``e_y`` for beams.
    contact_boundary : tuple of str
        Named boundary of each contact (solids; ``""`` for a contact on a named point or a
        1-D model): among the boundaries holding the node, the one holding the most contact
        nodes with the same direction.
    contact_measure : ndarray (n_contacts,) or None
        Tributary measure of each contact node on its boundary (length times thickness in
        2-D, area in 3-D; :func:`tributary_measure`), zero for a contact on no named boundary;
        None for bars and beams.
    boundaries : mapping str -> ndarray of int
        Nodes of every named boundary of a solid (every Lagrange node).
    boundary_facets : mapping str -> ndarray (n_facets, n_facet_vertices)
        Vertex nodes of the facets of every named boundary (edges in 2-D, triangles or
        quadrilaterals in cyclic order in 3-D).
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
        X = self.coordinates[nodes]
        if self.dim == 2:
            chains = _polyline_order(self.boundary_facets[name][:, :2])
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


def periodic_source(source: Any, mode: Any, owner: str):
    """``(source, None)`` for a PeriodicSolution; ``(modes, j)`` for LinearModes and the mode number
    ``mode`` (1-based: ``mode=1`` is the first mode, column ``j = mode - 1`` of ``modes.shapes``)."""
    if isinstance(source, PeriodicSolution):
        return source, None
    if isinstance(source, LinearModes):
        number = check_int("mode", mode, 1, owner=owner)  # mode numbers are 1-based everywhere (mode=1: the first)
        if number > len(source):
            raise ValueError(f"{owner}: mode={number} is out of range; the modes hold {len(source)} shapes "
                             f"(mode=1 .. {len(source)})")
        j = number - 1
        if not source.omega[j] > 0:
            raise ValueError(f"{owner}: mode {number} has zero frequency (rigid-body mode); it has no period to animate")
        return source, j
    raise TypeError(
        f"{owner}: expected a PeriodicSolution (e.g. branch[i]) or LinearModes (femodes.linear_modes), "
        f"got {type(source).__name__}"
    )


def mesh_fields(source: Any, model: Any, t: Any = None, *, n_frames: int = 36, mode: int | None = None,
                owner: str = "mesh_fields") -> MeshFields:
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
    owner : str
        Name used in error messages.

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
    source, j = periodic_source(source, mode, owner)
    model = resolve_model(source, model, owner)
    owner_model = model.mesh_owner
    if owner_model is None:
        raise ValueError(
            f"{owner}: the model has no mesh (a discrete StructuralModel); only FE models built with femodes.bar, "
            "femodes.beam or femodes.solid (or Craig-Bampton reductions of them) can be exported on a mesh. For discrete systems plot "
            "time histories instead (femodes.plot.time_history, femodes.plot.mode_shape)"
        )
    fe = owner_model.fe
    if j is None:
        omega, period = float(source.omega), float(source.period)
    else:
        omega = float(source.omega[j])
        period = 2.0 * math.pi / omega
    if t is None:
        n_frames = check_int("n_frames", n_frames, 1, owner=owner)
        t = np.arange(n_frames) * period / n_frames  # exactly j * T / n_frames
    else:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if t.ndim != 1 or not np.all(np.isfinite(t)):
            raise ValueError(f"{owner}: t must be a 1-D array of finite times, got shape {t.shape}")
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
    uq, uv = model.full_field(q), model.full_field(v)
    nodal = np.asarray(fe.nodal)
    nodes, comps = [], []
    for d in dofs:
        full = model.fe_dof(int(d))
        hit = np.argwhere(nodal == full) if full is not None else np.zeros((0, 2))
        nodes.append(int(hit[0, 1]) if hit.size else -1)
        comps.append(int(hit[0, 0]) if hit.size else 0)
    nodes = np.asarray(nodes, dtype=int)
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
            direction[j, :dim] = owner_model.dofmap.axis(int(node), int(comp))
        else:
            direction[j, comp] = 1.0
    groups = {name: np.asarray(g, dtype=np.int64) for name, g in owner_model.dofmap.groups.items()}
    boundary = _contact_boundaries(groups, nodes, np.asarray(comps))
    measure = np.zeros(nodes.size)
    for name in sorted(set(boundary) - {""}):
        bnodes, a = tributary_measure(owner_model, name)
        lookup = dict(zip(bnodes.tolist(), a.tolist()))
        for j, b in enumerate(boundary):
            if b == name:
                measure[j] = lookup[int(nodes[j])]
    cell_type, cells = _solid_cells(fe)
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
        boundary_facets=_boundary_facets(fe),
        **common,
    )
