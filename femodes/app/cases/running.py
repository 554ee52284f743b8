"""Application layer: running a case: build its model, run its [analysis], write its outputs."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Callable

from .building import CaseApi, build_model
from .reporting import summary_lines, write_animations, write_plot
from .schema import Case

__all__ = ["CaseResult", "analysis_span", "run_case", "run_analysis"]


@dataclass
class CaseResult:
    branch: Any
    model: Any
    files: list
    lines: list


def analysis_span(case: Case) -> tuple[float, float]:
    """Continuation parameter span: ``omega``, or ``log10(energy)`` for nonlinear modes."""
    an = case.data["analysis"]
    if an["type"] == "nonlinear_mode":
        a, b = an["energy"]
        if a > 0 and b > 0:
            return math.log10(a), math.log10(b)
        return float(a), float(b)
    a, b = an["omega"]
    return float(a), float(b)


def run_case(case: Case, out: Path, *, progress: bool | Callable = False, checkpoint=None) -> CaseResult:
    """Build the model, run the analysis, write the outputs to ``out``.

    ``progress`` goes to the analysis: ``True`` logs points at INFO, a callable receives every
    accepted continuation point (the command line's :class:`~femodes.app.progress.BranchProgress`).
    ``checkpoint`` (a :class:`femodes.Checkpoint`, optional) journals the points as they are found,
    so that an interrupted run keeps them and the same case run again continues from them
    (``femodes run`` uses ``out/checkpoint.npz``, removed once the outputs are written).
    """
    model, _full = build_model(case)
    branch = run_analysis(case, model, progress, checkpoint)
    outs = {"plot": True, "branch": "branch.npz", "animation": True, "gif": False}
    outs.update(case.data.get("outputs", {}))
    out.mkdir(parents=True, exist_ok=True)
    files, lines = [], summary_lines(case, model, branch)
    if outs["branch"]:
        files.append(branch.save(out / outs["branch"]))
    if len(branch):  # a run that found no point (its start failed) has nothing to draw
        if outs["plot"]:
            files.append(write_plot(case, model, branch, out))
        write_animations(model, branch, out, outs, files, lines)
    summary = out / "summary.txt"
    files.append(summary)
    summary.write_text("\n".join(lines) + "\n")
    if checkpoint is not None:  # the outputs hold the branch now: the run's journal is not needed
        Path(checkpoint.path).unlink(missing_ok=True)
    return CaseResult(branch=branch, model=model, files=files, lines=lines)


def run_analysis(case: Case, model, progress, checkpoint=None):
    """The [analysis] of the case on ``model``: its branch."""
    import femodes as fm
    from ...analyses import frequency_response_options
    from ...floquet import ShootingError

    api = CaseApi(case)
    an = case.data["analysis"]
    H = api("analysis", "harmonics", fm.Harmonics, an.get("harmonics", 10))
    opts = {}
    if "max_points" in an:
        opts["max_points"] = an["max_points"]
    stability = an.get("stability", False)
    if isinstance(stability, str):  # case files name the strategy
        stability = fm.stability_methods.by_name(stability)
    rtol = an.get("rtol")
    try:
        if an["type"] == "nonlinear_mode":
            energy = tuple(an["energy"])
            if an.get("energy_unit") == "grazing":
                eg = api("analysis", ["energy_unit", "mode"], fm.grazing_energy, model, an.get("mode", 1))
                energy = tuple(e * eg for e in energy)
            return api("analysis", ["mode", "energy", "harmonics", "stability", "rtol"], fm.nonlinear_mode, model,
                       an.get("mode", 1), energy=energy, harmonics=H, progress=progress,
                       stability=stability, checkpoint=checkpoint, rtol=rtol)
        options = frequency_response_options(**opts) if opts else None
        return api("analysis", ["omega", "harmonics", "stability", "rtol"], fm.frequency_response, model,
                   tuple(an["omega"]), H, options=options, progress=progress, stability=stability,
                   checkpoint=checkpoint, rtol=rtol)
    except ShootingError as exc:  # stability = "shooting" that does not converge (the message says: use "hill")
        raise case.error("analysis", "stability", str(exc)) from None
