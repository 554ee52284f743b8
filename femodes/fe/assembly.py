"""Models layer: shared FE model building (supports, point masses, springs, DOF naming).

``bar.py``, ``beam.py`` and ``solid.py`` hold only their weak forms; this module turns assembled
full matrices into a :class:`~femodes.model.StructuralModel` on the free DOFs.

*Nodes.* A node is a column of ``nodal`` (the full FE DOF of each component there). For bars and
beams these are the mesh vertices (``basis.nodal_dofs``; P2 interior DOFs are unnamed); for
solids every Lagrange node: the vertices first, then the edge, facet and interior nodes of P2/Q2
elements, so that a support or a contact on a boundary reaches every DOF on it.
*Locations.* A named point is one node (``DofMap.locations``); a named boundary of a solid is a
group of nodes (``DofMap.groups``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike
import scipy.sparse as sp
import skfem

from ..model import DofMap, StructuralModel
from ..solvers.checks import InputTypeError, InputValueError, entry_point
from .quadrature import orders

__all__ = ["FEInfo", "BasisRecipe", "element_property", "build_fe_model", "checked_basis", "stiffness_basis", "mass_basis",
           "assemble_blocks"]


@dataclass(frozen=True)
class BasisRecipe:
    """How to build a model's scikit-fem basis when it is asked for (:attr:`FEInfo.basis`).

    A mesh assembled in blocks (:func:`assemble_blocks`) never holds the shape functions of all
    its elements at once: at 1e6 P2 DOFs they take 8 GB. The model keeps what its outputs need
    without them (the global DOF numbering ``dofs`` and the DOF locations ``doflocs``) and this
    recipe (the element and the quadrature of the mass form) for the full basis.
    """

    elem: Any
    intorder: int | None
    dofs: Any
    doflocs: np.ndarray

    @property
    def N(self) -> int:
        return int(self.dofs.N)

    @property
    def nodal_dofs(self) -> np.ndarray:
        return self.dofs.nodal_dofs

    @entry_point("FEInfo.basis")
    def build(self, mesh: Any) -> Any:
        return checked_basis(mesh, self.elem, intorder=self.intorder, dofs=self.dofs)


@dataclass(frozen=True, eq=False)
class FEInfo:
    """What outputs need to map model DOFs back to the mesh.

    Attributes
    ----------
    kind : str
        ``"bar"`` (axial displacement along the axis), ``"beam"`` (transverse displacement) or
        ``"solid"`` (displacement vector ``u_x, u_y(, u_z)`` of a 2-D/3-D mesh).
    mesh : skfem.Mesh
    basis_source : skfem.Basis or BasisRecipe
        The basis of the mass form, or (meshes assembled in blocks) how to build it;
        :attr:`basis` builds it on first use.
    free : ndarray
        Full FE DOF index of each model DOF.
    n_full : int
        Number of FE DOFs before eliminating supports.
    nodal : ndarray, shape (n_components, n_nodes)
        Full FE DOF index of each nodal component (``basis.nodal_dofs`` for bars and beams;
        every Lagrange node of a solid, vertices first, see the module docstring).
    components : tuple of str
    node_coordinates : ndarray, shape (dim, n_nodes), optional
        Coordinates of the nodes (default: the mesh vertices).
    thickness : float
        Out-of-plane thickness of a 2-D solid (1 otherwise).
    plane : str or None
        ``"stress"`` or ``"strain"`` for 2-D solids, None otherwise.
    """

    kind: str
    mesh: Any
    basis_source: Any
    free: np.ndarray
    n_full: int
    nodal: np.ndarray
    components: tuple
    node_coordinates: Any = None
    thickness: float = 1.0
    plane: Any = None

    def __post_init__(self):
        if self.node_coordinates is None:
            object.__setattr__(self, "node_coordinates", np.asarray(self.mesh.p))

    @property
    def basis(self) -> Any:
        """The scikit-fem basis of the mass form (with its quadrature), built on first use for a
        mesh assembled in blocks (all elements' shape functions: large on large meshes)."""
        if not isinstance(self.basis_source, BasisRecipe):
            return self.basis_source
        built = self.__dict__.get("_basis")
        if built is None:
            built = self.basis_source.build(self.mesh)
            object.__setattr__(self, "_basis", built)
        return built

    @property
    def element(self) -> Any:
        """The scikit-fem element (``basis.elem``), without building the basis."""
        return self.basis_source.elem

    @property
    def element_dofs(self) -> np.ndarray:
        """``(n_local, n_elements)`` full DOF of each local function (``basis.element_dofs``)."""
        src = self.basis_source
        return src.dofs.element_dofs if isinstance(src, BasisRecipe) else src.element_dofs

    @property
    def doflocs(self) -> np.ndarray:
        """``(dim, n_full)`` location of every full DOF (``basis.doflocs``)."""
        return self.basis_source.doflocs

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state.pop("_basis", None)  # rebuilt from the recipe where needed (it may be GBs)
        return state

    @property
    def coordinates(self) -> np.ndarray:
        """Node coordinates along the axis (1-D models); the first coordinate of the nodes."""
        return np.asarray(self.node_coordinates[0])

    @property
    def dim(self) -> int:
        """Spatial dimension of the mesh."""
        return int(np.asarray(self.node_coordinates).shape[0])


def check_mesh(mesh: Any) -> None:
    """A line mesh (FE constructors of bars and beams), else TypeError (named by the public constructor called)."""
    if not isinstance(mesh, skfem.MeshLine):
        raise InputTypeError(
            f"mesh must be a skfem.MeshLine (use femodes.line_mesh or femodes.load_mesh), got {type(mesh).__name__}"
        )


def checked_basis(mesh: Any, element: Any, **options: Any) -> Any:
    """``skfem.Basis(mesh, element, **options)``, with a degenerate mesh reported as a ValueError naming it."""
    with np.errstate(all="ignore"):
        try:
            return skfem.Basis(mesh, element, **options)
        except np.linalg.LinAlgError as exc:
            h = np.diff(np.asarray(mesh.p[0]))
            raise InputValueError(
                f"mesh element lengths {h.min():.3g}..{h.max():.3g} are too small for the "
                f"{type(element).__name__} basis (its element map is numerically singular); rescale the length unit"
            ) from exc


def stiffness_basis(mesh: Any, element: Any) -> Any:
    """Basis of the stiffness form with the lowest quadrature exact on affine elements
    (:func:`femodes.fe.quadrature.orders`; scikit-fem's default rule on curved meshes).

    Assemble K with it first and drop it before :func:`mass_basis` builds the (larger) mass
    basis, so that the two sets of shape-function values are never held together: the peak
    memory of a build stays that of the mass basis alone.
    """
    o = orders(mesh, element)
    if o is None or o.stiffness == o.mass:
        return checked_basis(mesh, element, intorder=None if o is None else o.mass)
    return checked_basis(mesh, element, intorder=o.stiffness, disable_doflocs=True)


def mass_basis(stiffness: Any) -> Any:
    """Basis of the mass form: the stiffness basis itself when both forms take the same rule
    (Q1/Q2 quadrilaterals and hexahedra, curved meshes), else one with the mass rule that shares
    its DOF numbering and geometry map."""
    o = orders(stiffness.mesh, stiffness.elem)
    if o is None or o.stiffness == o.mass:
        return stiffness
    return checked_basis(stiffness.mesh, stiffness.elem, intorder=o.mass, mapping=stiffness.mapping,
                         dofs=stiffness.dofs)


def assemble_blocks(mesh: Any, element: Any, stiffness: tuple, mass: tuple) -> tuple:
    """``K``, ``M`` and the model's basis (or its :class:`BasisRecipe`): each form assembled by
    scikit-fem with the quadrature of :func:`stiffness_basis` / :func:`mass_basis`.

    ``stiffness`` and ``mass`` are ``(form, coefficients)``: a ``skfem.BilinearForm`` and its
    keyword arguments, each a number or one value per element (expanded to the quadrature points
    by :func:`quad_field`).

    A mesh whose scikit-fem work (:func:`femodes.fe.checks.assembly_block`: the shape functions
    at the quadrature points and the triplets of the element matrices) exceeds
    :data:`femodes.fe.checks.ASSEMBLY_BLOCK_BYTES` is assembled in blocks of consecutive
    elements, each one scikit-fem assembly of the same forms on ``Basis(..., elements=block)``,
    and the blocks' matrices are summed. The peak memory is then that of one block plus the
    assembled matrices, not the 8 GB of shape functions and 5 GB of triplets of a whole 1e6-DOF P2
    mesh (and the time the same: the work per element does not change). Only the order in which
    the contributions of elements of different blocks to one entry are summed differs from one
    assembly of the whole mesh (round-off). One block: exactly ``form.assemble(Basis(mesh, ...))``.
    """
    from .checks import assembly_block

    n_el = int(mesh.nelements)
    block = assembly_block(mesh, element)
    (kform, kcoef), (mform, mcoef) = stiffness, mass
    if block >= n_el:
        kbasis = stiffness_basis(mesh, element)
        K = kform.assemble(kbasis, **_coefficients(kbasis, kcoef, None))
        basis = mass_basis(kbasis)
        del kbasis  # one basis held at a time
        M = mform.assemble(basis, **_coefficients(basis, mcoef, None))
        return K, M, basis
    o = orders(mesh, element)
    ko, mo = (None, None) if o is None else (o.stiffness, o.mass)
    mapping = mesh.mapping()
    # the global numbering and DOF locations (of every element) from the first block's basis
    first = checked_basis(mesh, element, intorder=mo, mapping=mapping, elements=np.arange(block))
    dofs, doflocs = first.dofs, np.asarray(first.doflocs)
    del first
    # K over all blocks, then M: one matrix's pieces held at a time (P2 tetrahedra: the two forms
    # take different rules, so each block needs two bases anyway)
    K = _assemble_in_blocks(mesh, element, kform, kcoef, ko, mapping, dofs, block)
    M = _assemble_in_blocks(mesh, element, mform, mcoef, mo, mapping, dofs, block)
    return K, M, BasisRecipe(elem=element, intorder=mo, dofs=dofs, doflocs=doflocs)


#: Triplets (COO entries) of blocks gathered before they are summed into the running CSR matrix of
#: :func:`assemble_blocks`: a few such sums over a 1e6-DOF mesh, and never all its triplets at once.
SUM_TRIPLETS = 2**24


def _assemble_in_blocks(mesh, element, form, coefficients, intorder, mapping, dofs, block) -> sp.csr_matrix:
    """``form`` assembled block by block (:func:`assemble_blocks`), summed as CSR."""
    n_el, n = int(mesh.nelements), int(dofs.N)
    total, pending, count = None, [], 0
    for e0 in range(0, n_el, block):
        idx = np.arange(e0, min(n_el, e0 + block))
        b = checked_basis(mesh, element, intorder=intorder, mapping=mapping, elements=idx, dofs=dofs,
                          disable_doflocs=True)
        pending.append(form.assemble(b, **_coefficients(b, coefficients, idx)).tocoo())
        count += pending[-1].nnz
        del b
        if count >= SUM_TRIPLETS or e0 + block >= n_el:
            part = _sum_blocks(pending, n)
            total = part if total is None else total + part
            count = 0
    return total


def _coefficients(basis: Any, coefficients: Mapping, idx: np.ndarray | None) -> dict:
    """Keyword arguments of a form on ``basis``: per-element values (of the block ``idx``) at its
    quadrature points, numbers as they are."""
    out = {}
    for name, v in coefficients.items():
        if np.ndim(v) == 0:
            out[name] = v
        else:
            v = np.asarray(v, dtype=float)
            out[name] = quad_field(basis, v if idx is None else v[idx])
    return out


def _sum_blocks(blocks: list, n: int) -> sp.csr_matrix:
    """The sum of the blocks' ``n x n`` COO matrices, as CSR (one conversion; duplicates summed)."""
    rows = np.concatenate([b.row for b in blocks])
    cols = np.concatenate([b.col for b in blocks])
    data = np.concatenate([b.data for b in blocks])
    blocks.clear()
    return sp.csr_matrix((data, (rows, cols)), shape=(n, n))


def _check_assembled(mesh: Any, M: sp.spmatrix, K: sp.spmatrix) -> None:
    """Overflow/underflow of the assembled matrices, reported against the inputs that cause it."""
    if np.asarray(mesh.p).shape[0] == 1:
        h = np.diff(np.asarray(mesh.p[0]))
        scales = (
            f"element lengths {h.min():.3g}..{h.max():.3g}; rescale the units of the mesh length, the material "
            "(E, rho) and the section (area, inertia)"
        )
    else:
        size = np.ptp(np.asarray(mesh.p), axis=1)
        scales = (f"mesh extent {', '.join(f'{v:.3g}' for v in size)}; rescale the units of the mesh length, the "
                  "material (E, rho) and the thickness")
    for name, A in (("mass", M), ("stiffness", K)):
        if not np.all(np.isfinite(A.data)):
            raise InputValueError(f"the {name} matrix has non-finite entries (overflow) for the given material, section and {scales}")
    if not M.nnz or not np.any(M.diagonal() > 0):
        raise InputValueError(f"the mass matrix is zero (underflow of rho * area) for the given material, section and {scales}")


def element_property(mesh: Any, value: Any, cls: type, arg: str) -> np.ndarray:
    """Per-element objects from one object or a mapping {subdomain name: object}."""
    n_el = mesh.t.shape[1]
    if isinstance(value, cls):
        return np.array([value] * n_el, dtype=object)
    if isinstance(value, Mapping):
        subs = mesh.subdomains or {}
        out = np.full(n_el, None, dtype=object)
        assigned = np.zeros(n_el, dtype=bool)
        for name, v in value.items():
            if name not in subs:
                raise InputValueError(f"{arg} names subdomain {name!r}, but the mesh has subdomains {sorted(subs)}")
            if not isinstance(v, cls):
                raise InputTypeError(f"{arg}[{name!r}] must be a {cls.__name__}, got {type(v).__name__}")
            elements = np.asarray(subs[name], dtype=int)
            taken = elements[assigned[elements]]
            claimed = [(i, w) for i, w in zip(taken, out[taken]) if w != v]
            if claimed:  # the mapping's order chose the value of these elements without a word
                other = next(k for k in value if k != name and claimed[0][0] in np.asarray(subs[k]))
                raise InputValueError(
                    f"{arg}: subdomains {other!r} and {name!r} overlap with different values ({len(claimed)} "
                    f"element(s), first: element {claimed[0][0]}); give the shared elements one value (make the "
                    "subdomains disjoint, or give both the same)")
            out[elements] = v
            assigned[elements] = True
        missing = np.flatnonzero(out == None)  # noqa: E711 (object array comparison)
        if missing.size:
            raise InputValueError(
                f"{arg} does not cover {missing.size} element(s) (first: element {missing[0]}); "
                f"give a {cls.__name__} for every subdomain or a single {cls.__name__}"
            )
        return out
    raise InputTypeError(f"{arg} must be a {cls.__name__} or a mapping {{subdomain: {cls.__name__}}}, got {type(value).__name__}")


def quad_field(basis: Any, per_element: ArrayLike) -> np.ndarray:
    """Element-wise constant coefficient as a (n_elements, n_quadrature_points) array."""
    return np.repeat(np.asarray(per_element, dtype=float)[:, None], basis.X.shape[1], axis=1)


def support_names(value: Any, arg: str) -> list:
    """Boundary/point names of a support argument (``clamped="clamp"`` or a list of names)."""
    if value is None:
        return []
    if isinstance(value, str):
        return [value]
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        return list(value)
    raise InputTypeError(f"{arg} must be a location name or a list of names, got {value!r}")


def _location_node(mesh: Any, name: str, arg: str) -> int:
    b = mesh.boundaries or {}
    if name not in b:
        raise InputValueError(f"{arg} names location {name!r}, but the mesh has named points {sorted(b)}")
    facets = np.asarray(b[name])
    if facets.size != 1:
        raise InputValueError(f"location {name!r} has {facets.size} points; a support/contact location must be one point")
    # For MeshLine the facets are the vertices: facet index == vertex index.
    return int(mesh.facets[0, facets[0]])


def build_fe_model(
    *,
    kind: str,
    mesh: Any,
    basis: Any,
    M: sp.spmatrix,
    K: sp.spmatrix,
    components: tuple,
    aliases: Mapping[str, str],
    constraints: Sequence[tuple[str, Sequence[str], Sequence[str]]],
    point_masses: Mapping | None,
    springs: Mapping | None,
    nodal: np.ndarray | None = None,
    locations: Mapping[str, int] | None = None,
    groups: Mapping[str, np.ndarray] | None = None,
    group_weights: Mapping[str, np.ndarray] | None = None,
    point_sets: Mapping[str, np.ndarray] | None = None,
    node_coordinates: np.ndarray | None = None,
    displacement: tuple = (),
    fe_options: Mapping | None = None,
) -> StructuralModel:
    """Apply supports, point masses and springs, then return the model on the free DOFs.

    ``constraints`` is a list of ``(argument name, location names, components fixed)``. The
    optional arguments describe meshes whose locations are not single vertices (solids):
    ``nodal`` (default ``basis.nodal_dofs``), ``locations`` (named points -> node; default: every
    mesh boundary of a line mesh), ``groups`` (named boundaries -> nodes), ``group_weights``
    (consistent weights of the nodes of each group, summing to 1), ``point_sets`` (named sets of
    several points -> nodes: supports take them, laws and forces refuse them), ``node_coordinates``
    (``(dim, n_nodes)``), ``displacement`` (the components along x, y(, z)) and ``fe_options``
    (extra :class:`FEInfo` fields).
    """
    nodal = np.asarray(basis.nodal_dofs if nodal is None else nodal)  # (n_components, n_nodes)
    n_full = basis.N
    M = sp.csr_matrix(M)
    K = sp.csr_matrix(K)
    _check_assembled(mesh, M, K)
    if locations is None:
        locations = {name: _location_node(mesh, name, "mesh boundaries") for name in (mesh.boundaries or {})}
    groups = {} if groups is None else {k: np.asarray(v, dtype=int) for k, v in groups.items()}
    coords = np.asarray(mesh.p if node_coordinates is None else node_coordinates, dtype=float)
    point_sets = {k: np.asarray(v, dtype=int) for k, v in (point_sets or {}).items()}
    dofs = _NodalDofs(mesh=mesh, nodal=nodal, components=tuple(components), aliases=aliases,
                      locations=dict(locations), groups=groups, point_sets=point_sets)
    constrained = _constrained_dofs(dofs, constraints)
    added_mass = _lumped_values(dofs, "point_masses", point_masses)
    added_stiffness = _lumped_values(dofs, "springs", springs)
    _refuse_on_supports(dofs, constrained, {"point_masses": (point_masses, added_mass),
                                            "springs": (springs, added_stiffness)})
    M = _add_diagonal(M, added_mass, n_full)
    K = _add_diagonal(K, added_stiffness, n_full)
    free, node_dof = _free_dofs(nodal, n_full, constrained, constraints)
    dofmap = DofMap(
        n_dofs=free.size,
        components=tuple(components),
        node_dof=node_dof,
        locations=locations,
        constrained_by=constrained,
        aliases=dict(aliases),
        labels=tuple(_dof_labels(coords, components, free, node_dof, locations)),
        groups=groups,
        group_weights=dict(group_weights or {}),
        point_sets=point_sets,
        node_coordinates=coords,
        displacement=tuple(displacement),
    )
    fe = FEInfo(kind=kind, mesh=mesh, basis_source=basis, free=free, n_full=n_full, nodal=nodal, components=tuple(components),
                node_coordinates=coords, **dict(fe_options or {}))
    return StructuralModel(M=_on_free_dofs(M, free), K=_on_free_dofs(K, free), dofmap=dofmap, fe=fe)


@dataclass(frozen=True, eq=False)
class _NodalDofs:
    """Resolves locations and component names of one FE model to nodes and component indices."""

    mesh: Any
    nodal: np.ndarray
    components: tuple
    aliases: Mapping[str, str]
    locations: Mapping[str, int]
    groups: Mapping[str, np.ndarray]
    point_sets: Mapping[str, np.ndarray] = field(default_factory=dict)

    def component(self, comp: str, arg: str) -> int:
        """Index of component ``comp`` (or its alias), else ValueError naming ``arg``."""
        c = self.aliases.get(comp, comp)
        if c not in self.components:
            raise InputValueError(f"{arg} uses unknown component {comp!r}; components are {list(self.components)}")
        return self.components.index(c)

    def node(self, name: str, arg: str) -> int:
        """Node of the named point ``name``."""
        if name in self.locations:
            return int(self.locations[name])
        if name in self.groups:
            raise InputValueError(
                f"{arg} names boundary {name!r} with {len(self.groups[name])} nodes; this needs one "
                f"point: name it (gmsh physical point, or points={{...}} of femodes.solid)"
            )
        if name in self.point_sets:
            raise InputValueError(
                f"{arg} names {name!r}, a set of {len(self.point_sets[name])} points; this needs one point: name "
                f"it alone (a gmsh physical point of one vertex, or points={{...}} of femodes.solid)"
            )
        known = sorted(set(self.locations) | set(self.groups) | set(self.point_sets))
        raise InputValueError(f"{arg} names location {name!r}, but the mesh has the named locations {known}")

    def nodes(self, name: str, arg: str) -> np.ndarray:
        """Nodes of a named point, boundary or set of points."""
        if name in self.groups:
            return np.asarray(self.groups[name], dtype=int)
        if name in self.point_sets:
            return np.asarray(self.point_sets[name], dtype=int)
        return np.array([self.node(name, arg)])

    def resolve(self, at: Any, arg: str) -> tuple[int, int]:
        """``(node, component index)`` of a location name or a ``(name, component)`` pair."""
        if isinstance(at, str):
            loc, c = at, 0
        elif isinstance(at, tuple) and len(at) == 2 and all(isinstance(a, str) for a in at):
            loc, c = at[0], self.component(at[1], arg)
        else:
            raise InputTypeError(f"{arg} keys must be location names or (name, component) pairs, got {at!r}")
        return self.node(loc, arg), c


def _constrained_dofs(dofs: _NodalDofs, constraints: Sequence[tuple[str, Sequence[str], Sequence[str]]]) -> dict:
    """``{(node, component index): "arg='name'"}`` of every support."""
    constrained: dict = {}
    for arg, names, comps in constraints:
        for name in names:
            for node in dofs.nodes(name, arg):
                for comp in comps:
                    constrained[(int(node), dofs.component(comp, arg))] = f"{arg}={name!r}"
    return constrained


def _lumped_values(dofs: _NodalDofs, arg: str, table: Mapping | None) -> tuple[list, list]:
    """Full FE DOF indices and values of a point-mass or spring table (checked)."""
    idx: list = []
    vals: list = []
    if table is None:
        return idx, vals
    if not isinstance(table, Mapping):
        raise InputTypeError(f"{arg} must be a mapping {{location: value}}, got {type(table).__name__}")
    for at, value in table.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(value) or value < 0:
            raise InputValueError(f"{arg}[{at!r}] must be a finite non-negative number, got {value!r}")
        node, c = dofs.resolve(at, arg)
        idx.append(int(dofs.nodal[c, node]))
        vals.append(float(value))
    return idx, vals


def _refuse_on_supports(dofs: _NodalDofs, constrained: Mapping, tables: Mapping) -> None:
    """ValueError for a point mass or spring on a supported DOF: it was accepted and had no effect
    (the DOF is eliminated), where a contact or a force there is refused."""
    fixed = {int(dofs.nodal[c, node]) for node, c in constrained}
    for arg, (table, (idx, _)) in tables.items():
        for at, i in zip((table or {}), idx):
            if i in fixed:
                raise InputValueError(f"{arg}[{at!r}] acts on a supported DOF (clamped or fixed by supports=), where "
                                      f"it has no effect; put it on a free point, or remove that support")


def _add_diagonal(A: sp.spmatrix, added: tuple[list, list], n_full: int) -> sp.spmatrix:
    """``A`` plus the diagonal entries ``added = (indices, values)`` (none: ``A`` itself)."""
    idx, vals = added
    if not idx:
        return A
    return A + sp.csr_matrix((vals, (idx, idx)), shape=(n_full, n_full))


def _free_dofs(nodal: np.ndarray, n_full: int, constrained: dict, constraints: Sequence) -> tuple[np.ndarray, np.ndarray]:
    """Full FE index of each model DOF, and the model DOF of each (node, component) (-1: fixed)."""
    fixed_full = np.array(sorted(nodal[c, node] for node, c in constrained), dtype=int)
    free = np.setdiff1d(np.arange(n_full), fixed_full)
    if free.size == 0:
        given = ", ".join(f"{arg}={list(names)!r}" for arg, names, _ in constraints if names)
        raise InputValueError(f"the supports ({given}) fix every DOF of the mesh; leave at least one DOF free")
    free_of_full = np.full(n_full, -1, dtype=int)
    free_of_full[free] = np.arange(free.size)
    return free, free_of_full[nodal.T]  # node_dof: (n_nodes, n_components)


def _on_free_dofs(A: sp.spmatrix, free: np.ndarray) -> sp.csr_matrix:
    """``A`` restricted to the free DOFs and symmetrized to round-off (assembly sums in different orders)."""
    A = A.tocsr()[free][:, free]
    S = (A + A.T).tocsr()
    del A  # one copy fewer at a time (each is 1 GB at 1e6 P2 DOFs)
    S.data *= 0.5
    return S


def _dof_labels(coords: np.ndarray, components: tuple, free: np.ndarray, node_dof: np.ndarray,
                locations: Mapping[str, int]) -> list:
    """``"name.comp"`` at named points, ``"comp@x=..."`` (``"comp@(x, y)"`` in 2-D/3-D) at other nodes,
    ``"interior dof i"`` elsewhere."""
    labels = [""] * free.size
    for node in range(node_dof.shape[0]):
        where = f"x={coords[0, node]:.6g}" if coords.shape[0] == 1 else \
            "(" + ", ".join(f"{v:.6g}" for v in coords[:, node]) + ")"
        for c, comp in enumerate(components):
            i = node_dof[node, c]
            if i >= 0:
                labels[i] = f"{comp}@{where}"
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
    return labels
