"""Solvers layer: a bracketed scalar root, by the Illinois variant of regula falsi.

Used wherever a sign change of a test function between two points of a branch is located: folds
(the p-component of the tangent, :mod:`femodes.solvers.continuation`), stability changes
(``|mu| - 1``) and period doublings of harmonic balance orbits. Each evaluation there is a
corrector solve, so the superlinear Illinois update (Dowell and Jarratt, BIT 11 (1971) 168-174:
the retained end's value is halved when the same end is kept twice) is worth having; the
evaluation may fail (``None``), which ends the search with the bracket reached so far.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

import numpy as np

__all__ = ["Bracket", "illinois"]


@dataclass(frozen=True)
class Bracket:
    """The final bracket ``[lo, hi]`` with the true test-function values at its ends, and the
    number of evaluations."""

    lo: float
    hi: float
    f_lo: float
    f_hi: float
    nfev: int


def illinois(f: Callable[[float], float | None], lo: float, hi: float, f_lo: float, f_hi: float, *,
             max_iter: int, ftol: float = 0.0, xtol: float = 0.0, margin: float = 0.0,
             bisect_if_slow: bool = False) -> Bracket:
    """Shrink the bracket ``[lo, hi]`` of a sign change of ``f`` (``f(lo) = f_lo``, ``f(hi) = f_hi``).

    Stops after ``max_iter`` evaluations, when ``|f(x)| <= ftol`` or the bracket is at most
    ``xtol`` wide (both tested after each evaluation), or when ``f`` returns ``None``.
    ``margin`` keeps each trial at least that fraction of the bracket away from its ends;
    ``bisect_if_slow`` bisects whenever the previous step did not halve the bracket (for test
    functions that jump instead of crossing zero, where regula falsi alone crawls).
    """
    g_lo, g_hi = f_lo, f_hi  # Illinois-weighted values
    side = 0
    last = None
    n = 0
    for _ in range(max_iter):
        width = hi - lo
        x = (lo * g_hi - hi * g_lo) / (g_hi - g_lo) if g_hi != g_lo else 0.5 * (lo + hi)
        if not (lo < x < hi) or (bisect_if_slow and last is not None and width > 0.5 * last):
            x = 0.5 * (lo + hi)
        if margin:
            x = min(max(x, lo + margin * width), hi - margin * width)
        last = width
        fx = f(x)
        n += 1
        if fx is None:
            break
        stop = abs(fx) <= ftol
        if np.sign(fx) == np.sign(g_lo):
            lo, g_lo, f_lo = x, fx, fx
            if side == -1:
                g_hi *= 0.5
            side = -1
        else:
            hi, g_hi, f_hi = x, fx, fx
            if side == 1:
                g_lo *= 0.5
            side = 1
        if stop or hi - lo <= xtol:
            break
    return Bracket(lo=lo, hi=hi, f_lo=f_lo, f_hi=f_hi, nfev=n)
