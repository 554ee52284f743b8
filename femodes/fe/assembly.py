"""Models layer: shared FE model building (supports, point masses, springs, DOF naming).

``bar.py`` and ``beam.py`` hold only their weak forms; this module turns assembled full
matrices into a :class:`~femodes.model.StructuralModel` on the free DOFs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import scipy.sparse as sp
import skfem

from ..model import DofMap, StructuralModel

__all__ = ["FEInfo", "element_property", "build_fe_model", "checked_basis"]


@dataclass(frozen=True, eq=False)
class FEInfo:
    """What outputs need to map model DOFs back to the mesh.

    Attributes
    ----------
    kind : str
        ``"bar"`` (axial displacement along the axis) or ``"beam"`` (transverse displacement).
    mesh : skfem.MeshLine
    basis : skfem.Basis
    free : ndarray
        Full FE DOF index of each model DOF.
    n_full : int
        Number of FE DOFs before eliminating supports.
    nodal : ndarray, shape (n_components, n_nodes)
        Full FE DOF index of each nodal component (``basis.nodal_dofs``).
    components : tuple of str
    """

    kind: str
    mesh: Any
    basis: Any
    free: np.ndarray
    n_full: int
    nodal: np.ndarray
    components: tuple

    @property
    def coordinates(self) -> np.ndarray:
        """Node coordinates along the axis."""
        return np.asarray(self.mesh.p[0])


def check_mesh(mesh: Any, owner: str) -> None:
    """A line mesh (FE constructors of bars and beams), else TypeError naming ``owner``."""
    if not isinstance(mesh, skfem.MeshLine):
        raise TypeError(
            f"{owner}: mesh must be a skfem.MeshLine (use femodes.line_mesh or femodes.load_mesh), got {type(mesh).__name__}"
        )


def checked_basis(mesh: Any, element: Any, owner: str) -> Any:
    """``skfem.Basis(mesh, element)``, with a degenerate mesh reported as a ValueError naming it."""
    with np.errstate(all="ignore"):
        try:
            return skfem.Basis(mesh, element)
        except np.linalg.LinAlgError as exc:
            h = np.diff(np.asarray(mesh.p[0]))
            raise ValueError(
                f"{owner}: mesh element lengths {h.min():.3g}..{h.max():.3g} are too small for the "
                f"{type(element).__name__} basis (its element map is numerically singular); rescale the length unit"
            ) from exc


def _check_assembled(owner: str, mesh: Any, M: sp.spmatrix, K: sp.spmatrix) -> None:
    """Overflow/underflow of the assembled matrices, reported against the inputs that cause it."""
    h = np.diff(np.asarray(mesh.p[0]))
    scales = (
        f"element lengths {h.min():.3g}..{h.max():.3g}; rescale the units of the mesh length, the material "
        "(E, rho) and the section (area, inertia)"
    )
    for name, A in (("mass", M), ("stiffness", K)):
        if not np.all(np.isfinite(A.data)):
            raise ValueError(f"{owner}: the {name} matrix has non-finite entries (overflow) for the given material, section and {scales}")
    if not M.nnz or not np.any(M.diagonal() > 0):
        raise ValueError(f"{owner}: the mass matrix is zero (underflow of rho * area) for the given material, section and {scales}")


def element_property(mesh: Any, value: Any, cls: type, owner: str, arg: str) -> np.ndarray:
    """Per-element objects from one object or a mapping {subdomain name: object}."""
    n_el = mesh.t.shape[1]
    if isinstance(value, cls):
        return np.array([value] * n_el, dtype=object)
    if isinstance(value, Mapping):
        subs = mesh.subdomains or {}
        out = np.full(n_el, None, dtype=object)
        for name, v in value.items():
            if name not in subs:
                raise ValueError(f"{owner}: {arg} names subdomain {name!r}, but the mesh has subdomains {sorted(subs)}")
            if not isinstance(v, cls):
                raise TypeError(f"{owner}: {arg}[{name!r}] must be a {cls.__name__}, got {type(v).__name__}")
            out[np.asarray(subs[name])] = v
        missing = np.flatnonzero(out == None)  # noqa: E711 (object array comparison)
        if missing.size:
            raise ValueError(
                f"{owner}: {arg} does not cover {missing.size} element(s) (first: element {missing[0]}); "
                f"give a {cls.__name__} for every subdomain or a single {cls.__name__}"
            )
        return out
    raise TypeError(f"{owner}: {arg} must be a {cls.__name__} or a mapping {{subdomain: {cls.__name__}}}, got {type(value).__name__}")


def quad_field(basis: Any, per_element: np.ndarray) -> np.ndarray:
    """Element-wise constant coefficient as a (n_elements, n_quadrature_points) array."""
    return np.repeat(np.asarray(per_element, dtype=float)[:, None], basis.X.shape[1], axis=1)


def support_names(value: Any, owner: str, arg: str) -> list:
    """Boundary/point names of a support argument (``clamped="clamp"`` or a list of names)."""
    if value is None:
        return []
    if isinstance(value, str):
        return [value]
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        return list(value)
    raise TypeError(f"{owner}: {arg} must be a location name or a list of names, got {value!r}")


def _location_node(mesh: Any, name: str, owner: str, arg: str) -> int:
    b = mesh.boundaries or {}
    if name not in b:
        raise ValueError(f"{owner}: {arg} names location {name!r}, but the mesh has named points {sorted(b)}")
    facets = np.asarray(b[name])
    if facets.size != 1:
        raise ValueError(f"{owner}: location {name!r} has {facets.size} points; a support/contact location must be one point")
    # For MeshLine the facets are the vertices: facet index == vertex index.
    return int(mesh.facets[0, facets[0]])


def build_fe_model(
    *,
    owner: str,
    kind: str,
    mesh: Any,
    basis: Any,
    M: sp.spmatrix,
    K: sp.spmatrix,
    components: tuple,
    aliases: Mapping[str, str],
    constraints: Sequence[tuple[str, Sequence[str], str]],
    point_masses: Mapping | None,
    springs: Mapping | None,
) -> StructuralModel:
    """Apply supports, point masses and springs, then return the model on the free DOFs.

    ``constraints`` is a list of ``(argument name, location names, components fixed)``.
    """
    nodal = np.asarray(basis.nodal_dofs)  # (n_components, n_nodes)
    n_full = basis.N
    M = sp.csr_matrix(M)
    K = sp.csr_matrix(K)
    _check_assembled(owner, mesh, M, K)
    added = {"point_masses": ([], []), "springs": ([], [])}
    locations = {name: _location_node(mesh, name, owner, "mesh boundaries") for name in (mesh.boundaries or {})}

    def comp_index(comp: str, arg: str) -> int:
        c = aliases.get(comp, comp)
        if c not in components:
            raise ValueError(f"{owner}: {arg} uses unknown component {comp!r}; components are {list(components)}")
        return components.index(c)

    def resolve(at: Any, arg: str) -> tuple[int, int]:
        if isinstance(at, str):
            loc, c = at, 0
        elif isinstance(at, tuple) and len(at) == 2 and all(isinstance(a, str) for a in at):
            loc, c = at[0], comp_index(at[1], arg)
        else:
            raise TypeError(f"{owner}: {arg} keys must be location names or (name, component) pairs, got {at!r}")
        return _location_node(mesh, loc, owner, arg), c

    constrained: dict = {}
    for arg, names, comps in constraints:
        for name in names:
            node = _location_node(mesh, name, owner, arg)
            for comp in comps:
                constrained[(node, comp_index(comp, arg))] = f"{arg}={name!r}"

    for arg, table in (("point_masses", point_masses), ("springs", springs)):
        if table is None:
            continue
        if not isinstance(table, Mapping):
            raise TypeError(f"{owner}: {arg} must be a mapping {{location: value}}, got {type(table).__name__}")
        for at, value in table.items():
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"{owner}: {arg}[{at!r}] must be a finite non-negative number, got {value!r}")
            node, c = resolve(at, arg)
            added[arg][0].append(int(nodal[c, node]))
            added[arg][1].append(float(value))
    for arg in added:
        idx, vals = added[arg]
        if idx:
            D = sp.csr_matrix((vals, (idx, idx)), shape=(n_full, n_full))
            if arg == "point_masses":
                M = M + D
            else:
                K = K + D

    fixed_full = np.array(sorted(nodal[c, node] for node, c in constrained), dtype=int)
    free = np.setdiff1d(np.arange(n_full), fixed_full)
    if free.size == 0:
        given = ", ".join(f"{arg}={list(names)!r}" for arg, names, _ in constraints if names)
        raise ValueError(f"{owner}: the supports ({given}) fix every DOF of the mesh; leave at least one DOF free")
    free_of_full = np.full(n_full, -1, dtype=int)
    free_of_full[free] = np.arange(free.size)
    node_dof = free_of_full[nodal.T]  # (n_nodes, n_components)

    M = M.tocsr()[free][:, free]
    K = K.tocsr()[free][:, free]
    # Symmetrize to round-off: assembly sums in different orders.
    M = (0.5 * (M + M.T)).tocsr()
    K = (0.5 * (K + K.T)).tocsr()

    x = np.asarray(mesh.p[0])
    labels = [""] * free.size
    for node in range(nodal.shape[1]):
        for c, comp in enumerate(components):
            i = node_dof[node, c]
            if i >= 0:
                labels[i] = f"{comp}@x={x[node]:.6g}"
    for i in range(free.size):
        if not labels[i]:
            labels[i] = f"interior dof {free[i]}"
    named = {}
    # user names win over the automatic "left"/"right" ends in labels
    for name, node in sorted(locations.items(), key=lambda kv: kv[0] not in ("left", "right")):
        named[node] = name
    for node, name in named.items():
        for c, comp in enumerate(components):
            i = node_dof[node, c]
            if i >= 0:
                labels[i] = f"{name}.{comp}"

    dofmap = DofMap(
        n_dofs=free.size,
        components=tuple(components),
        node_dof=node_dof,
        locations=locations,
        constrained_by=constrained,
        aliases=dict(aliases),
        labels=tuple(labels),
    )
    fe = FEInfo(kind=kind, mesh=mesh, basis=basis, free=free, n_full=n_full, nodal=nodal, components=tuple(components))
    return StructuralModel(M=M, K=K, dofmap=dofmap, fe=fe)
