"""Models layer: linear elasticity of 2-D (plane stress/strain) and 3-D solids, scikit-fem assembly.

``rho u_tt - div sigma(u) = f`` with ``sigma = lambda tr(eps) I + 2 mu eps``, ``eps = sym grad u``,
discretised with vector Lagrange elements (P1/P2 triangles and tetrahedra, Q1/Q2 quadrilaterals
and hexahedra) and a consistent mass matrix.
"""

from __future__ import annotations

import math
from typing import Any
from collections.abc import Mapping

import numpy as np
import skfem
from skfem.helpers import ddot, div, dot, grad, transpose

from ..model import StructuralModel
from ..solvers.checks import entry_point
from .assembly import assemble_blocks, build_fe_model, element_property, support_names
from .material import Material
from .checks import check_assembly, check_element_measures
from .mesh import named_points
from .quadrature import facet_order

__all__ = ["solid", "POINT_RTOL"]

#: Relative tolerance (times the mesh extent) for a point of ``solid(points=...)`` to be a node.
POINT_RTOL = 1e-6

_COMPONENTS = {2: ("u_x", "u_y"), 3: ("u_x", "u_y", "u_z")}


@skfem.BilinearForm
def _stiffness(u, v, w):
    # t (lambda tr eps(u) tr eps(v) + 2 mu eps(u):eps(v)), with tr eps = div and, eps(v) being
    # symmetric, 2 eps(u):eps(v) = grad u : (grad v + grad v^T): no eps(u) tensors to build for
    # each of the (n_local)^2 pairs scikit-fem evaluates (1.4x faster than sym_grad)
    return w["t"] * (w["lam"] * div(u) * div(v) + w["mu"] * ddot(grad(u), grad(v) + transpose(grad(v))))


@skfem.BilinearForm
def _mass(u, v, w):
    # t rho u . v
    return w["t"] * w["rho"] * dot(u, v)


@skfem.LinearForm
def _boundary_measure(v, w):
    # int N_k ds: consistent weights of a boundary (scalar shape functions)
    return v


def _elements(mesh: Any, order: int) -> tuple[int, Any]:
    """Spatial dimension and scalar Lagrange element of ``order`` for the cell type of ``mesh``."""
    table = (
        (skfem.MeshTri1, 2, (skfem.ElementTriP1, skfem.ElementTriP2)),
        (skfem.MeshQuad1, 2, (skfem.ElementQuad1, skfem.ElementQuad2)),
        (skfem.MeshTet1, 3, (skfem.ElementTetP1, skfem.ElementTetP2)),
        (skfem.MeshHex1, 3, (skfem.ElementHex1, skfem.ElementHex2)),
    )
    for cls, dim, elems in table:
        if isinstance(mesh, cls):
            return dim, elems[order - 1]()
    raise TypeError(
        f"solid: mesh must be a scikit-fem triangle, quadrilateral, tetrahedron or hexahedron mesh "
        f"(femodes.rectangle_mesh, femodes.box_mesh or femodes.load_mesh), got {type(mesh).__name__}"
    )


def _lagrange_nodes(basis: Any, dim: int) -> np.ndarray:
    """``(dim, n_nodes)`` full DOF of each component at every Lagrange node, vertices first."""
    d = basis.dofs  # the global numbering (a basis, or the recipe of one: femodes.fe.assembly.BasisRecipe)
    blocks = [np.asarray(d.nodal_dofs)]
    for dofs in (d.edge_dofs if dim == 3 else None, d.facet_dofs, d.interior_dofs):
        if dofs is None:
            continue
        dofs = np.asarray(dofs)
        if dofs.size:
            # a Lagrange vector element has one DOF per component at each node of an entity;
            # entities with several nodes come as consecutive groups of dim rows
            blocks.extend(dofs[k:k + dim] for k in range(0, dofs.shape[0], dim))
    nodal = np.hstack(blocks)
    if nodal.shape[0] != dim or np.unique(nodal).size != d.N or nodal.size != d.N:
        raise RuntimeError(f"solid: unexpected DOF layout of {type(basis.elem).__name__}")  # pragma: no cover
    return nodal


def _groups(mesh: Any, basis: Any, scalar: Any, nodal: np.ndarray, node_of_full: np.ndarray) -> tuple[dict, dict]:
    """Nodes of every named boundary and their consistent weights ``int N_k ds / int ds``.

    ``N_k`` are the shape functions of the scalar element: scikit-fem numbers the DOFs of
    ``ElementVector(scalar)`` as ``dim * (scalar DOF) + component``, so node ``k``'s scalar DOF is
    ``nodal[0, k] // dim`` (the vector element's facet basis cost dim times as much).
    """
    groups, weights = {}, {}
    dim = nodal.shape[0]
    for name, facets in (mesh.boundaries or {}).items():
        facets = np.asarray(facets, dtype=np.int64)
        if facets.size == 0:
            continue
        nodes = np.unique(node_of_full[np.asarray(basis.dofs.get_facet_dofs(facets).all())])
        # int N_k ds has the degree of N_k: exact on flat facets with that rule (femodes.fe.quadrature)
        fb = skfem.FacetBasis(mesh, scalar, facets=facets, intorder=facet_order(mesh, scalar))
        b = _boundary_measure.assemble(fb)
        w = b[nodal[0, nodes] // dim]
        total = w.sum()
        groups[name] = nodes
        weights[name] = w / total if total > 0 else np.full(nodes.size, 1.0 / nodes.size)
    return groups, weights


def _points(mesh: Any, coords: np.ndarray, points: Mapping | None, groups: Mapping) -> tuple[dict, dict]:
    """Named points: gmsh physical points of the mesh and ``points={name: coordinates}``; and the
    point sets, gmsh physical points of several vertices (``{name: nodes}``: supports take them)."""
    named = named_points(mesh)
    located = {name: int(v[0]) for name, v in named.items() if len(v) == 1}
    sets = {name: np.unique(np.asarray(v, dtype=int)) for name, v in named.items() if len(v) > 1 and name not in groups}
    if points is None:
        return located, sets
    if not isinstance(points, Mapping):
        raise TypeError(f"solid: points must be a mapping {{name: coordinates}}, got {type(points).__name__}")
    dim = coords.shape[0]
    tol = POINT_RTOL * float(np.ptp(coords, axis=1).max())
    for name, xy in points.items():
        if not isinstance(name, str) or not name:
            raise TypeError(f"solid: names in points must be non-empty strings, got {name!r}")
        if name in groups or name in sets:
            what = "a boundary" if name in groups else "a set of points"
            raise ValueError(f"solid: points[{name!r}]: the name is {what} of the mesh; choose another name")
        try:
            x = np.asarray(xy, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            x = np.zeros(0)
        if x.size != dim or not np.all(np.isfinite(x)):
            raise ValueError(f"solid: points[{name!r}] must be {dim} finite coordinates, got {xy!r}")
        d = np.linalg.norm(coords - x[:, None], axis=0)
        k = int(np.argmin(d))
        if d[k] > tol:
            raise ValueError(
                f"solid: points[{name!r}] = {xy!r} is not a node of the mesh: the nearest node is at "
                f"{tuple(float(v) for v in coords[:, k])} (distance {d[k]:.3g} > {tol:.3g})"
            )
        located[name] = k
    return located, sets


def _plane_options(dim: int, plane: Any, thickness: Any) -> tuple[str | None, float]:
    if dim == 3:
        if plane is not None or thickness is not None:
            raise ValueError(
                f"solid: plane={plane!r} and thickness={thickness!r} apply to 2-D meshes only; this mesh is 3-D "
                "(leave them out)"
            )
        return None, 1.0
    plane = "stress" if plane is None else plane
    if plane not in ("stress", "strain"):
        raise ValueError(f"solid: plane must be 'stress' or 'strain' (2-D meshes), got {plane!r}")
    t = 1.0 if thickness is None else thickness
    if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not math.isfinite(t) or t <= 0:
        raise ValueError(f"solid: thickness must be a finite positive number, got {thickness!r}")
    return plane, float(t)


def _supports(clamped: Any, supports: Any, components: tuple) -> list:
    """``[(argument, names, components)]`` for :func:`build_fe_model`."""
    out = [("clamped", support_names(clamped, "clamped"), components)]
    if supports is None:
        return out
    if not isinstance(supports, Mapping):
        raise TypeError(
            f"solid: supports must be a mapping {{location: components}}, e.g. {{'bottom': ('u_y',)}}, got {supports!r}"
        )
    for name, comps in supports.items():
        if not isinstance(name, str):
            raise TypeError(f"solid: supports keys must be location names, got {name!r}")
        comps = (comps,) if isinstance(comps, str) else comps
        if not isinstance(comps, (tuple, list)) or not comps or not all(isinstance(c, str) for c in comps):
            raise TypeError(
                f"solid: supports[{name!r}] must be a component name or a tuple of them (of {list(components)}), "
                f"got {comps!r}"
            )
        out.append(("supports", [name], tuple(comps)))
    return out




@entry_point("solid")
def solid(
    mesh: Any,
    material: Material | Mapping[str, Material],
    *,
    clamped: Any = None,
    supports: Mapping[str, Any] | None = None,
    plane: str | None = None,
    thickness: float | None = None,
    order: int = 1,
    points: Mapping[str, Any] | None = None,
) -> StructuralModel:
    """Linear elastic solid: ``int t rho u.v`` (mass) and ``int t sigma(u):eps(v)`` (stiffness).

    ``sigma = lambda tr(eps) I + 2 mu eps``, ``eps = (grad u + grad u^T) / 2``, with
    ``mu = E / (2 (1 + nu))`` and ``lambda = E nu / ((1 + nu)(1 - 2 nu))`` in 3-D and plane
    strain, ``lambda = E nu / (1 - nu^2)`` in plane stress; ``t`` is the thickness of a 2-D
    solid (1 in 3-D). Consistent mass; each form takes the lowest Gauss rule exact on affine cells
    (:mod:`femodes.fe.quadrature`; points per element: :doc:`/guide/solids`).

    Parameters
    ----------
    mesh : skfem.MeshTri, MeshQuad, MeshTet or MeshHex
        From :func:`femodes.rectangle_mesh`, :func:`femodes.box_mesh` or :func:`femodes.load_mesh`; its
        named boundaries are the locations of supports, contacts and forces.
    material : Material or mapping {subdomain: Material}
        ``E``, ``rho`` and ``nu`` (one material, or one per named subdomain covering the mesh).
    clamped : str or list of str, optional
        Boundaries or named points where every displacement component is fixed (all their
        nodes, P2 mid-side nodes included).
    supports : mapping {location: component or tuple of components}, optional
        Per-component supports, e.g. ``{"bottom": ("u_y",)}`` (a roller on the bottom edge).
    plane : {"stress", "strain"}, optional
        2-D only (default ``"stress"``); a 3-D mesh with ``plane`` or ``thickness`` is an error.
    thickness : float, optional
        2-D only (default 1): multiplies M and K.
    order : {1, 2}, default 1
        Lagrange order: P1/P2 on simplices, Q1/Q2 on quadrilaterals and hexahedra. P1 simplices lock
        in bending; prefer quadrilaterals or ``order=2`` there.
    points : mapping {name: coordinates}, optional
        Extra named points: each must be a node (a vertex, or a P2 node) within
        ``POINT_RTOL`` times the mesh extent. gmsh physical points of :func:`femodes.load_mesh`
        are named points too.

    Returns
    -------
    StructuralModel
        DOF components ``"u_x", "u_y"(, "u_z")`` at every node; ``model.fe.kind == "solid"``.
        ``at=("tip_top", "u_y")`` selects one DOF of a named point; ``at="right"`` names a
        boundary: contact laws expand to one contact per node and forces are distributed over it
        (see :meth:`femodes.StructuralModel.with_contact` and ``with_forcing``).
    """
    if isinstance(order, (bool, np.bool_)) or not isinstance(order, (int, np.integer)) or order not in (1, 2):
        raise ValueError(f"solid: order must be 1 or 2, got {order!r}")
    dim, scalar = _elements(mesh, int(order))
    plane, t = _plane_options(dim, plane, thickness)
    components = _COMPONENTS[dim]
    check_assembly(mesh, skfem.ElementVector(scalar), "use a coarser mesh or order=1")  # refused before anything large is built
    check_element_measures(mesh)  # a flat element is named, not left to look like an overflow
    mats = element_property(mesh, material, Material, "material")
    lam, mu = np.array([m.lame for m in mats]).T
    if plane == "stress":  # sigma_zz = 0 eliminates eps_zz: lambda* = 2 lambda mu / (lambda + 2 mu) = E nu / (1 - nu^2)
        lam = 2.0 * lam * mu / (lam + 2.0 * mu)
    # quadrature exact for K and M on affine elements (femodes.fe.quadrature: Q2 hexahedra 27 points, not 343);
    # K first, its basis dropped before the mass basis is built (peak memory: one basis); large meshes in
    # blocks of elements (assemble_blocks: the model then keeps a recipe of its basis, not the basis)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):  # overflow is reported by build_fe_model
        K, M, basis = assemble_blocks(mesh, skfem.ElementVector(scalar),
                                      stiffness=(_stiffness, {"lam": lam, "mu": mu, "t": t}),
                                      mass=(_mass, {"rho": np.array([m.rho for m in mats], dtype=float), "t": t}))
    nodal = _lagrange_nodes(basis, dim)
    node_of_full = np.empty(basis.dofs.N, dtype=int)
    node_of_full[nodal] = np.arange(nodal.shape[1])[None, :]
    coords = np.asarray(basis.doflocs)[:, nodal[0]]
    groups, weights = _groups(mesh, basis, scalar, nodal, node_of_full)
    locations, point_sets = _points(mesh, coords, points, groups)
    return build_fe_model(
        kind="solid",
        mesh=mesh,
        basis=basis,
        M=M,
        K=K,
        components=components,
        aliases={},
        constraints=_supports(clamped, supports, components),
        point_masses=None,
        springs=None,
        nodal=nodal,
        locations=locations,
        groups=groups,
        group_weights=weights,
        point_sets=point_sets,
        node_coordinates=coords,
        displacement=components,
        fe_options={"thickness": t, "plane": plane},
    )
