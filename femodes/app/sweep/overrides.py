"""Application layer: the parameters of a sweep and the case text of each case.

A parameter is a dotted path into the case file: ``table.key`` for plain tables
(``analysis.harmonics``, ``mesh.n_elements``, ``damping.alpha``) and ``table.index.key`` for
``[[...]]`` tables (``contact.0.gap``, ``force.0.amplitude``). :func:`sweep_cases` makes the list
of ``{path: value}`` overrides, :func:`apply_overrides` applies one to a parsed case, and
:func:`case_text` writes the result as TOML (:func:`to_toml`, the subset that case files use;
``tomllib`` only reads) with the outputs every sweep case saves. :func:`parse_set` reads the
command line's ``--set PATH=V1,V2`` syntax.
"""

from __future__ import annotations

import itertools
import json
import math
import re
from pathlib import Path
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np

from ..cases import ARRAY_TABLES, SCHEMA, Case, schema_type_error

__all__ = ["CASE_OUTPUTS", "apply_overrides", "sweep_cases", "parse_set", "case_text", "to_toml"]

# Outputs of every sweep case: the branch only (plots and animations of many cases would cost
# more than the analyses; rerun one case with ``femodes run out/cases/<id>/case.toml`` for them).
CASE_OUTPUTS = {"plot": False, "branch": "branch.npz", "animation": False, "gif": False}


# ---------------------------------------------------------------------------------------------
# Parameter paths and values
# ---------------------------------------------------------------------------------------------
def _plain(v: Any, where: str) -> Any:
    """``v`` as a TOML-representable Python value (numpy scalars and arrays converted)."""
    if isinstance(v, np.ndarray):
        v = v.tolist()
    elif isinstance(v, np.generic):
        v = v.item()
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    if isinstance(v, (list, tuple)):
        return [_plain(x, where) for x in v]
    if isinstance(v, Mapping):
        return {str(k): _plain(x, where) for k, x in v.items()}
    raise TypeError(f"parameters: value {v!r} of {where!r} is not a number, string, boolean, list or table")


def _parse_path(path: Any) -> tuple[str, int | None, str]:
    """``"contact.0.gap"`` -> ``("contact", 0, "gap")``; ValueError naming the path otherwise."""
    if not isinstance(path, str):
        raise TypeError(f"parameters: a parameter path must be a string like 'contact.0.gap', got {path!r}")
    parts = path.split(".")
    tables = ", ".join(f"{t}.<index>" if t in ARRAY_TABLES else t for t in SCHEMA)
    if parts[0] not in SCHEMA:
        raise ValueError(f"parameters: unknown table {parts[0]!r} in path {path!r}; valid tables are {tables}")
    table = parts[0]
    keys = ", ".join(SCHEMA[table])
    if table in ARRAY_TABLES:
        if len(parts) != 3 or not re.fullmatch(r"\d+", parts[1]):
            raise ValueError(f"parameters: path {path!r} must look like '{table}.<index>.<key>' ([[{table}]] is a "
                             f"list of tables; index 0 is the first), with a key among {keys}")
        index, key = int(parts[1]), parts[2]
    else:
        if len(parts) != 2:
            raise ValueError(f"parameters: path {path!r} must look like '{table}.<key>' with a key among {keys}")
        index, key = None, parts[1]
    if key not in SCHEMA[table]:
        raise ValueError(f"parameters: unknown key {key!r} in path {path!r}; valid keys of [{table}] are {keys}")
    if table == "outputs" and key in CASE_OUTPUTS:
        raise ValueError(f"parameters: path {path!r} is set by the sweep (each case saves its branch only)")
    return table, index, key


def apply_overrides(data: Mapping, overrides: Mapping[str, Any]) -> dict:
    """Copy of a parsed case dict with ``{path: value}`` overrides applied (``None`` removes a key).

    Raises ValueError naming the path if it does not address the case (unknown table or key, or a
    ``[[table]]`` index beyond the tables of the case).
    """
    new = json.loads(json.dumps(data))  # deep copy of plain TOML data
    for path, value in overrides.items():
        table, index, key = _parse_path(path)
        value = _plain(value, path)
        if index is None:
            tab = new.setdefault(table, {})
        else:
            tabs = new.get(table, [])
            if isinstance(tabs, dict):
                tabs = new[table] = [tabs]
            if index >= len(tabs):
                raise ValueError(f"parameters: path {path!r} addresses [[{table}]] number {index + 1} but the case has "
                                 f"{len(tabs)} [[{table}]] table{'s' if len(tabs) != 1 else ''} (indices start at 0)")
            tab = tabs[index]
        if value is None:
            tab.pop(key, None)
        else:
            tab[key] = value
    return new


def _product_cases(parameters: Mapping[str, Sequence]) -> list[dict]:
    """``{path: [values]}`` -> the Cartesian product, first path varying slowest."""
    if not parameters:
        raise ValueError("parameters: give at least one parameter path with a list of values")
    lists = []
    for path, values in parameters.items():
        _parse_path(path)
        if isinstance(values, (str, bytes, Mapping)) or not isinstance(values, (Sequence, np.ndarray)):
            raise TypeError(f"parameters: the values of {path!r} must be a list, got {values!r} (a pair like "
                            f"omega is one value: {{'analysis.omega': [[0.5, 2.0], [0.5, 1.5]]}})")
        if len(values) == 0:
            raise ValueError(f"parameters: {path!r} has an empty list of values")
        lists.append([_plain(v, path) for v in values])
    return [dict(zip(parameters, combo)) for combo in itertools.product(*lists)]


def _listed_cases(parameters: Sequence[Mapping[str, Any]]) -> list[dict]:
    """An explicit ``[{path: value}, ...]``, checked and converted to plain values."""
    if isinstance(parameters, (str, bytes)) or not isinstance(parameters, Sequence):
        raise TypeError(f"parameters: expected {{path: [values]}} or a list of {{path: value}} dicts, got "
                        f"{type(parameters).__name__}")
    if not parameters:
        raise ValueError("parameters: the list of cases is empty")
    out = []
    for i, p in enumerate(parameters):
        if not isinstance(p, Mapping):
            raise TypeError(f"parameters: case {i} must be a {{path: value}} dict, got {p!r}")
        for path in p:
            _parse_path(path)
        out.append({path: _plain(v, path) for path, v in p.items()})
    return out


def sweep_cases(parameters: Mapping[str, Sequence] | Sequence[Mapping[str, Any]]) -> list[dict]:
    """The list of ``{path: value}`` overrides of a sweep.

    ``parameters`` is either ``{path: [values, ...]}`` (the Cartesian product, first path varying
    slowest) or an explicit sequence of ``{path: value}`` dicts. Paths are checked for syntax here
    and against the case in :func:`apply_overrides`.
    """
    if isinstance(parameters, Mapping):
        return _product_cases(parameters)
    return _listed_cases(parameters)


def case_text(base: Case, overrides: Mapping[str, Any]) -> str:
    """TOML text of the base case with ``overrides`` applied, as it runs from ``out/cases/<id>/``:
    a relative mesh file resolved against the base case's folder, outputs :data:`CASE_OUTPUTS`."""
    data = apply_overrides(base.data, overrides)
    mesh = data.get("mesh")
    if isinstance(mesh, dict) and isinstance(mesh.get("file"), str) and not Path(mesh["file"]).is_absolute():
        # the case runs from out/cases/<id>/: resolve the mesh against the base case's folder
        mesh["file"] = str((base.path.parent / mesh["file"]).resolve())
    outputs = {k: v for k, v in data.get("outputs", {}).items() if k not in CASE_OUTPUTS}
    data["outputs"] = {**outputs, **CASE_OUTPUTS}
    return to_toml(data)


# ---------------------------------------------------------------------------------------------
# The command line's --set PATH=V1,V2
# ---------------------------------------------------------------------------------------------
def _split_top(text: str) -> list[str]:
    """Split at commas outside brackets, braces and quotes."""
    items, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append("".join(cur))
            cur = []
            continue
        cur.append(ch)
    items.append("".join(cur))
    return [i.strip() for i in items]


def parse_set(text: str) -> tuple[str, list]:
    """``"contact.0.gap=0.005,0.01"`` -> ``("contact.0.gap", [0.005, 0.01])`` (the ``--set`` syntax).

    Values are TOML values separated by commas outside brackets (``analysis.omega=[0.5,2],[1,2]``
    is two pairs); a bare word is a string (``force.0.at=tip``). Raises ValueError with a message
    for the command line.
    """
    import tomllib

    if not isinstance(text, str) or "=" not in text:
        raise ValueError(f"--set {text!r}: expected PATH=VALUE[,VALUE...], e.g. contact.0.gap=0.005,0.01")
    path, _, rhs = text.partition("=")
    path = path.strip()
    if not path or not rhs.strip():
        raise ValueError(f"--set {text!r}: expected PATH=VALUE[,VALUE...], e.g. contact.0.gap=0.005,0.01")
    table, _, key = _parse_path(path)
    values = []
    for item in _split_top(rhs):
        if not item:
            raise ValueError(f"--set {text!r}: empty value (two commas in a row, or a trailing comma?)")
        try:
            values.append(tomllib.loads(f"v = {item}")["v"])
        except tomllib.TOMLDecodeError:
            if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", item):
                raise ValueError(f"--set {text!r}: cannot read value {item!r} (numbers, true/false, \"text\", "
                                 f"[lists] or plain names)") from None
            values.append(item)
    for v in values:  # a value of the wrong type is a --set mistake (exit 2), found before any case runs
        why = schema_type_error(table, key, v)
        if why:
            raise ValueError(f"--set {text!r}: {why}")
    return path, values


# ---------------------------------------------------------------------------------------------
# TOML writer (the subset that case files use; tomllib only reads)
# ---------------------------------------------------------------------------------------------
_BARE = re.compile(r"[A-Za-z0-9_\-]+")


def _toml_key(k: str) -> str:
    return k if _BARE.fullmatch(k) else json.dumps(k)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return repr(v)  # shortest round-trip repr; 'inf', '1e-05', '1e+16' are valid TOML floats
    if isinstance(v, str):
        return json.dumps(v)  # JSON string escapes are TOML basic-string escapes
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    raise TypeError(f"to_toml: cannot write {v!r} ({type(v).__name__})")


def to_toml(data: Mapping) -> str:
    """TOML text of a case dict (``tomllib.loads(to_toml(d)) == d`` for case-file data)."""
    lines = []
    for name, value in data.items():
        tabs = value if isinstance(value, list) else [value]
        for tab in tabs:
            if not isinstance(tab, Mapping):
                raise TypeError(f"to_toml: [{name}] must be a table, got {tab!r}")
            lines.append(f"[[{_toml_key(name)}]]" if isinstance(value, list) else f"[{_toml_key(name)}]")
            lines.extend(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in tab.items())
            lines.append("")
    return "\n".join(lines)
