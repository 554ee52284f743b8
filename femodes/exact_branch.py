"""Results layer: the exact branch (:class:`ExactBranch`), periodic orbits of a linear model with
rigid stops traced by :func:`femodes.exact_frequency_response`, and where its folds are."""

from __future__ import annotations

import math

import numpy as np

from .time.exact import LinearImpactFlow
from .time.exact_run import FlowRun

__all__ = ["ExactBranch", "EXACT_FOLD_RTOL", "FOLD_WINDOW", "fold_is_upper", "fold_window"]

#: Relative error stated for a fold of :func:`~femodes.exact_frequency_response` that is the extreme
#: frequency of its neighbours: its location by the continuation (secant on ``dw/ds``) measured
#: 3.2e-8 and 2.5e-13 against the seed cases' references, below 1e-9 against the shooting
#: refinement on the 2-DOF massless model (tests/test_exact_branch.py).
EXACT_FOLD_RTOL = 1e-6
#: Points on either side of a fold that :attr:`ExactBranch.fold_omega` looks at (and
#: :func:`fold_is_upper`). With a finite-difference ``dr/dw`` the continuation detected the lower
#: fold of the cantilever of ``benchmarks/bench_cantilever_time.py`` at 3.7193289, a point between
#: two of larger frequency on one side and smaller on the other (a kink); the extreme of the 3
#: points on either side was 3.7193164, their range 2.9e-5 relative; local continuations with
#: short steps give 3.719311942. Detected folds are now refined (``exact_response._refine_fold``).
FOLD_WINDOW = 3


def fold_is_upper(omega: np.ndarray, j: int) -> bool:
    """Whether the fold at point ``j`` of a branch is a largest frequency: ``omega[j]`` at least
    the mean of the frequencies :data:`FOLD_WINDOW` points before and after it (fewer at the
    ends)."""
    lo, hi = max(j - FOLD_WINDOW, 0), min(j + FOLD_WINDOW, omega.size - 1)
    return bool(omega[j] >= 0.5 * (omega[lo] + omega[hi]))


def fold_window(omega: np.ndarray, j: int) -> tuple[np.ndarray, bool, float]:
    """The frequencies of fold ``j`` and of the :data:`FOLD_WINDOW` points on either side of it,
    whether it is an upper fold (:func:`fold_is_upper`), and their extreme frequency that way."""
    win = omega[max(j - FOLD_WINDOW, 0):min(j + FOLD_WINDOW + 1, omega.size)]
    upper = fold_is_upper(omega, j)
    return win, upper, float(win.max() if upper else win.min())


class ExactBranch:
    """Periodic orbits of a linear model with rigid stops traced by continuation in the forcing
    frequency (:func:`femodes.exact_frequency_response`).

    Attributes
    ----------
    omega : ndarray (n_points,)
    states : ndarray (n_points, 2 n_dofs)
        Start states ``[q; v]`` at ``t = 0``, periodic to the continuation's Newton tolerance
        (massless DOFs' entries consistent with the others).
    atol : float
        That tolerance: ``|x(T) - x(0)|`` of the inertial entries is about that small at every
        point (Newton also stops on a step below its ``xtol``).
    folds : tuple of int
        Indices of the folds (turning points in ``omega``) the continuation located, or only
        detected (the point nearer to the sign change of ``dw/ds``).
    fold_omega, fold_error : ndarray (len(folds),)
        The folds' frequencies and relative errors: a located fold that is the extreme frequency
        of the :data:`FOLD_WINDOW` points on either side is taken as it is, with the error
        :data:`EXACT_FOLD_RTOL`; otherwise the extreme frequency of those points, with their
        range as the error. A fold the continuation detected but did not locate (a grazing at
        the turn: the corrector fails there) is refined by short-step continuations toward it
        from both sides (``exact_response._refine_fold``): the extreme frequency they and the branch reach,
        with the larger distance of either side's extreme from it (at least
        :data:`EXACT_FOLD_RTOL`) as the error.
    fold_upper : ndarray of bool (len(folds),)
        Whether a fold is a largest frequency (the branch turns back from increasing ``omega``;
        :func:`fold_is_upper`).
    pieces : tuple of int
        Start indices of the pieces: ``(0,)``, or ``(0, k)`` when the continuation stopped inside
        the span (a grazing orbit) and points ``k:`` were traced back from the other end.
    success, status, message
        Whether the pieces cover the span; the status (:data:`~femodes.solvers.STATUS_MESSAGES`)
        and message of the first continuation, and of the second if there is one.
    runs : int
        Runs of the flow (the cost).
    flow : LinearImpactFlow
    """

    def __init__(self, flow: LinearImpactFlow, omega, states, results, folds, runs: int, atol: float,
                 refined: dict | None = None, orbits: list | None = None):
        self.flow, self.atol = flow, float(atol)
        self.omega = np.asarray(omega, dtype=float)
        self.states = np.asarray(states, dtype=float)
        self.folds = tuple(sorted(int(i) for i in folds))
        self.fold_omega, self.fold_error, self.fold_upper = self._fold_frequencies()
        for k, j in enumerate(self.folds):  # detected folds refined by short-step continuations
            if refined and j in refined:
                self.fold_omega[k], self.fold_error[k] = refined[j]
        first = results[0]
        self.pieces = (0,) if len(results) == 1 else (0, len(first.p))
        # covered: the first run reached the end, or the second (backward) reached where it stopped
        self.success = first.status == 0 or (len(results) == 2 and results[1].status == 0)
        self.status = int(first.status)
        self.message = "; ".join(f"{'forward' if k == 0 else 'back'}: {r.message}" for k, r in enumerate(results))
        self.runs = int(runs)
        self._orbits = orbits

    def __len__(self) -> int:
        return self.omega.size

    def _fold_frequencies(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:attr:`fold_omega`, :attr:`fold_error`, :attr:`fold_upper`."""
        w = self.omega
        out_w, out_e = np.zeros(len(self.folds)), np.zeros(len(self.folds))
        out_u = np.zeros(len(self.folds), dtype=bool)
        for k, j in enumerate(self.folds):
            win, out_u[k], extreme = fold_window(w, j)
            if w[j] == extreme:  # the located fold is the extreme frequency around it
                out_w[k], out_e[k] = w[j], EXACT_FOLD_RTOL
            else:  # it is not (a kink of the branch next to it): the sampled extreme, and the window's range
                out_w[k], out_e[k] = extreme, float(np.ptp(win)) / abs(extreme)
        return out_w, out_e, out_u

    def orbit(self, i: int) -> FlowRun:
        """The run of point ``i`` over one forcing period (its impacts, switches, displacements):
        the continuation's own (kept), else run again."""
        if self._orbits is not None and self._orbits[i] is not None:
            return self._orbits[i]
        return self.flow.at(self.omega[i]).run(self.states[i], 0.0)

    def amplitude(self, dof, samples: int = 400, points=None) -> np.ndarray:
        """``max_t |q_dof(t)|`` of every orbit (or of ``points``) on ``samples`` points per period
        (those of :meth:`femodes.Branch.amplitude` are on the truncated Fourier series); ``dof``
        a DOF or a list of DOFs (the largest over them)."""
        points = range(len(self)) if points is None else points
        out = []
        for i in points:
            t = np.linspace(0.0, 2.0 * math.pi / self.omega[i], samples)
            out.append(float(np.max(np.abs(self.orbit(i).displacement(t)[:, dof]))))
        return np.asarray(out)

    def coefficients(self, i: int, H: int) -> tuple[np.ndarray, np.ndarray]:
        """Exact Fourier coefficients of point ``i`` to ``H`` harmonics (:meth:`~femodes.time.exact_run.FlowRun.coefficients`)."""
        return self.orbit(i).coefficients(H)


