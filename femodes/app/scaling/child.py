"""Application layer: one ``(N, H)`` case of a scaling study, measured in a fresh Python process.

:func:`run_child` (in the study's process) starts ``python -c "... child_main()"``, writes the
case to its stdin as JSON and reads the measurements back from the line of its stdout marked
``FEMODES_SCALING_RESULT``; :func:`child_main` is that child's entry point.

What is measured in the child process of one ``(N, H)`` case
-------------------------------------------------------------
1. ``setup``: :func:`femodes.app.cases.build_model` (mesh, assembly, contacts, Craig-Bampton
   reduction if the case has ``[reduction]``; then ``N`` is the full model's size and the
   reduced size is reported too).
2. ``per point``: the case's analysis as ``femodes run`` runs it
   (:func:`femodes.frequency_response` or :func:`femodes.nonlinear_mode` with their default
   continuation options), capped at ``points`` continuation points. Wall time of the whole call
   (problem setup, start point, continuation) divided by the number of points of the branch.
3. ``per iteration``: at a representative state ``(x, p)``, ``repeat`` times
   ``r, J, _ = problem.residual(x, p)`` followed by ``default_linear_solver(J, r)``; median and
   minimum, with the medians of the two parts. Repeat ``i`` is at the frequency of the state
   times ``1 + (i + 1) 1e-9`` (:data:`_SHIFT`), so that it costs the factorisations as a
   corrector iteration does (:doc:`/howto/scaling-and-sweeps`). The state is the branch point of
   step 2 with the largest contact force if there is one; otherwise the linear guess of largest
   amplitude over 5 parameter values of the span, moved by one Newton step (``contact_active``
   says whether the state has nonzero complementarity contact forces). With ``stability`` in the
   case's ``[analysis]``, the stability of the branch of step 2 is timed apart (``stability per
   point``: :func:`femodes.floquet.annotate_branch` divided by the points; ``stability_method``).
4. ``peak MiB``: ``ru_maxrss`` of the child at the end, the peak resident memory of the whole
   case (interpreter and imports included; their share, measured before the model is built, is
   ``baseline MiB``).

A failing case comes back as ``{"error": ...}``: an exception in the child, the child killed
(by the out-of-memory killer, say) or stopped after ``timeout`` seconds.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import logging
import math
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import femodes as fm

from ...analyses import frequency_response_options, nonlinear_mode_options
from ...floquet import annotate_branch
from ...stability_methods import by_name
from ...solvers import newton
from ..cases import Case, CaseError, analysis_span, build_model

__all__ = ["child_main", "run_child"]

log = logging.getLogger(__name__)

#: Marks the child's result line on its stdout (libraries may print other lines).
_MARK = "FEMODES_SCALING_RESULT "

#: What the child interpreter runs (``python -c``).
_COMMAND = f"from {__name__} import child_main; child_main()"

#: Number of parameter values scanned for a large-amplitude linear guess (step 3 above).
_N_GUESS = 5

#: Relative frequency shift between the timed iterations (step 3 above): enough to miss the
#: factor cache, far too small to change the work of an iteration.
_SHIFT = 1e-9


# ---------------------------------------------------------------------------------------------
# The study's side: run one case in a child process
# ---------------------------------------------------------------------------------------------
def run_child(spec: dict, timeout: float | None) -> dict:
    """Run one case in a fresh interpreter; errors become ``{"error": ...}``.

    ``spec`` is the case (``path``, ``text``, ``data``, ``name``) with ``repeat`` and ``points``;
    the returned measurements are :class:`~.records.ScalingRecord` fields, ``wall_s`` included.
    """
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", _COMMAND], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(json.dumps(spec), timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return {"error": f"timed out after {timeout:g} s", "wall_s": time.perf_counter() - t}
    except BaseException:  # Ctrl-C: do not leave the child running
        proc.kill()
        proc.communicate()
        raise
    wall = time.perf_counter() - t
    rec = _result(out)
    if rec is None:
        rec = {"error": _failure(proc.returncode, err)}
    rec["wall_s"] = wall
    return rec


def _result(out: str) -> dict | None:
    """The child's measurements from its stdout, None if it wrote none."""
    for line in reversed(out.splitlines()):
        if line.startswith(_MARK):
            return json.loads(line[len(_MARK):])
    return None


def _failure(returncode: int, err: str) -> str:
    """Why a child that wrote no result failed: the signal that killed it, or its last stderr line."""
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = f"signal {-returncode}"
        hint = " (out of memory? the kernel's OOM killer sends SIGKILL)" if name == "SIGKILL" else ""
        return f"child process killed by {name}{hint}"
    tail = [ln for ln in err.strip().splitlines() if ln.strip()]
    return f"child process failed (exit {returncode}): {tail[-1] if tail else 'no message'}"


# ---------------------------------------------------------------------------------------------
# The child's side: measure one case
# ---------------------------------------------------------------------------------------------
def child_main() -> None:
    """Entry point of the child process: spec as JSON on stdin, record as JSON on stdout."""
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    spec = json.loads(sys.stdin.read())
    rec: dict = {}
    try:
        _measure(spec, rec)
    except CaseError as exc:
        rec["error"] = str(exc)
    except Exception as exc:  # recorded; the parent goes on with the next case
        rec["error"] = f"{type(exc).__name__}: {exc}"
    rec.setdefault("peak_mib", _peak_mib())
    sys.stdout.write("\n" + _MARK + json.dumps(rec) + "\n")
    sys.stdout.flush()


def _measure(spec: dict, rec: dict) -> None:
    """Fill ``rec`` with the measurements of one case (steps 1 to 4 of the module docstring).

    ``rec`` is filled as the steps go, so a case that fails half-way keeps what was measured.
    """
    rec["baseline_mib"] = _peak_mib()
    setup = _build(spec, rec)
    states = _time_points(setup, int(spec["points"]), rec)
    gc.collect()
    problem = setup.problem()
    rec["unknowns"] = int(problem.size)
    x, p = _representative_state(problem, states, setup.span, rec)
    J = _time_iteration(problem, x, p, int(spec["repeat"]), rec)
    rec["peak_mib"] = _peak_mib()  # before assembling a structured J for its nnz below
    rec["jacobian"] = type(J).__name__
    rec["nnz_J"] = _nnz(J)


@dataclass(frozen=True)
class _Setup:
    """The built model of one case and what its analysis needs."""

    model: Any
    harmonics: fm.Harmonics
    analysis: dict
    span: tuple[float, float]
    mode: int

    @property
    def nonlinear_mode(self) -> bool:
        return self.analysis["type"] == "nonlinear_mode"

    def problem(self):
        """A fresh HBM problem of the case's analysis."""
        if self.nonlinear_mode:
            # the reference energy of fm.nonlinear_mode: the geometric mean of the span
            return fm.NonlinearModeProblem(self.model, self.harmonics, self.mode,
                                           reference_energy=10.0 ** (0.5 * (self.span[0] + self.span[1])))
        return fm.ForcedResponseProblem(self.model, self.harmonics)


def _build(spec: dict, rec: dict) -> _Setup:
    """Step 1: build the case's model (timed as ``setup_s``); its sizes ``N`` and ``n_reduced``."""
    case = Case(path=Path(spec["path"]), text=spec["text"], data=spec["data"], name=spec["name"])
    an = case.data["analysis"]
    t = time.perf_counter()
    model, full = build_model(case)
    rec["setup_s"] = time.perf_counter() - t
    rec["N"] = int(full.n_dofs)
    rec["n_reduced"] = int(model.n_dofs) if getattr(model, "is_reduced", False) else None
    return _Setup(model=model, harmonics=fm.Harmonics(int(an["harmonics"])), analysis=an,
                  span=analysis_span(case), mode=int(an.get("mode", 1)))


def _time_points(setup: _Setup, points: int, rec: dict) -> list[tuple[np.ndarray, float]]:
    """Step 2: time the analysis capped at ``points`` points (none if 0); its points ``(x, p)``.

    A failing analysis is recorded in ``continuation`` (the iteration is still measured) and
    gives no points.
    """
    states: list[tuple[np.ndarray, float]] = []
    if not points:
        return states

    def keep(point):
        states.append((np.array(point.x), float(point.p)))

    try:
        options = _analysis_options(setup, points, keep)
        t = time.perf_counter()
        branch = _run_analysis(setup, options)
        wall = time.perf_counter() - t
        rec["points"] = len(branch)
        rec["newton_iterations"] = int(np.sum(branch.nit))
        rec["point_s"] = wall / len(branch) if len(branch) else math.nan
        rec["continuation"] = ("" if branch.success else "failed: ") + str(branch.message)
        _time_stability(setup, branch, rec)
    except Exception as exc:  # the study goes on; the iteration is still measured
        rec["continuation"] = f"failed: {type(exc).__name__}: {exc}"
        states.clear()
    return states


def _time_stability(setup: _Setup, branch: fm.Branch, rec: dict) -> None:
    """The stability of the branch, when the case asks for it (timed apart from the points)."""
    method = setup.analysis.get("stability", False)
    if method is False or not len(branch):
        return
    strategy = by_name("auto" if method is True else str(method))  # case files name the strategy
    try:
        t = time.perf_counter()
        annotated = annotate_branch(branch, setup.problem(), setup.model, method=strategy)
        rec["stability_s"] = (time.perf_counter() - t) / len(branch)
        rec["stability_method"] = "+".join(sorted(set(annotated.stability_method)))
    except Exception as exc:  # reported; the rest of the case is still measured
        rec["stability_method"] = f"failed: {type(exc).__name__}: {exc}"


def _analysis_options(setup: _Setup, points: int, callback):
    """The analysis's own default continuation options, capped at ``points`` points."""
    if setup.nonlinear_mode:
        pr = setup.problem()
        return dataclasses.replace(nonlinear_mode_options(pr, pr.initial_guess(setup.span[0])),
                                   max_points=points, callback=callback)
    # frequency_response's own defaults, as run_case uses them with max_points
    return frequency_response_options(max_points=points, callback=callback)


def _run_analysis(setup: _Setup, options) -> fm.Branch:
    """The case's analysis as ``femodes run`` runs it."""
    an = setup.analysis
    if setup.nonlinear_mode:
        return fm.nonlinear_mode(setup.model, setup.mode, energy=tuple(an["energy"]), harmonics=setup.harmonics,
                                 options=options)
    return fm.frequency_response(setup.model, tuple(an["omega"]), setup.harmonics, options=options)


def _representative_state(problem, states: list, span, rec: dict) -> tuple[np.ndarray, float]:
    """Step 3's state ``(x, p)``: the branch point of largest contact force, else a linear guess.

    Records how it was chosen (``state``) and whether its contacts carry force
    (``contact_active``); ``states`` is emptied (its arrays are not needed any more).
    """
    chosen = _branch_state(problem, states)
    states.clear()
    x, p, rec["state"] = chosen if chosen is not None else _linear_guess_state(problem, span)
    f = _contact_force(problem, x, p)
    rec["contact_active"] = None if math.isnan(f) else bool(f > 0)
    return x, p


def _contact_force(problem, x: np.ndarray, p: float) -> float:
    """Largest contact force magnitude at ``(x, p)``; NaN for a problem without contacts."""
    P = np.asarray(problem.unpack(x, p).P)
    return float(np.max(np.abs(P))) if P.size else math.nan


def _branch_state(problem, states: list) -> tuple[np.ndarray, float, str] | None:
    """The branch point with the largest contact force, None if no point has a positive one."""
    if not states:
        return None
    forces = [_contact_force(problem, xs, ps) for xs, ps in states]
    i = int(np.nanargmax(forces)) if np.any(np.isfinite(forces)) else -1
    if not (np.isfinite(forces[i]) and forces[i] > 0):
        return None
    x, p = states[i]
    return x, p, f"branch point {i + 1} of {len(states)} (largest contact force), p = {p:.6g}"


def _linear_guess_state(problem, span) -> tuple[np.ndarray, float, str]:
    """The linear guess of largest amplitude over the span, moved by one Newton step if that
    step stays finite (it activates the contacts the guess violates)."""
    x, p = _largest_linear_guess(problem, span)
    text = f"linear guess at p = {p:.6g}"
    try:
        r, J, _ = problem.residual(x, p)
        x1 = x - newton.default_linear_solver(J, r)
        if np.all(np.isfinite(x1)) and np.all(np.isfinite(problem.residual(x1, p)[0])):
            x = x1
            text += " + 1 Newton step"
    except Exception as exc:  # e.g. a singular Jacobian: time at the linear guess itself
        log.debug("scaling: Newton step from the linear guess failed: %s", exc)
    return x, p, text


def _largest_linear_guess(problem, span) -> tuple[np.ndarray, float]:
    """``problem.initial_guess`` of largest displacement amplitude over ``_N_GUESS`` values of p."""
    best = None
    for pc in np.linspace(span[0], span[1], _N_GUESS):
        xc = problem.initial_guess(float(pc))
        amp = float(np.max(np.abs(problem.unpack(xc, float(pc)).Q)))
        if best is None or amp > best[0]:
            best = (amp, xc, float(pc))
    return best[1], best[2]


def _shifted(problem, x: np.ndarray, p: float, factor: float) -> tuple[np.ndarray, float]:
    """``(x, p)`` with the frequency times ``factor``: the parameter of a forced response, the
    frequency unknown of a nonlinear mode."""
    if isinstance(problem, fm.ForcedResponseProblem):
        return x, p * factor
    u = problem.unpack(x, p)
    return problem.pack(u.Q, u.P, u.omega * factor, u.xi), p


def _time_iteration(problem, x: np.ndarray, p: float, repeat: int, rec: dict):
    """Step 3: ``repeat`` Newton iterations (residual + linear solve) near ``(x, p)``, each at its
    own frequency (:data:`_SHIFT`); the last J."""
    gc.collect()
    it, res, sol = [], [], []
    for i in range(repeat):
        xi, pi = _shifted(problem, x, p, 1.0 + (i + 1) * _SHIFT)
        t0 = time.perf_counter()
        r, J, _ = problem.residual(xi, pi)
        t1 = time.perf_counter()
        newton.default_linear_solver(J, r)  # module attribute: follows a future dispatch
        t2 = time.perf_counter()
        it.append(t2 - t0)
        res.append(t1 - t0)
        sol.append(t2 - t1)
    rec["iteration_median_s"] = float(np.median(it))
    rec["iteration_min_s"] = float(np.min(it))
    rec["residual_median_s"] = float(np.median(res))
    rec["solve_median_s"] = float(np.median(sol))
    return J


def _peak_mib() -> float:
    """Step 4: the peak resident memory of this process so far, in MiB."""
    import resource

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 1024.0  # bytes on macOS, KiB on Linux


def _nnz(J) -> int | None:
    """Stored entries of J, or of its assembled sparse form for a structured operator."""
    import scipy.sparse as sp

    if sp.issparse(J):
        return int(J.nnz)
    if isinstance(J, np.ndarray):
        return int(J.size)
    if isinstance(getattr(type(J), "nnz", None), property):  # structured: its own count (low-rank parts
        return int(J.nnz)                                    # stay factors, never assembled dense)
    try:
        return int(J.tocsr().nnz)
    except Exception:  # an operator without an assembled form: nnz is not defined
        return None
