r"""The exact flow of a linear model with rigid stops: closed form between contact events.

Between contact events a model without smooth nonlinear laws is linear. Its DOFs split into the
inertial ones ``I`` (``M_II`` positive definite) and the massless ones ``Z`` (zero rows of ``M``
and ``C``: a contact node whose mass was redistributed, ``fm.RedistributeMass()``), whose
displacements follow from the others by static condensation. A *mode* is the set ``S`` of
massless contacts that are closed (``q_S = gap``); the others ``O = Z \ S`` are condensed,
``q_O = K_OO^-1 (f_O(t) - K_OI q_I - K_OS gap_S)``. In every mode the inertial state
``x = [q_I; v_I]`` obeys ``x' = A_S x + b_S(t)`` with the condensed stiffness, and with
``A_S = V diag(lambda) V^-1`` (diagonalised once per mode; :meth:`LinearImpactFlow.at` changes the
frequency) and the periodic particular solution ``x_p(t) = Re sum_k X_k e^{i k w t}``,
``(i k w I - A_S) X_k = [0; M_II^-1 F_k^S]``, the flow is

.. math::

    x(t) = x_p(t) + V\,e^{\Lambda (t - t_a)}\,V^{-1}\bigl(x(t_a) - x_p(t_a)\bigr)

from the start ``t_a`` of a segment. Every displacement, velocity and contact force is an affine
function of ``x`` and the forcing, hence of the same closed form. Events:

* a contact on an inertial DOF: the gap ``gap - q_c`` reaches 0 while approaching: an impact
  (Newton's law, impulse along ``M^-1 e_c``, the saltation matrix of :mod:`femodes.time.shooting`);
* an open massless contact: its condensed displacement reaches the gap: it closes;
* a closed massless contact: its contact force ``lambda = f_c(t) - K_c q`` falls to 0: it opens.
  Both sides of a switch have the same vector field (at ``q_c = gap`` the force is 0), so the
  state and the monodromy matrix pass it unchanged (saltation matrix ``I``).

Events are located by a certified search (:mod:`.exact_events`) on a grid of :data:`SAMPLES`
points per shortest period of the flow, refined only where a bound on the modal terms cannot
exclude an event. No step size, no integration error: the orbit is exact to round-off and to the
root tolerance of the event times (4 eps). Restitution below 1 is accepted, but an accumulation of
events (chattering) is refused after :data:`~femodes.time.shooting.MAX_IMPACTS` of them.

A run (:class:`~femodes.time.exact_run.FlowRun`) also gives the Fourier coefficients of the orbit
in closed form (:mod:`.exact_fourier`), which is what :mod:`femodes.accuracy` compares harmonic
balance solutions with.

Used by :mod:`femodes.accuracy` (shooting refinement of error-controlled branches); the general
event-driven integration with smooth laws is :mod:`femodes.time.shooting`.
"""

from __future__ import annotations

import collections
import copy
import dataclasses
import itertools
import logging
import math

import numpy as np
import scipy.linalg as sla

from ..laws import UnilateralContact
from ..model import StructuralModel
from ..solvers import ContinuationOptions, continuation
from .exact_events import CHUNK, REFINE
from .exact_run import FlowRun
from .shooting import unsupported

log = logging.getLogger(__name__)

__all__ = ["LinearImpactFlow", "FlowRun", "exact_flow_unsupported", "periodicity_residual", "SAMPLES", "CHUNK", "REFINE",
           "MAX_MASSLESS_CONTACTS", "ExactBranch", "exact_frequency_response", "EXACT_BRANCH_RTOL",
           "EXACT_FOLD_RTOL", "FOLD_WINDOW", "undamped"]

#: Grid points per shortest period of the flow (fastest eigenvalue or forcing harmonic) on which
#: the events are bracketed, and of the coarse grid per period of the highest forcing harmonic.
SAMPLES = 24
#: Largest condition number of the eigenvector matrix (a nearly defective A, e.g. critical
#: damping, makes the modal flow inaccurate).
MAX_CONDITION = 1e8
#: Largest number of contacts on massless DOFs (their open/closed combinations are the modes).
MAX_MASSLESS_CONTACTS = 8


def exact_flow_unsupported(model: StructuralModel) -> str:
    """Why :class:`LinearImpactFlow` cannot take ``model`` (``""`` if it can): smooth nonlinear
    laws (cubic springs, penalty contacts), no unilateral contact, more than ``MAX_DOFS`` DOFs, a
    massless DOF with damping, or too many massless contacts."""
    if not isinstance(model, StructuralModel):
        return f"model must be a StructuralModel (or ReducedModel), got {type(model).__name__}"
    why = unsupported(model, massless_contacts=True)
    if why:
        return why
    if model.nonlinearities:
        return "the model has smooth nonlinear laws (cubic springs): the flow between impacts is not linear"
    laws = [a.item for a in model.contacts]
    if not laws:
        return "the model has no contact"
    if not all(isinstance(law, UnilateralContact) for law in laws):
        return "the model has penalty contacts: the flow between impacts is not linear"
    Md = model.M.diagonal()
    Z = np.flatnonzero(~(Md > 0.0))
    if Z.size:
        M, C = abs(model.M).tocsr(), abs(model.damping_matrix()).tocsr()
        for d in Z:
            if M[d].sum() > 0.0 or C[d].sum() > 0.0:
                which = "mass" if M[d].sum() > 0.0 else "damping"
                hint = (" (stiffness-proportional damping beta K, or a damping matrix given directly, has a row "
                        "there: use mass-proportional (alpha) or modal damping, or keep the node's mass with "
                        "with_contact(..., contact_mass=fm.ConsistentMass()))" if which == "damping" else "")
                return (f"DOF {model.dofmap.label(int(d))!r} has no mass on the diagonal but {which} coupling it to other "
                        f"DOFs: a massless DOF must have zero rows of M and C (mass-proportional damping){hint}")
        n_massless = sum(1 for a in model.contacts if not Md[a.dof] > 0.0)
        if n_massless > MAX_MASSLESS_CONTACTS:
            return (f"the model has {n_massless} contacts on massless DOFs; the exact flow takes at most "
                    f"{MAX_MASSLESS_CONTACTS} (keep their mass: with_contact(..., contact_mass=fm.ConsistentMass()))")
    return ""


class _Mode:
    """The linear system of the inertial DOFs with the massless contacts ``closed`` closed."""

    def __init__(self, flow: LinearImpactFlow, closed: frozenset):
        n, I, Z = flow.n, flow.I, flow.Z
        K = flow.K
        S = [flow.dofs[j] for j in sorted(closed)]
        O = [d for d in Z if d not in S]
        self.closed, self.S, self.O = closed, np.array(S, dtype=int), np.array(O, dtype=int)
        nI = I.size
        Pq = np.zeros((n, nI))  # q = Pq q_I + (forcing and gap terms)
        Pq[I, np.arange(nI)] = 1.0
        self.Koo = None
        if O:
            try:
                self.Koo = sla.cho_factor(K[np.ix_(O, O)])
            except np.linalg.LinAlgError:
                raise ValueError("LinearImpactFlow: the stiffness of the massless DOFs is not positive definite "
                                 "(a massless DOF without elastic support)") from None
            Pq[O] = -sla.cho_solve(self.Koo, K[np.ix_(O, I)])
        self.Pq = Pq
        Keff = K[I] @ Pq
        A = np.zeros((2 * nI, 2 * nI))
        A[:nI, nI:] = np.eye(nI)
        A[nI:, :nI] = -flow.MinvII @ (0.5 * (Keff + Keff.T))
        A[nI:, nI:] = -flow.MinvII @ flow.CII
        self.A = A
        lam, V = np.linalg.eig(A)
        cond = np.linalg.cond(V)
        if not cond < MAX_CONDITION:
            raise ValueError(f"LinearImpactFlow: the state matrix is nearly defective (eigenvector condition "
                             f"{cond:.3g}, e.g. a critically damped mode); its modal flow is not accurate")
        self.lam, self.V, self.Vinv = lam, V, np.linalg.inv(V)
        self.Lq = np.hstack([Pq, np.zeros((n, nI))])  # q = Lq x + ...
        self.Lv = np.hstack([np.zeros((n, nI)), Pq])  # v = Lv x + ...
        self.Rq = self.Lq @ V
        # event functions: the gap of every contact, or the force of a closed massless one
        Le = np.array([-(K[c] @ self.Lq) if j in closed else -self.Lq[c] for j, c in enumerate(flow.dofs)])
        self.Le = Le.reshape(len(flow.dofs), 2 * nI)
        self.Re = self.Le @ V
        self.fastest = float(np.max(np.abs(lam)))
        self._loads = None

    def loads(self, flow: LinearImpactFlow):
        """The frequency-independent parts of the particular solutions (cached): harmonics ``ks``
        (0 included), the forcing and gap part ``G`` of the displacements, the right-hand sides
        in modal coordinates ``W = (V^-1 b_k)`` and the constant part of the event functions."""
        if self._loads is None:
            nI = flow.I.size
            ks = np.array(sorted(set(flow.k.tolist()) | {0}), dtype=int)
            G, B, E = [], [], []
            for k in ks:
                F = flow.F.get(int(k), np.zeros(flow.n, dtype=complex))
                g = self.gq(flow, int(k), F)
                B.append(np.concatenate([np.zeros(nI), flow.MinvII @ (F[flow.I] - flow.K[flow.I] @ g)]))
                G.append(g)
                E.append([F[c] - flow.K[c] @ g if j in self.closed else -g[c] + (flow.gaps[j] if k == 0 else 0.0)
                          for j, c in enumerate(flow.dofs)])
            self._loads = (ks, np.array(G), np.array(B) @ self.Vinv.T, np.array(E, dtype=complex).reshape(len(ks), -1))
        return self._loads

    def gq(self, flow: LinearImpactFlow, k: int, F: np.ndarray) -> np.ndarray:
        """Forcing and gap part of the displacements for harmonic ``k`` with load ``F``."""
        g = np.zeros(flow.n, dtype=complex)
        if k == 0 and self.S.size:
            g[self.S] = flow.gaps[sorted(self.closed)]
        if self.O.size:
            rhs = F[self.O] - flow.K[np.ix_(self.O, self.S)] @ g[self.S] if self.S.size else F[self.O].copy()
            g[self.O] = sla.cho_solve(self.Koo, rhs)
        return g


class _ModeAt:
    """A mode's particular solution at one forcing frequency: per harmonic ``k`` (0 included)
    the inertial state ``X``, the displacements ``Yq``, velocities ``Yv`` and event functions
    ``Ye`` (complex amplitudes, the gap constant in ``k = 0``; ``G`` the forcing and gap part of
    the displacements, not carried by the inertial state), and the fine grid step.
    ``(i k w I - A) X_k = b_k`` is solved in the mode's eigenbasis (the frequency-independent
    parts are the mode's: :meth:`_Mode.loads`)."""

    def __init__(self, flow: LinearImpactFlow, m: _Mode, omega: float):
        ks, G, W, Ye0 = m.loads(flow)
        iw = 1j * omega * ks
        den = iw[:, None] - m.lam[None, :]
        if np.any(den == 0.0):
            k = int(ks[np.flatnonzero(np.any(den == 0.0, axis=1))[0]])
            raise ValueError(f"LinearImpactFlow: forcing harmonic {k} at omega = {omega:g} is at an undamped "
                             "eigenfrequency (no periodic particular solution)")
        X = (W / den) @ m.V.T  # (n_k, 2nI)
        self.ks, self.X, self.iw, self.G = ks, X, iw, G
        self._W, self._den, self._V = W, den, m.V
        self._dX = None  # dX, when first asked for
        self.Yq = X @ m.Lq.T + G
        self.Yv = X @ m.Lv.T + iw[:, None] * G
        self.Ye = X @ m.Le.T + Ye0
        fastest = max(m.fastest, float(np.max(ks)) * omega)
        self.dt = 2.0 * math.pi / fastest / SAMPLES
        self.coarse = 2.0 * math.pi / (max(1, int(np.max(ks))) * omega) / SAMPLES

    def phases(self, t) -> np.ndarray:
        return np.exp(np.multiply.outer(t, self.iw))

    def particular(self, t) -> np.ndarray:
        return np.real(self.phases(t) @ self.X)

    @property
    def dX(self) -> np.ndarray:
        """``X_k' = d X_k / d w = V (-i k W_k / (i k w - lambda)^2)`` per harmonic (computed once)."""
        if self._dX is None:
            self._dX = (self._W * (-1j * self.ks[:, None]) / self._den ** 2) @ self._V.T
        return self._dX

    def particular_omega(self, t: float) -> np.ndarray:
        """``d x_p(t) / d w`` at a fixed time ``t``: ``Re sum_k (X_k' + i k t X_k) e^{i k w t}``."""
        ph = self.phases(t)
        return np.real(ph @ self.dX + (ph * (1j * self.ks * t)) @ self.X)


class LinearImpactFlow:
    """Closed-form flow of a linear model with rigid stops at forcing frequency ``omega``.

    States are full ``[q; v]`` (``2 n``); the entries of massless DOFs in a start state are not
    used (they follow from the others) and are returned consistent with them."""

    def __init__(self, model: StructuralModel, omega: float, restitution: float = 1.0):
        why = exact_flow_unsupported(model)
        if why:
            raise ValueError(f"LinearImpactFlow: {why}")
        omega = float(omega)
        if not (math.isfinite(omega) and omega > 0.0):
            raise ValueError(f"LinearImpactFlow: omega must be a finite positive frequency, got {omega!r}")
        if not 0.0 <= restitution <= 1.0:
            raise ValueError(f"LinearImpactFlow: restitution must lie in [0, 1], got {restitution!r}")
        n = model.n_dofs
        self.n, self.e = n, float(restitution)
        Md = model.M.diagonal()
        self.Z = np.flatnonzero(~(Md > 0.0))
        self.I = np.flatnonzero(Md > 0.0)
        nI = self.I.size
        M = model.M.toarray()[np.ix_(self.I, self.I)]
        try:
            MinvII = sla.cho_solve(sla.cho_factor(M), np.eye(nI))
        except np.linalg.LinAlgError:
            raise ValueError("LinearImpactFlow: the mass matrix of the DOFs with mass is not positive definite") from None
        self.MinvII = 0.5 * (MinvII + MinvII.T)
        K = model.K.toarray()
        self.K = 0.5 * (K + K.T)
        self.CII = model.damping_matrix().toarray()[np.ix_(self.I, self.I)]
        fv = model.force_vectors()
        self.k = np.array(sorted(fv), dtype=int)
        self.F = {int(k): np.asarray(fv[k], dtype=complex) for k in fv}
        self.contacts = [(j, a.item, a.dof) for j, a in enumerate(model.contacts)]
        self.dofs = np.array([c for _, _, c in self.contacts], dtype=int)
        self.gaps = np.array([law.gap for _, law, _ in self.contacts], dtype=float)
        self.massless = ~(Md[self.dofs] > 0.0)
        pos = np.full(n, -1)
        pos[self.I] = np.arange(nI)
        self.pos = pos  # index of a DOF among the inertial ones
        # the state's inertial entries in a full state [q; v]
        self.state_index = np.concatenate([self.I, n + self.I])
        # impulse along M^-1 e_c (inertial DOFs), scaled so that the contact velocity alone is reversed
        self.impact_dir = np.zeros((len(self.dofs), n))
        for j, c in enumerate(self.dofs):
            if not self.massless[j]:
                col = self.MinvII[:, pos[c]]
                self.impact_dir[j, self.I] = col / col[pos[c]]
        self._modes: dict = {}  # shared by the copies of at()
        self._set_omega(omega)
        self.mode(frozenset())  # the all-open mode: its eigenproblem (and errors) now

    def _set_omega(self, omega: float) -> None:
        self.omega = omega
        self._at: dict = {}

    def mode(self, closed: frozenset) -> tuple[_Mode, _ModeAt]:
        """The mode with the massless contacts ``closed`` closed, at this frequency."""
        m = self._modes.get(closed)
        if m is None:
            m = self._modes[closed] = _Mode(self, closed)
        d = self._at.get(closed)
        if d is None:
            d = self._at[closed] = _ModeAt(self, m, self.omega)
        return m, d

    def at(self, omega: float) -> LinearImpactFlow:
        """The same model at another forcing frequency (the eigenproblems are not solved again)."""
        omega = float(omega)
        if not (math.isfinite(omega) and omega > 0.0):
            raise ValueError(f"LinearImpactFlow.at: omega must be a finite positive frequency, got {omega!r}")
        new = copy.copy(self)
        new._set_omega(omega)
        return new

    # -- pieces -------------------------------------------------------------------------------
    def particular(self, t) -> np.ndarray:
        """The periodic response without contact (all massless contacts open), full states ``[q;
        v]``: shape ``(len(t), 2n)`` (or ``(2n,)`` for a scalar ``t``)."""
        _, d = self.mode(frozenset())
        ph = d.phases(np.asarray(t, dtype=float))
        return np.concatenate([np.real(ph @ d.Yq), np.real(ph @ d.Yv)], axis=-1)

    def free_harmonics(self) -> dict:
        """``{k: complex amplitudes of the contact DOFs' displacements}`` of the response without
        contact (``k = 0`` included)."""
        _, d = self.mode(frozenset())
        return {int(k): d.Yq[i, self.dofs] for i, k in enumerate(d.ks)}

    def admissible(self, x: np.ndarray) -> bool:
        """Whether a start state keeps off the obstacles at its inertial contact DOFs (the others
        are not part of the state)."""
        inertial = ~self.massless
        return bool(np.all(self.gaps[inertial] - x[self.dofs[inertial]] >= 0.0))

    def run(self, x0, t0: float, period: float | None = None, variational: bool = False) -> FlowRun:
        """The orbit from ``x(t0) = x0`` over ``period`` (default one forcing period)."""
        T = 2.0 * math.pi / self.omega if period is None else float(period)
        return FlowRun(self, np.asarray(x0, dtype=float), float(t0), float(t0) + T, variational)

    def start_mode(self, x: np.ndarray, t: float) -> frozenset:
        """The massless contacts closed at the start: the set whose condensed displacements keep
        to the gaps and whose forces are compressive (unique: the condensed stiffness is
        positive definite), by enumeration."""
        js = [j for j in range(len(self.dofs)) if self.massless[j]]
        if not js:
            return frozenset()
        best, best_v = None, -math.inf
        for r in range(len(js) + 1):
            for closed in itertools.combinations(js, r):
                S = frozenset(closed)
                m, d = self.mode(S)
                # gaps of the open, forces of the closed: Ye holds the particular solution's share too
                ev = m.Le @ x + np.real(d.phases(t) @ (d.Ye - d.X @ m.Le.T))
                v = float(np.min(ev[js]))
                if v >= 0.0:
                    return S
                if v > best_v:
                    best, best_v = S, v
        return best  # round-off on a switching surface: the least violated



# ------------------------------------------------------------------------------ the exact branch
#: Relative error stated for a fold of :func:`exact_frequency_response` that is the extreme
#: frequency of its neighbours: its location by the continuation (secant on ``dw/ds``) measured
#: 3.2e-8 and 2.5e-13 against the seed cases' references, below 1e-9 against the shooting
#: refinement on the 2-DOF massless model (tests/test_exact_branch.py).
EXACT_FOLD_RTOL = 1e-6
#: Points on either side of a fold that :attr:`ExactBranch.fold_omega` looks at (and
#: :func:`fold_is_upper`). With a finite-difference ``dr/dw`` the continuation detected the lower
#: fold of the cantilever of ``benchmarks/bench_cantilever_time.py`` at 3.7193289, a point between
#: two of larger frequency on one side and smaller on the other (a kink); the extreme of the 3
#: points on either side was 3.7193164, their range 2.9e-5 relative; local continuations with
#: short steps give 3.719311942. Detected folds are now refined (:func:`_refine_fold`).
FOLD_WINDOW = 3
#: Default Newton tolerance of :func:`exact_frequency_response`, relative to the larger of the
#: largest gap and the start state of the response without contact at the first frequency. On the
#: cantilever of ``benchmarks/bench_cantilever_time.py`` (scale 0.02) the continuation's default
#: 1e-10 was not reached: the corrector stalled at residuals of 4e-9, 2e-7 of the scale (stiff
#: modes: event times to round-off still leave that much in their velocities).
EXACT_BRANCH_RTOL = 1e-6


def fold_is_upper(omega: np.ndarray, j: int) -> bool:
    """Whether the fold at point ``j`` of a branch is a largest frequency: ``omega[j]`` at least
    the mean of the frequencies :data:`FOLD_WINDOW` points before and after it (fewer at the
    ends)."""
    lo, hi = max(j - FOLD_WINDOW, 0), min(j + FOLD_WINDOW, omega.size - 1)
    return bool(omega[j] >= 0.5 * (omega[lo] + omega[hi]))


def _fold_window(omega: np.ndarray, j: int) -> tuple[np.ndarray, bool, float]:
    """The frequencies of fold ``j`` and of the :data:`FOLD_WINDOW` points on either side of it,
    whether it is an upper fold (:func:`fold_is_upper`), and their extreme frequency that way."""
    win = omega[max(j - FOLD_WINDOW, 0):min(j + FOLD_WINDOW + 1, omega.size)]
    upper = fold_is_upper(omega, j)
    return win, upper, float(win.max() if upper else win.min())


class ExactBranch:
    """Periodic orbits of a linear model with rigid stops traced by continuation in the forcing
    frequency (:func:`exact_frequency_response`).

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
        from both sides (:func:`_refine_fold`): the extreme frequency they and the branch reach,
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
            win, out_u[k], extreme = _fold_window(w, j)
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
        """Exact Fourier coefficients of point ``i`` to ``H`` harmonics (:meth:`FlowRun.coefficients`)."""
        return self.orbit(i).coefficients(H)


#: Runs of the continuation's residual kept until it accepts a point (the corrector's last
#: iterate is evaluated last, or nearly: fold location and tangents come between).
RECENT_RUNS = 32


def periodicity_residual(flow: LinearImpactFlow, x: np.ndarray, omega: float, t0: float = 0.0,
                         variational: bool = True):
    """``(r, dr/dx, dr/dw, run)`` of ``r = x(t0 + T) - x``, one forcing period ``T = 2 pi / w`` of
    the exact flow from ``x(t0) = x``: ``dr/dx = Phi - I`` with the monodromy matrix and ``dr/dw``
    the end state's change with ``w`` at the fixed start time (:attr:`FlowRun.x_end_omega`), both
    from the variational run; without ``variational`` the two derivatives are None. The one
    periodicity residual of the exact branch (:class:`_ShootingResidual`, inertial entries) and
    of the shooting refinement of :mod:`femodes.accuracy` (full state, bordered by a hyperplane)."""
    run = flow.at(omega).run(x, t0, variational=variational)
    r = run.x_end - x
    if not variational:
        return r, None, None, run
    return r, run.Phi - np.eye(x.size), run.x_end_omega, run


class _ShootingResidual:
    """``r(x, w) = x(T) - x`` over one forcing period ``T = 2 pi / w`` from ``x(0) = x`` (the
    inertial entries of the state), with ``dr/dx = Phi - I`` and ``dr/dw`` from the variational
    run (:attr:`FlowRun.x_end_omega`). The last :data:`RECENT_RUNS` runs (:meth:`FlowRun.plain`)
    are kept by start state and frequency; :meth:`keep` (the continuation's callback) moves an
    accepted point's into ``orbits``: its orbit and its massless DOFs' entries."""

    def __init__(self, flow: LinearImpactFlow):
        self.flow, self.S = flow, flow.state_index
        self.massless = np.setdiff1d(np.arange(2 * flow.n), flow.state_index)
        self.runs = 0
        self.recent: collections.OrderedDict = collections.OrderedDict()
        self.orbits: dict = {}

    def keep(self, y: np.ndarray, w: float) -> None:
        key = (np.asarray(y, dtype=float).tobytes(), float(w))
        run = self.recent.get(key)
        if run is not None:
            self.orbits[key] = run

    def callback(self, then=None):
        """A continuation callback that keeps every accepted point's run, then calls ``then``."""
        def cb(point):
            self.keep(point.x, point.p)
            return None if then is None else then(point)
        return cb

    def full(self, y: np.ndarray) -> np.ndarray:
        x = np.zeros(2 * self.flow.n)
        x[self.S] = y
        return x

    def residual(self, y: np.ndarray, w: float):
        S = self.S
        x = self.full(y)
        self.runs += 1
        try:
            r, drdx, drdw, run = periodicity_residual(self.flow, x, w)
        except ValueError:
            # an iterate the flow cannot start from (inside an obstacle, w <= 0, an accumulation of
            # events): a non-finite residual, which makes Newton's line search cut the step
            nan = np.full(S.size, np.nan)
            return nan, np.full((S.size, S.size), np.nan), nan
        self.recent[(y.tobytes(), float(w))] = run.plain()
        if len(self.recent) > RECENT_RUNS:
            self.recent.popitem(last=False)
        return r[S], drdx[np.ix_(S, S)], drdw[S]


def undamped(model: StructuralModel, restitution: float = 1.0) -> bool:
    """True when nothing in ``model`` dissipates energy: no damping matrix entry, no modal damping,
    and elastic impacts (``restitution >= 1``); :func:`exact_frequency_response` refuses such a
    model (its forced orbits are unbounded at the resonances)."""
    return not model.has_damping and restitution >= 1.0


def exact_frequency_response(model: StructuralModel, span, *, x0=None, restitution: float = 1.0,
                             options=None) -> ExactBranch:
    """The forced response of a linear model with rigid stops, orbit by exact orbit.

    Pseudo-arclength continuation (:func:`femodes.solvers.continuation`) of the periodic orbits
    of :class:`LinearImpactFlow` in the forcing frequency: the unknowns are the start state at
    ``t = 0`` (the forcing fixes the phase), the residual ``x(T) - x(0)`` with the monodromy
    matrix (saltation at impacts) as its Jacobian. No harmonics and no time step: every point
    is a periodic orbit of the semi-discrete model to round-off, which is what harmonic balance
    converges to as H grows; folds are located as turning points. The orbits need not be
    stable (:func:`femodes.stability` or a time integration says which are).

    Parameters
    ----------
    model : StructuralModel
        Linear, with unilateral contacts (on DOFs with or without mass) and harmonic forcing;
        no smooth nonlinear laws or penalty contacts (:func:`exact_flow_unsupported` says why
        a model is refused).
    span : (float, float)
        Forcing frequencies ``(w_start, w_end)`` in rad/s, positive; may decrease.
    x0 : array_like (2 n_dofs,), optional
        Start state ``[q; v]`` at ``w_start``; default: the response without contact there
        (right when it keeps off the stops, a first guess otherwise).
    restitution : float
        Newton's coefficient of the impacts on DOFs with mass (1: the limit of harmonic balance).
    options : ContinuationOptions, optional
        Default: ``max_points=3000`` and Newton's ``atol`` :data:`EXACT_BRANCH_RTOL` times the
        larger of the largest gap and the size of the start state without contact at
        ``w_start``.

    Returns
    -------
    ExactBranch
        ``success``/``message`` report how the continuation ended; never raises on numerical
        failure.

    Raises
    ------
    TypeError
        ``model`` is not a model, ``options`` not a ContinuationOptions.
    ValueError
        A model the flow cannot take, a bad span or ``x0``.
    """
    owner = "exact_frequency_response"
    if not isinstance(model, StructuralModel):
        raise TypeError(f"{owner}: model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
    try:
        w0, w1 = (float(span[0]), float(span[1]))
    except (TypeError, ValueError, IndexError):
        raise ValueError(f"{owner}: span must be two forcing frequencies (w_start, w_end), got {span!r}") from None
    if len(span) != 2 or not (math.isfinite(w0) and math.isfinite(w1) and w0 > 0.0 and w1 > 0.0) or w0 == w1:
        raise ValueError(f"{owner}: span must be two different finite positive frequencies, got {span!r}")
    if not model.forces:
        raise ValueError(f"{owner}: the model has no harmonic forcing (add one with with_forcing)")
    if undamped(model, restitution):
        raise ValueError(f"{owner}: the model has no damping (C = 0) and restitution = {restitution:g}: nothing "
                         "dissipates, so near a resonance of the impacting structure the forced orbits grow without "
                         "bound and the continuation cannot pass it (an undamped oscillator against a stop ran 3000 "
                         "points to a step-size failure); add damping (model.with_damping(alpha=..., beta=...) or "
                         "modal=...) or use restitution < 1")
    flow = LinearImpactFlow(model, w0, restitution=restitution)
    n2 = 2 * model.n_dofs
    particular = flow.particular(0.0)
    if x0 is None:
        x0 = particular
    else:
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (n2,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"{owner}: x0 must be {n2} finite numbers [q; v], got shape {x0.shape}")
    if options is None:
        scale = max(float(np.linalg.norm(particular[flow.state_index])), float(np.max(np.abs(flow.gaps), initial=0.0)))
        base = ContinuationOptions()
        options = ContinuationOptions(max_points=3000, newton=dataclasses.replace(
            base.newton, atol=EXACT_BRANCH_RTOL * max(scale, 1e-300)))
    elif not isinstance(options, ContinuationOptions):
        raise TypeError(f"{owner}: options must be a ContinuationOptions or None, got {type(options).__name__}")
    problem = _ShootingResidual(flow)
    options = dataclasses.replace(options, callback=problem.callback(options.callback))
    res = continuation(problem, (w0, w1), x0=x0[flow.state_index], options=options)
    pieces = [res]
    if res.status == 4 and len(res.p):
        # the corrector gave up inside the span (a grazing orbit: the flow's derivative jumps
        # there): trace the rest back from the other end, from its response without contact
        w_stop = float(res.p[-1])
        back = continuation(problem, (w1, w_stop), x0=flow.at(w1).particular(0.0)[flow.state_index], options=options)
        log.info("%s: stopped at w = %.6g (%s); traced back from w = %.6g to %.6g (%s)", owner, w_stop, res.message,
                 w1, float(back.p[-1]) if len(back.p) else w1, back.message)
        if len(back.p):
            pieces.append(back)
    def joined(arrays):  # the pieces' arrays in the branch's order: the back piece reversed
        return np.concatenate([np.asarray(a, dtype=float)[::1 if k == 0 else -1] for k, a in enumerate(arrays)])

    omega = joined([r.p for r in pieces])
    ys = joined([np.reshape(r.x, (len(r.p), flow.state_index.size)) for r in pieces])
    steps = joined([r.step for r in pieces])
    folds, located = list(res.folds), set(res.located)
    if len(pieces) == 2:  # the back piece's index i is the branch's omega.size - 1 - i
        folds += [omega.size - 1 - int(i) for i in sorted(pieces[1].folds, reverse=True)]
        located |= {omega.size - 1 - int(i) for i in pieces[1].located}
    # the refinement steps in the first run's arclength norm (scales), comparable with its steps
    scaled = dataclasses.replace(options, x_scale=np.asarray(res.x_scale), p_scale=float(res.p_scale))
    refined = {j: got for j in folds if j not in located
               and (got := _refine_fold(problem, omega, ys, steps, j, scaled)) is not None}
    # the points' orbits: the continuation's runs from them (one more run where its last step was
    # not evaluated), and from those the massless DOFs' entries (consistent with the inertial
    # ones, which are the continuation's own: periodic to its Newton tolerance)
    states = np.zeros((omega.size, n2))
    orbits = []
    for i, (y, w) in enumerate(zip(ys, omega)):
        states[i] = problem.full(y)
        run = problem.orbits.get((y.tobytes(), float(w)))
        if run is None:
            problem.runs += 1
            run = flow.at(w).run(states[i], 0.0)
        orbits.append(run)
        states[i, problem.massless] = run.x_end[problem.massless]
    problem.orbits.clear()
    problem.recent.clear()
    return ExactBranch(flow, omega, states, pieces, folds, problem.runs, options.newton.atol, refined, orbits)


#: Points of :func:`_refine_fold`'s continuations toward a fold, from either side.
REFINE_FOLD_POINTS = 60


def _refine_fold(problem: _ShootingResidual, omega: np.ndarray, ys: np.ndarray, steps: np.ndarray, j: int,
                 options: ContinuationOptions) -> tuple[float, float] | None:
    """A fold ``j`` the continuation detected but did not locate: where the corrector fails at
    the turn (a grazing there), the branch jumped across it. Continuations with a quarter of the
    steps into and out of ``j`` (:data:`REFINE_FOLD_POINTS` points at most) from the points two before and two
    after ``j`` toward it, beyond it in frequency, in the first run's arclength scales: ``(the
    extreme frequency of theirs and the branch's points, the larger distance of either side's
    extreme from it relative to it (at least EXACT_FOLD_RTOL))``, or None if a side gets no
    point (the sampled window then stands). On the cantilever of ``benchmarks/bench_cantilever_time.py``
    (3 % modal damping) the lower fold was detected at 3.7193283 before the continuation located
    sharp folds (``_FOLD_SHARP_ITER``); the two sides reached 3.71931195 and 3.7193120 (233 runs),
    4.4e-6 lower, where the fold search of :mod:`femodes.accuracy` puts it (3.7193120 +- 2.3e-7).
    Seed case 2's lower fold, a grazing where the corrector fails, is still refined so."""
    upper, extreme = _fold_window(omega, j)[1:]
    lo, hi = max(j - 2, 0), min(j + 2, omega.size - 1)
    if lo == j or hi == j:
        return None
    step = max(0.25 * float(np.max(steps[j - 1:j + 2])), options.min_step)  # the steps into and out of j
    opt = dataclasses.replace(options, step=step, max_step=step, max_points=REFINE_FOLD_POINTS, callback=None)
    ext = []
    for k in (lo, hi):
        reach = 10.0 * abs(omega[k] - omega[j]) + EXACT_FOLD_RTOL * abs(omega[j])
        end = omega[k] + reach if upper else omega[k] - reach
        r = continuation(problem, (float(omega[k]), float(end)), x0=ys[k], options=opt)
        if len(r.p) < 2:
            return None
        p = np.asarray(r.p, dtype=float)
        ext.append(float(p.max() if upper else p.min()))
    # the branch's own points bound the fold too: the extreme of all, and how far each side fell short
    best = max(ext + [extreme]) if upper else min(ext + [extreme])
    log.info("exact branch: fold %d detected at w = %.8g, refined from both sides to %.8g and %.8g", j, omega[j], *ext)
    return best, max(max(abs(best - e) for e in ext) / abs(best), EXACT_FOLD_RTOL)
