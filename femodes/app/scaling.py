"""Application layer: scaling studies of a case file (``femodes scaling case.toml``).

How do the cost of one Newton iteration and of one continuation point, and the peak memory,
grow with the number of DOFs ``N`` and of harmonics ``H``? :func:`scaling_study` answers this
for a user's own case file: it varies ``[mesh] n_elements`` (line meshes only) and
``[analysis] harmonics``, measures every ``(N, H)`` pair in a fresh Python process and fits the
exponents ``t ~ N^a`` (at fixed ``H``) and ``t ~ H^b`` (at fixed ``N``).

What is measured in the child process of one ``(N, H)`` case
-------------------------------------------------------------
1. ``setup``: :func:`femodes.app.cases.build_model` (mesh, assembly, contacts, Craig-Bampton
   reduction if the case has ``[reduction]``; then ``N`` is the full model's size and the
   reduced size is reported too).
2. ``per point``: the case's analysis as ``femodes run`` runs it
   (:func:`femodes.frequency_response` or :func:`femodes.nonlinear_mode` with their default
   continuation options), capped at ``points`` continuation points
   (``ContinuationOptions.max_points``). Wall time (``time.perf_counter``) of the whole call --
   problem setup, start point, continuation -- divided by the number of points of the branch.
3. ``per iteration``: at a representative state ``(x, p)``, ``repeat`` times
   ``r, J, _ = problem.residual(x, p)`` followed by
   ``femodes.solvers.newton.default_linear_solver(J, r)`` (looked up at call time, so the
   timing follows whatever that solver dispatches to); median and minimum are reported, with
   the medians of the two parts. The state is the branch point of step 2 with the largest
   contact force if there is one; otherwise the linear guess (``problem.initial_guess``) of
   largest amplitude over 5 parameter values of the span, moved by one Newton step so that the
   contacts it violates become active (``contact_active`` in the record says whether the state
   has nonzero complementarity contact forces).
4. ``peak MiB``: ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` of the child at the end, i.e. the
   peak resident memory of the whole case (interpreter and imports included; their share,
   measured before the model is built, is ``baseline MiB``). Every case has its own process, so
   the peaks do not mix.

A case that fails (an exception, the child killed by the out-of-memory killer, a timeout) is
recorded with its error and the study goes on. ``scaling.csv`` and ``scaling.json`` are
rewritten after every case, so an interrupted study (Ctrl-C) keeps what it has measured.

Outputs in ``out``: ``scaling.csv`` (one row per case), ``scaling.json`` (settings, records,
fitted exponents), ``scaling.png`` (log-log plots with the fitted slopes in the legends).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import math
import numbers
import os
import platform
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .cases import Case, CaseError, load_case

__all__ = ["ScalingRecord", "ScalingFit", "ScalingResult", "scaling_study", "positive_int_list"]

log = logging.getLogger(__name__)

#: Marks the child's result line on its stdout (libraries may print other lines).
_MARK = "FEMODES_SCALING_RESULT "

#: Number of parameter values scanned for a large-amplitude linear guess (step 3 above).
_N_GUESS = 5

CSV_COLUMNS = (
    "n_elements", "N", "n_reduced", "H", "unknowns", "nnz_J", "iteration_median_s", "iteration_min_s",
    "residual_median_s", "solve_median_s", "point_s", "points", "newton_iterations", "peak_mib",
    "baseline_mib", "setup_s", "wall_s", "jacobian", "contact_active", "state", "continuation", "error",
)


# ---------------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ScalingRecord:
    """Measurements of one ``(N, H)`` case; times in seconds, memory in MiB (NaN: not measured).

    ``N`` is the number of DOFs of the full model, ``n_reduced`` that of the Craig-Bampton
    model the analysis runs on (None without reduction), ``unknowns`` the size of the HBM
    problem, ``jacobian`` the type of the Jacobian its ``residual`` returns and ``nnz_J`` the
    number of stored entries of that Jacobian (of its assembled sparse form for a structured
    operator). ``error`` is empty for a measured case.
    """

    n_elements: int | None
    H: int
    N: int | None = None
    n_reduced: int | None = None
    unknowns: int | None = None
    nnz_J: int | None = None
    iteration_median_s: float = math.nan
    iteration_min_s: float = math.nan
    residual_median_s: float = math.nan
    solve_median_s: float = math.nan
    point_s: float = math.nan
    points: int = 0
    newton_iterations: int = 0
    peak_mib: float = math.nan
    baseline_mib: float = math.nan
    setup_s: float = math.nan
    wall_s: float = math.nan
    jacobian: str = ""
    contact_active: bool | None = None
    state: str = ""
    continuation: str = ""
    error: str = ""

    @property
    def ok(self) -> bool:
        """True when the per-iteration time was measured."""
        return not self.error and math.isfinite(self.iteration_median_s)

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in CSV_COLUMNS}


_WHAT = {"iteration": "time per Newton iteration", "point": "time per continuation point",
         "memory": "peak memory above baseline"}


@dataclass(frozen=True)
class ScalingFit:
    """Fitted exponent: ``quantity ~ against**exponent`` with ``fixed`` held at ``fixed_value``.

    ``quantity`` is ``"iteration"`` (median time per Newton iteration), ``"point"`` (time per
    continuation point) or ``"memory"`` (peak MiB above the baseline); ``against`` is ``"N"`` or
    ``"H"``; ``sizes`` are the values of ``against`` the least-squares line
    (``np.polyfit(log x, log y, 1)``) went through.
    """

    quantity: str
    against: str
    fixed: str
    fixed_value: int
    exponent: float
    sizes: tuple[int, ...]

    def describe(self) -> str:
        return (f"{_WHAT[self.quantity]} ~ {self.against}^{self.exponent:.2f} at {self.fixed} = {self.fixed_value} "
                f"({self.against} = {', '.join(map(str, self.sizes))})")


@dataclass(frozen=True)
class ScalingResult:
    """Result of :func:`scaling_study`: one record per case, fitted exponents, written files."""

    case: str
    records: tuple[ScalingRecord, ...]
    fits: tuple[ScalingFit, ...]
    files: tuple[Path, ...]
    interrupted: bool = False
    settings: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        """All planned cases were measured."""
        return not self.interrupted and all(r.ok for r in self.records)

    def table(self) -> str:
        """Markdown table of the records."""
        head = ("| N | reduced | H | unknowns | nnz(J) | iteration median [ms] | min [ms] | residual [ms] | "
                "solve [ms] | per point [s] | points | setup [s] | peak [MiB] | note |")
        lines = [head, "|" + "---|" * (head.count("|") - 1)]
        for r in self.records:
            note = r.error or ("" if r.contact_active is not False else "no active contact")
            if r.continuation.startswith("failed") and not r.error:
                note = (note + "; " if note else "") + r.continuation
            cells = [_cell(r.N), _cell(r.n_reduced), str(r.H), _cell(r.unknowns), _cell(r.nnz_J),
                     _ms(r.iteration_median_s), _ms(r.iteration_min_s), _ms(r.residual_median_s),
                     _ms(r.solve_median_s), _num(r.point_s, "{:.3g}"), str(r.points),
                     _num(r.setup_s, "{:.3g}"), _num(r.peak_mib, "{:.0f}"), _short(note)]
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)

    def fit_lines(self) -> list[str]:
        """The fitted exponents, one line per quantity and variable: ``... ~ N^a: 1.02 (H=5), ...``."""
        lines = []
        for quantity in ("iteration", "point", "memory"):
            for against in ("N", "H"):
                fs = [f for f in self.fits if f.quantity == quantity and f.against == against]
                if fs:
                    lines.append(f"{_WHAT[quantity]} ~ {against}^a: " + ", ".join(
                        f"a = {f.exponent:.2f} ({f.fixed}={f.fixed_value})" for f in fs))
        return lines


def _cell(v) -> str:
    return "-" if v is None else str(v)


def _num(v: float, fmt: str) -> str:
    return fmt.format(v) if v is not None and math.isfinite(v) else "-"


def _ms(v: float) -> str:
    return _num(1e3 * v if v is not None else math.nan, "{:.3g}")


def _short(text: str, n: int = 70) -> str:
    text = " ".join(str(text).split()).replace("|", "/")
    return text if len(text) <= n else text[: n - 3] + "..."


# ---------------------------------------------------------------------------------------------
# Arguments
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


def _check_int(name: str, v: Any, minimum: int) -> int:
    if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < minimum:
        raise ValueError(f"scaling_study: {name} must be an integer >= {minimum}, got {v!r}")
    return int(v)


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


def _with(case: Case, n_elements: int | None, harmonics: int) -> Case:
    """A copy of the case with ``[mesh] n_elements`` and ``[analysis] harmonics`` overridden."""
    data = json.loads(json.dumps(case.data))  # deep copy; TOML case data is JSON data
    if n_elements is not None:
        data["mesh"]["n_elements"] = int(n_elements)
    data["analysis"]["harmonics"] = int(harmonics)
    return Case(path=case.path, text=case.text, data=data, name=case.name)


# ---------------------------------------------------------------------------------------------
# Child process: measure one case
# ---------------------------------------------------------------------------------------------
def _peak_mib() -> float:
    import resource

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 2**20 if sys.platform == "darwin" else rss / 1024.0  # bytes on macOS, KiB on Linux


def _measure(spec: dict, rec: dict) -> None:
    """Fill ``rec`` with the measurements of one case (see the module docstring)."""
    import gc

    import femodes as fm
    import femodes.solvers.newton as newton
    from femodes.analyses import nonlinear_mode_options

    from .cases import analysis_span, build_model

    rec["baseline_mib"] = _peak_mib()
    case = Case(path=Path(spec["path"]), text=spec["text"], data=spec["data"], name=spec["name"])
    an = case.data["analysis"]
    nnm = an["type"] == "nonlinear_mode"
    t = time.perf_counter()
    model, full = build_model(case)
    rec["setup_s"] = time.perf_counter() - t
    rec["N"] = int(full.n_dofs)
    rec["n_reduced"] = int(model.n_dofs) if getattr(model, "is_reduced", False) else None
    h = fm.Harmonics(int(an["harmonics"]))
    span = analysis_span(case)
    mode = int(an.get("mode", 1))

    def make_problem():
        if nnm:
            pr = fm.NonlinearModeProblem(model, h, mode)
            pr.set_reference_energy(10.0 ** (0.5 * (span[0] + span[1])))  # as fm.nonlinear_mode does
            return pr
        return fm.ForcedResponseProblem(model, h)

    # -- per continuation point: the analysis as `femodes run` runs it, capped at `points` ----
    states: list[tuple[np.ndarray, float]] = []
    points = int(spec["points"])
    if points:
        def keep(point):
            states.append((np.array(point.x), float(point.p)))

        try:
            if nnm:
                pr = make_problem()
                opts = nonlinear_mode_options(pr, pr.initial_guess(span[0]))
                del pr
                opts = dataclasses.replace(opts, max_points=points, callback=keep)
                t = time.perf_counter()
                br = fm.nonlinear_mode(model, mode, energy=tuple(an["energy"]), harmonics=h, options=opts)
            else:
                # frequency_response's own defaults, as run_case uses them with max_points
                opts = fm.ContinuationOptions(step=0.05, max_step=0.5, max_points=points, callback=keep,
                                              newton=fm.NewtonOptions(atol=1e-9, max_iter=20))
                t = time.perf_counter()
                br = fm.frequency_response(model, tuple(an["omega"]), h, options=opts)
            wall = time.perf_counter() - t
            rec["points"] = len(br)
            rec["newton_iterations"] = int(np.sum(br.nit))
            rec["point_s"] = wall / len(br) if len(br) else math.nan
            rec["continuation"] = ("" if br.success else "failed: ") + str(br.message)
            del br
        except Exception as exc:  # the study goes on; the iteration is still measured
            rec["continuation"] = f"failed: {type(exc).__name__}: {exc}"
            states.clear()
    gc.collect()

    # -- per Newton iteration at a representative state --------------------------------------
    pr = make_problem()
    rec["unknowns"] = int(pr.size)

    def contact_force(x, p) -> float:
        P = np.asarray(pr.unpack(x, p)["P"])
        return float(np.max(np.abs(P))) if P.size else math.nan

    x = None
    if states:
        forces = [contact_force(xs, ps) for xs, ps in states]
        i = int(np.nanargmax(forces)) if np.any(np.isfinite(forces)) else -1
        if np.isfinite(forces[i]) and forces[i] > 0:
            x, p = states[i]
            rec["state"] = f"branch point {i + 1} of {len(states)} (largest contact force), p = {p:.6g}"
    states.clear()
    if x is None:
        best = None
        for pc in np.linspace(span[0], span[1], _N_GUESS):
            xc = pr.initial_guess(float(pc))
            amp = float(np.max(np.abs(pr.unpack(xc, float(pc))["Q"])))
            if best is None or amp > best[0]:
                best = (amp, xc, float(pc))
        _, x, p = best
        rec["state"] = f"linear guess at p = {p:.6g}"
        try:
            r, J, _ = pr.residual(x, p)
            x1 = x - newton.default_linear_solver(J, r)
            if np.all(np.isfinite(x1)) and np.all(np.isfinite(pr.residual(x1, p)[0])):
                x = x1
                rec["state"] += " + 1 Newton step"
        except Exception as exc:  # e.g. a singular Jacobian: time at the linear guess itself
            log.debug("scaling: Newton step from the linear guess failed: %s", exc)
    f = contact_force(x, p)
    rec["contact_active"] = None if math.isnan(f) else bool(f > 0)
    gc.collect()
    it, res, sol = [], [], []
    for _ in range(int(spec["repeat"])):
        t0 = time.perf_counter()
        r, J, _ = pr.residual(x, p)
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
    rec["peak_mib"] = _peak_mib()  # before assembling a structured J for its nnz below
    rec["jacobian"] = type(J).__name__
    rec["nnz_J"] = _nnz(J)


def _nnz(J) -> int | None:
    """Stored entries of J, or of its assembled sparse form for a structured operator."""
    import scipy.sparse as sp

    if sp.issparse(J):
        return int(J.nnz)
    if isinstance(J, np.ndarray):
        return int(J.size)
    try:
        return int(J.tocsr().nnz)
    except Exception:  # an operator without an assembled form: nnz is not defined
        return None


def _child_main() -> None:
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


def _run_child(spec: dict, timeout: float | None) -> dict:
    """Run one case in a fresh interpreter; errors become ``{"error": ...}``."""
    cmd = [sys.executable, "-c", "from femodes.app.scaling import _child_main; _child_main()"]
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
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
    for line in reversed(out.splitlines()):
        if line.startswith(_MARK):
            rec = json.loads(line[len(_MARK):])
            rec["wall_s"] = wall
            return rec
    if proc.returncode < 0:
        try:
            name = signal.Signals(-proc.returncode).name
        except ValueError:
            name = f"signal {-proc.returncode}"
        hint = " (out of memory? the kernel's OOM killer sends SIGKILL)" if name == "SIGKILL" else ""
        return {"error": f"child process killed by {name}{hint}", "wall_s": wall}
    tail = [ln for ln in err.strip().splitlines() if ln.strip()]
    return {"error": f"child process failed (exit {proc.returncode}): {tail[-1] if tail else 'no message'}",
            "wall_s": wall}


def _record(ne: int | None, H: int, d: dict) -> ScalingRecord:
    names = {f.name for f in dataclasses.fields(ScalingRecord)} - {"n_elements", "H"}
    return ScalingRecord(n_elements=ne, H=H, **{k: v for k, v in d.items() if k in names and v is not None})


# ---------------------------------------------------------------------------------------------
# Fits, files, plot
# ---------------------------------------------------------------------------------------------
def _slope(xs, ys) -> float:
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


def _value(r: ScalingRecord, quantity: str) -> float:
    if quantity == "iteration":
        return r.iteration_median_s
    if quantity == "point":
        return r.point_s
    return r.peak_mib - r.baseline_mib


def fit_exponents(records: Sequence[ScalingRecord]) -> list[ScalingFit]:
    """Least-squares log-log slopes against N at every H, and against H at every N (>= 2 sizes)."""
    ok = [r for r in records if r.ok and r.N]
    fits = []
    for quantity in ("iteration", "point", "memory"):
        for against, fixed in (("N", "H"), ("H", "N")):
            for fv in sorted({getattr(r, fixed) for r in ok}):
                pts = sorted((getattr(r, against), _value(r, quantity)) for r in ok if getattr(r, fixed) == fv)
                pts = [(x, y) for x, y in pts if math.isfinite(y) and y > 0]
                if len({x for x, _ in pts}) >= 2:
                    xs, ys = zip(*pts)
                    fits.append(ScalingFit(quantity=quantity, against=against, fixed=fixed, fixed_value=int(fv),
                                           exponent=_slope(xs, ys), sizes=tuple(int(x) for x in xs)))
    return fits


def _jsonable(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, Path):
        return str(v)
    return v


def _write_tables(out: Path, case_name: str, records, fits, settings: dict, interrupted: bool) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    csv_path, json_path = out / "scaling.csv", out / "scaling.json"
    tmp = csv_path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for r in records:
            w.writerow(["" if (v is None or (isinstance(v, float) and not math.isfinite(v))) else v
                        for v in (getattr(r, k) for k in CSV_COLUMNS)])
    os.replace(tmp, csv_path)  # a Ctrl-C while writing leaves the previous complete file
    doc = {"case": case_name, "settings": settings, "interrupted": interrupted,
           "records": [r.to_dict() for r in records], "exponents": [dataclasses.asdict(f) for f in fits]}
    tmp = json_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(_jsonable(doc), indent=1) + "\n")
    os.replace(tmp, json_path)
    return [csv_path, json_path]


def plot_scaling(result_records: Sequence[ScalingRecord], fits: Sequence[ScalingFit], path: Path,
                 title: str = "") -> Path:
    """Log-log plot: times per iteration (solid) and per point (dashed) against N and against H."""
    from matplotlib.figure import Figure  # lazy: matplotlib is optional for `import femodes`

    ok = [r for r in result_records if r.ok and r.N]
    slope = {(f.quantity, f.against, f.fixed_value): f.exponent for f in fits}
    fig = Figure(figsize=(11, 5.4), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, against, fixed, xlabel in ((axes[0], "N", "H", "N (DOFs of the full model)"),
                                       (axes[1], "H", "N", "H (harmonics)")):
        groups = sorted({getattr(r, fixed) for r in ok})
        colours = [f"C{i % 10}" for i in range(len(groups))]
        xs_all = set()
        for fv, col in zip(groups, colours):
            rows = sorted((r for r in ok if getattr(r, fixed) == fv), key=lambda r: getattr(r, against))
            xs = [getattr(r, against) for r in rows]
            xs_all.update(xs)
            for quantity, style, marker, what in (("iteration", "-", "o", "iteration"),
                                                   ("point", "--", "s", "point")):
                ys = [_value(r, quantity) for r in rows]
                keep = [(x, y) for x, y in zip(xs, ys) if math.isfinite(y) and y > 0]
                if not keep:
                    continue
                s = slope.get((quantity, against, fv))
                label = f"{fixed}={fv}: per {what}" + (f", slope {s:.2f}" if s is not None else "")
                ax.plot(*zip(*keep), style, marker=marker, color=col, mfc=col if quantity == "iteration" else "none",
                        label=label)
        ax.set_xscale("log")
        ax.set_yscale("log")
        if xs_all and (against == "H" or len(xs_all) <= 6):
            # label the measured sizes themselves (log axes would print 5 x 10^0 for H)
            ax.set_xticks(sorted(xs_all), [str(x) for x in sorted(xs_all)])
            ax.minorticks_off()
        ax.set_xlabel(xlabel)
        ax.set_ylabel("wall time [s]")
        ax.set_title(f"time against {against} at fixed {fixed}")
        ax.grid(True, which="both", alpha=0.3)
        if len(xs_all) < 2:
            flag = "--elements" if against == "N" else "--harmonics"
            ax.text(0.5, 0.5, f"one {against} only: give several values with {flag}", transform=ax.transAxes,
                    ha="center", va="center", color="grey")
        if ok:
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
    if title:
        fig.suptitle(title + "  (per iteration: median of the repeats)", fontsize=10)
    fig.savefig(path, dpi=120)
    return path


# ---------------------------------------------------------------------------------------------
# The study
# ---------------------------------------------------------------------------------------------
def _progress_bar(n_cases: int, stream=None):
    from .cli import ProgressBar  # the command line's bar (this module is application layer too)

    class CaseBar(ProgressBar):
        """``[#####.....]  2/6 cases  N=1000 H=10 ...``."""

        def show(self, done: int, text: str) -> str:
            f = self.fraction(done)
            k = int(round(f * self.width))
            line = f"\r[{'#' * k}{'.' * (self.width - k)}] {done}/{int(self.p1)} cases  {text}\x1b[K"
            self.stream.write(line)
            self.stream.flush()
            self.shown = True
            return line

    return CaseBar((0, n_cases), "cases", stream=stream)


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
    the module docstring for what is timed and how); ``scaling.csv`` and ``scaling.json`` in
    ``out`` are rewritten after every case and ``scaling.png`` is drawn at the end.

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
    harmonics_list = _int_values("harmonics", harmonics) if harmonics is not None else [
        int(case.data["analysis"].get("harmonics", 10))]
    if elements is not None:
        elements_list: list[int | None] = list(_int_values("elements", elements))
        why = _variable_mesh(case)
        if why is not None:
            raise ValueError(f"scaling_study: elements: cannot vary the number of elements: {why}; "
                             "to vary only the harmonics, leave out elements (--elements)")
    else:
        elements_list = [case.data["mesh"].get("n_elements") if "mesh" in case.data else None]
    repeat = _check_int("repeat", repeat, 1)
    points = _check_int("points", points, 0)
    if points == 1:
        raise ValueError("scaling_study: points must be 0 (skip the continuation) or >= 2, got 1")
    if timeout is not None and not (isinstance(timeout, numbers.Real) and timeout > 0):
        raise ValueError(f"scaling_study: timeout must be a positive number of seconds, got {timeout!r}")
    out = Path(out)
    path = case.path.resolve() if case.path else Path("case.toml")
    settings = {
        "case": str(path), "elements": elements_list, "harmonics": harmonics_list, "repeat": repeat,
        "points": points, "analysis": case.data["analysis"]["type"],
        "reduction": case.data.get("reduction", {}).get("craig_bampton"),
        "machine": {"python": platform.python_version(), "numpy": np.__version__, "platform": platform.platform(),
                    "cpus": os.cpu_count(), **{v: os.environ.get(v) for v in (
                        "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS") if os.environ.get(v)}},
    }
    pairs = [(ne, H) for ne in elements_list for H in harmonics_list]
    records: list[ScalingRecord] = []
    files: list[Path] = []
    bar = _progress_bar(len(pairs)) if progress else None
    interrupted = False
    try:
        for k, (ne, H) in enumerate(pairs):
            label = (f"n_elements={ne} " if ne is not None else "") + f"H={H}"
            if bar is not None:
                bar.show(k, f"running {label}")
            sub = _with(case, ne, H)
            spec = {"path": str(path), "text": sub.text, "data": sub.data, "name": sub.name,
                    "repeat": repeat, "points": points}
            rec = _record(ne, H, _run_child(spec, timeout))
            records.append(rec)
            if bar is not None:
                bar.close()  # log records on their own lines; the bar is redrawn for the next case
            if rec.ok:
                log.info("scaling %s: N=%s, %.3g ms per iteration, %.3g s per point, peak %.0f MiB", label, rec.N,
                         1e3 * rec.iteration_median_s, rec.point_s, rec.peak_mib)
            else:
                log.warning("scaling %s failed: %s", label, rec.error)
            files = _write_tables(out, case.name, records, fit_exponents(records), settings, False)
        if bar is not None:
            bar.show(len(pairs), "done")
    except KeyboardInterrupt:
        interrupted = True
        log.warning("scaling study interrupted after %d of %d cases; keeping what was measured",
                    len(records), len(pairs))
    finally:
        if bar is not None:
            bar.close()
    fits = fit_exponents(records)
    files = _write_tables(out, case.name, records, fits, settings, interrupted)
    if records:
        title = f"{path.name}: {settings['analysis']}" + (" (Craig-Bampton)" if settings["reduction"] else "")
        files.append(plot_scaling(records, fits, out / "scaling.png", title=title))
    return ScalingResult(case=case.name, records=tuple(records), fits=tuple(fits), files=tuple(files),
                         interrupted=interrupted, settings=settings)


# ---------------------------------------------------------------------------------------------
# Command line (``femodes scaling``; the parser is in cli.py)
# ---------------------------------------------------------------------------------------------
SCALING_HELP = """Scaling study of a TOML case file: for every N x H pair, in a fresh process,
  per iteration   median (and min) over --repeat of problem.residual(x, p) + default_linear_solver(J, r)
                  at a state with active contacts when possible,
  per point       wall time of the case's analysis capped at --points points / points,
  peak MiB        ru_maxrss of the case's process.
N is varied through [mesh] n_elements (line meshes only; not for mesh files or discrete models),
H through [analysis] harmonics. Writes scaling.csv (after every case: Ctrl-C keeps what was
measured), scaling.json (with the fitted log-log exponents) and scaling.png to --out.
Example:  femodes scaling case.toml --elements 100,1000,10000 --harmonics 5,10,20
"""


def add_scaling_parser(sub) -> None:
    """The ``femodes scaling`` subcommand on the command line's subparsers."""
    import argparse

    sc = sub.add_parser("scaling", help="time and memory of a case file against N and H", description=SCALING_HELP,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    sc.add_argument("case", type=Path, help="the case file (a line mesh [mesh] n_elements = ... to vary N)")
    sc.add_argument("--elements", type=positive_int_list, default=None, metavar="NE,NE,...",
                    help="values of [mesh] n_elements, e.g. 100,1000,10000 (default: the case's mesh)")
    sc.add_argument("--harmonics", type=positive_int_list, default=None, metavar="H,H,...",
                    help="values of [analysis] harmonics, e.g. 5,10,20 (default: the case's)")
    sc.add_argument("--repeat", type=_positive_int, default=3, help="repetitions of the timed Newton iteration (3)")
    sc.add_argument("--points", type=_points, default=5,
                    help="continuation points of the timed analysis (5; 0 skips it)")
    sc.add_argument("--timeout", type=_positive_float, default=None, metavar="SECONDS",
                    help="stop a case after this long and record it as failed")
    sc.add_argument("--out", type=Path, default=None, help="output folder (default: out/<case file name>_scaling)")
    sc.add_argument("--progress", dest="progress", action="store_true", default=None,
                    help="show a progress bar over the cases on stderr (default: when stderr is a terminal)")
    sc.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")


def _positive_int(text: str) -> int:
    import argparse

    v = positive_int_list(text)
    if len(v) != 1:
        raise argparse.ArgumentTypeError(f"expected one positive integer, got {text!r}")
    return v[0]


def _points(text: str) -> int:
    import argparse

    if text.strip() == "0":
        return 0
    v = _positive_int(text)
    if v < 2:
        raise argparse.ArgumentTypeError(f"expected 0 (skip the continuation) or an integer >= 2, got {text!r}")
    return v


def _positive_float(text: str) -> float:
    import argparse

    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return v


def scaling_cli(args) -> int:
    """``femodes scaling``: 0 if every case was measured, 1 if some failed, 2 for bad input, 130 on Ctrl-C."""
    path = Path(args.case)
    out = args.out if args.out is not None else Path("out") / f"{path.stem}_scaling"
    show = sys.stderr.isatty() if args.progress is None else args.progress
    try:
        res = scaling_study(path, elements=args.elements, harmonics=args.harmonics, repeat=args.repeat,
                            points=args.points, out=out, timeout=args.timeout, progress=show)
    except CaseError as exc:
        print(f"femodes scaling: {exc}", file=sys.stderr)
        return 2
    except (ValueError, TypeError) as exc:
        print(f"femodes scaling: {str(exc).removeprefix('scaling_study: ')}", file=sys.stderr)
        return 2
    print(res.table())
    print()
    if res.fits:
        print("fitted exponents (least squares on log-log):")
        for line in res.fit_lines():
            print(f"  {line}")
    else:
        print("no exponent fitted (needs >= 2 measured sizes of N or H)")
    print(f"outputs written to {Path(out).resolve()} ({', '.join(p.name for p in res.files)})")
    if res.interrupted:
        print(f"interrupted: {len(res.records)} case(s) measured", file=sys.stderr)
        return 130
    return 0 if res.success else 1
