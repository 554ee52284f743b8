r"""Analyses layer: stability of periodic solutions (Floquet multipliers), at one point and along branches.

A periodic orbit is asymptotically stable when all its Floquet multipliers ``mu`` lie inside the
unit circle; here *stable* means ``max |mu| <= 1 + tol`` (the trivial multipliers of free orbits,
exactly 1, and round-off stay stable). Two independent methods give the multipliers:

``"hill"``
    Hill's method on the harmonic balance Jacobian (:mod:`femodes.hbm.hill`). Valid for every
    model femodes solves, full or reduced, with the HBM's own accuracy: spectrally accurate for
    smooth laws (cubic springs; penalty contacts, whose Jacobian is exact), but for
    complementarity contacts it describes the HBM orbit, whose contact *phases* stand in for
    instantaneous impacts, so near grazing and at few harmonics its multipliers are rough.
``"shooting"``
    Event-driven shooting (:mod:`femodes.time.shooting`) from the HBM state: the orbit is
    refined into a true periodic orbit of the time-continuous model (impacts with restitution 1,
    the time-domain counterpart of the Signorini law) and its monodromy matrix, with saltation
    matrices at impacts, gives the multipliers. The reference for contact, for models whose
    contact DOFs carry mass and that are small (or reduced): at most
    :data:`femodes.time.shooting.MAX_DOFS` DOFs.
``"auto"``
    Shooting for forced responses of small models with complementarity contacts whose fastest
    natural frequency is at most :data:`AUTO_MAX_STIFFNESS` times the orbit's (falling back to
    Hill at a point where shooting does not converge), Hill otherwise.

Along a branch (``frequency_response(..., stability=True)``, :func:`annotate_branch`), the
multipliers of every point are computed here, and a change in their number outside the circle
between two points is a bifurcation, bracketed, located and classified by
:mod:`femodes.branch_stability` (by default with two to four corrector and Hill solves, its
accuracy stated in ``Bifurcation.bracket``).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from typing import Any

import numpy as np

from .branch_stability import (BRANCH_POINT_DENSE_LIMIT, COLLISION, augmented_jacobian, branch_point_test,
                               find_bifurcations, refine_branch_point, root_on_secant, significant,
                               solve_on_secant)
from .hbm.hill import hill_exponents
from .hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from .hbm.system import HBMSystem
from .laws import UnilateralContact
from .model import StructuralModel
from .results import Branch, PeriodicSolution
from .solvers import NewtonOptions
from .solvers.threads import limit_blas_threads
from .time.shooting import shoot, unsupported

# the location helpers live in femodes.branch_stability; they are re-exported here, where
# switch_branch and scripts import them from
__all__ = ["stability", "StabilityResult", "StabilityOptions", "ShootingError", "annotate_branch", "solve_on_secant",
           "root_on_secant", "refine_branch_point", "branch_point_test", "augmented_jacobian", "COLLISION",
           "BRANCH_POINT_DENSE_LIMIT", "METHODS"]

log = logging.getLogger(__name__)

#: The methods :func:`stability` accepts.
METHODS = ("auto", "hill", "shooting")

#: Default tolerance on ``|mu| - 1`` above which an orbit is unstable.
TOL = 1e-4

#: ``"auto"`` shoots only when the fastest natural frequency of the model is at most this many
#: times the orbit's frequency: the explicit integration of the variational equations needs steps
#: of the fastest period, so its cost grows with that ratio (the Craig-Bampton blade of
#: examples/blade_casing.py, ratio 3764: 174 s for one shooting at a point without contact,
#: against 0.14 s for Hill's method; the 1-DOF seed cases: ratio about 1, a few ms).
AUTO_MAX_STIFFNESS = 50.0

#: Shooting that moves the HBM start state by more than this fraction of its size has found
#: another orbit (``"auto"`` then uses Hill's method at that point).
MAX_CORRECTION = 0.2

#: Seconds between progress lines of a stability run along a branch.
PROGRESS_EVERY = 5.0


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
        Why ``"auto"`` fell back to Hill, or ``""``.
    orbit_correction : float
        Shooting only: ``max |x_shooting - x_hbm|`` of the state at the start time, relative to
        ``max |x_hbm|`` (how far the HBM orbit is from the true periodic orbit); NaN for Hill.
    """

    multipliers: np.ndarray
    stable: bool
    method: str
    message: str = ""
    orbit_correction: float = math.nan


@dataclasses.dataclass(frozen=True)
class StabilityOptions:
    """Stability along a branch: ``stability=StabilityOptions(...)`` of the analyses
    (``stability=True`` is ``StabilityOptions()``, ``stability="hill"`` is
    ``StabilityOptions(method="hill")``).

    Attributes
    ----------
    method : {"auto", "hill", "shooting"}
        How the multipliers of each point are computed (module docstring).
    tol : float
        A point is unstable when ``max |mu| > 1 + tol``.
    locate : bool or float
        True (default): each change of stability between two points is located between them by
        bracketing (:mod:`femodes.branch_stability`): at most two corrector and Hill solves for a
        smooth crossing (at the crossing interpolated from the test function at the points and
        their neighbours, then straddling it), up to four for a jump of the multipliers
        (``"nonsmooth"``); the bifurcation is reported at the unstable end of the final bracket
        and ``Bifurcation.bracket`` says between which two solutions it lies. Problems of at most
        ``branch_stability.PRECISE_MAX_UNKNOWNS`` (100) unknowns are refined to 1e-7 of the
        segment instead. A number ``xtol`` in (0, 1): every problem refined by regula falsi until
        the bracket is ``xtol`` of the segment (about 6 solves for a jump, 5-15 for a smooth
        crossing at 1e-7). False: bracketing only, at no cost beyond the points' multipliers:
        the bifurcation is reported at the point of the bracket on its unstable side
        (``Bifurcation.located`` False), classified by that point's crossing multiplier (a jump
        cannot be told from a crossing there). :func:`~femodes.switch_branch` locates the
        bifurcation itself in every case.
    """

    method: str = "auto"
    tol: float = TOL
    locate: bool | float = True

    def __post_init__(self):
        _check_method(self.method, "StabilityOptions")
        object.__setattr__(self, "tol", _check_tol(self.tol, "StabilityOptions"))
        loc = self.locate
        if isinstance(loc, (bool, np.bool_)):
            object.__setattr__(self, "locate", bool(loc))
        elif isinstance(loc, (int, float, np.integer, np.floating)) and 0.0 < float(loc) < 1.0:
            object.__setattr__(self, "locate", float(loc))
        else:
            raise TypeError(f"StabilityOptions: locate must be True, False or a bracket width xtol in (0, 1) "
                            f"(a fraction of the segment between two points), got {loc!r}")

    @classmethod
    def parse(cls, stability: Any, owner: str) -> StabilityOptions | None:
        """``stability=`` of an analysis: False or None (no stability), True (the defaults), a
        method name, or a :class:`StabilityOptions`."""
        if stability is False or stability is None:
            return None
        if stability is True:
            return cls()
        if isinstance(stability, cls):
            return stability
        if isinstance(stability, str) and stability in METHODS:
            return cls(method=stability)
        raise ValueError(f"{owner}: stability must be True, False, one of {', '.join(map(repr, METHODS))} or a "
                         f"femodes.StabilityOptions, got {stability!r}")


def _check_method(method: Any, owner: str) -> str:
    if method not in METHODS:
        raise ValueError(f"{owner}: method must be one of {', '.join(repr(m) for m in METHODS)}, got {method!r}")
    return method


def _check_tol(tol: Any, owner: str) -> float:
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.integer, np.floating)):
        raise TypeError(f"{owner}: tol must be a number (the margin of |mu| above 1), got {tol!r}")
    if not 0 <= tol < 1:
        raise ValueError(f"{owner}: tol must be in [0, 1) (the margin of |mu| above 1), got {tol!r}")
    return float(tol)


def _prefers_shooting(model: StructuralModel, forced: bool, omega: float) -> bool:
    has_uc = any(isinstance(a.item, UnilateralContact) for a in model.contacts)
    if not (forced and has_uc and not unsupported(model)):
        return False
    ratio = _fastest_frequency(model) / max(abs(omega), 1e-300)
    if ratio > AUTO_MAX_STIFFNESS:
        log.debug("stability: w_max / w = %.3g > %g: Hill's method instead of shooting", ratio, AUTO_MAX_STIFFNESS)
        return False
    return True


_FASTEST: dict = {}


def _fastest_frequency(model: StructuralModel) -> float:
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
    theta = h.most_open_phase(Q, [ct.dof for ct in system.unilateral], [ct.law.gap for ct in system.unilateral])
    return float(theta / (2.0 * np.pi) * h.period(omega))


def _by_shooting(model: StructuralModel, system: HBMSystem, Q: np.ndarray, omega: float, tol: float,
                 free: bool = False) -> StabilityResult:
    h = system.h
    t0 = _start_time(system, Q, omega)
    theta = np.array([2.0 * np.pi * t0 / h.period(omega)])
    E = h.synthesis(theta)
    q0 = (E @ Q)[0]
    v0 = (E @ (omega * (system.D1 @ Q)))[0]
    x0 = np.concatenate([q0, v0])
    # a free orbit is shot on the free model (its period an unknown); a forced one with its forcing
    res = shoot(model.without_forcing() if free else model, omega, x0, period=h.period(omega), t0=t0)
    if not res.success:
        raise _ShootingFailed(res.message)
    mu = np.asarray(res.multipliers)
    corr = float(np.max(np.abs(res.x - x0)) / max(float(np.max(np.abs(x0))), 1e-300))
    if corr > MAX_CORRECTION:
        # Newton found a periodic orbit, but not this one (near an HBM fold the true orbit of the
        # same branch may not exist at this frequency, and shooting lands on a coexisting one)
        raise _ShootingFailed(f"shooting moved the start state by {corr:.0%} of its size: another orbit")
    return StabilityResult(multipliers=mu, stable=_is_stable(mu, tol, free), method="shooting",
                           orbit_correction=corr)


class _ShootingFailed(RuntimeError):
    pass


class ShootingError(RuntimeError):
    """``method="shooting"`` did not converge on a solution's orbit (``"auto"`` falls back to
    Hill's method instead)."""


def _is_stable(mu: np.ndarray, tol: float, free: bool) -> bool:
    m = significant(mu, free)
    return bool(m.size == 0 or np.abs(m[0]) <= 1.0 + tol)


def _by_hill(system: HBMSystem, y: np.ndarray, omega: float, xi: float, tol: float, free: bool,
             message: str = "") -> StabilityResult:
    mu = hill_exponents(system, y, omega, xi).multipliers
    return StabilityResult(multipliers=mu, stable=_is_stable(mu, tol, free), method="hill", message=message)


def _point_stability(model, system, y, Q, omega, xi, method, tol, forced) -> StabilityResult:
    if method == "hill" or (method == "auto" and not _prefers_shooting(model, forced, omega)):
        return _by_hill(system, y, omega, xi, tol, not forced)
    if method == "shooting":
        why = unsupported(model)
        if why:
            raise ValueError(f"stability: method='shooting' cannot take this model: {why}; use method='hill'")
        try:
            return _by_shooting(model, system, Q, omega, tol, not forced)
        except _ShootingFailed as exc:
            raise ShootingError(f"stability: shooting from the HBM orbit at w = {omega:g} did not converge ({exc}); "
                               "use method='hill' or raise the harmonics") from None
    try:
        return _by_shooting(model, system, Q, omega, tol, not forced)
    except (_ShootingFailed, ValueError) as exc:
        return _by_hill(system, y, omega, xi, tol, not forced, message=f"shooting failed ({exc}); Hill's method used")


@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
def stability(solution: PeriodicSolution, method: str = "auto", *, tol: float = TOL) -> StabilityResult:
    """Floquet multipliers and stability of one periodic solution (module docstring).

    Parameters
    ----------
    solution : PeriodicSolution
        ``branch[i]``; its model must be attached (``branch.attach(model)`` after loading).
    method : {"auto", "hill", "shooting"}
    tol : float
        Unstable when ``max |mu| > 1 + tol`` (default 1e-4).

    Returns
    -------
    StabilityResult
    """
    if not isinstance(solution, PeriodicSolution):
        raise TypeError(f"stability: solution must be a femodes PeriodicSolution (branch[i]), got {type(solution).__name__}")
    method = _check_method(method, "stability")
    tol = _check_tol(tol, "stability")
    model = solution.model
    if model is None:
        raise ValueError("stability: the solution has no model (loaded from a file?); attach it with "
                         "branch.attach(model) first")
    forced = solution.kind == "forced"
    system = HBMSystem(model if forced else model.without_forcing(), solution.harmonics)
    y = system.join(solution.Q, solution.P)
    return _point_stability(model, system, y, solution.Q, solution.omega_truncated, solution.xi, method, tol, forced)


def annotate_branch(branch: Branch, problem, model: StructuralModel, *, method: str = "auto", tol: float = TOL,
                    newton: NewtonOptions | None = None, locate: bool | float = True) -> Branch:
    """Fill ``branch.stable``, ``branch.multipliers``, ``branch.bifurcations``: the multipliers of
    every point (module docstring), then the bifurcations between them
    (:func:`femodes.branch_stability.find_bifurcations`).

    ``problem`` is the :class:`ForcedResponseProblem` or :class:`NonlinearModeProblem` the
    branch was traced with; ``newton`` the corrector options of the located points; ``locate``
    as in :class:`StabilityOptions`.
    """
    opts = StabilityOptions(method=method, tol=tol, locate=locate)
    if not isinstance(problem, (ForcedResponseProblem, NonlinearModeProblem)):
        raise TypeError(f"annotate_branch: problem must be an HBM problem, got {type(problem).__name__}")
    method, tol = opts.method, opts.tol
    forced = isinstance(problem, ForcedResponseProblem)
    system = problem.system

    def point(x: np.ndarray, p: float, how: str | None = None) -> StabilityResult:
        u = problem.unpack(x, p)
        return _point_stability(model, system, u.y, u.Q, u.omega, u.xi, how or method, tol, forced)

    results = []
    start = time.perf_counter()
    last = start
    b = branch
    for i in range(len(b)):
        results.append(point(problem.pack(b.Q[i], b.P[i], b.omega_truncated[i], b.xi[i]), b.parameter[i]))
        now = time.perf_counter()
        if i == 0 and len(b) > 1:
            # the first point carries the set-up (reduction modes, factorisations): an upper bound
            log.info("stability: %d points, about %.3g s (first point %.3g s)", len(b), (now - start) * len(b),
                     now - start)
        elif now - last > PROGRESS_EVERY or i == len(b) - 1:
            log.info("stability: %d of %d points, %.3g s", i + 1, len(b), now - start)
            last = now
    bifs = find_bifurcations(branch, problem, results, point, tol=tol, newton=newton or NewtonOptions(atol=1e-9, max_iter=20),
                             locate=opts.locate)
    m = max((r.multipliers.size for r in results), default=0)
    mult = np.full((len(branch), m), np.nan + 0j)
    for i, r in enumerate(results):
        mult[i, : r.multipliers.size] = r.multipliers
    branch.set_stability(stable=[_is_stable(r.multipliers, tol, not forced) for r in results], multipliers=mult,
                         bifurcations=bifs, methods=[r.method for r in results], tol=tol)
    n_fb = sum(r.message != "" for r in results)
    if n_fb:
        log.info("stability: shooting failed at %d of %d points; Hill's method used there", n_fb, len(results))
    return branch
