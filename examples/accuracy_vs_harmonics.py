"""How accurate is a harmonic balance frequency, and what does it cost to know? (femodes.accuracy)

Three 1-DOF systems with exact answers, against the number of harmonics H:

* **forced fold** - the upper fold of the forced impact oscillator (seed case 1)
  ``u'' + 0.1 u' + u = 0.2 cos(w t) - p``, stop at gap 1, w 0.5 -> 2.0 (``frequency_response``);
  exact: the event-driven fold ``upper_fold(0.1, 0.2, 1).w = 1.419158`` (``tests/impact_reference.py``,
  restitution 1, independent of femodes);
* **free backbone** - ``u'' + u = -p``, stop at gap 1, the backbone (``nonlinear_mode``) from
  E = 0.3 to E = A^2 / 2 at A = 1.9; its last point against the exact
  ``w = pi / (pi - arccos(g / A))``;
* **Duffing backbone** - ``u'' + u + u^3 = 0`` up to A = 1 (E = 0.75), against
  ``w = pi sqrt(1 + A^2) / (2 K(m))``, ``m = A^2 / (2 (1 + A^2))`` (elliptic integral).

For each H: the true relative error of the branch's own frequency, the estimate
``branch.accuracy.omega`` of ``fm.estimate_error`` (levels H/2, H, 2H), the extrapolated
``accuracy.omega_limit`` (impacts only: first order in 1/H) with the relative half-width
``accuracy.omega_limit_error`` of its bracket, and the CPU (and wall) time of the plain run and of
the estimate (``method=fm.error_methods.Levels()``: this example studies the levels of harmonics). Then
``nonlinear_mode(..., rtol=2e-3)`` from H = 10 on the free backbone: it adds levels 40, 80 where
the bracket is too wide; and ``frequency_response(..., rtol=1e-3)`` on the forced oscillator from
H = 10 and 20 with the default ``error_method`` (``fm.error_methods.Auto()``): a linear model with a rigid stop, so the
converged orbits come from shooting on the exact flow (``femodes.time.exact``).

Measured (H = 5, 10, 20, 40; estimates at H = 5, 10, 20, odd H = 5 with the levels 5, 10, 20):

* forced fold: true error 7.9, 4.4, 2.4, 1.3 % (first order in 1/H); estimate 9.7, 5.5, 2.7 %;
  extrapolated limit off by 0.094 % (half-width 0.50 %), 0.094 % (0.49 %), 0.022 % (0.14 %);
* free backbone at A = 1.9: true 10.2, 6.0, 3.4, 1.9 %; estimate 12.7, 7.7, 3.9 %; limit off by
  0.23 % (half-width 1.1 %), 0.23 % (1.1 %), 0.0017 % (0.33 %); ``rtol=2e-3`` from H = 10: limit off
  by 3.6e-5 (half-width 0.13 %, levels to 80), 1.6 s of CPU;
* Duffing at H = 1, 3, 5, 7: 2.5e-3, 3.7e-6, 3.3e-9, 2.2e-12 (~700x per odd harmonic), every
  estimate within 2 % of the true error;
* forced fold by shooting (``rtol=1e-3``): limit 1.4191583461 from H = 10 and H = 20, off by
  4e-15 and 1e-16 (stated half-width 1e-9), in 1.1 s and 2.0 s of CPU with the plain run.

So the estimate is safe and close (1.1-1.3x the true error) and the exact value lies inside the
bracket, whose midpoint is 20-2000x closer than the branch itself. Odd H costs more to estimate
(the levels H, 2H, 4H: H // 2 would not be a doubling, and the ratio and the bracket assume
doublings); prefer even H.

Costs (CPU, one BLAS thread, load about 1): the forced fold's plain runs take 0.2, 0.2, 0.5,
1.0 s at H = 5, 10, 20, 40; its estimate 0.9, 0.9, 1.8 s at H = 5, 10, 20 (3.7x the plain run at
H = 20: each level is traced by a continuation of its own over the part of the branch with
contact, the finest costing about a plain run at 2H there); the free backbone's estimate at
H = 20 takes 0.5 s for a 0.2 s branch. The estimate at H = 40 is left out to keep the example
short. ``benchmarks/bench_accuracy.py`` has the costs of ``rtol=1e-3`` and ``1e-4`` on the
forced cases (``README_accuracy.md``). About 14 s of CPU.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

import numpy as np
from scipy.special import ellipk

import femodes as fm


def _reference():
    """The event-driven references of the test suite (plain numpy/scipy, no femodes inside)."""
    path = Path(__file__).resolve().parents[1] / "tests" / "impact_reference.py"
    name = "femodes_examples_impact_reference"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, path)
        sys.modules[name] = importlib.util.module_from_spec(spec)  # dataclasses look their module up
        spec.loader.exec_module(sys.modules[name])
    return sys.modules[name]


_ref = _reference()

# -- the three systems ----------------------------------------------------------------------------
GAP, FORCE, DAMPING, W_SPAN = 1.0, 0.2, 0.1, (0.5, 2.0)
A_FREE = 1.9
E_FREE = (0.3, A_FREE**2 / 2)  # from below grazing (E = 0.5) to A = 1.9
A_DUFFING = 1.0
E_DUFFING = (0.05, A_DUFFING**2 / 2 + A_DUFFING**4 / 4)

FORCED_H = (5, 10, 20, 40)  # plain runs
ESTIMATE_H = (5, 10, 20)  # estimate_error (levels H/2, H, 2H; odd H: H, 2H, 4H); H = 40 costs 15 min
FREE_H = (5, 10, 20, 40)
DUFFING_H = (1, 3, 5, 7)  # odd harmonics only (the cubic spring has no even ones)
RTOL, RTOL_H = 2e-3, 10

#: Small steps on the free backbone: its estimate walks the levels along the points, and with
#: steps of 0.2 the level-40 solves next to grazing fail and are halved (H = 20: 10 points, 23 s of
#: CPU for the estimate; with 0.03: 39 points, 10 s, the same numbers at A = 1.9).
BACKBONE_OPTIONS = fm.ContinuationOptions(step=0.03, max_step=0.03, newton=fm.NewtonOptions(atol=1e-9, max_iter=20))

forced_model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[DAMPING]])
                .with_contact(fm.UnilateralContact(at=0, gap=GAP))
                .with_forcing(fm.HarmonicForce(at=0, amplitude=FORCE)))
free_model = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=GAP))
duffing_model = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))

FOLD_EXACT = _ref.upper_fold(DAMPING, FORCE, GAP).w


def free_exact(energy: float) -> float:
    return _ref.free_frequency(float(energy), GAP)


def duffing_exact(energy: float) -> float:
    A = np.sqrt(np.sqrt(1.0 + 4.0 * energy) - 1.0)  # E = A^2/2 + A^4/4 at the turning point
    m = A**2 / (2.0 * (1.0 + A**2))
    return float(np.pi * np.sqrt(1.0 + A**2) / (2.0 * ellipk(m)))


# -- one row per (system, H) ----------------------------------------------------------------------
class _Clock:
    """Wall and CPU (process) time of a block: the machine may be shared, CPU time is the cost."""

    def __enter__(self):
        self.wall, self.cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall, self.cpu = time.perf_counter() - self.wall, time.process_time() - self.cpu


def _row(branch, i: int, exact: float, plain: _Clock, estimate: _Clock | None) -> dict:
    """True error of point ``i``, its estimate and extrapolation (NaN if not estimated)."""
    w = float(branch.omega_truncated[i])  # the truncated series' own frequency (branch.omega: the answer)
    row = dict(H=branch.harmonics.n_harmonics, omega=w, exact=exact, true=abs(w / exact - 1.0), points=len(branch),
               wall_plain=plain.wall, cpu_plain=plain.cpu,
               wall_estimate=np.nan if estimate is None else estimate.wall,
               cpu_estimate=np.nan if estimate is None else estimate.cpu,
               estimate=np.nan, limit=np.nan, limit_error=np.nan, half_width=np.nan, finest=np.nan, met=None)
    acc = branch.accuracy
    if acc is not None:
        row["estimate"] = float(acc.omega[i])
        if acc.omega_limit is not None:
            row["limit"] = float(acc.omega_limit[i])
            row["limit_error"] = abs(row["limit"] / exact - 1.0)
            row["half_width"] = float(acc.omega_limit_error[i])
        row["finest"] = int(acc.finest[i]) if acc.finest is not None else np.nan
        row["met"] = bool(acc.met[i]) if acc.rtol is not None else None
    return row


def _estimated(branch, estimate: bool) -> _Clock | None:
    if not estimate:
        return None
    with _Clock() as c:
        fm.estimate_error(branch, method=fm.error_methods.Levels())  # the levels of harmonics (this example's subject)
    return c


def forced_fold(H: int, estimate: bool = True) -> dict:
    """The upper fold (``folds[0]``) of seed case 1 with ``H`` harmonics."""
    with _Clock() as c:
        b = fm.frequency_response(forced_model, W_SPAN, H)
    e = _estimated(b, estimate)
    return _row(b, b.folds[0], FOLD_EXACT, c, e)


def free_backbone(H: int, estimate: bool = True, rtol: float | None = None) -> dict:
    """The last point of the free impact backbone (E = A^2/2 exactly: the continuation ends there)."""
    with _Clock() as c:
        b = fm.nonlinear_mode(free_model, 1, energy=E_FREE, harmonics=H, options=BACKBONE_OPTIONS, rtol=rtol)
    e = _estimated(b, estimate and rtol is None)
    i = len(b) - 1
    return _row(b, i, free_exact(b.energy[i]), c, e)


def duffing_backbone(H: int) -> dict:
    with _Clock() as c:
        b = fm.nonlinear_mode(duffing_model, 1, energy=E_DUFFING, harmonics=H)
    e = _estimated(b, True)
    i = len(b) - 1
    return _row(b, i, duffing_exact(b.energy[i]), c, e)


forced = {H: forced_fold(H, estimate=H in ESTIMATE_H) for H in FORCED_H}
free = {H: free_backbone(H, estimate=H in ESTIMATE_H) for H in FREE_H}
duffing = {H: duffing_backbone(H) for H in DUFFING_H}
free_rtol = free_backbone(RTOL_H, rtol=RTOL)


def forced_shooting(H: int) -> dict:
    """``frequency_response(..., rtol=1e-3)`` with the default ``error_method`` (``fm.error_methods.Auto()``): this linear
    model with a rigid stop gets the converged orbits by shooting on the exact flow."""
    with _Clock() as c:
        b = fm.frequency_response(forced_model, W_SPAN, H, rtol=1e-3)
    return _row(b, b.folds[0], FOLD_EXACT, c, None)


SHOOT_H = (10, 20)
forced_shoot = {H: forced_shooting(H) for H in SHOOT_H}


def table() -> str:
    lines = ["system          H  points  w_H         true err   estimate   limit err  half-width  "
             "plain CPU (wall) [s]  estimate CPU (wall) [s]"]
    for name, rows in (("forced fold", forced), ("free backbone", free), ("Duffing", duffing)):
        for H, r in rows.items():
            lines.append(f"{name:14s} {H:3d} {r['points']:6d}  {r['omega']:.7f}  {r['true']:.3e}  {r['estimate']:.3e}  "
                         f"{r['limit_error']:.3e}  {r['half_width']:.3e}   {r['cpu_plain']:6.1f} ({r['wall_plain']:5.1f})"
                         f"        {r['cpu_estimate']:6.1f} ({r['wall_estimate']:5.1f})")
    for H, r in forced_shoot.items():
        lines.append(f"forced fold, rtol = 1e-3 by shooting from H = {H}: limit {r['limit']:.10f} (exact "
                     f"{r['exact']:.10f}), error {r['limit_error']:.1e}, half-width {r['half_width']:.0e}, met {r['met']}, "
                     f"CPU {r['cpu_plain']:.1f} s (wall {r['wall_plain']:.1f} s) with the plain run")
    r = free_rtol
    lines.append(f"free backbone, rtol = {RTOL:g} from H = {RTOL_H}: limit {r['limit']:.6f} (exact {r['exact']:.6f}), "
                 f"error {r['limit_error']:.2e}, half-width {r['half_width']:.2e}, met {r['met']}, finest level "
                 f"{r['finest']}, CPU {r['cpu_plain']:.1f} s (wall {r['wall_plain']:.1f} s)")
    return "\n".join(lines)


def _columns(rows: dict, *keys):
    return [np.array(list(rows), dtype=float)] + [np.array([r[k] for r in rows.values()], dtype=float) for k in keys]


def _h_ticks(ax, ticks):
    from matplotlib.ticker import NullFormatter

    ax.set_xticks(list(ticks))
    ax.set_xticklabels([str(t) for t in ticks])
    ax.xaxis.set_minor_formatter(NullFormatter())


def main(out="out"):
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(16, 8.0), gridspec_kw={"width_ratios": [1.25, 0.8, 1.0]})
    impacts = ((f"forced fold (seed case 1, w_exact = {FOLD_EXACT:.6f})", forced, "C0"),
               (f"free impact backbone at A = {A_FREE} (w_exact = {free[FREE_H[0]]['exact']:.6f})", free, "C1"))
    for label, rows, c in impacts:
        H, true, est, lim, half = _columns(rows, "true", "estimate", "limit_error", "half_width")
        ax1.loglog(H, true, "o-", color=c, ms=7, label=label)
        ok = np.isfinite(est)
        ax1.loglog(H[ok], est[ok], "s--", color=c, mfc="none", ms=10)
        ok = np.isfinite(lim)
        ax1.loglog(H[ok], lim[ok], "x", color=c, ms=10, mew=2)
        ax1.loglog(H[ok], half[ok], "v", color=c, mfc="none", ms=9)
    r = free_rtol
    ax1.loglog([RTOL_H], [r["limit_error"]], "*", color="C1", ms=15)
    Hs_ = np.array(list(forced_shoot), dtype=float)
    ax1.loglog(Hs_, np.full(Hs_.size, 7e-6), "P", color="C0", ms=11)  # exact to round-off: drawn on the axis
    ax1.text(Hs_[0] * 1.08, 8.5e-6, "forced fold by shooting (rtol = 1e-3, auto):\nerror < 1e-14, below the axis",
             fontsize=7.5, color="C0")
    ax1.text(4.2, 1.2e-4, "H = 5 is odd: its levels are 5, 10, 20\n(H // 2 = 2 would not be a doubling)",
             fontsize=7.5, color="0.3")
    Hs = np.array([4.0, 50.0])
    ax1.loglog(Hs, 0.4 / Hs, "k:", lw=1.2, label="slope -1 (first order in 1/H)")
    ax1.set_xlabel("harmonics H of the branch")
    ax1.set_ylabel("relative frequency error |w / w_exact - 1|")
    ax1.set_title("impacts: error against H (estimate from levels H/2, H, 2H)", fontsize=10)
    ax1.set_xlim(4, 50)
    ax1.set_ylim(5e-6, 0.3)
    _h_ticks(ax1, FORCED_H)
    ax1.grid(True, which="major", alpha=0.3)
    keys = ax1.get_legend_handles_labels()[0] + [
            Line2D([], [], color="k", marker="o", ls="-", label="true error of the branch's w"),
            Line2D([], [], color="k", marker="s", mfc="none", ls="--", label="estimate accuracy.omega"),
            Line2D([], [], color="k", marker="x", ls="", mew=2, label="extrapolated omega_limit: true error"),
            Line2D([], [], color="k", marker="v", mfc="none", ls="", label="omega_limit_error (bracket half-width)"),
            Line2D([], [], color="C1", marker="*", ls="", ms=12,
                   label=f"free backbone, rtol = {RTOL:g} from H = {RTOL_H}: omega_limit true error"),
            Line2D([], [], color="C0", marker="P", ls="", ms=10,
                   label="forced fold, rtol = 1e-3 by shooting (error_method auto): omega_limit exact")]
    ax1.legend(handles=keys, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=1)

    H, true, est = _columns(duffing, "true", "estimate")
    ax2.semilogy(H, true, "o-", color="C2", ms=7, label="true error of the branch's w")
    ax2.semilogy(H, est, "s--", color="C2", mfc="none", ms=10, label="estimate accuracy.omega")
    ax2.set_xlabel("harmonics H of the branch (odd: no even harmonics)")
    ax2.set_ylabel("relative frequency error |w / w_exact - 1|")
    ax2.set_title(f"smooth: Duffing backbone at A = {A_DUFFING}, exponential in H", fontsize=10)
    ax2.set_xticks(H)
    ax2.grid(True, which="major", alpha=0.3)
    ax2.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1))

    for label, rows, c in (("forced fold", forced, "C0"), ("free backbone", free, "C1"), ("Duffing", duffing, "C2")):
        H, tp, te = _columns(rows, "cpu_plain", "cpu_estimate")
        ax3.loglog(H, tp, "o-", color=c, ms=7, label=f"{label}: plain run")
        ok = np.isfinite(te)
        ax3.loglog(H[ok], tp[ok] + te[ok], "s--", color=c, mfc="none", ms=10, label=f"{label}: plain + estimate_error")
    ax3.loglog([RTOL_H], [r["cpu_plain"]], "*", color="C1", ms=15,
               label=f"free backbone: rtol = {RTOL:g} from H = {RTOL_H} (levels to {r['finest']})")
    H, ts = _columns(forced_shoot, "cpu_plain")
    ax3.loglog(H, ts, "P", color="C0", ms=11, label="forced fold: rtol = 1e-3 by shooting (plain run included)")
    ax3.set_xlabel("harmonics H of the branch")
    ax3.set_ylabel("CPU time [s] (one process, 1 BLAS thread)")
    ax3.set_title("cost of a run and of its error estimate", fontsize=10)
    ax3.grid(True, which="major", alpha=0.3)
    _h_ticks(ax3, (1, 3, 5, 10, 20, 40))
    ax3.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=1)
    fig.subplots_adjust(left=0.05, right=0.98, top=0.95, bottom=0.36, wspace=0.28)
    path = out / "accuracy_vs_harmonics.png"
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


if __name__ == "__main__":
    print(table())
    print("saved", main())
