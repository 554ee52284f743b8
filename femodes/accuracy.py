r"""Analyses layer: how far a harmonic balance branch is from the converged (``H -> inf``) answer.

Harmonic balance with ``H`` harmonics converges exponentially for smooth laws (Duffing) and
only algebraically for impacts: the velocity jumps at an impact, the displacement spectrum decays
like ``k^-2``, and the upper fold of a forced impact oscillator moves by ``~C/H`` (first order in
``1/H``: 4.4 %, 2.4 %, 1.2 %, 0.67 % at H = 10, 20, 40, 80 against the event-driven reference
of ``tests/impact_reference.py``). This module states that error for every point of a branch.

**Levels.** A point ``y_H = (x_H, p)`` of a branch is solved again with other harmonic counts
(the *levels* ``H/2`` and ``2H``) *on the hyperplane through the point normal to the branch*
(normal in the arclength norm of the branch; the new harmonics enter with zero normal
component), so the difference of two levels is the change of the curve, not a slide along it.
Nonlinear modes are compared at the same energy instead (the backbone's abscissa).
Newton cannot jump between levels from the branch's own point (the truncated or padded contact
forces are outside its basin), so each level is traced: with impacts by a continuation of the
level itself from a point without contact, each point being the crossing of that curve with its
hyperplane (:func:`_trace_level_by_continuation`; points it misses are walked from their
predecessor, and a continuation that stopped short starts again from a walked point; points
without contact force are every level's own point, nothing is solved for them, so the
continuation runs from the last of them before the first contact to two points after the last
contact), for smooth laws along the branch, point after point (:func:`_trace_level`). A
located fold is the level's nearest fold, so fold frequencies of the levels are compared
directly.

**Rate and estimate.** With the distances ``d_j = |X_j - X_{j-1}|`` of successive levels (``X``:
frequency and displacement coefficients, each relative), the observed contraction per doubling
is ``r = d_{j-1} / d_j``; if the error contracts geometrically with that ratio, the error of level
``j - 1`` is ``d_j r / (r - 1)``. The contraction observed at coarse levels is *smaller* than the
asymptotic one for impacts (fold of the seed's forced case: 1.62 at H = 10, 1.74 at H = 20,
-> 2), which makes the estimate err on the safe side (1.1-1.3x the true error there); a ratio
below :data:`RATE_MIN` (not yet in the asymptotic range, or not converging) is replaced by
``RATE_MIN``. Smooth laws give ratios of 10^2 - 10^6: the estimate is then the last difference.

**Extrapolation** (branches with complementarity contacts). Rigid impacts converge to first order
in ``1/H`` and the observed ratio rises towards 2 from below (fold of the seed's forced case:
1.69, 1.81, 1.85 at levels 5-10-20, 10-20-40, 20-40-80; free impact backbone 1.57, 1.71). If the
later ratios stay between the observed ``r`` and 2, the remaining change after the finest level
``X_2`` lies between ``d`` (ratio 2) and ``d / (r - 1)`` (ratio ``r``), ``d = X_2 - X_1``: the
frequency limit is bracketed, and :attr:`~femodes.results.ErrorEstimate.omega_limit` is the
midpoint with the relative half-width as its error. Measured: the fold of the forced case from
levels 10, 20, 40 lies in [1.41694, 1.42071] (reference 1.419158; midpoint -0.023 %, half-width
0.13 %), from 20, 40, 80 the midpoint is within 0.006 % (half-width 0.056 %); on the free
backbone (A = 1.9) from 10, 20, 40 the midpoint is within 0.002 % (half-width 0.32 %). The
assumption is not checked by three levels; a ratio outside ``(1, 2]`` or changes of opposite
signs give NaN; levels that agree to :data:`SAME_POINT` (points without contact) give the point
itself with their change as half-width. With impacts the frequency error of a point is at least
the distance from its frequency to the far end of the bracket, which keeps the estimate safe when
the observed ratio is not monotone (FE bar with a tip mass: 1.75, 1.52, 1.85 at levels 4-8-16,
10-20-40, 20-40-80).

**Refinement** (``rtol``, branches with complementarity contacts). The points whose bracket is
wider than ``rtol`` (or who have none) get a further level ``4 H``, ``8 H``... up to
``max_harmonics``, each traced by its own continuation from the last point without contact
before the first such point (every level is the branch's point there) and stopped a few points
past the last one (:class:`_Progress`); when those points fall in two groups far apart (the
rising side of a resonance and the unstable side by its lower fold), the second group is traced
backward from the branch's contact-free end instead (:func:`_plan_traces`: level 160 of the
seed's forced case at rtol 1e-3, 134 continuation points instead of 196). Each point's bracket
then comes from its last three levels.

**Shooting** (``method="auto"``, the default, or ``"shooting"``; forced branches of linear
models whose only contacts are rigid stops, on DOFs with mass (impacts) or on massless DOFs
(mass redistributed: the contact closes and opens, no impact); ``auto`` leaves to the levels a
model with more than :data:`SHOOTING_AUTO_MAX_DOFS` DOFs with mass, or whose probe run (one
period from the point with the largest contact force) evaluates more than
:data:`SHOOTING_AUTO_MAX_WORK` modal terms in its event search or has more than
:data:`SHOOTING_AUTO_MAX_EVENTS` events at one contact: a chattering orbit). The limit itself is computed
instead of extrapolated: the orbit of the exact flow with restitution 1 (closed form between
contact events, :class:`femodes.time.exact.LinearImpactFlow`) on each point's hyperplane, by Newton on
the start state and the frequency (monodromy matrix, the hyperplane's gradient and the frequency
column exact, from one variational run), each point from its predecessor's orbit. The
hyperplane is the levels' without its contact-force part (:class:`_Plane`: the exact contact
forces are impulses, whose coefficients the truncated forces do not resemble), so a point's
``omega_limit`` may differ from the levels' by the change of section (seed case 1: up to 0.6 %
on the steep sides, where the extrapolations' brackets are 0.03-0.08 % wide); folds do not
depend on it. A located fold is the extreme frequency of the exact orbits on hyperplanes
parallel to its own (Brent's method in the offset; with massless contacts a failed
continuation step to a plane is halved, :data:`FOLD_STEP_HALVINGS` times in all); where the impacting orbits end at a grazing
(the lower fold of a forced impact oscillator: the branch meets the linear response there) the
fold is that grazing frequency, in closed form (impacts only: with a massless contact DOF the
orbits with contact leave the linear one smoothly, and a lower fold is an ordinary one; 2-DOF
case of ``tests/test_exact_flow.py``: 1.0779321 by shooting, 1.0779320 at H = 80, the grazing
1.0808687). Measured from H = 20: the upper folds of the
seed's forced cases 1.4191583461 and 1.4227515912, equal to the event-driven references to
1e-16 and 9e-15; lower folds at the grazing frequencies 1.0808687 and 1.1519492. Just above
grazing the exact curve crosses the points' hyperplanes obliquely or backward (``kappa``,
:meth:`_Shooter.glancing`, outside ``(0, GLANCING_MAX]``, and a crossing angle with a cosine
below :data:`GLANCING_COS`, :meth:`_Shooter.crossing_cosine`): the crossing is no counterpart
of the point; the exact orbit at the point's own frequency is (:class:`_FrequencyPlane`: its
``omega_limit`` is the point's frequency, the error is in the amplitude). Seed cases at H = 20:
4 of 94 and 8 of 68 points are taken so (their amplitude errors 5.7e-4 to 2.0e-2, equal to
those of the orbits found independently at those frequencies, tests/test_exact_branch.py); where
Newton from the point stalls (6.3e-5 above the grazing), it starts from the linear orbit at the
point's frequency (:meth:`_Shooter.at_frequency`). Points where Newton finds no orbit start
again from the exact branch's crossing of their hyperplanes, and fall back to the levels if that
fails too. The exact branch over the branch's span (:func:`femodes.time.exact_frequency_response`,
continuation of exact orbits in the frequency) is traced once when needed
(:class:`_ExactBranchStarts`): after :data:`SHOOTING_EXACT_AFTER` points of the first pass without
an orbit (its crossings of the later points' hyperplanes are then tried before their own starts),
for the points still without one, and for folds the fold search does not locate. Once it is
there, the folds are taken from it instead of the fold search (:func:`_folds_from_exact_branch`):
each is paired with the nearest exact fold that turns the same way, one to one; a fold left
without a pair is a fold of the truncation: no estimate, method ``"truncation"`` (never met). The cantilever with 3 % modal
damping of ``benchmarks/README_accuracy.md`` (section 5): its main fold at H = 20, 3.8431, gets
the exact 3.9153002 (a time-domain sweep leaves the upper branch between 3.915 and 3.916), its
loop of two folds at 3.822 and 3.902 none; 3.9-4.1x the plain curve at rtol 1e-3 and 1e-4
(medians of three, README_accuracy section 6). The seed cases and the FE bars never need the exact branch.
That harmonic balance converges to the restitution-1 orbit is verified on the 1-DOF references
to round-off and on the FE bar of ``benchmarks/README_accuracy.md`` against its plain folds up
to H = 640.

Contact quality (penetration, tension) of every point is part of the estimate record
(:class:`femodes.results.ErrorEstimate`), relative to the displacement and contact-force levels.
"""

from __future__ import annotations

import logging
import time
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .hbm.harmonics import Harmonics
from .hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from .nonsmooth_modes import family_caveat
from .results import ERROR_METHODS, Branch, ErrorEstimate
from .solvers import ContinuationOptions, NewtonOptions, continuation
from .solvers.threads import limit_blas_threads
from .solvers.arclength import ArclengthSystem
from .solvers.bordered import bordered_solver
from .exact_branch import fold_is_upper
from .exact_response import exact_frequency_response
from .time.exact import LinearImpactFlow, exact_flow_unsupported, periodicity_residual, undamped

__all__ = ["estimate_error", "estimate_levels", "meet_tolerance", "RTOL_BUDGET", "RTOL_MIN_SECONDS", "rtol_time_limit", "shooting_unsupported_for", "refinement_options", "check_estimate_method",
           "shooting_unsupported", "ESTIMATE_METHODS", "RATE_MIN", "BRACKET_RATE_MAX"]

log = logging.getLogger(__name__)

#: Smallest contraction ratio per doubling of H used in the estimate: a ratio below it means the
#: levels are not yet in the asymptotic range (or diverge); ``r / (r - 1)`` is then at most 3.
RATE_MIN = 1.5

#: Methods of :func:`estimate_error`: "levels" (harmonic balance at other H), "shooting" (the
#: exact flow with rigid stops, :class:`_Shooter`), "auto" (shooting where it applies, levels for
#: the rest).
ESTIMATE_METHODS = ("auto", "levels", "shooting")

#: Largest observed ratio per doubling for which the frequency is bracketed: first order in 1/H
#: (rigid impacts) has the asymptotic ratio 2, approached from below on the references.
BRACKET_RATE_MAX = 2.0


#: Relative frequency change between levels below which they are the same point (a point without
#: contact: every level is the branch's own, up to the Newton tolerance of the level solves).
SAME_POINT = 1e-8


class _OutOfTime(Exception):
    """The estimate's time limit has passed (``estimate_error(time_limit=...)``)."""


@dataclass
class _State:
    """One solution at one level: the parts of the unknowns by name."""

    H: int
    Q: np.ndarray
    P: np.ndarray
    omega: float
    xi: float
    p: float
    nit: int = 0
    residual_norm: float = math.nan


class _Ladder:
    """The branch's HBM problem at any number of harmonics, and hyperplane solves on it."""

    def __init__(self, branch: Branch, projection=None, newton: NewtonOptions | None = None):
        if branch.model is None:
            raise ValueError("estimate_error: the branch has no model (loaded from a file?); attach it first with "
                             "branch.attach(model)")
        self.branch = branch
        self.model = branch.model
        self.h0 = branch.harmonics
        self.deadline: float | None = None  # time.perf_counter() after which the estimate stops
        self.level_times: dict[int, float] = {}  # seconds per level traced (NaN: started, unfinished)
        self.projection = projection
        self.newton = newton or NewtonOptions(atol=1e-9, max_iter=20)
        self.forced = branch.kind == "forced"
        self._problems: dict[int, object] = {}
        meta = branch.meta
        if not self.forced:
            span = meta.get("energy_span")
            if span is None or "mode" not in meta:
                raise ValueError("estimate_error: a nonlinear-mode branch needs its 'mode' and 'energy_span' "
                                 "(branch.meta, set by femodes.nonlinear_mode)")
            self.mode = int(meta["mode"])
            self.reference_energy = math.sqrt(float(span[0]) * float(span[1]))
        # arclength geometry of the branch (weights of the parts; the same for every level)
        Q, P = branch.Q, branch.P
        self.sQ = float(np.sqrt(np.mean(Q ** 2))) or 1.0
        self.sP = float(np.sqrt(np.mean(P ** 2))) if P.size else 1.0
        self.sP = self.sP or 1.0
        w = branch.omega
        if self.forced:  # the parameter is w: scaled by the width of the branch, as the continuation does
            self.sp = self.sw = float(np.ptp(w)) or 0.1 * float(np.mean(np.abs(w))) or 1.0
        else:  # p = log10(E) by 1; w (and xi) by a tenth of the mean frequency
            self.sp = 1.0
            self.sw = 0.1 * float(np.mean(np.abs(w))) or 1.0

    # -- levels -------------------------------------------------------------
    def check_time(self) -> None:
        """Raise :class:`_OutOfTime` once the deadline has passed."""
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise _OutOfTime

    def harmonics(self, H: int) -> Harmonics:
        h0 = self.h0
        default = Harmonics(H, subharmonic=h0.subharmonic)
        if h0.n_time == Harmonics(h0.n_harmonics, subharmonic=h0.subharmonic).n_time:
            return default  # the branch used the default sampling: so does every level
        return Harmonics(H, max(default.n_time, -(-h0.n_time * H // h0.n_harmonics)), h0.subharmonic)

    def problem(self, H: int):
        if H not in self._problems:
            h = self.harmonics(H)
            if self.forced:
                self._problems[H] = ForcedResponseProblem(self.model, h, projection=self.projection)
            else:
                self._problems[H] = NonlinearModeProblem(self.model, h, self.mode,
                                                         reference_energy=self.reference_energy,
                                                         projection=self.projection)
        return self._problems[H]

    def vector(self, H: int, Q, P, omega, xi, p) -> np.ndarray:
        """``y = (x, p)`` of level ``H`` from parts given on the branch's harmonics or level ``H``."""
        h = self.harmonics(H)
        Q = self._on(Q, h)
        P = self._on(P, h)
        x = self.problem(H).pack(Q, P, omega, xi)
        return np.append(x, omega if self.forced else p)

    def _on(self, A, h: Harmonics) -> np.ndarray:
        A = np.asarray(A, dtype=float)
        n_coef = A.shape[0]
        H = (n_coef - 1) // 2
        return self.harmonics(H).convert(A, h) if H != h.n_harmonics else A

    def padded(self, H: int, i: int) -> _State:
        """Point ``i`` of the branch on level ``H`` as it is (zero harmonics added, or dropped)."""
        a, h = _anchor(self.branch, i), self.harmonics(H)
        return _State(H, self._on(a.Q, h), self._on(a.P, h), a.omega, a.xi, a.p, a.nit, a.residual_norm)

    def state(self, H: int, y: np.ndarray) -> _State:
        u = self.problem(H).unpack(y[:-1], y[-1])
        return _State(H, u.Q.copy(), u.P.copy(), float(u.omega), float(u.xi), float(y[-1]))

    def weights(self, H: int) -> np.ndarray:
        """Weights of the branch's arclength norm, laid out on level ``H`` (1/n of level H0)."""
        h0 = self.h0
        nq = h0.n_coef * self.branch.Q.shape[2]
        npc = max(h0.n_coef * self.branch.P.shape[2], 1)
        h = self.harmonics(H)
        Qw = np.full((h.n_coef, self.branch.Q.shape[2]), 1.0 / (nq * self.sQ ** 2))
        Pw = np.full((h.n_coef, self.branch.P.shape[2]), 1.0 / (npc * self.sP ** 2))
        x = self.problem(H).pack(Qw, Pw, 1.0 / self.sw ** 2, 1.0 / self.sw ** 2)
        return np.append(x, 1.0 / self.sp ** 2)

    def solve(self, H: int, anchor: _State, normal: _State, guess: _State | None = None,
              deadline: int | None = None) -> _State | None:
        """The level-``H`` solution on the hyperplane through ``anchor`` normal to ``normal``
        (both on the branch's harmonics), Newton from ``guess`` (default: the anchor); with
        ``deadline``, abandoned as the continuation abandons a corrector
        (:meth:`~femodes.solvers.arclength.ArclengthSystem.correct`)."""
        prob = self.problem(H)
        a = self.vector(H, anchor.Q, anchor.P, anchor.omega, anchor.xi, anchor.p)
        c = self.weights(H) * self.vector(H, normal.Q, normal.P, normal.omega, normal.xi, normal.p)
        if guess is None:
            g = a
        else:
            g = self.vector(H, guess.Q, guess.P, guess.omega, guess.xi, guess.p)
            g = g - (c @ (g - a)) / (c @ c) * c  # onto the hyperplane
        sysa = ArclengthSystem(prob, prob.size, self.newton, bordered_solver)
        with np.errstate(all="ignore"):
            res = sysa.correct(g, c, deadline)
        if not res.success:
            log.debug("level H=%d: no solution on the hyperplane (%s)", H, res.message)
            return None
        st = self.state(H, res.x)
        st.nit, st.residual_norm = int(res.nit), float(res.residual_norm)
        return st

    @cached_property
    def tangents(self) -> list:
        """Normals of the hyperplanes of the points: the branch direction for forced responses
        (so that folds in w are crossed), the parameter for nonlinear modes (levels compared at
        the same energy, the backbone's own abscissa)."""
        if self.forced:
            return _tangents(self.branch)
        b = self.branch
        zero = _State(b.harmonics.n_harmonics, np.zeros_like(b.Q[0]), np.zeros_like(b.P[0]), 0.0, 0.0, 1.0)
        return [zero] * len(b)

    def Q_norm(self, i: int) -> float:
        return float(np.linalg.norm(self.branch.Q[i])) or 1.0

    def omega_ref(self, i: int) -> float:
        return abs(float(self.branch.omega[i])) or 1.0

    def moved(self, H: int, state: _State, a_from: _State, a_to: _State) -> _State:
        """The level-``H`` ``state`` moved by the branch's step from ``a_from`` to ``a_to``."""
        h = self.harmonics(H)
        return _State(H, self._on(state.Q, h) + self._on(a_to.Q - a_from.Q, h),
                      self._on(state.P, h) + self._on(a_to.P - a_from.P, h), state.omega + a_to.omega - a_from.omega,
                      state.xi + a_to.xi - a_from.xi, state.p + a_to.p - a_from.p)

    @staticmethod
    def blend(a: _State, b: _State, theta: float) -> _State:
        """``(1 - theta) a + theta b`` of two states on the same harmonics."""
        u = 1.0 - theta
        return _State(a.H, u * a.Q + theta * b.Q, u * a.P + theta * b.P, u * a.omega + theta * b.omega,
                      u * a.xi + theta * b.xi, u * a.p + theta * b.p)

    def locate_fold(self, H: int, states: list, f: int) -> _State | None:
        """The fold of level ``H`` that corresponds to the branch's fold ``f``.

        Normal hyperplanes cannot find it: the level's fold lies off the branch's by the error
        being measured (the H = 40 curve of the seed's forced case peaks below the amplitude of the
        H = 20 fold, so the hyperplane through that fold misses it). It is traced instead: a
        continuation of level ``H`` from the level's solution a few points before the fold, in
        the branch's direction, with the fold located by the continuation (regula falsi on dp/ds).
        """
        branch = self.branch
        j = next((j for j in range(f - 2, max(f - 60, -1), -1) if states[j] is not None), None)
        if j is None:
            return None
        st = states[j]
        dp = float(branch.parameter[f] - branch.parameter[j])
        width = max(4.0 * abs(dp), 0.1 * abs(float(branch.parameter[f])) if self.forced else 0.5)
        prob = self.problem(H)
        x0 = self.vector(H, st.Q, st.P, st.omega, st.xi, st.p)[:-1]
        span = (st.p, st.p + math.copysign(width, dp or 1.0))
        rms = float(np.sqrt(np.mean(x0 ** 2))) or 1.0
        opts = ContinuationOptions(step=0.02, max_step=0.1, max_points=300, x_scale=rms, p_scale=width,
                                   newton=self.newton)
        with np.errstate(all="ignore"):
            res = continuation(prob, span, x0=x0, options=opts)
        if not res.folds:
            log.info("accuracy: the fold near point %d was not found with H = %d (%s)", f, H, res.message)
            return None
        k = res.folds[0]
        out = self.state(H, np.append(res.x[k], res.p[k]))
        out.nit, out.residual_norm = int(res.nit[k]), float(res.residual_norm[k])
        return out


def _tangents(branch: Branch) -> list[_State]:
    """Branch directions at every point from its neighbours (central, one-sided at the ends);
    at a located fold the direction along the displacement (dp/ds = 0 there)."""
    n = len(branch)
    out = []
    for i in range(n):
        a, b = max(i - 1, 0), min(i + 1, n - 1)
        if a == b:
            raise ValueError("estimate_error: a branch of one point has no direction; it needs >= 2 points")
        out.append(_State(branch.harmonics.n_harmonics, branch.Q[b] - branch.Q[a], branch.P[b] - branch.P[a],
                          float(branch.omega[b] - branch.omega[a]), float(branch.xi[b] - branch.xi[a]),
                          float(branch.parameter[b] - branch.parameter[a])))
    return out


def _anchor(branch: Branch, i: int) -> _State:
    return _State(branch.harmonics.n_harmonics, branch.Q[i], branch.P[i], float(branch.omega[i]), float(branch.xi[i]),
                  float(branch.parameter[i]), int(branch.nit[i]), float(branch.residual_norm[i]))


@dataclass
class _Levels:
    """Solutions of one point at successive levels (doubling H), and what they say."""

    states: list
    Q_norm: float
    omega_ref: float

    def diffs(self, j: int) -> tuple[float, float]:
        """Relative changes (frequency, displacement) from level ``j - 1`` to level ``j``."""
        a, b = self.states[j - 1], self.states[j]
        h = Harmonics(max(a.H, b.H))
        dQ = Harmonics(b.H).convert(b.Q, h) - Harmonics(a.H).convert(a.Q, h) if a.H != b.H else b.Q - a.Q
        return abs(b.omega - a.omega) / self.omega_ref, float(np.linalg.norm(dQ)) / self.Q_norm

    def distance(self, j: int) -> float:
        dw, dq = self.diffs(j)
        return math.hypot(dw, dq)

    def rate(self, j: int) -> float:
        """Observed contraction per doubling at level ``j`` (needs ``j >= 2``), clamped below."""
        d1, d2 = self.distance(j - 1), self.distance(j)
        if d2 <= 1e-14 or not math.isfinite(d1 / d2):
            return math.inf if d1 <= 1e-14 or d2 <= 1e-14 else RATE_MIN
        return max(d1 / d2, RATE_MIN)

    def frequency_bracket(self) -> tuple[float, float]:
        """The frequency extrapolated to ``H -> inf`` from the last three levels and the relative
        half-width of the interval that contains it, assuming first-order convergence approached
        from below (rigid impacts; module docstring "Extrapolation"); NaN when the levels do not
        support that assumption."""
        w0, w1, w2 = (st.omega for st in self.states[-3:])
        d1, d2 = w1 - w0, w2 - w1
        dmax = max(abs(d1), abs(d2))
        if dmax <= SAME_POINT * self.omega_ref:  # the same point on every level (no contact), to the
            return w2, dmax / self.omega_ref     # solver's tolerance: signs of the changes are noise
        if d1 == 0.0 or d2 == 0.0 or d1 * d2 < 0.0:
            return math.nan, math.nan
        r = d1 / d2
        if not 1.0 < r <= BRACKET_RATE_MAX:
            return math.nan, math.nan
        lo, hi = w2 + d2, w2 + d2 / (r - 1.0)
        mid = 0.5 * (lo + hi)
        return mid, 0.5 * abs(hi - lo) / self.omega_ref

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


@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
def estimate_error(branch: Branch, *, rtol: float | None = None, max_harmonics: int | None = None, projection=None,
                   newton: NewtonOptions | None = None, method: str = "auto",
                   time_limit: float | None = None) -> Branch:
    """Attach the estimated error of every point of ``branch`` (``branch.error_estimate``).

    Each point is solved again with ``H // 2`` and ``2 H`` harmonics on the hyperplane normal to
    the branch (located folds: the fold of each level), and the error of the branch's level ``H``
    is ``|X_2H - X_H| r / (r - 1)`` with the observed ratio ``r`` (module docstring); with
    complementarity contacts the frequency error is at least the distance to the far end of the
    extrapolation bracket (:func:`_bounded_by_bracket`). Odd ``H >= 5`` uses the levels
    ``H, 2H, 4H``, ``H < 4`` the levels ``H, 2H + 1, 4H + 2`` (:func:`estimate_levels`; even ``H``
    is cheaper). Cost: one corrector solve per point and level, the finest dominating.

    With ``rtol`` (branches with complementarity contacts), the frequency bracket of every
    point whose half-width exceeds ``rtol`` (or that has none) is refined by a further level
    ``4 H``, ``8 H``... up to ``max_harmonics``: the level is traced only over the part of the
    branch that needs it, from the last point without contact before it (module docstring,
    "Refinement"). Smooth branches have no extrapolation; their estimate is that of the
    branch's own ``H`` (:func:`femodes.frequency_response` with ``rtol`` raises ``H`` instead).

    Parameters
    ----------
    branch : Branch
        From :func:`femodes.frequency_response` or :func:`femodes.nonlinear_mode`, with its model
        attached.
    rtol : float, optional
        Requested relative accuracy of the frequency (``0 < rtol < 0.5``);
        :attr:`~femodes.results.ErrorEstimate.met` tells which points meet it.
    max_harmonics : int, optional
        Largest level ``rtol`` may add (default ``8 H``; at least ``2 H``).
    projection : ExactProjection or SampledProjection, optional
        The projection the branch was computed with (default exact).
    newton : NewtonOptions, optional
    method : {"auto", "shooting", "levels"}, default "auto"
        ``"levels"``: harmonic balance at other H (above). ``"shooting"``: the exact orbits of
        the flow with rigid stops (module docstring, "Shooting"; forced branches of linear
        models with unilateral contacts only, else ValueError), the levels for the points where
        no orbit is found. ``"auto"``: shooting where it applies, else the levels.
        :attr:`~femodes.results.ErrorEstimate.method` tells per point which one answered.
    time_limit : float, optional
        Seconds after which the estimate stops (checked between the points of a level): the
        points it has not estimated get none (method ``"failed"``) and a warning says so. The
        analyses' ``rtol=`` gives :data:`RTOL_BUDGET` times the plain branch's own time.

    Returns
    -------
    Branch
        The same branch, with :attr:`~femodes.Branch.accuracy` (an
        :class:`~femodes.results.ErrorEstimate`) set.

    Notes
    -----
    The estimate covers the harmonic truncation only (``accuracy.covers``); the mesh's share is
    :func:`femodes.estimate_mesh_error`'s, which an estimate computed here keeps if the branch
    had it. A backbone that is the energy continuation's grazing family past grazing
    (:func:`femodes.nonsmooth_modes.family_caveat`) gets ``accuracy.caveat`` and meets ``rtol`` at
    no point. The levels of a period-driven backbone (``meta["family"] == "contact phase"``) are
    solved at each point from the branch's own orbit, neither continued in the energy nor walked
    from the previous point: both followed the grazing family past grazing, and the estimate was
    the distance between the two families (clamped bar, 20 elements, H = 10: 0.06 just past grazing
    to 0.6 at 20 E_g, where the error against the continuum's mode is a few 1e-3; solved point by
    point, 6e-4 to 1.6e-2 against true errors of 3e-4 to 7e-3). A point whose level has no orbit
    near it (in a tongue of internal resonance) gets no estimate (method ``"failed"``).
    """
    lad = _ladder(branch, projection, newton, "estimate_error")
    H = branch.harmonics.n_harmonics
    rtol, max_harmonics = refinement_options(rtol, max_harmonics, H)
    check_estimate_method(method, "estimate_error")
    if time_limit is not None:
        if isinstance(time_limit, bool) or not isinstance(time_limit, (int, float, np.integer, np.floating)) \
                or not time_limit > 0:
            raise ValueError(f"estimate_error: time_limit must be a positive number of seconds or None, got "
                             f"{time_limit!r}")
        lad.deadline = time.perf_counter() + float(time_limit)
    started = time.perf_counter()
    n = len(branch)
    impacts = "complementarity" in branch.contacts.kinds
    ew, eq, rates = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    w_lim, w_lim_err = (np.full(n, np.nan), np.full(n, np.nan)) if impacts else (None, None)
    finest = np.full(n, estimate_levels(H)[0][-1])
    kind = np.full(n, "doubling", dtype=object)
    todo = np.ones(n, dtype=bool)
    if method != "levels":
        why = shooting_unsupported(branch, projection)
        if why and method == "shooting":
            raise ValueError(f"estimate_error: method='shooting' cannot take this branch: {why}; use "
                             "method='levels' (or 'auto')")
        if not why:
            try:
                todo = _estimate_by_shooting(lad, ew, eq, rates, w_lim, w_lim_err, finest, kind,
                                             auto=method == "auto")
            except ValueError as exc:  # the flow itself (a nearly defective state matrix), or too stiff for auto
                if method == "shooting":
                    raise ValueError(f"estimate_error: method='shooting': {exc}") from None
                log.info("accuracy: no shooting (%s); levels", exc)
                ew[:] = eq[:] = rates[:] = w_lim[:] = w_lim_err[:] = np.nan
                kind[:] = "doubling"
                todo = np.ones(n, dtype=bool)
            if todo.any():
                log.info("accuracy: shooting found no exact orbit at %d point(s); levels there", int(todo.sum()))
    out_of_time = False
    if todo.any():
        try:
            _estimate_by_levels(lad, rtol, max_harmonics, todo, ew, eq, rates, w_lim, w_lim_err, finest)
        except _OutOfTime:
            out_of_time = True
    if out_of_time:
        missing = int(np.count_nonzero(~np.isfinite(ew) & (kind != "truncation")))
        done = ", ".join(f"H = {k} in {v:.3g} s" if np.isfinite(v) else f"H = {k} unfinished"
                         for k, v in lad.level_times.items())
        log.warning("accuracy: the error estimate stopped at its time limit (%.3g s, after %.3g s; levels: %s): "
                    "%d of %d points have no estimate (method 'failed'). The finer harmonic levels of this branch "
                    "cost far more than the branch; give estimate_error a larger time_limit, or fewer harmonics "
                    "or contacts (the rtol= of the analyses allows %g times the branch's own time, at least %g s)",
                    float(time_limit), time.perf_counter() - started, done or "none finished", missing, n,
                    RTOL_BUDGET, RTOL_MIN_SECONDS)
    pen, ten = branch.contact_quality()
    kind = np.where(np.isfinite(ew) | (kind == "truncation"), kind, "failed")
    # a mesh estimate already attached (femodes.estimate_mesh_error) does not depend on H: kept
    old = branch.accuracy
    mesh = {} if old is None or old.mesh is None else {"mesh": old.mesh, "mesh_method": old.mesh_method}
    branch.set_accuracy(ErrorEstimate(omega=ew, amplitude=eq, penetration=pen, tension=ten,
                                      harmonics=np.full(n, H), rate=rates, method=kind.astype(str), rtol=rtol,
                                      omega_limit=w_lim, omega_limit_error=w_lim_err, finest=finest,
                                      caveat=family_caveat(branch), **mesh))
    return branch


def _estimate_by_levels(lad: _Ladder, rtol, max_harmonics: int, todo: np.ndarray, ew, eq, rates, w_lim, w_lim_err,
                        finest) -> None:
    """The levels' estimate (module docstring) of the points ``todo``, into the arrays given."""
    branch = lad.branch
    H = branch.harmonics.n_harmonics
    levels, of = estimate_levels(H)
    if H >= 4 and H % 2:
        log.info("accuracy: odd H = %d: levels %d, %d, %d (H // 2 would not be a doubling; an even H is "
                 "about 4x cheaper to estimate)", H, *levels)
    impacts = "complementarity" in branch.contacts.kinds
    n = len(branch)
    if todo.all():
        trace = _trace_level_by_continuation if impacts and not _period_driven(branch) else _trace_level
        traced = []
        for H_l in levels:
            t0 = time.perf_counter()
            lad.level_times[H_l] = math.nan  # started
            traced.append(trace(lad, H_l))
            lad.level_times[H_l] = time.perf_counter() - t0
            lad.check_time()
    else:  # some points only (where shooting failed): continuations over their part of the branch
        free = _without_contact(branch)
        traced = []
        for H_l in levels:
            sts = [_anchor(branch, i) for i in range(n)] if H_l == H else _trace_by_continuation(lad, H_l, todo)
            lad.check_time()
            for i in np.flatnonzero(free):
                sts[i] = lad.padded(H_l, i)
            traced.append(sts)
    for i in np.flatnonzero(todo):
        sts = [t[i] for t in traced]
        if any(st is None for st in sts):
            continue
        lv = _Levels(sts, lad.Q_norm(i), lad.omega_ref(i))
        ew[i], eq[i], rates[i] = lv.error(2, of=of)
        if impacts:
            w_lim[i], w_lim_err[i] = lv.frequency_bracket()
            ew[i] = _bounded_by_bracket(ew[i], sts[of].omega, w_lim[i], w_lim_err[i], lad.omega_ref(i))
    finest[todo] = levels[-1]
    if rtol is not None and impacts:
        chains = [[t[i] for t in traced] for i in range(n)]
        top = levels[-1]
        while 2 * top <= max_harmonics:
            err = np.where(np.isfinite(w_lim_err), w_lim_err, ew)
            need = todo & ~(np.isfinite(err) & (err <= rtol)) & (finest == top)
            stays = np.array([need[i] and not _contracting(chains[i], lad.Q_norm(i), lad.omega_ref(i))
                              for i in range(n)], dtype=bool)
            if stays.any():
                log.info("accuracy: %d point(s) above rtol = %g whose last levels do not contract (or are missing): "
                         "no level H = %d for them (no convergence to extrapolate)", int(stays.sum()), rtol, 2 * top)
            need &= ~stays
            if not need.any():
                break
            top *= 2
            lad.check_time()
            log.info("accuracy: %d point(s) above rtol = %g; level H = %d", int(need.sum()), rtol, top)
            states = _trace_by_continuation(lad, top, need)
            lad.check_time()
            for i in np.flatnonzero(need):
                if states[i] is None or any(st is None for st in chains[i][-2:]):
                    continue
                chains[i] = chains[i][-2:] + [states[i]]
                lv = _Levels(chains[i], lad.Q_norm(i), lad.omega_ref(i))
                w_lim[i], w_lim_err[i] = lv.frequency_bracket()
                finest[i] = top


def _period_driven(branch: Branch) -> bool:
    """The branch holds the contact-phase family traced by period past grazing."""
    return branch.kind == "nonlinear mode" and branch.meta.get("family") == "contact phase"


def _contracting(chain: list, Q_norm: float, omega_ref: float) -> bool:
    """Whether a point's last three levels contract: all solved, and the change from the middle
    to the finest smaller than the one before (:meth:`_Levels.distance`). Only then does a
    further level of the refinement extend a convergence the levels show; where the changes
    grow, the truncation is not in its asymptotic range there (just above a grazing) or the limit
    is not an orbit the levels resolve. Seed case 2 from H = 20 by the levels: three points just
    above the rising grazing whose levels 10-20-40 grow got brackets from levels 80 and 160
    (0.79591 +- 4e-6 to 0.79663 +- 2.7e-5) that said "met" while the exact curve crosses their
    hyperplanes at 0.7936 or 0.86 and above; seed case 1 one such point (0.90837 +- 6.2e-4, the
    crossings at 0.956 and 1.407). ``cant20`` of benchmarks/README_accuracy.md (exact orbits that
    chatter): 152 of 257 points above rtol 1e-3 after level 40 and 23 of 81 after level 80 do
    not contract or miss a level; that alone took its estimate from 511 s to 459 s, most of it
    still the continuation of level 80, which :data:`LEVEL_POINTS_PER_POINT` now stops; it
    brackets none of its folds either way."""
    if len(chain) < 3 or any(st is None for st in chain[-3:]):
        return False
    lv = _Levels(chain[-3:], Q_norm, omega_ref)
    return lv.distance(2) < lv.distance(1)


def _estimate_by_shooting(lad: _Ladder, ew, eq, rates, w_lim, w_lim_err, finest, kind,
                          auto: bool = False) -> np.ndarray:
    """Errors of the points from the exact orbits on their hyperplanes (:class:`_Shooter`; the
    branch's folds: the exact folds), into the arrays given; returns the points without an
    exact orbit. ValueError if the flow cannot be built, or with ``auto`` if the model has more
    than :data:`SHOOTING_AUTO_MAX_DOFS` DOFs with mass, or the probe run's event search
    evaluates more than :data:`SHOOTING_AUTO_MAX_WORK` modal terms, or the probe orbit has more
    than :data:`SHOOTING_AUTO_MAX_EVENTS` events at one contact (:func:`_probe_run`)."""
    branch = lad.branch
    probe = LinearImpactFlow(lad.model, float(np.min(branch.omega)))
    if auto:
        if probe.I.size > SHOOTING_AUTO_MAX_DOFS:
            raise ValueError(f"the model has {probe.I.size} DOFs with mass; the exact flow's dense modal algebra (cost "
                             f"~ n^3 per run) is left to models of at most {SHOOTING_AUTO_MAX_DOFS} (reduce the model with "
                             "fm.craig_bampton, which keeps the contact DOFs, or ask for method='shooting')")
        run = _probe_run(lad, probe)
        work = float(run.samples) * 2 * probe.I.size
        if work > SHOOTING_AUTO_MAX_WORK:
            raise ValueError(f"the exact flow's event search evaluated {work:.3g} modal terms over one period of the "
                             f"point with the largest contact force (a stiff model); more than {SHOOTING_AUTO_MAX_WORK:g}")
        per_contact = np.bincount([e[1] for e in run.impacts + run.switches], minlength=len(probe.dofs))
        if per_contact.max(initial=0) > SHOOTING_AUTO_MAX_EVENTS:
            j = int(np.argmax(per_contact))
            raise ValueError(f"the exact flow from the point with the largest contact force has {int(per_contact[j])} "
                             f"events at contact {j} in one period (chattering: Newton on the exact orbit does not "
                             f"converge there); more than {SHOOTING_AUTO_MAX_EVENTS}")
    n = len(branch)
    H = branch.harmonics.n_harmonics
    free = _without_contact(branch)
    todo = np.zeros(n, dtype=bool)
    # points without contact force: the linear response, which H harmonics solve exactly
    ew[free] = eq[free] = w_lim_err[free] = SHOOTING_FLOOR
    w_lim[free] = branch.omega[free]
    rates[free] = math.inf
    finest[free] = H
    kind[free] = "shooting"
    solved, sh, exact = _shoot_branch(lad, probe)
    for i in sorted(i for i, r in solved.items() if r is None):
        solved[i] = exact.solve(i)
    K = 8 * H  # the exact orbit's displacement to 8 H harmonics: the error includes the tail
    hk = Harmonics(K)
    resolved: dict = {}  # folds located by the fold search: their exact frequencies
    for i, r in solved.items():
        if r is None:
            todo[i] = True
            continue
        if r is GLANCING:  # no counterpart on the exact curve, and no orbit at the point's frequency
            kind[i] = "failed"  # either: not estimated (the levels' ratios are erratic just above grazing)
            finest[i] = 0
            continue
        w = r[1]
        if i in branch.folds and exact.traced and exact.branch() is not None:
            todo[i] = True  # the exact branch is there: its folds, without the fold search (below)
            continue
        if i in branch.folds:
            fold = sh.fold(i, r)
            if fold is None:
                todo[i] = True
                continue
            w, half = fold
            resolved[i] = w
        else:
            half = max(r[4] / abs(w), SHOOTING_FLOOR)
        _record_exact(lad, i, w, half, r[3].coefficients(K)[0], hk, ew, eq, rates, w_lim, w_lim_err, finest, kind)
    log.info("accuracy: shooting: %d runs of the exact flow for %d points", sh.runs, len(solved))
    unresolved = [i for i in branch.folds if todo[i]]
    if unresolved and exact.branch() is not None:
        _folds_from_exact_branch(lad, probe, exact.branch(), unresolved, resolved, ew, eq, rates, w_lim, w_lim_err,
                                 finest, kind, todo, hk)
    return todo


def _record_exact(lad: _Ladder, i: int, w: float, half: float, Q: np.ndarray, hk: Harmonics, ew, eq, rates, w_lim,
                  w_lim_err, finest, kind) -> None:
    """Point ``i``'s estimate from an exact orbit: its frequency ``w`` (relative half-width
    ``half``) and displacement coefficients ``Q`` on the harmonics ``hk`` (8 H: the error
    includes the tail), into the arrays given."""
    branch = lad.branch
    dQ = Q - lad.harmonics(branch.harmonics.n_harmonics).convert(branch.Q[i], hk)
    w_lim[i], w_lim_err[i] = w, half
    ew[i] = abs(branch.omega[i] - w) / lad.omega_ref(i) + half
    eq[i] = float(np.linalg.norm(dQ)) / lad.Q_norm(i)
    rates[i] = math.nan
    finest[i] = 0
    kind[i] = "shooting"


def _near_fold(branch: Branch, i: int) -> bool:
    """Whether point ``i`` is a fold or next to one: the branch's dw/ds vanishes there and kappa
    (:meth:`_Shooter.glancing`) says nothing; the plane there is across the fold's amplitude,
    which the exact curve crosses near its own fold."""
    return any(abs(i - f) <= 1 for f in branch.folds)


def _contact_force_peak(branch: Branch) -> np.ndarray:
    """The largest contact-force coefficient of every point (zeros without contacts)."""
    P = np.abs(branch.P)
    return P.reshape(len(branch), -1).max(axis=1) if P.size else np.zeros(len(branch))


class _ExactBranchStarts:
    """The exact branch over the branch's span (:func:`femodes.time.exact_frequency_response`),
    traced once when first needed, and first guesses from it for the points where Newton from
    the branch found no orbit: the exact orbit next to where the exact branch crosses the
    point's hyperplane (the crossing nearest in frequency)."""

    def __init__(self, lad: _Ladder, sh: _Shooter):
        self.lad, self.sh = lad, sh
        self._eb = None
        self._Q = None
        self.traced = False

    def branch(self):
        if not self.traced:
            self.traced = True
            b = self.lad.branch
            span = (float(b.omega[0]), float(b.omega[-1]))
            if span[0] != span[1] and undamped(self.lad.model):
                log.info("accuracy: no exact branch of an undamped model (its orbits are unbounded at resonances)")
            elif span[0] != span[1]:
                eb = exact_frequency_response(self.lad.model, span)
                log.info("accuracy: exact branch over w %.6g -> %.6g: %d orbits, folds at %s, %d runs (%s)", *span,
                         len(eb), np.round(eb.fold_omega, 6).tolist(), eb.runs, eb.message)
                self._eb = eb if eb.success else None
        return self._eb

    def solve(self, i: int, check: bool = True):
        """The orbit on point ``i``'s hyperplane from the exact branch's crossing (as
        :meth:`_Shooter.solve`, or None); ``check``: :func:`_counterpart` (:func:`_shoot_branch`
        checks its points itself)."""
        eb = self.branch()
        if eb is None:
            return None
        if self._Q is None:  # the exact orbits' coefficients on the branch's harmonics, and their pieces
            self._Q = [eb.coefficients(j, self.sh.H)[0] for j in range(len(eb))]
            self._piece = np.searchsorted(np.asarray(eb.pieces), np.arange(len(eb)), side="right")
        plane = self.sh.plane(i)
        g = np.array([plane.at(Q, w) for Q, w in zip(self._Q, eb.omega)])
        piece = self._piece
        cross = [j for j in range(len(eb) - 1) if g[j] * g[j + 1] <= 0.0 and piece[j] == piece[j + 1]]
        w_i = float(self.lad.branch.omega[i])
        for j in sorted(cross, key=lambda j: abs(eb.omega[j] - w_i)):
            k = j if abs(g[j]) <= abs(g[j + 1]) else j + 1
            r = self.sh.solve(i, guess=(eb.states[k].copy(), float(eb.omega[k]), 0.0))
            if r is not None:
                log.info("accuracy: point %d: exact orbit from the exact branch's crossing at w = %.6g", i, eb.omega[k])
                return r if _near_fold(self.lad.branch, i) or not check else _counterpart(self.sh, i, r)
        return None


def _counterpart(sh: _Shooter, i: int, r):
    """``r``, or :data:`GLANCING` if the exact curve crosses point ``i``'s hyperplane obliquely or
    backward (:meth:`_Shooter.glancing`, :meth:`_Shooter.crossing_cosine`)."""
    kappa = sh.glancing(i, r)
    if not 0.0 < kappa <= GLANCING_MAX:
        cos = sh.crossing_cosine(i, r)
        if cos < GLANCING_COS:
            log.info("accuracy: point %d: the exact curve crosses its hyperplane obliquely or backward "
                     "(kappa = %.3g, outside (0, %g]; cos = %.3g): no counterpart", i, kappa, GLANCING_MAX, cos)
            return GLANCING
    return r


def _folds_from_exact_branch(lad: _Ladder, flow, eb, unresolved, resolved, ew, eq, rates, w_lim, w_lim_err, finest,
                             kind, todo, hk) -> None:
    """The folds the fold search did not locate (``unresolved``), from the exact branch over the
    branch's span (:func:`femodes.time.exact_frequency_response`): each is paired with the
    nearest exact fold that turns the same way (distance ``|dw| / w + |da| / a_max`` in
    frequency and the largest contact-DOF amplitude), one to one, nearest pairs first; exact
    folds that a located fold already has are not paired again. A fold left without a pair has
    no counterpart in the limit (a loop of the truncation): no estimate (method
    ``"truncation"``), and no levels either. Without an exact branch over the span the folds stay for the levels."""
    branch = lad.branch
    dofs = sorted({int(d) for d in flow.dofs})
    amp_h = np.max([branch.amplitude(d) for d in dofs], axis=0)
    scale = max(float(amp_h.max()), 1e-300)
    # exact folds (positions k in eb.folds) that a located fold already has are not paired again
    free = [k for k in range(len(eb.folds))
            if not any(abs(eb.fold_omega[k] - w) <= (eb.fold_error[k] + SHOOTING_FOLD_SLACK) * abs(w)
                       for w in resolved.values())]
    # the same amplitude of the exact folds' orbits (max |q| over a fine grid)
    amp_e = dict(zip(free, eb.amplitude(dofs, samples=800, points=[eb.folds[k] for k in free])))
    pairs = sorted((abs(branch.omega[i] - eb.fold_omega[k]) / eb.fold_omega[k] + abs(amp_h[i] - amp_e[k]) / scale, i, k)
                   for i in unresolved for k in free if fold_is_upper(branch.omega, i) == eb.fold_upper[k])
    taken_i, taken_j = set(), set()
    for _, i, j in pairs:  # j: a position in eb.folds
        if i in taken_i or j in taken_j:
            continue
        taken_i.add(i)
        taken_j.add(j)
        w, half = float(eb.fold_omega[j]), max(float(eb.fold_error[j]), SHOOTING_FLOOR)
        _record_exact(lad, i, w, half, eb.coefficients(eb.folds[j], hk.n_harmonics)[0], hk, ew, eq, rates, w_lim,
                      w_lim_err, finest, kind)
        todo[i] = False
        log.info("accuracy: fold %d (w = %.7g) paired with the exact fold at w = %.7g", i, branch.omega[i], w)
    for i in unresolved:
        if i not in taken_i:
            todo[i] = False
            finest[i] = 0
            kind[i] = "truncation"
            log.info("accuracy: fold %d (w = %.7g) has no counterpart on the exact branch (folds at %s): a fold of "
                     "the truncation, no estimate", i, branch.omega[i], np.round(eb.fold_omega, 6).tolist())


def _probe_run(lad: _Ladder, flow):
    """One run of ``flow`` over one period from the branch's point with the largest contact force
    at its most open phase: its event search's samples (times the state's size: the modal terms
    evaluated) are the cost of a run, which a stiff model drives up (the search refines to the
    fastest mode near events, and everywhere where impacts excite the fast modes); its events
    show an orbit that chatters."""
    branch = lad.branch
    i = int(np.argmax(_contact_force_peak(branch)))
    x0, theta0 = _Shooter(lad, flow).start(i)
    omega = float(branch.omega[i])
    return flow.at(omega).run(x0, theta0 / omega)


def check_estimate_method(method, owner: str, name: str = "method") -> str:
    """``method`` checked against :data:`ESTIMATE_METHODS`."""
    if not isinstance(method, str) or method not in ESTIMATE_METHODS:
        raise ValueError(f"{owner}: {name} must be one of {ESTIMATE_METHODS}, got {method!r}")
    return method


def estimate_levels(H: int) -> tuple[list[int], int]:
    """The levels of :func:`estimate_error` for a branch with ``H`` harmonics and which of them is
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


def _bounded_by_bracket(ew: float, omega: float, w_lim: float, half: float, omega_ref: float) -> float:
    """The frequency error estimate of a point with contacts, at least the distance from its own
    frequency to the far end of the bracket of the converged frequency: the estimate
    ``d r / (r - 1)`` assumes later ratios at least the observed ``r``, which a non-monotone
    ratio breaks (FE bar with a tip mass, H = 8: ratio 1.75 at levels 4-8-16, 1.52 at 10-20-40,
    estimate 2.41 % for a true 2.69 %); the bracket rests on the weaker assumption of ratios
    between ``r`` and 2."""
    if not (math.isfinite(w_lim) and math.isfinite(half)):
        return ew
    return max(ew, abs(omega - w_lim) / omega_ref + half)


#: ``rtol=`` of the analyses stops its error estimate after this many times the plain branch's
#: own computing time, and not before :data:`RTOL_MIN_SECONDS` (``estimate_error(time_limit=...)``):
#: a tolerance that cannot be met in that time is reported, not waited for (a many-contact blade
#: at H = 10 ran for minutes without output).
RTOL_BUDGET = 10.0

#: The least time ``rtol=`` allows its estimate: small models' branches take a fraction of a
#: second while their finest levels (8 H) take seconds (the free impact oscillator from H = 10:
#: 0.1 s, then 1.4 s for levels up to 80), and a limit in seconds must not make a machine's load
#: decide whether such a tolerance is met.
RTOL_MIN_SECONDS = 60.0


def rtol_time_limit(plain_seconds: float) -> float:
    """Seconds the analyses' ``rtol=`` gives its error estimate after a plain branch that took
    ``plain_seconds``: ``max(RTOL_BUDGET * plain_seconds, RTOL_MIN_SECONDS)``."""
    return max(RTOL_BUDGET * float(plain_seconds), RTOL_MIN_SECONDS)


def meet_tolerance(branch: Branch, rtol: float, max_harmonics: int | None, rerun, *, projection=None,
                   newton: NewtonOptions | None = None, method: str = "auto",
                   time_limit: float | None = None) -> Branch:
    """``rtol=`` of :func:`femodes.frequency_response` and :func:`femodes.nonlinear_mode`.

    With complementarity contacts (algebraic convergence): :func:`estimate_error` with ``rtol``,
    which brackets the converged frequency by extrapolation and adds levels where the bracket is
    too wide. Smooth branches (exponential convergence): the estimate of the branch's own ``H``;
    while some point misses ``rtol`` the whole branch is computed again with ``2 H``
    (``rerun(H)``), up to ``max_harmonics``.
    """
    H = branch.harmonics.n_harmonics
    rtol, max_harmonics = refinement_options(rtol, max_harmonics, H)
    if rtol is None:
        raise ValueError("meet_tolerance: rtol must be given")
    if len(branch) < 2:
        log.warning("accuracy: the branch has %d point(s) (%s); no error estimate for rtol", len(branch),
                    branch.message)
        return branch
    deadline = None if time_limit is None else time.perf_counter() + time_limit

    def left() -> float | None:
        return None if deadline is None else max(deadline - time.perf_counter(), 1e-3)

    if "complementarity" in branch.contacts.kinds:
        estimate_error(branch, rtol=rtol, max_harmonics=max_harmonics, projection=projection, newton=newton,
                       method=method, time_limit=left())
        _warn_unmet(branch, max_harmonics)
        return branch
    while True:
        estimate_error(branch, rtol=rtol, projection=projection, newton=newton, method=method, time_limit=left())
        H = branch.harmonics.n_harmonics
        # the estimate of 2 H needs level 4 H; a branch with a caveat (not the family asked for) meets rtol at no H
        if branch.accuracy.met.all() or branch.accuracy.caveat or 4 * H > max_harmonics:
            _warn_unmet(branch, max_harmonics)
            return branch
        if deadline is not None and time.perf_counter() > deadline:
            log.warning("accuracy: rtol = %g not met with H = %d, and its time limit (%.3g s) has passed: the "
                        "branch with H = %d is not computed", rtol, H, time_limit, 2 * H)
            _warn_unmet(branch, max_harmonics)
            return branch
        log.info("accuracy: %d point(s) above rtol = %g with H = %d; again with H = %d",
                 int((~branch.accuracy.met).sum()), rtol, H, 2 * H)
        branch = rerun(2 * H)


def _warn_unmet(branch: Branch, max_harmonics: int) -> None:
    """A warning that says where ``rtol`` is not met (points, folds and why), if anywhere."""
    acc = branch.accuracy
    miss = ~acc.met
    if not miss.any():
        return
    if acc.caveat:  # not the family asked for: no point is converged, whatever its error
        log.warning("accuracy: rtol = %g is met at no point: %s", acc.rtol, acc.caveat)
        return
    # per method: its name in the fold list, and why its points miss rtol
    words = {"doubling": ("levels", f"by the levels (bracket or estimate wider than rtol up to H = {max_harmonics}, "
                                    "or levels that do not contract)"),
             "shooting": ("exact orbit", "by the exact orbit (the point's error above rtol)"),
             "failed": ("no estimate", "without an estimate"),
             "truncation": ("truncation", "folds of the truncation (none in the limit)"),
             "none": ("not estimated", "whose harmonic truncation was not estimated")}
    counts = {k: int(np.sum(miss & (acc.method == k))) for k in ERROR_METHODS}
    folds = [f"w = {float(branch.omega[i]):.6g} ({words[str(acc.method[i])][0]})" for i in branch.folds if miss[i]]
    log.warning("accuracy: rtol = %g not met at %d of %d points%s: %s; branch.accuracy.met tells which",
                acc.rtol, int(miss.sum()), len(branch), f", including the folds at {', '.join(folds)}" if folds else "",
                "; ".join(f"{n} {words[k][1]}" for k, n in counts.items() if n))


def refinement_options(rtol, max_harmonics, H: int, owner: str = "estimate_error") -> tuple[float | None, int]:
    """Checked ``(rtol, max_harmonics)`` (default ``8 H``) for a branch with ``H`` harmonics."""
    if rtol is not None:
        if isinstance(rtol, bool) or not isinstance(rtol, (int, float, np.floating, np.integer)) \
                or not 0.0 < float(rtol) < 0.5:
            raise ValueError(f"{owner}: rtol must be a relative tolerance in (0, 0.5), e.g. 1e-3; got {rtol!r}")
        rtol = float(rtol)
    if max_harmonics is None:
        return rtol, 8 * H
    if isinstance(max_harmonics, bool) or not isinstance(max_harmonics, (int, np.integer)) or max_harmonics < 2 * H:
        raise ValueError(f"{owner}: max_harmonics must be an integer >= 2 H = {2 * H} (the estimate's own "
                         f"finest level); got {max_harmonics!r}")
    return rtol, int(max_harmonics)


def _ladder(branch, projection, newton, owner: str) -> _Ladder:
    if not isinstance(branch, Branch):
        raise TypeError(f"{owner}: branch must be a femodes.Branch, got {type(branch).__name__}")
    if len(branch) < 2:
        raise ValueError(f"{owner}: the branch has {len(branch)} point(s); at least 2 are needed (its direction)")
    used = branch.meta.get("projection")
    given = type(projection).__name__ if projection is not None else "ExactProjection"
    if isinstance(used, str) and used != given:
        raise ValueError(f"{owner}: the branch was computed with {used} but projection={projection!r} means {given}: "
                         "its levels would be another discretisation than the branch; pass the projection the branch "
                         f"was computed with (projection={used}(...))")
    return _Ladder(branch, projection, newton)


#: Smallest fraction of a branch step the tracing of a level takes (after halvings).
MIN_FRACTION = 1.0 / 16.0


#: A step of a walk (:func:`_walk`) whose Newton has not halved the residual of its guess after this
#: many iterations is abandoned and halved, as a step of the continuation is
#: (``ContinuationOptions.corrector_deadline``).
WALK_DEADLINE = 3


def _walk(lad: _Ladder, H: int, prev: tuple, anchor: _State, t0: _State, t1: _State) -> _State | None:
    """The level-``H`` point of ``anchor`` from the level's point ``prev = (anchor0, state0)`` of
    the previous branch point: in one step, or in fractions of it (halved down to
    :data:`MIN_FRACTION`) through intermediate anchors on the segment between the two branch
    points (tangents interpolated)."""
    a0, s0 = prev
    done, frac = 0.0, 1.0
    while done < 1.0:
        frac = min(frac, 1.0 - done)
        theta = done + frac
        target = anchor if theta >= 1.0 else lad.blend(a0, anchor, theta)
        tangent = t1 if theta >= 1.0 else lad.blend(t0, t1, theta)
        st = lad.solve(H, target, tangent, lad.moved(H, s0, lad.blend(a0, anchor, done), target), WALK_DEADLINE)
        if st is None:
            if frac <= MIN_FRACTION:
                return None
            frac *= 0.5
            continue
        s0, done = st, theta
        frac *= 2.0
    return s0


def _level_point(lad: _Ladder, H: int, i: int, anchor: _State, prev: tuple | None) -> _State | None:
    """Point ``i`` of the branch at level ``H``: walked from the level's point ``prev = (anchor,
    state)`` of point ``i - 1`` if there is one (:func:`_walk`), else (or if that fails) solved on
    its hyperplane from the branch's own point."""
    lad.check_time()
    tangents = lad.tangents
    st = _walk(lad, H, prev, anchor, tangents[i - 1], tangents[i]) if prev is not None else None
    if st is None:
        st = lad.solve(H, anchor, tangents[i], None, WALK_DEADLINE)
    if st is None:
        log.info("accuracy: point %d has no solution with H = %d near it", i, H)
    return st


def _trace_level(lad: _Ladder, H: int) -> list:
    """Every point of the branch at level ``H``, in branch order.

    A level cannot be solved from the branch's own point by Newton alone (measured: from the
    H = 20 point of the seed's forced case, semismooth Newton stalls at residual 1e-2 at H = 10
    and H = 40, the truncated or padded contact forces being too far from the level's). So the
    level is traced along the branch: the guess at point ``i`` is the level's solution at
    ``i - 1`` moved by the branch's own step from ``i - 1`` to ``i``, projected on the hyperplane
    of ``i``; a failed step is halved (:func:`_walk`). Located folds are then
    located on the level (:meth:`_Ladder.locate_fold`).
    """
    branch = lad.branch
    n = len(branch)
    out: list = [None] * n
    if H == branch.harmonics.n_harmonics:
        for i in range(n):
            out[i] = _anchor(branch, i)
    else:
        prev = None  # (branch anchor, level state) of the last solved point
        walk = not _period_driven(branch)
        for i in range(n):
            anchor = _anchor(branch, i)
            out[i] = st = _level_point(lad, H, i, anchor, prev)
            prev = None if st is None or not walk else (anchor, st)
    for f in branch.folds if H != branch.harmonics.n_harmonics else ():  # the branch's own are located
        out[f] = lad.locate_fold(H, out, f)
    return out


def _trace_level_by_continuation(lad: _Ladder, H: int) -> list:
    """Every point of the branch at level ``H`` (branches with impacts): the points without
    contact force as they are (:func:`_without_contact`), the others from a continuation of the
    level itself (:func:`_trace_by_continuation`), the points it misses walked from their
    predecessor as :func:`_trace_level` does, and a missed fold located by a short continuation.
    Seed's forced case at H = 20: 27 of 94 points without contact; levels 10 and 40 took 51 and
    96 continuation points over the whole branch, 30 and 67 over its contact part.

    Walking level 2H along every point costs more than tracing it: on the seed's forced case at
    H = 20, 230 hyperplane solves (26 failing, halved) and 33 s of CPU for level 40, against
    10 s by continuation with the same fold bracket; at H = 40 the walk lost level 80 one point
    before the upper fold and never recovered (NaN at the fold after 15 minutes).

    So a continuation that stops short is started again from the first point walked after the
    stop that has :data:`RESTART_MIN_POINTS` unsolved points after it (at most
    :data:`LEVEL_RESTARTS` times), and the walk's Newton solves are abandoned early
    (:data:`WALK_DEADLINE`). ``cant20`` of benchmarks/README_accuracy.md (exact orbits that
    chatter) from H = 20: level 40's continuation stops at w = 3.63913, where its corrector makes
    no progress (residual 8e-8 at best); walking the 121 points left took 87 s of CPU and solved
    44 of them; with one restart from point 186 and the deadline, 49 points are walked and the
    level has 277 of the 316 points with contact instead of 246, in 39 s instead of 103 s for the
    whole level."""
    branch = lad.branch
    n = len(branch)
    if H == branch.harmonics.n_harmonics:
        return [_anchor(branch, i) for i in range(n)]
    free = _without_contact(branch)
    out = _trace_by_continuation(lad, H, ~free) if not free.all() else [None] * n
    for i in np.flatnonzero(free):  # the branch's point is the level's (padded): nothing to solve
        out[i] = lad.padded(H, i)
    folds = set(branch.folds)
    missed = restarts = 0
    for i in range(n):
        if out[i] is not None or i in folds:
            continue
        missed += 1
        prev = (_anchor(branch, i - 1), out[i - 1]) if i > 0 and out[i - 1] is not None and i - 1 not in folds else None
        out[i] = _level_point(lad, H, i, _anchor(branch, i), prev)
        if (out[i] is not None and restarts < LEVEL_RESTARTS and i + RESTART_MIN_POINTS < n
                and all(out[k] is None and k not in folds for k in range(i + 1, i + 1 + RESTART_MIN_POINTS))):
            restarts += 1  # the level's own continuation again, from the point just walked
            _trace_segment(lad, H, np.array([k for k in range(i + 1, n) if out[k] is None and k not in folds]),
                           True, out, start=(i, out[i]))
    for f in branch.folds:
        if out[f] is None:
            out[f] = lad.locate_fold(H, out, f)
    if missed:
        log.info("accuracy: level H = %d: %d of %d points not on its continuation, walked (%d restarts of the "
                 "continuation)", H, missed, n, restarts)
    return out


def _trace_by_continuation(lad: _Ladder, H: int, need: np.ndarray) -> list:
    """The points ``need`` of the branch at level ``H``, from continuations of level ``H`` itself.

    Walking a fine level along the branch's own points (:func:`_trace_level`) fails often once the
    levels are far apart (seed's forced case from H = 10: 376 hyperplane solves for 111 points at
    H = 40, 604 at H = 80, 8 minutes in all). Here level ``H`` is traced by the continuation with
    its own step control, from a point without contact (where every level is the branch's point)
    and stopped a few points past the last needed point it meets (:class:`_Progress`); each needed
    point is then the crossing of that curve with the point's hyperplane nearest to the point
    (linear interpolation between two level points), polished by Newton on the hyperplane. A fold
    of the branch is the nearest fold of the level's continuation.

    The trace runs forward from the last point without contact before the first needed point;
    or, when the needed points fall in two groups (:func:`_plan_traces`), the first group forward
    that way and the second backward from the branch's end, if the branch ends without contact
    (the contact-free tail costs a few steps). The continuation cannot start where the second
    group's own contact-free neighbour is: the branch returns past that frequency after its lower
    fold, and a continuation stops where it passes its start again.
    """
    out: list = [None] * len(lad.branch)
    for idx, forward in _plan_traces(lad.branch, need):
        _trace_segment(lad, H, idx, forward, out)
    return out


#: Two traces of a level (:func:`_plan_traces`) instead of one only if they pass at most this
#: fraction of the points with contact that one trace passes: the second trace also walks the
#: contact-free tail and restarts the step control. Seed's forced case at rtol 1e-3: level 80,
#: 64 against 66 points with contact, took 138 continuation points in two traces against 103
#: in one; level 160, 39 against 66, took 134 against 196.
SPLIT_GAIN = 0.75


def _plan_traces(branch: Branch, need: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """``(needed points, forward)`` of each continuation that traces a level for ``need``: one
    forward trace, or two (forward to the end of the first group, backward from the branch's
    end to the start of the second) when they pass enough fewer points with contact
    (:data:`SPLIT_GAIN`). The groups are split at the widest gap between needed points. Seed's
    forced case at rtol 1e-3, level H = 160: the needed points are 22-36 (rising side) and 69-76
    (the unstable side next to the lower fold): one trace passes 66 points with contact (13-78),
    two pass 39."""
    idx = np.flatnonzero(need)
    contact = ~_without_contact(branch)
    n = len(branch)
    one = [(idx, True)]
    if idx.size < 2 or contact[-1] or not contact.any():
        return one

    def cost(a: int, b: int) -> int:  # points with contact from a to b (inclusive)
        a, b = max(a, 0), min(b, n - 1)
        return int(contact[a : b + 1].sum())

    gap = int(np.argmax(np.diff(idx)))
    first, second = idx[: gap + 1], idx[gap + 1 :]
    start = _free_before(branch, int(idx[0]))
    single = cost(start, int(idx[-1]) + PAST_LAST)
    split = cost(start, int(first[-1]) + PAST_LAST) + cost(int(second[0]) - PAST_LAST, n - 1)
    log.debug("accuracy: trace plan: one trace passes %d points with contact, two %d", single, split)
    if split > SPLIT_GAIN * single:
        return one
    return [(first, True), (second, False)]


def _trace_segment(lad: _Ladder, H: int, idx: np.ndarray, forward: bool, out: list,
                   start: tuple[int, _State] | None = None) -> None:
    """One continuation of level ``H`` for the needed points ``idx`` (:func:`_trace_by_continuation`):
    forward from the last point without contact before ``idx[0]``, or backward from the branch's
    last point (without contact), or forward from ``start = (i, state)``, the level's point of
    branch point ``i`` (in the direction the branch goes there, up to the branch's extreme
    parameter that way); the level points of ``idx`` are written into ``out``."""
    branch = lad.branch
    n = len(branch)
    prob = lad.problem(H)
    if start is None:
        start_i = _free_before(branch, int(idx[0])) if forward else n - 1
        a0 = _anchor(branch, start_i)
        x0 = lad.vector(H, a0.Q, a0.P, a0.omega, a0.xi, a0.p)[:-1]
        span = (a0.p, float(branch.parameter[-1] if forward else branch.parameter[0]))
    else:
        start_i, s0 = start
        x0 = lad.vector(H, s0.Q, s0.P, s0.omega, s0.xi, s0.p)[:-1]
        up = lad.tangents[start_i].p > 0
        span = (s0.p, float(np.max(branch.parameter) if up else np.min(branch.parameter)))
    if span[1] == span[0]:
        return
    w = lad.weights(H)
    x_scale = 1.0 / np.sqrt(w[:-1] * x0.size)  # the branch's arclength metric on level H
    # nearness in displacements and frequency only: contact forces of two levels differ by far
    # more than their displacements (their harmonics are where the truncation error sits)
    h = lad.harmonics(H)
    near = w.copy()
    near[:-1][prob.pack(np.zeros((h.n_coef, branch.Q.shape[2])), np.ones((h.n_coef, branch.P.shape[2])), 0.0,
                        0.0) != 0] = 0.0
    if forward:
        last = int(idx[-1]) + PAST_LAST
        progress = _Progress(lad, H, near, start_i, last) if last < n - 1 or start is not None else None
    else:  # followed from the first point without contact after the group (the level's own point
        # up to there, wherever the long contact-free steps land)
        last = int(idx[0]) - PAST_LAST
        after = int(idx[-1]) + int(np.argmax(_without_contact(branch)[idx[-1]:]))
        progress = _Progress(lad, H, near, after, last, step=-1) if last > 0 else None
    # folds of the level are located only if a fold of the branch is among the needed points
    # (level 160 of the seed case at rtol 1e-3, whose backward trace passes the lower fold, not
    # needed there: 8.8 -> 6.9 s)
    locate = any(f in idx for f in branch.folds)
    opts = ContinuationOptions(step=0.05, max_step=2.0, newton=lad.newton, x_scale=x_scale,
                               p_scale=float(1.0 / math.sqrt(w[-1])), max_points=20 * max(n, 50), callback=progress,
                               locate_folds=locate)
    with np.errstate(all="ignore"):
        res = continuation(prob, span, x0=x0, options=opts)
    log.info("accuracy: level H = %d traced by continuation %s from point %d%s: %d points (%s)", H,
             "forward" if forward else "backward", start_i, "" if start is None else " (walked, restart)",
             len(res.p), res.message)
    Y = np.column_stack([res.x, res.p])
    tangents = lad.tangents
    for i in idx:
        anchor = _anchor(branch, int(i))
        a = lad.vector(H, anchor.Q, anchor.P, anchor.omega, anchor.xi, anchor.p)
        t = tangents[i]
        c = w * lad.vector(H, t.Q, t.P, t.omega, t.xi, t.p)
        sd = (Y - a) @ c
        k = np.flatnonzero(sd[:-1] * sd[1:] <= 0.0)
        if not k.size:
            continue
        theta = sd[k] / np.where(sd[k] == sd[k + 1], 1.0, sd[k] - sd[k + 1])
        cand = np.array([_between(prob, Y[j], Y[j + 1], th) for j, th in zip(k, theta)])
        best = cand[int(np.argmin(((cand - a) ** 2) @ near))]
        out[i] = lad.solve(H, anchor, t, lad.state(H, best))
    for f in branch.folds:
        if f in idx and res.folds:
            a = lad.vector(H, branch.Q[f], branch.P[f], float(branch.omega[f]), float(branch.xi[f]),
                           float(branch.parameter[f]))
            k = min(res.folds, key=lambda j: float(((Y[j] - a) ** 2) @ near))
            out[f] = lad.state(H, Y[k])


#: A level whose continuation stopped short (:func:`_trace_level_by_continuation`) is traced again
#: by continuation from a point walked after the stop when the RESTART_MIN_POINTS points after it
#: are unsolved, at most LEVEL_RESTARTS times per level (a walked point costs several hyperplane
#: solves, a point of the continuation one corrector).
LEVEL_RESTARTS, RESTART_MIN_POINTS = 4, 3


#: A level traced for some points only (:func:`_trace_by_continuation`) stops once it is nearest
#: to the branch point this many points after the last point it is traced for.
PAST_LAST = 2


#: A level traced for some points stops once it has taken more than LEVEL_POINTS_PER_POINT
#: continuation points per branch point it has passed, plus LEVEL_POINTS_SLACK (:class:`_Progress`):
#: it then follows loops the branch does not have, and its later crossings would not converge
#: either. Measured at every point of every trace (levels 5-160) of the seed cases from H = 10
#: and 20 at rtol 1e-3 and 1e-4, and of the bars with 10 and 20 elements by the levels: the
#: points taken exceed 4 per branch point passed by at most 48 (seed case 2, level 160). On
#: ``cant20`` of benchmarks/README_accuracy.md (exact orbits that chatter) level 80 is stopped
#: after 177 points for 19 branch points, level 160 after 137 for 9; with 8 per point they took
#: 597 points for 62 and 189 for 11 (100 s and 60 s of CPU), and without the stop 1272 points
#: (269 s) and 343 (170 s).
LEVEL_POINTS_PER_POINT, LEVEL_POINTS_SLACK = 4, 100


class _Progress:
    """Callback of a level's continuation: follows which branch point the level is nearest to
    (in the direction ``step`` of the trace only, a few points ahead, in displacements and
    frequency) and stops the run once that is past branch point ``last``. On the seed's forced case from H = 20 at rtol 1e-3 the needed
    points of levels 80 and 160 end at w = 1.11 on the lower branch; the rest of the branch up to
    w = 2 was 24 of the 122 points of level 80 and 24 of the 215 of level 160 (few contacts there,
    cheap points: about 1 s of the 25 s run). Without the stop a level is traced to the end. It
    also stops a level that takes too many points for the branch points it passes
    (:data:`LEVEL_POINTS_PER_POINT`)."""

    def __init__(self, lad: _Ladder, H: int, near: np.ndarray, first: int, last: int, step: int = 1):
        self.lad, self.H, self.near, self.at, self.last, self.step = lad, H, near, first, last, step
        self.first = first
        self.points = 0
        self.vectors: dict = {}

    def _vector(self, i: int) -> np.ndarray:
        if i not in self.vectors:
            a = _anchor(self.lad.branch, i)
            self.vectors[i] = self.lad.vector(self.H, a.Q, a.P, a.omega, a.xi, a.p)
        return self.vectors[i]

    def __call__(self, point) -> bool:
        if self.lad.deadline is not None and time.perf_counter() > self.lad.deadline:
            return False  # the caller's check_time raises once the continuation has returned
        y = np.append(point.x, point.p)
        if self.step > 0:
            ahead = range(self.at, min(self.at + 4, len(self.lad.branch)))
        else:
            ahead = range(self.at, max(self.at - 4, -1), -1)
        self.at = ahead[int(np.argmin([float(((y - self._vector(i)) ** 2) @ self.near) for i in ahead]))]
        for i in [k for k in self.vectors if (k - self.at) * self.step < 0]:
            del self.vectors[i]
        self.points += 1
        passed = (self.at - self.first) * self.step
        if self.points > LEVEL_POINTS_PER_POINT * passed + LEVEL_POINTS_SLACK:
            log.info("accuracy: level H = %d stopped after %d continuation points for %d points of the branch (more "
                     "than %d per point: it follows loops the branch does not have)", self.H, self.points, passed,
                     LEVEL_POINTS_PER_POINT)
            return False
        return (self.last - self.at) * self.step >= 0


def _between(prob, y0: np.ndarray, y1: np.ndarray, theta: float) -> np.ndarray:
    """The point a fraction ``theta`` of the way from ``y0`` to ``y1`` (``[x; p]`` of two points
    of a continuation of ``prob``). For a problem that can delay its motion (``phase_shift``),
    the phase is interpolated: ``y1`` is delayed back by the phase ``tau`` between the two points
    (weighted mean of the first harmonics' phase differences), blended linearly with ``y0``, and
    the blend delayed by ``theta tau``; harmonic ``k`` then turns by ``k theta tau`` instead of
    moving along its chord. Measured on the seed case at rtol 1e-3: the continuation's points are
    far enough apart (phase predictor) that the linear blend, a poor start for the contact-force
    harmonics at H = 80-160, cost 56-65 Newton evaluations per hyperplane solve."""
    x0, x1, p0, p1 = y0[:-1], y1[:-1], float(y0[-1]), float(y1[-1])
    p = p0 + theta * (p1 - p0)
    shift = getattr(prob, "phase_shift", None)
    if shift is None:
        return y0 + theta * (y1 - y0)
    u0, u1 = prob.unpack(x0, p0), prob.unpack(x1, p1)
    # first harmonics (rows 1, 2: c_1, s_1) of all displacements and contact forces
    z0 = np.concatenate([u0.Q[1] + 1j * u0.Q[2], u0.P[1] + 1j * u0.P[2]]) if u0.Q.shape[0] > 2 else np.zeros(0)
    z1 = np.concatenate([u1.Q[1] + 1j * u1.Q[2], u1.P[1] + 1j * u1.P[2]]) if u1.Q.shape[0] > 2 else np.zeros(0)
    # c cos + s sin = Re((c - i s) e^{i theta}): a delay tau multiplies c + i s by e^{i tau}
    cross = np.sum(z1 * np.conj(z0))
    if not abs(cross) > 0:
        return y0 + theta * (y1 - y0)
    tau = float(np.angle(cross))
    back = np.asarray(shift(x1, -tau), dtype=float)
    return np.append(np.asarray(shift(x0 + theta * (back - x0), theta * tau), dtype=float), p)


def _without_contact(branch: Branch) -> np.ndarray:
    """The points without contact force (complementarity forces zero to round-off): every level is
    the branch's own point there (the linear response, padded with zero harmonics, solves the
    equations of any level exactly). None with other nonlinear laws (penalty contacts, cubic
    springs): their points are not linear even where the complementarity forces vanish."""
    model = branch.model
    others = "penalty" in branch.contacts.kinds or bool(model is not None and model.nonlinearities)
    if not branch.P.size or others:
        return np.zeros(len(branch), dtype=bool)
    peak = _contact_force_peak(branch)
    return peak <= 1e-12 * float(peak.max())  # the complementarity force below contact is zero to round-off


def _free_before(branch: Branch, i: int) -> int:
    """The last point at or before ``i`` without contact force (every level agrees there), else 0."""
    free = np.flatnonzero(_without_contact(branch)[: i + 1])
    return int(free[-1]) if free.size else (i if not branch.P.size else 0)


# --------------------------------------------------------------------------------------------
# Shooting refinement: the H -> inf limit of a point, from the exact flow with rigid stops
# --------------------------------------------------------------------------------------------
#: A shooting solution whose start state lies farther than this (relative) from the harmonic
#: balance point's is taken as another orbit, and the point is left to the levels.
SHOOTING_MAX_CORRECTION = 0.5
#: Floor of the relative half-width stated for a shooting limit: the exact flow is exact up to
#: round-off and the root tolerance of the impact times (4 eps); the Newton solve stops after a
#: relative frequency step of SHOOTING_STEP (1e-7), leaving about its square. The floor leaves a
#: margin of 1e3 and more over both (the seed folds came out within 1e-14 of their references).
SHOOTING_FLOOR = 1e-9
#: ``method="auto"`` shoots only if the event search of the probe run (one period from the point
#: with the largest contact force) evaluates at most this many modal terms (samples times the
#: state's size): the FE bar of README_accuracy with 40 elements (41 DOFs) needs 1.9e4, where a
#: fine grid over the whole period would need 8e5; a stiff model whose impacts excite its fast
#: modes pays the fine grid nearly everywhere.
SHOOTING_AUTO_MAX_WORK = 1e6
#: ``auto`` shoots only models with at most this many DOFs with mass: a run's dense algebra (modal
#: propagators, monodromy matrix, coefficient sensitivities) grows like n^3 (the FE bar of
#: README_accuracy: 41 DOFs 6.2 s, 81 DOFs 44 s for about 50 points); larger models go to the
#: levels, or can be reduced by Craig-Bampton first.
SHOOTING_AUTO_MAX_DOFS = 120
#: ``auto`` also leaves to the levels a model whose probe run (one period from the point with the
#: largest contact force) has more events than this at one contact: the 10-element Hermite cantilever of
#: README_accuracy (``cant20``) chatters, its massless tip node closing and opening 20 times within
#: 0.1 time units (88 impacts per period with the tip's mass kept), and Newton on its exact orbit
#: stalls (|F| 0.18 after 60 s); the seed cases and the FE bar (10-40 elements) have one impact.
SHOOTING_AUTO_MAX_EVENTS = 8
#: Largest ``kappa`` (:meth:`_Shooter.glancing`) for which the exact orbit on a point's
#: hyperplane is taken as the point's counterpart.
GLANCING_MAX = 3.0
#: A point whose ``kappa`` is outside ``(0, GLANCING_MAX]`` keeps its exact crossing if the exact
#: curve crosses the hyperplane at a cosine of at least this (:meth:`_Shooter.crossing_cosine`):
#: in a tongue, where the branch turns over many closely spaced points, the frequency slopes say
#: little (the FE bar with a massless tip of README_accuracy: kappa -0.2 to -0.8 at cosines
#: 0.5-0.95, crossings 1e-3 away). The points the seed cases reject all have cosines of 0.11-0.43.
GLANCING_COS = 0.5
#: Relative slack with which an exact fold of the exact branch counts as one a located fold
#: already has (:func:`_folds_from_exact_branch`; the fold search's half-widths are below 1e-6).
SHOOTING_FOLD_SLACK = 1e-6
#: After this many points of the first pass without an orbit (Newton from the predecessor's
#: orbit, from the point itself and the linear orbit all failed), :func:`_shoot_branch` traces
#: the exact branch and tries its crossings before the points' own starts: on the cantilever
#: with 3 % modal damping of README_accuracy (section 5) the H = 20 points on the rising side are
#: far from the exact curve. The seed cases' first pass misses at most 2 points (just above
#: grazing), the FE bars' none.
SHOOTING_EXACT_AFTER = 3
#: Marks a point whose exact crossing is no counterpart (:meth:`_Shooter.glancing`).
GLANCING = "glancing"
#: A lower fold with a point without contact at most this many points away may be a grazing
#: (:meth:`_Shooter.fold`; seed case 1: the lower fold is point 79, contact ends at point 81).
GRAZING_POINTS = 4
#: Halvings of the failed steps of one continuation over the parallel planes of a fold
#: (:meth:`_Shooter.fold`) of a model with massless contacts, whose orbits with contact go on
#: smoothly into the linear one past a lower fold (with impacts they end at a grazing there).
FOLD_STEP_HALVINGS = 4
#: Shooting solves stop when the periodicity residual (relative to the state) and the hyperplane
#: value are below SHOOTING_TOL and the last frequency step below SHOOTING_STEP (relative): Newton
#: converges quadratically, so the frequency is then off by about the square of that step.
SHOOTING_TOL, SHOOTING_STEP = 1e-11, 1e-7
#: Newton iterations of one shooting solve.
SHOOTING_MAX_ITER = 40
#: A shooting solve gives up after SHOOTING_STALL consecutive Newton steps that the backtracking
#: cut below SHOOTING_STALL_ALPHA of the full step: on the seed cases and the FE bars (10, 20
#: elements, with and without the tip's mass) no solve that converged had two such steps in a
#: row, while the failing ones had up to 23 (a failing solve costs up to 40 iterations of up to
#: 21 runs each).
SHOOTING_STALL, SHOOTING_STALL_ALPHA = 3, 2.0 ** -8


def shooting_unsupported(branch: Branch, projection=None) -> str:
    """Why the shooting refinement cannot take ``branch`` (``""`` if it can): it needs a forced
    branch (period one) of a linear model whose only contacts are rigid stops
    (:func:`femodes.time.exact.exact_flow_unsupported`), computed with the exact projection."""
    if branch.kind != "forced":
        return "nonlinear modes are compared at the same energy (levels only)"
    if branch.model is None:
        return "the branch has no model"
    return shooting_unsupported_for(branch.model, branch.harmonics, projection)


def shooting_unsupported_for(model, harmonics, projection=None) -> str:
    """:func:`shooting_unsupported` of the forced branch that ``model`` would give on ``harmonics``
    (checked by :func:`femodes.frequency_response` before it runs, for ``error_method="shooting"``)."""
    if harmonics.subharmonic != 1:
        return "sub-harmonic branch"
    if projection is not None and type(projection).__name__ != "ExactProjection":
        return "the branch is computed with a sampled projection"
    return exact_flow_unsupported(model)


class _Shooter:
    """Orbits of the exact flow (:class:`femodes.time.exact.LinearImpactFlow`) on the hyperplanes
    of a branch's points: the ``H -> inf`` limit the levels extrapolate to, for rigid impacts
    with restitution 1 (the limit of harmonic balance with complementarity contacts: 4.4, 2.4,
    1.2, 0.67 % fold errors at H = 10-80 against the event-driven reference converge to it)."""

    def __init__(self, lad: _Ladder, flow=None):
        self.lad = lad
        self.branch = lad.branch
        self.H = lad.h0.n_harmonics
        self.flow = flow or LinearImpactFlow(lad.model, float(np.mean(self.branch.omega)))
        self.n = self.flow.n
        self.runs = 0

    def start(self, i: int) -> tuple[np.ndarray, float]:
        """State of point ``i`` at its most open phase (largest smallest gap) and that phase."""
        b, h = self.branch, self.lad.h0
        Q = b.Q[i]
        theta = h.most_open_phase(Q, self.flow.dofs, self.flow.gaps)
        e = h.synthesis(np.array([theta]))[0]
        return np.concatenate([e @ Q, e @ (h.derivative(float(b.omega[i])) @ Q)]), theta

    def evaluate(self, x0: np.ndarray, omega: float, theta0: float, plane, jac: bool):
        """Periodicity residual, hyperplane value and (with ``jac``) their Jacobian in ``(x0, w)``,
        all from the variational run: the monodromy matrix, the end state's and the
        coefficients' change with ``w`` at the fixed start phase (:attr:`FlowRun.x_end_omega`,
        :meth:`FlowRun.coefficient_omega`) and the hyperplane's gradient."""
        F, dFdx, dFdw, run = periodicity_residual(self.flow, x0, omega, theta0 / omega, variational=jac)
        self.runs += 1
        h = plane.value(run, omega)
        if not jac:
            return F, h, None, run
        n2 = 2 * self.n
        J = np.zeros((n2 + 1, n2 + 1))
        J[:n2, :n2] = dFdx
        J[n2, :n2] = plane.gradient(run)
        J[:n2, n2] = dFdw
        J[n2, n2] = plane.omega_derivative(run)
        return F, h, J, run

    def plane(self, i: int, offset: float = 0.0) -> _Plane:
        """The hyperplane of point ``i`` (shifted by ``offset``) as a function of a run."""
        return _Plane(self, i, offset)

    def glancing(self, i: int, r) -> float:
        """How obliquely the exact curve crosses point ``i``'s hyperplane compared with the
        branch: ``kappa = (dw*/ds) / (dw/ds)``, the change of the crossing frequency per unit
        offset of the plane on the exact curve over the same on the branch (its neighbours).
        About 1 where the two curves run alike (1.0-1.1 on seed case 1 from the rising side to
        the fold); large just above grazing, where a displacement's amplitude stays at the gap
        while the frequency moves and the plane is nearly tangent to the exact curve (18, 14, 10
        at the first three points with contact of seed case 1, whose crossings lie 12 %, 7 %
        and 1.2 % away), or negative (seed case 2, three points above grazing: the exact curve
        runs back through the plane): the crossing is then not the point's counterpart."""
        J = r[5]
        b = self.branch
        if J is None:  # the linear orbit: its curve is the branch's own
            return 1.0
        n2 = J.shape[0] - 1
        try:
            dws = float(np.linalg.solve(J, np.r_[np.zeros(n2), 1.0])[n2])
        except np.linalg.LinAlgError:
            return math.inf
        plane = self.plane(i)
        j0, j1 = max(i - 1, 0), min(i + 1, len(b) - 1)
        ds = plane.at(b.Q[j1], float(b.omega[j1])) - plane.at(b.Q[j0], float(b.omega[j0]))
        dw = float(b.omega[j1] - b.omega[j0])
        if dw == 0.0 or ds == 0.0:
            return math.inf
        return dws / (dw / ds)

    def crossing_cosine(self, i: int, r) -> float:
        """Cosine of the angle between the exact curve at its crossing of point ``i``'s
        hyperplane and the hyperplane's normal (the branch direction), in the branch's arclength
        weights on the displacements and the frequency: 1 for a crossing at right angles, near 0
        for a glancing one. The exact curve's direction ``d(x0, w)/ds`` is the Newton Jacobian's
        last column of its inverse; the coefficients follow exactly in ``x0`` and ``w`` (a
        variational run)."""
        x0, w, theta0, _, _, J = r[:6]
        if J is None:  # the linear orbit: the branch's own curve
            return 1.0
        n2 = J.shape[0] - 1
        try:
            d = np.linalg.solve(J, np.r_[np.zeros(n2), 1.0])
        except np.linalg.LinAlgError:
            return 0.0
        run = self.flow.at(w).run(x0, theta0 / w, variational=True)
        self.runs += 1
        dQ = (np.einsum("kdc,c->kd", run.coefficient_sensitivity(self.H), d[:n2])
              + run.coefficient_omega(self.H) * d[n2])
        lad = self.lad
        W = lad.weights(self.H)
        wQ, wp = lad.problem(self.H).unpack(W[:-1], W[-1]).Q, float(W[-1])
        t = lad.tangents[i]
        num = float(np.sum(wQ * t.Q * dQ)) + wp * t.omega * d[n2]
        den = math.sqrt(float(np.sum(wQ * t.Q ** 2)) + wp * t.omega ** 2) * math.sqrt(
            float(np.sum(wQ * dQ ** 2)) + wp * d[n2] ** 2)
        return abs(num) / den if den > 0.0 else 0.0

    def warm(self, i: int, prev) -> tuple:
        """A first guess for point ``i`` from the exact orbit ``prev = (x0, w, theta0, j)`` of a
        neighbour ``j``: moved by the branch's change from ``j`` to ``i`` at the same phase."""
        x0, omega, theta0, j = prev[:4]
        b, h = self.branch, self.lad.h0
        e = h.synthesis(np.array([theta0]))[0]
        dQ = b.Q[i] - b.Q[j]
        dv = e @ (h.derivative(float(b.omega[i])) @ b.Q[i]) - e @ (h.derivative(float(b.omega[j])) @ b.Q[j])
        return x0 + np.concatenate([e @ dQ, dv]), omega + float(b.omega[i] - b.omega[j]), theta0

    def linear(self, i: int, offset: float = 0.0):
        """The orbit without impacts on the hyperplane of point ``i``, if that orbit stays off the
        obstacles (just above grazing the harmonic balance point touches, the exact orbit may
        not): the forced linear response, whose frequency on the hyperplane is found by the
        secant method. Same return as :meth:`solve`, or None."""
        plane = self.plane(i, offset)
        theta0 = self.start(i)[1]

        def value(omega):
            flow = self.flow.at(omega)
            t0 = theta0 / omega
            self.runs += 1
            run = flow.run(flow.particular(t0), t0)
            return plane.value(run, omega), run

        w0 = float(self.branch.omega[i])
        w1 = w0 * (1.0 + 1e-3)
        try:
            h0, _ = value(w0)
            for _ in range(30):
                h1, run = value(w1)
                if h1 == h0:
                    break
                w0, w1, h0 = w1, w1 - h1 * (w1 - w0) / (h1 - h0), h1
                if not w1 > 0.0:
                    return None
                if abs(w1 - w0) <= SHOOTING_STEP * abs(w1) and abs(h1) <= SHOOTING_TOL:
                    h1, run = value(w1)
                    if run.touches:
                        return None  # the linear orbit there reaches an obstacle
                    return run.x_end, w1, theta0, run, abs(w1 - w0), None
        except ValueError:
            return None
        return None

    def at_frequency(self, i: int):
        """The exact orbit at point ``i``'s own frequency (:class:`_FrequencyPlane`), from the point
        itself, else from the linear orbit at that frequency and the point's start phase: just
        above grazing the exact orbit is near the linear one, while Newton from the point may
        stall (seed case 1 at H = 20, w = 0.906552, 6.3e-5 above the grazing: three steps cut below
        2^-8 from the point; 15 Newton iterations from the linear orbit). Same return as :meth:`solve`, or
        None."""
        omega = float(self.branch.omega[i])
        plane = _FrequencyPlane(omega)
        r = self.solve(i, plane=plane)
        if r is None:
            theta0 = self.start(i)[1]
            x = self.flow.at(omega).particular(theta0 / omega)
            if self.flow.admissible(x):
                r = self.solve(i, guess=(x, omega, theta0), plane=plane)
        return r

    def solve_from(self, i: int, j: int, at_j, pieces: int = 8):
        """The orbit on point ``i``'s hyperplane by a continuation over the planes between a
        neighbour ``j``'s (solved: ``at_j``) and ``i``'s, in ``pieces`` steps: just above
        grazing, where the flow's derivative jumps with the impact, Newton from ``j``'s orbit
        in one step cycles between orbits with and without it (seed case 1: the first two
        points with contact)."""
        r = at_j
        for k in range(1, pieces + 1):
            plane = _Plane(self, j, toward=i, theta=k / pieces)
            r = self.solve(i, guess=r[:3], plane=plane)
            if r is None:
                return None
        return r

    def solve(self, i: int, guess=None, offset: float = 0.0, plane=None):
        """The exact orbit on the hyperplane of point ``i`` (shifted by ``offset``): ``(x0, w,
        theta0, run, dw)`` with the last Newton step ``dw``, or None. Newton with a backtracking
        search on the residual norm (near grazing the flow's derivative jumps where an impact
        appears, and full steps cycle between orbits with and without it)."""
        x_hbm, theta0 = self.start(i)
        if guess is None:
            x0, omega = x_hbm, float(self.branch.omega[i])
        else:
            x0, omega, theta0 = guess[0].copy(), guess[1], guess[2]
        plane = plane or self.plane(i, offset)
        n2 = 2 * self.n
        step = np.inf
        stalled = 0

        def converged(F, h, x, step, w):
            return (float(np.max(np.abs(F))) <= SHOOTING_TOL * max(1.0, float(np.max(np.abs(x))))
                    and abs(h) <= SHOOTING_TOL and step <= SHOOTING_STEP * w)

        def norm(F, h, x):
            return math.hypot(float(np.linalg.norm(F)) / max(1.0, float(np.max(np.abs(x)))), h)

        try:
            F, h, J, run = self.evaluate(x0, omega, theta0, plane, True)
        except ValueError as exc:  # a start state in the obstacle, an accumulation of impacts
            log.debug("accuracy: shooting at point %d: %s", i, exc)
            return None
        for _ in range(SHOOTING_MAX_ITER):
            if converged(F, h, x0, step, omega):
                corr = float(np.max(np.abs(x0 - x_hbm))) / max(float(np.max(np.abs(x_hbm))), 1e-300)
                if guess is None and corr > SHOOTING_MAX_CORRECTION:
                    log.info("accuracy: shooting at point %d found another orbit (start state moved by %.0f %%)",
                             i, 100 * corr)
                    return None
                return x0, omega, theta0, run, step, J
            try:
                d = np.linalg.solve(J, -np.append(F, h))
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(d)):
                return None
            r0 = norm(F, h, x0)
            alpha = 1.0
            while alpha >= 2.0 ** -20:
                x1, w1 = x0 + alpha * d[:n2], omega + alpha * d[n2]
                if w1 > 0.0 and self.flow.admissible(x1):
                    try:
                        F1, h1, _, run1 = self.evaluate(x1, w1, theta0, plane, False)
                    except ValueError:
                        F1 = None
                    if F1 is not None and norm(F1, h1, x1) <= (1.0 - 1e-4 * alpha) * r0:
                        break
                alpha *= 0.5
            else:
                log.debug("accuracy: shooting at point %d: no step reduces the residual", i)
                return None
            step = abs(alpha * d[n2])
            stalled = stalled + 1 if alpha < SHOOTING_STALL_ALPHA else 0
            if stalled >= SHOOTING_STALL:
                log.debug("accuracy: shooting at point %d stalls (%d steps shorter than %g)", i, stalled,
                          SHOOTING_STALL_ALPHA)
                return None
            x0, omega, F, h, run = x1, w1, F1, h1, run1
            if not converged(F, h, x0, step, omega):
                F, h, J, run = self.evaluate(x0, omega, theta0, plane, True)
        log.debug("accuracy: shooting at point %d did not converge", i)
        return None

    def fold(self, f: int, at_f) -> tuple[float, float] | None:
        """The fold of the exact curve next to the branch's fold ``f``: the extreme frequency of
        the exact orbits on the hyperplanes parallel to ``f``'s (offset ``s``), found by Brent's
        method in ``s`` from ``at_f`` (the orbit at ``s = 0``). Returns the frequency and the
        relative half-width of its uncertainty (the change of the frequency over the final
        tolerance in ``s``, at least :data:`SHOOTING_FLOOR`), or None."""
        from scipy.optimize import minimize_scalar

        b = self.branch
        n = len(b)
        nb = [j for j in (f - 1, f + 1) if 0 <= j < n]
        upper = all(b.omega[j] <= b.omega[f] for j in nb)
        sign = -1.0 if upper else 1.0
        # the offset of the neighbours in the plane's units: the scale of the search
        plane = _Plane(self, f)
        d = max(abs(plane.at(b.Q[j], float(b.omega[j]))) for j in nb)
        if not d > 0.0:
            return None
        solved = {0.0: at_f}

        # with impacts the orbits with contact end at a grazing next to a lower fold (handled below),
        # with massless contacts they go on into the linear orbit, which a step may overshoot
        halvings = FOLD_STEP_HALVINGS if self.flow.massless.any() else 0
        scale = d  # of the bracket; the continuation's steps are half of it

        def reach(s: float, exact: bool = True) -> float:
            """Continuation from the nearest solved offset to ``s`` in steps of ``scale / 2``, a failed
            step halved (``halvings`` times in all); the offset reached (``s`` if ``exact``)."""
            near = min(solved, key=lambda t: abs(t - s))
            r, at, step = solved[near], near, math.copysign(0.5 * scale, s - near)
            fails = 0
            while at != s:
                sk = s if abs(s - at) <= abs(step) else at + step
                rk = self.solve(f, guess=r[:3], offset=sk)
                if rk is None:
                    fails += 1
                    if fails > halvings:
                        if exact or at == near:
                            raise _ShootingFailed(f"no exact orbit at offset {sk:g} from fold {f}")
                        return at
                    step *= 0.5
                    continue
                r, at = rk, sk
                solved[sk] = r
            return at

        def omega_at(s: float) -> float:
            return sign * solved[reach(s)][1]

        def side(s: float) -> tuple[float, float]:
            at = reach(s, exact=False)
            return at, sign * solved[at][1]

        def extreme(h: float) -> tuple[float, float]:
            """A bracket (sa, sb, sc) with the extreme inside, walking downhill by ``h``, then Brent."""
            nonlocal scale
            scale = h
            sb, fb = 0.0, sign * at_f[1]
            (sa, fa), (sc, fc) = side(-h), side(h)
            for _ in range(8):
                if fb <= min(fa, fc):
                    break
                if fa < fc:
                    sa, sb, sc, fc, fb = sa - h, sa, sb, fb, fa
                    fa = omega_at(sa)
                else:
                    sa, sb, sc, fa, fb = sb, sc, sc + h, fb, fc
                    fc = omega_at(sc)
            else:
                raise _ShootingFailed(f"no extreme frequency within {8 * h:g} of fold {f}")
            res = minimize_scalar(omega_at, bracket=(sa, sb, sc), method="brent", options={"xtol": 1e-4})
            return float(res.x), sign * float(res.fun)

        try:
            try:
                s, w = extreme(d)
            except _ShootingFailed:
                if not halvings:
                    raise
                # massless contacts: planes a neighbour's offset away may cross the exact curve past its
                # fold (2-DOF case of the tests, H = 10: an orbit below the fold's frequency at 0.87 d)
                s, w = extreme(0.25 * d)
            tol = 1e-4 * max(abs(s), d)
            spread = max(abs(sign * omega_at(s + tol) - w), abs(sign * omega_at(s - tol) - w))
        except (_ShootingFailed, ValueError, RuntimeError) as exc:
            # a lower fold that ends the contact within a few points: the impacting orbits end at a
            # grazing there (past it the exact curve has no impacting orbit on these planes)
            free = _without_contact(b)
            ends_contact = bool(free[max(f - GRAZING_POINTS, 0): f + GRAZING_POINTS + 1].any())
            # (impacts only: a massless contact's orbits leave the linear one smoothly, its folds are ordinary)
            impacts = not self.flow.massless.any()
            graze = self.grazing(float(b.omega[f])) if not upper and ends_contact and impacts else None
            if graze is None:
                log.info("accuracy: the exact fold next to point %d was not located (%s)", f, exc)
                return None
            log.info("accuracy: the fold next to point %d is the grazing of the linear response at w = %.9g", f,
                     graze)
            return graze, SHOOTING_FLOOR
        return w, max(spread / abs(w), SHOOTING_FLOOR)

    def grazing(self, omega: float) -> float | None:
        """The frequency nearest ``omega`` (within 5 %) at which the linear response just touches
        an obstacle (``max_t q_c = gap``). With restitution 1 the branch of impacting orbits
        ends there on the linear one (a nonsmooth fold; harmonic balance smooths it into a fold:
        seed case 1, H = 20, 1.080770 against the grazing 1.080869). Forcing with one harmonic
        (and a static part) only: ``max_t q_c = Re X_0 + |X_1|`` in closed form."""
        from scipy.optimize import brentq

        flow = self.flow
        if not set(flow.k.tolist()) <= {0, 1}:
            return None

        def margin(w):
            fl = self.flow.at(w)
            X = fl.free_harmonics()
            top = np.abs(X[1]) if 1 in X else 0.0
            return float(np.min(fl.gaps - np.real(X[0]) - top))

        ws = omega * (1.0 + np.linspace(-0.05, 0.05, 201))
        m = np.array([margin(w) for w in ws])
        roots = [brentq(margin, ws[j], ws[j + 1], xtol=1e-14 * omega) for j in np.flatnonzero(m[:-1] * m[1:] < 0.0)]
        return min(roots, key=lambda r: abs(r - omega)) if roots else None


class _Plane:
    """The hyperplane of a branch point for orbits of the exact flow: ``(c_Q . (Q - Q_a) +
    c_w (w - w_a) - offset) / (|c| |a|)`` with ``Q`` the orbit's displacement coefficients on the
    branch's harmonics, ``c`` the point's normal in the branch's arclength weights (the levels'
    hyperplane without its contact-force part: the exact contact forces are impulses, whose
    coefficients the branch's truncated forces do not resemble) and ``a`` the point."""

    def __init__(self, sh: _Shooter, i: int, offset: float = 0.0, toward: int | None = None, theta: float = 0.0):
        lad, H = sh.lad, sh.H
        b = sh.branch
        a_st, n_st = _anchor(b, i), lad.tangents[i]
        if toward is not None:  # the plane a fraction theta of the way to point `toward`'s
            a_st = lad.blend(a_st, _anchor(b, toward), theta)
            n_st = lad.blend(n_st, lad.tangents[toward], theta)
        a = lad.vector(H, a_st.Q, a_st.P, a_st.omega, a_st.xi, a_st.p)
        c = lad.weights(H) * lad.vector(H, n_st.Q, 0.0 * n_st.P, n_st.omega, n_st.xi, n_st.p)
        self.H = H
        self.scale = (float(np.linalg.norm(c)) or 1.0) * (float(np.linalg.norm(a)) or 1.0)
        self.cQ = lad.problem(H).unpack(c[:-1], c[-1]).Q
        self.cw = float(c[-1])
        self.Qa, self.wa = a_st.Q, a_st.omega
        self.offset = offset

    def at(self, Q: np.ndarray, omega: float) -> float:
        return (float(np.sum(self.cQ * (Q - self.Qa))) + self.cw * (omega - self.wa) - self.offset) / self.scale

    def value(self, run, omega: float) -> float:
        return self.at(run.coefficients(self.H)[0], omega)

    def gradient(self, run) -> np.ndarray:
        """``d value / d x0`` (a variational run)."""
        return np.einsum("kd,kdc->c", self.cQ, run.coefficient_sensitivity(self.H)) / self.scale

    def omega_derivative(self, run) -> float:
        """``d value / d w`` at the run's start phase (a variational run)."""
        return (float(np.sum(self.cQ * run.coefficient_omega(self.H))) + self.cw) / self.scale


class _FrequencyPlane:
    """The plane ``w = w_a`` for :meth:`_Shooter.solve`: the exact orbit at a point's own
    frequency, the counterpart of a point where the exact curve crosses the branch's hyperplane
    obliquely (just above grazing)."""

    def __init__(self, omega: float):
        self.wa = float(omega)

    def at(self, Q: np.ndarray, omega: float) -> float:
        return (omega - self.wa) / self.wa

    def value(self, run, omega: float) -> float:
        return self.at(None, omega)

    def gradient(self, run) -> np.ndarray:
        return np.zeros(2 * run.flow.n)

    def omega_derivative(self, run) -> float:
        return 1.0 / self.wa


class _ShootingFailed(RuntimeError):
    pass


def _shoot_branch(lad: _Ladder, flow=None) -> tuple[dict, _Shooter, _ExactBranchStarts]:
    """Exact orbits on the hyperplanes of the branch's points with contact, each from its
    predecessor's (moved by the branch's step), else (after :data:`SHOOTING_EXACT_AFTER`
    failures) from the exact branch's crossing, else from the point itself, else the linear
    orbit, else (a second pass, backward) from its successor's; ``{i: (x0, w, theta0, run,
    step)}`` (None where none was found), the shooter and the exact branch's starts
    (:class:`_ExactBranchStarts`)."""
    sh = _Shooter(lad, flow)
    exact = _ExactBranchStarts(lad, sh)
    free = _without_contact(lad.branch)
    out: dict = {}
    prev = None
    failures = 0
    for i in range(len(lad.branch)):
        if free[i]:
            prev = None
            continue
        r = sh.solve(i, guess=sh.warm(i, prev)) if prev is not None else None
        if r is None and failures >= SHOOTING_EXACT_AFTER:  # the exact branch's crossing before the point's own start
            r = exact.solve(i, check=False)
        if r is None:
            r = sh.solve(i)
        if r is None:
            r = sh.linear(i)
        failures += r is None
        out[i] = r
        prev = r[:3] + (i,) if r is not None else None
    for i in sorted((i for i, r in out.items() if r is None), reverse=True):  # from the successor's orbit
        nxt = out.get(i + 1)
        if nxt is not None:
            out[i] = sh.solve(i, guess=sh.warm(i, nxt[:3] + (i + 1,))) or sh.solve_from(i, i + 1, nxt)
    for i, r in out.items():
        if r is not None and not _near_fold(lad.branch, i):
            out[i] = _counterpart(sh, i, r)
            if out[i] is GLANCING:  # the exact orbit at the point's own frequency instead
                at_w = sh.at_frequency(i)
                if at_w is not None:
                    log.info("accuracy: point %d: the exact orbit at its frequency w = %.6g instead", i,
                             lad.branch.omega[i])
                    out[i] = at_w
    return out, sh, exact
