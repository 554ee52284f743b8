"""The shooting estimator (:class:`Shooting`): forced branches of linear models whose only contacts
are rigid stops, on DOFs with mass (impacts) or massless DOFs (the contact closes and opens), get
the ``H -> inf`` limit itself instead of an extrapolation: the exact orbit on each point's
hyperplane (:class:`~.shooter.Shooter`), each from its predecessor's orbit, and at a fold the
exact fold (:func:`~.exact_fold.exact_fold`). Just above grazing the exact curve crosses a point's
hyperplane obliquely or backward (``kappa`` outside ``(0, glancing_max]`` and a crossing cosine
below ``glancing_cos``): that crossing is no counterpart of the point, the exact orbit at the
point's own frequency is (its error is then in the amplitude). Seed cases at H = 20: 4 of 94 and
8 of 68 points are taken so. ``fm.error_methods.Auto()`` leaves to the levels a model with too many DOFs with
mass, or whose probe run (one period from the point with the largest contact force) is too costly
or chatters (:class:`~.options.AccuracyOptions`, ``shooting_auto_*``).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..hbm.harmonics import Harmonics
from ..results import Branch
from ..time.exact import LinearImpactFlow, exact_flow_unsupported
from .exact_branch import ExactBranchCache
from .exact_fold import exact_fold
from .ladder import Ladder
from .options import AccuracyOptions
from .points import contact_force_peak, near_fold, without_contact
from .protocol import PointErrors, orbit_amplitudes
from .shooter import Shooter

__all__ = ["GLANCING", "Shooting", "shoot_branch", "stays_clear", "shooting_unsupported", "shooting_unsupported_for"]

log = logging.getLogger(__name__)

#: Marks a point whose exact crossing is no counterpart (:meth:`~.shooter.Shooter.glancing`).
GLANCING = "glancing"


class Shooting:
    """The exact orbits of the flow with rigid stops on the points' hyperplanes (an
    :class:`~.protocol.Estimator`). It takes the whole branch (each orbit starts from its
    predecessor's) and leaves the points without an orbit, and the folds the fold search does not
    locate, to the next estimators. ValueError if the flow cannot be built, or with ``auto`` if the
    model is too large, its probe run too costly or chattering (:meth:`check_auto`)."""

    def __init__(self, exact: ExactBranchCache, options: AccuracyOptions, auto: bool = False):
        self.exact, self.options, self.auto = exact, options, auto

    def estimate(self, lad: Ladder, errors: PointErrors, todo: np.ndarray) -> np.ndarray:
        branch, opts = lad.branch, self.options
        probe = LinearImpactFlow(lad.model, float(np.min(branch.omega_truncated)))
        if self.auto:
            self.check_auto(lad, probe)
        n = len(branch)
        H = branch.harmonics.n_harmonics
        free = without_contact(branch)
        todo = np.zeros(n, dtype=bool)
        # points without contact force: the linear response, which H harmonics solve exactly
        errors.omega[free] = errors.amplitude[free] = errors.omega_limit_error[free] = opts.shooting_floor
        errors.omega_limit[free] = branch.omega_truncated[free]
        errors.rate[free] = math.inf
        errors.finest[free] = H
        errors.method[free] = "shooting"
        sh = Shooter(lad, opts, probe)
        solved = shoot_branch(sh, self.exact, opts)
        for i in sorted(i for i, r in solved.items() if r is None):
            solved[i] = start_from_exact(sh, self.exact, i, opts)
        hk = Harmonics(8 * H)  # the exact orbit's displacement to 8 H harmonics: the error includes the tail
        for i, r in solved.items():
            if r is None:
                todo[i] = True
                continue
            if r is GLANCING:  # no counterpart on the exact curve, and no orbit at the point's frequency
                errors.method[i] = "failed"  # either: not estimated (the levels' ratios are erratic just above
                errors.finest[i] = 0  # grazing)
                continue
            w = r[1]
            if i in branch.folds and (self.exact.traced and self.exact.branch() is not None
                                      or not opts.shooting_fold_search):
                todo[i] = True  # the exact branch is there: its folds, without the fold search (ExactFolds)
                continue
            if i in branch.folds:
                fold = exact_fold(sh, i, r, opts)
                if fold is None:
                    todo[i] = True
                    continue
                w, half, amplitudes, amplitude_error = fold  # the fold orbit's (none at a grazing)
            else:
                half = max(r[4] / abs(w), opts.shooting_floor)
                amplitudes, amplitude_error = orbit_amplitudes(r[3]), None
            errors.record_exact(lad, i, w, half, r[3].coefficients(hk.n_harmonics)[0], hk, amplitudes=amplitudes,
                                amplitude_error=amplitude_error)
        log.info("accuracy: shooting: %d runs of the exact flow for %d points", sh.runs, len(solved))
        return todo

    def check_auto(self, lad: Ladder, probe: LinearImpactFlow) -> None:
        """ValueError if ``auto`` should leave the branch to the levels: more DOFs with mass than
        ``shooting_auto_max_dofs``, or a probe run (:func:`probe_run`) that evaluates more than
        ``shooting_auto_max_work`` modal terms or has more than ``shooting_auto_max_events``
        events at one contact."""
        opts = self.options
        if probe.I.size > opts.shooting_auto_max_dofs:
            raise ValueError(f"the model has {probe.I.size} DOFs with mass; the exact flow's dense modal algebra (cost "
                             f"~ n^3 per run) is left to models of at most {opts.shooting_auto_max_dofs} (reduce the "
                             "model with fm.craig_bampton, which keeps the contact DOFs, or ask for method=fm.error_methods.Shooting())")
        run = probe_run(lad, probe, opts)
        work = float(run.samples) * 2 * probe.I.size
        if work > opts.shooting_auto_max_work:
            raise ValueError(f"the exact flow's event search evaluated {work:.3g} modal terms over one period of the "
                             f"point with the largest contact force (a stiff model); more than "
                             f"{opts.shooting_auto_max_work:g}")
        per_contact = np.bincount([e[1] for e in run.impacts + run.switches], minlength=len(probe.dofs))
        if per_contact.max(initial=0) > opts.shooting_auto_max_events:
            j = int(np.argmax(per_contact))
            raise ValueError(f"the exact flow from the point with the largest contact force has {int(per_contact[j])} "
                             f"events at contact {j} in one period (chattering: Newton on the exact orbit does not "
                             f"converge there); more than {opts.shooting_auto_max_events}")


def probe_run(lad: Ladder, flow: LinearImpactFlow, options: AccuracyOptions):
    """One run of ``flow`` over one period from the branch's point with the largest contact force
    at its most open phase: its event search's samples (times the state's size: the modal terms
    evaluated) are the cost of a run, which a stiff model drives up (the search refines to the
    fastest mode near events, and everywhere where impacts excite the fast modes); its events
    show an orbit that chatters."""
    branch = lad.branch
    i = int(np.argmax(contact_force_peak(branch)))
    x0, theta0 = Shooter(lad, options, flow).start(i)
    omega = float(branch.omega_truncated[i])
    return flow.at(omega).run(x0, theta0 / omega)


def shoot_branch(sh: Shooter, exact: ExactBranchCache, options: AccuracyOptions) -> dict:
    """Exact orbits on the hyperplanes of the branch's points with contact, each from its
    predecessor's (moved by the branch's step), else (after ``options.shooting_exact_after``
    failures) from the exact branch's crossing, else from the point itself, else the linear
    orbit, else (a second pass, backward) from its successor's; ``{i: (x0, w, theta0, run,
    step, J)}``, None where none was found, :data:`GLANCING` where the crossing is no
    counterpart and the point's own frequency has no orbit either."""
    branch = sh.branch
    free = without_contact(branch)
    out: dict = {}
    prev = None
    failures = 0
    for i in range(len(branch)):
        if free[i]:
            prev = None
            continue
        r = sh.solve(i, guess=sh.warm(i, prev)) if prev is not None else None
        if r is None and failures >= options.shooting_exact_after:  # the exact branch's crossing first
            r = start_from_exact(sh, exact, i, options, check=False)
        if r is None:
            r = sh.solve(i)
        if r is None:
            r = sh.linear(i)
        failures += r is None
        out[i] = r
        prev = r[:3] + (i,) if r is not None else None
    for i in sorted((i for i, r in out.items() if r is None), reverse=True):  # from the successor's orbit
        nxt = out.get(i + 1)
        if nxt is not None:
            out[i] = sh.solve(i, guess=sh.warm(i, nxt[:3] + (i + 1,))) or sh.solve_from(i, i + 1, nxt)
    for i, r in out.items():
        if r is not None and stays_clear(sh, i, r, options):
            out[i] = None
        elif r is not None and not near_fold(branch, i):
            out[i] = counterpart(sh, i, r, options)
            if out[i] is GLANCING:  # the exact orbit at the point's own frequency instead
                at_w = sh.at_frequency(i)
                if at_w is not None and not stays_clear(sh, i, at_w, options):
                    log.info("accuracy: point %d: the exact orbit at its frequency w = %.6g instead", i,
                             branch.omega_truncated[i])
                    out[i] = at_w
    return out


def stays_clear(sh: Shooter, i: int, r, options: AccuracyOptions) -> bool:
    """Whether the exact orbit ``r`` found for point ``i`` (a point with contact force) touches no
    obstacle and stays more than ``options.shooting_clearance`` of every gap clear of it: the orbit
    without contact, another branch, not the point's counterpart (just above grazing the exact
    orbit may miss an obstacle that the truncated series touches, by far less). Logged."""
    run = r[3]
    if run.touches:
        return False
    flow = sh.flow
    t = np.linspace(run.t0, run.t1, 257)
    q = run.displacement(t)[:, flow.dofs]
    reach = np.max(q, axis=0)  # the contact DOFs' largest approach to their obstacles
    scale = np.maximum(np.abs(flow.gaps), np.max(np.abs(q), axis=0))
    clear = float(np.min((flow.gaps - reach) / np.where(scale > 0.0, scale, 1.0)))
    if clear <= options.shooting_clearance:
        return False
    log.info("accuracy: point %d: the exact orbit found (w = %.6g) touches no obstacle and stays %.0f %% of the "
             "gap clear of it: the orbit without contact, not this point's counterpart", i, r[1], 100.0 * clear)
    return True


def start_from_exact(sh: Shooter, exact: ExactBranchCache, i: int, options: AccuracyOptions, check: bool = True):
    """The orbit on point ``i``'s hyperplane from the exact branch's crossing (as
    :meth:`~.shooter.Shooter.solve`, or None; the exact branch traced if it is not yet);
    ``check``: :func:`counterpart` (:func:`shoot_branch` checks its points itself)."""
    eb = exact.branch()
    if eb is None:
        return None
    for k in exact.crossings(i, sh.plane(i)):
        r = sh.solve(i, guess=(eb.states[k].copy(), float(eb.omega[k]), 0.0))
        if r is not None and not stays_clear(sh, i, r, options):
            log.info("accuracy: point %d: exact orbit from the exact branch's crossing at w = %.6g", i, eb.omega[k])
            return r if near_fold(sh.branch, i) or not check else counterpart(sh, i, r, options)
    return None


def counterpart(sh: Shooter, i: int, r, options: AccuracyOptions):
    """``r``, or :data:`GLANCING` if the exact curve crosses point ``i``'s hyperplane obliquely or
    backward (:meth:`~.shooter.Shooter.glancing`, :meth:`~.shooter.Shooter.crossing_cosine`)."""
    kappa = sh.glancing(i, r)
    if not 0.0 < kappa <= options.glancing_max:
        cos = sh.crossing_cosine(i, r)
        if cos < options.glancing_cos:
            log.info("accuracy: point %d: the exact curve crosses its hyperplane obliquely or backward "
                     "(kappa = %.3g, outside (0, %g]; cos = %.3g): no counterpart", i, kappa, options.glancing_max, cos)
            return GLANCING
    return r


def shooting_unsupported(branch: Branch, projection=None) -> str:
    """Why the shooting estimator cannot take ``branch`` (``""`` if it can): it needs a forced
    branch (period one) of a linear model whose only contacts are rigid stops
    (:func:`femodes.time.exact.exact_flow_unsupported`), computed with the exact projection."""
    if branch.kind != "forced":
        return "nonlinear modes are compared at the same energy (levels only)"
    if branch.model is None:
        return "the branch has no model"
    return shooting_unsupported_for(branch.model, branch.harmonics, projection)


def shooting_unsupported_for(model, harmonics, projection=None) -> str:
    """:func:`shooting_unsupported` of the forced branch that ``model`` would give on ``harmonics``
    (checked by :func:`femodes.frequency_response` before it runs, for ``error_method=fm.error_methods.Shooting()``)."""
    if harmonics.subharmonic != 1:
        return "sub-harmonic branch"
    if projection is not None and type(projection).__name__ != "ExactProjection":
        return "the branch is computed with a sampled projection"
    return exact_flow_unsupported(model)
