"""What an error estimate can be told: :class:`AccuracyOptions` (the tuning of the estimators, with
the measurements behind each default) and the checks of the arguments of
:func:`~femodes.estimate_error` (``rtol``, ``max_harmonics``, ``method``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..solvers.checks import InputTypeError, InputValueError, is_real_number, show

__all__ = ["AccuracyOptions", "ESTIMATE_METHODS", "check_options", "refinement_options"]

#: Methods of :func:`~femodes.estimate_error`: "levels" (harmonic balance at other H), "shooting"
#: (the exact flow with rigid stops), "auto" (shooting where it applies, levels for the rest).
ESTIMATE_METHODS = ("auto", "levels", "shooting")


@dataclass(frozen=True, kw_only=True)
class AccuracyOptions:
    """Tuning of :func:`femodes.estimate_error` and of the analyses' ``rtol=`` (``dataclasses.replace`` it).
    The fields in the method: :doc:`/guide/accuracy`; their measurements: ``benchmarks/README_accuracy.md``.

    Parameters
    ----------
    rate_min, bracket_rate_max, same_point : float, default 1.5, 2.0, 1e-8
        Levels: the smallest contraction ratio per doubling of H used (``r / (r - 1)`` at most 3), the
        largest ratio for which the frequency is bracketed, the relative change of the same point.
    rtol_budget, rtol_min_seconds : float, default 10.0, 60.0
        ``rtol=`` stops its estimate after ``rtol_budget`` times the plain branch's time, at least
        ``rtol_min_seconds`` (:func:`rtol_time_limit`).
    min_fraction, walk_deadline : default 1/16, 3
        Walking a level: the smallest fraction of a branch step, and the Newton iterations after which
        a step that has not halved its residual is given up.
    split_gain, past_last, level_restarts, restart_min_points : default 0.75, 2, 4, 3
        Tracing a level: two traces if they pass at most ``split_gain`` of the contact points; stop
        ``past_last`` points after the last needed one; restart at most ``level_restarts`` times from a
        walked point followed by ``restart_min_points`` unsolved ones.
    level_points_per_point, level_points_slack : default 4, 100
        A level's trace stops past this many continuation points per branch point passed, plus the slack.
    shooting_auto_max_dofs, shooting_auto_max_work, shooting_auto_max_events : default 120, 1e6, 8
        ``Auto()`` shoots only models with at most that many DOFs with mass, modal terms evaluated in
        the probe run, and events at a contact.
    shooting_tol, shooting_step, shooting_max_iter : default 1e-11, 1e-7, 40
        A shooting solve stops at that residual, hyperplane value and relative frequency step, or
        after that many Newton iterations.
    shooting_stall, shooting_stall_alpha, shooting_max_correction, shooting_floor : default 3, 2^-8, 0.5, 1e-9
        Give up after that many successive steps cut below the alpha; a start state moved farther (relative)
        than the correction is another orbit; the floor of an exact limit's half-width.
    glancing_max, glancing_cos, shooting_clearance : float, default 3.0, 0.5, 0.1
        The exact orbit on a point's hyperplane is its counterpart if ``0 < kappa <= glancing_max`` or
        the exact curve crosses the plane at a cosine of at least ``glancing_cos``, and, for a point with
        contact force, if it touches an obstacle or comes within ``shooting_clearance`` of a gap of one.
    shooting_exact_after, shooting_fold_slack : default 3, 1e-6
        Trace the exact branch after that many points without an orbit; relative slack of a fold match.
    shooting_fold_search : bool, default True
        Locate the folds on the exact curve; False leaves them to the folds of the exact branch.
    grazing_points, fold_step_halvings : int, default 4, 4
        A lower fold that near a point without contact may be a grazing; halvings of a fold search step.
    """

    # -- the levels' estimate (estimate.PointLevels) --------------------------------------------
    #: A ratio below it means the levels are not yet in the asymptotic range (or diverge).
    rate_min: float = 1.5
    #: First order in 1/H (rigid impacts) has the asymptotic ratio 2, approached from below on the
    #: references (seed fold: 1.69, 1.81, 1.85 at levels 5-10-20 ... 20-40-80).
    bracket_rate_max: float = 2.0
    #: A point without contact: every level is the branch's own, up to the Newton tolerance.
    same_point: float = 1e-8
    # -- the time the analyses' rtol= allows ------------------------------------------------------
    #: A tolerance that cannot be met in that time is reported, not waited for (a many-contact blade
    #: at H = 10 ran for minutes without output).
    rtol_budget: float = 10.0
    #: Small models' branches take a fraction of a second while their finest levels take seconds (the
    #: free impact oscillator from H = 10: 0.1 s, then 1.4 s for levels up to 80): a machine's load
    #: must not decide whether such a tolerance is met.
    rtol_min_seconds: float = 60.0
    # -- walking a level along the branch (walk.py) -----------------------------------------------
    min_fraction: float = 1.0 / 16.0
    #: As a step of the continuation is (``ContinuationOptions.corrector_deadline``).
    walk_deadline: int = 3
    # -- tracing a level by continuation (level_trace.py) -----------------------------------------
    #: The second trace also walks the contact-free tail and restarts the step control. Seed's
    #: forced case at rtol 1e-3: level 80, 64 against 66 points with contact, took 138 continuation
    #: points in two traces against 103 in one; level 160, 39 against 66, took 134 against 196.
    split_gain: float = 0.75
    past_last: int = 2
    #: A walked point costs several hyperplane solves, a point of the continuation one corrector.
    level_restarts: int = 4
    restart_min_points: int = 3
    #: Every trace of the seed cases (H = 10, 20; rtol 1e-3, 1e-4) and of the bars with 10 and 20
    #: elements exceeds 4 per branch point by at most 48; ``cant20`` of README_accuracy (exact
    #: orbits that chatter) is stopped at level 80 after 177 points for 19 branch points, where it
    #: took 1272 points (269 s) without the stop.
    level_points_per_point: int = 4
    level_points_slack: int = 100
    # -- shooting: the exact flow with rigid stops (shooting.py, shooter.py, exact_fold.py) ------
    #: A run's dense algebra grows like n^3 (the FE bar of README_accuracy: 41 DOFs 6.2 s, 81 DOFs
    #: 44 s for about 50 points); larger models go to the levels, or are reduced by Craig-Bampton.
    shooting_auto_max_dofs: int = 120
    #: Samples times the state's size: the FE bar with 40 elements needs 1.9e4, a fine grid over the
    #: whole period 8e5; a stiff model whose impacts excite its fast modes pays the fine grid.
    shooting_auto_max_work: float = 1e6
    #: ``cant20`` chatters (its massless tip closes and opens 20 times within 0.1 time units) and
    #: Newton on its exact orbit stalls; the seed cases and the FE bars have one impact.
    shooting_auto_max_events: int = 8
    #: Newton converges quadratically: the frequency is then off by about the square of the step.
    shooting_tol: float = 1e-11
    shooting_step: float = 1e-7
    shooting_max_iter: int = 40
    #: No converged solve of the seed cases and the FE bars had two such steps in a row; failing ones
    #: had up to 23 (a failing solve costs up to 40 iterations of up to 21 runs each).
    shooting_stall: int = 3
    shooting_stall_alpha: float = 2.0 ** -8
    shooting_max_correction: float = 0.5
    #: The exact flow is exact up to round-off and the root tolerance of the impact times (4 eps);
    #: a solve leaves about the square of ``shooting_step``: a margin of 1e3 over both (the seed
    #: folds came out within 1e-14 of their references).
    shooting_floor: float = 1e-9
    glancing_max: float = 3.0
    #: In a tongue the frequency slopes say little (FE bar with a massless tip: kappa -0.2 to -0.8
    #: at cosines 0.5-0.95, crossings 1e-3 away); the points the seed cases reject have 0.11-0.43.
    glancing_cos: float = 0.5
    #: The cantilever with 3 % modal damping of README_accuracy (section 5): its rising side is far
    #: from the exact curve. The seed cases' first pass misses at most 2 points, the FE bars' none.
    shooting_exact_after: int = 3
    #: The fold search's half-widths are below 1e-6.
    shooting_fold_slack: float = 1e-6
    shooting_fold_search: bool = True
    #: Just above grazing the exact orbit comes within 1e-3 of the gap or less (the seed cases); the
    #: orbits without contact that shooting returned on the contact branch of a shallow arch
    #: (benchmarks/bench_arch.py, H = 7) stayed 13-100 % of the gap clear of the stop.
    shooting_clearance: float = 0.1
    #: Seed case 1: the lower fold is point 79, contact ends at point 81.
    grazing_points: int = 4
    fold_step_halvings: int = 4

    def __post_init__(self) -> None:
        for name, lo, hi, closed in (("rate_min", 1.0, math.inf, False), ("bracket_rate_max", 1.0, math.inf, False),
                                     ("min_fraction", 0.0, 1.0, True), ("split_gain", 0.0, math.inf, True),
                                     ("glancing_cos", 0.0, 1.0, True), ("shooting_stall_alpha", 0.0, 1.0, True)):
            _check_real(name, getattr(self, name), lo, hi, closed)
        for name in ("same_point", "rtol_budget", "rtol_min_seconds", "level_points_per_point",
                     "shooting_auto_max_work", "shooting_tol", "shooting_step", "shooting_max_correction",
                     "shooting_floor", "glancing_max", "shooting_fold_slack", "shooting_clearance"):
            _check_real(name, getattr(self, name), 0.0, math.inf, name == "glancing_max")
        for name, minimum in (("walk_deadline", 1), ("past_last", 0), ("level_restarts", 0),
                              ("restart_min_points", 1), ("level_points_slack", 0), ("shooting_auto_max_dofs", 0),
                              ("shooting_auto_max_events", 0), ("shooting_max_iter", 1), ("shooting_stall", 1),
                              ("shooting_exact_after", 0), ("grazing_points", 0), ("fold_step_halvings", 0)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < minimum:
                raise ValueError(f"AccuracyOptions: {name} must be an integer >= {minimum}, got {show(value)}")
        if not isinstance(self.shooting_fold_search, bool):
            raise ValueError("AccuracyOptions: shooting_fold_search must be a bool, got "
                             f"{show(self.shooting_fold_search)}")


def _check_real(name: str, value, lo: float, hi: float, closed_hi: bool) -> None:
    """``lo < value < hi`` (``<= hi`` if ``closed_hi``; infinity allowed only as a closed upper end)."""
    ok = is_real_number(value) and lo < value and (value <= hi if closed_hi else value < hi)
    if not ok or (math.isinf(value) and not (closed_hi and math.isinf(hi))):
        end = "]" if closed_hi else ")"
        raise ValueError(f"AccuracyOptions: {name} must be a number in ({lo:g}, {hi:g}{end}, got {show(value)}")


def refinement_options(rtol, max_harmonics, H: int) -> tuple[float | None, int]:
    """Checked ``(rtol, max_harmonics)`` (default ``8 H``) for a branch with ``H`` harmonics."""
    if rtol is not None:
        if isinstance(rtol, bool) or not isinstance(rtol, (int, float, np.floating, np.integer)) \
                or not 0.0 < float(rtol) < 0.5:
            raise InputValueError(f"rtol must be a relative tolerance in (0, 0.5), e.g. 1e-3; got {rtol!r}")
        rtol = float(rtol)
    if max_harmonics is None:
        return rtol, 8 * H
    if isinstance(max_harmonics, bool) or not isinstance(max_harmonics, (int, np.integer)) or max_harmonics < 2 * H:
        raise InputValueError(f"max_harmonics must be an integer >= 2 H = {2 * H} (the estimate's own "
                              f"finest level); got {max_harmonics!r}")
    return rtol, int(max_harmonics)


def check_options(options, name: str = "options") -> AccuracyOptions:
    """``options`` (default :class:`AccuracyOptions`) checked."""
    if options is None:
        return AccuracyOptions()
    if not isinstance(options, AccuracyOptions):
        raise InputTypeError(f"{name} must be a femodes.AccuracyOptions, got {type(options).__name__}")
    return options
