"""Results layer: reading a branch file (:func:`load_branch`), its schema checked field by field
first, so that a damaged or foreign file gives one ValueError naming what is wrong."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..hbm.harmonics import Harmonics
from ..store import read_record
from .bifurcation import Bifurcation
from .branch import FORMAT_VERSION, Branch
from .contacts import ContactInfo
from .error_estimate import ErrorEstimate

__all__ = ["load_branch"]



#: What a branch file holds (:func:`.branch_record.branch_header`, :func:`.branch_record.branch_arrays`):
#: header fields and their types, and the arrays over the points with their number of dimensions.
_HEADER_FIELDS = {"kind": str, "harmonics": list, "contacts": dict, "success": bool, "status": int, "message": str}
_CONTACT_FIELDS = ("kinds", "dofs", "gaps", "stiffness", "slots", "c")
_POINT_ARRAYS = {"omega": 1, "Q": 3, "P": 3, "energy": 1, "xi": 1, "residual_norm": 1, "nit": 1, "parameter": 1}
_ACCURACY_ARRAYS = ("omega", "amplitude", "penetration", "tension", "harmonics", "rate")
_STABILITY_ARRAYS = ("stable", "multipliers_re", "multipliers_im", "bif_index", "bif_real", "bif_Q", "bif_P")


def _check_schema(header: dict, arrays: dict, path: Path) -> None:
    """One ValueError naming the first missing or malformed field of a branch file (a file that
    reads but lacks a field would otherwise fail later as a KeyError or AttributeError)."""
    def bad(what: str):
        raise ValueError(f"load_branch: {str(path)!r} is incomplete or damaged: {what}; it cannot be read as a "
                         "branch (save it again with Branch.save)")

    for key, typ in _HEADER_FIELDS.items():
        if key not in header:
            bad(f"its header has no {key!r}")
        if not isinstance(header[key], typ) or (typ is int and isinstance(header[key], bool)):
            bad(f"header field {key!r} is {header[key]!r}, not a {typ.__name__}")
    h = header["harmonics"]
    if len(h) != 3 or not all(isinstance(v, int) and not isinstance(v, bool) for v in h):
        bad(f"header field 'harmonics' is {h!r}, not [n_harmonics, n_time, subharmonic]")
    ct = header["contacts"]
    for key in _CONTACT_FIELDS:
        if not isinstance(ct.get(key), list):
            bad(f"header field 'contacts' has no list {key!r}")
    if len({len(ct[k]) for k in _CONTACT_FIELDS}) != 1:
        bad("the lists of header field 'contacts' differ in length")
    for key in ("meta", "accuracy", "stability", "model"):
        if header.get(key) is not None and not isinstance(header[key], dict):
            bad(f"header field {key!r} is {header[key]!r}, not a dict")
    for key, ndim in {**_POINT_ARRAYS, "folds": 1}.items():
        if key not in arrays:
            bad(f"it has no array {key!r}")
        if np.ndim(arrays[key]) != ndim:
            bad(f"array {key!r} has {np.ndim(arrays[key])} dimensions, not {ndim}")
    n = arrays["omega"].shape[0]
    for key in list(_POINT_ARRAYS) + (["omega_truncated"] if "omega_truncated" in arrays else []):
        if arrays[key].shape[0] != n:
            bad(f"array {key!r} has {arrays[key].shape[0]} points, 'omega' {n}")
    try:
        nc = Harmonics(*h).n_coef
    except (TypeError, ValueError) as exc:
        bad(f"header field 'harmonics' is {h!r} ({exc})")
    n_uc = sum(k == "complementarity" for k in ct["kinds"])
    if arrays["Q"].shape[1] != nc or arrays["P"].shape[1] != nc or arrays["P"].shape[2] != n_uc:
        bad(f"arrays 'Q' {arrays['Q'].shape} and 'P' {arrays['P'].shape} do not fit {h[0]} harmonics "
            f"({nc} coefficients) and {n_uc} complementarity contacts")
    if any(not 0 <= d < arrays["Q"].shape[2] for d in ct["dofs"]):
        bad(f"a contact DOF of {ct['dofs']} is outside the {arrays['Q'].shape[2]} DOFs of 'Q'")
    acc = header.get("accuracy")
    if acc is not None:
        for key in ("method", "rtol"):
            if key not in acc:
                bad(f"header field 'accuracy' has no {key!r}")
        for key in _ACCURACY_ARRAYS:
            if f"accuracy_{key}" not in arrays:
                bad(f"it has an error estimate but no array 'accuracy_{key}'")
    stab = header.get("stability")
    if stab is not None:
        for key in ("methods", "kinds"):
            if not isinstance(stab.get(key), list):
                bad(f"header field 'stability' has no list {key!r}")
        for key in _STABILITY_ARRAYS:
            if key not in arrays:
                bad(f"it has stability but no array {key!r}")
        if len(stab["kinds"]) != len(arrays["bif_index"]) or arrays["bif_real"].shape[1:] != (6,):
            bad(f"its {len(stab['kinds'])} bifurcation kinds do not match arrays 'bif_index' and 'bif_real'")
        loc = stab.get("located")
        if loc is not None and (not isinstance(loc, list) or len(loc) != len(stab["kinds"])):
            bad(f"header field 'stability' has a 'located' that is not a list of {len(stab['kinds'])} flags")


def load_branch(path, model=None) -> Branch:
    """Read a branch written by :meth:`Branch.save`; ``model`` optionally re-attached."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"load_branch: no such file {str(path)!r}")
    try:
        header, arrays = read_record(path)
    except ValueError as exc:
        raise ValueError(f"load_branch: {str(path)!r} is not a readable femodes branch file ({exc})") from exc
    if not isinstance(header, dict) or header.get("format") != "femodes.Branch":
        raise ValueError(f"load_branch: {str(path)!r} is not a femodes branch file")
    if header.get("version") != FORMAT_VERSION:
        raise ValueError(
            f"load_branch: {str(path)!r} has format version {header.get('version')}, this femodes reads version {FORMAT_VERSION}"
        )
    _check_schema(header, arrays, path)
    H, N, nu = header["harmonics"]
    br = Branch(
        kind=header["kind"], harmonics=Harmonics(H, N, nu), contacts=ContactInfo.from_json(header["contacts"]),
        omega=arrays.get("omega_truncated", arrays["omega"]), Q=arrays["Q"], P=arrays["P"], energy=arrays["energy"], xi=arrays["xi"],
        residual_norm=arrays["residual_norm"], nit=arrays["nit"], parameter=arrays["parameter"],
        folds=arrays["folds"].tolist(), success=header["success"], status=header["status"], message=header["message"],
        meta=header.get("meta"),
    )
    sig = header.get("model")
    if not isinstance(sig, dict):  # older files: the finished branch of a checkpointed run has a fingerprint
        ck = (header.get("meta") or {}).get("checkpoint")
        sig = ck.get("model") if isinstance(ck, dict) and isinstance(ck.get("model"), dict) else None
    br.model_signature = sig
    acc = header.get("accuracy")
    if acc is not None:
        br = br.with_accuracy(ErrorEstimate(**{k: arrays[f"accuracy_{k}"] for k in ("omega", "amplitude", "penetration",
                                                                                "tension", "harmonics", "rate")},
                                           method=np.asarray(acc["method"], dtype=str), rtol=acc["rtol"],
                                           mesh_method=acc.get("mesh_method"), caveat=acc.get("caveat"),
                                           **{k: arrays[f"accuracy_{k}"] for k in ("omega_limit", "omega_limit_error",
                                                                                   "finest", "mesh", "amplitude_limit",
                                                                                   "amplitude_limit_error")
                                              if f"accuracy_{k}" in arrays}))
    stab = header.get("stability")
    if stab is not None:
        located = stab.get("located", [True] * len(stab["kinds"]))  # older files: every bifurcation located
        brackets = arrays.get("bif_bracket", np.full((len(stab["kinds"]), 2), np.nan))  # older files: not stated
        bifs = [Bifurcation(kind=k, index=int(i), omega=float(r[0]), energy=float(r[1]), parameter=float(r[2]),
                            multiplier=complex(r[3], r[4]), xi=float(r[5]), Q=q, P=p, located=bool(loc),
                            bracket=(float(w[0]), float(w[1])))
                for k, i, r, q, p, loc, w in zip(stab["kinds"], arrays["bif_index"], arrays["bif_real"],
                                                 arrays["bif_Q"], arrays["bif_P"], located, brackets)]
        br = br.with_stability(stable=arrays["stable"].astype(bool),
                               multipliers=arrays["multipliers_re"] + 1j * arrays["multipliers_im"], bifurcations=bifs,
                               methods=stab["methods"], tol=float(br.meta.get("stability_tol", 1e-4)),
                               checked=int(br.meta.get("stability_checked", 0)),
                               unconverged=br.meta.get("stability_unconverged", ()))
    if model is not None:
        br.attach(model)
    return br
