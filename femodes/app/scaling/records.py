"""Application layer: the records of a scaling study and their markdown table.

:class:`ScalingRecord` holds the measurements of one ``(N, H)`` case, :class:`ScalingFit` one
fitted exponent and :class:`ScalingResult` the whole study (records, fits, written files).
:data:`CSV_COLUMNS` is the order of the record's fields in ``scaling.csv`` and ``scaling.json``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["CSV_COLUMNS", "ScalingRecord", "ScalingFit", "ScalingResult"]

CSV_COLUMNS = (
    "n_elements", "refine", "mesh", "N", "n_reduced", "H", "unknowns", "nnz_J", "iteration_median_s", "iteration_min_s",
    "residual_median_s", "solve_median_s", "point_s", "points", "newton_iterations", "stability_s",
    "stability_method", "peak_mib",
    "baseline_mib", "setup_s", "wall_s", "jacobian", "contact_active", "state", "continuation", "error",
)

#: What each fitted quantity is, in words.
_WHAT = {"iteration": "time per Newton iteration", "point": "time per continuation point",
         "memory": "peak memory above baseline"}


#: A case's Jacobian counts as dense when it stores more than this fraction of unknowns^2 entries
#: (the HBM Jacobian of an FE model stores O(unknowns); an assembled modal damping or a dense
#: reduced model makes it O(unknowns^2), and every solve then costs O(unknowns^3)).
DENSE_JACOBIAN_FRACTION = 0.1


@dataclass(frozen=True)
class ScalingRecord:
    """Measurements of one ``(N, H)`` case; times in seconds, memory in MiB (NaN: not measured).

    ``N`` is the number of DOFs of the full model, ``n_reduced`` that of the Craig-Bampton
    model the analysis runs on (None without reduction), ``unknowns`` the size of the HBM
    problem, ``jacobian`` the type of the Jacobian its ``residual`` returns and ``nnz_J`` the
    number of stored entries of that Jacobian (of its assembled sparse form for a structured
    operator). ``stability_s`` is the cost of the branch's stability per point (NaN when the
    case asks for none) and ``stability_method`` the methods it used. ``error`` is empty for a
    measured case. ``n_elements`` is the line mesh's number of elements, ``refine`` the
    refinement factor of the case's mesh (``scaling_study(refine=...)``) and ``mesh`` the element
    divisions of a refined solid (``"nx=40 ny=4"``); None/empty when not varied.
    """

    n_elements: int | None
    H: int
    refine: float | None = None
    mesh: str = ""
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
    stability_s: float = math.nan
    stability_method: str = ""
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

    @property
    def dense_jacobian(self) -> bool:
        """``nnz(J) > DENSE_JACOBIAN_FRACTION * unknowns^2``: the case's Jacobian is dense."""
        return (self.nnz_J is not None and bool(self.unknowns)
                and self.nnz_J > DENSE_JACOBIAN_FRACTION * float(self.unknowns) ** 2)

    def dense_note(self) -> str:
        """The warning for a dense Jacobian (empty otherwise)."""
        if not self.dense_jacobian:
            return ""
        return (f"dense Jacobian: nnz(J) = {self.nnz_J / float(self.unknowns) ** 2:.0%} of unknowns^2 "
                f"(> {DENSE_JACOBIAN_FRACTION:.0%})")

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in CSV_COLUMNS}


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
    """Result of :func:`femodes.app.scaling.scaling_study`: one record per case, fitted exponents,
    written files."""

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
        """Markdown table of the records (``mesh``: the divisions of a refined solid, ``-`` otherwise)."""
        head = ("| N | reduced | H | unknowns | nnz(J) | iteration median [ms] | min [ms] | residual [ms] | "
                "solve [ms] | per point [s] | points | stability per point [s] | setup [s] | peak [MiB] | note | mesh |")
        lines = [head, "|" + "---|" * (head.count("|") - 1)]
        lines += ["| " + " | ".join(_row(r)) + " |" for r in self.records]
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


def _row(r: ScalingRecord) -> list[str]:
    """The cells of one record in :meth:`ScalingResult.table`."""
    return [_cell(r.N), _cell(r.n_reduced), str(r.H), _cell(r.unknowns), _cell(r.nnz_J),
            _ms(r.iteration_median_s), _ms(r.iteration_min_s), _ms(r.residual_median_s),
            _ms(r.solve_median_s), _num(r.point_s, "{:.3g}"), str(r.points), _stability(r),
            _num(r.setup_s, "{:.3g}"), _num(r.peak_mib, "{:.0f}"), _short(_note(r)), r.mesh or "-"]


def _stability(r: ScalingRecord) -> str:
    """Stability cost per point and the methods used (``-`` when the case computes none)."""
    if r.stability_method.startswith("failed"):
        return _short(r.stability_method, 40)
    if math.isnan(r.stability_s):
        return "-"
    return f"{r.stability_s:.3g} ({r.stability_method})"


def _note(r: ScalingRecord) -> str:
    """The error of a failed case, or what a measured one lacks (active contact, a full branch)."""
    note = r.error or ("" if r.contact_active is not False else "no active contact")
    if r.continuation.startswith("failed") and not r.error:
        note = (note + "; " if note else "") + r.continuation
    if r.dense_jacobian:
        note = r.dense_note() + ("; " + note if note else "")
    return note


def _cell(v) -> str:
    return "-" if v is None else str(v)


def _num(v: float, fmt: str) -> str:
    return fmt.format(v) if v is not None and math.isfinite(v) else "-"


def _ms(v: float) -> str:
    return _num(1e3 * v if v is not None else math.nan, "{:.3g}")


def _short(text: str, n: int = 70) -> str:
    text = " ".join(str(text).split()).replace("|", "/")
    return text if len(text) <= n else text[: n - 3] + "..."
