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
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
import scipy.sparse as sp

from .eigen import normal_modes
from .fe.redistribution import ConsistentMass, RedistributeMass
from .laws import CubicSpring, Location, PenaltyContact, UnilateralContact, check_location

__all__ = ["DofMap", "HarmonicForce", "Attached", "StructuralModel", "LowRankDamping", "as_sparse_matrix", "low_rank_solver"]

log = logging.getLogger(__name__)

CONTACT_LAWS = (UnilateralContact, PenaltyContact)
SMOOTH_LAWS = (CubicSpring,)


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

    @classmethod
    def discrete(cls, n_dofs: int, dof_names: Sequence[str] | None = None) -> "DofMap":
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

    def restrict(self, kept: np.ndarray) -> "DofMap":
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

    def extended(self, extra_labels: Sequence[str]) -> "DofMap":
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

    def restrict(self, rows) -> "LowRankDamping":
        """The part on a subset (or slice) of the DOFs: ``U[rows] diag(d) U[rows]^T``."""
        return LowRankDamping(self.U[rows], self.d)

    def project(self, T: np.ndarray) -> "LowRankDamping":
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
        """True if the damping (sparse or low-rank part) is not zero."""
        return bool(self.C.nnz) or (self.C_lowrank is not None and bool(np.any(self.C_lowrank.d)))

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

    def force_vectors(self) -> dict:
        """Complex force amplitude per harmonic: ``{k: F_k}`` with ``f(t) = Re sum F_k e^{i k w t}``."""
        out: dict = {}
        for a in self.forces:
            f = a.item
            vec = out.setdefault(f.harmonic, np.zeros(self.n_dofs, dtype=complex))
            vec[a.dof] += f.amplitude * np.exp(1j * f.phase)
        return out

    # -- frozen updates -------------------------------------------------------------------------
    def _replace(self, **changes) -> "StructuralModel":
        return dataclasses.replace(self, **changes)

    def with_damping(self, alpha: float = 0.0, beta: float = 0.0, *, modal: Any = None, n_modes: int | None = None) -> "StructuralModel":
        """Return a copy with damping (replacing any previous one).

        Rayleigh: ``C = alpha M + beta K`` (sparse). Modal: ``modal`` is a damping ratio (scalar)
        or a sequence of ratios ``zeta_j`` for the first ``n_modes`` modes (default: the length of
        the sequence, or 20 modes for a scalar), ``C = M Phi diag(2 zeta_j w_j) Phi^T M`` with
        mass-normalised modes ``Phi``. That matrix is dense, so it is kept as a low-rank part
        ``C_lowrank = LowRankDamping(U = M Phi, d = 2 zeta w)`` next to a zero sparse ``C``; every
        analysis uses it exactly and at the cost of a sparse one (no DOF limit).
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
            return self._replace(C=C, C_lowrank=None, damping_info=f"Rayleigh alpha={alpha:g}, beta={beta:g}")
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
        if zeta.size > self.n_dofs:
            raise ValueError(
                f"with_damping: modal gives {zeta.size} damping ratios but the model has only {self.n_dofs} modes"
            )
        nm = int(n_modes) if n_modes is not None else (zeta.size if zeta.size > 1 else min(self.n_dofs, 20))
        if zeta.size == 1:
            zeta = np.full(nm, zeta[0])
        if zeta.size != nm:
            raise ValueError(f"with_damping: modal gives {zeta.size} ratios but n_modes={nm}")
        omega, phi = normal_modes(self.K, self.M, nm, "with_damping")
        lowrank = LowRankDamping(self.M @ phi, 2.0 * zeta * omega, modes=np.asarray(phi), eigenvalues=omega**2)
        ratios = f"{zeta[0]:g}" if np.all(zeta == zeta[0]) else f"{zeta.min():g}..{zeta.max():g}"
        return self._replace(C=sp.csr_matrix((self.n_dofs, self.n_dofs)), C_lowrank=lowrank,
                             damping_info=f"modal zeta={ratios} on {nm} modes")

    def with_forcing(self, *forces: HarmonicForce) -> "StructuralModel":
        """Return a copy with these harmonic point forces added.

        On a named boundary of a meshed solid (``at=("tip", "u_y")``, or ``at="tip"`` for the
        first component) the amplitude is the *resultant* force, shared by the boundary's nodes
        with the consistent weights ``int N_k ds / int ds`` (a uniform traction of that
        resultant; ``DofMap.group_weights``). The share of supported nodes goes to the support
        (logged).
        """
        if not forces:
            raise ValueError("with_forcing: give at least one HarmonicForce")
        new = list(self.forces)
        for f in forces:
            if not isinstance(f, HarmonicForce):
                raise TypeError(f"with_forcing: expected HarmonicForce, got {type(f).__name__}")
            group = self._group_of(f.at)
            if group is None:
                new.append(Attached(f, self.dof(f.at, "with_forcing: HarmonicForce")))
                continue
            name, c = group
            dofs = self.dofmap.node_dof[self.dofmap.groups[name], c]
            weights = np.asarray(self.dofmap.group_weights[name], dtype=float)
            if np.any(dofs == -2):
                raise ValueError(f"with_forcing: HarmonicForce(at={f.at!r}): boundary {name!r} is not kept in this "
                                 f"reduced model; attach the force before reducing")
            lost = float(weights[dofs < 0].sum())
            if lost > 0:
                log.info("with_forcing: %.3g %% of the force on %r acts on supported nodes", 100 * lost, name)
            for d, w in zip(dofs, weights):
                if d >= 0 and w != 0.0:
                    new.append(Attached(dataclasses.replace(f, at=int(d), amplitude=f.amplitude * float(w)), int(d)))
        return self._replace(forces=tuple(new))

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

    def without_forcing(self) -> "StructuralModel":
        """Return a copy with no forcing (the autonomous system, for nonlinear modes)."""
        return self._replace(forces=())

    def _expand_contact(self, law) -> list:
        """``[(law on one DOF, dof)]`` of a contact law: one per node of a boundary, with its
        direction resolved to a component and a callable gap evaluated at the node."""
        dm = self.dofmap
        owner = f"with_contact: {type(law).__name__}(at={law.at!r})"
        at = law.at
        if law.direction is not None:
            comp = self._direction_component(law.direction, owner)
            if isinstance(at, tuple):
                if dm._component(at[1]) != comp:
                    raise ValueError(f"{owner}: direction={law.direction} selects {dm.displacement[comp]!r} but at= names "
                                     f"component {at[1]!r}; give one of them")
                at = at[0]
            if not isinstance(at, str):
                raise ValueError(f"{owner}: direction= needs a named location (boundary or point), not a DOF index")
            at = (at, dm.components[comp])
        group = self._group_of(at)
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
        gaps = self._contact_gaps(law.gap, nodes, dofs, owner)
        return [(dataclasses.replace(law, at=int(d), gap=float(g), direction=None), int(d)) for d, g in zip(dofs, gaps)]

    def _direction_component(self, direction: tuple, owner: str) -> int:
        dm = self.dofmap
        if not dm.displacement:
            raise ValueError(f"{owner}: direction= needs a meshed solid (femodes.solid); for bars, beams and discrete "
                             "models give the DOF with at=(name, component)")
        dim = len(dm.displacement)
        if len(direction) != dim:
            raise ValueError(f"{owner}: direction={direction} has {len(direction)} components, this model is {dim}-D "
                             f"(give {dim} components, e.g. {tuple([1.0] + [0.0] * (dim - 1))})")
        d = np.asarray(direction)
        axis = int(np.argmax(np.abs(d)))
        if abs(d[axis]) < 1.0 - 1e-12 or d[axis] < 0:
            raise ValueError(
                f"{owner}: direction={direction} is not along +x, +y or +z: contacts act on one displacement DOF "
                f"along its positive axis (g_N = gap - u), and inclined or negative normals (a nodal rotation of "
                f"the DOFs) are not implemented yet; orient the mesh so that the obstacle lies along a positive axis"
            )
        return dm._component(dm.displacement[axis])

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

    def with_contact(self, *laws, contact_mass=None) -> "StructuralModel":
        """Return a copy with these contact laws (UnilateralContact or PenaltyContact) added.

        A law on a named boundary of a meshed solid (``at="right"`` with ``direction=(1.0, 0.0)``,
        or ``at=("right", "u_x")``) becomes one law per node of that boundary (every Lagrange
        node: the P2 mid-side nodes carry contact too, so that no part of the discrete boundary
        can pass through the obstacle unchecked), on the component along ``direction``, with its
        gap evaluated at the node when ``gap`` is callable (``at="right"`` without a direction
        uses the first component, ``u_x``). Nodes where that component is supported are skipped
        (logged count); ``direction`` must be along +x, +y or +z (inclined or negative normals
        would need a rotation of the nodal DOFs, not implemented: ValueError). ``model.contacts`` holds one
        ``Attached(law, dof)`` per contact DOF.

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
            discrete models.
        """
        if contact_mass is not None and not callable(getattr(contact_mass, "apply", None)):
            raise TypeError(f"with_contact: contact_mass must be fm.RedistributeMass() or fm.ConsistentMass(), "
                            f"got {contact_mass!r}")
        if not laws:
            raise ValueError("with_contact: give at least one UnilateralContact or PenaltyContact")
        new = list(self.contacts)
        used = {a.dof for a in new}
        for law in laws:
            if not isinstance(law, CONTACT_LAWS):
                raise TypeError(
                    f"with_contact: expected UnilateralContact or PenaltyContact, got {type(law).__name__}"
                    + (" (use with_nonlinearity for smooth springs)" if isinstance(law, SMOOTH_LAWS) else "")
                )
            if law.direction is None and not callable(law.gap) and self._group_of(law.at) is None:
                pairs = [(law, self.dof(law.at, f"with_contact: {type(law).__name__}"))]
            else:
                pairs = self._expand_contact(law)
            for item, dof in pairs:
                if dof in used:
                    raise ValueError(
                        f"with_contact: {type(law).__name__}(at={law.at!r}): DOF {self.dofmap.label(dof)!r} already has a "
                        "contact law (one contact per DOF)"
                    )
                used.add(dof)
                new.append(Attached(item, dof))
        M = self.M
        reports = list(self.mass_redistribution)
        batches: dict = {}
        for a in new[len(self.contacts):]:
            strategy = contact_mass
            if strategy is None:
                auto = self.fe is not None and isinstance(a.item, UnilateralContact)
                strategy = RedistributeMass() if auto else ConsistentMass()
            batches.setdefault(id(strategy) if contact_mass is not None else type(strategy), (strategy, []))[1].append(a.dof)
        for strategy, dofs in batches.values():
            if callable(getattr(strategy, "apply_all", None)):
                M, reps = strategy.apply_all(self.fe, M, dofs)
                reports.extend(reps)
                continue
            for dof in dofs:
                M, rep = strategy.apply(self.fe, M, dof)
                if rep is not None:
                    reports.append(rep)
        if any(isinstance(a.item, UnilateralContact) for a in new) and any(isinstance(a.item, PenaltyContact) for a in new):
            log.info("model mixes complementarity and penalty contacts")
        return self._replace(contacts=tuple(new), M=M, mass_redistribution=tuple(reports))

    def with_nonlinearity(self, *laws) -> "StructuralModel":
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
    def mesh_owner(self) -> "StructuralModel | None":
        """The model that owns the FE mesh: this one for FE models, None for discrete ones
        (a reduced model answers with its parent's owner)."""
        return self if self.fe is not None else None

    def to_owner(self, q: np.ndarray) -> np.ndarray:
        """Coordinates ``(..., n_dofs)`` on the DOFs of :attr:`mesh_owner` (identity here; a
        reduced model expands through every reduction level)."""
        return np.asarray(q)

    def fe_dof(self, dof: int) -> int | None:
        """Index in the full FE field of a DOF of this model; None for a discrete model (and for
        the modal coordinates of a reduced one)."""
        return None if self.fe is None else int(np.asarray(self.fe.free)[dof])

    def full_field(self, q: np.ndarray) -> np.ndarray:
        """FE field with constrained DOFs set to zero, ``(..., n_fe_dofs)``; identity for discrete models."""
        q = np.asarray(q)
        if self.fe is None:
            return q
        out = np.zeros(q.shape[:-1] + (self.fe.n_full,), dtype=q.dtype)
        out[..., self.fe.free] = q
        return out

    def __repr__(self) -> str:
        kind = "discrete" if self.fe is None else self.fe.kind
        return (
            f"StructuralModel({kind}, n_dofs={self.n_dofs}, damping={self.damping_info}, forces={len(self.forces)}, "
            f"contacts={len(self.contacts)}, nonlinearities={len(self.nonlinearities)})"
        )
