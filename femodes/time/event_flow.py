r"""The event-driven flow of shooting: the state equations with their variations, integrated by DOP853 from event to event.

:class:`Flow` holds the model as a first-order system ``x = [q; v]`` (inverse mass, forcing,
smooth laws, impact directions); :class:`Run` integrates it, with or without the variational
equations, from one event to the next and applies each event's jump; :func:`unsupported` says
which models it cannot take. :mod:`femodes.time.shooting` builds the monodromy matrix and the
periodic orbits on it.

Events (``solve_ivp`` terminal events; the integration stops at each one and restarts after it):

* *Impact* at a :class:`~femodes.laws.UnilateralContact` (rigid stop): the gap
  ``g_N = gap - q_c`` reaches 0 from above. Newton's impact law reverses the contact velocity,
  ``v_c^+ = -e v_c^-``, by an impulse along ``M^{-1} e_c`` (the generalised Newton law; for a
  mass matrix whose row ``c`` is diagonal this changes ``v_c`` alone):

  .. math::

      v^+ = v^- - (1 + e)\,\frac{e_c^T v^-}{e_c^T M^{-1} e_c}\,M^{-1} e_c ,

  and the variations jump by the saltation matrix (Mueller 1995; Leine & Nijmeijer 2004, who
  also use it for the shooting of non-smooth periodic orbits)

  .. math::

      S = R + \frac{(f^+ - R f^-)\, n^T}{n^T f^-}, \qquad R = \frac{\partial x^+}{\partial x^-},
      \quad n = \nabla_x g_N ,

  with ``f^-``, ``f^+`` the vector field just before and after the impact.
* *Kink* of a :class:`~femodes.laws.PenaltyContact` (``q_c`` crosses ``gap``): the vector field
  is continuous there (saltation matrix the identity) but its derivative jumps; stopping at the
  kink keeps DOP853's error estimate honest (it assumes a smooth right-hand side within a step).

Refused with a ``ValueError`` pointing to Hill's method (``fm.stability_methods.Hill()``): a
unilateral contact on a DOF without mass (mass redistribution; the impact law needs a mass to
act on), a singular mass matrix, and, with ``restitution < 1``, accumulating impacts (chattering:
more than :data:`MAX_IMPACTS` impacts in one run, or an impact slower than
:data:`GRAZING_VELOCITY` times the velocity scale) or sticking (a contact with zero velocity
pushed into the obstacle). With ``restitution = 1`` a near-grazing impact is only logged: the
saltation matrix, and hence the multipliers, grow like ``1 / v_c`` there (grazing bifurcation).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import scipy.linalg as sla
from scipy.integrate import solve_ivp

from ..laws import PenaltyContact, UnilateralContact
from ..model import StructuralModel
from ..solvers.checks import InputTypeError, InputValueError, entry_name

__all__ = ["Flow", "Run", "TrialFailure", "split_state", "v_index", "unsupported", "MAX_IMPACTS", "GRAZING_VELOCITY",
           "MAX_DOFS"]

log = logging.getLogger(__name__)

#: More impacts than this in one run (one period) is taken as an accumulation of impacts
#: (chattering), which an event-driven integration cannot follow.
MAX_IMPACTS = 1000
#: An impact slower than this fraction of the velocity scale is grazing (restitution 1: logged)
#: or the end of an accumulation of impacts (restitution < 1: refused).
GRAZING_VELOCITY = 1e-9
#: Largest model for the dense variational equations ((2n)^2 of them; reduce larger models with
#: fm.craig_bampton first).
MAX_DOFS = 500
#: Bound on penalty-contact kinks per run (a hang guard: each kink restarts the integrator).
_MAX_KINKS = 100_000

#: How the refusals of event-driven integration point to the alternative.
_HILL = 'use Hill\'s method on the harmonic balance Jacobian instead: fm.stability(solution, fm.stability_methods.Hill())'


class TrialFailure(ValueError):
    """A state the flow cannot start from or follow (penetration, chattering, integration failure);
    :func:`shoot` treats it as a rejected trial step, everyone else sees an ``InputValueError`` named
    by the public function that ran the flow."""


# --------------------------------------------------------------------------------------------
# The state layout, in one place
# --------------------------------------------------------------------------------------------
def split_state(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(q, v)`` views of a state ``x = [q; v]``."""
    n = x.shape[0] // 2
    return x[:n], x[n:]


def v_index(n: int, dof: int) -> int:
    """Position of ``v[dof]`` in ``x = [q; v]``."""
    return n + dof


# --------------------------------------------------------------------------------------------
# The event-driven flow
# --------------------------------------------------------------------------------------------
def unsupported(model: StructuralModel, massless_contacts: bool = False) -> str:
    """Why the event-driven shooting cannot take ``model`` (``""`` if it can): more than
    :data:`MAX_DOFS` DOFs, or a UnilateralContact on a DOF without mass (unless
    ``massless_contacts``: the closed-form flow of :mod:`femodes.time.exact` condenses such a DOF).
    The one place these limits are checked (``fm.stability_methods.Auto()`` asks before choosing
    the method)."""
    n = model.n_dofs
    if n > MAX_DOFS:
        return (f"model has {n} DOFs; the dense variational equations ((2n)^2 = {4 * n * n} unknowns) are "
                f"limited to {MAX_DOFS} DOFs: reduce the model first (fm.craig_bampton) or {_HILL}")
    Md = model.M.diagonal()
    assert model.dofmap is not None  # check_fields fills it on construction
    for j, a in enumerate(model.contacts):
        if not massless_contacts and isinstance(a.item, UnilateralContact) and not Md[a.dof] > 0.0:
            return (f"model: UnilateralContact {j} (at={a.item.at!r}) acts on DOF {model.dofmap.label(a.dof)!r}, "
                    "which has no mass (mass redistributed away from the contact, e.g. fm.RedistributeMass()); an "
                    f"event-driven impact law needs a mass at the contact DOF: {_HILL}, or keep the mass with "
                    "with_contact(..., contact_mass=fm.ConsistentMass())")
    return ""


class Flow:
    """Vector field, Jacobian, events and resets of a model (dense matrices; see module docstring)."""

    def __init__(self, model: Any, omega: float, restitution: float, rtol: float, atol: float):
        if not isinstance(model, StructuralModel):
            raise InputTypeError(f"model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
        n = model.n_dofs
        why = unsupported(model)
        if why:
            raise InputValueError(f"{why}")
        self.n = n
        self.omega, self.e, self.rtol, self.atol = omega, restitution, rtol, atol
        M = model.M.toarray()
        self._contacts(model, M)
        self._inverse_mass(model, M)
        self._forcing(model)
        self._smooth_laws(model)
        self._impact_directions(M)

    def _contacts(self, model, M: np.ndarray) -> None:
        """Unilateral contacts (on DOFs with mass) and penalty contacts."""
        self.unilateral: list[tuple[int, UnilateralContact, int]] = []
        self.penalty: list[tuple[int, PenaltyContact, int]] = []
        for j, a in enumerate(model.contacts):
            if isinstance(a.item, UnilateralContact):  # on a DOF with mass: unsupported() checked it
                self.unilateral.append((j, a.item, a.dof))
            elif isinstance(a.item, PenaltyContact):
                self.penalty.append((j, a.item, a.dof))
            else:
                raise InputTypeError(f"model: contact law {type(a.item).__name__} is not known to the shooting")

    def _inverse_mass(self, model, M: np.ndarray) -> None:
        """``M^-1``, ``M^-1 K``, ``M^-1 C`` (dense); M must be definite."""
        # Mass matrix: symmetric positive semidefinite by construction of the model; the state
        # equations need it definite. The eigenvalue test also catches near-singular M.
        lam = np.linalg.eigvalsh(M)
        if lam[0] <= 1e-12 * lam[-1]:
            massless = [model.dofmap.label(i) for i in np.flatnonzero(np.diag(M) <= 0.0)[:5]]
            raise InputValueError(
                f"model: M is singular (smallest eigenvalue {lam[0]:.3g}, largest {lam[-1]:.3g}"
                + (f"; massless DOFs {massless}" if massless else "")
                + f"), so the state equations M v' = ... cannot be integrated explicitly: {_HILL}"
            )
        chol = sla.cho_factor(M)
        Minv = sla.cho_solve(chol, np.eye(self.n))
        self.Minv = 0.5 * (Minv + Minv.T)
        self.MinvK = self.Minv @ model.K.toarray()
        self.MinvC = self.Minv @ model.damping_matrix().toarray()  # with a modal damping part (dense here)

    def _forcing(self, model) -> None:
        """Forcing ``Re sum_k (M^-1 F_k) e^{i k w t}``."""
        fv = model.force_vectors()
        self.harmonics = np.array(sorted(fv), dtype=float)
        self.MinvF = np.array([self.Minv @ fv[k] for k in sorted(fv)]).reshape(len(fv), self.n)

    def _smooth_laws(self, model) -> None:
        """Smooth laws (cubic springs, penalty contacts), stacked per class: their force() gives
        value and derivative at once."""
        groups: dict[Any, list] = {}  # law class (with its stack()) -> attachments
        for a in list(model.nonlinearities) + [model.contacts[j] for j, _, _ in self.penalty]:
            if not callable(getattr(a.item, "force", None)) or not hasattr(type(a.item), "stack"):
                raise InputTypeError(
                    f"model: law {type(a.item).__name__} has no force(); the shooting cannot use it"
                )
            groups.setdefault(type(a.item), []).append(a)
        self.smooth = [(cls.stack([a.item for a in atts]), np.array([a.dof for a in atts], dtype=int))
                       for cls, atts in groups.items()]
        self.nl_dofs = (np.concatenate([d for _, d in self.smooth]) if self.smooth else np.zeros(0, dtype=int))
        self.Minv_nl = self.Minv[:, self.nl_dofs]

    def _impact_directions(self, M: np.ndarray) -> None:
        """Impact directions ``w_c = M^-1 e_c / (e_c.M^-1 e_c)``: exactly ``e_c`` when row ``c`` of
        M is diagonal, where the generalised law reduces to ``v_c+ = -e v_c-`` on the contact DOF."""
        self.impact_dir = {}
        for j, _, c in self.unilateral:
            row = M[c].copy()
            row[c] = 0.0
            if not np.any(row):
                w = np.zeros(self.n)
                w[c] = 1.0
            else:
                w = self.Minv[:, c] / self.Minv[c, c]
            self.impact_dir[j] = w

    # -- vector field ---------------------------------------------------------------------------
    def _nonlinear(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forces of the smooth laws and their derivatives, one entry per law (order of nl_dofs)."""
        if not self.smooth:
            return np.zeros(0), np.zeros(0)
        parts = [law.force(q[dofs]) for law, dofs in self.smooth]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def _acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``M^-1 (f(t) - C v - K q - f_nl(q))`` and the derivatives of the smooth laws' forces."""
        acc = -self.MinvK @ q - self.MinvC @ v
        if self.harmonics.size:
            acc += np.real(np.exp(1j * self.harmonics * self.omega * t) @ self.MinvF)
        f, df = self._nonlinear(q)
        if f.size:
            acc -= self.Minv_nl @ f
        return acc, df

    def field(self, t: float, x: np.ndarray) -> np.ndarray:
        q, v = split_state(x)
        return np.concatenate([v, self._acceleration(t, q, v)[0]])

    def field_variational(self, t: float, y: np.ndarray) -> np.ndarray:
        """``[f(t, x); vec(A(t, x) Phi)]`` with ``A = df/dx = [[0, I], [-M^-1 (K + K_nl(q)), -M^-1 C]]``."""
        n, n2 = self.n, 2 * self.n
        q, v, Phi = y[:n], y[n:n2], y[n2:].reshape(n2, n2)
        acc, df = self._acceleration(t, q, v)
        Pq, Pv = Phi[:n], Phi[n:]
        dPv = -self.MinvK @ Pq - self.MinvC @ Pv
        if df.size:
            dPv -= self.Minv_nl @ (df[:, None] * Pq[self.nl_dofs])
        return np.concatenate([v, acc, Pv.ravel(), dPv.ravel()])

    # -- impacts ----------------------------------------------------------------------------------
    def reset_matrix(self, j: int, c: int) -> np.ndarray:
        """``R = dx+/dx-`` of the impact at contact ``j`` (DOF ``c``); the reset is linear, ``x+ = R x-``."""
        n = self.n
        R = np.eye(2 * n)
        R[n:, v_index(n, c)] -= (1.0 + self.e) * self.impact_dir[j]
        return R

    def velocity_scale(self, x0: np.ndarray) -> float:
        q, v = split_state(x0)
        gaps = [abs(law.gap) for _, law, _ in self.unilateral]
        return max(float(np.max(np.abs(v))), self.omega * max([float(np.max(np.abs(q)))] + gaps), 1e-300)


class Run:
    """One event-driven integration from ``t0`` to ``t1`` (state, optionally with variations)."""

    def __init__(self, flow: Flow, x0: np.ndarray, t0: float, t1: float, variational: bool, dense: bool = False):
        self.flow, self.t0, self.t1 = flow, t0, t1
        self.variational, self.dense = variational, dense
        self.n2 = 2 * flow.n
        self.x0 = x0
        self.vscale = flow.velocity_scale(x0)
        self.impacts: list[tuple[float, int]] = []
        self.kinks: list[tuple[float, int]] = []
        self.segments: list = []
        self.active: dict[int, bool] = {}  # penalty contacts: spring acting (q_c > gap)
        self.Phi = np.eye(self.n2)

    def _gap(self, x: np.ndarray, law: UnilateralContact | PenaltyContact, c: int) -> float:
        return float(law.gap_function(x[c]))

    def _impact(self, t: float, x: np.ndarray, j: int, law: UnilateralContact, c: int) -> np.ndarray:
        flow, n = self.flow, self.flow.n
        vc = x[v_index(n, c)]
        name = entry_name()
        if vc <= 0.0:
            # a root of the gap without approach (tangency at rest, or round-off of a restart on
            # the stop): nothing to reverse
            log.debug("%s: contact %d touches at t = %.9g without approaching (v_c = %.3g)", name, j, t, vc)
            return x
        self.impacts.append((t, j))
        if len(self.impacts) > MAX_IMPACTS:
            raise TrialFailure(
                f"more than {MAX_IMPACTS} impacts in one run (t = {self.t0:.6g} .. {t:.6g}): "
                f"an accumulation of impacts (chattering) that event-driven integration cannot follow; {_HILL}"
            )
        if vc <= GRAZING_VELOCITY * self.vscale:
            if flow.e < 1.0:
                raise TrialFailure(
                    f"restitution={flow.e!r}: impact at contact {j} at t = {t:.9g} with velocity {vc:.3g} "
                    f"(below {GRAZING_VELOCITY:g} times the velocity scale {self.vscale:.3g}): impacts accumulate "
                    f"(chattering, then sticking), which event-driven integration cannot follow; {_HILL}"
                )
            log.warning("%s: grazing impact at contact %d at t = %.9g (velocity %.3g, scale %.3g): the saltation "
                        "matrix grows like 1/velocity, multipliers are unreliable near grazing", name, j, t, vc,
                        self.vscale)
        R = flow.reset_matrix(j, c)
        f_minus = flow.field(t, x)
        x_plus = R @ x
        f_plus = flow.field(t, x_plus)
        if flow.e < 1.0 and x_plus[v_index(n, c)] >= -GRAZING_VELOCITY * self.vscale and f_plus[v_index(n, c)] > 0:
            raise TrialFailure(
                f"restitution={flow.e!r}: contact {j} comes to rest on the obstacle after the impact at "
                f"t = {t:.9g} (rebound velocity {-x_plus[v_index(n, c)]:.3g}, below {GRAZING_VELOCITY:g} times the "
                f"velocity scale {self.vscale:.3g}, and the forces push it in): impacts accumulate (chattering) into "
                f"sticking, which event-driven integration cannot follow; {_HILL}"
            )
        if self.variational:
            # saltation matrix (Mueller 1995; Leine & Nijmeijer 2004); n = grad_x g_N:
            # g_N = gap - q_c (laws.py), so n = -e_c on the displacement block
            nvec = np.zeros(self.n2)
            nvec[c] = -1.0
            S = R + np.outer(f_plus - R @ f_minus, nvec) / (nvec @ f_minus)
            self.Phi = S @ self.Phi
        return x_plus

    def _touch_tol(self, x: np.ndarray, law) -> float:
        """Distance from a kink or stop counted as touching it (round-off of the event location)."""
        return 1e-9 * max(float(np.max(np.abs(split_state(x)[0]))), abs(law.gap), 1e-300)

    def _check_start(self, x: np.ndarray) -> None:
        for j, law, c in self.flow.unilateral:
            g = self._gap(x, law, c)
            if g < -self._touch_tol(x, law):
                raise TrialFailure(
                    f"x0 starts inside the obstacle of contact {j}: gap g_N = {g:.6g} < 0 "
                    f"(q[{c}] = {x[c]:.9g}, gap {law.gap:.9g})"
                )

    def _restart(self, t: float, x: np.ndarray) -> tuple[np.ndarray, list]:
        """Impacts of contacts touching and approaching at ``t``, then the events of the next segment.

        A contact touching its stop or kink at the restart (it has just impacted or crossed, or
        starts there) has a root of its event function at the start: an event function that is
        0 there would be found again when the next step brackets a second crossing (a short
        flight inside one step). Its event function is then divided by ``t - t_s``, which keeps
        the sign of the gap for ``t > t_s`` and tends to the gap rate at ``t_s``.
        """
        n = self.flow.n
        events: list[tuple] = []
        for j, law, c in self.flow.unilateral:
            touching = self._gap(x, law, c) <= self._touch_tol(x, law)
            if touching and x[v_index(n, c)] > 0.0:
                x = self._impact(t, x, j, law, c)
            # gap rate dg_N/dt = -v_c (g_N = gap - q_c, laws.py)
            events.append(("impact", j, law, c, self._event(law, c, t, -x[v_index(n, c)], touching, sign=1.0)))
            events[-1][-1].direction = -1  # the gap closes
        for j, spring, c in self.flow.penalty:
            pen = -self._gap(x, spring, c)  # penetration q_c - gap: > 0 where the spring acts
            touching = abs(pen) <= self._touch_tol(x, spring)
            vc = x[v_index(n, c)]
            if not touching:
                self.active[j] = pen > 0
            elif vc != 0.0:
                self.active[j] = vc > 0
            kink = self._event(spring, c, t, vc, touching, sign=-1.0)
            kink.direction = -1 if self.active[j] else 1  # leaving the current side
            events.append(("kink", j, spring, c, kink))
        return x, events

    @staticmethod
    def _event(law, c: int, ts: float, rate: float, touching: bool, sign: float):
        """Terminal event ``sign * g_N(q_c)`` (divided by ``t - ts`` when touching at ``ts``)."""
        if touching:
            def event(t, y):
                return sign * float(law.gap_function(y[c])) / (t - ts) if t > ts else rate
        else:
            def event(t, y):
                return sign * float(law.gap_function(y[c]))
        event.terminal = True  # type: ignore[attr-defined]  # solve_ivp reads a terminal attribute set on the function
        return event

    def run(self) -> tuple[np.ndarray, list]:
        flow, n2 = self.flow, self.n2
        x = self.x0.copy()
        self._check_start(x)
        t = self.t0
        span = self.t1 - self.t0
        fun = flow.field_variational if self.variational else flow.field
        while True:
            x, events = self._restart(t, x)
            if self.t1 - t <= 1e-13 * span:
                break
            y = np.concatenate([x, self.Phi.ravel()]) if self.variational else x
            sol = solve_ivp(fun, (t, self.t1), y, method="DOP853", events=[e[-1] for e in events] or None,
                            rtol=flow.rtol, atol=flow.atol, dense_output=self.dense)
            if sol.status == -1:
                raise TrialFailure(f"the integration failed at t = {sol.t[-1]:.9g}: {sol.message}")
            if self.dense:
                self.segments.append(sol)
            y = sol.y[:, -1]
            x = y[:n2].copy()
            if self.variational:
                self.Phi = y[n2:].reshape(n2, n2).copy()
            if not np.all(np.isfinite(y)):
                raise TrialFailure(f"the state became non-finite at t = {sol.t[-1]:.9g}")
            t = float(sol.t[-1])
            if sol.status == 0:
                break
            hit = [k for k, te in enumerate(sol.t_events) if te.size and te[-1] == sol.t[-1]]
            kind, j, law, c, _ = events[hit[0]]
            if kind == "impact":
                x = self._impact(t, x, j, law, c)
            else:
                self.kinks.append((t, j))  # saltation matrix = identity: nothing to do
                self.active[j] = not self.active[j]
                if len(self.kinks) > _MAX_KINKS:
                    raise TrialFailure(f"more than {_MAX_KINKS} penalty-contact kinks in one run")
        return x, self.segments

