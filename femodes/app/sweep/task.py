"""Application layer: the task of one sweep case, run in a worker: plain data in, plain dict out.

:func:`run_sweep_case` is what executors receive; it is pickled by reference, so it stays a
top-level function of this module (``femodes.app.sweep.task.run_sweep_case``), which every
worker imports.
"""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np

from ...store import Checkpoint
from ..cases import Case, CaseError, parse_case, run_case
from .overrides import CASE_OUTPUTS
from .records import BIFURCATION_FIELDS

__all__ = ["run_sweep_case", "max_penetration", "stability_summary"]


def _amplitude_dof(case: Case, model) -> int | None:
    rd = case.data.get("outputs", {}).get("response_dof")
    if rd is not None:
        return model.dof(tuple(rd) if isinstance(rd, list) else rd)
    if model.forces:
        return model.forces[0].dof
    if model.contacts:
        return model.contacts[0].dof
    return None


def max_penetration(br) -> float:
    """``max(0, max_t -g_N(t))`` over all points and contacts: the maximum of
    :attr:`femodes.Branch.penetration` (one synthesis matrix for the whole branch)."""
    return float(np.max(br.penetration, initial=0.0))


def stability_summary(br) -> dict[str, Any]:
    """The stability fields of a :class:`~femodes.app.sweep.CaseRecord` for a branch: ``n_stable``
    (stable points), ``stability_method`` (the methods used, ``"+"``-joined) and the bifurcation
    counts by kind (``n_period_doubling``, ...); ``{}`` (the record's defaults: -1 and "") when the
    branch has no stability."""
    if br.stable is None:
        return {}
    kinds = [b.kind for b in br.bifurcations]
    return dict(n_stable=int(np.count_nonzero(br.stable)),
                stability_method="+".join(sorted({str(m) for m in br.stability_method})),
                **{f: kinds.count(kind) for f, kind in BIFURCATION_FIELDS.items()})


def _branch_summary(case: Case, res, folder: Path) -> dict[str, Any]:
    """The :class:`~femodes.app.sweep.CaseRecord` fields that summarise the branch of a run case."""
    br = res.branch
    dof = _amplitude_dof(case, res.model)
    amp = br.amplitude(dof) if dof is not None else np.max([br.amplitude(i) for i in range(br.Q.shape[2])], axis=0)
    return dict(
        status="ok" if br.success else "incomplete", message=br.message, n_points=len(br),
        branch=str(folder / CASE_OUTPUTS["branch"]), omega_min=float(br.omega.min()),
        omega_max=float(br.omega.max()), energy_min=float(br.energy.min()), energy_max=float(br.energy.max()),
        max_amplitude=float(amp.max()), amplitude_dof="all" if dof is None else res.model.dofmap.label(dof),
        n_folds=len(br.folds), max_penetration=max_penetration(br), **stability_summary(br),
    )


def run_sweep_case(case_id: str, text: str, folder: str) -> dict:
    """Run one sweep case in the current process; never raises.

    Writes ``folder/case.toml`` (``text``), runs it with :func:`~femodes.app.cases.run_case`
    (outputs in ``folder``) and returns the :class:`~femodes.app.sweep.CaseRecord` fields as a
    plain dict, without ``parameters``; on any exception ``status = "failed"`` and ``message`` is
    the error.
    """
    t0, c0 = time.perf_counter(), time.thread_time()
    rec: dict[str, Any] = {"id": case_id, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        folder_p = Path(folder)
        folder_p.mkdir(parents=True, exist_ok=True)
        path = folder_p / "case.toml"
        path.write_text(text, encoding="utf-8")
        case = parse_case(text, path)
        # the points are journalled in the case folder: a case interrupted with its sweep continues
        # from them when the same sweep runs again (the journal goes once the outputs are written)
        checkpoint = Checkpoint(folder_p / "checkpoint.npz", resume=True)
        rec.update(_branch_summary(case, run_case(case, folder_p, progress=False, checkpoint=checkpoint), folder_p))
    except CaseError as exc:
        rec.update(status="failed", message=exc.message)
    except Exception as exc:  # noqa: BLE001 - a failed case is reported, the sweep goes on
        rec.update(status="failed", message=f"{type(exc).__name__}: {exc}")
    rec["wall_time"] = time.perf_counter() - t0
    rec["cpu_time"] = time.thread_time() - c0
    return rec
