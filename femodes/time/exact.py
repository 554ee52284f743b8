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
in closed form (:mod:`.exact_fourier`). Used by :mod:`femodes.accuracy` (shooting refinement of
error-controlled branches) and :func:`femodes.exact_frequency_response` (the exact branch); the
general event-driven integration with smooth laws is :mod:`femodes.time.shooting`.
"""

from __future__ import annotations

import copy
import importlib
import itertools
import math
import warnings

import numpy as np
import scipy.linalg as sla

from ..laws import UnilateralContact
from ..model import StructuralModel
from .exact_events import CHUNK, REFINE
from .exact_run import FlowRun
from .shooting import unsupported

__all__ = ["LinearImpactFlow", "FlowRun", "exact_flow_unsupported", "periodicity_residual", "undamped", "SAMPLES",
           "CHUNK", "REFINE", "MAX_MASSLESS_CONTACTS"]

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
                assert model.dofmap is not None  # check_fields fills it on construction
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
        self._loads: tuple | None = None

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
        self._dX: np.ndarray | None = None  # dX, when first asked for
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
        dX = self._dX
        if dX is None:
            dX = self._dX = (self._W * (-1j * self.ks[:, None]) / self._den ** 2) @ self._V.T
        return dX

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

    def start_mode(self, x: np.ndarray, t: float) -> frozenset | None:
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


def periodicity_residual(flow: LinearImpactFlow, x: np.ndarray, omega: float, t0: float = 0.0,
                         variational: bool = True):
    """``(r, dr/dx, dr/dw, run)`` of ``r = x(t0 + T) - x``, one forcing period ``T = 2 pi / w`` of
    the exact flow from ``x(t0) = x``: ``dr/dx = Phi - I`` with the monodromy matrix and ``dr/dw``
    the end state's change with ``w`` at the fixed start time (:attr:`FlowRun.x_end_omega`), both
    from the variational run; without ``variational`` the two derivatives are None. The one
    periodicity residual of the exact branch (:func:`femodes.exact_frequency_response`, inertial entries) and
    of the shooting refinement of :mod:`femodes.accuracy` (full state, bordered by a hyperplane)."""
    run = flow.at(omega).run(x, t0, variational=variational)
    r = run.x_end - x
    if not variational:
        return r, None, None, run
    assert run.Phi is not None  # a variational run has it
    return r, run.Phi - np.eye(x.size), run.x_end_omega, run


def undamped(model: StructuralModel, restitution: float = 1.0) -> bool:
    """True when nothing in ``model`` dissipates energy: no damping matrix entry, no modal damping,
    and elastic impacts (``restitution >= 1``); :func:`femodes.exact_frequency_response` refuses such a
    model (its forced orbits are unbounded at the resonances)."""
    return not model.damping.nonzero and restitution >= 1.0


# ------------------------------------------------------------------ names that moved up (issue 39)
#: The exact branch is an analysis (layer 5) with its own result type (layer 4): these names live
#: in :mod:`femodes.exact_response` and :mod:`femodes.exact_branch` now. The old paths
#: (``femodes.time.exact.X``, ``femodes.time.X``) still work for one release, with a
#: DeprecationWarning; the discretise layer does not import them (the layers' arrows point down).
MOVED = {
    "exact_frequency_response": "femodes.exact_response",
    "EXACT_BRANCH_RTOL": "femodes.exact_response",
    "RECENT_RUNS": "femodes.exact_response",
    "REFINE_FOLD_POINTS": "femodes.exact_response",
    "ExactBranch": "femodes.exact_branch",
    "EXACT_FOLD_RTOL": "femodes.exact_branch",
    "FOLD_WINDOW": "femodes.exact_branch",
    "fold_is_upper": "femodes.exact_branch",
}


def moved(old: str, name: str):
    """The object ``name`` that moved from module ``old`` to its :data:`MOVED` place, with a
    DeprecationWarning that names the new import."""
    new = MOVED[name]
    public = f"femodes.{name}" if name in ("exact_frequency_response", "ExactBranch") else f"{new}.{name}"
    warnings.warn(f"{old}.{name} moved to {public} (the exact branch is an analysis, no longer part of the time "
                  f"integration); import it from there: the old path is deprecated and will be removed",
                  DeprecationWarning, stacklevel=3)
    return getattr(importlib.import_module(new), name)


def __getattr__(name: str):
    if name in MOVED:
        return moved(__name__, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

