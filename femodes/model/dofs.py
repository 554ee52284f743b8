"""Names of a model's DOFs (:class:`DofMap`): the only place where ``at=`` is turned into an index
(``at="tip"``, ``at=("tip", "theta")``, ``at=3``), named boundaries of solids included."""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..laws import Location, check_location
from ..solvers.checks import InputValueError, named_by, user_stacklevel
from .declarations import show_vector
from .frames import NodalFrame

__all__ = ["DofMap", "node_dof_list", "deprecated_owner"]


@dataclass(frozen=True, eq=False)
class DofMap:
    """Names of a model's DOFs; the only place where ``at=`` is turned into an index.

    Parameters
    ----------
    n_dofs : int
        Number of (free) DOFs.
    components : tuple of str
        Component names per node, e.g. ``("u",)`` for bars, ``("w", "theta")`` for beams. The
        first one is the default when only a location name is given.
    node_dof : ndarray of int, shape (n_nodes, n_components)
        Model DOF of each (node, component); ``-1`` if constrained, ``-2`` if the DOF exists in
        the parent model but was not kept (reduced models).
    locations : mapping str -> int
        Named locations (boundaries of the mesh) -> node index.
    constrained_by : mapping (node, component index) -> str
        Which support constrains a DOF (for error messages).
    aliases : mapping str -> str
        Alternative component names (``"u_x"`` for ``"u"``...).
    dof_names : tuple of str, optional
        Names of individual DOFs for discrete models (``StructuralModel(dof_names=...)``).
    labels : tuple of str
        Human-readable label per DOF (for messages and plots).
    groups, group_weights : mapping str -> ndarray
        Named boundaries of meshed solids -> their (Lagrange) nodes, and each node's consistent
        weight ``int N_k ds / int ds`` (sums to 1). A group is not one DOF: contacts expand to one law
        per node, a force is shared by the weights; anything else asks for a named point.
    node_coordinates : ndarray, shape (dim, n_nodes), optional
        Coordinates of the nodes (FE models).
    displacement : tuple of str
        The components along the coordinate axes x, y(, z) (``("u_x", "u_y")`` for 2-D solids;
        empty for bars, beams and discrete models): what a contact ``direction`` selects.
    point_sets : mapping str -> ndarray
        Named sets of several points of a meshed solid (a gmsh physical point of several vertices)
        -> their nodes: supports take them; a contact law or a force asks for a boundary or one point.
    frames : mapping int -> NodalFrame
        Nodes of a meshed solid whose DOFs are rotated into a nodal frame (contacts with an
        inclined or negative normal): DOFs ``"u_n"``, ``"u_t"`` (2-D) or ``"u_t1"``, ``"u_t2"`` (3-D);
        ``at=`` with a physical component of such a node is an error (``with_forcing`` rotates).
    """

    n_dofs: int
    components: tuple = ()
    node_dof: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=int))
    locations: Mapping[str, int] = field(default_factory=dict)
    constrained_by: Mapping[tuple, str] = field(default_factory=dict)
    aliases: Mapping[str, str] = field(default_factory=dict)
    dof_names: tuple = ()
    labels: tuple = ()
    groups: Mapping[str, np.ndarray] = field(default_factory=dict)
    group_weights: Mapping[str, np.ndarray] = field(default_factory=dict)
    node_coordinates: Any = None
    displacement: tuple = ()
    frames: Mapping[int, NodalFrame] = field(default_factory=dict)
    point_sets: Mapping[str, np.ndarray] = field(default_factory=dict)

    @classmethod
    def discrete(cls, n_dofs: int, dof_names: Sequence[str] | None = None) -> DofMap:
        """DOF map of a discrete system: DOFs addressed by index or by ``dof_names``."""
        names: tuple = ()
        if dof_names is not None:
            # a str is iterable: "ab" would silently name two DOFs "a" and "b"
            if isinstance(dof_names, (str, bytes)) or not isinstance(dof_names, (Sequence, np.ndarray)):
                raise TypeError(
                    f"dof_names must be a list of {n_dofs} strings (one per DOF), got {dof_names!r}"
                )
            names = tuple(dof_names)
            if len(names) != n_dofs or not all(isinstance(n, str) and n for n in names):
                raise ValueError(
                    f"dof_names must be {n_dofs} non-empty strings (one per DOF), got {dof_names!r}"
                )
            if len(set(names)) != len(names):
                raise ValueError(f"dof_names must be unique, got {dof_names!r}")
        labels = names if names else tuple(f"dof {i}" for i in range(n_dofs))
        return cls(n_dofs=n_dofs, dof_names=names, labels=labels)

    def component_index(self, comp: str) -> int:
        """Component slot of the component name (or alias) ``comp``."""
        name = self.aliases.get(comp, comp)
        if name not in self.components:
            raise ValueError(
                f"unknown component {comp!r}; this model has components {list(self.components)}"
                + (f" (aliases {dict(self.aliases)})" if self.aliases else "")
            )
        return self.components.index(name)

    def index(self, at: Location, owner: str | None = None) -> int:
        """Model DOF index of ``at`` (a name, a (name, component) pair or an index).

        Errors start with ``"DofMap: "`` (:mod:`femodes.solvers.checks`); inside femodes,
        :meth:`find` leaves them to the public function called. ``owner`` is deprecated
        (it named the errors).

        Raises
        ------
        ValueError
            Unknown name or component, index out of range, or a constrained / not-kept DOF
            (the message names it and the support that constrains it).
        """
        with named_by(deprecated_owner(owner, "DofMap.index") or "DofMap"):
            return self.find(at)

    def find(self, at: Location) -> int:
        """:meth:`index` with its errors left to the public function called (femodes' own use)."""
        at = check_location(at)
        where = f"at={at!r}"
        if isinstance(at, int):
            if at >= self.n_dofs:
                raise InputValueError(
                    f"{where}: DOF index at={at} is out of range for a model with {self.n_dofs} DOFs "
                    f"(use 0 <= at < {self.n_dofs})"
                )
            return at
        if isinstance(at, str) and at in self.dof_names:
            return self.dof_names.index(at)
        if isinstance(at, str):
            loc, comp = at, (self.components[0] if self.components else None)
        else:
            loc, comp = at
        if loc in self.groups and loc not in self.locations:
            raise InputValueError(
                f"{where}: {loc!r} is a boundary with {len(self.groups[loc])} nodes, not one DOF; contact laws "
                f"and forces accept boundaries, for anything else name a point (gmsh physical point, or "
                f"points={{...}} of femodes.solid)"
            )
        if loc in self.point_sets and loc not in self.locations:
            raise InputValueError(
                f"{where}: {loc!r} is a set of {len(self.point_sets[loc])} points (a gmsh physical point of several "
                f"vertices), not one DOF; name each point alone (one gmsh physical point per vertex, or "
                f"points={{...}} of femodes.solid), or put the law or force on a named boundary"
            )
        if loc not in self.locations:
            known = sorted(set(self.locations) | set(self.groups) | set(self.point_sets)) + list(self.dof_names)
            raise InputValueError(f"{where}: unknown location {loc!r}; known names are {known}")
        if comp is None:
            raise InputValueError(f"{where}: location {loc!r} has no components in this model")
        node = self.locations[loc]
        frame = self.frames.get(node)
        if frame is not None and comp in frame.components:
            c = frame.components.index(comp)
        elif frame is not None:
            raise InputValueError(
                f"{where}: node {node} ({loc!r}) has rotated DOFs {list(frame.components)} (the nodal frame of a contact "
                f"with normal n={show_vector(frame.normal)}), so {comp!r} is not one of this model's DOFs; use "
                f"({loc!r}, {frame.components[frame.slot]!r}) or a tangent (forces in physical components are rotated "
                "by with_forcing)"
            )
        else:
            try:
                c = self.component_index(comp)
            except ValueError as exc:
                raise InputValueError(f"{where}: {exc}") from None
        dof = int(self.node_dof[node, c])
        if dof == -1:
            support = self.constrained_by.get((node, c), "a support")
            raise InputValueError(
                f"{where}: DOF ({loc!r}, {self.components[c]!r}) is constrained by {support!r}; "
                "contact, forcing and springs cannot act on a constrained DOF"
            )
        if dof == -2:
            raise InputValueError(
                f"{where}: DOF ({loc!r}, {self.components[c]!r}) is not kept in this reduced model; "
                f"pass keep=[({loc!r}, {self.components[c]!r})] to craig_bampton"
            )
        return dof

    def node_dofs(self, at: Location, owner: str | None = None) -> list[int]:
        """Model DOFs of ``at``: every free component of a named point (a node is taken whole),
        or the single DOF of a ``(name, component)`` pair, a DOF name or an index (errors and
        ``owner`` as in :meth:`index`)."""
        with named_by(deprecated_owner(owner, "DofMap.node_dofs") or "DofMap"):
            return self._node_dofs(at)

    def _node_dofs(self, at: Location) -> list[int]:
        at = check_location(at)
        if isinstance(at, str) and at in self.locations and at not in self.dof_names:
            node = self.locations[at]
            dofs = [int(d) for d in self.node_dof[node] if d >= 0]
            if not dofs:
                raise InputValueError(f"at={at!r}: every component of {at!r} is constrained or not kept")
            return dofs
        return [self.find(at)]

    def label(self, i: int) -> str:
        return self.labels[i] if i < len(self.labels) else f"dof {i}"

    def axis(self, node: int, c: int) -> np.ndarray:
        """Physical unit vector of the DOF in component slot ``c`` of ``node`` (a meshed solid):
        ``e_c``, or column ``c`` of the node's :class:`NodalFrame` if its DOFs are rotated."""
        frame = self.frames.get(int(node))
        if frame is not None:
            return np.array(frame.rotation[:, c])
        e = np.zeros(max(len(self.displacement), len(self.components)))
        e[c] = 1.0
        return e

    def restrict(self, kept: np.ndarray) -> DofMap:
        """DofMap of the DOFs ``kept`` (old indices in new order), followed by unnamed DOFs.

        Old DOFs not in ``kept`` are marked "not kept" (-2); constrained ones stay constrained.
        """
        kept = np.asarray(kept, dtype=int)
        new_of_old = np.full(self.n_dofs, -2, dtype=int)
        new_of_old[kept] = np.arange(kept.size)
        node_dof = self.node_dof.copy()
        free = node_dof >= 0
        node_dof[free] = new_of_old[node_dof[free]]
        names = tuple(self.dof_names[i] for i in kept) if self.dof_names else ()
        labels = tuple(self.label(i) for i in kept)
        return dataclasses.replace(self, n_dofs=kept.size, node_dof=node_dof, dof_names=names, labels=labels)

    def extended(self, extra_labels: Sequence[str]) -> DofMap:
        """The same map with unnamed extra DOFs appended (e.g. modal coordinates)."""
        names = self.dof_names + tuple(extra_labels) if self.dof_names else ()
        return dataclasses.replace(
            self, n_dofs=self.n_dofs + len(extra_labels), dof_names=names, labels=self.labels + tuple(extra_labels)
        )


    def group_of(self, at: Location) -> tuple[str, int] | None:
        """``(boundary name, component index)`` if ``at`` names a boundary of a solid, else None."""
        if isinstance(at, str) and at in self.groups and at not in self.locations and at not in self.dof_names:
            return at, 0
        if isinstance(at, tuple) and len(at) == 2 and at[0] in self.groups and at[0] not in self.locations:
            try:
                return at[0], self.component_index(at[1])
            except ValueError as exc:
                raise ValueError(f"at={at!r}: {exc}") from None
        return None

    def dof_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """Node and component slot of every DOF (node ``-1`` for DOFs on no node)."""
        nd = self.node_dof
        node_of = np.full(self.n_dofs, -1, dtype=int)
        comp_of = np.zeros(self.n_dofs, dtype=int)
        if nd.size:
            k, c = np.nonzero(nd >= 0)
            node_of[nd[k, c]] = k
            comp_of[nd[k, c]] = c
        return node_of, comp_of


def node_dof_list(dm: DofMap, at: Location) -> list[int]:
    """:meth:`DofMap.node_dofs` with its errors left unnamed."""
    return dm._node_dofs(at)


def deprecated_owner(owner: str | None, where: str) -> str | None:
    """``owner`` (a DeprecationWarning when given: the public function called names the errors)."""
    if owner is not None:
        warnings.warn(f"{where}: owner= is deprecated and will be removed; the public function called names the "
                      "errors", DeprecationWarning, stacklevel=user_stacklevel())
    return owner
