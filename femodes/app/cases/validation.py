"""Application layer: reading and checking a case file (TOML syntax, tables, keys, types, and the
values across keys and tables), in the order the first mistake is reported."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path, PurePosixPath, PureWindowsPath

from .schema import (ANALYSES, ARRAY_TABLES, CHECKPOINT_NAME, LINE_MESH_KEYS, MODEL_KINDS, SCHEMA, SOLID_DIVISIONS,
                     SOLID_MESH_KEYS, TYPE_TEXT, Case, CaseError, all_finite, check_type, fmt_value, key_line, suggest)

__all__ = ["parse_case", "load_case"]


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
            raise case.error(None, None, f"unknown table [{tname}]{suggest(tname, SCHEMA)}; "
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
                    raise case.error(tname, key, f"unknown key {key!r}{suggest(key, SCHEMA[tname])}; valid keys "
                                     f"are {', '.join(SCHEMA[tname])}", i)
                kind = SCHEMA[tname][key]
                if not check_type(v, kind):
                    raise case.error(tname, key, f"{key} must be {TYPE_TEXT[kind]}, got {fmt_value(v)}", i)
                if not all_finite(v):
                    # TOML has nan and inf; no key of the schema accepts them
                    raise case.error(tname, key, f"{key} must be finite (no nan or inf), got {fmt_value(v)}", i)
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
                         f"{suggest(kind, MODEL_KINDS)}")
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
                         f"{suggest(plane, ('stress', 'strain'))}")
    if "thickness" in model and not model["thickness"] > 0:
        raise case.error("model", "thickness", f"thickness must be > 0, got {fmt_value(model['thickness'])}")
    for loc, comps in model.get("supports", {}).items():
        if not (isinstance(comps, str) or (isinstance(comps, list) and comps
                                           and all(isinstance(c, str) for c in comps))):
            raise case.error("model", "supports", f"supports must be a table like {{ bottom = \"u_y\" }} (a component "
                             f"name or a list of them per location), got {loc} = {fmt_value(comps)}")


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
            raise case.error("mesh", k, f"{k} must be > 0, got {fmt_value(mesh[k])}")
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
            raise case.error("contact", "gap", f"gap must be >= 0, got {fmt_value(c['gap'])}", i)
        law = c.get("law", "complementarity")
        if law not in ("complementarity", "penalty"):
            raise case.error("contact", "law", f"law must be \"complementarity\" or \"penalty\", got {law!r}"
                             f"{suggest(law, ('complementarity', 'penalty'))}", i)
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
                         f"{typ!r}{suggest(typ, ANALYSES)}")
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
        from ...floquet import METHODS  # "auto", "hill", "shooting"; true is "auto"

        if st not in METHODS:
            raise case.error("analysis", "stability", f"stability must be true, false or one of "
                             f"{', '.join(map(repr, METHODS))}, got {st!r}{suggest(st, METHODS)}")
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
        from ...hbm.harmonics import Harmonics

        try:
            Harmonics(an["harmonics"])
        except (TypeError, ValueError) as exc:
            raise case.error("analysis", "harmonics", f"harmonics = {an['harmonics']}: {exc}") from None


def _check_outputs(case: Case) -> None:
    outs = case.data.get("outputs", {})
    name = outs.get("branch")
    if isinstance(name, str) and not name.strip():
        raise case.error("outputs", "branch", "branch must be a file name like \"branch.npz\" (or false), got ''")
    if isinstance(name, str) and (PurePosixPath(name).name != name or PureWindowsPath(name).name != name):
        # a path: written outside the output folder, where the run's report says the outputs are
        raise case.error("outputs", "branch", f"branch must be a file name like \"branch.npz\", written in the "
                         f"output folder (choose it with --out), got {name!r}")
    if isinstance(name, str):
        from ...store import RECORD_SUFFIXES

        # checked before the run: after it, a bad name ended in a traceback and the run's points were removed
        if PurePosixPath(name).suffix.lower() not in RECORD_SUFFIXES:
            raise case.error("outputs", "branch", f"branch must end in {', '.join(RECORD_SUFFIXES)} (a .npz or HDF5 "
                             f"file), got {name!r}")
        if name.lower() == CHECKPOINT_NAME:  # the run's checkpoint, removed once the outputs are written
            raise case.error("outputs", "branch", f"branch = {name!r} is the name of the run's own checkpoint "
                             "in the output folder; choose another name, like \"branch.npz\"")


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
