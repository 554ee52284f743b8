"""Outputs layer: cells and boundaries of meshed solids, as the mesh fields need them.

The meshio/VTK cell type and node order of a solid's mesh (:func:`solid_cells`,
:data:`VTK_QUADRATIC_NODES`), its boundary facets (:func:`boundary_facets`), the tributary
measure of the contact nodes of a boundary (:func:`tributary_measure`, from which the nodal
contact pressure is ``force / measure``), the boundaries the contacts sit on
(:func:`contact_boundaries`) and the polylines along a 2-D boundary (:func:`polyline_order`).
:mod:`femodes.fields` re-exports the public ones.
"""

from __future__ import annotations

from typing import Any
from collections.abc import Mapping

import numpy as np
import skfem
from skfem.helpers import dot

from .model import StructuralModel

__all__ = ["VTK_QUADRATIC_NODES", "solid_cells", "boundary_facets", "tributary_measure", "contact_boundaries",
           "polyline_order"]


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


def solid_cells(fe: Any) -> tuple[str, np.ndarray]:
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


def boundary_facets(fe: Any) -> dict:
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
    mesh_map = getattr(model, "mesh_map", None)
    owner = None if mesh_map is None else mesh_map.owner
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


def contact_boundaries(groups: Mapping, nodes: np.ndarray, comps: np.ndarray) -> list[str]:
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


def polyline_order(edges: np.ndarray) -> list[np.ndarray]:
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

