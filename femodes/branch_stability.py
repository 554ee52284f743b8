r"""Analyses layer: the bifurcations of a branch, from the Floquet multipliers of its points.

The multipliers of every point come from :mod:`femodes.floquet` (a callable here). A change in the
number of multipliers outside the unit circle between two points is a bifurcation; unless a
located fold sits there, it is located on the test function ``tau = |mu_(k)| - 1`` (the ``k``-th
largest modulus, ``k`` the larger count) over solutions corrected on the secant between the two
points (:func:`solve_on_secant`), and classified by the crossing multiplier: ``+1`` a branch
point, ``-1`` period doubling, a complex pair a Neimark-Sacker bifurcation; multipliers that jump
across the circle instead of crossing it are ``"nonsmooth"`` (a change of the contact pattern).

Location, by bracketing (``StabilityOptions(locate=True)``, the default): at most
:data:`LOCATE_SOLVES` = 2 solves on a smooth crossing, the first at the root of the polynomial
through ``tau`` at the two points and their neighbours, the second past the inverse quadratic
interpolation by :data:`STRADDLE`, so that the two fall on either side of the crossing. The
bifurcation is reported at the end of the final bracket on its unstable side, and
``Bifurcation.bracket`` holds the frequencies of the two solutions the sign change lies between
(an end where ``|tau| <=`` :data:`FTOL` is the crossing itself). A first solve within :data:`FLAT`
of the change looks like a jump: it is bisected up to :data:`JUMP_SOLVES` solves, and a bracket of
at most :data:`CHEAP_JUMP_BRACKET` of the segment, flat on both sides with ``|tau| >``
:data:`JUMP`, is ``"nonsmooth"``. Problems of at most :data:`PRECISE_MAX_UNKNOWNS` unknowns are
refined to :data:`PRECISE_XTOL` instead. ``locate=xtol`` (a number) refines by regula falsi until
the bracket is ``xtol`` of the segment (a jump is told apart at :data:`JUMP_BRACKET`);
``locate=False`` only brackets (``Bifurcation.located`` False). The costs:
:doc:`/guide/stability` (Bifurcations along a branch).

On a free (conservative) orbit a pair that collides at ``+-1`` and leaves the circle as a real pair
is a branch point (period doubling at ``-1``) even when it is found on its still-complex side
(:data:`COLLISION`); a branch point of a backbone is then located by the sign change of
``det [r_x, r_p; c^T]`` (:func:`branch_point_test`, shared with :func:`femodes.switch_branch`),
where the augmented Jacobian drops rank.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .hbm.problems import ForcedResponseProblem
from .results import Bifurcation, Branch
from .solvers import NewtonOptions, semismooth_newton
from .solvers.roots import illinois

__all__ = ["find_bifurcations", "significant", "crossing_kind", "solve_on_secant", "root_on_secant",
           "augmented_jacobian", "branch_point_test", "refine_branch_point", "LOCATE_SOLVES", "PRECISE_MAX_UNKNOWNS",
           "COLLISION", "BRANCH_POINT_DENSE_LIMIT"]

log = logging.getLogger(__name__)

#: Corrector and Hill solves spent on locating one bifurcation (``locate=True``; module docstring).
LOCATE_SOLVES = 2

#: ``locate=True`` on problems of at most this many unknowns refines every bifurcation to
#: :data:`PRECISE_XTOL` of the segment instead: a solve costs about a millisecond there (the
#: seed impact oscillator, 1 DOF, H = 10: 0.04 s for the branch, 0.30 s for the multipliers of
#: its 6 points by shooting, 0.10 s more to bracket its period doubling with two solves, 0.74 s
#: to refine it with 16), and the demo and case files print such bifurcations to six digits.
PRECISE_MAX_UNKNOWNS = 100

#: Bracket width (fraction of the segment) of a precise location.
PRECISE_XTOL = 1e-7

#: Solves spent on a change that looks like a jump (module docstring): bisections down to
#: :data:`CHEAP_JUMP_BRACKET` of the segment.
JUMP_SOLVES = 4

#: The second solve lands this fraction of its distance from the first beyond the interpolated
#: crossing (module docstring): an inverse quadratic step cuts the error of a smooth crossing by
#: far more than this factor, so the two solves straddle the crossing.
STRADDLE = 0.2

#: A first solve whose ``|tau|`` exceeds this fraction of the change of ``tau`` over the segment
#: is not near a smooth crossing where the interpolation put it: the second solve bisects.
SMOOTH_SHARE = 0.25

#: First solves stay this fraction of the segment away from its ends.
MARGIN = 0.02

#: ``|tau|`` at or below this is on the circle: an end of the segment there is the crossing.
FTOL = 1e-9

#: A located crossing whose test function ``|mu| - 1`` stays above this on both sides of a narrow
#: bracket is a jump (kind ``"nonsmooth"``), not a smooth crossing.
JUMP = 1e-3

#: Precise location (``locate=xtol``): bracket width (fraction of the segment between two branch
#: points) at which a jump is declared.
JUMP_XTOL = 1e-3

#: Precise location: a bracket of this fraction of the segment whose ends still differ by
#: :data:`JUMP_SHARE` of the test function's change over the whole segment (and both above
#: :data:`JUMP`) is a jump: a smooth crossing's change shrinks with its bracket.
JUMP_BRACKET = 1.0 / 32.0
JUMP_SHARE = 0.5

#: Location by bracketing: the widest bracket that can be told to hold a jump, and how close
#: (fraction of the change of ``tau`` over the segment) the values at every solve must still be
#: to those of the segment's ends on their sides (flat on both sides, all the change inside the
#: bracket: a smooth crossing would need 80 % of its change in an eighth of the segment). A smooth crossing where a multiplier pair collides (``tau`` has a kink) is not
#: flat on both sides (measured: 50 % of the change on one side, a forced Duffing pair).
CHEAP_JUMP_BRACKET = 0.125
FLAT = 0.1

#: On a free (conservative) orbit, a crossing multiplier within this distance of +1 or -1 is a
#: pair colliding there and leaving the circle as a real pair (a branch point, e.g. where an
#: internal-resonance tongue leaves a backbone, or a period doubling); the test function
#: ``|mu| - 1`` is flat on the circle, so the crossing is found on the side where the pair is
#: still complex (measured 0.999 +- 0.045j at a 2:1 tongue).
COLLISION = 0.1

#: Largest augmented Jacobian ``[r_x, r_p]`` (unknowns) whose determinant test locates a branch
#: point (dense; beyond it the crossing of the multipliers' test function is kept).
BRANCH_POINT_DENSE_LIMIT = 4000


def significant(mu: np.ndarray, free: bool) -> np.ndarray:
    """The multipliers that decide stability, largest modulus first: all of a forced orbit's; a
    free orbit's without its two trivial ones (the double +1 of phase and energy, a Jordan block
    whose computed pair splits by the square root of the solver tolerance, ~1e-5)."""
    mu = mu[np.isfinite(mu)]
    if free and mu.size >= 2:
        mu = mu[np.argsort(np.abs(mu - 1.0), kind="stable")[2:]]
    return mu[np.argsort(-np.abs(mu), kind="stable")]


def crossing_kind(mu: complex, all_mu: np.ndarray, free: bool = False) -> str:
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


def find_bifurcations(branch: Branch, problem, results: Sequence[Any], point: Callable[..., Any], *, tol: float,
                      newton: NewtonOptions, locate: bool | float = True) -> list[Bifurcation]:
    """The bifurcations of ``branch`` (module docstring), folds first in index order.

    ``results[i]`` holds the multipliers (``.multipliers``) and the method (``.method``) of point
    ``i``; ``point(x, p, method)`` computes them for a solution ``x`` at parameter ``p`` of
    ``problem`` (the problem the branch was traced with); ``tol`` the margin of ``|mu|`` above 1;
    ``newton`` the corrector options of the solutions between the points; ``locate`` as
    :class:`~femodes.StabilityOptions` takes it.
    """
    return _Finder(branch, problem, results, point, tol, newton, locate).run()


class _Finder:
    def __init__(self, branch: Branch, problem, results, point, tol: float, newton: NewtonOptions,
                 locate: bool | float):
        self.branch, self.problem, self.results, self.point = branch, problem, list(results), point
        self.tol, self.newton, self.locate = tol, newton, locate
        self.free = not isinstance(problem, ForcedResponseProblem)

    def count(self, mu: np.ndarray) -> int:
        return int(np.count_nonzero(np.abs(significant(mu, self.free)) > 1.0 + self.tol))

    def tau(self, mu: np.ndarray, k: int) -> float:
        """Test function ``|mu_(k)| - 1`` (``k``-th largest modulus)."""
        a = np.abs(significant(mu, self.free))
        return float(a[k - 1] - 1.0) if a.size >= k else -1.0

    def crossing(self, mu: np.ndarray, k: int) -> complex:
        m = significant(mu, self.free)
        return complex(m[k - 1]) if m.size >= k else complex(1.0)

    def z(self, i: int) -> np.ndarray:
        b = self.branch
        return np.append(self.problem.pack(b.Q[i], b.P[i], b.omega_truncated[i], b.xi[i]), b.parameter[i])

    def run(self) -> list[Bifurcation]:
        b, results = self.branch, self.results
        counts = [self.count(r.multipliers) for r in results]
        bifs = [self._fold(f) for f in b.folds]
        near_fold: set[int] = set()
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
            rising = counts[i + 1] > counts[i]
            if self.locate is False:
                bifs.append(self._bracketed(i, k, rising))
                continue
            log.info("stability: locating the change between points %d and %d", i, i + 1)
            if self.locate is not True:
                bif = self._refined(i, k, float(self.locate))
            elif self.problem.size <= PRECISE_MAX_UNKNOWNS:
                bif = self._refined(i, k, PRECISE_XTOL)
            else:
                bif = self._two_solves(i, k, rising)
            if bif is not None:
                bifs.append(bif)
        bifs.sort(key=lambda z: (z.index, z.parameter))
        return bifs

    def _fold(self, f: int) -> Bifurcation:
        b = self.branch
        return Bifurcation(kind="fold", index=int(f), omega=float(b.omega_truncated[f]), energy=float(b.energy[f]),
                           parameter=float(b.parameter[f]), multiplier=complex(1.0), Q=b.Q[f], P=b.P[f],
                           xi=float(b.xi[f]))

    def _bracketed(self, i: int, k: int, rising: bool) -> Bifurcation:
        """The change between points ``i`` and ``i + 1`` reported at the point on its unstable side
        (``locate=False``)."""
        j = i + 1 if rising else i
        r = self.results[j]
        b = self.branch
        crossing = self.crossing(r.multipliers, k)
        return Bifurcation(kind=crossing_kind(crossing, r.multipliers, self.free), index=int(i),
                           omega=float(b.omega_truncated[j]), energy=float(b.energy[j]), parameter=float(b.parameter[j]),
                           multiplier=complex(crossing), Q=np.array(b.Q[j]), P=np.array(b.P[j]), xi=float(b.xi[j]),
                           located=False, bracket=(float(b.omega_truncated[i]), float(b.omega_truncated[i + 1])))

    # -- location ------------------------------------------------------------------------------
    def _evaluator(self, i: int, k: int):
        """``tau(theta)`` on the secant from point ``i`` to ``i + 1`` (None where the corrector or
        the multipliers fail), and the dict of what it computed, ``theta -> (z, result)``."""
        za, zb = self.z(i), self.z(i + 1)
        method = self.results[i].method
        ends: dict[float, tuple[np.ndarray, Any]] = {0.0: (za, self.results[i]), 1.0: (zb, self.results[i + 1])}
        d = zb - za
        known = dict(self._neighbours(i, za, d))  # theta -> z, solutions projected on the secant

        def start(theta: float) -> np.ndarray:
            """The corrector's start: the polynomial through the 4 known solutions nearest to
            ``theta`` (Lagrange, in theta), on the hyperplane of ``theta``: the branch's curvature
            is in it, which the secant's own point lacks (measured on the damped backbone of
            examples/user_blade_3d.py: 21 Newton steps for its 7 solves, 25 from the secant)."""
            known.update({t: zt for t, (zt, _) in ends.items()})
            ts = sorted(known, key=lambda t: abs(t - theta))[:4]
            z = np.zeros_like(za)
            for a in ts:
                w = 1.0
                for b in ts:
                    if b != a:
                        w *= (theta - b) / (a - b)
                z += w * known[a]
            return z - (float(d @ (z - za)) / float(d @ d) - theta) * d

        def tau(theta: float) -> float | None:
            z = solve_on_secant(self.problem, za, zb, theta, self.newton, start=start(theta))
            if z is None:  # the interpolation misled Newton (a kink of the branch): the secant's point
                z = solve_on_secant(self.problem, za, zb, theta, self.newton)
            if z is None:
                return None
            try:
                r = self.point(z[:-1], z[-1], method)
            except (RuntimeError, ValueError):  # shooting lost the orbit between the points
                return None
            ends[theta] = (z, r)
            return self.tau(r.multipliers, k)

        return za, zb, tau, ends

    def _neighbours(self, i: int, za: np.ndarray, d: np.ndarray):
        """``(theta, z)`` of points ``i - 1`` and ``i + 2`` projected on the secant from ``za``
        along ``d``, those that fall outside the segment on their own side."""
        for j, outside in ((i - 1, lambda t: t < -MARGIN), (i + 2, lambda t: t > 1.0 + MARGIN)):
            if 0 <= j < len(self.branch):
                zj = self.z(j)
                t = float((zj - za) @ d / float(d @ d))
                if outside(t):
                    yield t, zj

    def _guess(self, i: int, k: int, fa: float, fb: float, za: np.ndarray, zb: np.ndarray) -> float:
        """The crossing on the secant (``theta`` in (0, 1)) from the polynomial through ``tau`` at
        points ``i``, ``i + 1`` and their neighbours projected on the secant (those of the same
        method that project outside the segment, in order); the secant's own root when it has no
        single root inside."""
        lin = fa / (fa - fb)
        d = zb - za
        dd = float(d @ d)
        th, f = [0.0, 1.0], [fa, fb]
        method = self.results[i].method
        for j, outside in ((i - 1, lambda t: t < -MARGIN), (i + 2, lambda t: t > 1.0 + MARGIN)):
            if 0 <= j < len(self.branch) and self.results[j].method == method:
                t = float((self.z(j) - za) @ d / dd)
                if outside(t):
                    th.append(t)
                    f.append(self.tau(self.results[j].multipliers, k))
        if len(th) == 2:
            return lin
        with np.errstate(all="ignore"):
            c = np.polyfit(np.asarray(th), np.asarray(f), len(th) - 1)
            roots = np.roots(c)
        inside = [float(r.real) for r in roots if abs(r.imag) <= 1e-12 * max(1.0, abs(r)) and 0.0 < r.real < 1.0]
        return inside[0] if len(inside) == 1 else lin

    def _two_solves(self, i: int, k: int, rising: bool) -> Bifurcation | None:
        """At most :data:`LOCATE_SOLVES` corrector and Hill solves (module docstring)."""
        za, zb, tau, ends = self._evaluator(i, k)
        fa, fb = self.tau(self.results[i].multipliers, k), self.tau(self.results[i + 1].multipliers, k)
        lo, hi, f_lo, f_hi = 0.0, 1.0, fa, fb

        def update(x: float, fx: float):
            nonlocal lo, hi, f_lo, f_hi
            if np.sign(fx) == np.sign(f_lo):
                lo, f_lo = x, fx
            else:
                hi, f_hi = x, fx

        change = abs(fb - fa)

        def flat(fx: float) -> bool:  # the value of the segment's end on its side (a jump's profile)
            return abs(fx - (fa if np.sign(fx) == np.sign(fa) else fb)) <= FLAT * change

        jump = failed = False
        if min(abs(fa), abs(fb)) > FTOL:
            x1 = min(max(self._guess(i, k, fa, fb, za, zb), MARGIN), 1.0 - MARGIN)
            f1 = tau(x1)
            if f1 is None:
                return self._bracketed(i, k, rising)
            update(x1, f1)
            if flat(f1):
                # a jump's profile: bisect while it stays one, until the bracket is narrow enough
                # to tell (at most JUMP_SOLVES)
                jump = True
                for _ in range(JUMP_SOLVES - 1):
                    if hi - lo <= CHEAP_JUMP_BRACKET:
                        break
                    x = 0.5 * (lo + hi)
                    fx = tau(x)
                    if fx is None:  # no solution to follow across it: a jump, as the precise location says
                        failed = True
                        break
                    update(x, fx)
                    if not flat(fx):
                        jump = False
                        break
            elif LOCATE_SOLVES >= 2 and abs(f1) > FTOL:
                width = hi - lo
                if abs(f1) > SMOOTH_SHARE * change:
                    x2 = 0.5 * (lo + hi)
                else:
                    x2 = _inverse_quadratic((0.0, x1, 1.0), (fa, f1, fb))
                    if not lo < x2 < hi:
                        x2 = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
                    x2 += math.copysign(STRADDLE * abs(x2 - x1), x2 - x1)
                x2 = min(max(x2, lo + MARGIN * width), hi - MARGIN * width)
                f2 = tau(x2)
                if f2 is not None:
                    update(x2, f2)
        # a jump: a narrow bracket whose ends both still hold (to FLAT of the change over the
        # segment) the values of the segment's ends on their sides
        jump = jump and min(abs(f_lo), abs(f_hi)) > JUMP and (hi - lo <= CHEAP_JUMP_BRACKET or failed)
        if min(abs(f_lo), abs(f_hi)) <= FTOL:  # an end on the circle is the crossing itself
            th = lo if abs(f_lo) <= abs(f_hi) else hi
            pair = (th, th)
        else:
            # the unstable end: the multiplier outside the circle there is the one that crossed
            th, pair = (hi if f_hi > 0 else lo), (lo, hi)
        return self._report(i, k, ends, th, pair, jump, za, zb)

    def _refined(self, i: int, k: int, xtol: float) -> Bifurcation | None:
        """Regula falsi (Illinois, bisecting whenever the bracket does not halve) on ``tau`` to a
        bracket of ``xtol`` of the segment, jumps told apart in passes (module docstring)."""
        za, zb, tau, ends = self._evaluator(i, k)
        fa, fb = self.tau(self.results[i].multipliers, k), self.tau(self.results[i + 1].multipliers, k)
        # in passes: a jump (the test function stays above JUMP on both sides) is told apart
        # once the bracket is JUMP_BRACKET of the segment wide and still holds most of the change
        # of the test function (a smooth crossing's change shrinks with the bracket), or else
        # once it is JUMP_XTOL wide; only a smooth crossing is refined to xtol
        opts: dict[str, Any] = dict(ftol=FTOL, margin=1e-3, bisect_if_slow=True)

        def small(br):
            return min(abs(br.f_lo), abs(br.f_hi)) <= JUMP

        br = illinois(tau, 0.0, 1.0, fa, fb, max_iter=40, xtol=max(JUMP_BRACKET, xtol), **opts)
        jump = not small(br) and abs(br.f_hi - br.f_lo) >= JUMP_SHARE * abs(fb - fa)
        if not jump and not small(br):
            br = illinois(tau, br.lo, br.hi, br.f_lo, br.f_hi, max_iter=max(1, 40 - br.nfev),
                          xtol=max(JUMP_XTOL, xtol), **opts)
        if small(br) and abs(br.f_lo) > FTOL and abs(br.f_hi) > FTOL:
            br = illinois(tau, br.lo, br.hi, br.f_lo, br.f_hi, max_iter=max(1, 40 - br.nfev), xtol=xtol, **opts)
        smooth = small(br)
        if smooth:
            th = br.lo if abs(br.f_lo) <= abs(br.f_hi) else br.hi
        else:
            th = br.hi if br.f_hi > 0 else br.lo  # the unstable side: its crossing multiplier is reported
        f_th = br.f_lo if th == br.lo else br.f_hi
        pair = (th, th) if abs(f_th) <= FTOL else (br.lo, br.hi)
        return self._report(i, k, ends, th, pair, not smooth, za, zb)

    def _report(self, i: int, k: int, ends: dict, th: float, pair: tuple[float, float], jump: bool,
                za: np.ndarray, zb: np.ndarray) -> Bifurcation:
        z, r = ends[th]
        u = self.problem.unpack(z[:-1], z[-1])
        crossing = self.crossing(r.multipliers, k)
        kind = "nonsmooth" if jump else crossing_kind(crossing, r.multipliers, self.free)
        bracket = tuple(float(self.problem.unpack(ends[t][0][:-1], ends[t][0][-1]).omega) for t in pair)
        if kind == "branch_point" and self.free and za.size <= BRANCH_POINT_DENSE_LIMIT:
            # a conservative pair colliding at +1: |mu| - 1 is flat on the side where it is still
            # complex, so its crossing is anywhere there; the branch point itself is where the
            # augmented Jacobian drops rank (located to round-off)
            zbp = refine_branch_point(self.problem, za, zb, self.newton)
            if zbp is not None:
                z = zbp
                u = self.problem.unpack(z[:-1], z[-1])
                bracket = (float(u.omega), float(u.omega))
        energy = float(self.problem.system.energy(u.y, u.omega)[0])
        return Bifurcation(kind=kind, index=int(i), omega=float(u.omega), energy=energy, parameter=float(z[-1]),
                           multiplier=complex(crossing), Q=np.array(u.Q), P=np.array(u.P), xi=float(u.xi),
                           bracket=(min(bracket), max(bracket)))


def _inverse_quadratic(x: Sequence[float], f: Sequence[float]) -> float:
    """The root of the inverse quadratic through ``(x_j, f_j)`` (NaN when two ``f`` coincide)."""
    (x0, x1, x2), (f0, f1, f2) = x, f
    try:
        return (x0 * f1 * f2 / ((f0 - f1) * (f0 - f2)) + x1 * f0 * f2 / ((f1 - f0) * (f1 - f2))
                + x2 * f0 * f1 / ((f2 - f0) * (f2 - f1)))
    except ZeroDivisionError:
        return math.nan


def solve_on_secant(problem, za: np.ndarray, zb: np.ndarray, theta: float, newton: NewtonOptions,
                    start: np.ndarray | None = None) -> np.ndarray | None:
    """The solution ``z = [x; p]`` of ``problem`` on the hyperplane through ``(1 - theta) za +
    theta zb`` normal to the secant ``zb - za`` (None if Newton fails): a point between two
    points of a branch, for locating what happens between them. Newton starts from ``start``
    (default: the secant's point)."""
    d = zb - za
    t = d / float(d @ d)
    zp = za + theta * d
    n = za.size - 1

    def fun(z):
        r, J, dr_dp = problem.residual(z[:n], z[n])
        return np.append(r, t @ (z - zp)), J.bordered(dr_dp[:, None], t[None, :n], np.array([[t[n]]]))

    res = semismooth_newton(fun, zp if start is None else start, options=newton)
    return res.x if res.success else None


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
