"""Application layer: the records of a sweep, one :class:`CaseRecord` per case gathered in a
:class:`SweepResult`, and the conversion of a task's plain-dict answer into a record.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any
from collections.abc import Mapping

import numpy as np

__all__ = ["CaseRecord", "SweepResult", "NUMERIC_FIELDS", "INTEGER_FIELDS", "TEXT_FIELDS", "BIFURCATION_FIELDS",
           "fmt_value", "record_from_task"]

#: The record fields that count bifurcations by kind (``n_<kind>`` for the kinds of
#: :data:`femodes.results.BIFURCATION_KINDS` other than folds, which ``n_folds`` counts).
BIFURCATION_FIELDS = {"n_branch_point": "branch_point", "n_period_doubling": "period_doubling",
                      "n_neimark_sacker": "neimark_sacker", "n_nonsmooth": "nonsmooth"}


@dataclass(frozen=True)
class CaseRecord:
    """Summary of one sweep case.

    ``status`` is ``"ok"`` (branch complete), ``"incomplete"`` (branch saved, continuation stopped
    before the end of the span: see ``message``), ``"failed"`` (no branch; ``message`` is the
    error) or ``"pending"`` (not finished: the study file of an interrupted sweep). ``wall_time`` and ``cpu_time`` (of the thread that ran it, so robust to a loaded
    machine) are the task's, in seconds, measured in its worker (``worker`` = host:pid).
    ``branch`` is the branch file relative to the study file's folder ("" if none). The numbers
    summarise the branch: frequency and energy ranges, ``max_amplitude`` = max over the branch of
    ``max_t |q(t)|`` at ``amplitude_dof`` (``[outputs] response_dof``, else the first force, else
    the first contact DOF), ``max_penetration`` of the contacts; NaN when failed.

    Stability (``[analysis] stability``, e.g. the sweep parameter ``analysis.stability``):
    ``n_stable`` is the number of stable points (orbits) of the branch, ``stability_method`` the
    methods used (``"shooting"``, ``"hill"`` or ``"hill+shooting"``) and ``n_branch_point``,
    ``n_period_doubling``, ``n_neimark_sacker``, ``n_nonsmooth`` count the bifurcations by kind
    (folds: ``n_folds``). When stability was not computed (or the case failed) the counts are
    ``-1`` and ``stability_method`` is ``""``.
    """

    id: str
    parameters: dict
    status: str
    message: str = ""
    n_points: int = 0
    wall_time: float = math.nan
    cpu_time: float = math.nan
    branch: str = ""
    omega_min: float = math.nan
    omega_max: float = math.nan
    energy_min: float = math.nan
    energy_max: float = math.nan
    max_amplitude: float = math.nan
    amplitude_dof: str = ""
    n_folds: int = 0
    max_penetration: float = math.nan
    worker: str = ""
    n_stable: int = -1
    stability_method: str = ""
    n_branch_point: int = -1
    n_period_doubling: int = -1
    n_neimark_sacker: int = -1
    n_nonsmooth: int = -1

    @property
    def ok(self) -> bool:
        return self.status == "ok"


#: The record fields stored as one number array, and as one text array, over the cases.
NUMERIC_FIELDS = ("n_points", "wall_time", "cpu_time", "omega_min", "omega_max", "energy_min", "energy_max",
                  "max_amplitude", "n_folds", "max_penetration", "n_stable", *BIFURCATION_FIELDS)
#: The numeric fields that are integers (stored as integer arrays; ``-1`` = not computed).
INTEGER_FIELDS = ("n_points", "n_folds", "n_stable", *BIFURCATION_FIELDS)
TEXT_FIELDS = ("id", "status", "message", "branch", "amplitude_dof", "worker", "stability_method")


@dataclass(frozen=True)
class SweepResult:
    """All cases of a sweep, in case order, and where the study file is.

    ``result[i]`` / ``result["c003"]`` is a :class:`CaseRecord`; ``result.column("max_amplitude")``
    an array over the cases; ``result.load_branch(i)`` reads a case's branch; ``result.table()``
    a text table.
    """

    cases: tuple
    parameters: tuple
    study: Path
    case: str = ""
    elapsed: float = math.nan

    def __len__(self) -> int:
        return len(self.cases)

    def __iter__(self):
        return iter(self.cases)

    def __getitem__(self, key: int | str) -> CaseRecord:
        if isinstance(key, str):
            for r in self.cases:
                if r.id == key:
                    return r
            raise KeyError(f"SweepResult: no case with id {key!r}; ids are {[r.id for r in self.cases]}")
        return self.cases[key]

    @property
    def success(self) -> bool:
        """True if every case ran to the end of its span."""
        return all(r.ok for r in self.cases)

    @property
    def failed(self) -> tuple:
        """The records whose status is not ``"ok"``."""
        return tuple(r for r in self.cases if not r.ok)

    def column(self, name: str) -> np.ndarray:
        """A record field (or a parameter path) as an array over the cases."""
        if name in self.parameters:
            return np.array([r.parameters.get(name) for r in self.cases], dtype=object)
        names = [f.name for f in fields(CaseRecord) if f.name != "parameters"]
        if name not in names:
            raise KeyError(f"SweepResult.column: unknown column {name!r}; columns are {names} "
                           f"and the parameters {list(self.parameters)}")
        return np.array([getattr(r, name) for r in self.cases])

    def load_branch(self, key: int | str):
        """The saved :class:`femodes.Branch` of a case (by index or id)."""
        from ...results import load_branch

        rec = self[key]
        if not rec.branch:
            raise ValueError(f"SweepResult.load_branch: case {rec.id} has no branch ({rec.status}: {rec.message})")
        return load_branch(self.study.parent / rec.branch)

    def table(self, max_message: int = 60) -> str:
        """Text table: id, parameter values, status, points, frequency range, amplitude, time, message;
        when any case computed stability, also ``stable`` (stable of all points, ``-`` where not
        computed) and ``bifurcations`` (counts by kind, e.g. ``period_doubling 1``)."""
        stab = any(r.n_stable >= 0 for r in self.cases)
        head = ["id", *self.parameters, "status", "points", *(["stable"] if stab else []), "w range [rad/s]",
                "max amp", *(["bifurcations"] if stab else []), "time [s]", "message"]
        rows = []
        for r in self.cases:
            w = f"{r.omega_min:.4g}..{r.omega_max:.4g}" if r.n_points else "-"
            msg = r.message if len(r.message) <= max_message else r.message[: max_message - 3] + "..."
            st = [f"{r.n_stable}/{r.n_points}" if r.n_stable >= 0 else "-"] if stab else []
            bif = [_bifurcation_text(r)] if stab else []
            rows.append([r.id, *(fmt_value(r.parameters.get(p)) for p in self.parameters), r.status, str(r.n_points),
                         *st, w, f"{r.max_amplitude:.6g}" if r.n_points else "-", *bif, f"{r.wall_time:.2f}", msg])
        widths = [max(len(h), *(len(row[j]) for row in rows)) if rows else len(h) for j, h in enumerate(head)]
        fmt = lambda row: "  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip()  # noqa: E731
        return "\n".join([fmt(head), fmt(["-" * w for w in widths]), *map(fmt, rows)])


def _bifurcation_text(r: CaseRecord) -> str:
    """``period_doubling 1, nonsmooth 2`` (``none``; ``-`` without stability) for :meth:`SweepResult.table`."""
    if r.n_stable < 0:
        return "-"
    found = [f"{kind} {getattr(r, f)}" for f, kind in BIFURCATION_FIELDS.items() if getattr(r, f) > 0]
    return ", ".join(found) or "none"


def fmt_value(v: Any) -> str:
    """A parameter value as a table cell or log text: ``-`` for none, JSON for text and lists."""
    return "-" if v is None else json.dumps(v) if isinstance(v, (str, list, dict)) else str(v)


def record_from_task(raw: Mapping, overrides: Mapping, out: Path) -> CaseRecord:
    """The :class:`CaseRecord` of a task's answer (``run_sweep_case``), its branch path made
    relative to the sweep folder ``out`` (where the study file is)."""
    kw = {k: raw[k] for k in raw if k in {f.name for f in fields(CaseRecord)}}
    if kw.get("branch"):
        try:
            kw["branch"] = Path(kw["branch"]).resolve().relative_to(out).as_posix()
        except ValueError:
            kw["branch"] = str(kw["branch"])
    return CaseRecord(**{**kw, "parameters": dict(overrides)})
