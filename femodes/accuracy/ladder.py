"""The branch's harmonic balance problem at any number of harmonics (the *levels*), and solves on
the hyperplane through a branch point normal to the branch (in the branch's arclength norm: the
difference of two levels is then the change of the curve, not a slide along it).
"""

from __future__ import annotations

import logging
import math
import time
from functools import cached_property

import numpy as np

from ..hbm.harmonics import Harmonics
from ..hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from ..results import Branch
from ..solvers import NewtonOptions
from ..solvers.arclength import ArclengthSystem
from ..solvers.bordered import bordered_solver
from ..solvers.checks import InputTypeError, InputValueError
from .points import State, anchor, branch_tangents

__all__ = ["Ladder", "OutOfTime", "ladder_for"]

log = logging.getLogger(__name__)


class OutOfTime(Exception):
    """The estimate's time limit has passed (``estimate_error(time_limit=...)``)."""


class Ladder:
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
        w = branch.omega_truncated
        if self.forced:  # the parameter is w: scaled by the width of the branch, as the continuation does
            self.sp = self.sw = float(np.ptp(w)) or 0.1 * float(np.mean(np.abs(w))) or 1.0
        else:  # p = log10(E) by 1; w (and xi) by a tenth of the mean frequency
            self.sp = 1.0
            self.sw = 0.1 * float(np.mean(np.abs(w))) or 1.0

    # -- levels -------------------------------------------------------------
    def check_time(self) -> None:
        """Raise :class:`OutOfTime` once the deadline has passed."""
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise OutOfTime

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
        return self.harmonics(H).layout.convert(A, h) if H != h.n_harmonics else A

    def padded(self, H: int, i: int) -> State:
        """Point ``i`` of the branch on level ``H`` as it is (zero harmonics added, or dropped)."""
        a, h = anchor(self.branch, i), self.harmonics(H)
        return State(H, self._on(a.Q, h), self._on(a.P, h), a.omega, a.xi, a.p, a.nit, a.residual_norm)

    def state(self, H: int, y: np.ndarray) -> State:
        u = self.problem(H).unpack(y[:-1], y[-1])
        return State(H, u.Q.copy(), u.P.copy(), float(u.omega), float(u.xi), float(y[-1]))

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

    def solve(self, H: int, anchor: State, normal: State, guess: State | None = None,
              deadline: int | None = None) -> State | None:
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
            return branch_tangents(self.branch)
        b = self.branch
        zero = State(b.harmonics.n_harmonics, np.zeros_like(b.Q[0]), np.zeros_like(b.P[0]), 0.0, 0.0, 1.0)
        return [zero] * len(b)

    def Q_norm(self, i: int) -> float:
        return float(np.linalg.norm(self.branch.Q[i])) or 1.0

    def omega_ref(self, i: int) -> float:
        return abs(float(self.branch.omega_truncated[i])) or 1.0

    def moved(self, H: int, state: State, a_from: State, a_to: State) -> State:
        """The level-``H`` ``state`` moved by the branch's step from ``a_from`` to ``a_to``."""
        h = self.harmonics(H)
        return State(H, self._on(state.Q, h) + self._on(a_to.Q - a_from.Q, h),
                     self._on(state.P, h) + self._on(a_to.P - a_from.P, h), state.omega + a_to.omega - a_from.omega,
                     state.xi + a_to.xi - a_from.xi, state.p + a_to.p - a_from.p)


def ladder_for(branch, projection, newton) -> Ladder:
    """The :class:`Ladder` of ``branch``, after checking that it can have one (a Branch of at least two
    points, estimated with the projection it was computed with)."""
    if not isinstance(branch, Branch):
        raise InputTypeError(f"branch must be a femodes.Branch, got {type(branch).__name__}")
    if len(branch) < 2:
        raise InputValueError(f"the branch has {len(branch)} point(s); at least 2 are needed (its direction)")
    used = branch.meta.get("projection")
    given = type(projection).__name__ if projection is not None else "ExactProjection"
    if isinstance(used, str) and used != given:
        raise InputValueError(f"the branch was computed with {used} but projection={projection!r} means {given}: "
                         "its levels would be another discretisation than the branch; pass the projection the branch "
                         f"was computed with (projection={used}(...))")
    return Ladder(branch, projection, newton)
