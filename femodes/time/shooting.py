r"""Shooting and monodromy: Floquet multipliers of periodic orbits in the time domain.

.. math::

    \dot x = f(t, x) = \begin{bmatrix} v \\ M^{-1}\big(f(t) - C v - K q - f_{nl}(q)\big)
    \end{bmatrix}, \qquad x = \begin{bmatrix} q \\ v \end{bmatrix}, \qquad
    \dot\Phi = \frac{\partial f}{\partial x}\,\Phi, \quad \Phi(t_0) = I,

integrated together (``2n + (2n)^2`` equations) by ``scipy.integrate.solve_ivp`` (DOP853, an
explicit Runge-Kutta of order 8 with dense output of order 7; Hairer, Norsett & Wanner 1993,
section II.10) from ``t0`` to ``t0 + T``. ``f_nl`` gathers the smooth laws of the model, cubic
springs and penalty contacts, each evaluated by its own vectorised ``force`` (value and
derivative, :mod:`femodes.laws`). The monodromy matrix is ``Phi(t0 + T)`` and its eigenvalues
are the Floquet multipliers: the orbit is asymptotically stable when all lie inside the unit
circle (the trivial multiplier 1 of an autonomous orbit aside).

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
  is continuous there, so the saltation matrix is the identity (``f^+ = f^-`` and ``R = I`` in
  the formula above), but its derivative jumps; stopping at the kink keeps
  DOP853's error estimate honest (it assumes a smooth right-hand side within a step).

What event-driven integration cannot do, and is refused with a ``ValueError`` that points to
Hill's method on the harmonic balance Jacobian (``fm.stability(solution, method="hill")``): a
unilateral contact on a DOF without mass (mass redistribution; the impact law needs a mass to
act on), a singular mass matrix, and, with ``restitution < 1``, accumulating impacts (chattering:
more than :data:`MAX_IMPACTS` impacts in one run, or an impact slower than
:data:`GRAZING_VELOCITY` times the velocity scale) or sticking (a contact with zero velocity
pushed into the obstacle). With ``restitution = 1`` a near-grazing impact is only logged: the
saltation matrix, and hence the multipliers, grow like ``1 / v_c`` there (grazing bifurcation).

This module imports the models and laws, never :mod:`femodes.hbm`: the time-domain multipliers
are the independent reference for Hill's method.
"""

from __future__ import annotations

import logging
import functools
import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
from scipy.integrate import solve_ivp

from ..laws import PenaltyContact, UnilateralContact
from ..model import StructuralModel
from ..solvers import NewtonOptions, semismooth_newton
from ..solvers.checks import check_finite, check_in_range, check_int, check_positive, show
from .stepper import solve_or_lstsq

__all__ = ["Monodromy", "ShootingResult", "monodromy", "shoot", "trajectory", "MAX_IMPACTS", "GRAZING_VELOCITY",
           "MAX_DOFS", "STATUS", "unsupported"]

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
#: Step halvings of the line search of :func:`shoot` (smallest step 2^-12).
_MAX_HALVINGS = 12

_HILL = 'use Hill\'s method on the harmonic balance Jacobian instead: fm.stability(solution, method="hill")'

STATUS = {
    0: "success: periodic orbit found to tolerance",
    1: "max_iter Newton iterations reached",
    2: "the damped Newton step could not reduce the residual",
    3: "singular Newton matrix (a multiplier at +1: fold or free-orbit family) and no reducing step",
}


class _TrialFailure(ValueError):
    """A state the flow cannot start from or follow (penetration, chattering, integration failure);
    :func:`shoot` treats it as a rejected trial step, everyone else sees a ValueError."""


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------
def _sorted_multipliers(matrix: np.ndarray) -> np.ndarray:
    """Eigenvalues by decreasing modulus (ties: larger imaginary part first, for a stable order)."""
    mu = np.linalg.eigvals(matrix)
    return mu[np.lexsort((-mu.imag, -np.abs(mu)))]


@dataclass(frozen=True, eq=False)
class Monodromy:
    """Flow over one period and its derivative (:func:`monodromy`).

    Attributes
    ----------
    matrix : ndarray (2 n_dofs, 2 n_dofs)
        Monodromy matrix ``d x(t0 + T) / d x(t0)`` of the state ``x = [q; v]`` (saltation
        matrices included).
    state_end : ndarray (2 n_dofs,)
        ``x(t0 + T)``.
    impacts : list of (float, int)
        ``(time, contact index)`` of every impact (index into ``model.contacts``).
    multipliers : ndarray (2 n_dofs,), complex
        Eigenvalues of ``matrix``, largest modulus first.
    kinks : list of (float, int)
        ``(time, contact index)`` where a penalty contact opened or closed.
    period : float
        ``T``.
    """

    matrix: np.ndarray
    state_end: np.ndarray
    impacts: list
    multipliers: np.ndarray
    kinks: list = field(default_factory=list)
    period: float = math.nan


@dataclass(frozen=True, eq=False)
class ShootingResult:
    """Periodic orbit refined by :func:`shoot`, with scipy's field names.

    Attributes
    ----------
    x : ndarray (2 n_dofs,)
        State ``[q; v]`` at ``t0`` on the orbit (see :attr:`u0`, :attr:`v0`).
    success : bool
        ``residual_norm <= tol * max(1, max|x|)``.
    status : int
        0 success, 1 ``max_iter`` reached, 2 damped step failed, 3 singular Newton matrix
        (:data:`STATUS`).
    message : str
        Words for ``status``.
    nit : int
        Newton iterations.
    residual_norm : float
        ``max |x(t0 + T) - x(t0)|`` at ``x``.
    multipliers : ndarray, complex
        Floquet multipliers at ``x``, largest modulus first. An autonomous orbit keeps its
        trivial multipliers near +1 (a double one for a conservative family), reported as they
        are: their distance from 1 measures the integration error, not stability.
    monodromy : ndarray (2 n_dofs, 2 n_dofs)
        Monodromy matrix at ``x``.
    impacts : list of (float, int)
        Impacts over one period of the orbit.
    period : float
        Period ``T`` (unknown of the Newton iteration for an autonomous model).
    omega : float
        ``2 pi / T`` for an autonomous model; the forcing frequency otherwise.
    """

    x: np.ndarray
    success: bool
    status: int
    message: str
    nit: int
    residual_norm: float
    multipliers: np.ndarray
    monodromy: np.ndarray
    impacts: list
    period: float
    omega: float

    @property
    def u0(self) -> np.ndarray:
        """Displacements ``q(t0)`` on the orbit."""
        return _split(self.x)[0]

    @property
    def v0(self) -> np.ndarray:
        """Velocities ``v(t0)`` on the orbit."""
        return _split(self.x)[1]


# --------------------------------------------------------------------------------------------
# The state layout, in one place
# --------------------------------------------------------------------------------------------
def _split(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(q, v)`` views of a state ``x = [q; v]``."""
    n = x.shape[0] // 2
    return x[:n], x[n:]


def _v_index(n: int, dof: int) -> int:
    """Position of ``v[dof]`` in ``x = [q; v]``."""
    return n + dof


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------
def _state0(x0: Any, n: int, owner: str) -> np.ndarray:
    try:
        x = np.array(x0, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{owner}: x0 must be a real array [q; v] of shape ({2 * n},), got {show(x0)}"
        ) from exc
    if x.shape != (2 * n,):
        raise ValueError(
            f"{owner}: x0 must have shape ({2 * n},) (displacements then velocities of the {n} DOFs, "
            f"x = [q; v]), got shape {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{owner}: x0 contains NaN or infinite values: {show(x0)}")
    return x


def _forced(model: StructuralModel) -> bool:
    """Harmonic forcing (k >= 1) makes the model non-autonomous; a static load (k = 0) does not."""
    return any(k >= 1 and np.any(F != 0) for k, F in model.force_vectors().items())


def _period(model: StructuralModel, omega: float, period: Any, owner: str) -> float:
    base = 2.0 * math.pi / omega
    if period is None:
        return base
    T = check_positive("period", period, owner=owner)
    if _forced(model):
        # A forced orbit repeats only after a whole number of forcing periods (sub-harmonic nu).
        nu = T / base
        if round(nu) < 1 or abs(nu - round(nu)) > 1e-9 * max(1.0, nu):
            raise ValueError(
                f"{owner}: period={show(period)} is {nu:.12g} forcing periods 2 pi/omega = {base:.12g}; a forced "
                "orbit needs a whole number nu of them (period = nu * 2 pi / omega)"
            )
    return T


# --------------------------------------------------------------------------------------------
# The event-driven flow
# --------------------------------------------------------------------------------------------
def unsupported(model: StructuralModel, massless_contacts: bool = False) -> str:
    """Why the event-driven shooting cannot take ``model`` (``""`` if it can): more than
    :data:`MAX_DOFS` DOFs, or a UnilateralContact on a DOF without mass (unless
    ``massless_contacts``: the closed-form flow of :mod:`femodes.time.exact` condenses such a DOF).
    The one place these limits are checked (``fm.stability(method="auto")`` asks before choosing
    the method)."""
    n = model.n_dofs
    if n > MAX_DOFS:
        return (f"model has {n} DOFs; the dense variational equations ((2n)^2 = {4 * n * n} unknowns) are "
                f"limited to {MAX_DOFS} DOFs: reduce the model first (fm.craig_bampton) or {_HILL}")
    Md = model.M.diagonal()
    for j, a in enumerate(model.contacts):
        if not massless_contacts and isinstance(a.item, UnilateralContact) and not Md[a.dof] > 0.0:
            return (f"model: UnilateralContact {j} (at={a.item.at!r}) acts on DOF {model.dofmap.label(a.dof)!r}, "
                    "which has no mass (mass redistributed away from the contact, e.g. fm.RedistributeMass()); an "
                    f"event-driven impact law needs a mass at the contact DOF: {_HILL}, or keep the mass with "
                    "with_contact(..., contact_mass=fm.ConsistentMass())")
    return ""


class _Flow:
    """Vector field, Jacobian, events and resets of a model (dense matrices; see module docstring)."""

    def __init__(self, model: Any, omega: float, restitution: float, rtol: float, atol: float, owner: str):
        if not isinstance(model, StructuralModel):
            raise TypeError(f"{owner}: model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
        n = model.n_dofs
        why = unsupported(model)
        if why:
            raise ValueError(f"{owner}: {why}")
        self.n, self.owner = n, owner
        self.omega, self.e, self.rtol, self.atol = omega, restitution, rtol, atol
        M = model.M.toarray()
        self._contacts(model, M)
        self._inverse_mass(model, M)
        self._forcing(model)
        self._smooth_laws(model)
        self._impact_directions(M)

    def _contacts(self, model, M: np.ndarray) -> None:
        """Unilateral contacts (on DOFs with mass) and penalty contacts."""
        owner = self.owner
        self.unilateral: list[tuple[int, UnilateralContact, int]] = []
        self.penalty: list[tuple[int, PenaltyContact, int]] = []
        for j, a in enumerate(model.contacts):
            if isinstance(a.item, UnilateralContact):  # on a DOF with mass: unsupported() checked it
                self.unilateral.append((j, a.item, a.dof))
            elif isinstance(a.item, PenaltyContact):
                self.penalty.append((j, a.item, a.dof))
            else:
                raise TypeError(f"{owner}: model: contact law {type(a.item).__name__} is not known to the shooting")

    def _inverse_mass(self, model, M: np.ndarray) -> None:
        """``M^-1``, ``M^-1 K``, ``M^-1 C`` (dense); M must be definite."""
        # Mass matrix: symmetric positive semidefinite by construction of the model; the state
        # equations need it definite. The eigenvalue test also catches near-singular M.
        lam = np.linalg.eigvalsh(M)
        if lam[0] <= 1e-12 * lam[-1]:
            massless = [model.dofmap.label(i) for i in np.flatnonzero(np.diag(M) <= 0.0)[:5]]
            raise ValueError(
                f"{self.owner}: model: M is singular (smallest eigenvalue {lam[0]:.3g}, largest {lam[-1]:.3g}"
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
        groups: dict[type, list] = {}
        for a in list(model.nonlinearities) + [model.contacts[j] for j, _, _ in self.penalty]:
            if not callable(getattr(a.item, "force", None)) or not hasattr(type(a.item), "stack"):
                raise TypeError(
                    f"{self.owner}: model: law {type(a.item).__name__} has no force(); the shooting cannot use it"
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
        q, v = _split(x)
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
        R[n:, _v_index(n, c)] -= (1.0 + self.e) * self.impact_dir[j]
        return R

    def velocity_scale(self, x0: np.ndarray) -> float:
        q, v = _split(x0)
        gaps = [abs(law.gap) for _, law, _ in self.unilateral]
        return max(float(np.max(np.abs(v))), self.omega * max([float(np.max(np.abs(q)))] + gaps), 1e-300)


class _Run:
    """One event-driven integration from ``t0`` to ``t1`` (state, optionally with variations)."""

    def __init__(self, flow: _Flow, x0: np.ndarray, t0: float, t1: float, variational: bool, dense: bool = False):
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
        vc = x[_v_index(n, c)]
        owner = flow.owner
        if vc <= 0.0:
            # a root of the gap without approach (tangency at rest, or round-off of a restart on
            # the stop): nothing to reverse
            log.debug("%s: contact %d touches at t = %.9g without approaching (v_c = %.3g)", owner, j, t, vc)
            return x
        self.impacts.append((t, j))
        if len(self.impacts) > MAX_IMPACTS:
            raise _TrialFailure(
                f"{owner}: more than {MAX_IMPACTS} impacts in one run (t = {self.t0:.6g} .. {t:.6g}): "
                f"an accumulation of impacts (chattering) that event-driven integration cannot follow; {_HILL}"
            )
        if vc <= GRAZING_VELOCITY * self.vscale:
            if flow.e < 1.0:
                raise _TrialFailure(
                    f"{owner}: restitution={flow.e!r}: impact at contact {j} at t = {t:.9g} with velocity {vc:.3g} "
                    f"(below {GRAZING_VELOCITY:g} times the velocity scale {self.vscale:.3g}): impacts accumulate "
                    f"(chattering, then sticking), which event-driven integration cannot follow; {_HILL}"
                )
            log.warning("%s: grazing impact at contact %d at t = %.9g (velocity %.3g, scale %.3g): the saltation "
                        "matrix grows like 1/velocity, multipliers are unreliable near grazing", owner, j, t, vc,
                        self.vscale)
        R = flow.reset_matrix(j, c)
        f_minus = flow.field(t, x)
        x_plus = R @ x
        f_plus = flow.field(t, x_plus)
        if flow.e < 1.0 and x_plus[_v_index(n, c)] >= -GRAZING_VELOCITY * self.vscale and f_plus[_v_index(n, c)] > 0:
            raise _TrialFailure(
                f"{owner}: restitution={flow.e!r}: contact {j} comes to rest on the obstacle after the impact at "
                f"t = {t:.9g} (rebound velocity {-x_plus[_v_index(n, c)]:.3g}, below {GRAZING_VELOCITY:g} times the "
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
        return 1e-9 * max(float(np.max(np.abs(_split(x)[0]))), abs(law.gap), 1e-300)

    def _check_start(self, x: np.ndarray) -> None:
        for j, law, c in self.flow.unilateral:
            g = self._gap(x, law, c)
            if g < -self._touch_tol(x, law):
                raise _TrialFailure(
                    f"{self.flow.owner}: x0 starts inside the obstacle of contact {j}: gap g_N = {g:.6g} < 0 "
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
        events = []
        for j, law, c in self.flow.unilateral:
            touching = self._gap(x, law, c) <= self._touch_tol(x, law)
            if touching and x[_v_index(n, c)] > 0.0:
                x = self._impact(t, x, j, law, c)
            # gap rate dg_N/dt = -v_c (g_N = gap - q_c, laws.py)
            events.append(("impact", j, law, c, self._event(law, c, t, -x[_v_index(n, c)], touching, sign=1.0)))
            events[-1][-1].direction = -1  # the gap closes
        for j, law, c in self.flow.penalty:
            pen = -self._gap(x, law, c)  # penetration q_c - gap: > 0 where the spring acts
            touching = abs(pen) <= self._touch_tol(x, law)
            vc = x[_v_index(n, c)]
            if not touching:
                self.active[j] = pen > 0
            elif vc != 0.0:
                self.active[j] = vc > 0
            kink = self._event(law, c, t, vc, touching, sign=-1.0)
            kink.direction = -1 if self.active[j] else 1  # leaving the current side
            events.append(("kink", j, law, c, kink))
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
        event.terminal = True
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
                raise _TrialFailure(f"{flow.owner}: the integration failed at t = {sol.t[-1]:.9g}: {sol.message}")
            if self.dense:
                self.segments.append(sol)
            y = sol.y[:, -1]
            x = y[:n2].copy()
            if self.variational:
                self.Phi = y[n2:].reshape(n2, n2).copy()
            if not np.all(np.isfinite(y)):
                raise _TrialFailure(f"{flow.owner}: the state became non-finite at t = {sol.t[-1]:.9g}")
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
                    raise _TrialFailure(f"{flow.owner}: more than {_MAX_KINKS} penalty-contact kinks in one run")
        return x, self.segments


def _setup(model, omega, x0, restitution, rtol, atol, owner):
    w = check_positive("omega", omega, owner=owner)
    e = check_in_range("restitution", restitution, 0.0, 1.0, owner=owner)
    rtol = check_positive("rtol", rtol, owner=owner)
    atol = check_positive("atol", atol, owner=owner)
    flow = _Flow(model, w, e, rtol, atol, owner)
    x0 = _state0(x0, flow.n, owner)
    return flow, x0


def _monodromy(flow: _Flow, x0: np.ndarray, t0: float, T: float) -> Monodromy:
    run = _Run(flow, x0, t0, t0 + T, variational=True)
    x_end, _ = run.run()
    matrix = run.Phi
    return Monodromy(matrix=matrix, state_end=x_end, impacts=run.impacts, multipliers=_sorted_multipliers(matrix),
                     kinks=run.kinks, period=T)


# --------------------------------------------------------------------------------------------
# Public functions
# --------------------------------------------------------------------------------------------
def _state0_renamed(f):
    """``state0=`` was the keyword of the start state; ``x0`` is, as everywhere else the unknown
    ``[q; v]`` or first guess is given (``exact_frequency_response(x0=)``, ``semismooth_newton``).
    The old keyword still works, with a DeprecationWarning."""
    @functools.wraps(f)
    def wrapper(*args, **kwargs):
        if "state0" in kwargs:
            if "x0" in kwargs or len(args) > 2:
                raise TypeError(f"{f.__name__}: give x0 only (state0= is its deprecated spelling), not both")
            warnings.warn(f"{f.__name__}(..., state0=...) is deprecated; use {f.__name__}(..., x0=...)",
                          DeprecationWarning, stacklevel=2)
            kwargs["x0"] = kwargs.pop("state0")
        return f(*args, **kwargs)
    return wrapper


@_state0_renamed
def monodromy(
    model: StructuralModel,
    omega: float,
    x0,
    *,
    t0: float = 0.0,
    period: float | None = None,
    restitution: float = 1.0,
    rtol: float = 1e-11,
    atol: float = 1e-12,
) -> Monodromy:
    r"""Monodromy matrix ``Phi(t0 + T) = d x(t0 + T) / d x(t0)`` of the event-driven flow.

    .. math::

        \dot x = f(t, x), \quad \dot\Phi = \partial_x f\,\Phi, \quad \Phi(t_0) = I, \qquad
        \Phi \leftarrow S\,\Phi \ \text{at each impact}

    (module docstring: state equations, impact law, saltation matrix ``S``).

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        With a nonsingular mass matrix (at most :data:`MAX_DOFS` DOFs); UnilateralContact,
        PenaltyContact and CubicSpring laws; harmonic forcing ``Re sum_k F_k e^{i k omega t}``.
    omega : float
        Forcing frequency (rad/s); for an autonomous model it only sets the default period.
    x0 : array_like (2 n_dofs,)
        State ``x(t0) = [q; v]``.
    t0 : float, default 0
        Start time (the phase of the forcing).
    period : float, optional
        ``T``; default ``2 pi / omega``. Forced models need ``T = nu 2 pi / omega`` with an
        integer ``nu`` (``nu > 1``: sub-harmonic orbits).
    restitution : float, default 1
        Newton's coefficient ``e`` in ``[0, 1]`` of the UnilateralContact impacts.
    rtol, atol : float
        Tolerances of ``solve_ivp`` (DOP853), applied to the state and to the variations.

    Returns
    -------
    Monodromy
        ``matrix``, ``state_end``, ``impacts``, ``multipliers`` (largest modulus first), ``kinks``.

    Raises
    ------
    TypeError, ValueError
        Invalid arguments (the message names the argument and quotes the value); what the
        event-driven integration cannot do (massless contact DOF, singular M, chattering or
        sticking with ``restitution < 1``, ``x0`` inside an obstacle), with a pointer to
        Hill's method.
    """
    owner = "monodromy"
    flow, x0 = _setup(model, omega, x0, restitution, rtol, atol, owner)
    t0 = check_finite("t0", t0, owner=owner)
    T = _period(model, flow.omega, period, owner)
    try:
        return _monodromy(flow, x0, t0, T)
    except _TrialFailure as exc:
        raise ValueError(str(exc)) from None


@_state0_renamed
def trajectory(
    model: StructuralModel,
    omega: float,
    x0,
    t,
    *,
    t0: float = 0.0,
    restitution: float = 1.0,
    rtol: float = 1e-11,
    atol: float = 1e-12,
) -> np.ndarray:
    """States ``x(t) = [q(t); v(t)]`` of the event-driven flow from ``x(t0) = x0``.

    The same integration as :func:`monodromy` without the variations (e.g. the extreme
    displacement of an orbit found by :func:`shoot`); at an impact time the state just before it.

    Parameters
    ----------
    t : array_like
        Times ``>= t0`` (any order).

    Returns
    -------
    ndarray (len(t), 2 n_dofs)
    """
    owner = "trajectory"
    flow, x0 = _setup(model, omega, x0, restitution, rtol, atol, owner)
    t0 = check_finite("t0", t0, owner=owner)
    tt = np.atleast_1d(np.asarray(t, dtype=float))
    if tt.ndim != 1 or tt.size == 0 or not np.all(np.isfinite(tt)) or np.any(tt < t0):
        raise ValueError(f"{owner}: t must be a non-empty 1-D array of finite times >= t0 = {t0}, got {show(t)}")
    t1 = float(tt.max())
    out = np.empty((tt.size, 2 * flow.n))
    if t1 == t0:
        out[:] = x0
        return out
    try:
        x_end, segments = _Run(flow, x0, t0, t1, variational=False, dense=True).run()
    except _TrialFailure as exc:
        raise ValueError(str(exc)) from None
    done = np.zeros(tt.size, dtype=bool)
    for s in segments:
        sel = ~done & (tt >= s.t[0]) & (tt <= s.t[-1])
        if np.any(sel):
            out[sel] = s.sol(tt[sel]).T
            done |= sel
    out[~done] = x_end  # the last 1e-13 of the span when an event falls there
    out[tt == t0] = x0  # x0 as given, even when it starts with an impact
    return out


class _ShootingEquations:
    """The periodicity equations ``x(t0 + T) - x(t0) = 0`` in the Newton unknowns ``z``.

    Forced model: ``z = x``, Jacobian ``Phi - I``. Autonomous model: ``z = [x_free; T]`` with
    ``q_j`` and ``v_j = 0`` pinned (``shoot``'s docstring) and the equation of ``q_j`` left out:
    for a conservative orbit it follows from the others by energy conservation (with the other
    states periodic and ``v_j(T) = 0``, the energy fixes ``q_j(T)`` up to the other turning
    point, far from the orbit), so the system is square. The ``q_j`` equation is the one to drop:
    at a turning point ``d q_j / dT = v_j = 0``, so it would only fix ``T`` to second order, while
    ``v_j(T)`` moves with ``T`` at the acceleration. The column of ``T`` is the vector field at
    ``t0 + T``.
    A state the flow cannot follow gives a non-finite residual (the line search then shortens
    the step).
    """

    def __init__(self, flow, x0: np.ndarray, T0: float, t0: float, free: np.ndarray, rows: np.ndarray,
                 autonomous: bool, owner: str):
        self.flow, self.x0, self.T0, self.t0 = flow, x0, T0, t0
        self.free, self.rows, self.autonomous, self.owner = free, rows, autonomous, owner
        self.z0 = np.append(x0[free], T0) if autonomous else x0.copy()
        self._cache: dict = {}

    def state(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        x = self.x0.copy()
        x[self.free] = z[: self.free.size]
        return x, float(z[-1]) if self.autonomous else self.T0

    def last(self, z: np.ndarray):
        key = z.tobytes()
        if key not in self._cache:
            self(z)
        if key not in self._cache:  # pragma: no cover - the iterate returned was evaluated finite
            raise ValueError(f"{self.owner}: the flow cannot be followed from the final iterate")
        return self._cache[key]

    def __call__(self, z: np.ndarray):
        x, T = self.state(z)
        size = z.size
        if not T > 0:
            return np.full(size, np.inf), np.eye(size)
        try:
            mono = _monodromy(self.flow, x, self.t0, T)
        except _TrialFailure as exc:
            log.debug("%s: trial state rejected: %s", self.owner, exc)
            return np.full(size, np.inf), np.eye(size)
        self._cache = {z.tobytes(): mono}
        n2 = 2 * self.flow.n
        r = (mono.state_end - x)[self.rows]
        J = (mono.matrix - np.eye(n2))[np.ix_(self.rows, self.free)]
        if self.autonomous:
            J = np.column_stack([J, self.flow.field(self.t0 + T, mono.state_end)[self.rows]])
        return r, J


@_state0_renamed
def shoot(
    model: StructuralModel,
    omega: float,
    x0,
    *,
    period: float | None = None,
    restitution: float = 1.0,
    tol: float = 1e-10,
    max_iter: int = 30,
    t0: float = 0.0,
    phase_dof: int | None = None,
    rtol: float = 1e-11,
    atol: float = 1e-12,
) -> ShootingResult:
    r"""Periodic orbit by Newton shooting, ``x(t0 + T; x0) - x0 = 0``, and its Floquet multipliers.

    Solved by :func:`femodes.solvers.semismooth_newton` (monotone Armijo search down to a step
    of ``2^-12``, least-squares steps at a singular matrix). Forced model (harmonic forcing): the
    unknown is ``x0``; the Newton matrix is ``Phi - I`` (``Phi`` the monodromy matrix,
    :func:`monodromy`).

    Autonomous model (no harmonic forcing: free orbits, nonlinear modes): the period ``T`` is
    unknown too. Free periodic orbits of the models femodes builds exist only without
    dissipation and then come in one-parameter families (energy), so ``Phi`` has the multiplier
    +1 twice and a phase condition alone leaves the bordered system singular. The orbit is
    therefore pinned at a turning point of DOF ``j = phase_dof``: ``v_j(t0) = 0`` (phase) and
    ``q_j(t0) = x0[j]`` (amplitude, the member of the family), and the remaining ``2n - 2``
    states and ``T`` solve the ``2n - 1`` periodicity equations other than that of ``q_j``
    (redundant by energy conservation; see ``_ShootingEquations``). The columns are ``Phi - I``
    for the states and the vector field ``f(x(t0 + T))`` for ``T``.

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        As in :func:`monodromy`.
    omega : float
        Forcing frequency (rad/s); for an autonomous model the first guess of the orbit's
        angular frequency (``T = 2 pi / omega`` unless ``period`` is given).
    x0 : array_like (2 n_dofs,)
        First guess of ``x(t0) = [q; v]``.
    period : float, optional
        Forced: ``nu 2 pi / omega`` for a period-``nu`` (sub-harmonic) orbit, default ``nu = 1``.
        Autonomous: first guess of the period.
    restitution : float, default 1
        Newton's impact coefficient.
    tol : float, default 1e-10
        Converged when ``max|x(t0 + T) - x0| <= tol * max(1, max|x0|)``.
    max_iter : int, default 30
        Newton iterations.
    t0 : float, default 0
        Time of the state ``x0`` (phase of the forcing).
    phase_dof : int, optional
        Autonomous models: DOF pinned at its turning point; default the DOF with the largest
        ``|q|`` in ``x0``. Refused for forced models.
    rtol, atol : float
        Tolerances of ``solve_ivp``.

    Returns
    -------
    ShootingResult
        ``x, success, status, message, nit, residual_norm, multipliers, monodromy, impacts,
        period, omega``; non-convergence is reported there, not raised. The multipliers are
        those of the returned ``x``; the trivial multipliers near +1 of an autonomous orbit are
        kept as computed (their distance from 1, of the order of the square root of the
        integration error for a conservative family's Jordan block, is not a stability verdict).

    Raises
    ------
    TypeError, ValueError
        Invalid arguments, or a first guess the event-driven integration cannot follow (as in
        :func:`monodromy`).
    """
    owner = "shoot"
    flow, x = _setup(model, omega, x0, restitution, rtol, atol, owner)
    t0 = check_finite("t0", t0, owner=owner)
    T = _period(model, flow.omega, period, owner)
    tol = check_positive("tol", tol, owner=owner)
    max_iter = check_int("max_iter", max_iter, 1, owner=owner)
    n = flow.n
    autonomous = not _forced(model)
    free = np.arange(2 * n)
    if autonomous:
        if phase_dof is None:
            j = int(np.argmax(np.abs(_split(x)[0])))
        else:
            j = check_int("phase_dof", phase_dof, 0, owner=owner)
            if j >= n:
                raise ValueError(f"{owner}: phase_dof must be a DOF index in [0, {n}), got {show(phase_dof)}")
        x[_v_index(n, j)] = 0.0  # phase condition: t0 at a turning point of DOF j
        free = np.setdiff1d(free, [j, _v_index(n, j)])
    elif phase_dof is not None:
        raise ValueError(f"{owner}: phase_dof={show(phase_dof)} is for autonomous models; this model is forced "
                         "(its phase is fixed by the forcing)")

    rows = np.setdiff1d(np.arange(2 * n), [j]) if autonomous else np.arange(2 * n)
    problem = _ShootingEquations(flow, x, T, t0, free, rows, autonomous, owner)
    try:
        problem(problem.z0)
    except _TrialFailure as exc:
        raise ValueError(f"{str(exc)} (first guess x0)") from None
    # One Newton for all of femodes: semismooth_newton with a monotone Armijo search (no
    # watchdog: each trial is a whole period of integration), the house's least-squares fallback
    # at a singular Phi - I, and the stopping rule max|x(T) - x0| <= tol max(1, max|x0|).
    res = semismooth_newton(problem, problem.z0, options=NewtonOptions(
        atol=tol, rtol=0.0, rtol_x=tol, xtol=1e-15, max_iter=max_iter, watchdog=0, min_alpha=0.5 ** _MAX_HALVINGS,
        linear_solver=solve_or_lstsq))
    x, T = problem.state(res.x)
    mono = problem.last(res.x)
    r = mono.state_end - x
    norm = float(np.max(np.abs(r)))
    status = 0 if norm <= tol * max(1.0, float(np.max(np.abs(x)))) else min(res.status, 3) or 2
    nit = res.nit
    message = {
        0: f"converged in {nit} Newton iterations: max|x(T) - x0| = {norm:.3g} <= tol*max(1, max|x0|)",
        1: f"max_iter={max_iter} Newton iterations reached with max|x(T) - x0| = {norm:.3g} (tol={tol:g})",
        2: f"iteration {nit + 1}: no step reduced max|x(T) - x0| = {norm:.3g} ({res.message})",
        3: f"iteration {nit + 1}: Phi - I is singular (a multiplier at +1: fold) and no least-squares step reduced "
           f"max|x(T) - x0| = {norm:.3g}",
    }[status]
    res = norm
    (log.info if status == 0 else log.debug)("%s: %s", owner, message)  # reported in the result
    return ShootingResult(
        x=x, success=status == 0, status=status, message=message, nit=nit, residual_norm=res,
        multipliers=mono.multipliers, monodromy=mono.matrix, impacts=mono.impacts, period=T,
        omega=2.0 * math.pi / T if autonomous else flow.omega,
    )
