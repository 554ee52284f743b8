"""Application layer: the model of a checked case (FE or discrete model, damping, contacts,
springs, forces, reduction) built with the public API; every ValueError or TypeError of femodes
becomes a :class:`~femodes.app.cases.schema.CaseError` at the responsible key."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any
from collections.abc import Callable

from .schema import Case, CaseError, fmt_value, suggest
from ...solvers.checks import named_by

__all__ = ["CaseApi", "build_model", "as_location", "discrete_model", "case_mesh", "fe_model", "add_damping",
           "add_contacts", "add_cubic_springs", "add_forces"]


def as_location(v: Any):
    return tuple(v) if isinstance(v, list) else v


def _guess_key(message: str, keys) -> str | None:
    """The key named first in ``message`` ("K has shape ... (M is 1x1)" is about K, not M)."""
    best, pos = None, None
    for k in keys:
        m = re.search(rf"\b{re.escape(k)}\b", message)
        if m and (pos is None or m.start() < pos):
            best, pos = k, m.start()
    return best


class CaseApi:
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
                msg += suggest(m.group(1), re.findall(r"'([^']*)'", m.group(2)))
            key = _guess_key(msg, [k for k in keys if k]) or (keys[0] if keys else None)
            if table is None:
                raise CaseError(msg, self.case.name) from None
            raise self.case.error(table, key, msg, index) from None


def build_model(case: Case):
    """Model of the case: FE or discrete model, damping, contacts, springs, forces, reduction.

    Returns ``(model, full)``: the model to analyse (reduced if [reduction]) and the full model.
    """
    api = CaseApi(case)
    d = case.data
    model = discrete_model(case, api) if d["model"]["kind"] == "discrete" else fe_model(case, api)
    model = add_damping(case, api, model)
    model = add_contacts(case, api, model)
    model = add_cubic_springs(case, api, model)
    model = add_forces(case, api, model)
    full = model
    if "reduction" in d and "craig_bampton" in d["reduction"]:
        import femodes as fm

        model = api("reduction", "craig_bampton", fm.craig_bampton, model, d["reduction"]["craig_bampton"])
    if "outputs" in d and "response_dof" in d["outputs"]:
        api("outputs", "response_dof", _response_dof, model, as_location(d["outputs"]["response_dof"]))
    return model, full


def discrete_model(case: Case, api: CaseApi):
    """[model] kind = "discrete": a StructuralModel from M, K (and C, dof_names)."""
    import numpy as np

    import femodes as fm

    m = case.data["model"]

    def matrix(k):
        v = m[k]
        if isinstance(v, list) and (not v or len({len(r) for r in v}) != 1 or len(v) != len(v[0])):
            raise case.error("model", k, f"{k} must be a square matrix like [[1.0, 0.0], [0.0, 1.0]] (n rows of "
                             f"n numbers), got {fmt_value(v)}")
        return np.atleast_2d(np.asarray(v, dtype=float))

    args = dict(M=matrix("M"), K=matrix("K"), C=matrix("C") if "C" in m else None, dof_names=m.get("dof_names"))
    return api("model", ["M", "K", "C", "dof_names"], fm.StructuralModel, **args)


def case_mesh(case: Case, api: CaseApi):
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


def fe_model(case: Case, api: CaseApi):
    """[model] kind = "beam" | "bar" | "solid" on the mesh of [mesh]."""
    import femodes as fm

    m = case.data["model"]
    mesh = case_mesh(case, api)
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


def add_damping(case: Case, api: CaseApi, model):
    if "damping" not in case.data:
        return model
    dm = case.data["damping"]
    if "modal" in dm:
        if "alpha" in dm or "beta" in dm:
            raise case.error("damping", "modal", "give either Rayleigh alpha/beta or modal, not both")
        return api("damping", "modal", model.with_damping, modal=dm["modal"])
    return api("damping", list(dm), model.with_damping, alpha=dm.get("alpha", 0.0), beta=dm.get("beta", 0.0))


def add_contacts(case: Case, api: CaseApi, model):
    import femodes as fm

    for i, c in enumerate(case.tables("contact")):
        at = as_location(c["at"])
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


def add_cubic_springs(case: Case, api: CaseApi, model):
    import femodes as fm

    for i, s in enumerate(case.tables("cubic")):
        law = api("cubic", ["at", "k3"], fm.CubicSpring, at=as_location(s["at"]), k3=s["k3"], index=i)
        model = api("cubic", ["at", "k3"], model.with_nonlinearity, law, index=i)
    return model


def add_forces(case: Case, api: CaseApi, model):
    import femodes as fm

    for i, f in enumerate(case.tables("force")):
        hf = api("force", ["at", "amplitude", "harmonic", "phase"], fm.HarmonicForce, at=as_location(f["at"]),
                 amplitude=f.get("amplitude", 1.0), harmonic=f.get("harmonic", 1), phase=f.get("phase", 0.0), index=i)
        model = api("force", ["at"], model.with_forcing, hf, index=i)
    return model


def _response_dof(model, at) -> int:
    """The DOF of ``[outputs] response_dof``, its errors named after the key."""
    with named_by("response_dof"):
        return model.dofmap.find(at)
