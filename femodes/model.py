"""Models layer: ``StructuralModel`` (M, K, C plus declarations) and ``DofMap`` (naming of DOFs).

A model describes ``M q'' + C q' + K q + f_nl(q) = sum_k f_k cos(k w t + phi_k) - w_c p`` on its
free DOFs ``q`` (constrained DOFs are eliminated). Models are frozen: ``with_damping``,
``with_forcing``, ``with_contact`` and ``with_nonlinearity`` return new models. Only ``DofMap``
turns names into indices (``at="tip"``, ``at=("tip", "theta")``, ``at=3``).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import warnings
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np
import scipy.sparse as sp

from .eigen import normal_modes
from .fe.checks import outward_normal
from .fe.redistribution import ConsistentMass, RedistributeMass, apply_each
from .laws import CubicSpring, Location, PenaltyContact, UnilateralContact, check_location

__all__ = ["DofMap", "NodalFrame", "HarmonicForce", "Attached", "StructuralModel", "LowRankDamping", "as_sparse_matrix",
           "low_rank_solver", "nodal_frame"]

log = logging.getLogger(__name__)

CONTACT_LAWS = (UnilateralContact, PenaltyContact)
SMOOTH_LAWS = (CubicSpring,)


# --------------------------------------------------------------------------------------------
# Nodal frames (contacts with inclined or negative normals)
# --------------------------------------------------------------------------------------------
#: A contact ``direction`` whose largest component is at least ``1 - AXIS_TOL`` (unit vector) is
#: along that positive coordinate axis: the contact acts on that displacement DOF, no rotation.
AXIS_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class NodalFrame:
    """Orthonormal frame of the DOFs of one node of a meshed solid: ``u_node = rotation @ q_node``.

    ``rotation`` is a proper rotation (``det = +1``, columns = the nodal axes in physical
    coordinates); column ``slot`` is the contact normal ``n``, so that the model DOF in that
    component slot is ``u_n = n . u`` and a contact acts on it with ``g_N = gap - u_n``. The other
    columns are tangents (``u_t`` in 2-D; ``u_t1``, ``u_t2`` in 3-D, in slot order).
    """

    rotation: np.ndarray
    slot: int

    @property
    def normal(self) -> np.ndarray:
        return self.rotation[:, self.slot]

    @property
    def components(self) -> tuple:
        """Names of the nodal-frame components, one per slot (``("u_n", "u_t")``, ...)."""
        dim = self.rotation.shape[0]
        tangents = iter(("u_t",) if dim == 2 else tuple(f"u_t{k + 1}" for k in range(dim - 1)))
        return tuple("u_n" if j == self.slot else next(tangents) for j in range(dim))


def nodal_frame(normal: Sequence[float]) -> NodalFrame:
    """The nodal frame of a contact normal (a proper rotation whose column ``slot`` is ``normal``).

    ``slot`` is the component of largest magnitude of ``normal`` (the coordinate axis nearest to
    it, so that a normal near an axis keeps that axis' slot). 2-D: the other column is ``n``
    turned by -90 or +90 degrees, whichever gives ``det = +1`` (``(-1, 0)`` gives the rotation by
    180 degrees, not the reflection ``diag(-1, 1)``). 3-D: the Householder reflection
    ``H = I - 2 v v^T / v^T v``, ``v = n + sign(n_s) e_s`` (no cancellation: ``|v|^2 >= 2``),
    maps ``e_s`` to ``-sign(n_s) n``; its column ``s`` is rescaled to ``n`` and, where that leaves
    ``det = -1``, the first tangent is negated.
    """
    n = np.asarray(normal, dtype=float).reshape(-1)
    n = n / np.linalg.norm(n)
    dim = n.size
    s = int(np.argmax(np.abs(n)))
    if dim == 2:
        t = np.array([-n[1], n[0]])  # n turned by +90 degrees
        R = np.column_stack([n, t]) if s == 0 else np.column_stack([-t, n])
    elif dim == 3:
        sigma = 1.0 if n[s] >= 0 else -1.0
        v = n.copy()
        v[s] += sigma
        R = np.eye(3) - (2.0 / (v @ v)) * np.outer(v, v)
        R[:, s] = n
        if sigma < 0:  # det(H) = -1 and column s was multiplied by -sigma = +1
            R[:, 0 if s != 0 else 1] *= -1.0
    else:
        raise ValueError(f"nodal_frame: a normal of a 2-D or 3-D solid is needed, got {tuple(normal)}")
    R.flags.writeable = False
    return NodalFrame(rotation=R, slot=s)


def _same_normal(a: NodalFrame, b: NodalFrame) -> bool:
    return a.slot == b.slot and bool(np.allclose(a.normal, b.normal, rtol=0.0, atol=1e-12))


def _block_rotation(node_dof: np.ndarray, n: int, nodes: Sequence[int], rotations: np.ndarray) -> sp.csr_matrix:
    """Sparse orthogonal ``n x n`` matrix: ``rotations[k]`` on the DOFs ``node_dof[nodes[k]]`` (all
    free), the identity on every other DOF."""
    nodes = np.asarray(nodes, dtype=int)
    rotations = np.asarray(rotations, dtype=float).reshape(nodes.size, node_dof.shape[1], node_dof.shape[1])
    dofs = node_dof[nodes]  # (k, dim)
    other = np.ones(n, dtype=bool)
    other[dofs.ravel()] = False
    eye = np.flatnonzero(other)
    dim = dofs.shape[1]
    rows = np.concatenate([eye, np.repeat(dofs, dim, axis=1).ravel()])
    cols = np.concatenate([eye, np.tile(dofs, (1, dim)).ravel()])
    vals = np.concatenate([np.ones(eye.size), rotations.ravel()])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def _frame_force(f, R: np.ndarray, dofs: np.ndarray, c: int, weight: float) -> list:
    """``weight`` times the force ``f`` along physical component ``c`` of a node with nodal frame
    ``R`` (model DOFs ``dofs``), as forces on the node's DOFs: ``R^T e_c`` (nonzero parts only)."""
    out = []
    for j, d in enumerate(dofs):
        share = float(R[c, j]) * weight
        if share != 0.0:
            out.append(Attached(dataclasses.replace(f, at=int(d), amplitude=f.amplitude * share), int(d)))
    return out


# --------------------------------------------------------------------------------------------
# DOF naming
# --------------------------------------------------------------------------------------------
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
    groups : mapping str -> ndarray of int
        Named boundaries of meshed solids -> their nodes (every Lagrange node on the boundary).
        A group is not one DOF: contacts expand to one law per node
        (:meth:`StructuralModel.with_contact`), a force is distributed over it
        (:meth:`StructuralModel.with_forcing`); anything else asks for a named point.
    group_weights : mapping str -> ndarray of float
        Consistent weight of each node of a group, ``int_boundary N_k ds / int_boundary ds`` (sums
        to 1): how a resultant force on the boundary is shared by its nodes.
    node_coordinates : ndarray, shape (dim, n_nodes), optional
        Coordinates of the nodes (FE models).
    displacement : tuple of str
        The components along the coordinate axes x, y(, z) (``("u_x", "u_y")`` for 2-D solids;
        empty for bars, beams and discrete models): what a contact ``direction`` selects.
    frames : mapping int -> NodalFrame
        Nodes of a meshed solid whose DOFs are rotated into a nodal frame (contacts with an
        inclined or negative normal, :meth:`StructuralModel.with_contact`). Their DOFs are named
        ``"u_n"`` (along the normal) and ``"u_t"`` (2-D) or ``"u_t1"``, ``"u_t2"`` (3-D): ``at=``
        with a physical component (``"u_x"``...) of such a node is an error for :meth:`index`
        (``with_forcing`` rotates forces given in physical components itself).
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

    def _component(self, comp: str) -> int:
        name = self.aliases.get(comp, comp)
        if name not in self.components:
            raise ValueError(
                f"unknown component {comp!r}; this model has components {list(self.components)}"
                + (f" (aliases {dict(self.aliases)})" if self.aliases else "")
            )
        return self.components.index(name)

    def index(self, at: Location, owner: str = "DofMap") -> int:
        """Model DOF index of ``at`` (a name, a (name, component) pair or an index).

        ``owner`` (e.g. ``"with_contact"``) starts the error messages.

        Raises
        ------
        ValueError
            Unknown name or component, index out of range, or a constrained / not-kept DOF
            (the message names it and the support that constrains it).
        """
        at = check_location(at, owner)
        where = f"{owner}: at={at!r}"
        if isinstance(at, int):
            if at >= self.n_dofs:
                raise ValueError(
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
            raise ValueError(
                f"{where}: {loc!r} is a boundary with {len(self.groups[loc])} nodes, not one DOF; contact laws "
                f"and forces accept boundaries, for anything else name a point (gmsh physical point, or "
                f"points={{...}} of femodes.solid)"
            )
        if loc not in self.locations:
            known = sorted(set(self.locations) | set(self.groups)) + list(self.dof_names)
            raise ValueError(f"{where}: unknown location {loc!r}; known names are {known}")
        if comp is None:
            raise ValueError(f"{where}: location {loc!r} has no components in this model")
        node = self.locations[loc]
        frame = self.frames.get(node)
        if frame is not None and comp in frame.components:
            c = frame.components.index(comp)
        elif frame is not None:
            raise ValueError(
                f"{where}: node {node} ({loc!r}) has rotated DOFs {list(frame.components)} (the nodal frame of a contact "
                f"with normal n={_vector(frame.normal)}), so {comp!r} is not one of this model's DOFs; use "
                f"({loc!r}, {frame.components[frame.slot]!r}) or a tangent (forces in physical components are rotated "
                "by with_forcing)"
            )
        else:
            try:
                c = self._component(comp)
            except ValueError as exc:
                raise ValueError(f"{where}: {exc}") from None
        dof = int(self.node_dof[node, c])
        if dof == -1:
            support = self.constrained_by.get((node, c), "a support")
            raise ValueError(
                f"{where}: DOF ({loc!r}, {self.components[c]!r}) is constrained by {support!r}; "
                "contact, forcing and springs cannot act on a constrained DOF"
            )
        if dof == -2:
            raise ValueError(
                f"{where}: DOF ({loc!r}, {self.components[c]!r}) is not kept in this reduced model; "
                f"pass keep=[({loc!r}, {self.components[c]!r})] to craig_bampton"
            )
        return dof

    def node_dofs(self, at: Location, owner: str = "DofMap") -> list[int]:
        """Model DOFs of ``at``: every free component of a named point (a node is taken whole),
        or the single DOF of a ``(name, component)`` pair, a DOF name or an index."""
        at = check_location(at, owner)
        if isinstance(at, str) and at in self.locations and at not in self.dof_names:
            node = self.locations[at]
            dofs = [int(d) for d in self.node_dof[node] if d >= 0]
            if not dofs:
                raise ValueError(f"{owner}: at={at!r}: every component of {at!r} is constrained or not kept")
            return dofs
        return [self.index(at, owner)]

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


# --------------------------------------------------------------------------------------------
# Declarations attached to a model
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HarmonicForce:
    """Point force ``amplitude * cos(harmonic * w t + phase)`` at a DOF.

    ``harmonic`` is the multiple of the forcing frequency ``w`` (1 = primary forcing).
    """

    at: Location
    amplitude: float = 1.0
    harmonic: int = 1
    phase: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "at", check_location(self.at, "HarmonicForce"))
        for name in ("amplitude", "phase"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise ValueError(f"HarmonicForce: {name} must be a finite real number, got {v!r}")
            object.__setattr__(self, name, float(v))
        h = self.harmonic
        if isinstance(h, bool) or not isinstance(h, (int, np.integer)) or h < 0:
            raise ValueError(f"HarmonicForce: harmonic must be an integer >= 0 (0 = static load), got {h!r}")
        object.__setattr__(self, "harmonic", int(h))


@dataclass(frozen=True)
class Attached:
    """A declaration (law or force) bound to a model DOF index."""

    item: Any
    dof: int


def _vector(v) -> str:
    return "(" + ", ".join(f"{float(x):.6g}" for x in v) + ")"


def as_sparse_matrix(A: Any, name: str, n: int | None = None) -> sp.csr_matrix:
    """Validate a square real finite matrix (dense or sparse) and return it as CSR."""
    if A is None:
        raise ValueError(f"{name} is required")
    if sp.issparse(A):
        if np.iscomplexobj(A.data):
            raise TypeError(f"{name} must be a real matrix, got complex entries (dtype {A.dtype})")
        A = sp.csr_matrix(A, dtype=float)
    else:
        try:
            raw = np.asarray(A)
            if raw.dtype.kind == "c":
                raise TypeError(f"{name} must be a real matrix, got complex entries (dtype {raw.dtype})")
            if raw.dtype.kind in "SUV" or isinstance(A, (str, bytes)):
                raise TypeError(f"{name} must be a square real matrix, got entries of type {raw.dtype} ({A!r:.60})")
            arr = np.asarray(raw, dtype=float)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, TypeError) and str(exc).startswith(name):
                raise
            raise TypeError(
                f"{name} must be a square real matrix (numpy array or scipy.sparse) with rows of equal length, "
                f"got {type(A).__name__} ({exc})"
            ) from exc
        if arr.ndim == 0 and n == 1:
            arr = arr.reshape(1, 1)
        if arr.ndim != 2:
            raise ValueError(f"{name} must be a 2-D square matrix, got shape {arr.shape}")
        A = sp.csr_matrix(arr)
    if A.shape[0] != A.shape[1]:
        raise ValueError(f"{name} must be square, got shape {A.shape}")
    if n is not None and A.shape[0] != n:
        raise ValueError(f"{name} has shape {A.shape} but the model has {n} DOFs (M is {n}x{n})")
    if not np.all(np.isfinite(A.data)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    return A


def _check_symmetric(A: sp.csr_matrix, name: str) -> None:
    scale = abs(A).max() if A.nnz else 0.0
    asym = abs(A - A.T).max() if A.nnz else 0.0
    if asym > 1e-10 * max(scale, 1e-300):
        raise ValueError(f"{name} must be symmetric: max |{name} - {name}^T| = {asym:.3e} (max |{name}| = {scale:.3e})")


def _check_semidefinite(A: sp.csr_matrix, name: str, *, definite: bool) -> None:
    """Reject matrices with a clearly negative eigenvalue (or a non-positive diagonal for M)."""
    d = A.diagonal()
    scale = float(abs(A).max()) if A.nnz else 0.0
    # Zero diagonal entries are legitimate (mass redistributed away from a contact node).
    if np.any(d < -1e-12 * max(scale, 1e-300)):
        i = int(np.argmin(d))
        raise ValueError(f"{name} must be positive semidefinite; diagonal entry {name}[{i},{i}] = {d[i]:.6g} < 0")
    n = A.shape[0]
    if n <= 400:
        lam = np.linalg.eigvalsh(A.toarray())
        if lam[0] < -1e-9 * max(abs(lam[-1]), 1e-300):
            raise ValueError(f"{name} must be positive semidefinite; its smallest eigenvalue is {lam[0]:.6g}")
        if definite and lam[-1] <= 0:
            raise ValueError(f"{name} must not be zero")
    # Large sparse matrices: the diagonal test above; a full eigenvalue test would cost a factorization.


# --------------------------------------------------------------------------------------------
# Modal damping: a low-rank part of C
# --------------------------------------------------------------------------------------------
#: Models above this many DOFs refuse to assemble a damping matrix that has a low-rank part
#: (:meth:`StructuralModel.damping_matrix`): its n^2 entries are what the low-rank form avoids.
DENSE_DAMPING_MAX_DOFS = 20000


@dataclass(frozen=True, eq=False)
class LowRankDamping:
    r"""The low-rank part ``U diag(d) U^T`` of a damping matrix (modal damping).

    Modal damping ``C = M Phi diag(2 zeta_j w_j) Phi^T M`` on ``m`` mass-normalised modes is
    kept as ``U = M Phi`` (``n x m``, dense) and ``d = 2 zeta w`` (``m``): ``2 n m`` numbers
    instead of ``n^2``, and ``C v`` costs ``4 n m`` flops. Every consumer uses it exactly: the
    harmonic balance residual and Jacobian, its block solver (the modal coordinates
    ``y = U^T q`` join the boundary of the Schur complement), linear responses and time stepping
    (Woodbury, :func:`low_rank_solver`), shooting and Hill's method (assembled, small models).

    Parameters
    ----------
    U : array_like, shape (n, m)
    d : array_like, shape (m,)
        Non-negative gains.
    modes, eigenvalues : ndarray, optional
        ``Phi`` and ``w_j^2`` when ``U = M Phi`` with ``K Phi = M Phi diag(w^2)`` (set by
        ``with_damping``): then ``(K - a M) Phi = U diag(w^2 - a)``, which gives the block solver
        ``Z^-1 U`` without solves. Only a hint: users of it check the relation on their matrices.
    """

    U: Any
    d: Any
    modes: Any = None
    eigenvalues: Any = None

    def __post_init__(self):
        U = np.array(self.U, dtype=float, order="C")
        d = np.array(self.d, dtype=float).ravel()
        if U.ndim != 2 or d.shape != (U.shape[1],):
            raise ValueError(f"LowRankDamping: U must be (n, m) and d (m,), got shapes {U.shape} and {d.shape}")
        if not (np.all(np.isfinite(U)) and np.all(np.isfinite(d))) or np.any(d < 0):
            raise ValueError("LowRankDamping: U and d must be finite and d non-negative")
        U.flags.writeable = d.flags.writeable = False
        object.__setattr__(self, "U", U)
        object.__setattr__(self, "d", d)

    @property
    def n(self) -> int:
        return self.U.shape[0]

    @property
    def rank(self) -> int:
        return self.U.shape[1]

    @property
    def nnz(self) -> int:
        """Stored numbers (``U`` and ``d``)."""
        return int(self.U.size + self.d.size)

    def matmul(self, X: np.ndarray) -> np.ndarray:
        """``U diag(d) U^T X`` for ``X`` of shape ``(n,)`` or ``(n, k)`` (real or complex)."""
        X = np.asarray(X)
        Y = self.U.T @ X
        Y = (self.d * Y.T).T if Y.ndim == 2 else self.d * Y
        return self.U @ Y

    def rmatmul_rows(self, Q: np.ndarray) -> np.ndarray:
        """``(C_lr Q^T)^T = Q U diag(d) U^T`` for ``Q`` of shape ``(k, n)`` (rows are vectors)."""
        return ((np.asarray(Q) @ self.U) * self.d) @ self.U.T

    def abs_bound_rows(self, Q: np.ndarray) -> np.ndarray:
        """An upper bound of ``|C_lr| |Q|`` on rows, like :meth:`rmatmul_rows`: ``|U| d |U|^T``."""
        aU = np.abs(self.U)
        return ((np.abs(np.asarray(Q)) @ aU) * self.d) @ aU.T

    def abs_row_sums(self) -> np.ndarray:
        """Upper bounds of the row sums of ``|U diag(d) U^T|``."""
        aU = np.abs(self.U)
        return aU @ (self.d * aU.sum(axis=0))

    def toarray(self) -> np.ndarray:
        """The assembled ``n x n`` matrix (symmetrized; small models and checks only)."""
        C = (self.U * self.d) @ self.U.T
        return 0.5 * (C + C.T)

    def restrict(self, rows) -> LowRankDamping:
        """The part on a subset (or slice) of the DOFs: ``U[rows] diag(d) U[rows]^T``."""
        return LowRankDamping(self.U[rows], self.d)

    def project(self, T: np.ndarray) -> LowRankDamping:
        """``T^T (U diag(d) U^T) T`` as a low-rank part: ``(T^T U, d)``."""
        return LowRankDamping(np.asarray(T).T @ self.U, self.d)


def low_rank_solver(solve, L: np.ndarray, g: np.ndarray, R: np.ndarray, *, matvec=None, refine: int = 2):
    r"""Solver of ``(A + L diag(g) R^T) x = b`` from a solver ``solve(b) = A^{-1} b`` (Woodbury).

    With ``X = A^{-1} L`` (``m`` solves, done here once) and the ``m x m`` capacitance matrix
    ``S = I + diag(g) R^T X``: ``x0 = A^{-1} b``, ``y = S^{-1} diag(g) R^T x0``, ``x = x0 - X y``
    (Hager 1989, "Updating the inverse of a matrix", SIAM Rev. 31:221). No ``g^{-1}`` is formed,
    so zero gains are fine. ``matvec(x) = A x``, if given, adds up to ``refine`` steps of
    iterative refinement against the full matrix (``A`` may be ill-conditioned: the undamped
    sparse part near a resonance that the low-rank part damps). ``b`` may be 1-D or 2-D.
    """
    import scipy.linalg as sla

    L = np.asarray(L)
    R = np.asarray(R)
    g = np.asarray(g)
    X = solve(L)
    S = np.eye(g.size, dtype=np.result_type(X, g)) + g[:, None] * (R.T @ X)
    lu = sla.lu_factor(S, check_finite=False)

    def apply(x):
        Rx = R.T @ x
        return (L @ ((g * Rx.T).T if Rx.ndim == 2 else g * Rx))

    def once(b):
        x0 = solve(b)
        Rx = R.T @ x0
        y = sla.lu_solve(lu, (g * Rx.T).T if Rx.ndim == 2 else g * Rx, check_finite=False)
        return x0 - X @ y

    def run(b):
        b = np.asarray(b)
        x = once(b)
        if matvec is not None:
            scale = float(np.max(np.abs(b))) if b.size else 0.0
            for _ in range(refine):
                r = b - matvec(x) - apply(x)
                if not np.max(np.abs(r), initial=0.0) > 1e-14 * scale:
                    break
                x = x + once(r)
        return x

    return run


def _redistribute(strategy, fe, M, dofs) -> tuple:
    """``(M, reports)`` after the contact-mass ``strategy`` on ``dofs`` (all at once if it can)."""
    if callable(getattr(strategy, "apply_all", None)):
        M, reps = strategy.apply_all(fe, M, dofs)
        return M, list(reps)
    return apply_each(strategy, fe, M, dofs)


# --------------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class StructuralModel:
    """Linear structure with nonlinear declarations.

    ``M q'' + C q' + K q + f_nl(q) = f(t) - w_c p`` on ``n_dofs`` free DOFs.

    Parameters
    ----------
    M, K : array_like or scipy.sparse matrix
        Symmetric mass (positive semidefinite, not zero) and stiffness (positive semidefinite)
        matrices, ``n_dofs x n_dofs``.
    C : array_like or sparse, optional
        Symmetric damping matrix (zero if omitted): the sparse part of the damping.
    dof_names : sequence of str, optional
        Names of the DOFs of a discrete system (then ``at="x1"`` works).
    C_lowrank : LowRankDamping, optional
        Low-rank part of the damping, set by ``with_damping(modal=...)``: the damping matrix is
        ``C + U diag(d) U^T`` (see :class:`LowRankDamping`). Use :meth:`apply_damping` for
        products and :meth:`damping_matrix` for the assembled matrix (small models, checks);
        ``C`` alone is only the sparse part (zero for modal damping).
    frame : scipy.sparse matrix, optional
        Nodal rotations of a meshed solid (set by ``with_contact`` for inclined or negative
        contact normals): the physical displacement on the free DOFs of the FE field is
        ``u = frame @ q``, ``frame`` orthogonal and block diagonal (one rotation per rotated node,
        :class:`NodalFrame` in ``dofmap.frames``; the identity elsewhere). ``M``, ``K``, ``C`` and
        the forces are the transformed ``T^T A T``, ``T^T f``. None (the default): ``q`` is
        physical.
    damping_spec : tuple, optional
        The arguments of the last :meth:`with_damping` as ``(name, value)`` pairs and the
        ``"fingerprint"`` of the matrices it made (empty when the damping was given as a matrix):
        :meth:`with_contact` recomputes the damping from them when it redistributes mass, unless
        the matrices were replaced since (a warning; they are then kept).

    Notes
    -----
    FE constructors (:func:`femodes.bar`, :func:`femodes.beam`) fill ``dofmap`` and ``fe`` (the
    mesh, the scikit-fem basis and the free DOFs of the full field).
    """

    M: Any
    K: Any
    C: Any = None
    dof_names: Sequence[str] | None = None
    dofmap: DofMap | None = None
    forces: tuple = ()
    contacts: tuple = ()
    nonlinearities: tuple = ()
    fe: Any = None
    damping_info: str = "none"
    mass_redistribution: tuple = ()
    C_lowrank: LowRankDamping | None = None
    frame: Any = None
    damping_spec: tuple = ()

    def __post_init__(self):
        M = as_sparse_matrix(self.M, "M")
        n = M.shape[0]
        if n == 0:
            raise ValueError("M must have at least one DOF")
        K = as_sparse_matrix(self.K, "K", n)
        C = sp.csr_matrix((n, n)) if self.C is None else as_sparse_matrix(self.C, "C", n)
        _check_symmetric(M, "M")
        _check_symmetric(K, "K")
        _check_symmetric(C, "C")
        if M.nnz == 0 or not np.any(M.diagonal() > 0):
            raise ValueError("M must have positive mass on at least one DOF")
        _check_semidefinite(M, "M", definite=True)
        _check_semidefinite(K, "K", definite=False)
        _check_semidefinite(C, "C", definite=False)
        object.__setattr__(self, "M", M)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "C", C)
        if self.C_lowrank is not None:
            if not isinstance(self.C_lowrank, LowRankDamping):
                raise TypeError(f"C_lowrank must be a LowRankDamping or None, got {type(self.C_lowrank).__name__}")
            if self.C_lowrank.n != n:
                raise ValueError(f"C_lowrank has {self.C_lowrank.n} rows but the model has {n} DOFs")
        if self.damping_info == "none" and C.nnz and np.any(C.data != 0):
            object.__setattr__(self, "damping_info", "matrix C")  # given directly (StructuralModel(C=...))
        dm = self.dofmap
        if dm is None:
            dm = DofMap.discrete(n, self.dof_names)
        elif dm.n_dofs != n:
            raise ValueError(f"dofmap has {dm.n_dofs} DOFs but M is {n}x{n}")
        object.__setattr__(self, "dofmap", dm)
        if self.frame is not None:
            if not sp.issparse(self.frame) or self.frame.shape != (n, n):
                raise ValueError(f"frame must be a sparse {n}x{n} matrix (u = frame @ q) or None")
            if self.fe is None:
                raise ValueError("frame (nodal rotations) needs an FE model (fe=...)")
            object.__setattr__(self, "frame", sp.csr_matrix(self.frame))

    # -- basic properties ---------------------------------------------------------------------
    @property
    def n_dofs(self) -> int:
        return self.M.shape[0]

    @property
    def n_contacts(self) -> int:
        return len(self.contacts)

    @property
    def is_reduced(self) -> bool:
        return False

    @property
    def has_damping(self) -> bool:
        """True if the damping (sparse or low-rank part) is not zero (stored zeros do not count)."""
        return bool(self.C.count_nonzero()) or (self.C_lowrank is not None and bool(np.any(self.C_lowrank.d)))

    def apply_damping(self, V: np.ndarray) -> np.ndarray:
        """The damping matrix times ``V`` (shape ``(n,)`` or ``(n, k)``): ``C V + U diag(d) U^T V``."""
        out = self.C @ V
        if self.C_lowrank is not None:
            out = out + self.C_lowrank.matmul(V)
        return out

    def damping_matrix(self) -> sp.csr_matrix:
        """The assembled damping matrix ``C + U diag(d) U^T`` (``C`` itself without a low-rank part).

        With a low-rank part the matrix is dense: for small models and checks only; refused
        above :data:`DENSE_DAMPING_MAX_DOFS` DOFs.
        """
        lr = self.C_lowrank
        if lr is None:
            return self.C
        if self.n_dofs > DENSE_DAMPING_MAX_DOFS:
            raise ValueError(
                f"damping_matrix: the modal damping of this {self.n_dofs}-DOF model is kept as a low-rank part; "
                f"assembling it would store {self.n_dofs}^2 entries (use apply_damping, or C and C_lowrank)"
            )
        return sp.csr_matrix(self.C.toarray() + lr.toarray())

    def dof(self, at: Location, owner: str = "dof") -> int:
        """Model DOF index of a location (see :class:`DofMap`); ``owner`` starts error messages."""
        return self.dofmap.index(at, owner)

    def probe(self, at: Location, how: str = "mean", owner: str = "probe") -> np.ndarray:
        """Weights ``w`` that read a response at ``at`` from the model's DOFs: ``w @ q``.

        A DOF location gives its unit vector (shape ``(n_dofs,)``). A named boundary of a meshed
        solid (``"tip"`` or ``("tip", "u_z")``; first component by default) gives, with
        ``how="mean"``, its average displacement in that component (the consistent weights of
        :attr:`DofMap.group_weights`, supported nodes counting as zero; shape ``(n_dofs,)``),
        and with ``how="max"`` one row per free node (shape ``(k, n_dofs)``: take the largest).
        A Craig-Bampton model reads boundaries of its parent, kept or not (``w_parent @ T``), so
        responses anywhere need no new model.
        """
        if how not in ("mean", "max"):
            raise ValueError(f"{owner}: how must be 'mean' or 'max' (over the boundary's nodes), got {how!r}")
        group = self._group_of(at)
        if group is None:
            w = np.zeros(self.n_dofs)
            w[self.dof(at, owner)] = 1.0
            return w
        name, c = group
        dm = self.dofmap
        dofs = dm.node_dof[np.asarray(dm.groups[name]), c]
        weights = np.asarray(dm.group_weights[name], dtype=float)
        if np.any(dofs == -2):
            raise ValueError(f"{owner}: boundary {name!r} is not kept in this model; read it on the full model")
        free = dofs >= 0
        if not free.any():
            raise ValueError(f"{owner}: every node of boundary {name!r} is supported in that component")
        if how == "max":
            W = np.zeros((int(free.sum()), self.n_dofs))
            W[np.arange(W.shape[0]), dofs[free]] = 1.0
            return W
        w = np.zeros(self.n_dofs)
        np.add.at(w, dofs[free], weights[free] / weights.sum())
        return w

    def force_vectors(self) -> dict:
        """Complex force amplitude per harmonic: ``{k: F_k}`` with ``f(t) = Re sum F_k e^{i k w t}``."""
        out: dict = {}
        for a in self.forces:
            f = a.item
            vec = out.setdefault(f.harmonic, np.zeros(self.n_dofs, dtype=complex))
            vec[a.dof] += f.amplitude * np.exp(1j * f.phase)
        return out

    # -- frozen updates -------------------------------------------------------------------------
    def _replace(self, **changes) -> StructuralModel:
        return dataclasses.replace(self, **changes)

    def with_damping(self, alpha: float = 0.0, beta: float = 0.0, *, modal: Any = None, n_modes: int | None = None) -> StructuralModel:
        """Return a copy with damping (replacing any previous one).

        Rayleigh: ``C = alpha M + beta K`` (sparse). Modal: ``modal`` is a damping ratio (scalar)
        or a sequence of ratios ``zeta_j`` for the first ``n_modes`` modes (default: the length of
        the sequence, or for a scalar 20 modes, fewer if the model has fewer DOFs with mass),
        ``C = M Phi diag(2 zeta_j w_j) Phi^T M`` with mass-normalised modes ``Phi``. That matrix is
        dense, so it is kept as a low-rank part ``C_lowrank = LowRankDamping(U = M Phi, d = 2 zeta
        w)`` next to a zero sparse ``C``; every analysis uses it exactly and at the cost of a
        sparse one (no DOF limit).

        The arguments are kept (``damping_spec``): a later :meth:`with_contact` that
        redistributes the contact nodes' mass recomputes the damping from the new mass matrix (and
        modes), so ``with_damping`` may come before or after ``with_contact``.
        """
        for name, v in (("alpha", alpha), ("beta", beta)):
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise TypeError(f"with_damping: {name} must be a finite non-negative number, got {v!r}")
            if not math.isfinite(v) or v < 0:
                raise ValueError(f"with_damping: {name} must be a finite non-negative number, got {v!r}")
        if modal is None:
            with np.errstate(over="ignore"):
                C = alpha * self.M + beta * self.K
            if C.nnz and not np.all(np.isfinite(C.data)):
                raise ValueError(
                    f"with_damping: alpha={alpha!r}, beta={beta!r} overflow: C = alpha M + beta K has infinite entries"
                )
            return self._replace(C=C, C_lowrank=None, damping_info=f"Rayleigh alpha={alpha:g}, beta={beta:g}",
                                 damping_spec=(("alpha", alpha), ("beta", beta)))._fingerprinted()
        if alpha or beta:
            raise ValueError("with_damping: give either Rayleigh coefficients (alpha, beta) or modal=, not both")
        if isinstance(modal, (str, bytes, bool, np.bool_)):
            raise TypeError(f"with_damping: modal must be a damping ratio or a list of ratios, got {modal!r}")
        try:
            zeta = np.atleast_1d(np.asarray(modal, dtype=float))
        except (TypeError, ValueError) as exc:
            raise TypeError(f"with_damping: modal must be a damping ratio or a list of ratios, got {modal!r}") from exc
        if zeta.ndim != 1 or zeta.size == 0 or not np.all(np.isfinite(zeta)) or np.any(zeta < 0):
            raise ValueError(f"with_damping: modal must be non-negative finite damping ratios, got {modal!r}")
        if n_modes is not None:
            if isinstance(n_modes, (bool, np.bool_)) or not isinstance(n_modes, (int, np.integer)):
                raise TypeError(f"with_damping: n_modes must be an integer >= 1 or None, got {n_modes!r}")
            if not 1 <= n_modes <= self.n_dofs:
                raise ValueError(
                    f"with_damping: n_modes must be in [1, {self.n_dofs}] (the model has {self.n_dofs} DOFs), got {n_modes!r}"
                )
        # a DOF without mass (a contact node whose mass was redistributed) carries no mode
        n_inertial = int(np.count_nonzero(self.M.diagonal() > 0))
        if zeta.size > n_inertial or (n_modes is not None and n_modes > n_inertial):
            extra = f" ({self.n_dofs - n_inertial} of its {self.n_dofs} DOFs have no mass)" if n_inertial < self.n_dofs else ""
            raise ValueError(
                f"with_damping: modal gives {max(zeta.size, n_modes or 0)} modes' damping ratios (modal=, n_modes=) "
                f"but the model has only {n_inertial} modes{extra}; give at most {n_inertial}"
            )
        nm = int(n_modes) if n_modes is not None else (zeta.size if zeta.size > 1 else min(n_inertial, 20))
        if zeta.size == 1:
            zeta = np.full(nm, zeta[0])
        if zeta.size != nm:
            raise ValueError(f"with_damping: modal gives {zeta.size} ratios but n_modes={nm}")
        omega, phi = normal_modes(self.K, self.M, nm, "with_damping")
        lowrank = LowRankDamping(self.M @ phi, 2.0 * zeta * omega, modes=np.asarray(phi), eigenvalues=omega**2)
        ratios = f"{zeta[0]:g}" if np.all(zeta == zeta[0]) else f"{zeta.min():g}..{zeta.max():g}"
        return self._replace(C=sp.csr_matrix((self.n_dofs, self.n_dofs)), C_lowrank=lowrank,
                             damping_info=f"modal zeta={ratios} on {nm} modes",
                             damping_spec=(("modal", tuple(float(z) for z in np.atleast_1d(np.asarray(modal, dtype=float)))),
                                           ("n_modes", n_modes)))._fingerprinted()

    def _damping_fingerprint(self) -> tuple:
        """Sums that change when the damping matrices are replaced: ``sum |C|`` and the low-rank
        part's ``sum d`` and ``sum |U|``."""
        lr = self.C_lowrank
        return (float(abs(self.C).sum()), 0.0 if lr is None else float(np.sum(lr.d)),
                0.0 if lr is None else float(np.sum(np.abs(lr.U))))

    def _damping_spec_fresh(self) -> bool:
        """Whether ``damping_spec``'s fingerprint is that of the damping matrices (they were not
        replaced since :meth:`with_damping`)."""
        return dict(self.damping_spec).get("fingerprint") == self._damping_fingerprint()

    def _fingerprinted(self) -> StructuralModel:
        """This new model (just built by :meth:`with_damping`, or rotated into nodal frames) with
        its damping matrices' fingerprint in ``damping_spec``: a later change of ``C`` by
        ``dataclasses.replace`` makes the spec stale, and :meth:`with_contact` then keeps the
        matrices as they are."""
        spec = tuple(kv for kv in self.damping_spec if kv[0] != "fingerprint")
        object.__setattr__(self, "damping_spec", spec + (("fingerprint", self._damping_fingerprint()),))
        return self

    def with_forcing(self, *forces: HarmonicForce) -> StructuralModel:
        """Return a copy with these harmonic point forces added.

        On a named boundary of a meshed solid (``at=("tip", "u_y")``, or ``at="tip"`` for the
        first component) the amplitude is the *resultant* force, shared by the boundary's nodes
        with the consistent weights ``int N_k ds / int ds`` (a uniform traction of that
        resultant; ``DofMap.group_weights``). The share of supported nodes goes to the support
        (logged).

        A force given in a physical component (``"u_x"``...) on a node whose DOFs are rotated
        (a contact with an inclined or negative normal, ``dofmap.frames``) is rotated into the
        node's DOFs: ``f_q = R^T f`` (one force per nodal-frame component, nonzero parts only,
        so a load along ``n`` given by its x and y parts also loads ``u_t`` with parts that
        cancel). ``at=(point, "u_n")`` names the normal DOF of such a node directly, and
        ``at=(boundary, "u_n")`` (or ``"u_t"``...) the normal DOFs of a boundary whose free nodes
        are all rotated (a resultant along the normals, shared with the boundary's weights).
        """
        if not forces:
            raise ValueError("with_forcing: give at least one HarmonicForce")
        new = list(self.forces)
        dm = self.dofmap
        for f in forces:
            if not isinstance(f, HarmonicForce):
                raise TypeError(f"with_forcing: expected HarmonicForce, got {type(f).__name__}")
            owner = f"with_forcing: HarmonicForce(at={f.at!r})"
            framed = self._frame_group(f.at, owner)
            if framed is not None:
                dofs, weights = framed
                new.extend(Attached(dataclasses.replace(f, at=int(d), amplitude=f.amplitude * float(w)), int(d))
                           for d, w in zip(dofs, weights) if w != 0.0)
                continue
            group = self._group_of(f.at)
            if group is None:
                rotated = self._rotated_point(f.at)
                if rotated is None:
                    new.append(Attached(f, self.dof(f.at, "with_forcing: HarmonicForce")))
                else:
                    new.extend(self._rotated_force(f, *rotated, 1.0, owner))
                continue
            name, c = group
            nodes = np.asarray(dm.groups[name])
            dofs = dm.node_dof[nodes, c]
            weights = np.asarray(dm.group_weights[name], dtype=float)
            if np.any(dofs == -2):
                raise ValueError(f"with_forcing: HarmonicForce(at={f.at!r}): boundary {name!r} is not kept in this "
                                 f"reduced model; attach the force before reducing")
            lost = float(weights[dofs < 0].sum())
            if lost > 0:
                log.info("with_forcing: %.3g %% of the force on %r acts on supported nodes", 100 * lost, name)
            for node, d, w in zip(nodes, dofs, weights):
                if d < 0 or w == 0.0:
                    continue
                if int(node) in dm.frames:
                    new.extend(self._rotated_force(f, int(node), c, float(w), owner))
                else:
                    new.append(Attached(dataclasses.replace(f, at=int(d), amplitude=f.amplitude * float(w)), int(d)))
        return self._replace(forces=tuple(new))

    def _frame_group(self, at: Location, owner: str) -> tuple[np.ndarray, np.ndarray] | None:
        """``(dofs, weights)`` of ``at=(boundary, nodal-frame component)`` (e.g. ``("right", "u_n")``),
        else None; every free node of the boundary must be rotated."""
        dm = self.dofmap
        if not (dm.frames and isinstance(at, tuple) and len(at) == 2 and at[0] in dm.groups
                and at[0] not in dm.locations and at[1] not in dm.components and at[1] not in dm.aliases):
            return None
        name, comp = at
        nodes = np.asarray(dm.groups[name])
        weights = np.asarray(dm.group_weights[name], dtype=float)
        dofs = np.full(nodes.size, -1, dtype=int)
        for j, k in enumerate(nodes):
            row = dm.node_dof[k]
            if np.all(row == -1):
                continue  # a supported node: its share goes to the support
            frame = dm.frames.get(int(k))
            if frame is None or comp not in frame.components:
                raise ValueError(
                    f"{owner}: node {int(k)} of {name!r} has no nodal-frame component {comp!r} (only nodes rotated "
                    f"by a contact with an inclined or negative normal have u_n, u_t...); give a physical component "
                    f"of {list(dm.components)}"
                )
            dofs[j] = row[frame.components.index(comp)]
            if dofs[j] == -2:
                raise ValueError(f"{owner}: boundary {name!r} is not kept in this reduced model; attach the force "
                                 "before reducing")
        lost = float(weights[dofs < 0].sum())
        if lost > 0:
            log.info("with_forcing: %.3g %% of the force on %r acts on supported nodes", 100 * lost, name)
        return dofs[dofs >= 0], weights[dofs >= 0]

    def _rotated_point(self, at: Location) -> tuple[int, int] | None:
        """``(node, physical component)`` if ``at`` names a physical component (or only the point,
        i.e. its first component) of a named point whose DOFs are rotated, else None."""
        dm = self.dofmap
        if not dm.frames:
            return None
        if isinstance(at, str) and at in dm.locations and at not in dm.dof_names:
            loc, comp = at, dm.components[0]
        elif isinstance(at, tuple) and len(at) == 2 and at[0] in dm.locations:
            loc, comp = at
        else:
            return None
        node = int(dm.locations[loc])
        if node not in dm.frames or comp in dm.frames[node].components:
            return None
        return node, dm._component(comp)

    def _rotated_force(self, f: HarmonicForce, node: int, c: int, weight: float, owner: str) -> list:
        """The share ``weight`` of force ``f`` along physical component ``c`` of rotated ``node``, on
        the node's nodal-frame DOFs (``R^T e_c``)."""
        dm = self.dofmap
        dofs = dm.node_dof[node]
        if np.any(dofs < 0):
            raise ValueError(f"{owner}: the DOFs of rotated node {node} are not all kept in this reduced model; "
                             f"attach the force before reducing or keep the node (craig_bampton(keep=...))")
        return _frame_force(f, dm.frames[node].rotation, dofs, c, weight)

    def _group_of(self, at: Location) -> tuple[str, int] | None:
        """``(boundary name, component index)`` if ``at`` names a boundary of a solid, else None."""
        dm = self.dofmap
        if isinstance(at, str) and at in dm.groups and at not in dm.locations and at not in dm.dof_names:
            return at, 0
        if isinstance(at, tuple) and len(at) == 2 and at[0] in dm.groups and at[0] not in dm.locations:
            try:
                return at[0], dm._component(at[1])
            except ValueError as exc:
                raise ValueError(f"at={at!r}: {exc}") from None
        return None

    def without_forcing(self) -> StructuralModel:
        """Return a copy with no forcing (the autonomous system, for nonlinear modes)."""
        return self._replace(forces=())

    def _expand_contact(self, law) -> tuple[list, dict]:
        """``([(law on one DOF, dof)], {node: NodalFrame})`` of a contact law: one law per node of a
        boundary, with its direction resolved to a component and a callable gap evaluated at the
        node. An inclined or negative normal acts on the normal DOF of a nodal frame; the nodes to
        rotate come second (empty for a positive axis)."""
        dm = self.dofmap
        owner = f"with_contact: {type(law).__name__}(at={law.at!r})"
        at = law.at
        if law.direction is not None:
            self._warn_direction_into_body(law, owner)
            comp = self._direction_component(law.direction, owner)
            if comp is None:
                return self._expand_inclined(law, owner)
            if isinstance(at, tuple):
                if dm._component(at[1]) != comp:
                    raise ValueError(f"{owner}: direction={law.direction} selects {dm.displacement[comp]!r} but at= names "
                                     f"component {at[1]!r}; give one of them")
                at = at[0]
            if not isinstance(at, str):
                raise ValueError(f"{owner}: direction= needs a named location (boundary or point), not a DOF index")
            at = (at, dm.components[comp])
        group = self._group_of(at)
        if law.direction is None and isinstance(at, str) and group is not None and len(dm.displacement) > 1:
            # a boundary of a 2-D/3-D solid without a direction: the contact acts along +x, which is
            # rarely what was meant (a stop above a blade tip is along z)
            warnings.warn(f"{owner}: no direction= for boundary {at!r} of a {len(dm.displacement)}-D solid; the contact "
                          f"acts along +x ({dm.displacement[0]!r}). Give the stop's direction, e.g. "
                          f"direction={tuple(1.0 if i == len(dm.displacement) - 1 else 0.0 for i in range(len(dm.displacement)))}, "
                          f"or at=({at!r}, {dm.displacement[0]!r}) to keep +x and silence this", UserWarning, stacklevel=4)
        if group is None:
            dof = self.dof(at, owner)
            nodes, dofs = None, np.array([dof])
        else:
            name, c = group
            nodes = np.asarray(dm.groups[name])
            dofs = dm.node_dof[nodes, c]
            if np.any(dofs == -2):
                raise ValueError(f"{owner}: boundary {name!r} is not kept in this reduced model; attach the contact "
                                 "before reducing (craig_bampton keeps contact DOFs)")
            held = dofs < 0
            if held.all():
                support = dm.constrained_by.get((int(nodes[0]), c), "a support")
                raise ValueError(f"{owner}: every node of {name!r} is constrained ({support!r}) in {dm.components[c]!r}; "
                                 "contact cannot act on a constrained DOF")
            if held.any():
                log.info("with_contact: %d of %d nodes of %r are constrained in %r and get no contact",
                         int(held.sum()), held.size, name, dm.components[c])
            nodes, dofs = nodes[~held], dofs[~held]
            for k in nodes:
                if int(k) in dm.frames:
                    raise ValueError(self._two_normals(owner, int(k), dm.frames[int(k)].normal, dm.axis(int(k), c)))
        gaps = self._contact_gaps(law.gap, nodes, dofs, owner)
        return [(dataclasses.replace(law, at=int(d), gap=float(g), direction=None), int(d)) for d, g in zip(dofs, gaps)], {}

    def _expand_inclined(self, law, owner: str) -> tuple[list, dict]:
        """:meth:`_expand_contact` of a law whose normal is not a positive coordinate axis: each of
        its nodes gets the nodal frame of the normal; the law acts on the normal DOF ``u_n``."""
        dm = self.dofmap
        direction = law.direction
        if self.fe is None:
            raise ValueError(f"{owner}: direction={direction} is not along +x, +y or +z: the contact acts on the normal "
                             "DOF of a nodal rotation, which is done on the meshed solid itself; attach the contact "
                             "before reducing (craig_bampton keeps contact DOFs)")
        at = law.at
        if isinstance(at, tuple):
            raise ValueError(f"{owner}: direction={direction} is not along +x, +y or +z: the contact acts on the normal "
                             f"DOF 'u_n' of rotated nodes, not on a component; give at= a boundary or point name only "
                             f"(at={at[0]!r})")
        if not isinstance(at, str):
            raise ValueError(f"{owner}: direction= needs a named location (boundary or point), not a DOF index")
        if at in dm.groups and at not in dm.locations:
            name, nodes = at, np.asarray(dm.groups[at], dtype=int)
        elif at in dm.locations:
            name, nodes = None, np.array([int(dm.locations[at])])
        else:
            self.dof(at, owner)  # raises: unknown location
            raise AssertionError("unreachable")  # pragma: no cover
        frame = nodal_frame(direction)
        node_dof = dm.node_dof[nodes]  # (k, dim)
        held = node_dof < 0
        every = held.all(axis=1)
        partial = held.any(axis=1) & ~every
        if partial.any():
            k = int(nodes[np.argmax(partial)])
            c = int(np.argmax(dm.node_dof[k] < 0))
            support = dm.constrained_by.get((k, c), "a support")
            free = [dm.components[j] for j in range(dm.node_dof.shape[1]) if dm.node_dof[k, j] >= 0]
            raise ValueError(
                f"{owner}: node {k} at {_vector(dm.node_coordinates[:, k])} is constrained in {dm.components[c]!r} by "
                f"{support} but free in {free}: the contact normal {_vector(frame.normal)} rotates the node's DOFs, "
                "which would mix constrained and free DOFs; constrain that node fully (clamped=...) or not at all"
            )
        if every.all():
            support = dm.constrained_by.get((int(nodes[0]), 0), "a support")
            where = f"every node of {name!r} is" if name is not None else f"{at!r} is"
            raise ValueError(f"{owner}: {where} constrained ({support!r}); contact cannot act on a constrained DOF")
        if every.any():
            log.info("with_contact: %d of %d nodes of %r are constrained and get no contact", int(every.sum()),
                     every.size, name)
        nodes = nodes[~every]
        dofs = dm.node_dof[nodes, frame.slot]
        gaps = self._contact_gaps(law.gap, nodes, dofs, owner)
        pairs = [(dataclasses.replace(law, at=int(d), gap=float(g), direction=None), int(d)) for d, g in zip(dofs, gaps)]
        return pairs, {int(k): frame for k in nodes}

    def _two_normals(self, owner: str, node: int, old, new) -> str:
        X = self.dofmap.node_coordinates
        where = f" at {_vector(X[:, node])}" if X is not None else ""
        return (f"{owner}: node {node}{where} would get two contact normals, {_vector(old)} and {_vector(new)}: a node "
                "with an inclined or negative normal has its DOFs rotated into one nodal frame (u_n along the normal), "
                "so all contacts of that node must share that normal (or act on its tangent DOF, at=(point, 'u_t')); "
                "give the stops the same direction or put them on different nodes")

    def _warn_direction_into_body(self, law, owner: str) -> None:
        """A stop along ``direction`` from a boundary whose outward normal points the other way sits
        inside the material (``direction`` is the way the structure moves towards the stop)."""
        name = law.at[0] if isinstance(law.at, tuple) else law.at
        mesh = getattr(self.fe, "mesh", None)
        if not isinstance(name, str) or mesh is None or self.fe.kind != "solid":
            return
        n = outward_normal(mesh, name)
        d = np.asarray(law.direction, dtype=float)
        if n is None or d.shape != n.shape or not np.all(np.isfinite(d)) or not np.any(d):
            return
        cos = float(d @ n / np.linalg.norm(d))
        if cos < -0.5:
            def show(v):
                return "(" + ", ".join(f"{float(x) + 0.0:.4g}" for x in v) + ")"

            warnings.warn(f"{owner}: direction={show(d)} points into the body at boundary {name!r} (its outward "
                          f"normal is {show(n)}), so the stop sits inside the material; give the direction in which "
                          f"{name!r} moves towards the stop, e.g. direction={show(-d)}", UserWarning, stacklevel=4)

    def _direction_component(self, direction: tuple, owner: str) -> int | None:
        """Component of a contact ``direction`` along a positive coordinate axis, or None for an
        inclined or negative normal (a nodal rotation, :meth:`_expand_inclined`)."""
        dm = self.dofmap
        if not dm.displacement:
            raise ValueError(f"{owner}: direction= needs a meshed solid (femodes.solid); for bars, beams and discrete "
                             "models give the DOF with at=(name, component)")
        dim = len(dm.displacement)
        if len(direction) != dim:
            raise ValueError(f"{owner}: direction={direction} has {len(direction)} components, this model is {dim}-D "
                             f"(give {dim} components, e.g. {tuple([1.0] + [0.0] * (dim - 1))})")
        d = np.asarray(direction, dtype=float)
        if not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
            raise ValueError(f"{owner}: direction={direction} must be a finite non-zero vector")
        axis = int(np.argmax(np.abs(d)))
        if d[axis] >= 1.0 - AXIS_TOL:
            return dm._component(dm.displacement[axis])
        return None

    def _contact_gaps(self, gap, nodes, dofs, owner: str) -> np.ndarray:
        """The gap of each contact DOF: the number, or the callable at the nodes' coordinates."""
        n = len(dofs)
        if not callable(gap):
            return np.full(n, float(gap))
        X = self.dofmap.node_coordinates
        if X is None:
            raise ValueError(f"{owner}: a callable gap needs a meshed model with node coordinates; give a number")
        X = np.asarray(X, dtype=float)
        if nodes is None:  # a named point or a (point, component) pair
            loc = self.dofmap.node_dof
            nodes = np.array([int(np.argwhere(loc == dofs[0])[0, 0])])
        x = X[:, nodes]
        g = None
        try:
            with np.errstate(all="ignore"):
                v = np.asarray(gap(x), dtype=float)
            if v.shape in ((n,), (1, n)):
                g = v.reshape(n)
        except Exception:  # noqa: BLE001 - a pointwise function may fail on arrays; it is called per node below
            g = None
        if g is None:
            try:
                g = np.array([float(gap(x[:, k])) for k in range(n)])
            except Exception as exc:  # noqa: BLE001 - report any error of the user's function
                raise ValueError(f"{owner}: the gap function failed at node {tuple(x[:, 0])}: {exc!r}; it must map "
                                 "coordinates of shape (dim,) or (dim, n) to gaps") from exc
        bad = np.flatnonzero(~np.isfinite(g) | (g < 0))
        if bad.size:
            k = int(bad[0])
            raise ValueError(f"{owner}: the gap function gives {g[k]!r} at node {tuple(float(v) for v in x[:, k])}; "
                             "gaps must be finite and >= 0")
        return g

    def with_contact(self, *laws, contact_mass=None) -> StructuralModel:
        """Return a copy with these contact laws (UnilateralContact or PenaltyContact) added.

        A law on a named boundary of a meshed solid (``at="right"`` with ``direction=(1.0, 0.0)``,
        or ``at=("right", "u_x")``) becomes one law per node of that boundary (every Lagrange
        node: the P2 mid-side nodes carry contact too, so that no part of the discrete boundary
        can pass through the obstacle unchecked), on the component along ``direction``, with its
        gap evaluated at the node when ``gap`` is callable (``at="right"`` without a direction
        uses the first component, ``u_x``). Nodes where that component is supported are skipped
        (logged count). ``model.contacts`` holds one ``Attached(law, dof)`` per contact DOF, and
        every law acts on one model DOF with ``g_N = gap - q_dof``.

        Inclined or negative normals (``direction=(0.8, 0.6)``, ``(-1.0, 0.0)``): the DOFs of each
        contact node are rotated into a nodal frame (:func:`nodal_frame`, a proper rotation ``R``
        whose column ``slot`` is the normal ``n``; ``slot`` is the axis nearest to ``n``), so that
        the model DOF in that slot is ``u_n = n . u`` and the law acts on it. With the sparse
        orthogonal ``T`` of these rotations (identity elsewhere) the physical displacement is
        ``u = T q``: ``K``, ``M``, ``C`` (and a modal low-rank part) become ``T^T A T`` and the
        forces already attached ``T^T f``, before the contact mass is redistributed, so the
        redistribution acts on ``u_n``. ``model.frame`` holds ``T`` (composed over calls) and
        ``dofmap.frames`` the rotation of each node: :meth:`full_field` (hence every mesh output)
        is physical, :meth:`with_forcing` rotates forces given in ``u_x, u_y(, u_z)``, and the
        rotated DOFs are named ``"u_n"``, ``"u_t"`` (2-D) or ``"u_t1"``, ``"u_t2"`` (3-D)
        (``at=(point, "u_n")``; ``at=(point, "u_x")`` of a rotated node is an error). A node
        constrained in some components only, a node that would carry two different normals,
        and an inclined normal on a reduced model (rotate before ``craig_bampton``) are errors;
        nodes supported in every component are skipped. Positive-axis directions rotate nothing
        (``frame`` stays None).

        Parameters
        ----------
        contact_mass : RedistributeMass or ConsistentMass, optional
            What happens to the mass of each new contact DOF. ``fm.RedistributeMass()`` moves it
            to the neighbours (zero mass at the contact node, total mass and centre of mass
            conserved; Khenous, Laborde & Renard 2008; for solids see
            :func:`femodes.fe.redistribution.redistribute_surface_mass`); ``fm.ConsistentMass()``
            keeps it. Default: ``RedistributeMass()`` for complementarity contacts of FE models,
            where a massful contact node makes the nonsmooth modes ill-posed under mesh
            refinement (Thorin & Legrand 2018), ``ConsistentMass()`` for penalty contacts and
            discrete models. For a rotated normal ``n`` the redistribution runs in the frame
            where ``n`` is a coordinate axis (every node not rotated otherwise is turned by the
            same ``R``, coordinates by ``R^T``): there it is the computation of a positive-axis
            normal, so a rotated model is the rotation of the axis-aligned one. Nodes with
            other nodal frames, partial supports or massless DOFs near the contact keep their
            own DOFs in that frame (mass conservation along ``n`` is then approximate there).
        """
        if contact_mass is not None and not callable(getattr(contact_mass, "apply", None)):
            raise TypeError(f"with_contact: contact_mass must be fm.RedistributeMass() or fm.ConsistentMass(), "
                            f"got {contact_mass!r}")
        if not laws:
            raise ValueError("with_contact: give at least one UnilateralContact or PenaltyContact")
        dm = self.dofmap
        node_of, comp_of = self._dof_nodes()
        new = list(self.contacts)
        used = {a.dof for a in new}
        frames = dict(dm.frames)
        pending: dict = {}  # nodes rotated by this call
        normals = {}  # node -> normal of its first contact
        for a in self.contacts:
            k = int(node_of[a.dof])
            if k >= 0:
                normals.setdefault(k, dm.axis(k, int(comp_of[a.dof])))
        for law in laws:
            if not isinstance(law, CONTACT_LAWS):
                raise TypeError(
                    f"with_contact: expected UnilateralContact or PenaltyContact, got {type(law).__name__}"
                    + (" (use with_nonlinearity for smooth springs)" if isinstance(law, SMOOTH_LAWS) else "")
                )
            owner = f"with_contact: {type(law).__name__}(at={law.at!r})"
            if law.direction is None and not callable(law.gap) and self._group_of(law.at) is None:
                pairs, rot = [(law, self.dof(law.at, f"with_contact: {type(law).__name__}"))], {}
            else:
                pairs, rot = self._expand_contact(law)
            for k, frame in rot.items():
                old = frames.get(k)
                if old is not None:
                    if not _same_normal(old, frame):
                        raise ValueError(self._two_normals(owner, k, old.normal, frame.normal))
                elif k in normals:
                    raise ValueError(self._two_normals(owner, k, normals[k], frame.normal))
                else:
                    pending[k] = frames[k] = frame
            for item, dof in pairs:
                k, c = int(node_of[dof]), int(comp_of[dof])
                if k in pending and k not in rot:  # a component of a node this call rotates
                    raise ValueError(self._two_normals(owner, k, pending[k].normal, dm.axis(k, c)))
                if dof in used:
                    what = f"{pending[k].components[c]!r} of node {k}" if k in pending else repr(dm.label(dof))
                    raise ValueError(f"with_contact: {type(law).__name__}(at={law.at!r}): DOF {what} already has a "
                                     "contact law (one contact per DOF)")
                used.add(dof)
                new.append(Attached(item, dof))
                if k >= 0:
                    normals.setdefault(k, frames[k].rotation[:, c] if k in frames else dm.axis(k, c))
        base = self._rotated(pending, node_of, comp_of) if pending else self
        M = base.M
        reports = list(self.mass_redistribution)
        batches: dict = {}
        for a in new[len(self.contacts):]:
            strategy = contact_mass
            if strategy is None:
                auto = self.fe is not None and isinstance(a.item, UnilateralContact)
                strategy = RedistributeMass() if auto else ConsistentMass()
            k = int(node_of[a.dof])
            frame = base.dofmap.frames.get(k) if k >= 0 else None
            fkey = None if frame is None else (frame.slot,) + tuple(np.round(frame.normal, 12))
            skey = id(strategy) if contact_mass is not None else type(strategy)
            batches.setdefault((skey, fkey), (strategy, frame, []))[2].append(a.dof)
        for strategy, frame, dofs in batches.values():
            if frame is None:
                M, reps = _redistribute(strategy, self.fe, M, dofs)
            else:
                M, reps = base._redistribute_in_frame(strategy, M, dofs, frame)
            reports.extend(reps)
        if any(isinstance(a.item, UnilateralContact) for a in new) and any(isinstance(a.item, PenaltyContact) for a in new):
            log.info("model mixes complementarity and penalty contacts")
        out = base._replace(contacts=tuple(new), M=M, mass_redistribution=tuple(reports))
        spec = dict(self.damping_spec)
        spec.pop("fingerprint", None)
        if spec and M is not base.M and not self._damping_spec_fresh():
            log.warning("with_contact: the damping matrices changed after with_damping(%s) (dataclasses.replace?): "
                        "kept as they are, not recomputed for the redistributed mass; call with_damping again",
                        ", ".join(f"{k}={v}" for k, v in spec.items()))
            out = out._replace(damping_spec=())
        elif spec and M is not base.M:
            # damping given before the contact: recomputed from the redistributed mass (C = alpha M +
            # beta K, or the new modes), which the contact node's zero mass row then also zeroes in C
            log.info("with_contact: damping (%s) recomputed for the redistributed mass", self.damping_info)
            if "modal" in spec:
                z = spec["modal"]
                spec["modal"] = z[0] if len(z) == 1 else list(z)
            out = out.with_damping(**spec)
        return out

    def _dof_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """Node and component slot of every model DOF (node ``-1`` for DOFs on no node)."""
        nd = self.dofmap.node_dof
        node_of = np.full(self.n_dofs, -1, dtype=int)
        comp_of = np.zeros(self.n_dofs, dtype=int)
        if nd.size:
            k, c = np.nonzero(nd >= 0)
            node_of[nd[k, c]] = k
            comp_of[nd[k, c]] = c
        return node_of, comp_of

    def _rotated(self, pending: Mapping[int, NodalFrame], node_of: np.ndarray, comp_of: np.ndarray) -> StructuralModel:
        """This model with the DOFs of the nodes ``pending`` rotated into their nodal frames:
        ``q = T^T q_old``, matrices ``T^T A T``, forces ``T^T f``, ``frame`` composed, labels."""
        dm = self.dofmap
        for a in self.nonlinearities:
            k = int(node_of[a.dof])
            if k in pending:
                raise ValueError(
                    f"with_contact: {type(a.item).__name__}(at={a.item.at!r}) acts on DOF {dm.label(a.dof)!r} of node {k}, "
                    f"whose DOFs the contact normal {_vector(pending[k].normal)} rotates; add the contact first and "
                    f"attach the nonlinearity to the rotated DOFs (at=(point, 'u_n'), ...)"
                )
        nodes = sorted(pending)
        T = _block_rotation(dm.node_dof, self.n_dofs, nodes, [pending[k].rotation for k in nodes])

        def rotate(A):
            B = (T.T @ A @ T).tocsr()
            return (0.5 * (B + B.T)).tocsr()

        lr = self.C_lowrank
        if lr is not None:
            lr = LowRankDamping(T.T @ lr.U, lr.d, modes=None if lr.modes is None else T.T @ lr.modes,
                                eigenvalues=lr.eigenvalues)
        forces = []
        for a in self.forces:
            k = int(node_of[a.dof])
            if k in pending:
                forces.extend(_frame_force(a.item, pending[k].rotation, dm.node_dof[k], int(comp_of[a.dof]), 1.0))
            else:
                forces.append(a)
        labels = list(dm.labels)
        for k in nodes:
            names = pending[k].components
            for j, d in enumerate(dm.node_dof[k]):
                old, comp = labels[d], dm.components[j]
                if old.startswith(comp + "@"):
                    lab = names[j] + old[len(comp):]
                elif old.endswith("." + comp):
                    lab = old[: -len(comp)] + names[j]
                else:
                    lab = f"{old} {names[j]}"
                labels[d] = f"{lab} (rotated node {k})"
        dofmap = dataclasses.replace(dm, frames={**dm.frames, **pending}, labels=tuple(labels))
        frame = T if self.frame is None else (self.frame @ T).tocsr()
        log.info("with_contact: %d nodes rotated into the nodal frames of their contact normals", len(nodes))
        out = self._replace(M=rotate(self.M), K=rotate(self.K), C=rotate(self.C) if self.C.nnz else self.C,
                            C_lowrank=lr, forces=tuple(forces), dofmap=dofmap, frame=frame)
        # the spec's matrices in the new frame: its fingerprint follows them (a stale one stays stale)
        return out._fingerprinted() if out.damping_spec and self._damping_spec_fresh() else out

    def _redistribute_in_frame(self, strategy, M, dofs, frame: NodalFrame):
        """Contact mass ``strategy`` on the normal DOFs ``dofs`` of nodes with nodal frame
        ``frame``, run where its normal is a coordinate axis: ``q = P w`` turns every node that is
        fully free, not rotated and not massless by ``R`` (``P`` block diagonal), and the
        coordinates by ``R^T``; the result comes back as ``P M_w P^T``."""
        dm = self.dofmap
        nd = dm.node_dof
        diag = M.diagonal()
        turn = np.all(nd >= 0, axis=1) & np.all(diag[np.maximum(nd, 0)] > 0, axis=1)
        turn[np.fromiter(dm.frames, dtype=int, count=len(dm.frames))] = False
        nodes = np.flatnonzero(turn)
        R = frame.rotation
        P = _block_rotation(nd, self.n_dofs, nodes, np.broadcast_to(R, (len(nodes),) + R.shape))
        Mw = (P.T @ M @ P).tocsr()
        Mw = (0.5 * (Mw + Mw.T)).tocsr()
        X = np.asarray(self.fe.node_coordinates, dtype=float)
        fe = dataclasses.replace(self.fe, node_coordinates=R.T @ X)
        Mw, reps = _redistribute(strategy, fe, Mw, dofs)
        if not reps:
            return M, reps
        out = (P @ Mw @ P.T).tocsr()
        return (0.5 * (out + out.T)).tocsr(), reps

    def with_nonlinearity(self, *laws) -> StructuralModel:
        """Return a copy with these smooth nonlinear laws (e.g. CubicSpring) added."""
        if not laws:
            raise ValueError("with_nonlinearity: give at least one law, e.g. CubicSpring(at=0, k3=1.0)")
        new = list(self.nonlinearities)
        for law in laws:
            if not isinstance(law, SMOOTH_LAWS):
                raise TypeError(
                    f"with_nonlinearity: expected CubicSpring, got {type(law).__name__}"
                    + (" (use with_contact for contact laws)" if isinstance(law, CONTACT_LAWS) else "")
                )
            new.append(Attached(law, self.dof(law.at, "with_nonlinearity: CubicSpring")))
        return self._replace(nonlinearities=tuple(new))

    # -- fields ---------------------------------------------------------------------------------
    def nonlinear_dofs(self) -> np.ndarray:
        """Sorted unique DOFs that carry contact or nonlinear laws."""
        d = [a.dof for a in self.contacts] + [a.dof for a in self.nonlinearities]
        return np.unique(np.asarray(d, dtype=int))

    def expand(self, q: np.ndarray) -> np.ndarray:
        """Model DOFs -> model DOFs (identity; a reduced model maps to its parent's DOFs)."""
        return np.asarray(q)

    @property
    def mesh_owner(self) -> StructuralModel | None:
        """The model that owns the FE mesh: this one for FE models, None for discrete ones
        (a reduced model answers with its parent's owner)."""
        return self if self.fe is not None else None

    def to_owner(self, q: np.ndarray) -> np.ndarray:
        """Coordinates ``(..., n_dofs)`` on the DOFs of :attr:`mesh_owner` (identity here; a
        reduced model expands through every reduction level). These are the owner's model DOFs,
        nodal-frame components at rotated nodes; :meth:`full_field` gives the physical field."""
        return np.asarray(q)

    def fe_dof(self, dof: int) -> int | None:
        """Index in the full FE field of a DOF of this model; None for a discrete model (and for
        the modal coordinates of a reduced one). A DOF of a rotated node (``dofmap.frames``)
        occupies the FE DOF of its component slot; its physical direction is
        ``dofmap.axis(node, slot)``."""
        return None if self.fe is None else int(np.asarray(self.fe.free)[dof])

    def full_field(self, q: np.ndarray) -> np.ndarray:
        """FE field with constrained DOFs set to zero, ``(..., n_fe_dofs)``; identity for discrete models.

        The field is physical: the DOFs of rotated nodes (:attr:`frame`) are turned back into
        their components along x, y(, z).
        """
        q = np.asarray(q)
        if self.fe is None:
            return q
        if self.frame is not None:
            flat = q.reshape(-1, q.shape[-1])
            q = np.asarray(self.frame @ flat.T).T.reshape(q.shape)
        out = np.zeros(q.shape[:-1] + (self.fe.n_full,), dtype=q.dtype)
        out[..., self.fe.free] = q
        return out

    def __repr__(self) -> str:
        kind = "discrete" if self.fe is None else self.fe.kind
        return (
            f"StructuralModel({kind}, n_dofs={self.n_dofs}, damping={self.damping_info}, forces={len(self.forces)}, "
            f"contacts={len(self.contacts)}, nonlinearities={len(self.nonlinearities)})"
        )
