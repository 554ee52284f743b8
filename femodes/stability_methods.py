r"""Analyses layer: how the Floquet multipliers of one periodic orbit are computed, as strategy
objects (``stability=fm.stability_methods.Hill()``, ``fm.stability(solution, Hill())``).

:class:`Hill`
    Hill's method on the harmonic balance Jacobian (:mod:`femodes.hbm.hill`). Valid for every
    model femodes solves, full or reduced, with the HBM's own accuracy: spectrally accurate for
    smooth laws (cubic springs; penalty contacts, whose Jacobian is exact), but for
    complementarity contacts it describes the HBM orbit, whose contact *phases* stand in for
    instantaneous impacts, so near grazing and at few harmonics its multipliers are rough.
:class:`Shooting`
    Event-driven shooting (:mod:`femodes.time.shooting`) from the HBM state: the orbit is
    refined into a true periodic orbit of the time-continuous model (impacts with restitution 1,
    the time-domain counterpart of the Signorini law) and its monodromy matrix, with saltation
    matrices at impacts, gives the multipliers. The reference for contact, for models whose
    contact DOFs carry mass and that are small (or reduced): at most
    :data:`femodes.time.shooting.MAX_DOFS` DOFs.
:class:`Auto` (the default)
    Shooting for forced responses of small models with complementarity contacts whose fastest
    natural frequency is at most ``max_stiffness`` times the orbit's (falling back to Hill at a
    point where shooting does not converge), Hill otherwise.

A strategy is called on an :class:`Orbit` with the tolerance ``tol`` (unstable when
``max |mu| > 1 + tol``, the trivial multipliers of free orbits excluded) and returns a
:class:`StabilityResult`. The names ``"auto"``, ``"hill"``, ``"shooting"`` are deprecated
spellings of these objects (:func:`as_stability_method`); case files keep them.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any, ClassVar, Protocol

import numpy as np

from .branch_stability import crossing_kind, significant
from .hbm.hill import coarse_multipliers, hill_exponents
from .hbm.system import HBMSystem
from .laws import UnilateralContact
from .model import StructuralModel
from .solvers.checks import InputValueError, entry_point, strategy
from .time.shooting import shoot, unsupported

__all__ = ["StabilityMethod", "Orbit", "Hill", "Shooting", "Auto", "StabilityResult", "ShootingError",
           "as_stability_method", "by_name", "harmonic_check", "checked_lead", "describe_unconverged", "METHODS", "AUTO_MAX_STIFFNESS", "MAX_CORRECTION", "AUTO_MAX_ITER", "AUTO_MAX_FAILED_TIME"]

log = logging.getLogger(__name__)

#: :class:`Auto` shoots only when the fastest natural frequency of the model is at most this many
#: times the orbit's frequency: the explicit integration of the variational equations needs steps
#: of the fastest period, so its cost grows with that ratio (the Craig-Bampton blade of
#: examples/blade_casing.py, ratio 3764: 174 s for one shooting at a point without contact,
#: against 0.14 s for Hill's method; the 1-DOF seed cases: ratio about 1, a few ms).
AUTO_MAX_STIFFNESS = 50.0

#: Shooting that moves the HBM start state by more than this fraction of its size has found
#: another orbit (:class:`Auto` then uses Hill's method at that point).
MAX_CORRECTION = 0.2

#: Newton iterations :class:`Auto` gives one shooting (an explicit ``Shooting()`` takes 30). From
#: the HBM orbit a shooting that converges does so in a few: 0 to 8 along the forced curve of the
#: seed impact oscillator (H = 20; most 4 or 5), where the ones that fail stall after 16 to 24. On
#: a shallow arch's Craig-Bampton model (11 DOFs, deep contact at H = 7) every contact orbit
#: stalled after 11 to 21 iterations, 6 to 11 s each, against 0.06 s for Hill's method.
AUTO_MAX_ITER = 12

#: :class:`Auto` gives shooting up along a branch once its failed shootings took this many seconds
#: (:meth:`Auto.gives_up`), and the whole branch takes Hill's method. Failures alone do not tell:
#: the seed impact oscillator at H = 6 fails at 13 points in a row near its upper fold and then
#: shoots its period doubling, a few milliseconds each; a shallow arch's Craig-Bampton model (11
#: DOFs) failed at every contact orbit, 105 of 129 points at 6-11 s each (650 s for a 0.7 s
#: branch). A budget in time bounds what shooting can waste without touching cheap models.
AUTO_MAX_FAILED_TIME = 10.0


#: Hill's truncation check (:func:`harmonic_check`): a verdict that changes with the truncation is
#: flagged when the leading multiplier's modulus moves by more than this. A smooth law's exponents
#: converge fast, except for a multiplier near +1 (the forced Duffing oscillator, H = 9 against 6:
#: 1e-15 at its stable points, 2e-9 to 2e-4 at its unstable ones, growing toward the upper fold,
#: 5e-4 at that fold, where the coarse truncation no longer holds the exact +1 of the whole
#: Jacobian); the contact artefacts it is there for move it by 0.1 to 25 (the cantilever with a tip
#: stop of examples/cantilever_tip_stop.py, 4 modes, H = 10 and 20).
HARMONIC_CHANGE = 1e-2


@dataclasses.dataclass(frozen=True, eq=False)
class StabilityResult:
    """Floquet multipliers of one periodic solution.

    Attributes
    ----------
    multipliers : ndarray, complex
        Largest modulus first.
    stable : bool
        ``max |mu| <= 1 + tol``.
    method : str
        ``"hill"`` or ``"shooting"`` (the method actually used).
    message : str
        Why :class:`Auto` fell back to Hill, or ``""``.
    orbit_correction : float
        Shooting only: ``max |x_shooting - x_hbm|`` of the state at the start time, relative to
        ``max |x_hbm|`` (how far the HBM orbit is from the true periodic orbit); NaN for Hill.
    error : float
        Hill only: the estimated error of the multipliers' moduli from the reduction Hill's
        problem was solved on (:attr:`femodes.hbm.hill.HillResult.reduction_error`; 0 when solved
        whole, NaN for shooting).
    coarse : float
        Hill only, where checked (:func:`harmonic_check`): the largest modulus of the multipliers
        the check compares (:func:`checked_lead`) with the perturbation truncated to
        ``floor(0.75 H)`` harmonics instead of ``H`` (:func:`femodes.hbm.hill.coarse_multipliers`);
        NaN where not checked.
    n_modes : int or None
        Hill only: the free-interface modes of the reduction its problem was solved on (None: the
        model itself).
    """

    multipliers: np.ndarray
    stable: bool
    method: str
    message: str = ""
    orbit_correction: float = math.nan
    error: float = math.nan
    coarse: float = math.nan
    n_modes: int | None = None

    def unconverged(self, tol: float, free: bool) -> bool:
        """Hill's truncation check done and failed: on the multipliers it compares
        (:func:`checked_lead`), the coarser truncation gives the other verdict, with a leading
        modulus more than :data:`HARMONIC_CHANGE` (and ``tol``) away (``free``: an orbit of the
        free system)."""
        if not math.isfinite(self.coarse):
            return False
        lead = checked_lead(self.multipliers, free)
        return (self.coarse > 1.0 + tol) != (lead > 1.0 + tol) and abs(self.coarse - lead) > max(tol, HARMONIC_CHANGE)


class ShootingError(RuntimeError):
    """:class:`Shooting` did not converge on a solution's orbit (:class:`Auto` falls back to
    Hill's method instead)."""


@dataclasses.dataclass(frozen=True, eq=False)
class Orbit:
    """One periodic solution as the strategies see it: ``y`` the HBM unknowns of ``system``,
    ``Q`` its displacement coefficients, ``xi`` the artificial damping of a nonlinear mode;
    ``forced`` False for an orbit of the free system (its trivial multipliers are 1)."""

    model: StructuralModel
    system: HBMSystem
    y: np.ndarray
    Q: np.ndarray
    omega: float
    xi: float
    forced: bool


class StabilityMethod(Protocol):
    """A way to compute the multipliers of an orbit."""

    name: ClassVar[str]

    def __call__(self, orbit: Orbit, tol: float) -> StabilityResult: ...


def is_stable(mu: np.ndarray, tol: float, free: bool) -> bool:
    """``max |mu| <= 1 + tol`` over the multipliers that count (:func:`significant`)."""
    m = significant(mu, free)
    return bool(m.size == 0 or np.abs(m[0]) <= 1.0 + tol)


@dataclasses.dataclass(frozen=True)
class Hill:
    """Hill's method (module docstring)."""

    name: ClassVar[str] = "hill"

    def __call__(self, orbit: Orbit, tol: float, message: str = "") -> StabilityResult:
        res = hill_exponents(orbit.system, orbit.y, orbit.omega, orbit.xi)
        mu = res.multipliers
        return StabilityResult(multipliers=mu, stable=is_stable(mu, tol, not orbit.forced), method="hill",
                               message=message, error=float(res.reduction_error), n_modes=res.n_modes)


def harmonic_check(orbit: Orbit, result: StabilityResult) -> StabilityResult:
    """``result`` of Hill's method with :attr:`StabilityResult.coarse` filled in: the same orbit's
    multipliers with the perturbation truncated to fewer harmonics
    (:func:`femodes.hbm.hill.coarse_multipliers`, on the same reduction); ``result`` itself for
    shooting, or below 2 harmonics."""
    if result.method != "hill":
        return result
    mu = coarse_multipliers(orbit.system, orbit.y, orbit.omega, orbit.xi, result.n_modes)
    if mu.size == 0:
        return result
    return dataclasses.replace(result, coarse=checked_lead(mu, not orbit.forced))


def checked_lead(mu: np.ndarray, free: bool) -> float:
    """The largest modulus of the multipliers Hill's truncation check compares: those that decide
    stability (:func:`~femodes.branch_stability.significant`), without the real positive ones. An
    odd number of real multipliers above 1 is the sign of the whole harmonic balance Jacobian's
    determinant (between two folds of a forced curve, past a branch point), which the coarse
    truncation does not keep: on the forced curve of examples/blade_casing.py (H = 7) the unstable
    stretch between the folds read 1.02-1.25 whole and 0.92-0.94 at 5 harmonics."""
    m = significant(mu, free)
    kept = [abs(z) for z in m if crossing_kind(complex(z), m) != "branch_point"]
    return float(max(kept)) if kept else 0.0


def describe_unconverged(records: list[dict], limit: int) -> str:
    """The points that failed Hill's truncation check, as the warning and ``summary.txt`` list
    them: ``"5 (1.14 / 1), 6 (2.8 / 1), ..."`` (point, leading modulus at H / with fewer
    harmonics), at most ``limit`` of them (records of
    :attr:`~femodes.results.Branch.stability_unconverged`)."""
    shown = ", ".join(f"{d['index']} ({d['modulus']:.3g} / {d['coarse']:.3g})" for d in records[:limit])
    return shown + (", ..." if len(records) > limit else "")


@dataclasses.dataclass(frozen=True)
class Shooting:
    """Event-driven shooting from the HBM orbit (module docstring); a model it cannot take is a
    ValueError, an orbit it does not converge on a :class:`ShootingError`."""

    name: ClassVar[str] = "shooting"

    def __call__(self, orbit: Orbit, tol: float) -> StabilityResult:
        why = unsupported(orbit.model)
        if why:
            raise ValueError(f"stability: the shooting method cannot take this model: {why}; use "
                             "femodes.stability_methods.Hill()")
        try:
            return shooting_multipliers(orbit, tol)
        except ShootingFailed as exc:
            raise ShootingError(f"stability: shooting from the HBM orbit at w = {orbit.omega:g} did not converge "
                                f"({exc}); use femodes.stability_methods.Hill() or raise the harmonics") from None


@dataclasses.dataclass(frozen=True)
class Auto:
    """Shooting where it is the reference and affordable, Hill's method elsewhere (module
    docstring); ``max_stiffness`` is the largest ratio of the model's fastest natural frequency
    to the orbit's that is shot."""

    max_stiffness: float = AUTO_MAX_STIFFNESS
    name: ClassVar[str] = "auto"

    @entry_point("Auto")
    def __post_init__(self):
        m = self.max_stiffness
        if isinstance(m, bool) or not isinstance(m, (int, float, np.integer, np.floating)) or not m > 0:
            raise InputValueError(f"max_stiffness must be a positive number, got {m!r}")

    def __call__(self, orbit: Orbit, tol: float) -> StabilityResult:
        if not self.shoots(orbit):
            return Hill()(orbit, tol)
        try:
            return shooting_multipliers(orbit, tol, AUTO_MAX_ITER)
        except (ShootingFailed, ValueError) as exc:
            return Hill()(orbit, tol, message=f"shooting failed ({exc}); Hill's method used")

    def gives_up(self, failed_time: float) -> bool:
        """Whether shooting is given up for a branch once its failed shootings took
        ``failed_time`` seconds (more than :data:`AUTO_MAX_FAILED_TIME`)."""
        return failed_time > AUTO_MAX_FAILED_TIME

    def shoots(self, orbit: Orbit) -> bool:
        """Whether this orbit is shot: forced, complementarity contacts, a model shooting takes,
        and a fastest natural frequency within ``max_stiffness`` times the orbit's."""
        model = orbit.model
        has_uc = any(isinstance(a.item, UnilateralContact) for a in model.contacts)
        if not (orbit.forced and has_uc and not unsupported(model)):
            return False
        ratio = fastest_frequency(model) / max(abs(orbit.omega), 1e-300)
        if ratio > self.max_stiffness:
            log.debug("stability: w_max / w = %.3g > %g: Hill's method instead of shooting", ratio, self.max_stiffness)
            return False
        return True


_BY_NAME: dict[str, StabilityMethod] = {"auto": Auto(), "hill": Hill(), "shooting": Shooting()}

#: The deprecated method names (case files keep them).
METHODS = tuple(_BY_NAME)


def by_name(name: str) -> StabilityMethod:
    """The strategy a :class:`StabilityResult` names (``"hill"``, ``"shooting"``)."""
    return _BY_NAME[name]


def as_stability_method(value: Any, name: str = "method") -> StabilityMethod:
    """``value`` as a strategy (:func:`~femodes.solvers.checks.strategy`): a strategy object, or
    any callable with a ``name``, as it is; one of the names ``"auto"``, ``"hill"``,
    ``"shooting"`` its object, with a DeprecationWarning; anything else a ValueError that lists
    the strategies."""
    return strategy(value, name, _BY_NAME, "femodes.stability_methods", "a stability strategy",
                    lambda v: callable(v) and isinstance(getattr(v, "name", None), str))


# -- shooting from an HBM orbit ------------------------------------------------------------------
class ShootingFailed(RuntimeError):
    """Shooting did not find this orbit (the reason in the message)."""


_FASTEST: dict = {}


def fastest_frequency(model: StructuralModel) -> float:
    """Largest undamped natural frequency ``sqrt(max eig(K, M))`` of a model shooting can take
    (at most MAX_DOFS DOFs, nonsingular M), cached per matrix pair."""
    key = (id(model.K), id(model.M))
    hit = _FASTEST.get(key)
    if hit is not None and hit[0] is model.K and hit[1] is model.M:
        return hit[2]
    import scipy.linalg as sla

    K, M = model.K.toarray(), model.M.toarray()
    n = K.shape[0]
    try:
        lam = float(sla.eigh(K, M, eigvals_only=True, subset_by_index=[n - 1, n - 1])[0]) if n else 0.0
        w = math.sqrt(max(lam, 0.0))
    except np.linalg.LinAlgError:  # M not positive definite (a massless DOF): no finite fastest mode
        w = math.inf
    if len(_FASTEST) > 16:
        _FASTEST.clear()
    _FASTEST[key] = (model.K, model.M, w)  # the matrices are kept so that their ids are not reused
    return w


def _start_time(system: HBMSystem, Q: np.ndarray, omega: float) -> float:
    """The most open instant of the orbit (largest smallest gap): the shooting starts there, away
    from the HBM's contact phases and slight penetrations."""
    h = system.h
    theta = h.grid.most_open_phase(Q, [ct.dof for ct in system.unilateral], [ct.law.gap for ct in system.unilateral])
    return float(theta / (2.0 * np.pi) * h.grid.period(omega))


def shooting_multipliers(orbit: Orbit, tol: float, max_iter: int = 30) -> StabilityResult:
    """The multipliers of the true periodic orbit shot from the HBM orbit (:class:`ShootingFailed`
    when shooting does not converge in ``max_iter`` Newton iterations, or converges on another
    orbit)."""
    model, system, Q, omega = orbit.model, orbit.system, orbit.Q, orbit.omega
    free = not orbit.forced
    h = system.h
    t0 = _start_time(system, Q, omega)
    theta = np.array([2.0 * np.pi * t0 / h.grid.period(omega)])
    E = h.grid.synthesis(theta)
    q0 = (E @ Q)[0]
    v0 = (E @ (omega * (system.D1 @ Q)))[0]
    x0 = np.concatenate([q0, v0])
    # a free orbit is shot on the free model (its period an unknown); a forced one with its forcing
    res = shoot(model.without_forcing() if free else model, omega, x0, period=h.grid.period(omega), t0=t0,
                max_iter=max_iter)
    if not res.success:
        raise ShootingFailed(res.message)
    mu = np.asarray(res.multipliers)
    corr = float(np.max(np.abs(res.x - x0)) / max(float(np.max(np.abs(x0))), 1e-300))
    if corr > MAX_CORRECTION:
        # Newton found a periodic orbit, but not this one (near an HBM fold the true orbit of the
        # same branch may not exist at this frequency, and shooting lands on a coexisting one)
        raise ShootingFailed(f"shooting moved the start state by {corr:.0%} of its size: another orbit")
    return StabilityResult(multipliers=mu, stable=is_stable(mu, tol, free), method="shooting", orbit_correction=corr)
