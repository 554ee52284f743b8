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

The flow itself, from event to event (impacts, penalty-contact kinks) and what it refuses, is
:mod:`femodes.time.event_flow`; its limits are re-exported here.

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

from ..model import StructuralModel
from ..solvers import NewtonOptions, semismooth_newton
from ..solvers.checks import (InputValueError, check_finite, check_in_range, check_int, check_positive, entry_name,
                              entry_point, show)
from .event_flow import (GRAZING_VELOCITY, MAX_DOFS, MAX_IMPACTS, Flow, Run, TrialFailure, split_state, unsupported,
                         v_index)
from .stepper import solve_or_lstsq

__all__ = ["Monodromy", "ShootingResult", "monodromy", "shoot", "trajectory", "MAX_IMPACTS", "GRAZING_VELOCITY",
           "MAX_DOFS", "STATUS", "unsupported"]

log = logging.getLogger(__name__)

#: Step halvings of the line search of :func:`shoot` (smallest step 2^-12).
_MAX_HALVINGS = 12

STATUS = {
    0: "success: periodic orbit found to tolerance",
    1: "max_iter Newton iterations reached",
    2: "the damped Newton step could not reduce the residual",
    3: "singular Newton matrix (a multiplier at +1: fold or free-orbit family) and no reducing step",
}


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
        return split_state(self.x)[0]

    @property
    def v0(self) -> np.ndarray:
        """Velocities ``v(t0)`` on the orbit."""
        return split_state(self.x)[1]

# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------
def _state0(x0: Any, n: int) -> np.ndarray:
    try:
        x = np.array(x0, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputValueError(
            f"x0 must be a real array [q; v] of shape ({2 * n},), got {show(x0)}"
        ) from exc
    if x.shape != (2 * n,):
        raise InputValueError(
            f"x0 must have shape ({2 * n},) (displacements then velocities of the {n} DOFs, "
            f"x = [q; v]), got shape {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise InputValueError(f"x0 contains NaN or infinite values: {show(x0)}")
    return x


def _forced(model: StructuralModel) -> bool:
    """Harmonic forcing (k >= 1) makes the model non-autonomous; a static load (k = 0) does not."""
    return any(k >= 1 and np.any(F != 0) for k, F in model.force_vectors().items())


def _period(model: StructuralModel, omega: float, period: Any) -> float:
    base = 2.0 * math.pi / omega
    if period is None:
        return base
    T = check_positive("period", period)
    if _forced(model):
        # A forced orbit repeats only after a whole number of forcing periods (sub-harmonic nu).
        nu = T / base
        if round(nu) < 1 or abs(nu - round(nu)) > 1e-9 * max(1.0, nu):
            raise InputValueError(
                f"period={show(period)} is {nu:.12g} forcing periods 2 pi/omega = {base:.12g}; a forced "
                "orbit needs a whole number nu of them (period = nu * 2 pi / omega)"
            )
    return T


def _setup(model, omega, x0, restitution, rtol, atol):
    w = check_positive("omega", omega)
    e = check_in_range("restitution", restitution, 0.0, 1.0)
    rtol = check_positive("rtol", rtol)
    atol = check_positive("atol", atol)
    flow = Flow(model, w, e, rtol, atol)
    x0 = _state0(x0, flow.n)
    return flow, x0


def _monodromy(flow: Flow, x0: np.ndarray, t0: float, T: float) -> Monodromy:
    run = Run(flow, x0, t0, t0 + T, variational=True)
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
@entry_point("monodromy")
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
    rtol, atol : float, default 1e-11, 1e-12
        Tolerances of ``solve_ivp`` (DOP853), applied to the state and to the variations.

    Returns
    -------
    Monodromy
        ``matrix``, ``state_end``, ``impacts``, ``multipliers`` (largest modulus first), ``kinks``.

    Raises
    ------
    TypeError, ValueError
        Invalid arguments (named, value quoted); what the event-driven integration cannot do (massless
        contact DOF, singular M, chattering or sticking with ``restitution < 1``, ``x0`` in an obstacle).
    """
    flow, x0 = _setup(model, omega, x0, restitution, rtol, atol)
    t0 = check_finite("t0", t0)
    T = _period(model, flow.omega, period)
    try:
        return _monodromy(flow, x0, t0, T)
    except TrialFailure as exc:
        raise InputValueError(str(exc)) from None


@_state0_renamed
@entry_point("trajectory")
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
    flow, x0 = _setup(model, omega, x0, restitution, rtol, atol)
    t0 = check_finite("t0", t0)
    tt = np.atleast_1d(np.asarray(t, dtype=float))
    if tt.ndim != 1 or tt.size == 0 or not np.all(np.isfinite(tt)) or np.any(tt < t0):
        raise InputValueError(f"t must be a non-empty 1-D array of finite times >= t0 = {t0}, got {show(t)}")
    t1 = float(tt.max())
    out = np.empty((tt.size, 2 * flow.n))
    if t1 == t0:
        out[:] = x0
        return out
    try:
        x_end, segments = Run(flow, x0, t0, t1, variational=False, dense=True).run()
    except TrialFailure as exc:
        raise InputValueError(str(exc)) from None
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
                 autonomous: bool):
        self.flow, self.x0, self.T0, self.t0 = flow, x0, T0, t0
        self.free, self.rows, self.autonomous = free, rows, autonomous
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
            raise InputValueError("the flow cannot be followed from the final iterate")
        return self._cache[key]

    def __call__(self, z: np.ndarray):
        x, T = self.state(z)
        size = z.size
        if not T > 0:
            return np.full(size, np.inf), np.eye(size)
        try:
            mono = _monodromy(self.flow, x, self.t0, T)
        except TrialFailure as exc:
            log.debug("%s: trial state rejected: %s", entry_name(), exc)
            return np.full(size, np.inf), np.eye(size)
        self._cache = {z.tobytes(): mono}
        n2 = 2 * self.flow.n
        r = (mono.state_end - x)[self.rows]
        J = (mono.matrix - np.eye(n2))[np.ix_(self.rows, self.free)]
        if self.autonomous:
            J = np.column_stack([J, self.flow.field(self.t0 + T, mono.state_end)[self.rows]])
        return r, J


@_state0_renamed
@entry_point("shoot")
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

    Newton (:func:`femodes.solvers.semismooth_newton`) on ``x0`` with the matrix ``Phi - I`` (``Phi`` the
    monodromy matrix, :func:`monodromy`). Autonomous model (no forcing): ``T`` is unknown too and the orbit
    pinned at a turning point of ``phase_dof`` (``v_j(t0) = 0``): :doc:`/guide/stability` (Shooting).

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        As in :func:`monodromy`.
    omega : float
        Forcing frequency (rad/s); autonomous: first guess of the orbit's (``T = 2 pi / omega``).
    x0 : array_like (2 n_dofs,)
        First guess of ``x(t0) = [q; v]``.
    period : float, optional
        Forced: ``nu 2 pi / omega`` for a period-``nu`` orbit (default ``nu = 1``); autonomous: first guess.
    restitution : float, default 1
        Newton's impact coefficient.
    tol : float, default 1e-10
        Converged when ``max|x(t0 + T) - x0| <= tol * max(1, max|x0|)``.
    max_iter : int, default 30
        Newton iterations.
    t0 : float, default 0
        Time of the state ``x0`` (phase of the forcing).
    phase_dof : int, optional
        Autonomous models only: DOF pinned at its turning point (default: largest ``|q|`` in ``x0``).
    rtol, atol : float, default 1e-11, 1e-12
        Tolerances of ``solve_ivp``.

    Returns
    -------
    ShootingResult
        ``x, success, status, message, nit, residual_norm, multipliers, monodromy, impacts, period,
        omega``; non-convergence is reported there, not raised. Multipliers of the returned ``x``.

    Raises
    ------
    TypeError, ValueError
        Invalid arguments, or a first guess the event-driven integration cannot follow.
    """
    flow, x = _setup(model, omega, x0, restitution, rtol, atol)
    t0 = check_finite("t0", t0)
    T = _period(model, flow.omega, period)
    tol = check_positive("tol", tol)
    max_iter = check_int("max_iter", max_iter, 1)
    n = flow.n
    autonomous = not _forced(model)
    free = np.arange(2 * n)
    if autonomous:
        if phase_dof is None:
            j = int(np.argmax(np.abs(split_state(x)[0])))
        else:
            j = check_int("phase_dof", phase_dof, 0)
            if j >= n:
                raise InputValueError(f"phase_dof must be a DOF index in [0, {n}), got {show(phase_dof)}")
        x[v_index(n, j)] = 0.0  # phase condition: t0 at a turning point of DOF j
        free = np.setdiff1d(free, [j, v_index(n, j)])
    elif phase_dof is not None:
        raise InputValueError(f"phase_dof={show(phase_dof)} is for autonomous models; this model is forced "
                         "(its phase is fixed by the forcing)")

    rows = np.setdiff1d(np.arange(2 * n), [j]) if autonomous else np.arange(2 * n)
    problem = _ShootingEquations(flow, x, T, t0, free, rows, autonomous)
    try:
        problem(problem.z0)
    except TrialFailure as exc:
        raise InputValueError(f"{exc} (first guess x0)") from None
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
    # reported in the result; DEBUG, not INFO: a branch's stability pass shoots every point, and its
    # progress (progress=True shows femodes' INFO records) would drown in one line per orbit
    log.debug("shoot: %s", message)
    return ShootingResult(
        x=x, success=status == 0, status=status, message=message, nit=nit, residual_norm=norm,
        multipliers=mono.multipliers, monodromy=mono.matrix, impacts=mono.impacts, period=T,
        omega=2.0 * math.pi / T if autonomous else flow.omega,
    )
