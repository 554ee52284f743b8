r"""Analyses layer: stability of periodic solutions (Floquet multipliers), at one point and along branches.

A periodic orbit is asymptotically stable when all its Floquet multipliers ``mu`` lie inside the
unit circle; here *stable* means ``max |mu| <= 1 + tol`` (the trivial multipliers of free orbits,
exactly 1, and round-off stay stable). Two independent methods give the multipliers, as strategy objects of
:mod:`femodes.stability_methods`: Hill's method on the harmonic balance Jacobian
(:class:`~femodes.stability_methods.Hill`), event-driven shooting with saltation matrices
(:class:`~femodes.stability_methods.Shooting`), and :class:`~femodes.stability_methods.Auto`,
which shoots where shooting is the reference and affordable.

Along a branch (``frequency_response(..., stability=True)``, :func:`annotate_branch`), the
multipliers of every point are computed here, and a change in their number outside the circle
between two points is a bifurcation, bracketed, located and classified by
:mod:`femodes.branch_stability` (by default with two to four corrector and Hill solves, its
accuracy stated in ``Bifurcation.bracket``).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any

import numpy as np

from .branch_stability import (BRANCH_POINT_DENSE_LIMIT, COLLISION, augmented_jacobian, branch_point_test,
                               find_bifurcations, refine_branch_point, root_on_secant, significant, solve_on_secant)
from .hbm.hill import COARSE
from .hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from .hbm.system import HBMSystem
from .model import StructuralModel
from .results import Branch, PeriodicSolution
from .results.branch import fill_in_place
from .solvers import NewtonOptions
from .solvers.checks import InputTypeError, InputValueError, entry_point
from .solvers.threads import limit_blas_threads
from .stability_methods import (AUTO_MAX_STIFFNESS, MAX_CORRECTION, METHODS, Auto, Hill, Orbit, ShootingError,
                                StabilityMethod, StabilityResult, as_stability_method, by_name, checked_lead,
                                describe_unconverged, harmonic_check, is_stable)

# the location helpers live in femodes.branch_stability; they are re-exported here, where
# switch_branch and scripts import them from
__all__ = ["stability", "StabilityResult", "StabilityOptions", "ShootingError", "annotate_branch", "solve_on_secant",
           "root_on_secant", "refine_branch_point", "branch_point_test", "augmented_jacobian", "COLLISION",
           "BRANCH_POINT_DENSE_LIMIT", "METHODS", "AUTO_MAX_STIFFNESS", "MAX_CORRECTION"]

log = logging.getLogger(__name__)

#: Default tolerance on ``|mu| - 1`` above which an orbit is unstable.
TOL = 1e-4

#: Seconds between progress lines of a stability run along a branch.
PROGRESS_EVERY = 5.0


@dataclasses.dataclass(frozen=True)
class StabilityOptions:
    """Stability along a branch: ``stability=StabilityOptions(...)`` of the analyses
    (``stability=True`` is ``StabilityOptions()``; ``stability=Hill()`` is
    ``StabilityOptions(method=Hill())``).

    Attributes
    ----------
    method : StabilityMethod
        How the multipliers of each point are computed: a strategy of
        :mod:`femodes.stability_methods` (default :class:`~femodes.stability_methods.Auto`). The
        names ``"auto"``, ``"hill"``, ``"shooting"`` are deprecated spellings.
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
    check : bool
        True (default): Hill's truncation check where a verdict is made (the points unstable by a
        complex or negative multiplier, and both ends of every change): the same orbits' Hill
        problems with the perturbation cut to ``floor(0.75 H)`` harmonics, one warning for the
        verdicts that change (:func:`~femodes.stability_methods.harmonic_check`,
        ``Branch.stability_unconverged``), at about 0.42 of a point's Hill solve each. False
        skips it.
    """

    method: StabilityMethod = dataclasses.field(default_factory=Auto)
    tol: float = TOL
    locate: bool | float = True
    check: bool = True

    @entry_point("StabilityOptions")
    def __post_init__(self):
        object.__setattr__(self, "method", as_stability_method(self.method))
        object.__setattr__(self, "tol", _check_tol(self.tol))
        if not isinstance(self.check, (bool, np.bool_)):
            raise InputTypeError(f"check must be True or False (Hill's truncation check), got {self.check!r}")
        object.__setattr__(self, "check", bool(self.check))
        loc = self.locate
        if isinstance(loc, (bool, np.bool_)):
            object.__setattr__(self, "locate", bool(loc))
        elif isinstance(loc, (int, float, np.integer, np.floating)) and 0.0 < float(loc) < 1.0:
            object.__setattr__(self, "locate", float(loc))
        else:
            raise InputTypeError(f"locate must be True, False or a bracket width xtol in (0, 1) "
                                 f"(a fraction of the segment between two points), got {loc!r}")

    @classmethod
    def parse(cls, stability: Any) -> StabilityOptions | None:
        """``stability=`` of an analysis: False or None (no stability), True (the defaults), a
        strategy of :mod:`femodes.stability_methods`, or a :class:`StabilityOptions` (a method
        name is a deprecated spelling of its strategy)."""
        if stability is False or stability is None:
            return None
        if stability is True:
            return cls()
        if isinstance(stability, cls):
            return stability
        if isinstance(stability, str) and stability not in METHODS:
            raise InputValueError(f"stability must be True, False, a strategy of femodes.stability_methods "
                                  f"(Auto(), Hill(), Shooting()) or a femodes.StabilityOptions, got {stability!r}")
        return cls(method=as_stability_method(stability, "stability"))


def _check_tol(tol: Any) -> float:
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"tol must be a number (the margin of |mu| above 1), got {tol!r}")
    if not 0 <= tol < 1:
        raise InputValueError(f"tol must be in [0, 1) (the margin of |mu| above 1), got {tol!r}")
    return float(tol)


@entry_point("stability")
@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
def stability(solution: PeriodicSolution, method: StabilityMethod | None = None, *, tol: float = TOL) -> StabilityResult:
    """Floquet multipliers and stability of one periodic solution (module docstring).

    Parameters
    ----------
    solution : PeriodicSolution
        ``branch[i]``; its model must be attached (``branch.attach(model)`` after loading).
    method : StabilityMethod, optional
        A strategy of :mod:`femodes.stability_methods`; default
        :class:`~femodes.stability_methods.Auto` (a method name is a deprecated spelling).
    tol : float
        Unstable when ``max |mu| > 1 + tol`` (default 1e-4).

    Returns
    -------
    StabilityResult
    """
    if not isinstance(solution, PeriodicSolution):
        raise TypeError(f"stability: solution must be a femodes PeriodicSolution (branch[i]), got {type(solution).__name__}")
    method = Auto() if method is None else as_stability_method(method)
    tol = _check_tol(tol)
    model = solution.model
    if model is None:
        raise ValueError("stability: the solution has no model (loaded from a file?); attach it with "
                         "branch.attach(model) first")
    forced = solution.kind == "forced"
    system = HBMSystem(model if forced else model.without_forcing(), solution.harmonics)
    y = system.join(solution.Q, solution.P)
    orbit = Orbit(model, system, y, solution.Q, solution.omega_truncated, solution.xi, forced)
    res = harmonic_check(orbit, method(orbit, tol))
    if res.unconverged(tol, not forced):
        log.warning("stability: Hill's verdict is not converged in the harmonics: the largest multiplier but for "
                    "real positive ones is %.4g with the perturbation truncated to H = %d harmonics and %.4g with %d. "
                    "Raise the harmonics of the analysis, or check this orbit with "
                    "fm.stability(solution, fm.stability_methods.Shooting())",
                    checked_lead(res.multipliers, not forced), solution.harmonics.n_harmonics,
                    res.coarse, int(COARSE * solution.harmonics.n_harmonics))
    return res


def annotate_branch(branch: Branch, problem, model: StructuralModel, *, method: StabilityMethod | None = None,
                    tol: float = TOL,
                    newton: NewtonOptions | None = None, locate: bool | float = True, check: bool = True) -> Branch:
    """``branch`` with ``stable``, ``multipliers``, ``bifurcations`` (a new branch; for this release
    ``branch`` is filled too, :func:`~femodes.results.branch.fill_in_place`): the multipliers of every point (module docstring), then the bifurcations between them
    (:func:`femodes.branch_stability.find_bifurcations`).

    ``problem`` is the :class:`ForcedResponseProblem` or :class:`NonlinearModeProblem` the
    branch was traced with; ``newton`` the corrector options of the located points; ``locate``
    and ``check`` as in :class:`StabilityOptions`; ``method`` a strategy (default
    :class:`~femodes.stability_methods.Auto`).
    """
    opts = StabilityOptions(method=Auto() if method is None else method, tol=tol, locate=locate, check=check)
    if not isinstance(problem, (ForcedResponseProblem, NonlinearModeProblem)):
        raise TypeError(f"annotate_branch: problem must be an HBM problem, got {type(problem).__name__}")
    chosen: StabilityMethod = opts.method
    tol = opts.tol
    forced = isinstance(problem, ForcedResponseProblem)
    system = problem.system

    def orbit(x: np.ndarray, p: float) -> Orbit:
        u = problem.unpack(x, p)
        return Orbit(model, system, u.y, u.Q, u.omega, u.xi, forced)

    def orbit_of(i: int) -> Orbit:
        """The orbit of the branch's point ``i``."""
        return orbit(problem.pack(b.Q[i], b.P[i], b.omega_truncated[i], b.xi[i]), b.parameter[i])

    def point(x: np.ndarray, p: float, how: str | None = None) -> StabilityResult:
        """The multipliers at a solution ``x`` by the branch's strategy; :class:`Auto` takes the method
        ``how`` names (the one a neighbouring point used), so that a bifurcation is located with
        the method that found it."""
        strategy = by_name(how) if how and isinstance(chosen, Auto) else chosen
        return strategy(orbit(x, p), tol)

    results = []
    start = time.perf_counter()
    last = last_point = start
    b = branch
    failed_time = 0.0
    for i in range(len(b)):
        results.append(chosen(orbit_of(i), tol))
        now = time.perf_counter()
        if results[-1].message:  # Auto's shooting failed there
            failed_time += now - last_point
        if isinstance(chosen, Auto) and chosen.gives_up(failed_time):
            # one method along the branch: a bifurcation is only looked for between points of the same one
            log.info("stability: shooting failed at %d of the first %d points (%.3g s); Hill's method along the whole "
                     "branch", sum(r.message != "" for r in results), i + 1, failed_time)
            chosen = Hill()
            results = [chosen(orbit_of(j), tol) for j in range(i + 1)]
            now = time.perf_counter()
        last_point = now
        if i == 0 and len(b) > 1:
            # the first point carries the set-up (reduction modes, factorisations): an upper bound
            log.info("stability: %d points, about %.3g s (first point %.3g s)", len(b), (now - start) * len(b),
                     now - start)
        elif now - last > PROGRESS_EVERY or i == len(b) - 1:
            log.info("stability: %d of %d points, %.3g s", i + 1, len(b), now - start)
            last = now
    bifs = find_bifurcations(branch, problem, results, point, tol=tol, newton=newton or NewtonOptions(atol=1e-9, max_iter=20),
                             locate=opts.locate)
    checked: list[int] = []
    bad: list[dict] = []
    if opts.check:
        results, checked, bad = _check_harmonics(results, orbit_of, tol, forced)
    m = max((r.multipliers.size for r in results), default=0)
    mult = np.full((len(branch), m), np.nan + 0j)
    for i, r in enumerate(results):
        mult[i, : r.multipliers.size] = r.multipliers
    annotated = branch.with_stability(stable=[is_stable(r.multipliers, tol, not forced) for r in results],
                                      multipliers=mult, bifurcations=bifs, methods=[r.method for r in results], tol=tol,
                                      # Hill's truncation check, kept with the branch (summary.txt reports it)
                                      checked=len(checked), unconverged=bad)
    _warn_uncertain(results, tol, forced)
    n_fb = sum(r.message != "" for r in results)
    if n_fb:
        log.info("stability: shooting failed at %d of %d points; Hill's method used there", n_fb, len(results))
    fill_in_place(branch, annotated)  # the legacy of this release: the branch given is filled too
    return annotated


def _check_harmonics(results: list, orbit, tol: float, forced: bool) -> tuple[list, list[int], list[dict]]:
    """Hill's truncation check (:func:`~femodes.stability_methods.harmonic_check`) at the points
    where a verdict is made on the multipliers it compares (real positive ones left out,
    :func:`~femodes.stability_methods.checked_lead`): those unstable by them, and both ends of every
    change; one warning lists the points whose verdict is not converged in the harmonics
    (``orbit(i)`` the :class:`Orbit` of point ``i``). Returns the results, the points checked and
    a record of each flagged one (``index``, ``modulus`` at H, ``coarse``:
    :attr:`~femodes.results.Branch.stability_unconverged`)."""
    # the largest modulus of the multipliers it compares (real positive ones left out), and verdicts on it
    lead = [checked_lead(r.multipliers, not forced) for r in results]
    unstable = [m > 1.0 + tol for m in lead]
    at = {i for i, r in enumerate(results) if r.method == "hill" and unstable[i]}
    at |= {j for i in range(len(results) - 1) if unstable[i] != unstable[i + 1] for j in (i, i + 1)
           if results[j].method == "hill"}
    if not at:
        return results, [], []
    start = time.perf_counter()
    out = list(results)
    for i in sorted(at):
        out[i] = harmonic_check(orbit(i), results[i])
    bad = [{"index": i, "modulus": lead[i], "coarse": out[i].coarse} for i in sorted(at)
           if out[i].unconverged(tol, not forced)]
    log.info("stability: Hill's truncation check at %d points, %.3g s", len(at), time.perf_counter() - start)
    if bad:
        shown = describe_unconverged(bad, 6)
        log.warning("stability: at %d of %d points checked, Hill's verdict changes when the perturbation is truncated "
                    "to %d%% of the harmonics (largest |mu| but for real positive ones, at H / at the coarser truncation: "
                    "%s): those verdicts "
                    "are not converged in the harmonics. Raise the harmonics, or check those points with "
                    "fm.stability(branch[i], fm.stability_methods.Shooting())", len(bad), len(at), int(100 * COARSE),
                    shown)
    return out, sorted(at), bad


def _warn_uncertain(results, tol: float, forced: bool) -> None:
    """One warning when the estimated error of reduced Hill solves could flip the verdict of a
    point: its leading multiplier within that error of ``1 + tol``."""
    near, worst = [], 0.0
    for i, r in enumerate(results):
        m = significant(r.multipliers, not forced)
        err = r.error if np.isfinite(r.error) else 0.0
        if m.size and err > 0 and abs(abs(m[0]) - 1.0 - tol) <= err:
            near.append(i)
            worst = max(worst, err)
    if near:
        shown = ", ".join(map(str, near[:8])) + (", ..." if len(near) > 8 else "")
        log.warning("stability: at %d of %d points (%s) the leading multiplier lies within the estimated error of "
                    "Hill's reduced problem (up to %.2g in |mu|) of the stability limit, so their verdict is uncertain. "
                    "The reduction holds at most half the model's DOFs: a reduced model with more modes "
                    "(craig_bampton(model, n_modes)) lets it grow; or check those points with "
                    "fm.stability(branch[i], fm.stability_methods.Shooting())", len(near), len(results), shown, worst)
