"""Outputs layer: ParaView time series (``.vtu`` frames + ``.pvd`` collection) of periodic motions.

One period of a :class:`~femodes.results.PeriodicSolution` (or of a linear mode,
``q(t) = phi cos(w t)``) is sampled at ``t_j = j T / n_frames`` and written with meshio as one
``.vtu`` file per frame, listed with its physical time in a ``.pvd`` collection that ParaView
opens as an animation. Points are the mesh nodes in 3-D (``x`` along the axis); displacements
are 3-vectors (bars: axial ``u`` along ``x``; beams: transverse ``w`` along ``y``) so that
ParaView's *Warp By Vector* shows the deformed structure.

The helpers :func:`mesh_fields` and :class:`MeshFields` (nodal fields sampled on the mesh, reduced
models expanded to the full mesh) are shared with :mod:`femodes.plot` and :mod:`femodes.viz`.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..linear import LinearModes
from ..model import StructuralModel
from ..results import PeriodicSolution

__all__ = ["MeshFields", "mesh_fields", "mesh_owner", "write_animation", "write_linear_mode"]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# Validation helpers (shared with plot.py and viz.py)
# --------------------------------------------------------------------------------------------
def check_int(value: Any, name: str, owner: str, minimum: int) -> int:
    """An integer ``>= minimum`` (bools rejected), else ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{owner}: {name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


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


def mesh_owner(model: StructuralModel) -> StructuralModel | None:
    """The model that owns the FE mesh (the parent of reduced models, recursively); None if discrete."""
    m = model
    while getattr(m, "is_reduced", False):
        m = m.parent
    return m if getattr(m, "fe", None) is not None else None


def _full_dof(model: StructuralModel, dof: int) -> int | None:
    """Full FE DOF of a physical model DOF (through reduction levels); None for modal coordinates."""
    m = model
    while getattr(m, "is_reduced", False):
        if dof >= m.n_kept:
            return None
        dof = int(np.asarray(m.kept)[dof])
        m = m.parent
    return int(np.asarray(m.fe.free)[dof])


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


def _source(source: Any, mode: Any, owner: str):
    if isinstance(source, PeriodicSolution):
        return source, None
    if isinstance(source, LinearModes):
        j = check_int(mode, "mode", owner, 0)
        if j >= len(source):
            raise ValueError(f"{owner}: mode={j} is out of range; the modes hold {len(source)} shapes (0-based index)")
        if not source.omega[j] > 0:
            raise ValueError(f"{owner}: mode {j} has zero frequency (rigid-body mode); it has no period to animate")
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
        Mode index (0-based) for ``LinearModes``.
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
    source, j = _source(source, mode, owner)
    model = resolve_model(source, model, owner)
    owner_model = mesh_owner(model)
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
        n_frames = check_int(n_frames, "n_frames", owner, 1)
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
        full = _full_dof(model, int(d))
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


# --------------------------------------------------------------------------------------------
# Writers
# --------------------------------------------------------------------------------------------
def _stem(path: Any, owner: str) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{owner}: path must be a str or os.PathLike file stem (e.g. 'out/mode1'), got {type(path).__name__}")
    p = Path(path)
    if p.suffix.lower() in (".pvd", ".vtu"):
        p = p.with_suffix("")
    if not p.name:
        raise ValueError(f"{owner}: path must name a file stem such as 'out/mode1', got {str(path)!r}")
    return p


def _add_field_data(path: Path, field_data: dict) -> None:
    """Insert a VTK ``<FieldData>`` block (ascii) into a ``.vtu`` written by meshio.

    meshio reads field data from ``.vtu`` files but its writer drops it, so it is added here.
    """
    arrays = []
    for name, values in field_data.items():
        values = np.atleast_1d(np.asarray(values))
        if np.issubdtype(values.dtype, np.integer):
            vtype, text = "Int64", " ".join(str(int(v)) for v in values)
        else:
            vtype, text = "Float64", " ".join(repr(float(v)) for v in values)
        arrays.append(f'<DataArray type="{vtype}" Name={quoteattr(name)} NumberOfTuples="{values.size}" '
                      f'format="ascii">{text}</DataArray>')
    block = "<FieldData>\n" + "\n".join(arrays) + "\n</FieldData>\n"
    text = path.read_text(encoding="utf-8")
    tag = "<UnstructuredGrid>"
    i = text.find(tag)
    if i < 0:  # pragma: no cover - depends on meshio's output layout
        log.warning("could not add field data to %s (unexpected meshio output)", path)
        return
    i += len(tag)
    if text[i : i + 1] == "\n":
        i += 1
    path.write_text(text[:i] + block + text[i:], encoding="utf-8")


def _write_series(fields: MeshFields, stem: Path, scale: float | None, owner: str) -> Path:
    import meshio

    stem.parent.mkdir(parents=True, exist_ok=True)
    n = fields.t.size
    width = max(4, len(str(n - 1)))
    points = fields.points()
    cells = [("line", fields.cells)]
    disp, vel = fields.vector(fields.displacement), fields.vector(fields.velocity)
    fnode = fields.nodal_contact_force()
    field_base = {"period": np.array([fields.period]), "omega": np.array([fields.omega])}
    if fields.contact_nodes.size:
        field_base["contact_node"] = fields.contact_nodes.astype(np.int64)
        field_base["contact_gap"] = fields.contact_gaps
    if scale is not None:
        field_base["scale"] = np.array([scale])
    entries = []
    for j in range(n):
        pd = {"displacement": disp[j], "velocity": vel[j], "contact_force": fnode[j]}
        if fields.rotation is not None:
            pd["rotation"] = fields.rotation[j]
        if scale is not None:
            pd["displacement_scaled"] = scale * disp[j]
        fd = dict(field_base, TimeValue=np.array([fields.t[j]]))
        name = f"{stem.name}_{j:0{width}d}.vtu"
        meshio.write(stem.parent / name, meshio.Mesh(points, cells, point_data=pd), file_format="vtu")
        _add_field_data(stem.parent / name, fd)
        entries.append((float(fields.t[j]), name))
    pvd = stem.parent / (stem.name + ".pvd")
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
             "  <Collection>"]
    lines += [f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(name)}/>' for t, name in entries]
    lines += ["  </Collection>", "</VTKFile>", ""]
    tmp = pvd.with_name(pvd.name + ".tmp")
    tmp.write_text("\n".join(lines), encoding="utf-8")
    os.replace(tmp, pvd)
    log.info("%s: wrote %d frames and %s", owner, n, pvd)
    return pvd


def write_animation(solution: PeriodicSolution, model: StructuralModel | None, path: Any, n_frames: int = 36,
                    scale: float | None = None) -> Path:
    """Write one period of a periodic solution as a ParaView time series.

    Parameters
    ----------
    solution : PeriodicSolution
        E.g. ``branch[i]``.
    model : StructuralModel or None
        The model the solution was solved on (None: ``solution.model``). A Craig-Bampton
        :class:`~femodes.reduction.ReducedModel` is expanded to the full mesh of its parent.
    path : str or os.PathLike
        File stem, e.g. ``"out/mode1"``: frames ``out/mode1_0000.vtu ...`` and the collection
        ``out/mode1.pvd`` (a trailing ``.pvd`` is accepted). Parent folders are created.
    n_frames : int
        Frames per period (>= 2), at times ``t_j = j T / n_frames``.
    scale : float, optional
        If given, an extra point array ``"displacement_scaled"`` = ``scale * displacement`` is
        written (for *Warp By Vector* without a scale factor) and ``scale`` stored as field data.

    Returns
    -------
    pathlib.Path
        The ``.pvd`` file (open it in ParaView).

    Notes
    -----
    Point data per frame: ``"displacement"`` and ``"velocity"`` (3-vectors: bars along ``x``,
    beams along ``y``), ``"rotation"`` (beams: ``theta``), ``"contact_force"`` (nonzero only at
    contact nodes, compression positive). Field data: ``"TimeValue"``, ``"period"``,
    ``"omega"``, and with contacts ``"contact_node"`` and ``"contact_gap"`` (the obstacle is at
    ``displacement = gap`` in the motion direction).

    Raises
    ------
    ValueError
        ``n_frames`` < 2 or not an integer; a discrete model without a mesh; a model that does
        not match the solution; no model available.
    TypeError
        Wrong types for ``solution``, ``model``, ``path`` or ``scale``.
    """
    owner = "write_animation"
    if not isinstance(solution, PeriodicSolution):
        raise TypeError(f"{owner}: solution must be a PeriodicSolution (e.g. branch[i]), got {type(solution).__name__}")
    n_frames = check_int(n_frames, "n_frames", owner, 2)
    scale = check_scale(scale, owner)
    stem = _stem(path, owner)
    fields = mesh_fields(solution, model, n_frames=n_frames, owner=owner)
    return _write_series(fields, stem, scale, owner)


def write_linear_mode(modes: LinearModes, j: int, model: StructuralModel, path: Any, n_frames: int = 36,
                      scale: float | None = None) -> Path:
    """Write linear mode ``j`` as a ParaView time series ``q(t) = phi_j cos(w_j t)``.

    Parameters
    ----------
    modes : LinearModes
        From :func:`femodes.linear_modes`.
    j : int
        Mode index, 0-based (``modes.omega[j]``).
    model : StructuralModel
        The model the modes were computed on (reduced models are expanded to the full mesh).
    path, n_frames, scale
        As in :func:`write_animation`. Shapes are mass-normalised, so use ``scale`` to choose a
        visible amplitude.

    Returns
    -------
    pathlib.Path
        The ``.pvd`` file. Frames carry the same arrays as :func:`write_animation` (the contact
        force is zero).

    Raises
    ------
    ValueError
        Bad ``j`` (out of range or a rigid-body mode), ``n_frames``, discrete model.
    TypeError
        ``modes`` not LinearModes, wrong ``model`` or ``path`` type.
    """
    owner = "write_linear_mode"
    if not isinstance(modes, LinearModes):
        raise TypeError(f"{owner}: modes must be LinearModes (femodes.linear_modes), got {type(modes).__name__}")
    if model is None:
        raise ValueError(f"{owner}: model is required (the model the modes were computed on)")
    n_frames = check_int(n_frames, "n_frames", owner, 2)
    scale = check_scale(scale, owner)
    stem = _stem(path, owner)
    fields = mesh_fields(modes, model, n_frames=n_frames, mode=j, owner=owner)
    return _write_series(fields, stem, scale, owner)
