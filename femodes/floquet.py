r"""Analyses layer: stability of periodic solutions (Floquet multipliers) and bifurcations along branches.

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

Along a branch (``frequency_response(..., stability=True)``), a change in the number of
multipliers outside the circle between two points is a bifurcation; unless a located fold sits
there, it is located by regula falsi on the test function ``|mu_(k)| - 1`` (the ``k``-th largest
modulus, ``k`` the larger count) over solutions corrected on the secant between the points, and
classified by the crossing multiplier: ``+1`` a branch point, ``-1`` period doubling, a complex
pair a Neimark-Sacker bifurcation. On a free (conservative) orbit a pair that collides at
``+-1`` and leaves the circle as a real pair is a branch point (period doubling at ``-1``) even
when it is found on its still-complex side (:data:`COLLISION`); ``|mu| - 1`` is flat there, so a
branch point of a backbone is then located by the sign change of ``det [r_x, r_p; c^T]``
(:func:`branch_point_test`, shared with :func:`femodes.switch_branch`), where the augmented
Jacobian drops rank.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from typing import Any

import numpy as np

from .hbm.hill import hill_exponents
from .hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from .hbm.system import HBMSystem
from .laws import UnilateralContact
from .model import StructuralModel
from .results import Bifurcation, Branch, PeriodicSolution
from .solvers import NewtonOptions, semismooth_newton
from .solvers.roots import illinois
from .solvers.threads import limit_blas_threads
from .time.shooting import shoot, unsupported

__all__ = ["stability", "StabilityResult", "StabilityOptions", "ShootingError", "annotate_branch", "solve_on_secant",
           "METHODS"]

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

#: A located crossing whose test function ``|mu| - 1`` stays above this on both sides of a
#: narrow bracket (:data:`JUMP_BRACKET`, :data:`JUMP_XTOL`) is a jump (kind ``"nonsmooth"``), not a
#: smooth crossing (which is then refined to a bracket of 1e-7).
JUMP = 1e-3

#: Seconds between progress lines of a stability run along a branch.
PROGRESS_EVERY = 5.0

#: Bracket width (fraction of the segment between two branch points) at which a jump is declared.
JUMP_XTOL = 1e-3

#: A bracket of this fraction of the segment whose ends still differ by :data:`JUMP_SHARE` of the
#: test function's change over the whole segment (and both above :data:`JUMP`) is a jump: a
#: smooth crossing's change shrinks with its bracket.
JUMP_BRACKET = 1.0 / 32.0
JUMP_SHARE = 0.5


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
    locate : bool
        True (default): each change of stability between two points is located between them by
        regula falsi over solutions corrected on the secant, about 6 corrector and Hill solves
        for a jump of the multipliers and 5-15 for a smooth crossing, and classified there
        (``"nonsmooth"`` for a jump). False: bracketing only, at no cost beyond the points'
        multipliers: the bifurcation is reported at the point of the bracket on its unstable
        side (``Bifurcation.located`` False), classified by that point's crossing multiplier
        (a jump cannot be told from a crossing there). :func:`~femodes.switch_branch` locates
        the bifurcation itself in either case.
    """

    method: str = "auto"
    tol: float = TOL
    locate: bool = True

    def __post_init__(self):
        _check_method(self.method, "StabilityOptions")
        object.__setattr__(self, "tol", _check_tol(self.tol, "StabilityOptions"))
        if not isinstance(self.locate, (bool, np.bool_)):
            raise TypeError(f"StabilityOptions: locate must be True or False, got {self.locate!r}")

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


def _significant(mu: np.ndarray, free: bool) -> np.ndarray:
    """The multipliers that decide stability, largest modulus first: all of a forced orbit's; a
    free orbit's without its two trivial ones (the double +1 of phase and energy, a Jordan block
    whose computed pair splits by the square root of the solver tolerance, ~1e-5)."""
    mu = mu[np.isfinite(mu)]
    if free and mu.size >= 2:
        mu = mu[np.argsort(np.abs(mu - 1.0), kind="stable")[2:]]
    return mu[np.argsort(-np.abs(mu), kind="stable")]


def _is_stable(mu: np.ndarray, tol: float, free: bool) -> bool:
    m = _significant(mu, free)
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


# ------------------------------------------------------------------------------------------------
# Along a branch
# ------------------------------------------------------------------------------------------------
class _Annotator:
    """Multipliers at every point of a branch, and its bifurcations located between points."""

    def __init__(self, branch: Branch, problem, model: StructuralModel, method: str, tol: float,
                 newton: NewtonOptions, locate: bool = True):
        self.branch, self.problem, self.model = branch, problem, model
        self.method, self.tol, self.newton, self.locate = method, tol, newton, locate
        self.forced = isinstance(problem, ForcedResponseProblem)
        self.system = problem.system

    def at(self, x: np.ndarray, p: float, method: str | None = None) -> StabilityResult:
        u = self.problem.unpack(x, p)
        return _point_stability(self.model, self.system, u.y, u.Q, u.omega, u.xi, method or self.method, self.tol,
                                self.forced)

    def _outside(self, mu: np.ndarray) -> np.ndarray:
        return _significant(mu, not self.forced)

    def count(self, mu: np.ndarray) -> int:
        return int(np.count_nonzero(np.abs(self._outside(mu)) > 1.0 + self.tol))

    def tau(self, mu: np.ndarray, k: int) -> float:
        """Test function ``|mu_(k)| - 1`` (``k``-th largest modulus)."""
        a = np.abs(self._outside(mu))
        return float(a[k - 1] - 1.0) if a.size >= k else -1.0

    def crossing(self, mu: np.ndarray, k: int) -> complex:
        m = self._outside(mu)
        return complex(m[k - 1]) if m.size >= k else complex(1.0)

    def point(self, i: int) -> np.ndarray:
        b = self.branch
        return self.problem.pack(b.Q[i], b.P[i], b.omega_truncated[i], b.xi[i])

    def run(self):
        b = self.branch
        results = []
        start = time.perf_counter()
        last = start
        for i in range(len(b)):
            results.append(self.at(self.point(i), b.parameter[i]))
            now = time.perf_counter()
            if i == 0 and len(b) > 1:
                # the first point carries the set-up (reduction modes, factorisations): an upper bound
                log.info("stability: %d points, about %.3g s (first point %.3g s)", len(b), (now - start) * len(b),
                         now - start)
            elif now - last > PROGRESS_EVERY or i == len(b) - 1:
                log.info("stability: %d of %d points, %.3g s", i + 1, len(b), now - start)
                last = now
        counts = [self.count(r.multipliers) for r in results]
        bifs = [self._fold(f) for f in b.folds]
        near_fold = set()
        for f in b.folds:
            near_fold.update((f - 1, f))
        for i in range(len(b) - 1):
            if counts[i] == counts[i + 1] or i in near_fold:
                continue
            if results[i].method != results[i + 1].method:
                # "auto" fell back to Hill at one end: the two methods' multipliers differ by the
                # HBM's contact error, which is not a bifurcation
                log.info("stability: no bifurcation test between points %d and %d (%s vs %s)", i, i + 1,
                         results[i].method, results[i + 1].method)
                continue
            k = max(counts[i], counts[i + 1])
            if not self.locate:
                bifs.append(self._bracketed(i, k, results[i], results[i + 1], counts[i + 1] > counts[i]))
                continue
            log.info("stability: locating the change between points %d and %d", i, i + 1)
            bif = self._locate(i, k, results[i], results[i + 1])
            if bif is not None:
                bifs.append(bif)
        bifs.sort(key=lambda z: (z.index, z.parameter))
        return results, bifs

    def _fold(self, f: int) -> Bifurcation:
        b = self.branch
        return Bifurcation(kind="fold", index=int(f), omega=float(b.omega_truncated[f]), energy=float(b.energy[f]),
                           parameter=float(b.parameter[f]), multiplier=complex(1.0), Q=b.Q[f], P=b.P[f], xi=float(b.xi[f]))

    def _bracketed(self, i: int, k: int, ra: StabilityResult, rb: StabilityResult, rising: bool) -> Bifurcation:
        """The change between points ``i`` and ``i + 1`` reported at the point on its unstable side
        (``StabilityOptions(locate=False)``)."""
        j, r = (i + 1, rb) if rising else (i, ra)
        b = self.branch
        crossing = self.crossing(r.multipliers, k)
        return Bifurcation(kind=_kind(crossing, r.multipliers, not self.forced), index=int(i), omega=float(b.omega_truncated[j]),
                           energy=float(b.energy[j]), parameter=float(b.parameter[j]), multiplier=complex(crossing),
                           Q=np.array(b.Q[j]), P=np.array(b.P[j]), xi=float(b.xi[j]), located=False)

    def _locate(self, i: int, k: int, ra: StabilityResult, rb: StabilityResult) -> Bifurcation | None:
        """Regula falsi (Illinois, bisecting whenever the bracket does not halve) on
        ``tau(theta) = |mu_(k)| - 1`` along the secant from point ``i`` to ``i + 1``.

        A bracket that shrinks to :data:`JUMP_BRACKET` of the segment with ``|tau|`` above
        :data:`JUMP` on both sides and its ends still :data:`JUMP_SHARE` of the change over the
        segment apart, or to :data:`JUMP_XTOL` with ``|tau|`` above :data:`JUMP`, is a jump of the
        multipliers across the circle, not a smooth crossing: kind ``"nonsmooth"`` (a change of
        the contact pattern, e.g. grazing)."""
        b = self.branch
        za = np.append(self.point(i), b.parameter[i])
        zb = np.append(self.point(i + 1), b.parameter[i + 1])
        ends = {0.0: (za, ra), 1.0: (zb, rb)}

        def tau(theta: float) -> float | None:
            z = solve_on_secant(self.problem, za, zb, theta, self.newton)
            if z is None:
                return None
            try:
                r = self.at(z[:-1], z[-1], ra.method)
            except (RuntimeError, ValueError):  # shooting lost the orbit between the points
                return None
            ends[theta] = (z, r)
            return self.tau(r.multipliers, k)

        # in passes: a jump (the test function stays above JUMP on both sides) is told apart
        # once the bracket is JUMP_BRACKET of the segment wide and still holds most of the change
        # of the test function (a smooth crossing's change shrinks with the bracket), or else
        # once it is JUMP_XTOL wide; only a smooth crossing is refined to 1e-7 (a jump took ~27
        # Hill solves to 1e-7, then ~13 to 1e-3, now ~6)
        opts: dict[str, Any] = dict(ftol=1e-9, margin=1e-3, bisect_if_slow=True)
        fa, fb = self.tau(ra.multipliers, k), self.tau(rb.multipliers, k)

        def small(br):
            return min(abs(br.f_lo), abs(br.f_hi)) <= JUMP

        br = illinois(tau, 0.0, 1.0, fa, fb, max_iter=40, xtol=JUMP_BRACKET, **opts)
        jump = not small(br) and abs(br.f_hi - br.f_lo) >= JUMP_SHARE * abs(fb - fa)
        if not jump and not small(br):
            br = illinois(tau, br.lo, br.hi, br.f_lo, br.f_hi, max_iter=max(1, 40 - br.nfev), xtol=JUMP_XTOL, **opts)
        if small(br) and abs(br.f_lo) > 1e-9 and abs(br.f_hi) > 1e-9:
            br = illinois(tau, br.lo, br.hi, br.f_lo, br.f_hi, max_iter=max(1, 40 - br.nfev), xtol=1e-7, **opts)
        smooth = small(br)
        th = br.lo if abs(br.f_lo) <= abs(br.f_hi) else br.hi
        if not smooth:
            th = br.hi if br.f_hi > 0 else br.lo  # the unstable side: its crossing multiplier is reported
        z, r = ends[th]
        u = self.problem.unpack(z[:-1], z[-1])
        crossing = self.crossing(r.multipliers, k)
        kind = _kind(crossing, r.multipliers, not self.forced) if smooth else "nonsmooth"
        if kind == "branch_point" and not self.forced and za.size <= BRANCH_POINT_DENSE_LIMIT:
            # a conservative pair colliding at +1: |mu| - 1 is flat on the side where it is still
            # complex, so its crossing is anywhere there; the branch point itself is where the
            # augmented Jacobian drops rank
            zbp = refine_branch_point(self.problem, za, zb, self.newton)
            if zbp is not None:
                z = zbp
                u = self.problem.unpack(z[:-1], z[-1])
        energy = float(self.system.energy(u.y, u.omega)[0])
        return Bifurcation(kind=kind, index=int(i), omega=float(u.omega), energy=energy, parameter=float(z[-1]),
                           multiplier=complex(crossing), Q=np.array(u.Q), P=np.array(u.P), xi=float(u.xi))


def solve_on_secant(problem, za: np.ndarray, zb: np.ndarray, theta: float, newton: NewtonOptions) -> np.ndarray | None:
    """The solution ``z = [x; p]`` of ``problem`` on the hyperplane through ``(1 - theta) za +
    theta zb`` normal to the secant ``zb - za`` (None if Newton fails): a point between two
    points of a branch, for locating what happens between them."""
    d = zb - za
    t = d / float(d @ d)
    zp = za + theta * d
    n = za.size - 1

    def fun(z):
        r, J, dr_dp = problem.residual(z[:n], z[n])
        return np.append(r, t @ (z - zp)), J.bordered(dr_dp[:, None], t[None, :n], np.array([[t[n]]]))

    res = semismooth_newton(fun, zp, options=newton)
    return res.x if res.success else None


#: On a free (conservative) orbit, a crossing multiplier within this distance of +1 or -1 is a
#: pair colliding there and leaving the circle as a real pair (a branch point, e.g. where an
#: internal-resonance tongue leaves a backbone, or a period doubling); the test function
#: ``|mu| - 1`` is flat on the circle, so the crossing is found on the side where the pair is
#: still complex (measured 0.999 +- 0.045j at a 2:1 tongue).
COLLISION = 0.1



#: Largest augmented Jacobian ``[r_x, r_p]`` (unknowns) whose determinant test locates a branch
#: point (dense; beyond it the crossing of the multipliers' test function is kept).
BRANCH_POINT_DENSE_LIMIT = 4000


def augmented_jacobian(problem, z: np.ndarray) -> np.ndarray:
    """``A = [r_x, r_p]`` of ``problem`` at ``z = [x; p]`` (dense, ``n x (n + 1)``)."""
    _, J, dr_dp = problem.residual(z[:-1], z[-1])
    return np.hstack([J.toarray(), np.asarray(dr_dp, dtype=float)[:, None]])


def branch_point_test(problem, z: np.ndarray, c: np.ndarray) -> tuple[float, float]:
    """``(sign, log|det|)`` of ``[A(z); c^T]``: ``c . a(z)``, with ``a`` the signed maximal minors of
    ``A = [r_x, r_p]``, which span its null space on a regular branch. It vanishes at a simple
    branch point and changes sign there; at a fold ``A`` keeps full rank and the test its sign
    (Keller 1977; Allgower and Georg 2003, sec. 8.1)."""
    return np.linalg.slogdet(np.vstack([augmented_jacobian(problem, z), c[None, :]]))


def refine_branch_point(problem, za: np.ndarray, zb: np.ndarray, newton: NewtonOptions) -> np.ndarray | None:
    """The branch point between the branch points ``za`` and ``zb``: regula falsi on
    ``det [A(z); c^T] / |det [A(za); c^T]|`` (``c`` the secant) over solutions on the secant; None
    when the test has the same sign at both ends."""
    c = zb - za
    c = c / (np.linalg.norm(c) or 1.0)
    s0, l0 = branch_point_test(problem, za, c)
    s1, l1 = branch_point_test(problem, zb, c)
    if s0 != 0 and s1 != 0 and s0 == s1:
        return None

    def test(z: np.ndarray) -> float:
        sg, ld = branch_point_test(problem, z, c)
        return float(sg * math.exp(ld - l0))  # linear in theta near a simple branch point

    return root_on_secant(problem, za, zb, test, float(s0), float(s1 * math.exp(l1 - l0)), newton,
                          max_iter=60, ftol=1e-12, xtol=1e-13)


def root_on_secant(problem, za: np.ndarray, zb: np.ndarray, test, fa: float, fb: float, newton: NewtonOptions,
                   **illinois_options) -> np.ndarray:
    """The solution between the branch points ``za`` and ``zb`` where ``test(z)`` changes sign:
    Illinois regula falsi (:func:`~femodes.solvers.roots.illinois`, ``illinois_options``) on
    ``theta`` over the solutions on the secant (:func:`solve_on_secant`), ``fa``, ``fb`` the
    values at the ends; the end of the final bracket with the smaller ``|test|``."""
    points = {0.0: za, 1.0: zb}

    def f(theta: float) -> float | None:
        z = solve_on_secant(problem, za, zb, theta, newton)
        if z is None:
            return None
        points[theta] = z
        return test(z)

    br = illinois(f, 0.0, 1.0, fa, fb, **illinois_options)
    return points[br.lo if abs(br.f_lo) <= abs(br.f_hi) else br.hi]


def _kind(mu: complex, all_mu: np.ndarray, free: bool = False) -> str:
    """Bifurcation kind from the crossing multiplier: a complex one whose conjugate is also a
    multiplier crosses as a pair (Neimark-Sacker) unless, on a free orbit, it is within
    :data:`COLLISION` of +-1; otherwise it is real (Hill's multipliers of a contact orbit carry an
    imaginary error that breaks the conjugate symmetry) and its sign tells period doubling (-1)
    from a branch point (+1)."""
    scale = max(abs(mu), 1.0)
    if free and min(abs(mu - 1.0), abs(mu + 1.0)) <= COLLISION:
        return "period_doubling" if mu.real < 0 else "branch_point"
    if abs(mu.imag) > 1e-8 * scale:
        partner = np.min(np.abs(all_mu[np.isfinite(all_mu)] - np.conj(mu)))
        if partner <= 1e-6 * scale:
            return "neimark_sacker"
    return "period_doubling" if mu.real < 0 else "branch_point"


def annotate_branch(branch: Branch, problem, model: StructuralModel, *, method: str = "auto", tol: float = TOL,
                    newton: NewtonOptions | None = None, locate: bool = True) -> Branch:
    """Fill ``branch.stable``, ``branch.multipliers``, ``branch.bifurcations`` (module docstring).

    ``problem`` is the :class:`ForcedResponseProblem` or :class:`NonlinearModeProblem` the
    branch was traced with; ``newton`` the corrector options of the located points; ``locate``
    as in :class:`StabilityOptions`.
    """
    opts = StabilityOptions(method=method, tol=tol, locate=locate)
    if not isinstance(problem, (ForcedResponseProblem, NonlinearModeProblem)):
        raise TypeError(f"annotate_branch: problem must be an HBM problem, got {type(problem).__name__}")
    method, tol = opts.method, opts.tol
    ann = _Annotator(branch, problem, model, method, tol, newton or NewtonOptions(atol=1e-9, max_iter=20),
                     opts.locate)
    results, bifs = ann.run()
    m = max((r.multipliers.size for r in results), default=0)
    mult = np.full((len(branch), m), np.nan + 0j)
    for i, r in enumerate(results):
        mult[i, : r.multipliers.size] = r.multipliers
    branch.set_stability(stable=[ann.count(r.multipliers) == 0 for r in results], multipliers=mult,
                         bifurcations=bifs, methods=[r.method for r in results], tol=tol)
    n_fb = sum(r.message != "" for r in results)
    if n_fb:
        log.info("stability: shooting failed at %d of %d points; Hill's method used there", n_fb, len(results))
    return branch
