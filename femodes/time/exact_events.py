"""The certified search for the next contact event of the exact flow (:mod:`.exact`).

On one segment in one mode, the event functions (the gap of every contact, the force of a closed
massless one) are ``g(t + s) = Re(Re_c e^{Lambda s} z + sum_k Ye_k e^{i k w (t + s)})``. They are
sampled on a coarse grid (:data:`~femodes.time.exact.SAMPLES` per period of the highest forcing
harmonic); on an interval of length ``h`` each modal term ``c_m e^{lambda_m s}`` moves the
function by less than ``|c_m| min(|lambda_m|^2 h^2 / 8, 2)`` away from the chord of its samples,
so an interval whose samples exceed that bound has no event and is not looked at again; the
others are split (:data:`REFINE` parts) down to ``SAMPLES`` points per shortest period of the
flow, where sign changes and sampled minima bracket the event, which Newton on the closed form
locates to round-off (4 eps in time). A stiff model pays the fine grid only near its events.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

__all__ = ["EventSearch", "CHUNK", "REFINE"]

#: Largest number of grid points of one fine search evaluated at once (memory CHUNK x 2n complex
#: numbers); longer searches go chunk by chunk and stop at the first event.
CHUNK = 4096
#: Parts into which the certified search splits an interval that may hold an event.
REFINE = 8


class EventSearch:
    """The first event of one segment of a run in the mode ``m`` at its frequency ``d`` (the
    mode's particular solution and grid steps): :meth:`first`. ``samples`` counts the event
    function evaluations (the cost of a stiff model)."""

    def __init__(self, m, d):
        self._m, self._d = m, d
        self.samples = 0

    def values(self, t: float, z: np.ndarray, tau: np.ndarray, rates: bool = True):
        """Event functions and their rates (None without ``rates``) at ``t + tau`` (rows) for
        every contact (columns)."""
        m, d = self._m, self._d
        self.samples += tau.size
        E = np.exp(np.multiply.outer(tau, m.lam)) * z  # (p, 2nI)
        ph = d.phases(t + tau)  # (p, nk)
        g = np.real(E @ m.Re.T + ph @ d.Ye)
        if not rates:
            return g, None
        r = np.real((E * m.lam) @ m.Re.T + (ph * d.iw) @ d.Ye)
        return g, r

    def first(self, t: float, z: np.ndarray, t1: float):
        """``(time, contact)`` of the first event in ``(t, t1]``, or None: the certified coarse
        search (module docstring), then the fine search where it cannot exclude an event."""
        span = t1 - t
        if span <= 0.0:
            return None
        d = self._d
        fine = d.dt
        m0 = max(1, int(math.ceil(span / d.coarse)))
        h = span / m0
        if h <= REFINE * fine:  # not stiff: the fine search everywhere
            return self._fine(t, z, 0.0, span)
        m = self._m
        # intervals [j h, (j + 1) h] by their integer index j on the current level's grid: the end
        # of one is the start of the next to the bit, so each grid point is evaluated once
        idx = np.arange(m0)
        amp = np.abs(m.Re * z)  # (nc, 2nI) modal amplitudes of the event functions
        famp = np.abs(d.Ye[1:]) if d.ks.size > 1 else np.zeros((0, d.Ye.shape[1]))
        kw = np.abs(d.iw[1:])
        while h > fine:
            # the starts, then the ends that are not the next interval's start
            p = idx.size
            joined = np.append(np.diff(idx) == 1, False)
            g, _ = self.values(t, z, np.concatenate([idx, idx[~joined] + 1]) * h, rates=False)
            ga, gb = g[:p], g[np.where(joined, np.arange(1, p + 1), p + np.cumsum(~joined) - 1)]
            if idx[0] == 0:
                ga[0] = np.minimum(ga[0], 0.0)  # after an event the function starts at 0: look closer
            starts = idx * h
            growth = np.exp(np.multiply.outer(starts, m.lam.real)) * np.maximum(1.0, np.exp(m.lam.real * h))
            curv = np.minimum(np.abs(m.lam) ** 2 * h * h / 8.0, 2.0)
            bound = growth @ (amp * curv).T + (np.minimum(kw ** 2 * h * h / 8.0, 2.0) @ famp)
            unsure = np.any(np.minimum(ga, gb) - bound < 0.0, axis=1)
            below = np.flatnonzero(np.any(gb < 0.0, axis=1))
            if below.size:  # an event for sure up to there: nothing after it matters
                unsure[below[0] + 1:] = False
            idx = idx[unsure]
            if not idx.size:
                return None
            idx = (idx[:, None] * REFINE + np.arange(REFINE)).ravel()
            h /= REFINE
        starts = idx * h
        # the intervals left, in time order, as runs of adjacent ones: the first event found is the first
        cut = np.flatnonzero(np.diff(starts) > 1.5 * h) + 1
        for run in np.split(starts, cut):
            hit = self._fine(t, z, float(run[0]), float(run[-1]) + h)
            if hit is not None:
                return hit
        return None

    def _fine(self, t: float, z: np.ndarray, a: float, b: float):
        """The first event in ``(t + a, t + b]`` on the fine grid (chunk by chunk)."""
        fine = self._d.dt
        m = max(2, int(math.ceil((b - a) / fine)))
        if m > CHUNK:
            edges = np.linspace(a, b, -(-m // CHUNK) + 1)
            for lo, hi in zip(edges[:-1], edges[1:]):
                hit = self._fine(t, z, lo, hi)
                if hit is not None:
                    return hit
            return None
        tau = np.linspace(a, b, m + 1)
        g, r = self.values(t, z, tau)
        return self._first_crossing(t, z, tau, g, r, m, after_event=(a == 0.0))

    def _first_crossing(self, t, z, tau, g, r, m, after_event: bool):
        """The earliest crossing on the sampled event functions ``g`` (rates ``r``) at ``t + tau``."""
        best = None
        for c in range(g.shape[1]):
            gc, rc = g[:, c], r[:, c]
            gc0 = max(gc[0], 0.0) if after_event else gc[0]  # at 0 after an event (or round-off below)

            def value(s, c=c):
                return self._scalar(t, z, c, s)[0]

            found = None
            for i in range(1, m + 1):
                a = gc0 if i == 1 else gc[i - 1]
                if gc[i] < 0.0:
                    lo = tau[i - 1]
                    if i == 1 and gc[0] <= 0.0 and after_event:  # leaving zero: where does it return?
                        lo = self._leave(value, tau[0], tau[1])
                        if lo is None:
                            found = None
                            break
                    found = self._root(t, z, c, lo, tau[i])
                    break
                if a > 0.0 and rc[i - 1] < 0.0 < rc[i]:  # a minimum between two grid points: grazing?
                    s_min = self._root(t, z, c, tau[i - 1], tau[i], rate=True)
                    if self._scalar(t, z, c, s_min)[0] < 0.0:
                        found = self._root(t, z, c, tau[i - 1], s_min)
                        break
            if found is not None and (best is None or found < best[0]):
                best = (found, c)
        if best is None:
            return None
        return t + best[0], best[1]

    def _scalar(self, t: float, z: np.ndarray, c: int, s: float) -> tuple[float, float, float]:
        """Event function ``c`` at ``t + s``, its rate and the rate's rate (one point)."""
        m, d = self._m, self._d
        e = np.exp(m.lam * s) * z
        ph = np.exp(d.iw * (t + s))
        row, y = m.Re[c], d.Ye[:, c]
        val = (row @ e + y @ ph).real
        rate = (row @ (m.lam * e) + y @ (d.iw * ph)).real
        acc = (row @ (m.lam ** 2 * e) + y @ (d.iw ** 2 * ph)).real
        return val, rate, acc

    def _root(self, t: float, z: np.ndarray, c: int, a: float, b: float, rate: bool = False) -> float:
        """The zero in ``[a, b]`` of event function ``c`` (positive at ``a``, negative at ``b``),
        or with ``rate`` of its rate (negative at ``a``, positive at ``b``: the function's
        minimum): Newton on the closed form with its derivative, kept in the bracket (bisection
        when a step leaves it), to round-off in time."""
        tol = 4.0 * np.finfo(float).eps * max(1.0, abs(t) + abs(b))
        sign = -1.0 if rate else 1.0  # the function is positive at a
        x = 0.5 * (a + b)
        for _ in range(100):
            g, r, dr = self._scalar(t, z, c, x)
            val, der = (sign * r, sign * dr) if rate else (g, r)
            if val > 0.0:
                a = x
            elif val < 0.0:
                b = x
            else:
                return x
            x1 = x - val / der if der != 0.0 else 0.5 * (a + b)
            if not a < x1 < b:
                x1 = 0.5 * (a + b)
            if abs(x1 - x) <= tol or b - a <= tol:
                return x1
            x = x1
        return x

    @staticmethod
    def _leave(value, a: float, b: float):
        """After an event the function starts at 0 and must grow: the first sampled interval is
        negative only if it returns within one grid step; the root sought is then the one after
        the function's maximum."""
        res = minimize_scalar(lambda s: -value(s), bounds=(a, b), method="bounded")
        if -res.fun <= 0.0:
            return None
        return res.x
