"""Application layer: the scaling study of a case file, case by case.

:func:`scaling_study` checks its arguments, makes one copy of the case per ``(n_elements, H)``
pair, measures each in its own process (:mod:`.child`) and rewrites ``scaling.csv`` and
``scaling.json`` after every case (:mod:`.report`), so an interrupted study (Ctrl-C) keeps what
it has measured; a case that fails is recorded with its error and the study goes on.
:func:`positive_int_list` reads the lists of sizes of the command line.
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
from typing import Any, Sequence

import numpy as np

from ...solvers.checks import check_int
from ..cases import Case, load_case
from ..progress import ProgressBar
from .child import run_child as _run_child  # a module global, looked up per case: tests replace it
from .records import ScalingRecord, ScalingResult
from .report import fit_exponents, plot_scaling, write_tables

__all__ = ["scaling_study", "positive_int_list"]

log = logging.getLogger(__name__)


def scaling_study(
    case: Case | str | Path,
    *,
    elements: Sequence[int] | None = None,
    harmonics: Sequence[int] | None = None,
    repeat: int = 3,
    points: int = 5,
    out: str | Path = "out/scaling",
    timeout: float | None = None,
    progress: bool = False,
) -> ScalingResult:
    """Time per Newton iteration and per continuation point, and peak memory, against N and H.

    For every pair of ``elements`` x ``harmonics`` the case is measured in a fresh process (see
    :mod:`femodes.app.scaling.child` for what is timed and how); ``scaling.csv`` and
    ``scaling.json`` in ``out`` are rewritten after every case and ``scaling.png`` is drawn at
    the end.

    Parameters
    ----------
    case : Case, str or Path
        A case file (:func:`femodes.app.cases.load_case`) or its path.
    elements : sequence of int, optional
        Values of ``[mesh] n_elements``; only for a line mesh (``[mesh] length/n_elements``).
        Default: the case's own mesh (only H varies).
    harmonics : sequence of int, optional
        Values of ``[analysis] harmonics``. Default: the case's own (10 if not given).
    repeat : int
        Repetitions of the timed Newton iteration (median and minimum reported), >= 1.
    points : int
        Cap on the continuation points of the timed analysis (>= 2), or 0 to skip it.
    out : str or Path
        Output folder.
    timeout : float, optional
        Seconds after which one case is stopped and recorded as failed.
    progress : bool
        Show a progress bar over the cases on stderr.

    Returns
    -------
    ScalingResult
        ``interrupted`` is True if Ctrl-C stopped the study: the cases measured until then are
        kept (and written).

    Raises
    ------
    ValueError, TypeError
        Bad arguments, naming the argument; ``elements`` for a case whose mesh cannot be refined.
    CaseError
        Mistakes in the case file.
    """
    if not isinstance(case, Case):
        case = load_case(case)
    harmonics_list = _harmonics_values(case, harmonics)
    elements_list = _elements_values(case, elements)
    repeat = check_int("repeat", repeat, 1, owner="scaling_study")
    points = _points_value(points)
    if timeout is not None and not (isinstance(timeout, numbers.Real) and timeout > 0):
        raise ValueError(f"scaling_study: timeout must be a positive number of seconds, got {timeout!r}")
    out = Path(out)
    path = case.path.resolve() if case.path else Path("case.toml")
    settings = _settings(case, path, elements_list, harmonics_list, repeat, points)
    specs = [(ne, H, _spec(case, path, ne, H, repeat, points)) for ne in elements_list for H in harmonics_list]
    records, interrupted = _measure_cases(specs, timeout, progress, out, case.name, settings)
    fits = fit_exponents(records)
    files = write_tables(out, case.name, records, fits, settings, interrupted)
    if records:
        title = f"{path.name}: {settings['analysis']}" + (" (Craig-Bampton)" if settings["reduction"] else "")
        files.append(plot_scaling(records, fits, out / "scaling.png", title=title))
    return ScalingResult(case=case.name, records=tuple(records), fits=tuple(fits), files=tuple(files),
                         interrupted=interrupted, settings=settings)


def _measure_cases(specs: list, timeout: float | None, progress: bool, out: Path, case_name: str,
                   settings: dict) -> tuple[list[ScalingRecord], bool]:
    """Measure the cases ``(n_elements, H, spec)`` one by one, rewriting the tables after each;
    the records and whether Ctrl-C stopped the study."""
    records: list[ScalingRecord] = []
    bar = _CaseBar((0, len(specs)), "cases") if progress else None
    interrupted = False
    try:
        for k, (ne, H, spec) in enumerate(specs):
            label = (f"n_elements={ne} " if ne is not None else "") + f"H={H}"
            if bar is not None:
                bar.show(k, f"running {label}")
            rec = _record(ne, H, _run_child(spec, timeout))
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


def _record(ne: int | None, H: int, d: dict) -> ScalingRecord:
    """The record of one case from the child's measurements (unknown keys and None left out)."""
    names = {f.name for f in dataclasses.fields(ScalingRecord)} - {"n_elements", "H"}
    return ScalingRecord(n_elements=ne, H=H, **{k: v for k, v in d.items() if k in names and v is not None})


class _CaseBar(ProgressBar):
    """``[#####.....]  2/6 cases  N=1000 H=10 ...``."""

    def show(self, done: int, text: str) -> str:
        f = self.fraction(done)
        k = int(round(f * self.width))
        return self.write(f"\r[{'#' * k}{'.' * (self.width - k)}] {done}/{int(self.p1)} cases  {text}\x1b[K")


# ---------------------------------------------------------------------------------------------
# Arguments and cases
# ---------------------------------------------------------------------------------------------
def positive_int_list(text: str) -> list[int]:
    """``"100,1e3, 10000"`` -> ``[100, 1000, 10000]``; for argparse (raises ArgumentTypeError)."""
    import argparse

    values = []
    for item in str(text).split(","):
        item = item.strip()
        try:
            v = float(item)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected positive integers separated by commas (like 100,1000 or 1e2,1e3), got {text!r}") from None
        if not math.isfinite(v) or v < 1 or v != int(v):
            raise argparse.ArgumentTypeError(f"values must be positive integers, got {item!r} in {text!r}")
        values.append(int(v))
    return values


def _harmonics_values(case: Case, harmonics: Sequence[int] | None) -> list[int]:
    """The harmonics to measure: ``harmonics`` checked and sorted, or the case's own (10 if none)."""
    if harmonics is None:
        return [int(case.data["analysis"].get("harmonics", 10))]
    return _int_values("harmonics", harmonics)


def _elements_values(case: Case, elements: Sequence[int] | None) -> list[int | None]:
    """The numbers of elements to measure: ``elements`` checked and sorted (if the case's mesh can
    be refined), or the case's own (None without a mesh)."""
    if elements is None:
        return [case.data["mesh"].get("n_elements") if "mesh" in case.data else None]
    values: list[int | None] = list(_int_values("elements", elements))
    why = _variable_mesh(case)
    if why is not None:
        raise ValueError(f"scaling_study: elements: cannot vary the number of elements: {why}; "
                         "to vary only the harmonics, leave out elements (--elements)")
    return values


def _points_value(points: Any) -> int:
    points = check_int("points", points, 0, owner="scaling_study")
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
        return (f"the mesh is read from a file ([mesh] file = {mesh['file']!r}); only a line mesh given by "
                "[mesh] length/n_elements can be refined")
    return None


def _settings(case: Case, path: Path, elements: list, harmonics: list[int], repeat: int, points: int) -> dict:
    """The study's settings and machine, as ``scaling.json`` records them."""
    return {
        "case": str(path), "elements": elements, "harmonics": harmonics, "repeat": repeat,
        "points": points, "analysis": case.data["analysis"]["type"],
        "reduction": case.data.get("reduction", {}).get("craig_bampton"),
        "machine": {"python": platform.python_version(), "numpy": np.__version__, "platform": platform.platform(),
                    "cpus": os.cpu_count(), **{v: os.environ.get(v) for v in (
                        "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS") if os.environ.get(v)}},
    }


def _spec(case: Case, path: Path, n_elements: int | None, harmonics: int, repeat: int, points: int) -> dict:
    """What the child process of one case reads: the case with its sizes, ``repeat`` and ``points``."""
    sub = _with(case, n_elements, harmonics)
    return {"path": str(path), "text": sub.text, "data": sub.data, "name": sub.name,
            "repeat": repeat, "points": points}


def _with(case: Case, n_elements: int | None, harmonics: int) -> Case:
    """A copy of the case with ``[mesh] n_elements`` and ``[analysis] harmonics`` overridden."""
    data = json.loads(json.dumps(case.data))  # deep copy; TOML case data is JSON data
    if n_elements is not None:
        data["mesh"]["n_elements"] = int(n_elements)
    data["analysis"]["harmonics"] = int(harmonics)
    return Case(path=case.path, text=case.text, data=data, name=case.name)
