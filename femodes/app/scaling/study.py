"""Application layer: the scaling study of a case file, case by case.

:func:`scaling_study` checks its arguments, makes one copy of the case per mesh size and ``H``
(a mesh size is a number of elements of a line mesh, ``elements``, or a refinement factor of the
case's own mesh, ``refine``: ``[mesh] n_elements`` of a line mesh, ``nx, ny, nz`` of a solid's
rectangle or box), measures each in its own process (:mod:`.child`) and rewrites ``scaling.csv`` and
``scaling.json`` after every case (:mod:`.report`), so an interrupted study (Ctrl-C) keeps what
it has measured; a case that fails is recorded with its error and the study goes on.
:func:`positive_int_list` and :func:`positive_float_list` read the lists of sizes of the command
line.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import numbers
import os
import platform
from pathlib import Path
from typing import Any
from collections.abc import Sequence

import numpy as np

from ...solvers.checks import check_int, named_by
from ..cases import SOLID_DIVISIONS, Case, load_case
from ..progress import ProgressBar
from .child import run_child as _run_child  # a module global, looked up per case: tests replace it
from .records import ScalingRecord, ScalingResult
from .report import fit_exponents, plot_scaling, write_tables

__all__ = ["scaling_study", "positive_int_list", "positive_float_list", "refined_divisions"]

log = logging.getLogger(__name__)


def scaling_study(
    case: Case | str | Path,
    *,
    elements: Sequence[int] | None = None,
    refine: Sequence[float] | None = None,
    harmonics: Sequence[int] | None = None,
    repeat: int = 3,
    points: int = 5,
    out: str | Path = "out/scaling",
    timeout: float | None = None,
    progress: bool = False,
) -> ScalingResult:
    """Time per Newton iteration and per continuation point, and peak memory, against N and H.

    Every pair of ``elements`` x ``harmonics`` is measured in a fresh process (:mod:`~femodes.app.scaling.child`);
    ``out/scaling.csv`` and ``.json`` are rewritten after every case, ``scaling.png`` drawn at the end.

    Parameters
    ----------
    case : Case, str or Path
        A case file (:func:`femodes.app.cases.load_case`) or its path.
    elements : sequence of int, optional
        Values of ``[mesh] n_elements`` (line meshes only). Default: the case's own mesh (only H varies).
    refine : sequence of float, optional
        Refinement factors of the case's own generated mesh (instead of ``elements``): every element
        division is multiplied by the factor and rounded (at least 1; :func:`refined_divisions`).
    harmonics : sequence of int, optional
        Values of ``[analysis] harmonics``. Default: the case's own (10 if not given).
    repeat : int, default 3
        Repetitions of the timed Newton iteration (median and minimum reported), >= 1.
    points : int, default 5
        Cap on the continuation points of the timed analysis (>= 2), or 0 to skip it.
    out : str or Path, default "out/scaling"
        Output folder.
    timeout : float, optional
        Seconds after which one case is stopped and recorded as failed.
    progress : bool, default False
        Show a progress bar over the cases on stderr.

    Returns
    -------
    ScalingResult
        ``interrupted`` is True if Ctrl-C stopped the study; the cases measured until then are kept.

    Raises
    ------
    ValueError, TypeError
        Bad arguments, naming the argument: ``elements`` or ``refine`` for a mesh that cannot be
        refined, ``elements`` for a solid (use ``refine``), both given.
    CaseError
        Mistakes in the case file.
    """
    if not isinstance(case, Case):
        case = load_case(case)
    harmonics_list = _harmonics_values(case, harmonics)
    sizes = _size_values(case, elements, refine)
    with named_by("scaling_study"):
        repeat = check_int("repeat", repeat, 1)
    points = _points_value(points)
    if timeout is not None and not (isinstance(timeout, numbers.Real) and timeout > 0):
        raise ValueError(f"scaling_study: timeout must be a positive number of seconds, got {timeout!r}")
    out = Path(out)
    path = case.path.resolve() if case.path else Path("case.toml")
    settings = _settings(case, path, sizes, refine is not None, harmonics_list, repeat, points)
    _check_earlier_study(out, case.name, settings)
    specs = [(size, H, _spec(case, path, size, H, repeat, points)) for size in sizes for H in harmonics_list]
    records, interrupted = _measure_cases(specs, timeout, progress, out, case.name, settings)
    fits = fit_exponents(records)
    files = write_tables(out, case.name, records, fits, settings, interrupted)
    if records:
        title = f"{path.name}: {settings['analysis']}" + (" (Craig-Bampton)" if settings["reduction"] else "")
        files.append(plot_scaling(records, fits, out / "scaling.png", title=title))
    return ScalingResult(case=case.name, records=tuple(records), fits=tuple(fits), files=tuple(files),
                         interrupted=interrupted, settings=settings)


def _check_earlier_study(out: Path, case_name: str, settings: dict) -> None:
    """ValueError if ``out`` holds the scaling study of other settings (another case, sizes,
    harmonics, repeat or points): its tables would be replaced by this one's. The same study
    again (on any machine) measures anew."""
    path = out / "scaling.json"
    if not path.is_file():
        return
    try:
        doc = json.loads(path.read_text())
        saved = dict(doc["settings"], case_name=doc["case"])
    except (OSError, ValueError, KeyError, TypeError):
        raise ValueError(f"scaling_study: out {str(out)!r} holds a scaling.json that is not readable; choose another "
                         "output folder (--out), or delete it to start over") from None
    mine = dict(json.loads(json.dumps(settings)), case_name=case_name)
    diff = [k for k in mine if k != "machine" and saved.get(k) != mine[k]]
    if diff:
        raise ValueError(f"scaling_study: out {str(out)!r} already holds the scaling study of other settings "
                         f"({', '.join(diff)} differ); choose another output folder (--out), or delete its "
                         "scaling.json to start over")


def _measure_cases(specs: list, timeout: float | None, progress: bool, out: Path, case_name: str,
                   settings: dict) -> tuple[list[ScalingRecord], bool]:
    """Measure the cases ``(size, H, spec)`` one by one (``size``: a :class:`_Size`), rewriting the
    tables after each; the records and whether Ctrl-C stopped the study."""
    records: list[ScalingRecord] = []
    bar = _CaseBar((0, len(specs)), "cases") if progress else None
    interrupted = False
    try:
        for k, (size, H, spec) in enumerate(specs):
            label = (f"{size.label} " if size.label else "") + f"H={H}"
            if bar is not None:
                bar.show(k, f"running {label}")
            rec = _record(size, H, _run_child(spec, timeout))
            records.append(rec)
            if bar is not None:
                bar.close()  # log records on their own lines; the bar is redrawn for the next case
            _log_record(label, rec)
            write_tables(out, case_name, records, fit_exponents(records), settings, False)
        if bar is not None:
            bar.show(len(specs), "done")
    except KeyboardInterrupt:
        interrupted = True
        log.warning("scaling study interrupted after %d of %d cases; keeping what was measured",
                    len(records), len(specs))
    finally:
        if bar is not None:
            bar.close()
    return records, interrupted


def _log_record(label: str, rec: ScalingRecord) -> None:
    if rec.dense_jacobian:
        log.warning("scaling %s: %s; its solves cost O(unknowns^3) (modal damping is kept sparse; "
                    "a dense matrix C or a dense reduced model is not)", label, rec.dense_note())
    if rec.ok:
        log.info("scaling %s: N=%s, %.3g ms per iteration, %.3g s per point, peak %.0f MiB", label, rec.N,
                 1e3 * rec.iteration_median_s, rec.point_s, rec.peak_mib)
    else:
        log.warning("scaling %s failed: %s", label, rec.error)


def _record(size: _Size, H: int, d: dict) -> ScalingRecord:
    """The record of one case from the child's measurements (unknown keys and None left out)."""
    names = {f.name for f in dataclasses.fields(ScalingRecord)} - {"n_elements", "refine", "mesh", "H"}
    return ScalingRecord(n_elements=size.n_elements, refine=size.refine, mesh=size.mesh, H=H,
                         **{k: v for k, v in d.items() if k in names and v is not None})


class _CaseBar(ProgressBar):
    """``[#####.....]  2/6 cases  N=1000 H=10 ...``."""

    def show(self, done: int, text: str) -> str:
        f = self.fraction(done)
        k = int(round(f * self.width))
        return self.write(f"\r[{'#' * k}{'.' * (self.width - k)}] {done}/{int(self.p1)} cases  {text}\x1b[K")


# ---------------------------------------------------------------------------------------------
# Arguments and cases
# ---------------------------------------------------------------------------------------------
def _comma_numbers(text: str, what: str, like: str):
    """``(item, value)`` of every comma-separated number of ``text``; ArgumentTypeError naming
    ``what`` is expected (``like``: an example) for an item that is not a number."""
    import argparse

    for item in str(text).split(","):
        item = item.strip()
        try:
            yield item, float(item)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {what} separated by commas (like {like}), got {text!r}") from None


def positive_int_list(text: str) -> list[int]:
    """``"100,1e3, 10000"`` -> ``[100, 1000, 10000]``; for argparse (raises ArgumentTypeError)."""
    import argparse

    values = []
    for item, v in _comma_numbers(text, "positive integers", "100,1000 or 1e2,1e3"):
        if not math.isfinite(v) or v < 1 or v != int(v):
            raise argparse.ArgumentTypeError(f"values must be positive integers, got {item!r} in {text!r}")
        values.append(int(v))
    return values


def positive_float_list(text: str) -> list[float]:
    """``"1, 1.5,2"`` -> ``[1.0, 1.5, 2.0]``; for argparse (raises ArgumentTypeError)."""
    import argparse

    values = []
    for item, v in _comma_numbers(text, "positive numbers", "1,2,4 or 1,1.5,2"):
        if not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"values must be positive numbers, got {item!r} in {text!r}")
        values.append(v)
    return values


@dataclasses.dataclass(frozen=True)
class _Size:
    """One mesh size of a study: the overrides of ``[mesh]`` and how the record names them."""

    n_elements: int | None = None      # line mesh: [mesh] n_elements
    refine: float | None = None        # refinement factor (line or solid mesh)
    divisions: tuple = ()              # ((key, value), ...) of [mesh] to override
    mesh: str = ""                     # "nx=40 ny=4" (solids), for the record

    @property
    def label(self) -> str:
        if self.refine is not None:
            return f"refine={self.refine:g}" + (f" ({self.mesh})" if self.mesh else "")
        return f"n_elements={self.n_elements}" if self.n_elements is not None else ""


def refined_divisions(case: Case, factor: float) -> dict[str, int]:
    """The element divisions of the case's generated mesh times ``factor``, rounded, at least 1:
    ``{"n_elements": ...}`` for a line mesh, ``{"nx": ..., "ny": ...(, "nz": ...)}`` for a
    solid's rectangle or box. ValueError if the mesh cannot be refined (a file, a discrete model)."""
    why = _variable_mesh(case)
    if why is not None:
        raise ValueError(f"scaling_study: refine: cannot refine the mesh: {why}")
    mesh = case.data["mesh"]
    keys = [k for k in SOLID_DIVISIONS if k in mesh] if _is_solid(case) else ["n_elements"]
    return {k: max(1, int(round(factor * mesh[k]))) for k in keys}


def _is_solid(case: Case) -> bool:
    return case.data["model"].get("kind") == "solid"


def _size_values(case: Case, elements: Sequence[int] | None, refine: Sequence[float] | None) -> list[_Size]:
    """The mesh sizes to measure: from ``elements`` or ``refine`` (checked, sorted), else the case's own."""
    if elements is not None and refine is not None:
        raise ValueError("scaling_study: give either elements (numbers of elements of a line mesh) or refine "
                         "(refinement factors of the case's mesh), not both")
    if refine is not None:
        factors = _float_values("refine", refine)
        sizes = []
        for f in factors:
            div = refined_divisions(case, f)
            solid = _is_solid(case)
            sizes.append(_Size(n_elements=None if solid else div["n_elements"], refine=f,
                               divisions=tuple(div.items()),
                               mesh=" ".join(f"{k}={v}" for k, v in div.items()) if solid else ""))
        return sizes
    if elements is not None and _is_solid(case) and "file" not in case.data.get("mesh", {}):
        raise ValueError("scaling_study: elements: a solid's mesh is refined with refine (a factor on nx, ny and nz "
                         "that keeps the aspect of the elements), not with a number of elements")
    return [_Size(n_elements=ne, divisions=(("n_elements", ne),) if ne is not None else ())
            for ne in _elements_values(case, elements)]


def _float_values(name: str, values: Any) -> list[float]:
    try:
        items = list(values)
    except TypeError:
        raise TypeError(f"scaling_study: {name} must be a sequence of positive numbers, got {values!r}") from None
    if not items:
        raise ValueError(f"scaling_study: {name} must not be empty")
    for v in items:
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise TypeError(f"scaling_study: {name} must be positive numbers, got {v!r} in {values!r}")
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"scaling_study: {name} must be positive numbers, got {v!r} in {values!r}")
    return sorted({float(v) for v in items})


def _harmonics_values(case: Case, harmonics: Sequence[int] | None) -> list[int]:
    """The harmonics to measure: ``harmonics`` checked and sorted, or the case's own (10 if none)."""
    if harmonics is None:
        return [int(case.data["analysis"].get("harmonics", 10))]
    return _int_values("harmonics", harmonics)


def _elements_values(case: Case, elements: Sequence[int] | None) -> list[int | None]:
    """The numbers of elements to measure: ``elements`` checked and sorted (if the case's mesh can
    be refined), or the case's own (None without a mesh)."""
    if elements is None:
        return [None if _is_solid(case) else case.data["mesh"].get("n_elements") if "mesh" in case.data else None]
    values: list[int | None] = list(_int_values("elements", elements))
    why = _variable_mesh(case)
    if why is not None:
        raise ValueError(f"scaling_study: elements: cannot vary the number of elements: {why}; "
                         "to vary only the harmonics, leave out elements (--elements)")
    return values


def _points_value(points: Any) -> int:
    with named_by("scaling_study"):
        points = check_int("points", points, 0)
    if points == 1:
        raise ValueError("scaling_study: points must be 0 (skip the continuation) or >= 2, got 1")
    return points


def _int_values(name: str, values: Any) -> list[int]:
    try:
        items = list(values)
    except TypeError:
        raise TypeError(f"scaling_study: {name} must be a sequence of positive integers, got {values!r}") from None
    if not items:
        raise ValueError(f"scaling_study: {name} must not be empty")
    for v in items:
        if isinstance(v, bool) or not isinstance(v, numbers.Integral):
            raise TypeError(f"scaling_study: {name} must be positive integers, got {v!r} in {values!r}")
        if v < 1:
            raise ValueError(f"scaling_study: {name} must be positive integers, got {v!r} in {values!r}")
    return sorted({int(v) for v in items})


def _variable_mesh(case: Case) -> str | None:
    """None if ``[mesh] n_elements`` can be varied, else the reason why not."""
    d = case.data
    if d["model"]["kind"] == "discrete":
        return "the case is a discrete model (kind = \"discrete\"), whose number of DOFs is fixed by its matrices"
    mesh = d.get("mesh", {})
    if "file" in mesh:
        return (f"the mesh is read from a file ([mesh] file = {mesh['file']!r}); only a generated mesh (a line "
                "mesh by [mesh] length/n_elements, a solid's rectangle or box by nx, ny(, nz)) can be refined")
    return None


def _settings(case: Case, path: Path, sizes: list, refined: bool, harmonics: list[int], repeat: int,
              points: int) -> dict:
    """The study's settings and machine, as ``scaling.json`` records them."""
    return {
        "case": str(path), "elements": [s.n_elements for s in sizes] if not refined else None,
        "refine": [s.refine for s in sizes] if refined else None,
        "meshes": [dict(s.divisions) for s in sizes], "harmonics": harmonics, "repeat": repeat,
        "points": points, "analysis": case.data["analysis"]["type"],
        "reduction": case.data.get("reduction", {}).get("craig_bampton"),
        "machine": {"python": platform.python_version(), "numpy": np.__version__, "platform": platform.platform(),
                    "cpus": os.cpu_count(), **{v: os.environ.get(v) for v in (
                        "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS") if os.environ.get(v)}},
    }


def _spec(case: Case, path: Path, size: _Size, harmonics: int, repeat: int, points: int) -> dict:
    """What the child process of one case reads: the case with its sizes, ``repeat`` and ``points``."""
    sub = _with(case, size, harmonics)
    return {"path": str(path), "text": sub.text, "data": sub.data, "name": sub.name,
            "repeat": repeat, "points": points}


def _with(case: Case, size: _Size, harmonics: int) -> Case:
    """A copy of the case with the element divisions of ``[mesh]`` (``n_elements``, or ``nx, ny,
    nz``) and ``[analysis] harmonics`` overridden."""
    data = json.loads(json.dumps(case.data))  # deep copy; TOML case data is JSON data
    for key, value in size.divisions:
        data["mesh"][key] = int(value)
    data["analysis"]["harmonics"] = int(harmonics)
    return Case(path=case.path, text=case.text, data=data, name=case.name)
