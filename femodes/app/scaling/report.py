"""Application layer: what a scaling study reports: fitted exponents, files and the plot.

:func:`fit_exponents` fits ``t ~ N^a`` (at fixed ``H``) and ``t ~ H^b`` (at fixed ``N``) by least
squares on log-log axes. :func:`write_tables` writes ``scaling.csv`` (one row per case) and
``scaling.json`` (settings, records, fitted exponents), each atomically, so that an interrupted
study keeps its last complete files; :func:`plot_scaling` draws ``scaling.png`` (log-log plots
with the fitted slopes in the legends).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
from pathlib import Path
from collections.abc import Sequence

import numpy as np

from .records import CSV_COLUMNS, ScalingFit, ScalingRecord

__all__ = ["fit_exponents", "write_tables", "plot_scaling"]


# ---------------------------------------------------------------------------------------------
# Fits
# ---------------------------------------------------------------------------------------------
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


def _slope(xs, ys) -> float:
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


def _value(r: ScalingRecord, quantity: str) -> float:
    """The fitted ``quantity`` of a record (see :class:`ScalingFit`)."""
    if quantity == "iteration":
        return r.iteration_median_s
    if quantity == "point":
        return r.point_s
    return r.peak_mib - r.baseline_mib


# ---------------------------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------------------------
def write_tables(out: Path, case_name: str, records, fits, settings: dict, interrupted: bool) -> list[Path]:
    """Write ``scaling.csv`` and ``scaling.json`` in ``out`` (created if missing); their paths."""
    out.mkdir(parents=True, exist_ok=True)
    csv_path, json_path = out / "scaling.csv", out / "scaling.json"
    _write_csv(csv_path, records)
    doc = {"case": case_name, "settings": settings, "interrupted": interrupted,
           "records": [r.to_dict() for r in records], "exponents": [dataclasses.asdict(f) for f in fits]}
    tmp = json_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(_jsonable(doc), indent=1) + "\n")
    os.replace(tmp, json_path)
    return [csv_path, json_path]


def _write_csv(path: Path, records) -> None:
    """One row per record, :data:`CSV_COLUMNS` in order; None and NaN as empty cells."""
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for r in records:
            w.writerow(["" if (v is None or (isinstance(v, float) and not math.isfinite(v))) else v
                        for v in (getattr(r, k) for k in CSV_COLUMNS)])
    os.replace(tmp, path)  # a Ctrl-C while writing leaves the previous complete file


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


# ---------------------------------------------------------------------------------------------
# Plot
# ---------------------------------------------------------------------------------------------
def plot_scaling(result_records: Sequence[ScalingRecord], fits: Sequence[ScalingFit], path: Path,
                 title: str = "") -> Path:
    """Log-log plot: times per iteration (solid) and per point (dashed) against N and against H."""
    from matplotlib.figure import Figure  # lazy: matplotlib is optional for `import femodes`

    ok = [r for r in result_records if r.ok and r.N]
    slope = {(f.quantity, f.against, f.fixed_value): f.exponent for f in fits}
    fig = Figure(figsize=(11, 5.4), layout="constrained")
    axes = fig.subplots(1, 2)
    _plot_against(axes[0], ok, slope, "N", "H", "N (DOFs of the full model)")
    _plot_against(axes[1], ok, slope, "H", "N", "H (harmonics)")
    if title:
        fig.suptitle(title + "  (per iteration: median of the repeats)", fontsize=10)
    fig.savefig(path, dpi=120)
    return path


def _plot_against(ax, ok: list[ScalingRecord], slope: dict, against: str, fixed: str, xlabel: str) -> None:
    """One panel: the measured records against ``against``, one colour per value of ``fixed``."""
    groups = sorted({getattr(r, fixed) for r in ok})
    xs_all = set()
    for i, fv in enumerate(groups):
        rows = sorted((r for r in ok if getattr(r, fixed) == fv), key=lambda r: getattr(r, against))
        xs_all.update(getattr(r, against) for r in rows)
        _plot_group(ax, rows, slope, against, fixed, fv, f"C{i % 10}")
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
        flag = "--elements or --refine" if against == "N" else "--harmonics"
        ax.text(0.5, 0.5, f"one {against} only: give several values with {flag}", transform=ax.transAxes,
                ha="center", va="center", color="grey")
    if ok:
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)


def _plot_group(ax, rows: list[ScalingRecord], slope: dict, against: str, fixed: str, fv: int, col: str) -> None:
    """The times per iteration (solid, filled) and per point (dashed, open) of one ``fixed = fv``."""
    xs = [getattr(r, against) for r in rows]
    for quantity, style, marker in (("iteration", "-", "o"), ("point", "--", "s")):
        ys = [_value(r, quantity) for r in rows]
        keep = [(x, y) for x, y in zip(xs, ys) if math.isfinite(y) and y > 0]
        if not keep:
            continue
        s = slope.get((quantity, against, fv))
        label = f"{fixed}={fv}: per {quantity}" + (f", slope {s:.2f}" if s is not None else "")
        ax.plot(*zip(*keep), style, marker=marker, color=col, mfc=col if quantity == "iteration" else "none",
                label=label)
