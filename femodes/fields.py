"""Outputs layer: the nodal fields of a periodic motion on the FE mesh, shared by all outputs.

:func:`mesh_fields` samples a :class:`~femodes.results.PeriodicSolution` (or a linear mode,
``q(t) = phi cos(w t)``) at given times on the mesh of the model that owns it (reduced models
are expanded to the full mesh of their parent) and returns :class:`MeshFields`, which the
ParaView writer (:mod:`femodes.io`), the plots (:mod:`femodes.plot`) and the renderer
(:mod:`femodes.viz`) all use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .linear import LinearModes
from .model import StructuralModel
from .results import PeriodicSolution
from .solvers.checks import check_int

__all__ = ["MeshFields", "mesh_fields", "periodic_source", "resolve_model", "check_scale"]


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
    return model


# --------------------------------------------------------------------------------------------
# Nodal fields on the mesh
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MeshFields:
    """Nodal fields of a periodic motion sampled at times ``t`` on the FE mesh.

    Attributes
    ----------
    kind : str
        ``"bar"`` (``displacement`` is the axial ``u``) or ``"beam"`` (transverse ``w``).
    x : ndarray (n_nodes,)
        Node coordinates along the axis.
    cells : ndarray (n_elements, 2)
        Element connectivity (mesh vertices; higher-order interior DOFs are not exported).
    t : ndarray (n_t,)
        Sample times.
    period : float
    omega : float
    displacement, velocity : ndarray (n_t, n_nodes)
        Nodal ``u`` (bars) or ``w`` (beams) and its time derivative.
    rotation : ndarray (n_t, n_nodes) or None
        Beam rotation ``theta`` (None for bars).
    contact_nodes : ndarray of int (n_contacts,)
        Node of each contact (``-1`` if it cannot be located on the mesh).
    contact_gaps : ndarray (n_contacts,)
        Initial gap of each contact; the obstacle is at ``displacement = gap``.
    contact_force : ndarray (n_t, n_contacts)
        Contact force (compression positive; zeros for linear modes).
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

    @property
    def n_nodes(self) -> int:
        return self.x.size

    def nodal_contact_force(self) -> np.ndarray:
        """Contact force per node, ``(n_t, n_nodes)``, nonzero only at contact nodes."""
        out = np.zeros((self.t.size, self.n_nodes))
        for j, node in enumerate(self.contact_nodes):
            if node >= 0:
                out[:, node] += self.contact_force[:, j]
        return out

    def vector(self, values: np.ndarray) -> np.ndarray:
        """Nodal scalars ``(..., n_nodes)`` as 3-D vectors ``(..., n_nodes, 3)`` in the motion direction."""
        out = np.zeros(values.shape + (3,))
        out[..., 0 if self.kind == "bar" else 1] = values
        return out

    def points(self) -> np.ndarray:
        """Undeformed node coordinates in 3-D, ``(n_nodes, 3)``."""
        p = np.zeros((self.n_nodes, 3))
        p[:, 0] = self.x
        return p


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
            f"{owner}: the model has no mesh (a discrete StructuralModel); only FE models built with femodes.bar / "
            "femodes.beam (or Craig-Bampton reductions of them) can be exported on a mesh. For discrete systems plot "
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
    nodes = []
    for d in dofs:
        full = model.fe_dof(int(d))
        hit = np.argwhere(nodal == full) if full is not None else np.zeros((0, 2))
        nodes.append(int(hit[0, 1]) if hit.size else -1)
    mesh = fe.mesh
    return MeshFields(
        kind=str(fe.kind),
        x=np.asarray(mesh.p[0], dtype=float),
        cells=np.asarray(mesh.t[:2].T, dtype=int),
        t=t,
        period=period,
        omega=omega,
        displacement=uq[:, nodal[0]],
        velocity=uv[:, nodal[0]],
        rotation=uq[:, nodal[1]] if fe.kind == "beam" and nodal.shape[0] > 1 else None,
        contact_nodes=np.asarray(nodes, dtype=int),
        contact_gaps=np.asarray(gaps, dtype=float),
        contact_force=np.asarray(force, dtype=float).reshape(t.size, len(dofs)),
    )
