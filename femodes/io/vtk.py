"""Outputs layer: ParaView time series (``.vtu`` frames + ``.pvd`` collection) of periodic motions.

One period of a :class:`~femodes.results.PeriodicSolution` (or of a linear mode,
``q(t) = phi cos(w t)``) is sampled at ``t_j = j T / n_frames`` and written with meshio as one
``.vtu`` file per frame, listed with its physical time in a ``.pvd`` collection that ParaView
opens as an animation. Points are the mesh nodes in 3-D (``x`` along the axis of bars and
beams); displacements are 3-vectors (bars: axial ``u`` along ``x``; beams: transverse ``w``
along ``y``; solids: ``u_x, u_y(, u_z)``) so that ParaView's *Warp By Vector* shows the
deformed structure.

Meshed solids (:func:`femodes.solid`) are written with their cells (triangle, quad, tetra,
hexahedron; for ``order=2`` the quadratic VTK cells triangle6, quad9, tetra10, hexahedron27,
whose every node, the mid-side contact nodes included, carries the point data: ParaView and
pyvista draw them with curved edges, and *Warp By Vector* moves the mid-side nodes too; vertex
cells would drop the data of the P2 nodes from the picture) and the contact fields
``"contact_force"`` (vector) and ``"contact_pressure"`` (scalar).

The nodal fields come from :func:`femodes.fields.mesh_fields` (shared with :mod:`femodes.plot`
and :mod:`femodes.viz`).
"""

from __future__ import annotations

import glob
import logging
import os
import re
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..fields import MeshFields, check_scale, sample_fields
from ..solvers.checks import InputTypeError, InputValueError, check_int, entry_name, entry_point
from ..linear import LinearModes
from ..model import StructuralModel
from ..results import PeriodicSolution
from ..store import atomic_write

__all__ = ["write_animation", "write_linear_mode"]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# Writers
# --------------------------------------------------------------------------------------------
def _stem(path: Any) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise InputTypeError(f"path must be a str or os.PathLike file stem (e.g. 'out/mode1'), got {type(path).__name__}")
    text = os.fspath(path)
    p = Path(text)
    if isinstance(text, str) and text.endswith(("/", os.sep)):
        # a folder: the files went next to it ('d/' wrote d.pvd and d_0000.vtu in the parent)
        raise InputValueError(f"path must name a file stem such as 'out/mode1', got the folder {text!r}; "
                              f"give a stem inside it, e.g. {str(p / 'mode1')!r}")
    if p.suffix.lower() in (".pvd", ".vtu", ".vtk"):
        p = p.with_suffix("")
    if not p.name:
        raise InputValueError(f"path must name a file stem such as 'out/mode1', got {str(path)!r}")
    return p


def _add_field_data(path: Path, field_data: dict) -> None:
    """Insert a VTK ``<FieldData>`` block (ascii) into a ``.vtu`` written by meshio.

    meshio reads field data from ``.vtu`` files but its writer drops it, so it is added here.
    """
    arrays = []
    for name, values in field_data.items():
        values = np.atleast_1d(np.asarray(values))
        # a 2-D array is one tuple per row (e.g. contact directions, 3 components each)
        n_tuples, n_comp = (values.shape[0], values.shape[1]) if values.ndim == 2 else (values.size, 1)
        values = values.ravel()
        if np.issubdtype(values.dtype, np.integer):
            vtype, text = "Int64", " ".join(str(int(v)) for v in values)
        else:
            vtype, text = "Float64", " ".join(repr(float(v)) for v in values)
        comp = f' NumberOfComponents="{n_comp}"' if n_comp > 1 else ""
        arrays.append(f'<DataArray type="{vtype}" Name={quoteattr(name)} NumberOfTuples="{n_tuples}"{comp} '
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


def _frame_data(fields: MeshFields, scale: float | None) -> tuple[list, dict, list]:
    """Cells, field data common to every frame, and the point data of each frame."""
    field_base: dict[str, np.ndarray | None] = {"period": np.array([fields.period]), "omega": np.array([fields.omega])}
    if fields.contact_nodes.size:
        field_base["contact_node"] = fields.contact_nodes.astype(np.int64)
        field_base["contact_gap"] = fields.contact_gaps
    if scale is not None:
        field_base["scale"] = np.array([scale])
    n = fields.t.size
    if fields.dim == 1:  # bars and beams: the files as they always were
        disp, vel = fields.vector(fields.displacement), fields.vector(fields.velocity)
        fnode = fields.nodal_contact_force()
        frames = []
        for j in range(n):
            pd = {"displacement": disp[j], "velocity": vel[j], "contact_force": fnode[j]}
            if fields.rotation is not None:
                pd["rotation"] = fields.rotation[j]
            if scale is not None:
                pd["displacement_scaled"] = scale * disp[j]
            frames.append(pd)
        return [("line", fields.cells)], field_base, frames
    if fields.contact_nodes.size:
        field_base["contact_direction"] = fields.contact_direction
        field_base["contact_measure"] = fields.contact_measure
    force, pressure = fields.contact_force_vectors(), fields.contact_pressure()
    frames = []
    for j in range(n):
        pd = {"displacement": fields.displacement[j], "velocity": fields.velocity[j], "contact_force": force[j],
              "contact_pressure": pressure[j]}
        if scale is not None:
            pd["displacement_scaled"] = scale * fields.displacement[j]
        frames.append(pd)
    return [(fields.cell_type, fields.cells)], field_base, frames


def _write_series(fields: MeshFields, stem: Path, scale: float | None, extra: dict | None = None) -> Path:
    import meshio

    stem.parent.mkdir(parents=True, exist_ok=True)
    n = fields.t.size
    width = max(4, len(str(n - 1)))
    points = fields.points()
    cells, field_base, frames = _frame_data(fields, scale)
    field_base.update(extra or {})
    entries = []
    for j, pd in enumerate(frames):
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
    atomic_write(pvd, lambda tmp: Path(tmp).write_text("\n".join(lines), encoding="utf-8"))
    # frames of an earlier series under this stem that this one does not have (it had more frames):
    # removed, so the folder never mixes two animations
    written = {name for _, name in entries}
    pattern = re.compile(rf"{re.escape(stem.name)}_\d+\.vtu")
    for old in stem.parent.glob(f"{glob.escape(stem.name)}_*.vtu"):
        if pattern.fullmatch(old.name) and old.name not in written:
            old.unlink(missing_ok=True)
    log.info("%s: wrote %d frames and %s", entry_name(), n, pvd)
    return pvd


#: Units of the written quantities for ``units="SI"`` (field data ``"unit <quantity>: <unit>"``).
SI_UNITS = {"displacement": "m", "velocity": "m/s", "rotation": "rad", "contact_force": "N",
            "contact_pressure": "Pa", "contact_gap": "m", "contact_measure": "m^2 (3-D), m^2 per m of thickness "
            "(2-D) or 1 (bars, beams)", "omega": "rad/s", "omega_truncated": "rad/s", "period": "s", "TimeValue": "s"}


def _units_and_quality(solution: PeriodicSolution, units: Any) -> dict:
    """Field data that say the units and how far the truncated contact law is from exact."""
    out = _units(units)
    if solution.P.size:
        pen, ten = float(solution.penetration), float(solution.tension)
        out["max_penetration"] = np.array([pen])
        out["max_tension"] = np.array([ten])
        out["harmonics"] = np.array([solution.harmonics.n_harmonics], dtype=np.int64)
        if pen > 0 or ten > 0:
            note = (f"note: with H = {solution.harmonics.n_harmonics} the truncated Fourier series penetrates the "
                    f"obstacle (max {pen:.3g}) and pulls (max tension {ten:.3g}): negative contact_pressure and "
                    "contact_force off contact are truncation artefacts; raise the harmonics to reduce them")
            out[note] = np.array([1], dtype=np.int64)
    if solution.omega_truncated != solution.omega:  # an error-controlled point: say which is which
        out["omega_truncated"] = np.array([solution.omega_truncated])
        out[f"note: the frames are the truncated series (H = {solution.harmonics.n_harmonics}) over its own period "
            f"2 pi / omega_truncated; omega = {solution.omega:.8g} is the error estimate's converged frequency"] = \
            np.array([1], dtype=np.int64)
    return out


def _units(units: Any) -> dict:
    """Field data that say the units (``units`` of the writers).

    meshio cannot read VTK string arrays, so text is carried by array *names* (value 1): ParaView
    lists them in the Information panel's field data, meshio in ``mesh.field_data``."""
    if units is None:
        marks = {"units: those of the model's inputs (femodes does not convert; SI inputs give m, m/s, N, Pa, "
                 "rad/s, s)": 1}
    elif units == "SI":
        marks = {f"unit {q}: {u}": 1 for q, u in SI_UNITS.items()}
    elif isinstance(units, dict) and all(isinstance(k, str) and isinstance(v, str) for k, v in units.items()):
        marks = {f"unit {q}: {u}": 1 for q, u in units.items()}
    else:
        raise InputValueError(f"units must be None, 'SI' or a dict {{quantity: unit}} of strings, got {units!r}")
    return {k: np.array([v], dtype=np.int64) for k, v in marks.items()}




@entry_point("write_animation")
def write_animation(solution: PeriodicSolution, model: StructuralModel | None, path: Any, n_frames: int = 36,
                    scale: float | None = None, *, units: Any = None) -> Path:
    """Write one period of a periodic solution as a ParaView time series.

    Parameters
    ----------
    solution : PeriodicSolution
        E.g. ``branch[i]``.
    model : StructuralModel or None
        The model of the solution (None: ``solution.model``); a reduced model is expanded to its mesh.
    path : str or os.PathLike
        File stem, e.g. ``"out/mode1"``: frames ``out/mode1_0000.vtu ...`` and the collection
        ``out/mode1.pvd`` (a trailing ``.pvd`` is accepted). Parent folders are created.
    n_frames : int, default 36
        Frames per period (>= 2), at times ``t_j = j T / n_frames``.
    scale : float, optional
        If given, an extra point array ``"displacement_scaled"`` = ``scale * displacement`` (for
        *Warp By Vector* without a scale factor); ``scale`` is stored as field data.
    units : None, "SI" or dict, optional
        Units stated in the field data (names of arrays such as ``"unit displacement: m"``): ``"SI"``
        (:data:`SI_UNITS`), a dict ``{quantity: unit}``, or None (a note: those of the model's inputs).

    Returns
    -------
    pathlib.Path
        The ``.pvd`` file (open it in ParaView).

    Notes
    -----
    Point data: ``"displacement"``, ``"velocity"``, ``"rotation"`` (beams), ``"contact_force"`` (its
    truncated series leaks into frames away from contact), ``"contact_pressure"`` (solids). Field data:
    time, period, frequency, contacts, contact quality, units, Floquet multipliers (``stability=True``).
    Every array, and the measured leak: :doc:`/howto/paraview`.

    Raises
    ------
    ValueError
        ``n_frames`` < 2 or not an integer; a discrete model without a mesh; a model that does not
        match the solution; no model available.
    TypeError
        Wrong types for ``solution``, ``model``, ``path`` or ``scale``.
    """
    if not isinstance(solution, PeriodicSolution):
        raise InputTypeError(f"solution must be a PeriodicSolution (e.g. branch[i]), got {type(solution).__name__}")
    n_frames = check_int("n_frames", n_frames, 2)
    scale = check_scale(scale)
    stem = _stem(path)
    extra = _units_and_quality(solution, units)
    fields = sample_fields(solution, model, n_frames=n_frames)
    if solution.multipliers is not None:  # computed with stability=True
        extra.update({"floquet_multipliers_real": solution.multipliers.real,
                      "floquet_multipliers_imag": solution.multipliers.imag,
                      "stable": np.array([int(bool(solution.stable))], dtype=np.int64)})
    return _write_series(fields, stem, scale, extra)




@entry_point("write_linear_mode")
def write_linear_mode(modes: LinearModes, model: StructuralModel, path: Any, n_frames: int = 36,
                      scale: float | None = None, *, mode: int = 1, units: Any = None) -> Path:
    """Write a linear mode as a ParaView time series ``q(t) = phi cos(w t)``.

    Parameters
    ----------
    modes : LinearModes
        From :func:`femodes.linear_modes`.
    model : StructuralModel
        The model the modes were computed on (reduced models are expanded to the full mesh).
    path, n_frames, scale
        As in :func:`write_animation` (same argument order). Shapes are mass-normalised, so use
        ``scale`` to choose a visible amplitude.
    mode : int
        Mode number, 1 = the first mode (``modes.omega[mode - 1]``), as everywhere in femodes.
    units : None, "SI" or dict, optional
        As in :func:`write_animation`; the field data also say that the shape is mass-normalised
        (its amplitude, in units of the displacement per square root of mass, is arbitrary).

    Returns
    -------
    pathlib.Path
        The ``.pvd`` file. Frames carry the same arrays as :func:`write_animation` (the contact
        force is zero).

    Raises
    ------
    ValueError
        Bad ``mode`` (out of range or a rigid-body mode), ``n_frames``, discrete model.
    TypeError
        ``modes`` not LinearModes, wrong ``model`` or ``path`` type.
    """
    if not isinstance(modes, LinearModes):
        raise InputTypeError(f"modes must be LinearModes (femodes.linear_modes), got {type(modes).__name__}")
    if model is None:
        raise InputValueError("model is required (the model the modes were computed on)")
    n_frames = check_int("n_frames", n_frames, 2)
    scale = check_scale(scale)
    stem = _stem(path)
    extra = _units(units)
    fields = sample_fields(modes, model, n_frames=n_frames, mode=mode)
    extra["note: linear mode shape, mass-normalised (its amplitude is arbitrary)"] = np.array([1], dtype=np.int64)
    return _write_series(fields, stem, scale, extra)
