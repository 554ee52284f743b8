"""Application layer: the schema of case files (tables, keys and their types), the error type
that points at a line of the file, and the checked :class:`Case`; the type checks of one value."""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: The checkpoint of `femodes run` in its output folder (journal CHECKPOINT_NAME.points/ while it
#: runs; removed when the outputs are written): an interrupted run is resumed by the same command.
CHECKPOINT_NAME = "checkpoint.npz"

__all__ = ["CaseError", "Case", "SCHEMA", "ARRAY_TABLES", "MODEL_KINDS", "LINE_MESH_KEYS", "SOLID_MESH_KEYS",
           "SOLID_DIVISIONS", "ANALYSES", "TYPE_TEXT", "key_line", "schema_type_error", "check_type", "all_finite",
           "fmt_value", "is_number", "suggest"]

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


def fmt_value(v: Any) -> str:
    return repr(v) if isinstance(v, str) else str(v).lower() if isinstance(v, bool) else str(v)


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def check_type(v: Any, kind: str) -> bool:
    if kind == "number":
        return is_number(v)
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
        return isinstance(v, list) and len(v) == 2 and all(is_number(x) for x in v)
    if kind == "vector":
        return isinstance(v, list) and 1 <= len(v) <= 3 and all(is_number(x) for x in v)
    if kind == "string or list":
        return isinstance(v, str) or (isinstance(v, list) and all(isinstance(x, str) for x in v))
    if kind == "string or false":
        return isinstance(v, str) or v is False
    if kind == "number or list":
        return is_number(v) or (isinstance(v, list) and all(is_number(x) for x in v))
    if kind == "list":
        return isinstance(v, list)
    if kind == "matrix":
        return is_number(v) or (isinstance(v, list) and all(
            isinstance(r, list) and all(is_number(x) for x in r) for r in v))
    if kind == "location":
        return ((isinstance(v, int) and not isinstance(v, bool)) or isinstance(v, str)
                or (isinstance(v, list) and len(v) == 2 and all(isinstance(x, str) for x in v)))
    return True


def schema_type_error(table: str, key: str, value: Any) -> str:
    """Why ``value`` cannot be ``[table] key`` by its type (``"gap must be a number, got 'abc'"``),
    ``""`` if it can; the type checks of :func:`parse_case` (values are checked there too)."""
    kind = SCHEMA[table][key]
    if not check_type(value, kind):
        return f"{key} must be {TYPE_TEXT[kind]}, got {fmt_value(value)}"
    if not all_finite(value):
        return f"{key} must be finite (no nan or inf), got {fmt_value(value)}"
    return ""


def all_finite(v: Any) -> bool:
    """False if ``v`` is (or contains, in lists and inline tables) a nan or inf float."""
    if isinstance(v, float):
        return math.isfinite(v)
    if isinstance(v, list):
        return all(all_finite(x) for x in v)
    if isinstance(v, dict):
        return all(all_finite(x) for x in v.values())
    return True


TYPE_TEXT = {
    "number": "a number", "integer": "an integer", "string": "a string", "boolean": "true or false",
    "boolean or method": "true, false or a method name (\"auto\", \"hill\", \"shooting\")",
    "table": "a table like { name = value }", "pair": "a pair [start, end] of numbers",
    "vector": "a vector of 1 to 3 numbers like [1.0, 0.0]",
    "string or list": "a name or a list of names", "string or false": "a file name or false",
    "number or list": "a number or a list of numbers", "list": "a list",
    "matrix": "a matrix like [[1.0, 0.0], [0.0, 1.0]]",
    "location": "a location: a name like \"tip\", a pair like [\"tip\", \"w\"] or a DOF index",
}


def suggest(word: str, options) -> str:
    close = difflib.get_close_matches(word, list(options), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""
