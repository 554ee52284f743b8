"""The error estimate of a branch (:func:`estimate_error`): the estimators of :mod:`.protocol` in
turn, shooting where it applies (:func:`shooting_unsupported`), the levels for the rest, within a
time limit; the result attached as ``branch.accuracy`` (:class:`~femodes.results.ErrorEstimate`,
with the contact quality of every point).
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..nonsmooth_modes import family_caveat
from ..results import Branch, ErrorEstimate
from ..results.branch import fill_in_place
from ..solvers import NewtonOptions
from ..solvers.checks import entry_point
from ..solvers.threads import limit_blas_threads
from .extrapolation import estimate_levels
from .ladder import Ladder, OutOfTime, ladder_for
from .levels import Levels
from .methods import ErrorMethod, as_error_method
from .options import AccuracyOptions, check_options, refinement_options
from .protocol import PointErrors

__all__ = ["estimate_error"]

log = logging.getLogger(__name__)


@entry_point("estimate_error")
@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
def estimate_error(branch: Branch, *, rtol: float | None = None, max_harmonics: int | None = None, projection=None,
                   newton: NewtonOptions | None = None, method: ErrorMethod | None = None, time_limit: float | None = None,
                   options: AccuracyOptions | None = None) -> Branch:
    """Attach the estimated error of every point of ``branch`` (``branch.error_estimate``).

    Each point is solved again with further harmonics (levels ``H, 2H, 4H``, or ``H, 2H + 1, 4H + 2``
    for ``H < 4``: :func:`~femodes.accuracy.estimate_levels`) on the hyperplane normal to the branch,
    and the error of level ``H`` is ``|X_2H - X_H| r / (r - 1)`` with the observed ratio ``r``; with
    complementarity contacts the frequency error is at least the distance to the far end of the
    extrapolation bracket. With ``rtol``, points whose bracket is wider are refined by levels ``4 H``,
    ``8 H``... up to ``max_harmonics``. The method and its cost: :doc:`/guide/accuracy`.

    Parameters
    ----------
    branch : Branch
        From :func:`femodes.frequency_response` or :func:`femodes.nonlinear_mode`, with its model attached.
    rtol : float, optional
        Requested relative accuracy of the frequency (``0 < rtol < 0.5``);
        :attr:`~femodes.results.ErrorEstimate.met` tells which points meet it.
    max_harmonics : int, optional
        Largest level ``rtol`` may add (default ``8 H``; at least ``2 H``).
    projection, newton : optional
        The projection the branch was computed with (default exact); the corrector's NewtonOptions.
    method : ErrorMethod, optional
        A strategy of :mod:`femodes.error_methods`: ``Levels()`` (above), ``Shooting()`` (the exact orbits
        of the flow with rigid stops; forced branches of linear models with unilateral contacts only,
        else ``ValueError``) or ``Auto()`` (default: shooting where it applies, else the levels).
    time_limit : float, optional
        Seconds after which the estimate stops (checked between points); the points left get none
        (method ``"failed"``) and a warning.
    options : AccuracyOptions, optional
        Tuning of the estimators (default :class:`~femodes.AccuracyOptions`).

    Returns
    -------
    Branch
        A new branch: ``branch`` with :attr:`~femodes.Branch.accuracy` (an
        :class:`~femodes.results.ErrorEstimate`); for this release ``branch`` itself is filled too
        (:func:`~femodes.results.branch.fill_in_place`). It covers the harmonic truncation only
        (``accuracy.covers``); a mesh share the branch had is kept. A backbone past grazing
        (:func:`femodes.nonsmooth_modes.family_caveat`) gets ``accuracy.caveat`` and meets ``rtol`` at
        no point; a point whose level has no orbit near it gets no estimate (method ``"failed"``).
    """
    lad = ladder_for(branch, projection, newton)
    H = branch.harmonics.n_harmonics
    rtol, max_harmonics = refinement_options(rtol, max_harmonics, H)
    method = as_error_method(method)
    options = check_options(options)
    if time_limit is not None:
        if isinstance(time_limit, bool) or not isinstance(time_limit, (int, float, np.integer, np.floating)) \
                or not time_limit > 0:
            raise ValueError(f"estimate_error: time_limit must be a positive number of seconds or None, got "
                             f"{time_limit!r}")
        lad.deadline = time.perf_counter() + float(time_limit)
    started = time.perf_counter()
    n = len(branch)
    errors = PointErrors.empty(n, "complementarity" in branch.contacts.kinds, estimate_levels(H)[0][-1])
    todo = method.shoot(lad, errors, projection, options)
    out_of_time = False
    if todo.any():
        try:
            Levels(options, rtol, max_harmonics).estimate(lad, errors, todo)
        except OutOfTime:
            out_of_time = True
    if out_of_time:
        _warn_out_of_time(lad, errors, time_limit, time.perf_counter() - started, options)
    pen, ten = branch.contact_quality()
    kind = np.where(np.isfinite(errors.omega) | (errors.method == "truncation"), errors.method, "failed")
    # a mesh estimate already attached (femodes.estimate_mesh_error) does not depend on H: kept
    old = branch.accuracy
    mesh = {} if old is None or old.mesh is None else {"mesh": old.mesh, "mesh_method": old.mesh_method}
    new = branch.with_accuracy(ErrorEstimate(omega=errors.omega, amplitude=errors.amplitude, penetration=pen, tension=ten,
                                      harmonics=np.full(n, H), rate=errors.rate, method=kind.astype(str), rtol=rtol,
                                      omega_limit=errors.omega_limit, omega_limit_error=errors.omega_limit_error,
                                      finest=errors.finest, caveat=family_caveat(branch),
                                      amplitude_limit=errors.amplitude_limit,
                                      amplitude_limit_error=errors.amplitude_limit_error, **mesh))
    fill_in_place(branch, new)  # the legacy of this release: the branch given is filled too
    return new


def _warn_out_of_time(lad: Ladder, errors: PointErrors, time_limit: float, elapsed: float,
                      options: AccuracyOptions) -> None:
    missing = int(np.count_nonzero(~np.isfinite(errors.omega) & (errors.method != "truncation")))
    done = ", ".join(f"H = {k} in {v:.3g} s" if np.isfinite(v) else f"H = {k} unfinished"
                     for k, v in lad.level_times.items())
    log.warning("accuracy: the error estimate stopped at its time limit (%.3g s, after %.3g s; levels: %s): "
                "%d of %d points have no estimate (method 'failed'). The finer harmonic levels of this branch "
                "cost far more than the branch; give estimate_error a larger time_limit, or fewer harmonics "
                "or contacts (the rtol= of the analyses allows %g times the branch's own time, at least %g s)",
                float(time_limit), elapsed, done or "none finished", missing, len(lad.branch),
                options.rtol_budget, options.rtol_min_seconds)
