"""Application layer: TOML case files for ``femodes run case.toml``.

A case file describes a model and one analysis; :func:`load_case` reads and checks it,
:func:`build_model` turns it into a :class:`femodes.StructuralModel` with the public API and
:func:`run_case` runs the analysis and writes the outputs. Every user mistake raises
:class:`CaseError`, whose message is ``file:line: [table] message`` (the line of the offending
key when it can be found, else of its table).

Schema (see ``examples/cases/*.toml`` for commented examples)::

    [mesh]                      # FE models only; either a file ...
    file = "../../meshes/cantilever.msh"   # relative to the case file (gmsh, vtu, ... via meshio;
                                # line meshes for beams and bars, 2-D/3-D meshes for solids)
    # ... or a straight line mesh (beam, bar):
    # length = 1.0
    # n_elements = 40
    # boundaries = { clamp = 0.0, tip = 1.0 }   # named points (x coordinates)
    # grading = 1.0
    # ... or a structured solid mesh (kind = "solid"): a rectangle [0, length] x [0, height]
    # (boundaries "left", "right", "bottom", "top") or, with nz, a box [0, length] x [0, width]
    # x [0, height] (also "front", "back"); see femodes.rectangle_mesh and femodes.box_mesh
    # length = 1.0
    # height = 0.1
    # width = 0.1               # box only
    # nx = 40                   # element divisions along x, y (and z for a box)
    # ny = 4
    # nz = 2                    # makes it a box
    # quad = true               # rectangle: quadrilaterals instead of triangles (default false)
    # hexahedra = true          # box: hexahedra instead of tetrahedra (default false)

    [model]
    kind = "beam"               # "beam" | "bar" | "solid" | "discrete"
    E = 1.0                     # beam, bar, solid
    rho = 1.0                   # beam, bar, solid
    area = 1.0                  # beam, bar
    inertia = 1.0               # beam (required)
    clamped = ["clamp"]         # beam, bar: named points; solid: named boundaries (a string or a list)
    pinned = []                 # beam only
    # order = 1                 # bar, solid: Lagrange order 1 or 2 (P1/P2, Q1/Q2)
    # nu = 0.3                  # solid: Poisson's ratio
    # plane = "stress"          # solid, 2-D meshes: "stress" or "strain"
    # thickness = 1.0           # solid, 2-D meshes
    # supports = { bottom = "u_y" }   # solid: per-component supports (a component or a list)
    # discrete: M = [[1.0]], K = [[1.0]], C = [[0.1]] (C optional), dof_names = ["x"]

    [damping]                   # optional: Rayleigh alpha, beta  or  modal = 0.02
    alpha = 0.02

    [[contact]]                 # 0..n tables
    at = "tip"                  # a name, ["tip", "w"] or a DOF index; solids: a boundary name
    gap = 0.01                  # >= 0
    # direction = [1.0, 0.0]    # solids: contact normal along +x, +y or +z (one contact per node)
    law = "complementarity"     # or "penalty" (then stiffness = ... is required)
    # c = 10.0                  # complementarity parameter (optional)

    [[force]]                   # 0..n harmonic point forces
    at = "tip"                  # solids: ["right", "u_x"] spreads the force over a boundary
    amplitude = 0.004
    # harmonic = 1
    # phase = 0.0

    [[cubic]]                   # 0..n cubic springs
    # at = "tip"
    # k3 = 1.0

    [reduction]                 # optional
    craig_bampton = 10          # number of fixed-interface modes

    [analysis]                  # required
    type = "nonlinear_mode"     # or "frequency_response"
    mode = 1                    # nonlinear_mode
    energy = [1e-4, 3e-3]       # nonlinear_mode: energy span
    # omega = [3.0, 4.2]        # frequency_response: frequency span (rad/s)
    harmonics = 10
    # max_points = 2000         # optional cap on the number of continuation points
    # stability = true          # Floquet multipliers and bifurcations of every point: true ("auto"),
                                # "hill", "shooting" or false (default); see femodes.floquet
    # rtol = 1e-3               # error control: points and folds to this relative error (rtol= of
                                # the analyses; see femodes.estimate_error)
    # energy_unit = "grazing"   # nonlinear_mode: energy in multiples of the grazing energy of the
                                # mode (femodes.grazing_energy), e.g. energy = [0.5, 20]

    [outputs]                   # optional; defaults shown
    plot = true                 # frequency_energy.png (nonlinear mode) / response.png (forced)
    branch = "branch.npz"       # saved Branch (femodes.load_branch); false to skip
    animation = true            # ParaView series of the last point (FE models only)
    gif = false                 # rendered GIF (needs pyvista; skipped with a note otherwise)
    # response_dof = "tip"      # DOF of the response plot (default: the first force)
"""

from __future__ import annotations

import difflib
import math
import re
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Callable

import numpy as np

__all__ = ["CaseError", "Case", "SCHEMA", "load_case", "parse_case", "build_model", "run_case", "key_line",
           "schema_type_error"]

# table -> {key: description of the expected type}; ARRAY_TABLES are [[...]] tables.
SCHEMA: dict[str, dict[str, str]] = {
    "mesh": {"file": "string", "length": "number", "n_elements": "integer", "boundaries": "table",
             "grading": "number", "height": "number", "width": "number", "nx": "integer", "ny": "integer",
             "nz": "integer", "quad": "boolean", "hexahedra": "boolean"},
    "model": {"kind": "string", "E": "number", "rho": "number", "area": "number", "inertia": "number",
              "clamped": "string or list", "pinned": "string or list", "M": "matrix", "K": "matrix",
              "C": "matrix", "dof_names": "list", "nu": "number", "plane": "string", "thickness": "number",
              "order": "integer", "supports": "table"},
    "damping": {"alpha": "number", "beta": "number", "modal": "number or list"},
    "contact": {"at": "location", "gap": "number", "law": "string", "c": "number", "stiffness": "number",
                "direction": "vector"},
    "force": {"at": "location", "amplitude": "number", "harmonic": "integer", "phase": "number"},
    "cubic": {"at": "location", "k3": "number"},
    "reduction": {"craig_bampton": "integer"},
    "analysis": {"type": "string", "mode": "integer", "energy": "pair", "omega": "pair", "harmonics": "integer",
                 "max_points": "integer", "stability": "boolean or method", "rtol": "number",
                 "energy_unit": "string"},
    "outputs": {"plot": "boolean", "branch": "string or false", "animation": "boolean", "gif": "boolean",
                "response_dof": "location"},
}
ARRAY_TABLES = ("contact", "force", "cubic")
MODEL_KINDS = ("beam", "bar", "solid", "discrete")
#: [mesh] keys of a line mesh (beam, bar) and of a generated solid mesh (rectangle, or box with nz).
LINE_MESH_KEYS = ("length", "n_elements", "boundaries", "grading")
SOLID_MESH_KEYS = ("length", "height", "width", "nx", "ny", "nz", "quad", "hexahedra")
#: Element divisions of a generated solid mesh (what ``femodes scaling --refine`` multiplies).
SOLID_DIVISIONS = ("nx", "ny", "nz")
ANALYSES = ("nonlinear_mode", "frequency_response")


class CaseError(Exception):
    """A user mistake in a case file; ``str(err)`` is ``file:line: message``."""

    def __init__(self, message: str, file: str = "case", line: int | None = None):
        super().__init__(message)
        self.message, self.file, self.line = message, file, line

    def _at(self, line: int | None) -> CaseError:
        self.line = line
        return self

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.message}" if self.line else f"{self.file}: {self.message}"


# ---------------------------------------------------------------------------------------------
# Locating keys in the text
# ---------------------------------------------------------------------------------------------
_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-\"' ]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+|\"[^\"]*\")\s*=")


def key_line(text: str, table: str | None, key: str | None = None, index: int = 0) -> int | None:
    """1-based line of ``key = ...`` in ``[table]`` (the ``index``-th ``[[table]]``), else of the header.

    ``table=None`` means the top level (before any header). Returns None if not found.
    """
    current, count, header_line = None, {}, None
    found_header = None
    for no, raw in enumerate(text.splitlines(), 1):
        m = _HEADER.match(raw)
        if m and "=" not in raw.split("#")[0]:
            name = m.group(2).strip().strip("\"'")
            k = count.get(name, 0)
            count[name] = k + 1
            current = (name, k)
            if name == table and k == index:
                found_header = header_line = no
            continue
        if key is None:
            continue
        km = _KEY.match(raw)
        if km and km.group(1).strip('"') == key:
            if (table is None and current is None) or (current == (table, index)):
                return no
    return found_header if key is None or found_header else header_line


# ---------------------------------------------------------------------------------------------
# Parsed case
# ---------------------------------------------------------------------------------------------
@dataclass
class Case:
    """A checked case file: ``data`` as read by tomllib, plus where it came from."""

    path: Path
    text: str
    data: dict
    name: str = field(default="")

    def __post_init__(self):
        self.name = self.name or str(self.path)

    def tables(self, name: str) -> list[dict]:
        v = self.data.get(name)
        if v is None:
            return []
        return v if isinstance(v, list) else [v]

    def label(self, table: str, index: int = 0) -> str:
        if table in ARRAY_TABLES and len(self.tables(table)) > 1:
            return f"[{table} #{index + 1}]"
        return f"[{table}]"

    def error(self, table: str | None, key: str | None, message: str, index: int = 0) -> CaseError:
        line = key_line(self.text, table, key, index) if table else None
        prefix = f"{self.label(table, index)} " if table else ""
        return CaseError(prefix + message, self.name, line)


def _fmt(v: Any) -> str:
    return repr(v) if isinstance(v, str) else str(v).lower() if isinstance(v, bool) else str(v)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_type(v: Any, kind: str) -> bool:
    if kind == "number":
        return _is_num(v)
    if kind == "integer":
        return isinstance(v, int) and not isinstance(v, bool)
    if kind == "string":
        return isinstance(v, str)
    if kind == "boolean":
        return isinstance(v, bool)
    if kind == "boolean or method":
        return isinstance(v, (bool, str))
    if kind == "table":
        return isinstance(v, dict)
    if kind == "pair":
        return isinstance(v, list) and len(v) == 2 and all(_is_num(x) for x in v)
    if kind == "vector":
        return isinstance(v, list) and 1 <= len(v) <= 3 and all(_is_num(x) for x in v)
    if kind == "string or list":
        return isinstance(v, str) or (isinstance(v, list) and all(isinstance(x, str) for x in v))
    if kind == "string or false":
        return isinstance(v, str) or v is False
    if kind == "number or list":
        return _is_num(v) or (isinstance(v, list) and all(_is_num(x) for x in v))
    if kind == "list":
        return isinstance(v, list)
    if kind == "matrix":
        return _is_num(v) or (isinstance(v, list) and all(
            isinstance(r, list) and all(_is_num(x) for x in r) for r in v))
    if kind == "location":
        return ((isinstance(v, int) and not isinstance(v, bool)) or isinstance(v, str)
                or (isinstance(v, list) and len(v) == 2 and all(isinstance(x, str) for x in v)))
    return True


def schema_type_error(table: str, key: str, value: Any) -> str:
    """Why ``value`` cannot be ``[table] key`` by its type (``"gap must be a number, got 'abc'"``),
    ``""`` if it can; the type checks of :func:`parse_case` (values are checked there too)."""
    kind = SCHEMA[table][key]
    if not _check_type(value, kind):
        return f"{key} must be {_TYPE_TEXT[kind]}, got {_fmt(value)}"
    if not _all_finite(value):
        return f"{key} must be finite (no nan or inf), got {_fmt(value)}"
    return ""


def _all_finite(v: Any) -> bool:
    """False if ``v`` is (or contains, in lists and inline tables) a nan or inf float."""
    if isinstance(v, float):
        return math.isfinite(v)
    if isinstance(v, list):
        return all(_all_finite(x) for x in v)
    if isinstance(v, dict):
        return all(_all_finite(x) for x in v.values())
    return True


_TYPE_TEXT = {
    "number": "a number", "integer": "an integer", "string": "a string", "boolean": "true or false",
    "boolean or method": "true, false or a method name (\"auto\", \"hill\", \"shooting\")",
    "table": "a table like { name = value }", "pair": "a pair [start, end] of numbers",
    "vector": "a vector of 1 to 3 numbers like [1.0, 0.0]",
    "string or list": "a name or a list of names", "string or false": "a file name or false",
    "number or list": "a number or a list of numbers", "list": "a list",
    "matrix": "a matrix like [[1.0, 0.0], [0.0, 1.0]]",
    "location": "a location: a name like \"tip\", a pair like [\"tip\", \"w\"] or a DOF index",
}


def _suggest(word: str, options) -> str:
    close = difflib.get_close_matches(word, list(options), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""


def parse_case(text: str, path: str | Path = "case.toml") -> Case:
    """Parse and check the text of a case file (syntax, tables, keys, types, simple values)."""
    path = Path(path)
    name = str(path)
    text = text.removeprefix("\ufeff")  # a byte-order mark (Windows editors) is not a TOML statement
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = re.search(r"\(at line (\d+), column (\d+)\)", msg)
        line = int(m.group(1)) if m else None
        msg = re.sub(r"\s*\(at line \d+, column \d+\)", "", msg) if m else msg
        if m is None and "end of document" in msg:
            line = max(1, len(text.splitlines()))
        raise CaseError(f"TOML syntax error: {msg}", name, line) from None
    case = Case(path=path, text=text, data=data)
    for tname, value in data.items():
        if tname not in SCHEMA:
            raise case.error(None, None, f"unknown table [{tname}]{_suggest(tname, SCHEMA)}; "
                             f"valid tables are {', '.join('[' + t + ']' for t in SCHEMA)}")._at(
                key_line(text, tname) or key_line(text, None, tname))
        if tname in ARRAY_TABLES:
            if isinstance(value, dict):
                value = data[tname] = [value]  # [contact] accepted for a single table
            if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
                raise case.error(None, None, f"{tname} must be a table [[{tname}]]")._at(key_line(text, None, tname))
        elif not isinstance(value, dict):
            raise case.error(None, None, f"{tname!r} must be a table [{tname}], got a value")._at(
                key_line(text, None, tname))
        for i, tab in enumerate(case.tables(tname)):
            for key, v in tab.items():
                if key not in SCHEMA[tname]:
                    raise case.error(tname, key, f"unknown key {key!r}{_suggest(key, SCHEMA[tname])}; valid keys "
                                     f"are {', '.join(SCHEMA[tname])}", i)
                kind = SCHEMA[tname][key]
                if not _check_type(v, kind):
                    raise case.error(tname, key, f"{key} must be {_TYPE_TEXT[kind]}, got {_fmt(v)}", i)
                if not _all_finite(v):
                    # TOML has nan and inf; no key of the schema accepts them
                    raise case.error(tname, key, f"{key} must be finite (no nan or inf), got {_fmt(v)}", i)
    _check_values(case)
    return case


def _check_values(case: Case) -> None:
    """Checks across keys and tables, in the order the first mistake is reported."""
    _check_required_tables(case)
    kind = _check_model(case)
    _check_contacts(case)
    _check_forces_and_springs(case)
    _check_analysis(case)
    _check_outputs(case)
    _check_reduction(case, kind)


def _check_required_tables(case: Case) -> None:
    if "model" not in case.data:
        raise CaseError("missing table [model] (kind = \"beam\" | \"bar\" | \"solid\" | \"discrete\", ...)",
                        case.name, 1)
    if "analysis" not in case.data:
        raise CaseError("missing table [analysis] (type = \"nonlinear_mode\" or \"frequency_response\", ...)",
                        case.name, 1)


def _check_model(case: Case) -> str:
    """Check [model] (and [mesh] for FE models); returns the model kind."""
    model = case.data["model"]
    kind = model.get("kind")
    if kind is None:
        raise case.error("model", None, "missing key kind (\"beam\", \"bar\", \"solid\" or \"discrete\")")
    if kind not in MODEL_KINDS:
        raise case.error("model", "kind", f"kind must be one of {', '.join(map(repr, MODEL_KINDS))}, got {kind!r}"
                         f"{_suggest(kind, MODEL_KINDS)}")
    if kind == "discrete":
        _check_discrete_model(case, model)
    elif kind == "solid":
        _check_solid_model(case, model)
        _check_solid_mesh(case, model)
    else:
        _check_fe_model(case, kind, model)
        _check_mesh(case, kind)
    if "order" in model and model["order"] not in (1, 2):
        raise case.error("model", "order", f"order must be 1 or 2, got {model['order']}")
    return kind


def _check_discrete_model(case: Case, model: dict) -> None:
    for k in ("M", "K"):
        if k not in model:
            raise case.error("model", None, f"a discrete model needs {k} = [[...]]")
    for k in ("E", "rho", "area", "inertia", "clamped", "pinned", "nu", "plane", "thickness", "order", "supports"):
        if k in model:
            raise case.error("model", k, f"{k} is not used by a discrete model (give M, K, C)")
    if "mesh" in case.data:
        raise case.error("mesh", None, "a discrete model has no mesh; remove [mesh]")


def _check_fe_model(case: Case, kind: str, model: dict) -> None:
    for k in ("E", "rho", "area") + (("inertia",) if kind == "beam" else ()):
        if k not in model:
            raise case.error("model", None, f"a {kind} model needs {k} = ...")
    for k in ("M", "K", "C", "dof_names") + (("pinned", "inertia") if kind == "bar" else ("order",)):
        if k in model:
            raise case.error("model", k, f"{k} is not used by a {kind} model")
    for k in ("nu", "plane", "thickness", "supports"):
        if k in model:
            raise case.error("model", k, f"{k} is used by solid models only (kind = \"solid\"), not by a {kind} model")


def _check_solid_model(case: Case, model: dict) -> None:
    """[model] kind = "solid": material, element order, supports, plane and thickness."""
    for k in ("E", "rho"):
        if k not in model:
            raise case.error("model", None, f"a solid model needs {k} = ...")
    for k in ("area", "inertia", "pinned", "M", "K", "C", "dof_names"):
        if k in model:
            hint = " (a 2-D solid takes thickness = ...)" if k == "area" else ""
            raise case.error("model", k, f"{k} is not used by a solid model{hint}")
    plane = model.get("plane")
    if plane is not None and plane not in ("stress", "strain"):
        raise case.error("model", "plane", f"plane must be \"stress\" or \"strain\", got {plane!r}"
                         f"{_suggest(plane, ('stress', 'strain'))}")
    if "thickness" in model and not model["thickness"] > 0:
        raise case.error("model", "thickness", f"thickness must be > 0, got {_fmt(model['thickness'])}")
    for loc, comps in model.get("supports", {}).items():
        if not (isinstance(comps, str) or (isinstance(comps, list) and comps
                                           and all(isinstance(c, str) for c in comps))):
            raise case.error("model", "supports", f"supports must be a table like {{ bottom = \"u_y\" }} (a component "
                             f"name or a list of them per location), got {loc} = {_fmt(comps)}")


def _check_solid_mesh(case: Case, model: dict) -> None:
    """[mesh] of a solid: a file, or a rectangle (nx, ny) or box (nx, ny, nz) with positive sides."""
    mesh = case.data.get("mesh")
    if mesh is None:
        raise CaseError("a solid model needs a [mesh] table (file = ... or nx, ny (and nz) with length, height "
                        "(and width))", case.name, key_line(case.text, "model", "kind"))
    for k in ("n_elements", "boundaries", "grading"):
        if k in mesh:
            raise case.error("mesh", k, f"{k} is for line meshes (beam, bar); a solid mesh is generated from nx, ny "
                             "(and nz for a box) or read from a file")
    if "file" in mesh:
        k = next((k for k in SOLID_MESH_KEYS if k in mesh), None)
        if k is not None:
            raise case.error("mesh", k, f"give either file = ... or a generated mesh (nx, ny, ...), not both ({k})")
        return
    for k in ("nx", "ny"):
        if k not in mesh:
            raise case.error("mesh", None, f"a generated solid mesh needs nx and ny (and nz for a box), or "
                             f"file = \"...\"; {k} is missing")
    box = "nz" in mesh
    for k in (("quad",) if box else ("width", "hexahedra")):
        if k in mesh:
            hint = ("quad is for rectangles (2-D); a box (nz) takes hexahedra = true" if k == "quad"
                    else f"{k} is for boxes (3-D): give nz too, or leave {k} out for a rectangle")
            raise case.error("mesh", k, hint)
    for k in SOLID_DIVISIONS:
        if k in mesh and mesh[k] < 1:
            raise case.error("mesh", k, f"{k} must be >= 1, got {mesh[k]}")
    for k in ("length", "height", "width"):
        if k in mesh and not mesh[k] > 0:
            raise case.error("mesh", k, f"{k} must be > 0, got {_fmt(mesh[k])}")
    if box:
        for k in ("plane", "thickness"):
            if k in model:
                raise case.error("model", k, f"{k} applies to 2-D solids; [mesh] with nz is a 3-D box (leave {k} out)")


def _check_mesh(case: Case, kind: str) -> None:
    mesh = case.data.get("mesh")
    if mesh is None:
        raise CaseError(f"a {kind} model needs a [mesh] table (file = ... or length/n_elements)", case.name,
                        key_line(case.text, "model", "kind"))
    if "file" in mesh and any(k in mesh for k in LINE_MESH_KEYS):
        k = next(k for k in LINE_MESH_KEYS if k in mesh)
        raise case.error("mesh", k, f"give either file = ... or length/n_elements/boundaries, not both ({k})")
    if "file" not in mesh and "n_elements" not in mesh:
        raise case.error("mesh", None, "needs file = \"...\" or n_elements = ... (with length, boundaries)")
    k = next((k for k in SOLID_MESH_KEYS if k in mesh and k != "length"), None)
    if k is not None:
        raise case.error("mesh", k, f"{k} is for the meshes of solids (kind = \"solid\"); a {kind} takes a line mesh "
                         "(length, n_elements, boundaries)")


def _check_contacts(case: Case) -> None:
    for i, c in enumerate(case.tables("contact")):
        for k in ("at", "gap"):
            if k not in c:
                raise case.error("contact", None, f"missing key {k}", i)
        if c["gap"] < 0:
            raise case.error("contact", "gap", f"gap must be >= 0, got {_fmt(c['gap'])}", i)
        law = c.get("law", "complementarity")
        if law not in ("complementarity", "penalty"):
            raise case.error("contact", "law", f"law must be \"complementarity\" or \"penalty\", got {law!r}"
                             f"{_suggest(law, ('complementarity', 'penalty'))}", i)
        if law == "penalty" and "stiffness" not in c:
            raise case.error("contact", "law", "a penalty contact needs stiffness = ...", i)
        if law == "penalty" and "c" in c:
            raise case.error("contact", "c", "c is the complementarity parameter; a penalty contact uses stiffness", i)
        if law == "complementarity" and "stiffness" in c:
            raise case.error("contact", "stiffness", "stiffness is for law = \"penalty\"", i)
        if "direction" in c and case.data["model"].get("kind") != "solid":
            raise case.error("contact", "direction", "direction is for contacts on the boundaries of solids "
                             "(kind = \"solid\")", i)


def _check_forces_and_springs(case: Case) -> None:
    for tname, required in (("force", ("at",)), ("cubic", ("at", "k3"))):
        for i, t in enumerate(case.tables(tname)):
            for k in required:
                if k not in t:
                    raise case.error(tname, None, f"missing key {k}", i)


def _check_analysis(case: Case) -> None:
    an = case.data["analysis"]
    typ = an.get("type")
    if typ is None:
        raise case.error("analysis", None, "missing key type (\"nonlinear_mode\" or \"frequency_response\")")
    if typ not in ANALYSES:
        raise case.error("analysis", "type", f"type must be \"nonlinear_mode\" or \"frequency_response\", got "
                         f"{typ!r}{_suggest(typ, ANALYSES)}")
    need, forbid = (("energy",), ("omega",)) if typ == "nonlinear_mode" else (("omega",), ("energy", "mode"))
    for k in need:
        if k not in an:
            raise case.error("analysis", None, f"{typ} needs {k} = [start, end]")
    for k in forbid:
        if k in an:
            raise case.error("analysis", k, f"{k} is not used by {typ}")
    if typ == "frequency_response" and not case.tables("force"):
        raise CaseError("frequency_response needs at least one [[force]] table", case.name,
                        key_line(case.text, "analysis", "type"))
    for k in need:
        a, b = an[k]
        if not (a > 0 and b > 0 and a != b):
            raise case.error("analysis", k, f"{k} must be two distinct positive numbers [start, end], got {an[k]}")
    _check_analysis_settings(case, an, typ)


def _check_analysis_settings(case: Case, an: dict, typ: str) -> None:
    """The optional [analysis] keys: max_points, harmonics, mode, stability."""
    st = an.get("stability")
    if isinstance(st, str):
        from ..floquet import METHODS  # "auto", "hill", "shooting"; true is "auto"

        if st not in METHODS:
            raise case.error("analysis", "stability", f"stability must be true, false or one of "
                             f"{', '.join(map(repr, METHODS))}, got {st!r}{_suggest(st, METHODS)}")
    if typ == "nonlinear_mode" and "max_points" in an:
        raise case.error("analysis", "max_points", "max_points is only supported for frequency_response")
    for k in ("harmonics", "mode", "max_points"):
        if k in an and an[k] < (2 if k == "max_points" else 1):
            raise case.error("analysis", k, f"{k} must be >= {2 if k == 'max_points' else 1}, got {an[k]}")
    if "rtol" in an and not (0 < an["rtol"] < 1):
        raise case.error("analysis", "rtol", f"rtol must be a relative error in (0, 1), e.g. 1e-3, got {an['rtol']}")
    if "energy_unit" in an:
        if typ != "nonlinear_mode":
            raise case.error("analysis", "energy_unit", "energy_unit is only for nonlinear_mode")
        if an["energy_unit"] != "grazing":
            raise case.error("analysis", "energy_unit", f"energy_unit must be \"grazing\" (energies in multiples of "
                             f"the mode's grazing energy), got {an['energy_unit']!r}; leave it out for energies as given")
    if "harmonics" in an:
        from ..hbm.harmonics import Harmonics

        try:
            Harmonics(an["harmonics"])
        except (TypeError, ValueError) as exc:
            raise case.error("analysis", "harmonics", f"harmonics = {an['harmonics']}: {exc}") from None


def _check_outputs(case: Case) -> None:
    outs = case.data.get("outputs", {})
    if isinstance(outs.get("branch"), str) and not outs["branch"].strip():
        raise case.error("outputs", "branch", "branch must be a file name like \"branch.npz\" (or false), got ''")


def _check_reduction(case: Case, kind: str) -> None:
    red = case.data.get("reduction", {})
    if "craig_bampton" in red and red["craig_bampton"] < 0:
        raise case.error("reduction", "craig_bampton", f"craig_bampton must be >= 0, got {red['craig_bampton']}")
    if "reduction" in case.data and kind == "discrete":
        raise case.error("reduction", None, "Craig-Bampton reduction needs an FE model (beam, bar or solid)")


def load_case(path: str | Path) -> Case:
    """Read and check a case file; raises CaseError (file missing, syntax, schema)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")  # a UTF-8 byte-order mark is dropped
    except FileNotFoundError:
        raise CaseError("case file not found", str(path)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CaseError(f"cannot read case file: {exc}", str(path)) from None
    case = parse_case(text, p)
    return case


# ---------------------------------------------------------------------------------------------
# Building and running
# ---------------------------------------------------------------------------------------------
def _location(v: Any):
    return tuple(v) if isinstance(v, list) else v


def _guess_key(message: str, keys) -> str | None:
    """The key named first in ``message`` ("K has shape ... (M is 1x1)" is about K, not M)."""
    best, pos = None, None
    for k in keys:
        m = re.search(rf"\b{re.escape(k)}\b", message)
        if m and (pos is None or m.start() < pos):
            best, pos = k, m.start()
    return best


class _Api:
    """Calls into femodes, turning ValueError/TypeError into CaseError at the responsible key."""

    def __init__(self, case: Case):
        self.case = case

    def __call__(self, table: str | None, keys, fn: Callable, *args, index: int = 0, **kwargs):
        keys = [keys] if isinstance(keys, str) or keys is None else list(keys)
        try:
            return fn(*args, **kwargs)
        except (ValueError, TypeError, FileNotFoundError) as exc:
            msg = str(exc)
            m = re.search(r"unknown location '([^']*)'; known names are \[(.*)\]", msg)
            if m:
                msg += _suggest(m.group(1), re.findall(r"'([^']*)'", m.group(2)))
            key = _guess_key(msg, [k for k in keys if k]) or (keys[0] if keys else None)
            if table is None:
                raise CaseError(msg, self.case.name) from None
            raise self.case.error(table, key, msg, index) from None


def build_model(case: Case):
    """Model of the case: FE or discrete model, damping, contacts, springs, forces, reduction.

    Returns ``(model, full)``: the model to analyse (reduced if [reduction]) and the full model.
    """
    api = _Api(case)
    d = case.data
    model = _discrete_model(case, api) if d["model"]["kind"] == "discrete" else _fe_model(case, api)
    model = _add_damping(case, api, model)
    model = _add_contacts(case, api, model)
    model = _add_cubic_springs(case, api, model)
    model = _add_forces(case, api, model)
    full = model
    if "reduction" in d and "craig_bampton" in d["reduction"]:
        import femodes as fm

        model = api("reduction", "craig_bampton", fm.craig_bampton, model, d["reduction"]["craig_bampton"])
    if "outputs" in d and "response_dof" in d["outputs"]:
        api("outputs", "response_dof", model.dof, _location(d["outputs"]["response_dof"]), "response_dof")
    return model, full


def _discrete_model(case: Case, api: _Api):
    """[model] kind = "discrete": a StructuralModel from M, K (and C, dof_names)."""
    import numpy as np

    import femodes as fm

    m = case.data["model"]

    def matrix(k):
        v = m[k]
        if isinstance(v, list) and (not v or len({len(r) for r in v}) != 1 or len(v) != len(v[0])):
            raise case.error("model", k, f"{k} must be a square matrix like [[1.0, 0.0], [0.0, 1.0]] (n rows of "
                             f"n numbers), got {_fmt(v)}")
        return np.atleast_2d(np.asarray(v, dtype=float))

    args = dict(M=matrix("M"), K=matrix("K"), C=matrix("C") if "C" in m else None, dof_names=m.get("dof_names"))
    return api("model", ["M", "K", "C", "dof_names"], fm.StructuralModel, **args)


def _mesh(case: Case, api: _Api):
    """The mesh of [mesh]: read from ``file``, a rectangle or box (solids) or a straight line mesh."""
    import femodes as fm

    mesh_t = case.data["mesh"]
    if "file" in mesh_t:
        f = Path(mesh_t["file"])
        if not f.is_absolute():
            f = case.path.parent / f
        if not f.is_file():
            raise case.error("mesh", "file", f"mesh file {str(f)!r} does not exist")
        return api("mesh", "file", fm.load_mesh, str(f))
    if case.data["model"]["kind"] == "solid":
        g = {k: mesh_t[k] for k in ("length", "height", "width", "nx", "ny", "nz") if k in mesh_t}
        if "nz" in mesh_t:
            return api("mesh", list(g) + ["hexahedra"], fm.box_mesh, **g, hexahedra=mesh_t.get("hexahedra", False))
        return api("mesh", list(g) + ["quad"], fm.rectangle_mesh, **g, quadrilaterals=mesh_t.get("quad", False))
    return api("mesh", ["boundaries", "n_elements", "length", "grading"], fm.line_mesh,
               mesh_t.get("length", 1.0), mesh_t["n_elements"], boundaries=mesh_t.get("boundaries"),
               grading=mesh_t.get("grading", 1.0))


def _fe_model(case: Case, api: _Api):
    """[model] kind = "beam" | "bar" | "solid" on the mesh of [mesh]."""
    import femodes as fm

    m = case.data["model"]
    mesh = _mesh(case, api)
    if m["kind"] == "solid":
        mat = api("model", ["E", "rho", "nu"], fm.Material, E=m["E"], rho=m["rho"],
                  **({"nu": m["nu"]} if "nu" in m else {}))
        supports = {k: tuple(v) if isinstance(v, list) else v for k, v in m["supports"].items()} \
            if "supports" in m else None
        return api("model", ["clamped", "supports", "plane", "thickness", "order"], fm.solid, mesh, mat,
                   clamped=m.get("clamped"), supports=supports, plane=m.get("plane"), thickness=m.get("thickness"),
                   order=m.get("order", 1))
    mat = api("model", ["E", "rho"], fm.Material, E=m["E"], rho=m["rho"])
    sec = api("model", ["area", "inertia"], fm.Section, area=m["area"], inertia=m.get("inertia"))
    if m["kind"] == "beam":
        return api("model", ["clamped", "pinned"], fm.beam, mesh, mat, sec, clamped=m.get("clamped"),
                   pinned=m.get("pinned"))
    return api("model", ["clamped", "order"], fm.bar, mesh, mat, sec, clamped=m.get("clamped"), order=m.get("order", 1))


def _add_damping(case: Case, api: _Api, model):
    if "damping" not in case.data:
        return model
    dm = case.data["damping"]
    if "modal" in dm:
        if "alpha" in dm or "beta" in dm:
            raise case.error("damping", "modal", "give either Rayleigh alpha/beta or modal, not both")
        return api("damping", "modal", model.with_damping, modal=dm["modal"])
    return api("damping", list(dm), model.with_damping, alpha=dm.get("alpha", 0.0), beta=dm.get("beta", 0.0))


def _add_contacts(case: Case, api: _Api, model):
    import femodes as fm

    for i, c in enumerate(case.tables("contact")):
        at = _location(c["at"])
        direction = tuple(c["direction"]) if "direction" in c else None
        if c.get("law", "complementarity") == "penalty":
            law = api("contact", ["at", "gap", "stiffness", "direction"], fm.PenaltyContact, at=at, gap=c["gap"],
                      stiffness=c["stiffness"], direction=direction, index=i)
        else:
            law = api("contact", ["at", "gap", "c", "direction"], fm.UnilateralContact, at=at, gap=c["gap"],
                      c=c.get("c"), direction=direction, index=i)
        try:
            model = api("contact", ["at", "gap"], model.with_contact, law, index=i)
        except CaseError as exc:
            if direction is None or "direction=" not in exc.message:
                raise
            # "UnilateralContact(at=...): direction=(...) has 3 components...": about the direction
            raise case.error("contact", "direction", re.sub(r"^\[contact[^\]]*\] ", "", exc.message), i) from None
    return model


def _add_cubic_springs(case: Case, api: _Api, model):
    import femodes as fm

    for i, s in enumerate(case.tables("cubic")):
        law = api("cubic", ["at", "k3"], fm.CubicSpring, at=_location(s["at"]), k3=s["k3"], index=i)
        model = api("cubic", ["at", "k3"], model.with_nonlinearity, law, index=i)
    return model


def _add_forces(case: Case, api: _Api, model):
    import femodes as fm

    for i, f in enumerate(case.tables("force")):
        hf = api("force", ["at", "amplitude", "harmonic", "phase"], fm.HarmonicForce, at=_location(f["at"]),
                 amplitude=f.get("amplitude", 1.0), harmonic=f.get("harmonic", 1), phase=f.get("phase", 0.0), index=i)
        model = api("force", ["at"], model.with_forcing, hf, index=i)
    return model


class OutputFolderError(ValueError):
    """An output folder that cannot be used (a file in the way, no permission)."""


def usable_folder(folder: Path, option: str) -> Path:
    """Create ``folder`` (and parents) and check it is writable, or raise one-sentence
    :class:`OutputFolderError` naming ``option`` and what to change."""
    folder = Path(folder)
    blocker = next((p for p in (folder, *folder.parents) if p.exists() and not p.is_dir()), None)
    if blocker is not None:
        raise OutputFolderError(f"{option} {str(folder)!r}: {str(blocker)!r} is a file, not a folder; "
                                f"choose another {option}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / ".femodes-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OutputFolderError(f"{option} {str(folder)!r} is not writable ({exc.strerror or exc}); "
                                f"choose another {option}") from None
    return folder


def command_out_folder(out: Path | None, default: Path, command: str) -> Path | None:
    """The ``--out`` folder of ``femodes COMMAND`` (``default`` if not given), created and
    writable; else None after printing the one-line error (the command then exits with 2)."""
    try:
        return usable_folder(out if out is not None else default, "--out")
    except OutputFolderError as exc:
        print(f"femodes {command}: {exc}", file=sys.stderr)
        return None


@dataclass
class CaseResult:
    branch: Any
    model: Any
    files: list
    lines: list


def analysis_span(case: Case) -> tuple[float, float]:
    """Continuation parameter span: ``omega``, or ``log10(energy)`` for nonlinear modes."""
    an = case.data["analysis"]
    if an["type"] == "nonlinear_mode":
        a, b = an["energy"]
        if a > 0 and b > 0:
            return math.log10(a), math.log10(b)
        return float(a), float(b)
    a, b = an["omega"]
    return float(a), float(b)


def run_case(case: Case, out: Path, *, progress: bool | Callable = False, checkpoint=None) -> CaseResult:
    """Build the model, run the analysis, write the outputs to ``out``.

    ``progress`` goes to the analysis: ``True`` logs points at INFO, a callable receives every
    accepted continuation point (the command line's :class:`~femodes.app.progress.BranchProgress`).
    ``checkpoint`` (a :class:`femodes.Checkpoint`, optional) journals the points as they are found,
    so that an interrupted run keeps them and the same case run again continues from them
    (``femodes run`` uses ``out/checkpoint.npz``, removed once the outputs are written).
    """
    model, _full = build_model(case)
    branch = _run_analysis(case, model, progress, checkpoint)
    outs = {"plot": True, "branch": "branch.npz", "animation": True, "gif": False}
    outs.update(case.data.get("outputs", {}))
    out.mkdir(parents=True, exist_ok=True)
    files, lines = [], _summary_lines(case, model, branch)
    if outs["branch"]:
        files.append(branch.save(out / outs["branch"]))
    if outs["plot"]:
        files.append(_write_plot(case, model, branch, out))
    _write_animations(model, branch, out, outs, files, lines)
    summary = out / "summary.txt"
    files.append(summary)
    summary.write_text("\n".join(lines) + "\n")
    if checkpoint is not None:  # the outputs hold the branch now: the run's journal is not needed
        Path(checkpoint.path).unlink(missing_ok=True)
    return CaseResult(branch=branch, model=model, files=files, lines=lines)


def _run_analysis(case: Case, model, progress, checkpoint=None):
    """The [analysis] of the case on ``model``: its branch."""
    import femodes as fm
    from ..analyses import frequency_response_options
    from ..floquet import ShootingError

    api = _Api(case)
    an = case.data["analysis"]
    H = api("analysis", "harmonics", fm.Harmonics, an.get("harmonics", 10))
    opts = {}
    if "max_points" in an:
        opts["max_points"] = an["max_points"]
    stability = an.get("stability", False)
    rtol = an.get("rtol")
    try:
        if an["type"] == "nonlinear_mode":
            energy = tuple(an["energy"])
            if an.get("energy_unit") == "grazing":
                eg = api("analysis", ["energy_unit", "mode"], fm.grazing_energy, model, an.get("mode", 1))
                energy = tuple(e * eg for e in energy)
            return api("analysis", ["mode", "energy", "harmonics", "stability", "rtol"], fm.nonlinear_mode, model,
                       an.get("mode", 1), energy=energy, harmonics=H, progress=progress,
                       stability=stability, checkpoint=checkpoint, rtol=rtol)
        options = frequency_response_options(**opts) if opts else None
        return api("analysis", ["omega", "harmonics", "stability", "rtol"], fm.frequency_response, model,
                   tuple(an["omega"]), H, options=options, progress=progress, stability=stability,
                   checkpoint=checkpoint, rtol=rtol)
    except ShootingError as exc:  # stability = "shooting" that does not converge (the message says: use "hill")
        raise case.error("analysis", "stability", str(exc)) from None


def _summary_lines(case: Case, model, branch) -> list[str]:
    """The first lines of summary.txt: case, model and what the branch found (with the error
    estimate: which sources it covers; a grazing family: that it does not predict the resonance)."""
    from ..nonsmooth_modes import family_caveat
    from ..results import ERROR_SOURCES

    lines = [f"case: {case.name}", f"model: {model!r}"]
    lines.append(f"{branch.kind}: {len(branch)} points, success={branch.success} ({branch.message}), "
                 f"w from {branch.omega[0]:.6g} to {branch.omega[-1]:.6g} rad/s (min {branch.omega.min():.6g}, "
                 f"max {branch.omega.max():.6g}), energy {branch.energy.min():.4g}..{branch.energy.max():.4g}")
    if branch.kind == "nonlinear mode":
        lines.append(f"max |xi| (artificial damping) = {abs(branch.xi).max():.2e}")
    if len(branch.folds):
        lines.append(f"folds at w = {', '.join(f'{w:.6g}' for w in branch.omega[list(branch.folds)])}")
    if len(branch) and len(branch.contacts.dofs):
        pen, ten = branch.penetration, branch.tension
        lines.append(f"contact quality (truncated Fourier series, relative): max penetration {np.max(pen):.3g}, "
                     f"max tension {np.max(ten):.3g}")
    if branch.error_estimate is not None:
        acc = branch.accuracy
        met = f", rtol = {acc.rtol:g} met at {int(np.sum(acc.met))} of {len(branch)} points" if acc.rtol else ""
        names = " and ".join(ERROR_SOURCES[k] for k in acc.sources)
        lines.append(f"error estimate ({names}): largest {np.nanmax(branch.error_estimate):.3g}{met}; "
                     f"covers {acc.covers}")
    caveat = family_caveat(branch)
    if caveat:
        lines.append(caveat)
    if branch.internal_resonances:
        ws = ", ".join(f"{t['omega'][0]:.5g}" for t in branch.internal_resonances)
        lines.append(f"internal-resonance tongues stepped over at w = {ws} (branch.internal_resonances)")
    lines.extend(stability_lines(branch))
    return lines


def _fmt_multiplier(mu: complex) -> str:
    """A Floquet multiplier: a real number, or ``a+bj (|mu| = r)``."""
    mu = complex(mu)
    if abs(mu.imag) <= 1e-9 * max(1.0, abs(mu)):
        return f"{mu.real:.6g}"
    return f"{mu.real:.4g}{mu.imag:+.4g}j (|mu| = {abs(mu):.6g})"


def stability_lines(branch) -> list[str]:
    """summary.txt lines on the stability of a branch, none if it was not computed.

    ``stability (shooting): 2 stable, 4 unstable of 6 points`` (the methods used, with their
    point counts when ``"auto"`` mixed them), then ``bifurcations: none`` or
    ``bifurcations: N`` and one line per bifurcation in branch order:
    ``  period_doubling at w = 0.996204 (between points 3 and 4, multiplier -1)``.
    """
    if branch.stable is None:
        return []
    n, n_stable = len(branch), int(sum(bool(s) for s in branch.stable))
    used: dict[str, int] = {}
    for m in branch.stability_method:
        used[str(m)] = used.get(str(m), 0) + 1
    methods = ", ".join(used) if len(used) == 1 else ", ".join(f"{m} at {k} points" for m, k in sorted(used.items()))
    lines = [f"stability ({methods or '-'}): {n_stable} stable, {n - n_stable} unstable of {n} points"]
    if not branch.bifurcations:
        return lines + ["bifurcations: none"]
    lines.append(f"bifurcations: {len(branch.bifurcations)}")
    for b in branch.bifurcations:
        where = f"w = {b.omega:.6g}" + (f", energy {b.energy:.4g}" if branch.kind == "nonlinear mode" else "")
        pos = f"point {b.index}" if b.kind == "fold" else f"between points {b.index} and {b.index + 1}"
        lines.append(f"  {b.kind} at {where} ({pos}, multiplier {_fmt_multiplier(b.multiplier)})")
    return lines


def _write_plot(case: Case, model, branch, out: Path) -> Path:
    """frequency_energy.png (nonlinear mode) or response.png (frequency response) in ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import femodes as fm

    fig, ax = plt.subplots(figsize=(7, 4))
    if case.data["analysis"]["type"] == "nonlinear_mode":
        fm.plot.frequency_energy(branch, ax=ax)
        png = out / "frequency_energy.png"
    else:
        rd = case.data.get("outputs", {}).get("response_dof")
        dof = model.dof(_location(rd)) if rd is not None else model.forces[0].dof
        fm.plot.frequency_amplitude(branch, dof, ax=ax)
        png = out / "response.png"
    ax.set_title(f"{case.path.name}: {branch.kind}")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def _write_animations(model, branch, out: Path, outs: dict, files: list, lines: list) -> None:
    """Animation of the last point (VTK series and/or gif); appends to ``files`` and ``lines``."""
    import femodes as fm

    last = branch[len(branch) - 1]
    if not (outs["animation"] or outs["gif"]):
        return
    if model.fe is None and not getattr(model, "is_reduced", False):
        lines.append("animation skipped: a discrete model has no mesh")
        return
    if outs["animation"]:
        files.append(fm.io.write_animation(last, model, out / "animation", n_frames=24))
    if outs["gif"]:
        try:
            files.append(fm.viz.animate(last, model, out / "animation.gif", n_frames=24))
        except (ImportError, RuntimeError) as exc:
            lines.append(f"gif skipped: {exc}")
