"""The analyses' ``rtol=`` (:func:`meet_tolerance`): with complementarity contacts one estimate with
``rtol``, which refines the levels' brackets where they are too wide; smooth branches (exponential
convergence) computed again with ``2 H`` while a point misses ``rtol``. Either within a time limit
of a multiple of the plain branch's own time (:func:`rtol_time_limit`), and with a warning that
says where ``rtol`` is not met, and why.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from .methods import ErrorMethod
from ..results import ERROR_METHODS, Branch
from ..solvers import NewtonOptions
from ..solvers.checks import entry_point
from .estimate import estimate_error
from .options import AccuracyOptions, check_options, refinement_options

__all__ = ["meet_tolerance", "rtol_time_limit"]

log = logging.getLogger(__name__)


@entry_point("rtol_time_limit")
def rtol_time_limit(plain_seconds: float, options: AccuracyOptions | None = None) -> float:
    """Seconds the analyses' ``rtol=`` gives its error estimate after a plain branch that took
    ``plain_seconds``: ``max(rtol_budget * plain_seconds, rtol_min_seconds)`` of ``options``
    (default :class:`AccuracyOptions`: 10 times, at least 60 s)."""
    options = check_options(options)
    return max(options.rtol_budget * float(plain_seconds), options.rtol_min_seconds)


def meet_tolerance(branch: Branch, rtol: float, max_harmonics: int | None, rerun, *, projection=None,
                   newton: NewtonOptions | None = None, method: ErrorMethod | None = None, time_limit: float | None = None,
                   options: AccuracyOptions | None = None) -> Branch:
    """``rtol=`` of :func:`femodes.frequency_response` and :func:`femodes.nonlinear_mode`.

    With complementarity contacts (algebraic convergence): :func:`estimate_error` with ``rtol``,
    which brackets the converged frequency by extrapolation and adds levels where the bracket is
    too wide. Smooth branches (exponential convergence): the estimate of the branch's own ``H``;
    while some point misses ``rtol`` the whole branch is computed again with ``2 H``
    (``rerun(H)``), up to ``max_harmonics``. ``options`` go to every :func:`estimate_error`.
    """
    H = branch.harmonics.n_harmonics
    rtol, max_harmonics = refinement_options(rtol, max_harmonics, H)
    if rtol is None:
        raise ValueError("meet_tolerance: rtol must be given")
    if len(branch) < 2:
        log.warning("accuracy: the branch has %d point(s) (%s); no error estimate for rtol", len(branch),
                    branch.message)
        return branch
    deadline = None if time_limit is None else time.perf_counter() + time_limit

    def left() -> float | None:
        return None if deadline is None else max(deadline - time.perf_counter(), 1e-3)

    if "complementarity" in branch.contacts.kinds:
        branch = estimate_error(branch, rtol=rtol, max_harmonics=max_harmonics, projection=projection,
                                newton=newton, method=method, time_limit=left(), options=options)
        _warn_unmet(branch, max_harmonics)
        return branch
    while True:
        branch = estimate_error(branch, rtol=rtol, projection=projection, newton=newton, method=method,
                                time_limit=left(), options=options)
        H = branch.harmonics.n_harmonics
        # the estimate of 2 H needs level 4 H; a branch with a caveat (not the family asked for) meets rtol at no H
        if branch.accuracy.met.all() or branch.accuracy.caveat or 4 * H > max_harmonics:
            _warn_unmet(branch, max_harmonics)
            return branch
        if deadline is not None and time.perf_counter() > deadline:
            log.warning("accuracy: rtol = %g not met with H = %d, and its time limit (%.3g s) has passed: the "
                        "branch with H = %d is not computed", rtol, H, time_limit, 2 * H)
            _warn_unmet(branch, max_harmonics)
            return branch
        log.info("accuracy: %d point(s) above rtol = %g with H = %d; again with H = %d",
                 int((~branch.accuracy.met).sum()), rtol, H, 2 * H)
        branch = rerun(2 * H)


def _warn_unmet(branch: Branch, max_harmonics: int) -> None:
    """A warning that says where ``rtol`` is not met (points, folds and why), if anywhere."""
    acc = branch.accuracy
    miss = ~acc.met
    if not miss.any():
        return
    if acc.caveat:  # not the family asked for: no point is converged, whatever its error
        log.warning("accuracy: rtol = %g is met at no point: %s", acc.rtol, acc.caveat)
        return
    # per method: its name in the fold list, and why its points miss rtol
    words = {"doubling": ("levels", f"by the levels (bracket or estimate wider than rtol up to H = {max_harmonics}, "
                                    "or levels that do not contract)"),
             "shooting": ("exact orbit", "by the exact orbit (the point's error above rtol)"),
             "failed": ("no estimate", "without an estimate"),
             "truncation": ("truncation", "folds of the truncation (none in the limit)"),
             "none": ("not estimated", "whose harmonic truncation was not estimated")}
    counts = {k: int(np.sum(miss & (acc.method == k))) for k in ERROR_METHODS}
    folds = [f"w = {float(branch.omega[i]):.6g} ({words[str(acc.method[i])][0]})" for i in branch.folds if miss[i]]
    log.warning("accuracy: rtol = %g not met at %d of %d points%s: %s; branch.accuracy.met tells which",
                acc.rtol, int(miss.sum()), len(branch), f", including the folds at {', '.join(folds)}" if folds else "",
                "; ".join(f"{n} {words[k][1]}" for k, n in counts.items() if n))
