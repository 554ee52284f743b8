"""Application layer: :func:`run_sweep`, a case file run for many parameter values as
independent tasks, gathered into one study file.

Steps: check the arguments (nothing starts on a mistake), prepare every case's text and reject
the cases that the case-file checks refuse, submit the others to the executor, and record each
finished case in the study file as it arrives.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Callable, Mapping

from ...store import FileInUse, file_lock
from ..cases import Case, CaseError, load_case, parse_case
from .executors import check_main_guarded, check_where, open_executor
from .overrides import case_text, sweep_cases
from .records import CaseRecord, SweepResult, fmt_value, record_from_task
from .study import load_study_header, save_study
from .task import run_sweep_case

__all__ = ["run_sweep"]

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------------------
# Arguments
# ---------------------------------------------------------------------------------------------
def _check_arguments(*, out, study, progress, executor, n_workers) -> None:
    """TypeError/ValueError quoting the first bad argument of :func:`run_sweep`."""
    if out is None or not isinstance(out, (str, os.PathLike)):
        raise TypeError(f"run_sweep: out must be a folder path, got {out!r}")
    if (not isinstance(study, str) or Path(study).suffix.lower() not in (".npz", ".h5", ".hdf5")
            or Path(study).name != study):
        raise ValueError(f"run_sweep: study must be a file name ending in .npz or .h5, got {study!r}")
    if not isinstance(progress, bool) and not callable(progress):
        raise TypeError(f"run_sweep: progress must be True, False or a callable(record, n_done, n_total), "
                        f"got {progress!r}")
    check_where(executor, n_workers)
    if executor is None:
        check_main_guarded("run_sweep")


def _base_case(case) -> Case:
    if isinstance(case, Case):
        return case
    if isinstance(case, (str, os.PathLike)):
        return load_case(case)
    raise TypeError(f"run_sweep: case must be a case file path or a Case (femodes.app.cases.load_case), "
                    f"got {type(case).__name__}")


# ---------------------------------------------------------------------------------------------
# Cases
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Plan:
    """The cases of a sweep: ids ``c000, c001, ...``, their overrides and case texts, and the
    parameter paths in first-seen order."""

    base: Case
    ids: tuple[str, ...]
    overrides: tuple[dict, ...]
    texts: tuple[str, ...]
    paths: tuple[str, ...]


def _plan(base: Case, parameters) -> _Plan:
    combos = sweep_cases(parameters)
    width = max(3, len(str(len(combos) - 1)))
    ids = tuple(f"c{i:0{width}d}" for i in range(len(combos)))
    texts = tuple(case_text(base, ov) for ov in combos)  # a path that does not fit the case: ValueError, nothing run
    paths = tuple(dict.fromkeys(p for c in combos for p in c))
    return _Plan(base=base, ids=ids, overrides=tuple(combos), texts=texts, paths=paths)


class _Ledger:
    """The records of a running sweep: every finished case rewrites the study file (small,
    atomic), so an interrupted sweep keeps its finished cases and marks the others "pending"."""

    def __init__(self, plan: _Plan, study: Path, *, t_start: float,
                 progress: bool | Callable[[CaseRecord, int, int], None]):
        self.plan, self.study, self.t_start = plan, study, t_start
        self.progress = progress
        self.records: dict[str, CaseRecord] = {}
        self.pending = {cid: CaseRecord(id=cid, parameters=ov, status="pending", message="not finished")
                        for cid, ov in zip(plan.ids, plan.overrides)}

    def snapshot(self) -> SweepResult:
        return SweepResult(cases=tuple(self.records.get(i, self.pending[i]) for i in self.plan.ids),
                           parameters=self.plan.paths, study=self.study, case=self.plan.base.name,
                           elapsed=time.perf_counter() - self.t_start)

    def save(self) -> SweepResult:
        res = self.snapshot()
        save_study(res, text=self.plan.base.text)
        return res

    def done(self, rec: CaseRecord) -> None:
        self.records[rec.id] = rec
        self.save()
        n, k = len(self.plan.ids), len(self.records)
        if callable(self.progress):
            self.progress(rec, k, n)
        elif self.progress:
            log.info("case %s (%d/%d) %s in %.2f s: %s %s", rec.id, k, n, rec.status, rec.wall_time,
                     ", ".join(f"{p}={fmt_value(v)}" for p, v in rec.parameters.items()), rec.message)


def _earlier_records(plan: _Plan, out: Path, study: Path) -> dict[str, CaseRecord]:
    """The finished cases of an earlier run of the same sweep in ``out`` (a resumed sweep keeps
    them); ValueError if ``out`` holds another sweep's study or case folders (two studies are never
    mixed in one folder)."""
    def refuse(why: str):
        raise ValueError(f"run_sweep: out {str(out)!r} already holds another sweep ({why}); choose another "
                         "output folder (--out), or delete its study file and cases/ to start over")

    planned = dict(zip(plan.ids, zip(plan.overrides, plan.texts)))
    kept: dict[str, CaseRecord] = {}
    if study.exists():
        try:
            header = load_study_header(study)
        except ValueError as exc:
            refuse(f"{study.name} is not readable: {exc}")
        if header.get("case_text") != plan.base.text:
            refuse(f"{study.name} was run from another base case file ({header.get('case')!r})")
        saved = [(r.get("id"), r.get("parameters")) for r in header.get("records", [])]
        mine = [(cid, json.loads(json.dumps(ov))) for cid, ov in zip(plan.ids, plan.overrides)]
        if saved != mine:
            refuse(f"{study.name} has other parameter values: {len(saved)} cases "
                   f"({', '.join(header.get('parameters', []))}), this sweep has {len(mine)}")
        for r in header["records"]:
            rec = CaseRecord(**r)
            if rec.status in ("ok", "incomplete") and rec.branch and (out / rec.branch).is_file():
                kept[rec.id] = dataclasses.replace(rec, parameters=dict(planned[rec.id][0]))
    folders = out / "cases"
    for d in sorted(folders.iterdir()) if folders.is_dir() else ():
        if d.name not in planned:
            refuse(f"cases/{d.name} is not a case of this sweep")
        toml = d / "case.toml"
        if toml.is_file() and toml.read_text(encoding="utf-8") != planned[d.name][1]:
            refuse(f"cases/{d.name}/case.toml is not the case {d.name} of this sweep")
    if kept:
        log.info("sweep of %s: resuming the study in %s, %d of %d cases already finished", plan.base.name, out,
                 len(kept), len(plan.ids))
    return kept


def _checked_jobs(plan: _Plan, out: Path, ledger: _Ledger) -> list[tuple[str, dict, str]]:
    """The ``(id, overrides, text)`` that pass the case-file checks in this process (a rejected
    value costs no task); the others are recorded as failed with the check's message. Cases an
    earlier run of the same sweep finished are not run again."""
    jobs = []
    for cid, ov, text in zip(plan.ids, plan.overrides, plan.texts):
        if cid in ledger.records:
            continue
        try:
            parse_case(text, out / "cases" / cid / "case.toml")
        except CaseError as exc:
            ledger.done(CaseRecord(id=cid, parameters=ov, status="failed", message=exc.message, wall_time=0.0))
            continue
        jobs.append((cid, ov, text))
    return jobs


# ---------------------------------------------------------------------------------------------
# Execution
# ---------------------------------------------------------------------------------------------
def _task_answer(fut: cf.Future, case_id: str) -> Mapping[str, Any]:
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001 - the task itself could not run (worker lost, ...)
        return {"id": case_id, "status": "failed", "message": f"{type(exc).__name__}: {exc}"}


def _execute(jobs: list[tuple[str, dict, str]], out: Path, ledger: _Ledger, *, executor, n_workers: int) -> None:
    """Submit one :func:`~femodes.app.sweep.task.run_sweep_case` per job; record each as it finishes."""
    with open_executor(executor, n_workers) as (ex, where):
        log.info("sweep of %s: %d cases (%d to run) on %s", ledger.plan.base.name, len(ledger.plan.ids), len(jobs),
                 where)
        futures = {ex.submit(run_sweep_case, cid, text, str(out / "cases" / cid)): (cid, ov)
                   for cid, ov, text in jobs}
        for fut in cf.as_completed(futures):
            cid, ov = futures[fut]
            ledger.done(record_from_task(_task_answer(fut, cid), ov, out))


def run_sweep(case, parameters, *, out, executor=None, n_workers: int = 2, study: str = "study.npz",
              progress: bool | Callable[[CaseRecord, int, int], None] = False) -> SweepResult:
    """Run a case file for many parameter values as independent tasks; gather one study file.

    Every case ``i`` is the base case with its overrides applied; it runs
    :func:`~femodes.app.cases.run_case` in a task and saves ``out/cases/c<i>/branch.npz``. A case
    the case-file checks reject, or whose task raises, gets ``status = "failed"`` with the error;
    the other cases complete.

    Parameters
    ----------
    case : str, Path or Case
        The base case file (or a parsed :class:`~femodes.app.cases.Case`).
    parameters : dict or list of dict
        ``{path: [values]}`` (Cartesian product) or ``[{path: value}, ...]``; paths like
        ``"contact.0.gap"``, ``"analysis.harmonics"`` (see :mod:`femodes.app.sweep.overrides`).
    out : str or Path
        Output folder: ``cases/<id>/`` per case and the study file.
    executor : concurrent.futures.Executor, distributed.Client or str, optional
        Where the tasks run. An executor or client is used as is and not shut down by the sweep
        (worker environments are the caller's); a string is the address of a running Dask
        scheduler (``"tcp://host:8786"``), which the sweep connects to and disconnects from (``out``
        must be on a file system its workers share). Default: an embedded
        :func:`~femodes.app.sweep.local_cluster` of ``n_workers``, started and closed by the sweep.
    n_workers : int
        Workers of the embedded cluster (used only when ``executor`` is None).
    study : str
        Study file name in ``out``: ``*.npz`` or ``*.h5`` (needs h5py).
    progress : bool or callable
        ``True`` logs one INFO line per finished case; a callable gets ``progress(record, n_done,
        n_total)`` in the calling process (an exception it raises stops the sweep, keeping the study).

    An ``out`` that holds the study of the same sweep (same base case text, same cases) is
    resumed: its finished cases (``"ok"``, ``"incomplete"``, branch file present) are kept and
    the others run; an ``out`` holding another sweep's study or case folders is a ValueError,
    never overwritten.

    Returns
    -------
    SweepResult
        Records in case order; ``result.study`` is the study file (:func:`~femodes.app.sweep.load_study`).
    """
    t_start = time.perf_counter()
    _check_arguments(out=out, study=study, progress=progress, executor=executor, n_workers=n_workers)
    plan = _plan(_base_case(case), parameters)
    out = Path(out).resolve()
    # one sweep at a time in `out`: a second one (even the same) would rewrite the study under the first
    with file_lock(out / (study + ".lock"), lambda holder: FileInUse(
            f"run_sweep: out {str(out)!r} is in use by another sweep (process {holder}); wait for it to finish, or "
            "choose another output folder (--out)")):
        kept = _earlier_records(plan, out, out / study)  # another sweep in `out`: refused before anything runs
        (out / "cases").mkdir(parents=True, exist_ok=True)
        ledger = _Ledger(plan, out / study, t_start=t_start, progress=progress)
        ledger.records.update(kept)
        jobs = _checked_jobs(plan, out, ledger)
        if jobs:
            _execute(jobs, out, ledger, executor=executor, n_workers=n_workers)
        return ledger.save()
