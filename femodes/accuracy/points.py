"""The points of a branch as the estimators see them: one solution at one level (:class:`State`),
the branch's own points and directions, and which points are without contact force (every level
is the branch's own point there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..results import Branch

__all__ = ["State", "anchor", "blend", "branch_tangents", "contact_force_peak", "free_before", "near_fold",
           "period_driven", "without_contact"]


@dataclass
class State:
    """One solution at one level: the parts of the unknowns by name."""

    H: int
    Q: np.ndarray
    P: np.ndarray
    omega: float
    xi: float
    p: float
    nit: int = 0
    residual_norm: float = math.nan


def blend(a: State, b: State, theta: float) -> State:
    """``(1 - theta) a + theta b`` of two states on the same harmonics."""
    u = 1.0 - theta
    return State(a.H, u * a.Q + theta * b.Q, u * a.P + theta * b.P, u * a.omega + theta * b.omega,
                 u * a.xi + theta * b.xi, u * a.p + theta * b.p)


def anchor(branch: Branch, i: int) -> State:
    """Point ``i`` of the branch, on its own harmonics."""
    return State(branch.harmonics.n_harmonics, branch.Q[i], branch.P[i], float(branch.omega_truncated[i]), float(branch.xi[i]),
                 float(branch.parameter[i]), int(branch.nit[i]), float(branch.residual_norm[i]))


def branch_tangents(branch: Branch) -> list[State]:
    """Branch directions at every point from its neighbours (central, one-sided at the ends);
    at a located fold the direction along the displacement (dp/ds = 0 there)."""
    n = len(branch)
    out = []
    for i in range(n):
        a, b = max(i - 1, 0), min(i + 1, n - 1)
        if a == b:
            raise ValueError("estimate_error: a branch of one point has no direction; it needs >= 2 points")
        out.append(State(branch.harmonics.n_harmonics, branch.Q[b] - branch.Q[a], branch.P[b] - branch.P[a],
                         float(branch.omega_truncated[b] - branch.omega_truncated[a]), float(branch.xi[b] - branch.xi[a]),
                         float(branch.parameter[b] - branch.parameter[a])))
    return out


def contact_force_peak(branch: Branch) -> np.ndarray:
    """The largest contact-force coefficient of every point (zeros without contacts)."""
    P = np.abs(branch.P)
    return P.reshape(len(branch), -1).max(axis=1) if P.size else np.zeros(len(branch))


def without_contact(branch: Branch) -> np.ndarray:
    """The points without contact force (complementarity forces zero to round-off): every level is
    the branch's own point there (the linear response, padded with zero harmonics, solves the
    equations of any level exactly). None with other nonlinear laws (penalty contacts, cubic
    springs): their points are not linear even where the complementarity forces vanish."""
    model = branch.model
    others = "penalty" in branch.contacts.kinds or bool(model is not None and model.nonlinearities)
    if not branch.P.size or others:
        return np.zeros(len(branch), dtype=bool)
    peak = contact_force_peak(branch)
    return peak <= 1e-12 * float(peak.max())  # the complementarity force below contact is zero to round-off


def free_before(branch: Branch, i: int) -> int:
    """The last point at or before ``i`` without contact force (every level agrees there), else 0."""
    free = np.flatnonzero(without_contact(branch)[: i + 1])
    return int(free[-1]) if free.size else (i if not branch.P.size else 0)


def near_fold(branch: Branch, i: int) -> bool:
    """Whether point ``i`` is a fold or next to one: the branch's dw/ds vanishes there, and the
    plane there is across the fold's amplitude, which the exact curve crosses near its own fold."""
    return any(abs(i - f) <= 1 for f in branch.folds)


def period_driven(branch: Branch) -> bool:
    """The branch holds the contact-phase family traced by period past grazing."""
    return branch.kind == "nonlinear mode" and branch.meta.get("family") == "contact phase"
