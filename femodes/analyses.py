"""Analyses layer: wire a model into an HBM problem, run the continuation, wrap the result.

The one module that sees both the problems (``femodes.hbm``) and the generic solvers
(``femodes.solvers``). Running the continuation with progress, checkpoints and resume
(``checkpoint=femodes.Checkpoint(path, resume=True)``) is :func:`femodes.runs.run_continuation`.
"""

from __future__ import annotations

import dataclasses
import logging
import time
import math
import os
import warnings
from collections.abc import Callable

import numpy as np

from .analysis_inputs import (check_continuation_options, check_harmonics, check_model, check_span, commensurate_modes,
                              largest_unknown, resonant_harmonics, start_vector, warn_rigid_body, warn_undamped)
from .hbm.harmonics import Harmonics
from .hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from .model import StructuralModel
from .results import Branch, ContactInfo
from .runs import checkpoint_spec, model_fingerprint, run_continuation, shows_progress, warn_short_of_span
from .store import Checkpoint
from .solvers import ContinuationOptions, NewtonOptions, continuation, semismooth_newton
from .solvers.checks import entry_point, user_stacklevel
from .solvers.threads import limit_blas_threads
from .accuracy import AccuracyOptions, check_options, meet_tolerance, refinement_options, rtol_time_limit
from .accuracy.methods import ErrorMethod, as_error_method
from .floquet import StabilityOptions, annotate_branch
from .stability_methods import StabilityMethod
from .nonsmooth_modes import PeriodDriven, continue_past_grazing
from .static_contact import StaticContactResult, static_contact  # its own module; importable from here too

__all__ = ["frequency_response", "frequency_response_options", "nonlinear_mode", "nonlinear_mode_options", "static_contact", "StaticContactResult",
           "branch_from_continuation", "model_fingerprint"]

log = logging.getLogger(__name__)


def branch_from_continuation(problem, result, *, kind: str, model: StructuralModel, meta: dict | None = None) -> Branch:
    """Wrap a :class:`~femodes.solvers.ContinuationResult` of an HBM problem into a Branch."""
    s = problem.system
    n_pts = result.x.shape[0]
    omega = np.empty(n_pts)
    Q = np.empty((n_pts, s.h.n_coef, s.n))
    P = np.empty((n_pts, s.h.n_coef, s.n_uc))
    energy = np.empty(n_pts)
    xi = np.empty(n_pts)
    for i in range(n_pts):
        u = problem.unpack(result.x[i], result.p[i])
        omega[i], Q[i], P[i], xi[i] = u.omega, u.Q, u.P, u.xi
        energy[i] = s.energy(u.y, u.omega)[0]
    return Branch(
        kind=kind, harmonics=s.h, contacts=ContactInfo.from_system(s), omega=omega, Q=Q, P=P, energy=energy, xi=xi,
        residual_norm=result.residual_norm, nit=result.nit, parameter=result.p, folds=result.folds,
        success=result.success, status=result.status, message=result.message, model=model,
        meta={"projection": type(s.projection).__name__, **(meta or {})},  # what estimate_error must use again
    )


@entry_point("frequency_response")
@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
@shows_progress
def frequency_response(
    model: StructuralModel,
    omega: tuple[float, float],
    harmonics: Harmonics | int,
    *,
    options: ContinuationOptions | None = None,
    x0: np.ndarray | None = None,
    projection=None,
    progress: bool | Callable = False,
    checkpoint: str | os.PathLike | Checkpoint | None = None,
    stability: bool | StabilityMethod | StabilityOptions = False,
    rtol: float | None = None,
    max_harmonics: int | None = None,
    error_method: ErrorMethod | None = None,
    error_options: AccuracyOptions | None = None,
) -> Branch:
    """Forced frequency-response curve by HBM and pseudo-arclength continuation.

    Solves ``M q'' + C q' + K q + f_nl(q) = f cos(w t) - w_c p`` from ``omega[0]`` to ``omega[1]``, through folds.

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        With forcing; contacts and nonlinear springs as declared.
    omega : (float, float)
        Start and end frequencies (rad/s); the branch may run downwards.
    harmonics : Harmonics or int
    options, x0 : ContinuationOptions, ndarray, optional
        Step control, Newton options, callback; initial guess at ``omega[0]`` (default: the linear response).
    projection : ExactProjection or SampledProjection, optional
        How ``max(0, .)`` of the contact laws is projected on the harmonics: exactly (default) or
        sampled (``femodes.hbm.SampledProjection()``, only for comparison).
    progress : bool or callable
        ``True`` shows femodes' INFO records (a line per point, the stability pass, ``rtol``'s levels),
        on stderr if logging is not configured; a callable gets every accepted ``ContinuationPoint``.
    checkpoint : str, PathLike or femodes.Checkpoint, optional
        Final branch file (``.npz`` or ``.h5``), journaled point by point; ``Checkpoint(path, resume=True)``
        continues a run, a plain path never overwrites one (:doc:`/howto/checkpoints`).
    stability : bool, StabilityMethod or StabilityOptions
        Floquet stability of every point and the bifurcations between points: False (default) none, True
        the defaults of :class:`~femodes.StabilityOptions`, or a strategy of :mod:`femodes.stability_methods`.
    rtol : float, optional
        Requested relative accuracy of the frequency against the converged (``H -> inf``) answer; the
        branch then carries :attr:`~femodes.Branch.accuracy` (:doc:`/guide/accuracy`).
    max_harmonics : int, optional
        Largest number of harmonics ``rtol`` may use (default ``8 H``).
    error_method, error_options : ErrorMethod, AccuracyOptions, optional
        How ``rtol`` is met with complementarity contacts (a strategy of :mod:`femodes.error_methods`,
        default ``Auto()``, as in :func:`femodes.estimate_error`) and its tuning; only with ``rtol``.

    Returns
    -------
    Branch
        ``success`` False (with ``message``) on failure; ``status == 2``: stopped at ``options.max_points``.
    """
    model = check_model(model)
    checkpoint = checkpoint_spec(checkpoint)
    h = check_harmonics(harmonics)
    check_continuation_options(options)
    refinement_options(rtol, max_harmonics, h.n_harmonics)
    chosen = error_method
    error_method = as_error_method(error_method, "error_method")
    error_options = check_options(error_options, "error_options")
    span = check_span(omega, "omega", positive=True)
    if chosen is not None and rtol is None:
        raise ValueError(f"frequency_response: error_method={chosen!r} chooses how rtol= is met, but rtol is not "
                         "given; pass rtol=..., or leave error_method out")
    # an explicit method that does not apply is refused before anything runs, as estimate_error does
    error_method.check(model, h, projection)
    problem = ForcedResponseProblem(model, h, projection=projection)
    opts = options or frequency_response_options()
    if x0 is not None:
        x0 = start_vector(x0, problem.size, f"{model.n_dofs} DOFs x {h.n_coef} coefficients"
                           + (f" + {problem.size - model.n_dofs * h.n_coef} contact-force coefficients"
                              if problem.size > model.n_dofs * h.n_coef else ""))

    def start(run_options: ContinuationOptions) -> tuple[np.ndarray, ContinuationOptions]:
        if x0 is not None:
            xs = x0
        else:
            with np.errstate(all="ignore"):
                xs = _starting_point(problem, span[0], run_options.newton)
            _check_response_scale(problem, xs, span[0])
        warn_undamped(model)  # once the input is known to be valid: bad input is an error first
        warn_rigid_body(model)
        if run_options.x_scale is None:
            run_options = dataclasses.replace(run_options, x_scale=_response_scale(problem, span, xs))
        return xs, run_options

    stab = StabilityOptions.parse(stability)

    def wrap(res, meta) -> Branch:
        if res.status == 6 and (why := resonant_harmonics(model, span[0], h)):  # say it in the user's terms
            res = dataclasses.replace(res, message=(
                f"the harmonic balance is singular at the start: {why}, and the model has no damping (an undamped "
                "resonance has no finite response); start the span away from it, or add damping"))
        branch = branch_from_continuation(problem, res, kind="forced", model=model, meta={"span": list(span), **meta})
        return _with_stability(branch, problem, model, stab, opts)

    description = {"analysis": "frequency_response", "omega": list(span), "harmonics": _harmonics_key(h),
                   "projection": repr(problem.system.projection), "n_unknowns": int(problem.size),
                   "model": model_fingerprint(model)} if checkpoint is not None else {}
    started = time.perf_counter()
    describe = _frequency_named
    branch = run_continuation(problem, span, opts, "frequency_response", progress, x0=start, wrap=wrap, model=model,
                              checkpoint=checkpoint, description=description, describe=describe)
    warn_short_of_span(branch, span, "frequency_response", describe, opts)
    branch = _with_stability(branch, problem, model, stab, opts)  # a finished checkpoint saved without it
    if rtol is None or _already_refined(branch, rtol):
        return branch

    def rerun(H: int) -> Branch:
        return frequency_response(model, omega, Harmonics(H, subharmonic=h.subharmonic), options=options,
                                  projection=projection, progress=progress, stability=stab or False)

    final = meet_tolerance(branch, rtol, max_harmonics, rerun, projection=projection, method=error_method,
                           time_limit=rtol_time_limit(time.perf_counter() - started, error_options),
                           options=error_options)
    return _saved_as_returned(final, branch, checkpoint)


def frequency_response_options(**changes) -> ContinuationOptions:
    """The continuation options :func:`frequency_response` uses by default, with ``changes``
    (e.g. ``max_points=50``) applied: step 0.05, max_step 3 (the step control of
    :class:`ContinuationOptions` sizes the steps below it; with the phase predictor most steps of
    the seed contact case reached max_step 2: 113 -> 91 points, 499 -> 436 residual evaluations at
    H = 20, benchmarks/README_steps.md), ``target_norm_change=0.3`` (the response's size changes by
    about 30 % per step at most, so that lines drawn through the points follow the curve away from
    resonance, where the tangent barely turns: :class:`ContinuationOptions`), Newton to
    ``atol=1e-9`` in at most 20 iterations."""
    base = ContinuationOptions(step=0.05, max_step=3.0, newton=NewtonOptions(atol=1e-9, max_iter=20),
                               target_norm_change=0.3)
    return dataclasses.replace(base, **changes) if changes else base


def _response_scale(problem: ForcedResponseProblem, span: tuple[float, float], x_start: np.ndarray) -> np.ndarray:
    """Arclength scales of the unknowns: displacement coefficients by the larger RMS of the start
    point and of the linear response at the other end of the span; contact-force coefficients by
    that times the largest complementarity parameter (a contact stiffness), as
    :meth:`NonlinearModeProblem.arclength_scale` does.

    The continuation's own default (the RMS of the start point alone) makes the step sizes depend
    on the direction of travel: above a resonance the response is small, and the same curve
    traced downwards took 1146 points instead of 305 (1-DOF contact case, w 2.0 -> 0.5, H = 20).
    One scale for displacements and forces fails in SI units: a steel blade's contact forces (N)
    are ~1e8 times its displacements (m), the arclength became all contact force from the first
    touch and the curve crawled at grazing (2000 points without passing it).
    """
    x_start = np.asarray(x_start, dtype=float)
    with np.errstate(all="ignore"):
        rms = [float(np.sqrt(np.mean(x_start ** 2))), float(np.sqrt(np.mean(problem.linear_guess(span[1]) ** 2)))]
    good = [r for r in rms if math.isfinite(r) and r > 0]
    sq = max(good) if good else 1.0
    s = problem.system
    cmax = max([ct.c for ct in s.unilateral] or [1.0])
    _check_law_scales(problem, sq, "frequency_response")
    return s.join(np.full((s.h.n_coef, s.n), sq), np.full((s.h.n_coef, s.n_uc), cmax * sq))


def _check_law_scales(problem, sq: float, label: str) -> None:
    """ValueError naming the law parameter (complementarity ``c``, penalty ``stiffness``) whose
    product with the response scale ``sq`` makes forces whose squares overflow floating point:
    every step would otherwise fail as a "non-finite residual" that names nothing."""
    s, big = problem.system, largest_unknown(problem.size)
    for ct in s.unilateral:
        if ct.c * sq > big:
            raise ValueError(f"{label}: the contact parameter c = {ct.c:.3g} (UnilateralContact c, DOF {ct.dof}) times "
                             f"the response scale {sq:.3g} gives contact forces whose squares overflow floating point; "
                             "leave c=None (chosen from the model's stiffness) or rescale the units")
    for law, dof in s.penalty:
        if law.stiffness * sq > big:
            raise ValueError(f"{label}: the penalty stiffness {law.stiffness:.3g} (PenaltyContact stiffness, DOF {dof}) "
                             f"times the response scale {sq:.3g} gives contact forces whose squares overflow floating "
                             "point; use a stiffness of the order of the structure's, or rescale the units")


def _check_response_scale(problem, x: np.ndarray, omega: float) -> None:
    """ValueError naming the forcing amplitude when the (linear or converged) response at ``omega``
    is not finite, or so large that its square overflows (:func:`largest_unknown`)."""
    big = float(np.max(np.abs(x), initial=0.0)) if np.all(np.isfinite(x)) else math.inf
    if big > largest_unknown(problem.size):
        raise ValueError(f"frequency_response: the response at omega = {omega:g} is {big:.3g}, too large for floating "
                         "point (its square overflows the norms of Newton and the arclength): the forcing amplitude "
                         "(HarmonicForce amplitude) is too large for these units; rescale them")


def _harmonics_key(h: Harmonics) -> list:
    return [int(h.n_harmonics), None if h.n_time is None else int(h.n_time), int(h.subharmonic)]


class _ForcingHomotopy:
    """``r(x; lam) = r(x, w0) + (1 - lam) F``: the forced problem with the forcing scaled by ``lam``."""

    def __init__(self, problem: ForcedResponseProblem, omega: float):
        self.problem, self.omega = problem, float(omega)
        self.f = problem.forcing()

    def residual(self, x, lam):
        r, J, _ = self.problem.residual(x, self.omega)
        return r + (1.0 - lam) * self.f, J, -self.f


def _starting_point(problem: ForcedResponseProblem, omega: float, newton: NewtonOptions) -> np.ndarray:
    """Converged start at ``omega``: Newton from the linear response, else a forcing homotopy.

    Near superharmonic resonances the linear guess can be outside Newton's basin (forced Duffing
    at w = 0.5, H = 5); growing the forcing from 1 % by continuation from the linear solution
    (nonlinear terms negligible at small amplitude) reaches the solution.
    """
    with np.errstate(all="ignore"):
        x0 = problem.linear_guess(omega)
    _check_response_scale(problem, x0, omega)  # before Newton and the homotopy square it
    res = semismooth_newton(lambda x: problem.residual(x, omega)[:2], x0, options=newton)
    if res.success:
        return res.x
    log.info("frequency_response: Newton from the linear guess failed at w = %g (%s); forcing homotopy", omega, res.message)
    hom = _ForcingHomotopy(problem, omega)
    lam0 = 0.01
    linear = problem.linear_guess(omega)
    start = linear * lam0
    # arclength scale of the full-forcing response: with the default (the size of the 1 % start)
    # the unknowns grow 100x over the homotopy and the steps in lam shrink accordingly (measured:
    # 522 points and 44 s on a 1e4-DOF bar against a stop, 14 points and 4 s with this scale)
    scale = float(np.sqrt(np.mean(linear ** 2))) or 1.0
    out = continuation(hom, (lam0, 1.0), x0=start,
                       options=ContinuationOptions(step=0.05, max_step=0.2, newton=newton, x_scale=scale))
    if out.success and out.status == 0:
        return out.x[-1]
    log.warning("frequency_response: forcing homotopy at w = %g failed (%s)", omega, out.message)
    return x0


def nonlinear_mode_options(problem: NonlinearModeProblem, x0: np.ndarray,
                           options: ContinuationOptions | None = None) -> ContinuationOptions:
    """Continuation options for a nonlinear mode starting at ``x0`` (used by :func:`nonlinear_mode`).

    Arclength scaling: :meth:`NonlinearModeProblem.arclength_scale` of the start, ``log10(E)``
    by 1. With ``options`` given, the scaling is filled in only if the options do not set
    ``x_scale`` themselves.
    """
    scale = problem.arclength_scale(x0)
    _check_law_scales(problem, float(np.max(np.abs(x0), initial=0.0)) or 1.0, "nonlinear_mode")
    if options is None:
        # the step control of issue 16 is not used by default here yet: with it the end orbits of
        # examples/validation_cantilever.py move by ~1e-7 and its time-stepping energy drift
        # (sensitive to the start orbit) rose from 0.017 to 0.053 (tests/test_validation_cantilever_and_forced.py)
        return ContinuationOptions(step=0.05, max_step=0.25, x_scale=scale, p_scale=1.0,
                                   newton=NewtonOptions(atol=1e-9, max_iter=20),
                                   target_angle=None, target_contraction=None, corrector_deadline=None)
    if options.x_scale is None:
        return dataclasses.replace(options, x_scale=scale, p_scale=options.p_scale or 1.0)
    return options


class _Required:
    """Default of ``nonlinear_mode``'s ``harmonics`` while leaving it out is deprecated."""

    def __repr__(self) -> str:
        return "<required>"


_REQUIRED = _Required()


@entry_point("nonlinear_mode")
@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
@shows_progress
def nonlinear_mode(
    model: StructuralModel,
    mode: int = 1,
    energy: tuple[float, float] = (1e-3, 1.0),
    harmonics: Harmonics | int = _REQUIRED,  # type: ignore[assignment]  # required, after a deprecation
    *,
    options: ContinuationOptions | None = None,
    projection=None,
    progress: bool | Callable = False,
    checkpoint: str | os.PathLike | Checkpoint | None = None,
    stability: bool | StabilityMethod | StabilityOptions = False,
    rtol: float | None = None,
    max_harmonics: int | None = None,
    past_grazing: PeriodDriven | None = PeriodDriven(),
    error_options: AccuracyOptions | None = None,
) -> Branch:
    """Nonlinear mode (frequency-energy backbone) by the extended periodic motion concept.

    Follows the periodic motions of the free system ``M q'' + K q + f_nl(q) = -w_c p`` that
    continue linear mode ``mode`` from energy ``energy[0]`` to ``energy[1]`` (continuation in
    ``log10`` of the period-averaged mechanical energy). ``branch.xi`` holds the artificial
    damping, which is ~0 for a conservative model (a check of the solution).

    ``progress`` (bool or callable) and ``checkpoint`` (a path, or
    ``femodes.Checkpoint(path, resume=True)`` to continue a killed run) are as for
    :func:`frequency_response`: every converged point is written to a journal as it is found; the
    checkpoint must come from the same model, ``mode``, energy span, harmonics and ``projection``.
    ``rtol``, ``max_harmonics`` and ``error_options`` are as for :func:`frequency_response` (levels
    compared at equal energy), and so is ``stability`` (``True`` or a :class:`~femodes.StabilityOptions`).

    Past grazing (models with unilateral contacts): the returned family is the one whose motions
    have a contact phase in every period and keep most of their energy in mode ``mode``; it is the
    family that the forced, damped structure's resonance follows. When the continuation in the
    energy is caught at grazing by an internal resonance (a clamped bar hitting a stop: its spectrum
    is commensurate, and mode 4 takes the energy while the tip only grazes), the part past the
    grazing energy is traced again by frequency (``past_grazing``, a
    :class:`~femodes.nonsmooth_modes.PeriodDriven`), which steps over the tongues of internal
    resonance; they are listed in ``branch.internal_resonances`` with the modes that take the energy.
    ``branch.meta["energy_continuation"]`` says why. ``past_grazing=None`` keeps the energy
    continuation's branch whatever it follows.

    ``harmonics`` (a :class:`~femodes.Harmonics` or an int) is required, as in
    :func:`frequency_response`; leaving it out is deprecated: it still means 10 harmonics, with a
    ``DeprecationWarning``.

    Returns
    -------
    Branch
        ``omega`` (rad/s) against ``energy``.
    """
    model = check_model(model)
    checkpoint = checkpoint_spec(checkpoint)
    if harmonics is _REQUIRED:  # not None: an explicit None stays the TypeError it was
        warnings.warn("nonlinear_mode without harmonics= is deprecated (it uses 10); pass harmonics=10 (or a "
                      "femodes.Harmonics), as frequency_response requires", DeprecationWarning,
                      stacklevel=user_stacklevel())
        harmonics = 10
    h = check_harmonics(harmonics)
    check_continuation_options(options)
    refinement_options(rtol, max_harmonics, h.n_harmonics)
    error_options = check_options(error_options, "error_options")
    if past_grazing is not None and not isinstance(past_grazing, PeriodDriven):
        raise TypeError(f"nonlinear_mode: past_grazing must be a femodes.PeriodDriven or None, got {past_grazing!r}")
    e0, e1 = check_span(energy, "energy", positive=True)
    if e1 < e0:
        raise ValueError(f"nonlinear_mode: energy must increase, got energy={tuple(energy)!r}: the backbone starts "
                         f"from the linear mode at energy[0], where the motion is nearly linear; pass "
                         f"energy=({e1:g}, {e0:g})")
    problem = NonlinearModeProblem(model, h, mode, reference_energy=math.sqrt(e0 * e1),
                                   projection=projection)
    span = (math.log10(e0), math.log10(e1))
    x0 = problem.linear_guess(e0)
    user_options = options
    options = nonlinear_mode_options(problem, x0, options)
    stab = StabilityOptions.parse(stability)

    def wrap(res, meta) -> Branch:
        if res.status == 5:  # the start failed: say it in the user's terms, not as p = log10(E)
            res = dataclasses.replace(res, message=(
                f"no periodic motion found at the start energy {e0:g} by Newton from linear mode {mode} ({res.message}); "
                f"start at a lower energy, where the motion is nearly linear (e.g. below first contact), "
                f"or raise the harmonics"))
        elif res.status == 6:  # the first tangent: p is log10(E) there too
            ratio = commensurate_modes(model, mode, h)
            res = dataclasses.replace(res, message=(
                f"the harmonic balance is singular at the start energy {e0:g} (no unique tangent to follow)"
                + (f": {ratio}, an exact internal resonance whose orbits form a continuum there; starting at another "
                   "energy will not help while the frequencies stay commensurate: detune the model slightly"
                   if ratio else "; start at a slightly different energy")))
        branch = branch_from_continuation(problem, res, kind="nonlinear mode", model=model,
                                          meta={"mode": int(mode), "energy_span": [e0, e1], **meta})
        return _with_stability(branch, problem, model, stab, options)

    description = {"analysis": "nonlinear_mode", "mode": int(mode), "energy": [e0, e1], "harmonics": _harmonics_key(h),
                   "projection": repr(problem.system.projection), "n_unknowns": int(problem.size),
                   "model": model_fingerprint(model)} if checkpoint is not None else {}
    started = time.perf_counter()
    branch = run_continuation(problem, span, options, "nonlinear_mode", progress, x0=lambda o: (x0, o), wrap=wrap,
                              model=model, checkpoint=checkpoint, description=description, describe=_energy_named)
    continued = branch
    if branch.meta.get("family") != "contact phase":  # a finished checkpoint holds the composed branch
        branch = continue_past_grazing(branch, problem, model, past_grazing, e1, options.newton)
    warn_short_of_span(branch, span, "nonlinear_mode", _energy_named, options)
    branch = _with_stability(branch, problem, model, stab, options)
    if rtol is None or _already_refined(branch, rtol):
        return _saved_as_returned(branch, continued, checkpoint)

    def rerun(H: int) -> Branch:
        return nonlinear_mode(model, mode, energy, Harmonics(H, subharmonic=h.subharmonic), options=user_options,
                              projection=projection, progress=progress, stability=stab or False, past_grazing=past_grazing)

    final = meet_tolerance(branch, rtol, max_harmonics, rerun, projection=projection,
                           time_limit=rtol_time_limit(time.perf_counter() - started, error_options),
                           options=error_options)
    return _saved_as_returned(final, continued, checkpoint)


def _already_refined(branch: Branch, rtol: float) -> bool:
    """A finished checkpoint's branch that holds the error estimate of this ``rtol`` already."""
    return branch.accuracy is not None and branch.accuracy.rtol == rtol and "checkpoint" in branch.meta


def _saved_as_returned(final: Branch, continued: Branch, checkpoint: Checkpoint | None) -> Branch:
    """``final``, also written to the checkpoint's file, whole (its notes too): the file held the
    continuation's branch, from before ``rtol``'s estimate (an upper fold 9 % low, no error
    estimate) or before a nonlinear mode's past-grazing family (11 grazing points instead of 42),
    while the call returned the other. It keeps the run's description, so that resuming the
    finished run returns it as it is."""
    if checkpoint is None:
        return final
    if "checkpoint" in continued.meta:
        final.meta["checkpoint"] = continued.meta["checkpoint"]
    final.save(checkpoint.path)
    return final


def _frequency_named(p: float) -> str:
    return f"w = {p:.6g} rad/s"


def _energy_named(p: float) -> str:  # a nonlinear mode's continuation parameter is log10(E)
    return f"the energy {10.0 ** p:.6g}"


def _with_stability(branch: Branch, problem, model: StructuralModel, stability: StabilityOptions | None,
                    options: ContinuationOptions) -> Branch:
    """The branch with its stability and bifurcations (:mod:`femodes.floquet`), once."""
    if stability is None or branch.stable is not None or not len(branch):
        return branch
    return annotate_branch(branch, problem, model, method=stability.method, tol=stability.tol, newton=options.newton,
                           locate=stability.locate, check=stability.check)

