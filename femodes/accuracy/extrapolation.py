"""What the levels of one point say (:class:`PointLevels`): with the distances ``d_j`` of successive
levels (frequency and displacement coefficients, each relative), the contraction per doubling of H
is ``r = d_{j-1} / d_j`` and the error of level ``j - 1`` is ``d_j r / (r - 1)``; with rigid impacts
(first order in ``1/H``, ``r`` rising to 2 from below) the converged frequency is bracketed between
the finest level plus ``d`` and plus ``d / (r - 1)``. The measurements behind these rules are in
docs/guide/accuracy.md ("Levels") and benchmarks/README_accuracy.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..hbm.harmonics import Harmonics
from .options import AccuracyOptions

__all__ = ["PointLevels", "bounded_by_bracket", "contracting", "estimate_levels", "BRACKET_MAX_HALF_WIDTH"]


@dataclass
class PointLevels:
    """Solutions of one point at successive levels (doubling H), and what they say."""

    states: list
    Q_norm: float
    omega_ref: float
    options: AccuracyOptions = AccuracyOptions()

    def diffs(self, j: int) -> tuple[float, float]:
        """Relative changes (frequency, displacement) from level ``j - 1`` to level ``j``."""
        a, b = self.states[j - 1], self.states[j]
        h = Harmonics(max(a.H, b.H))
        dQ = Harmonics(b.H).layout.convert(b.Q, h) - Harmonics(a.H).layout.convert(a.Q, h) if a.H != b.H else b.Q - a.Q
        return abs(b.omega - a.omega) / self.omega_ref, float(np.linalg.norm(dQ)) / self.Q_norm

    def distance(self, j: int) -> float:
        dw, dq = self.diffs(j)
        return math.hypot(dw, dq)

    def rate(self, j: int) -> float:
        """Observed contraction per doubling at level ``j`` (needs ``j >= 2``), clamped below."""
        d1, d2 = self.distance(j - 1), self.distance(j)
        if d2 <= 1e-14 or not math.isfinite(d1 / d2):
            return math.inf if d1 <= 1e-14 or d2 <= 1e-14 else self.options.rate_min
        return max(d1 / d2, self.options.rate_min)

    def frequency_bracket(self) -> tuple[float, float]:
        """The frequency extrapolated to ``H -> inf`` from the last three levels and the relative
        half-width of the interval that contains it, assuming first-order convergence approached
        from below (rigid impacts; docs/guide/accuracy.md, "Levels"); NaN when the levels do not
        support that assumption, or bracket a non-positive frequency or one wider than
        :data:`BRACKET_MAX_HALF_WIDTH`."""
        w0, w1, w2 = (st.omega for st in self.states[-3:])
        d1, d2 = w1 - w0, w2 - w1
        dmax = max(abs(d1), abs(d2))
        if dmax <= self.options.same_point * self.omega_ref:  # the same point on every level (no contact),
            return w2, dmax / self.omega_ref  # to the solver's tolerance: signs of the changes are noise
        if d1 == 0.0 or d2 == 0.0 or d1 * d2 < 0.0:
            return math.nan, math.nan
        r = d1 / d2
        if not 1.0 < r <= self.options.bracket_rate_max:
            return math.nan, math.nan
        lo, hi = w2 + d2, w2 + d2 / (r - 1.0)
        mid = 0.5 * (lo + hi)
        half = 0.5 * abs(hi - lo) / self.omega_ref
        if not (mid > 0.0 and half <= BRACKET_MAX_HALF_WIDTH):
            return math.nan, math.nan  # levels far from their asymptotic range: no limit to report
        return mid, half

    def error(self, j: int, of: int) -> tuple[float, float, float]:
        """Estimated relative error (frequency, displacement) of level ``of`` (``j - 2``,
        ``j - 1`` or ``j``) from levels ``j - 2, j - 1, j``; and the ratio used: the change to the
        next level times ``r / (r - 1)``, or for the finest level its last change over ``r - 1``."""
        if of not in (j - 2, j - 1, j):
            raise ValueError(f"error: level {of} is not one of {j - 2}, {j - 1}, {j}")
        r = self.rate(j)
        dw, dq = self.diffs(j if of == j else of + 1)
        if not math.isfinite(r):
            return dw, dq, r
        f = 1.0 / (r - 1.0) if of == j else r / (r - 1.0)
        return dw * f, dq * f, r


#: A bracket of the converged frequency wider than this (relative half-width) is not reported: the
#: levels are then far from the first-order range the bracket assumes. Near the peak of a user's
#: curved P2 bracket (a Craig-Bampton model, 11 contacts, levels 5-10-20) the levels changed the
#: frequency by tens of percent with ratios just above 1; the brackets were 30-142 % wide and
#: their middles 615-2504 rad/s and -3420 rad/s for series at 5294-5366 rad/s, which the branch
#: then reported as its frequencies. Every bracket the test suite computes (the seed references
#: among them) is narrower: the suite passes unchanged with the limit.
BRACKET_MAX_HALF_WIDTH = 0.1


def estimate_levels(H: int) -> tuple[list[int], int]:
    """The levels of :func:`~femodes.estimate_error` for a branch with ``H`` harmonics and which of them is
    the branch's own: ``H // 2, H, 2H`` for even ``H >= 4``; ``H, 2H, 4H`` for odd ``H >= 5``
    (``H // 2`` would not be a doubling: for H = 5 the levels 2, 5, 10 made the rate and the
    bracket assume the wrong spacing, an optimistic estimate and an exact value outside the
    bracket); ``H, 2H + 1, 4H + 2`` for ``H < 4`` (from H = 1, 2H = 2 adds only an even harmonic,
    zero for a symmetric law such as Duffing's, which would estimate no error at all)."""
    if H < 4:
        return [H, 2 * H + 1, 4 * H + 2], 0
    if H % 2:
        return [H, 2 * H, 4 * H], 0
    return [H // 2, H, 2 * H], 1


def bounded_by_bracket(ew: float, omega: float, w_lim: float, half: float, omega_ref: float) -> float:
    """The frequency error estimate of a point with contacts, at least the distance from its own
    frequency to the far end of the bracket of the converged frequency: the estimate
    ``d r / (r - 1)`` assumes later ratios at least the observed ``r``, which a non-monotone
    ratio breaks (FE bar with a tip mass, H = 8: ratio 1.75 at levels 4-8-16, 1.52 at 10-20-40,
    estimate 2.41 % for a true 2.69 %); the bracket rests on the weaker assumption of ratios
    between ``r`` and 2."""
    if not (math.isfinite(w_lim) and math.isfinite(half)):
        return ew
    return max(ew, abs(omega - w_lim) / omega_ref + half)


def contracting(chain: list, Q_norm: float, omega_ref: float) -> bool:
    """Whether a point's last three levels contract: all solved, and the change from the middle
    to the finest smaller than the one before (:meth:`PointLevels.distance`). Only then does a
    further level of the refinement extend a convergence the levels show; where the changes
    grow, the truncation is not in its asymptotic range there (just above a grazing) or the limit
    is not an orbit the levels resolve. Seed case 2 from H = 20 by the levels: three points just
    above the rising grazing whose levels 10-20-40 grow got brackets from levels 80 and 160
    (0.79591 +- 4e-6 to 0.79663 +- 2.7e-5) that said "met" while the exact curve crosses their
    hyperplanes at 0.7936 or 0.86 and above; seed case 1 one such point (0.90837 +- 6.2e-4, the
    crossings at 0.956 and 1.407). ``cant20`` of benchmarks/README_accuracy.md (exact orbits that
    chatter): 152 of 257 points above rtol 1e-3 after level 40 and 23 of 81 after level 80 do
    not contract or miss a level; that alone took its estimate from 511 s to 459 s, most of it
    still the continuation of level 80, which ``AccuracyOptions.level_points_per_point`` now stops;
    it brackets none of its folds either way."""
    if len(chain) < 3 or any(st is None for st in chain[-3:]):
        return False
    lv = PointLevels(chain[-3:], Q_norm, omega_ref)
    return lv.distance(2) < lv.distance(1)
