"""Application layer: the study file of a sweep, written atomically by :func:`save_study` after
every finished case and read back by :func:`load_study`.

Layout (``.npz`` arrays or ``.h5`` datasets): ``header`` (JSON: format, version, base case name
and text, parameter paths, every record), plus one array per record field over the cases
(``status``, ``message``, ``branch``, ``max_amplitude``, ``n_stable``, ...) and ``param:<path>`` per
parameter (JSON text of each value) for readers without femodes.

Versions: 2 added the stability columns (``n_stable``, ``stability_method``, ``n_branch_point``,
``n_period_doubling``, ``n_neimark_sacker``, ``n_nonsmooth``; ``-1`` / ``""`` when stability was
not computed). :func:`load_study` reads versions 1 and 2; a version-1 study reads with those
fields at ``-1`` / ``""`` (it has no stability).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from ...store import atomic_write
from .records import INTEGER_FIELDS, NUMERIC_FIELDS, TEXT_FIELDS, CaseRecord, SweepResult

__all__ = ["STUDY_VERSION", "save_study", "load_study", "load_study_header"]

STUDY_VERSION = 2
#: The versions :func:`load_study` reads (see the module docstring).
READABLE_VERSIONS = (1, 2)


def _header(result: SweepResult, text: str) -> dict:
    return {"format": "femodes.Study", "version": STUDY_VERSION, "case": result.case, "case_text": text,
            "parameters": list(result.parameters), "elapsed": result.elapsed,
            "records": [asdict(r) for r in result.cases]}


def _columns(result: SweepResult) -> dict[str, np.ndarray]:
    """One array per record field and per parameter (``param:<path>``, JSON text) over the cases."""
    arrays = {k: np.array([getattr(r, k) for r in result.cases], dtype=int if k in INTEGER_FIELDS else float)
              for k in NUMERIC_FIELDS}
    arrays.update({k: np.array([getattr(r, k) for r in result.cases], dtype=str) for k in TEXT_FIELDS})
    arrays.update({f"param:{p}": np.array([json.dumps(r.parameters.get(p)) for r in result.cases], dtype=str)
                   for p in result.parameters})
    return arrays


def _write_npz(tmp: str, header: dict, arrays: dict[str, np.ndarray]) -> None:
    with open(tmp, "wb") as f:
        np.savez_compressed(f, header=np.array(json.dumps(header)), **arrays)


def _write_h5(tmp: str, header: dict, arrays: dict[str, np.ndarray]) -> None:
    try:
        import h5py
    except ImportError as exc:
        raise ImportError("a .h5 study file needs h5py (pip install 'femodes[store]'); use study.npz") from exc
    with h5py.File(tmp, "w") as f:
        f.attrs["header"] = json.dumps(header)
        for k, v in arrays.items():
            f.create_dataset(k.replace("/", "|"), data=v.astype(object) if v.dtype.kind == "U" else v,
                             dtype=h5py.string_dtype() if v.dtype.kind == "U" else v.dtype)


def save_study(result: SweepResult, *, text: str = "") -> Path:
    """Write ``result.study`` atomically (temporary file + ``os.replace``).

    ``text`` is the base case file's text, kept in the header. Layout: see the module docstring.
    """
    path = Path(result.study)
    path.parent.mkdir(parents=True, exist_ok=True)
    header, arrays = _header(result, text), _columns(result)
    writer = _write_npz if path.suffix.lower() == ".npz" else _write_h5
    atomic_write(path, lambda tmp: writer(tmp, header, arrays))  # readers never see a half-written study
    return path


def _read_header(path: Path) -> dict:
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as f:
                return json.loads(str(f["header"]))
        import h5py

        with h5py.File(path, "r") as f:
            return json.loads(f.attrs["header"])
    except Exception as exc:  # noqa: BLE001 - any unreadable file gets the same message
        raise ValueError(f"load_study: {str(path)!r} is not a readable femodes study file ({exc})") from exc


def load_study_header(path) -> dict:
    """The JSON header of a study file (format, version, base case name and text, parameter
    paths, every record), checked like :func:`load_study` checks it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"load_study: no such file {str(path)!r}")
    header = _read_header(path)
    if not isinstance(header, dict) or header.get("format") != "femodes.Study":
        raise ValueError(f"load_study: {str(path)!r} is not a femodes study file")
    if header.get("version") not in READABLE_VERSIONS:
        raise ValueError(f"load_study: {str(path)!r} has study version {header.get('version')}, this femodes reads "
                         f"versions {', '.join(map(str, READABLE_VERSIONS))}")
    for key in ("records", "parameters"):
        if not isinstance(header.get(key), list):
            raise ValueError(f"load_study: {str(path)!r} is incomplete or damaged: its header has no list {key!r}")
    known = {f.name for f in fields(CaseRecord)}
    for r in header["records"]:
        if not isinstance(r, dict) or not {"id", "parameters", "status"} <= set(r) or not set(r) <= known:
            raise ValueError(f"load_study: {str(path)!r} is incomplete or damaged: a record is {r!r}, not the "
                             f"fields of a CaseRecord")
    return header


def load_study(path) -> SweepResult:
    """Read a study file written by :func:`~femodes.app.sweep.run_sweep`; branches via
    ``result.load_branch(i)``."""
    path = Path(path)
    header = load_study_header(path)
    recs = tuple(CaseRecord(**r) for r in header["records"])
    return SweepResult(cases=recs, parameters=tuple(header["parameters"]), study=path, case=header.get("case", ""),
                       elapsed=header.get("elapsed", math.nan))
