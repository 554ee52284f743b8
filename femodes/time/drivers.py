"""Drivers of the Moreau-Jean time stepping: :func:`simulate` and :func:`steady_state`.

They validate the arguments (messages name the argument and quote the value), build the
:class:`~femodes.time.stepper.Stepper` for the step actually used, run it and wrap the samples
and the local solver's outcome in a :class:`~femodes.time.results.TimeHistory` or
:class:`~femodes.time.results.SteadyState`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model import StructuralModel
from ..solvers import NewtonOptions
from ..solvers.checks import (InputTypeError, InputValueError, check_finite, check_in_range, check_int, check_positive,
                              entry_name, entry_point)
from ..solvers.threads import limit_blas_threads
from .results import SteadyState, TimeHistory
from .stepper import Segment, Stepper, integrate

__all__ = ["simulate", "steady_state", "TimeSteppingOptions"]

log = logging.getLogger(__name__)

#: Bounds that turn an absurd dt (or t_end) into an error naming it instead of an overflow or a
#: failed allocation deep inside numpy: steps per run, and stored floats per history array
#: (2**28 float64 = 2 GiB).
_MAX_STEPS = 10**9
_MAX_STORED = 2**28
#: Fewest time steps per forcing period that simulate and steady_state accept. The trapezoidal
#: rule (theta = 1/2, the default) lengthens the period of a smooth oscillation by the relative
#: amount (w h)^2 / 12 (Hughes, *The Finite Element Method*, 2000, sec. 9.3: period elongation of
#: the trapezoidal rule): 0.8 % at 20 steps per period, 3.3 % at 10 and 36 % at 3, and near a
#: resonance an error of the frequency is a far larger error of the amplitude (at 3 steps per period
#: the forced oscillator's amplitude came out 0.068 instead of 0.438); theta > 1/2 adds numerical
#: damping of order (theta - 1/2) w h per step on top. Contacts resolve impacts to O(h) only, so 20
#: is a floor, not a recommendation.
MIN_STEPS_PER_PERIOD = 20

#: A rigid stop can only take energy out of the structure, so a positive net work of the contact
#: impulses (:func:`femodes.time.stepper.contact_work`) is energy the steps put in. steady_state
#: warns when the periods it integrated got more than this fraction of the orbit's largest energy
#: per period, on average (the last periods alone can miss it: a motion that touches the stop now
#: and then). Energy put in at a rate ``p`` a period against damping that takes out ``d`` raises the
#: energy by about ``p / (d - p)``: 2.4 % at this tolerance for 1 % damping (``d`` = 12.6 %).
#: Measured on a Craig-Bampton ring with 43 contact nodes (benchmarks/study_ring.py, 0.96 w1,
#: restitution 0, theta = 1/2): +5 % a period at dt = T/400 (energy 8-22x the harmonic balance's),
#: +14 to +25 % at T/1600 (2x), -0.02 % and +0.07 % (100 and 200 periods) at T/6400 (within 10 %),
#: but +1.5 % at T/6400 and 1.00 w1 (400 periods); with theta = 0.55, -0.6 to -6 % at T/400, -4 % at
#: T/1600, and -0.4 to -5 % at T/6400 over 1.00-1.22 w1 (measured with the impulses working on
#: ``theta v1 + (1 - theta) v0``; on the mean velocity they take a little more: -4.4 -> -4.9 % on
#: the plate of tests/test_time.py).
PERIOD_WORK_TOL = 3e-3

#: simulate warns when the whole run's contact impulses put in more than this fraction of its
#: largest energy (a run has no period to normalise by).
RUN_WORK_TOL = 1e-2


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------
def _state(x: Any, name: str, n: int) -> np.ndarray:
    if x is None:
        return np.zeros(n)
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a real array of shape ({n},), got {type(x).__name__}") from exc
    if arr.ndim == 0 and n == 1:
        arr = arr.reshape(1)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) (one value per model DOF), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr.copy()


def _check_omega(model: StructuralModel, omega: Any) -> float | None:
    harmonic = any(a.item.harmonic >= 1 for a in model.forces)
    if omega is None:
        if harmonic:
            raise InputValueError("omega (forcing frequency, rad/s) is required: the model has harmonic forcing")
        return None
    check_finite("omega", omega)
    w = check_positive("omega", omega)
    if not harmonic:
        raise InputValueError(
            f"omega={omega!r} given but the model has no harmonic forcing (add with_forcing or omit omega)"
        )
    return w


def _check_common(model, dt, restitution, theta, newton):
    if not isinstance(model, StructuralModel):
        raise InputTypeError(f"model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
    check_finite("dt", dt)
    dt = check_positive("dt", dt)
    e = check_in_range("restitution", restitution, 0.0, 1.0)
    th = check_in_range("theta", theta, 0.5, 1.0)
    if newton is not None and not isinstance(newton, NewtonOptions):
        raise InputTypeError(f"newton must be a NewtonOptions or None, got {type(newton).__name__}")
    return model, dt, e, th


def _n_steps(span: float, dt: float, what: str) -> int:
    """``ceil(span / dt)`` steps, or a ValueError naming ``dt`` when that is not a sane count."""
    ratio = span / dt
    if not math.isfinite(ratio) or ratio > _MAX_STEPS:
        raise InputValueError(
            f"dt={dt!r} gives {ratio:.3g} steps over {what} = {span:.6g} (more than {_MAX_STEPS:.0e}); "
            "increase dt"
        )
    return max(1, int(math.ceil(ratio - 1e-9)))


# --------------------------------------------------------------------------------------------
# Reports
# --------------------------------------------------------------------------------------------
def _check_steps_per_period(dt: float, w: float | None) -> None:
    """ValueError naming ``dt`` when it gives fewer than :data:`MIN_STEPS_PER_PERIOD` steps per
    forcing period ``2 pi / w`` (nothing to check without forcing)."""
    if w is None:
        return
    T = 2.0 * math.pi / w
    n = T / dt
    if n < MIN_STEPS_PER_PERIOD:
        err = (2.0 * math.pi / math.ceil(n)) ** 2 / 12.0
        raise InputValueError(
            f"dt={dt!r} gives {n:.3g} steps per forcing period 2 pi / omega = {T:.6g}, fewer than the "
            f"{MIN_STEPS_PER_PERIOD} the integrator needs (its period error (w h)^2 / 12 would be {err:.1%}); "
            f"use dt <= {T / MIN_STEPS_PER_PERIOD:.4g}"
        )


def _local_report(n_failed: int, first: tuple[float, str] | None, n_steps: int, where: str = "") -> str:
    """Words for the steps whose local problem was not solved (``""`` if none)."""
    if not n_failed:
        return ""
    assert first is not None  # the recorder keeps the first failure of n_failed > 0
    t, why = first
    return (f"the local problem (contact impulses + nonlinear forces) was not solved to tolerance at {n_failed} of "
            f"{n_steps} steps, first at t = {t:.6g}{where}: {why}")


# --------------------------------------------------------------------------------------------
# Drivers
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class TimeSteppingOptions:
    """The rarely changed settings of :func:`simulate` and :func:`steady_state` (validated at
    construction; change with ``dataclasses.replace``).

    Parameters
    ----------
    theta : float, default 0.5
        Theta-method parameter in ``[1/2, 1]`` (1/2: trapezoidal, energy conserving for linear
        parts; 1: backward Euler, dissipative).
    newton : NewtonOptions, optional
        Options of the semismooth Newton solves of each step's local problem (contacts and
        nonlinear DOFs); default :data:`femodes.time.stepper.LOCAL_NEWTON`.
    t0 : float, default 0
        Initial time (:func:`simulate`).
    store_every : int, default 1
        Store every ``store_every``-th step, the last one always (:func:`simulate`).
    n_periods_max : int, default 2000
        Bound on the forcing periods integrated (:func:`steady_state`; non-convergence is
        reported, never a hang).
    tol : float, default 1e-8
        Relative tolerance of the period-start state (:func:`steady_state`).
    periods_per_check : int, default 1
        Check convergence every this many periods (:func:`steady_state`).
    """

    theta: float = 0.5
    newton: NewtonOptions | None = None
    t0: float = 0.0
    store_every: int = 1
    n_periods_max: int = 2000
    tol: float = 1e-8
    periods_per_check: int = 1

    @entry_point("TimeSteppingOptions")
    def __post_init__(self) -> None:
        object.__setattr__(self, "theta", check_in_range("theta", self.theta, 0.5, 1.0))
        if self.newton is not None and not isinstance(self.newton, NewtonOptions):
            raise InputTypeError(f"newton must be a NewtonOptions or None, got {type(self.newton).__name__}")
        object.__setattr__(self, "t0", check_finite("t0", self.t0))
        for name in ("store_every", "n_periods_max", "periods_per_check"):
            object.__setattr__(self, name, check_int(name, getattr(self, name), 1))
        check_finite("tol", self.tol)
        object.__setattr__(self, "tol", check_positive("tol", self.tol))


def _options(options: Any) -> TimeSteppingOptions:
    if options is None:
        return TimeSteppingOptions()
    if not isinstance(options, TimeSteppingOptions):
        raise InputTypeError(f"options must be a femodes.TimeSteppingOptions or None, got {type(options).__name__}")
    return options


@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
@entry_point("simulate")
def simulate(
    model: StructuralModel,
    t_end: float,
    dt: float,
    *,
    u0=None,
    v0=None,
    omega: float | None = None,
    restitution: float = 1.0,
    options: TimeSteppingOptions | None = None,
) -> TimeHistory:
    r"""Moreau-Jean time-stepping of a model with unilateral contact (Jean 1999; Moreau 1988).

    .. math::

        M \Delta v = h\,\Theta F_{k+1} + h (I - \Theta) F_k - \sum_c e_c P_c, \quad
        0 \le U_{c,k+1} + e\,U_{c,k} \perp P_c \ge 0 \ \text{(predicted gap} \le 0)

    (:mod:`femodes.time.moreau`; Acary & Brogliato 2008, chapter 10).

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        Linear structure with contact and cubic-spring laws and optional harmonic forcing.
    t_end : float
        Final time (``> t0``).
    dt : float
        Time step (``0 < dt < t_end - t0``), reduced to fit an integer number of steps; with forcing at
        most ``2 pi / omega / MIN_STEPS_PER_PERIOD`` (20 steps per period).
    u0, v0 : array_like (n_dofs,), optional
        Initial displacement and velocity (zero by default).
    omega : float, optional
        Forcing frequency (rad/s): required if the model has harmonic forcing, refused otherwise.
    restitution : float, default 1.0
        Newton restitution coefficient ``e`` in ``[0, 1]`` (a massless contact DOF uses the
        position-level Signorini law).
    options : TimeSteppingOptions, optional
        ``theta`` (default 1/2), ``newton`` (local solves), ``t0`` (initial time), ``store_every``.

    Returns
    -------
    TimeHistory
        ``success``/``status``/``message`` report an unsolved local step (the run goes on from its best iterate).

    Raises
    ------
    TypeError, ValueError
        Invalid arguments (the message names the argument).
    FloatingPointError
        If the state becomes non-finite.
    """
    opts = _options(options)
    theta, newton, t0, store_every = opts.theta, opts.newton, opts.t0, opts.store_every
    model, dt, e, th = _check_common(model, dt, restitution, theta, newton)
    t_end = check_finite("t_end", t_end)
    if t_end <= t0:
        raise InputValueError(f"t_end must be > t0 = {t0}, got {t_end!r}")
    if not math.isfinite(t_end - t0):
        raise InputValueError(f"t_end - t0 overflows: t_end={t_end!r}, t0={t0!r}")
    if dt >= t_end - t0:
        raise InputValueError(f"dt must be smaller than t_end - t0 = {t_end - t0:g}, got {dt!r}")
    w = _check_omega(model, omega)
    _check_steps_per_period(dt, w)
    n = model.n_dofs
    q = _state(u0, "u0", n)
    v = _state(v0, "v0", n)
    n_steps = _n_steps(t_end - t0, dt, "t_end - t0")
    n_stored = (n_steps // store_every + 2) * max(n, 1)
    if n_stored > _MAX_STORED:
        raise InputValueError(
            f"storing {n_steps} steps of {n} DOFs every store_every={store_every} step(s) needs "
            f"{n_stored:.3g} values per array (more than {_MAX_STORED:.3g}); increase store_every or dt"
        )
    h = (t_end - t0) / n_steps
    st = Stepper(model, h, th, e, w, newton)
    _warn_massless_trapezoidal(st)
    for j, a in enumerate(model.contacts):
        g = float(a.item.gap_function(q[a.dof]))
        if g < 0:
            log.warning("simulate: initial penetration %.3g at contact %d", g, j)
    seg = integrate(st, t0, n_steps, q, v, store_every)
    failure = _local_report(seg.n_failed, seg.first_failure, n_steps)
    if failure:
        log.warning("simulate: %s", failure)
    message = failure or f"{n_steps} steps of {h:.6g} from t = {t0:g} to {t_end:g}, every local problem solved"
    injected = _energy_injected(seg.contact_work, seg.energy, RUN_WORK_TOL, "over the run")
    if injected:
        log.warning("simulate: %s", injected)
        message += "; " + injected
    log.info("simulate: %s", message)
    status = 1 if failure else 0
    return TimeHistory(t=seg.t, u=seg.u, v=seg.v, impulse=seg.impulse, energy=seg.energy, gap=seg.gap, dt=h,
                       success=status == 0, status=status, message=message, contact_work=seg.contact_work)


def _energy_injected(work: float, energy: np.ndarray, tol: float, window: str) -> str:
    """The sentence that says the contact impulses put energy in (positive ``work`` above ``tol``
    times the largest of ``energy``, per ``window``), or ``""``."""
    scale = float(np.max(energy)) if energy.size else 0.0
    if not (scale > 0.0 and work > tol * scale):
        return ""
    return (f"the contact impulses put {work:.3g} J into the structure {window} ({100 * work / scale:.3g} % of its "
            "largest energy), where a rigid stop can only take energy out: the steps excite motions of the contact "
            "DOFs that they do not resolve, and the result overstates the energy. Use "
            "TimeSteppingOptions(theta=0.55), which damps those motions, or a smaller dt (compare two)")


def _warn_massless_trapezoidal(st) -> None:
    """Warn when the trapezoidal rule meets a contact on a massless DOF (:mod:`femodes.time.moreau`):
    every switch of that contact excites stiff modes that theta = 1/2 neither resolves nor damps."""
    if st.theta == 0.5 and st.impact.any_massless:
        log.warning("%s: theta = 1/2 with a contact on a massless DOF: each switch of the contact adds energy "
                    "(O(dt^2)) to stiff modes the trapezoidal rule does not damp; over long runs this can grow "
                    "without bound (the 10-element cantilever with its tip stop, dt = T/400: 1e76 after 480 "
                    "periods). Use TimeSteppingOptions(theta=0.55) or steps far below the fastest period", entry_name())


@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
@entry_point("steady_state")
def steady_state(
    model: StructuralModel,
    omega: float,
    *,
    dt: float,
    u0=None,
    v0=None,
    restitution: float = 1.0,
    options: TimeSteppingOptions | None = None,
) -> SteadyState:
    r"""Periodic steady state of a forced model by Moreau-Jean integration, period after period.

    The step is ``h = T / N`` with ``T = 2 pi / omega`` and ``N = ceil(T / dt)``, so the discrete
    map over one forcing period ``x_j -> x_{j+1}`` (``x = (q, v)`` at ``t = j T``) is iterated until
    ``|x_j - x_{j-nu}| <= tol |x_j|`` (displacements and velocities measured separately) for the
    smallest ``nu`` in 1..4, where every shorter order changes by more than ``sqrt(tol)`` (a
    decaying transient is not a sub-harmonic orbit: ``_PeriodMap.periodic_order``). The last
    ``nu`` periods are returned.

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        With harmonic forcing.
    omega : float
        Forcing frequency (rad/s).
    dt : float
        Largest time step; at most ``2 pi / omega / MIN_STEPS_PER_PERIOD`` (20 steps per period).
    u0, v0 : array_like, optional
        Initial state at ``t = 0``.
    restitution : float
        As in :func:`simulate`.
    options : TimeSteppingOptions, optional
        ``n_periods_max``, ``tol``, ``periods_per_check`` (the period iteration), ``theta`` and
        ``newton`` (as in :func:`simulate`).

    Returns
    -------
    SteadyState
        ``converged`` says whether the period-start state repeated; ``success``/``status``/
        ``message`` also report steps whose local problem was not solved.
    """
    opts = _options(options)
    theta, newton = opts.theta, opts.newton
    n_periods_max, tol, periods_per_check = opts.n_periods_max, opts.tol, opts.periods_per_check
    model, dt, e, th = _check_common(model, dt, restitution, theta, newton)
    w = _check_omega(model, omega)
    if w is None:
        raise InputValueError("omega is required")
    T = 2.0 * math.pi / w
    if dt >= T:
        raise InputValueError(f"dt must be smaller than the forcing period {T:g}, got {dt!r}")
    _check_steps_per_period(dt, w)
    n = model.n_dofs
    q = _state(u0, "u0", n)
    v = _state(v0, "v0", n)
    N = _n_steps(T, dt, "the forcing period 2 pi / omega")
    if N * max(n, 1) > _MAX_STORED:
        raise InputValueError(
            f"dt={dt!r} gives {N} steps per period for {n} DOFs (more than {_MAX_STORED:.3g} stored "
            "values); increase dt"
        )
    st = Stepper(model, T / N, th, e, w, newton)
    _warn_massless_trapezoidal(st)
    orbit = _PeriodMap(st, N, T, q, v)
    nu, converged = orbit.iterate(n_periods_max, periods_per_check, tol)
    j = orbit.n_periods
    # theta = 1/2 does not damp what the steps do not resolve: after impacts, modes that the model's
    # damping leaves undamped ring on (the Craig-Bampton ring of benchmarks/study_ring.py: its
    # constraint modes, damping ratios 3e-6 and less, kept it from settling without contact for 400
    # periods, where theta = 0.55 settled)
    ringing = (" With theta = 1/2 the scheme does not damp motions faster than its steps, which impacts excite: "
               "if the model's damping leaves its fast modes undamped (modal damping covers its first modes "
               "only), they ring on. TimeSteppingOptions(theta=0.55) damps them"
               if not converged and th == 0.5 and st.n_contacts and n > 1 else "")
    m, c = orbit.closest
    if not converged and m > 1 and c < orbit.change:
        # a sub-harmonic orbit that does not repeat to tol (impacts on a fixed step grid land within
        # a step of their times: an impact oscillator with restitution 1 and 2 % damping, period 2,
        # repeated to 1e-2 at 400 steps a period and never to 1e-3)
        ringing = (f" The state came nearest to repeating every {m} periods (relative change {c:.2g}): the "
                   "step places impacts only to within dt, which can keep an impacting orbit from repeating "
                   f"to tol; compare a smaller dt.") + ringing
    if not converged:
        log.warning("steady_state: no periodic state after %d periods (last relative change %.3g).%s", j,
                    orbit.change, ringing)
    seg = orbit.history[-nu:]
    tt = np.concatenate([seg[0].t] + [s.t[1:] + (i + 1) * T for i, s in enumerate(seg[1:])])
    U, V, IMP, E, G = (np.concatenate([getattr(seg[0], k)] + [getattr(s, k)[1:] for s in seg[1:]])
                       for k in ("u", "v", "impulse", "energy", "gap"))
    failure = _local_report(orbit.n_failed, orbit.first_failure, j * N, f" (period {orbit.failed_period})")
    reasons = [failure] if failure else []
    if not converged:
        reasons.append(f"no periodic state within n_periods_max={n_periods_max} periods (last relative change of "
                       f"the period-start state {orbit.change:.3g} > tol={tol:g}).{ringing}")
    status = 1 if failure else (2 if not converged else 0)
    message = "; ".join(reasons) or (f"period-{nu} orbit after {j} periods of {N} steps (relative change "
                                     f"{orbit.change:.3g} <= tol={tol:g}), every local problem solved")
    if failure:
        log.warning("steady_state: %s", failure)
    injected = _energy_injected(orbit.work / j, E, PERIOD_WORK_TOL, f"a period on average over {j} periods")
    if injected:
        log.warning("steady_state: %s", injected)
        message += "; " + injected
    log.info("steady_state: w = %.6g, nu = %d, %d periods, change %.3g, converged %s", w, nu, j, orbit.change,
             converged)
    return SteadyState(t=tt, u=U, v=V, impulse=IMP, gap=G, energy=E, period=nu * T, nu=nu,
                       amplitude=np.max(np.abs(U), axis=0), converged=converged, n_periods=j, change=orbit.change,
                       dt=st.h, success=status == 0, status=status, message=message, contact_work=orbit.work)


class _PeriodMap:
    """The Moreau-Jean map over one forcing period, iterated until the period-start state repeats."""

    def __init__(self, st: Stepper, N: int, T: float, q: np.ndarray, v: np.ndarray):
        self.st, self.N, self.T, self.n = st, N, T, q.size
        self.q, self.v = q, v
        self.starts = [np.concatenate([q, v])]
        self.history: list[Segment] = []  # the last 4 periods
        self.n_periods = 0
        self.change = math.inf
        self.closest = (1, math.inf)  # (m, change over m periods): the order that came nearest a repeat
        self.n_failed, self.failed_period = 0, 0
        self.first_failure: tuple[float, str] | None = None
        self.work = 0.0  # net work of the contact impulses over all periods

    def advance(self) -> None:
        """Integrate one period (time restarts at 0 each period: the forcing is T-periodic)."""
        out = integrate(self.st, 0.0, self.N, self.q, self.v)
        self.n_periods += 1
        self.work += out.contact_work
        if out.n_failed:
            if self.first_failure is None:
                assert out.first_failure is not None  # the recorder keeps the first failure of n_failed > 0
                t, why = out.first_failure
                self.first_failure = ((self.n_periods - 1) * self.T + t, why)
                self.failed_period = self.n_periods
            self.n_failed += out.n_failed
        self.q, self.v = out.u[-1].copy(), out.v[-1].copy()
        self.history.append(out)
        if len(self.history) > 4:
            self.history.pop(0)
        self.starts.append(np.concatenate([self.q, self.v]))
        if len(self.starts) > 6:
            self.starts.pop(0)

    def _rel(self, a: np.ndarray, b: np.ndarray) -> float:
        """Relative distance of two period-start states (displacements and velocities separately)."""
        n, x = self.n, self.starts[-1]
        sq = max(float(np.linalg.norm(x[:n])), 1e-300)
        sv = max(float(np.linalg.norm(x[n:])), 1e-300)
        return max(float(np.linalg.norm(a[:n] - b[:n])) / sq, float(np.linalg.norm(a[n:] - b[n:])) / sv)

    def periodic_order(self, tol: float) -> int | None:
        """Smallest ``nu`` in 1..4 with ``|x_j - x_{j-nu}| <= tol |x_j|`` (for ``nu > 1`` also one
        period earlier, and every shorter ``m`` with a change above ``sqrt(tol)``: a genuine
        period-``nu`` orbit), else ``None``; updates :attr:`change`: the change over ``nu`` periods
        when one is found (over one period, that of a period-2 orbit read 0.07 "<= tol = 1e-8"),
        else over one period.

        A decaying transient that turns by about ``2 pi / m`` a period comes back near its start
        every ``m`` periods: its change over ``m`` periods falls below ``tol`` first (a linear
        oscillator forced at three times its natural frequency was reported as a period-3 orbit),
        while its change over one period is then a few ``tol``; a genuine period-``m`` orbit's is
        of the order of its amplitude."""
        starts = self.starts
        shorter: list[float] = []
        for m in range(1, 5):
            if len(starts) > m + (1 if m > 1 else 0):
                c = self._rel(starts[-1], starts[-1 - m])
                if m == 1 or c < self.closest[1]:
                    self.closest = (m, c)
                if m == 1:
                    self.change = c
                ok = c <= tol
                if ok and m > 1:
                    c = max(c, self._rel(starts[-2], starts[-2 - m]))
                    ok = c <= tol and min(shorter) > math.sqrt(tol)
                if ok:
                    self.change = c
                    return m
                shorter.append(c)
        return None

    def iterate(self, n_periods_max: int, periods_per_check: int, tol: float) -> tuple[int, bool]:
        """``(nu, converged)`` after at most ``n_periods_max`` periods."""
        while self.n_periods < n_periods_max:
            self.advance()
            if self.n_periods % periods_per_check:
                continue
            nu = self.periodic_order(tol)
            if nu is not None:
                return nu, True
        return 1, False
