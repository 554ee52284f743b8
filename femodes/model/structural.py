"""The model: :class:`StructuralModel`, ``M q'' + C q' + K q + f_nl(q) = f(t) - w_c p`` on the free
DOFs, with its declarations. A frozen value: every ``with_*`` returns a new model; the work is done
by the modules of :mod:`femodes.model` (damping, forcing, contact, probes, checks) and by its two
collaborators: ``model.damping`` (:class:`Damping`) and ``model.mesh_map`` (:class:`MeshMap`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import scipy.sparse as sp

from ..laws import Location
from ..solvers.checks import entry_point, named_by
from .checks import check_fields
from .contact import add_contacts
from .damping import Damping, LowRankDamping, damped
from .declarations import HarmonicForce, bind_nonlinearities
from .dofs import DofMap, deprecated_owner
from .forcing import bind_forces
from .mesh_map import MeshMap
from .deprecations import moved_attribute

__all__ = ["StructuralModel"]


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
        ``C + U diag(d) U^T`` (see :class:`LowRankDamping`). Use ``damping.apply`` for
        products and ``damping.matrix()`` (or :meth:`damping_matrix`) for the assembled matrix
        (small models, checks); ``C`` alone is only the sparse part (zero for modal damping).
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
        check_fields(self)

    @property
    def n_dofs(self) -> int:
        return self.M.shape[0]

    #: False: a Craig-Bampton model (:class:`femodes.ReducedModel`) says True
    is_reduced: ClassVar[bool] = False

    @property
    def damping(self) -> Damping:
        """The damping matrix ``C + U diag(d) U^T`` as one operator (:class:`Damping`):
        ``damping.nonzero``, ``damping.apply(V)``, ``damping.matrix()``."""
        return Damping(self.C, self.C_lowrank)

    def damping_matrix(self) -> sp.csr_matrix:
        """The assembled damping matrix, :meth:`Damping.matrix` of :attr:`damping`."""
        return self.damping.matrix()

    @property
    def mesh_map(self) -> MeshMap:
        """Where the model's DOFs sit on the FE mesh (:class:`MeshMap`): ``mesh_map.owner``,
        ``mesh_map.full_field(q)``, ``mesh_map.to_owner(q)``, ``mesh_map.fe_dof(i)``,
        ``mesh_map.probe(at)``; a reduced model's goes through its parent."""
        return MeshMap(self)

    @entry_point("dof")
    def dof(self, at: Location, owner: str | None = None) -> int:
        """Model DOF index of a location (see :class:`DofMap`); ``owner`` is deprecated (it named
        the errors, which start with ``"dof: "``)."""
        with named_by(deprecated_owner(owner, "StructuralModel.dof")):
            assert self.dofmap is not None  # check_fields fills it on construction
            return self.dofmap.find(at)

    def force_vectors(self) -> dict:
        """Complex force amplitude per harmonic: ``{k: F_k}`` with ``f(t) = Re sum F_k e^{i k w t}``."""
        out: dict = {}
        for a in self.forces:
            f = a.item
            vec = out.setdefault(f.harmonic, np.zeros(self.n_dofs, dtype=complex))
            vec[a.dof] += f.amplitude * np.exp(1j * f.phase)
        return out

    # -- frozen updates -------------------------------------------------------------------------
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
        return damped(self, alpha, beta, modal, n_modes)

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
        return dataclasses.replace(self, forces=tuple(self.forces) + tuple(bind_forces(self, forces)))

    def without_forcing(self) -> StructuralModel:
        """Return a copy with no forcing (the autonomous system, for nonlinear modes)."""
        return dataclasses.replace(self, forces=())

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
        contact node are rotated into a nodal frame whose DOF ``u_n = n . u`` the law acts on
        (``"u_t"`` or ``"u_t1"``, ``"u_t2"`` tangent); ``model.frame`` holds the rotation ``T``
        (``u = T q``; ``K``, ``M``, ``C`` become ``T^T A T``), mesh outputs stay physical and
        :meth:`with_forcing` rotates forces given in ``u_x, u_y(, u_z)``. A partly constrained
        node, two normals on one node, and an inclined normal on a reduced model (rotate before
        ``craig_bampton``) are errors. Details: :doc:`/guide/solids`.

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
            discrete models. For a rotated normal the redistribution runs in the frame where the
            normal is an axis, so a rotated model is the rotation of the axis-aligned one.
        """
        return add_contacts(self, laws, contact_mass)

    def with_nonlinearity(self, *laws) -> StructuralModel:
        """Return a copy with these smooth nonlinear laws (e.g. CubicSpring) added."""
        new = bind_nonlinearities(self, laws)
        return dataclasses.replace(self, nonlinearities=tuple(self.nonlinearities) + tuple(new))

    # -- fields ---------------------------------------------------------------------------------
    def expand(self, q: np.ndarray) -> np.ndarray:
        """Model DOFs -> model DOFs (identity; a reduced model maps to its parent's DOFs)."""
        return np.asarray(q)

    if not TYPE_CHECKING:  # the type checker sees no moved name
        def __getattr__(self, name: str) -> Any:
            # the names moved to collaborators (model/deprecations.py): they still work, with a DeprecationWarning
            return moved_attribute(self, name)

    def __repr__(self) -> str:
        kind = "discrete" if self.fe is None else self.fe.kind
        return (
            f"StructuralModel({kind}, n_dofs={self.n_dofs}, damping={self.damping_info}, forces={len(self.forces)}, "
            f"contacts={len(self.contacts)}, nonlinearities={len(self.nonlinearities)})"
        )
