"""Analyses layer: nonsmooth modes past grazing by a period-driven continuation.

Above the energy at which a linear mode first touches a unilateral contact (its grazing energy,
:func:`femodes.grazing_energy`), the free periodic motions split into families: motions with a
contact phase of finite duration in each period, whose frequency rises with the energy and which
predict the forced resonance, and grazing motions that stay at the linear frequency while an
internal resonance takes their energy into another mode. On a structure with a commensurate
spectrum (a clamped bar: ``w_k = (2k - 1) w_1``; a P1 mesh keeps ``w_4 / w_1 = 7.01``) a
continuation in the energy is caught at grazing by such a resonance and climbs it: the tip only
grazes the stop while mode 4 takes 95 % of the energy.

The contact-phase family is followed here by its frequency instead: harmonic balance solved at
given ``w`` (:class:`~femodes.hbm.PeriodDrivenModeProblem`), ``w`` increased step by step from
just above the linear frequency, each solve started from the secant through the last two orbits.
This is the period sweep of Lu & Legrand's wave-equation harmonic balance; it steps over the
near-vertical tongues of internal resonance that an energy continuation climbs (narrow bands). A
solve that fails, or whose orbit has given most of its energy to other modes, is such a tongue:
it is left out of the branch and listed with the modes that took the energy (:class:`InternalResonance`).

With many harmonics the tongues are dense, and past a cluster of them the secant through the last
orbits leads Newton onto a neighbouring family with more energy. With more harmonics than
``PeriodDriven.start_harmonics`` the sweep is therefore guided by the family traced first with
that many (:func:`_coarse_family`): the predictor follows it, an orbit off it (in frequency at its
energy, or with an energy rising over it) is solved again from its orbit, and the tongues' and the
end's tests are drawn against it (issue 35; ``benchmarks/README_bar_convergence.md``).

Checked against the bar's continuum nonsmooth mode (d'Alembert; Yoong, Thorin & Legrand 2018).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import NamedTuple

import numpy as np

from .hbm.problems import NonlinearModeProblem, PeriodDrivenModeProblem
from .laws import UnilateralContact
from .linear import grazing_energy, linear_modes
from .model import StructuralModel
from .resonance import another_mode_at_end, close_partner, modal_energy_shares
from .results import Branch
from .solvers import NewtonOptions, semismooth_newton
from .sweep_guide import Guide, solve_in_stages

__all__ = ["PeriodDriven", "InternalResonance", "modal_energy_fractions", "period_driven_sweep", "captured_past_grazing",
           "continue_past_grazing", "family_caveat"]

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class PeriodDriven:
    """Strategy of :func:`femodes.nonlinear_mode` past grazing: the period-driven continuation.

    Parameters
    ----------
    start : float
        First frequency of the sweep, relative to the linear one: ``w = (1 + start) w0``. Closer
        to 1, Newton falls back onto the trivial orbit (zero motion solves every frequency).
    step, max_step : float
        First and largest frequency step, relative to ``w0``; a step grows by 1.5 after a solve
        in at most 4 Newton iterations.
    min_fraction : float
        Smallest share of the energy the traced mode keeps on the branch; an orbit below it has
        given its energy to other modes (an internal-resonance tongue) and is left out.
    max_points, max_skips, n_modes : int
        Largest number of frequencies tried; consecutive tongue points after which the sweep
        stops; linear modes used to tell which modes take the energy in a tongue.
    grazing_shift : float
        Largest relative frequency shift of an energy continuation's orbits past ``1.5 E_g`` for
        which that branch is taken for a grazing family (:func:`captured_past_grazing`; the bar's
        grazing families shift by 0.14-1.2 %, contact-phase families by 5-10 %).
    always : bool
        Trace by frequency even when the energy continuation reached its end without grazing.
    start_harmonics : int
        When Newton from the linear mode fails at the sweep's first frequency, the orbit with this
        many harmonics starts it instead, refined by doubling the harmonics (the new ones zero) up
        to all of them (with H = 80 on a 160-element bar the linear mode is too far from the
        contact-phase orbit).
    off_curve : float
        Relative departure of an orbit's energy from the smooth curve through its neighbours
        beyond which it is taken for a tongue's orbit (the family's own curvature between
        neighbours stays below 3 % on the bar; the tongues' orbits that the lower envelope keeps lie
        10-40 % off).
    family_tol : float
        With more than ``start_harmonics`` harmonics the sweep is guided by the family traced first
        with ``start_harmonics`` (:func:`period_driven_sweep`): an orbit whose frequency departs by
        more than this (relative) from that family's at the same energy is not on the family (a
        tongue's orbit, or a neighbouring family with about twice the energy), and the solve is
        started again from that family's orbit at the same frequency, refined up to all the
        harmonics (the bar: truncation moves the family by 0.1-0.6 %, neighbours lie 2-4 % off).
    """

    start: float = 0.02
    step: float = 0.005
    max_step: float = 0.01
    min_fraction: float = 0.25
    max_points: int = 400
    max_skips: int = 30
    n_modes: int = 12
    off_curve: float = 0.1
    family_tol: float = 0.01
    grazing_shift: float = 0.03
    always: bool = False
    start_harmonics: int = 10

    def __post_init__(self):
        for name in ("start", "step", "max_step"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v < 1):
                raise ValueError(f"PeriodDriven: {name} must be a number in (0, 1) (relative to the linear frequency), "
                                 f"got {v!r}")
        if not (0 < self.min_fraction < 1 and 0 < self.off_curve < 1 and 0 < self.grazing_shift < 1
                and 0 < self.family_tol < 1):
            raise ValueError(f"PeriodDriven: min_fraction, off_curve, grazing_shift and family_tol must be in (0, 1), "
                             f"got {self.min_fraction!r}, {self.off_curve!r}, {self.grazing_shift!r} and "
                             f"{self.family_tol!r}")
        for name in ("max_points", "max_skips", "n_modes", "start_harmonics"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"PeriodDriven: {name} must be a positive integer, got {v!r}")


@dataclasses.dataclass(frozen=True)
class InternalResonance:
    """A tongue of internal resonance met by the period-driven sweep (its orbits are not on the
    branch).

    ``omega``: the frequencies (rad/s) of the sweep's orbits that fell in it (or ``nan`` energy for
    failed solves); ``energy``: their energies; ``modes``: the linear modes (1-based) holding the
    largest share of the energy there (where no solve succeeded, on the family's orbits on either
    side), with ``shares``; ``ratios``: for each, the harmonic ``j``
    nearest to ``w_k / w`` (a ``j:1`` resonance with mode ``k``).
    """

    omega: tuple[float, ...]
    energy: tuple[float, ...]
    modes: tuple[int, ...]
    shares: tuple[float, ...]
    ratios: tuple[float, ...]

    def as_dict(self) -> dict:
        return {k: list(v) for k, v in dataclasses.asdict(self).items()}


def modal_energy_fractions(problem: NonlinearModeProblem, x: np.ndarray, omegas: np.ndarray,
                           shapes: np.ndarray) -> np.ndarray:
    """:func:`~femodes.resonance.modal_energy_shares` of the orbit ``x`` of ``problem``."""
    u = problem.unpack(x, 0.0)
    return modal_energy_shares(problem.system.h, u.Q, u.omega, problem.system.M, omegas, shapes)


class _Orbit(NamedTuple):
    """An orbit the sweep kept: its unknowns, frequency, energy and Newton iterations."""

    x: np.ndarray
    omega: float
    energy: float
    nit: int


def _spectrum(model: StructuralModel, problem: NonlinearModeProblem, strategy: PeriodDriven):
    """The linear modes that tell which modes take the energy (at least the traced one and the
    next), computed once for the detection, the sweep and the grazing energy."""
    return linear_modes(model, n=int(min(max(strategy.n_modes, problem.mode + 1), model.n_dofs)))


def _tongue(points: list[tuple[float, float, np.ndarray | None]], lm, mode: int, beside=()) -> InternalResonance:
    """The tongue of the sweep's points ``(w, E, energy shares or None)``: the (up to three) other
    modes with more than 5 % of the energy there on average, and their ``w_k / w``; where no solve
    succeeded, the shares of the family's orbits ``beside`` it (the 2-D blade at H = 10: mode 2
    holds 10 % just below its 5:1 tongue)."""
    shares = np.mean([f for _, _, f in points if f is not None] or list(beside) or [np.zeros(lm.omega.size)], axis=0)
    order = [k for k in np.argsort(shares)[::-1] if k != mode - 1 and shares[k] > 0.05][:3]
    wm = float(np.mean([w for w, _, _ in points]))
    return InternalResonance(omega=tuple(float(w) for w, _, _ in points), energy=tuple(float(e) for _, e, _ in points),
                             modes=tuple(int(k) + 1 for k in order), shares=tuple(float(shares[k]) for k in order),
                             ratios=tuple(float(lm.omega[k] / wm) for k in order))


def period_driven_sweep(model: StructuralModel, problem: NonlinearModeProblem, energy_max: float,
                        strategy: PeriodDriven, newton: NewtonOptions | None = None, *, spectrum=None
                        ) -> tuple[list[_Orbit], list[InternalResonance], str]:
    """Orbits of the contact-phase family of ``problem``'s mode from just above grazing up to
    ``energy_max``, by increasing frequency; returns ``(orbits, tongues, message)``. ``spectrum``:
    the linear modes of :func:`_spectrum`, if already computed."""
    w0 = problem.omega0
    mode = problem.mode
    n = problem.system.size
    pd = PeriodDrivenModeProblem(model, problem.system.h, mode, reference_energy=problem.reference_energy,
                                 projection=problem.system.projection)
    lm = spectrum if spectrum is not None else _spectrum(model, problem, strategy)
    eg = grazing_energy(model, mode, modes=lm)
    newton = newton or NewtonOptions(atol=1e-9, max_iter=30)
    orbits: list[_Orbit] = []
    tongues: list[InternalResonance] = []
    pending: list[tuple[float, float, np.ndarray | None]] = []

    def close_tongue(after=None):
        if pending:
            beside = [modal_energy_fractions(problem, orbits[-1].x, lm.omega, lm.shapes)] if orbits else []
            tongues.append(_tongue(pending, lm, mode, beside + ([after] if after is not None else [])))
            pending.clear()

    w = (1.0 + strategy.start) * w0
    step = strategy.step * w0
    message = f"reached the energy {energy_max:g}"
    skips = 0
    seed = problem.linear_guess(eg * (1.0 + strategy.start))
    guide = _coarse_family(model, problem, energy_max, strategy, newton, lm)

    def solve(guess):
        res = semismooth_newton(lambda z, w=w: pd.residual(z, w)[:2], guess, options=newton)
        E = _energy(problem, res.x) if res.success else math.nan
        fractions = modal_energy_fractions(problem, res.x, lm.omega, lm.shapes) if res.success else None
        return res, E, fractions

    for _ in range(strategy.max_points):
        if guide is not None and orbits and w > guide.w[-1]:
            # past the coarse family's last orbit (twice the end of the span) nothing guides the
            # sweep any more: towards the family's asymptote the tongues are dense
            message = f"stopped at w = {w:.6g} rad/s, past the coarse family's last orbit"
            break
        secant = False
        if guide is not None and orbits and guide.covers(w) and guide.covers(orbits[-1].omega):
            # the last orbit moved as the coarse family moves (a secant through orbits pulled by a
            # tongue beside them would lead onto a neighbouring family)
            guess = orbits[-1].x + guide.padded(w) - guide.padded(orbits[-1].omega)
        elif len(orbits) >= 2:
            a, b = orbits[-2], orbits[-1]
            guess = b.x + (b.x - a.x) * (w - b.omega) / (b.omega - a.omega)
            secant = True
        else:
            guess = (orbits[-1].x if orbits else seed).copy()
        guess[n] = w
        res, E, fractions = solve(guess)
        if secant and skips and not (res.success and fractions[mode - 1] >= strategy.min_fraction):
            # inside a gap the secant through the two orbits before it extrapolates over the whole
            # gap (the 2-D blade of examples/resonance_on_backbones.py with H = 10: from 1048 to
            # 1124 rad/s, nine times the spacing of those orbits) and leads Newton nowhere; the
            # last orbit itself, at the new frequency, finds the family again past the tongue
            guess = orbits[-1].x.copy()
            guess[n] = w
            again, E2, f2 = solve(guess)
            if again.success and f2[mode - 1] >= strategy.min_fraction:
                res, E, fractions = again, E2, f2
        if not orbits and not res.success and problem.system.h.n_harmonics > strategy.start_harmonics:
            res = _start_coarse(model, problem, w, seed, strategy, newton, res)
            E = _energy(problem, res.x) if res.success else math.nan
            fractions = modal_energy_fractions(problem, res.x, lm.omega, lm.shapes) if res.success else None
        def fits(E):
            """On the family the coarse one guides: at its frequency for its energy, and its energy
            not above the coarse family's by more than _ENERGY_JUMP beyond the last orbits' (the
            median of the last three: one orbit pulled low by a tongue beside it must not turn the
            family away)."""
            if guide is None:
                return True
            if not guide.holds(w, E):
                return False
            last = [o for o in orbits[-3:] if guide.covers(o.omega)]
            if last and guide.covers(w):
                offset = float(np.median([math.log(o.energy) - guide.log_energy(o.omega) for o in last]))
                jump = math.log(E) - guide.log_energy(w) - offset
                return jump <= math.log1p(_ENERGY_JUMP)
            return True

        if not fits(E):
            # off the family traced with fewer harmonics (a tongue's orbit, or the secant led onto a
            # neighbouring family): start again from that family's orbit at this frequency
            log.debug("w = %.6g: E = %.4g is off the coarse family; restarting from it", w, E)
            assert guide is not None  # fits() is False only with a guide
            again = guide.refine(w)
            if again is not None:
                res = again
                E = _energy(problem, res.x)
                fractions = modal_energy_fractions(problem, res.x, lm.omega, lm.shapes)
        log.debug("w = %.6g: success %s, E = %.4g, share of mode %d %.3f", w, res.success, E, mode,
                  fractions[mode - 1] if fractions is not None else math.nan)
        if (res.success and E > eg * (1.0 - strategy.start) and fractions[mode - 1] >= strategy.min_fraction
                and fits(E)):
            close_tongue(fractions)
            skips = 0
            orbits.append(_Orbit(res.x, w, E, int(res.nit)))
            # past the end once the orbits left after removing the tongues' (_drop_off_curve) are
            if E >= energy_max and len(orbits) >= 2 and orbits[-2].energy >= energy_max:
                kept, _ = _drop_off_curve(problem, orbits, [], lm, strategy, guide)
                if sum(o.energy >= energy_max for o in kept) >= 2:
                    break
            # (guided: once the orbit past the end that the branch would end at is there)
            if guide is not None and E >= energy_max and _end(_drop_off_curve(problem, orbits, [], lm, strategy, guide)[0],
                                                              energy_max, guide, strategy) is not None:
                break
            if res.nit <= 4:
                step = min(1.5 * step, strategy.max_step * w0)
            slope = guide.slope(w) if guide is not None else math.nan
            if slope > 0:
                # where the family's energy is steep in w (towards its asymptote), steps of at most
                # 10 % in the coarse family's energy: the orbits between the tongues stay close
                # enough for the tests of the tongues' orbits (_drop_off_curve)
                step = min(step, max(math.log1p(_ENERGY_STEP) / slope, 0.25 * strategy.step * w0))
        else:
            if not orbits and not res.success:
                return [], [], (f"no periodic motion with a contact phase found at w = {w:.6g} rad/s, just above "
                                f"linear mode {mode}'s frequency {w0:.6g} ({res.message})")
            pending.append((w, E, fractions))
            skips += 1
            if skips > strategy.max_skips:
                close_tongue()
                message = (f"stopped at w = {w:.6g} rad/s: {skips} consecutive frequencies in internal-resonance "
                           f"tongues or without a solution")
                break
            step = max(strategy.step * w0, 0.5 * step)
        w += step
    else:
        message = f"stopped after {strategy.max_points} frequencies (PeriodDriven.max_points)"
    close_tongue()
    orbits, tongues = _drop_off_curve(problem, orbits, tongues, lm, strategy, guide)
    past = [i for i, o in enumerate(orbits) if o.energy >= energy_max]
    if past:  # the branch ends at the first orbit past the end of the span...
        below = orbits[: past[0]]
        # ...if it continues the two before it (the tail of the sweep has no later orbits to judge
        # it by, and the family's energy is steep there); a guided sweep takes the first orbit past
        # the end that does, judged by its frequency at its energy (steady there, unlike the energy
        # at a frequency), the others past the end are left out
        end = _end(orbits, energy_max, guide, strategy)
        if end is None:
            orbits = below
            message = (f"stopped at the energy {orbits[-1].energy:g}, short of {energy_max:g}: the next orbit is "
                       "a tongue's")
        else:
            orbits = below + [end]
        tongues = [t for t in tongues if t.omega[0] < orbits[-1].omega]
    log.info("period-driven sweep of mode %d: %d orbits, %d tongues; %s", mode, len(orbits), len(tongues), message)
    return orbits, tongues, message


def _end(orbits: list[_Orbit], energy_max: float, guide, strategy: PeriodDriven) -> _Orbit | None:
    """The orbit past ``energy_max`` that ends the branch ``orbits``: the first one, or for a guided
    sweep the first that continues the two before the first (:func:`_continues`); None if none does."""
    past = [i for i, o in enumerate(orbits) if o.energy >= energy_max]
    if not past:
        return None
    below = orbits[: past[0]]
    candidates = [orbits[i] for i in past] if guide is not None else [orbits[past[0]]]
    return next((c for c in candidates if len(below) < 2 or _continues(below[-2], below[-1], c, guide, strategy)),
                None)


def _continues(a: _Orbit, b: _Orbit, c: _Orbit, guide, strategy: PeriodDriven) -> bool:
    """Whether the orbit ``c`` continues the line through ``a`` and ``b``: within ``off_curve`` in
    ``log E`` at its frequency, or, for a guided sweep, within ``family_tol`` in the frequency at
    its energy on the line through ``b`` with the coarse family's slope there (two orbits close
    together, each pulled by a tongue beside it, gave half the family's slope on 80 elements with
    H = 40 and rejected the family's own orbit past the end; the secant where the guide has none)."""
    la, lb, lc = (math.log(o.energy) for o in (a, b, c))
    line = lb + (lb - la) * (c.omega - b.omega) / (b.omega - a.omega)
    if abs(lc - line) <= math.log1p(strategy.off_curve):
        return True
    if guide is None:
        return False
    slope = guide.slope(b.omega)
    if not slope > 0:
        if not lb > la:
            return False
        slope = (lb - la) / (b.omega - a.omega)
    w_line = b.omega + (lc - lb) / slope
    return abs(c.omega / w_line - 1.0) <= strategy.family_tol


def _start_coarse(model: StructuralModel, problem: NonlinearModeProblem, w: float, seed: np.ndarray,
                  strategy: PeriodDriven, newton: NewtonOptions, failed):
    """The sweep's first orbit when Newton from the linear mode failed with all the harmonics: the
    orbit with ``strategy.start_harmonics`` harmonics at the same frequency, then with twice as many
    (started from the linear mode, or else from the last stage's orbit, its new harmonics zero), and so on
    up to all of them (on a 160-element bar the linear mode is a good enough start with up to 40
    harmonics, not with 80; the orbit with 40 is). Returns ``failed`` if a stage fails."""
    s = problem.system
    H = s.h.n_harmonics
    linear = s.split(seed[: s.size])

    def starts(k: int, previous):  # the linear mode (with all harmonics it just failed), else the last stage's orbit
        return ([linear] if k < H else []) + ([previous] if previous is not None else [])

    res = solve_in_stages(model, problem, w, strategy.start_harmonics, starts, newton)
    return failed if res is None else res


_ENERGY_STEP = 0.1  # largest relative energy step of a guided sweep where the family is steep
_ENERGY_JUMP = 0.3  # largest rise of the energy over the coarse family's between orbits of a guided sweep


def _coarse_family(model, problem, energy_max, strategy, newton, lm) -> Guide | None:
    """With more than ``strategy.start_harmonics`` harmonics: the contact-phase family traced first
    with ``start_harmonics`` (a sweep of its own, to twice ``energy_max``), which guides the sweep
    with all the harmonics. With many harmonics the tongues are dense, and past a cluster of them
    the secant through the last orbits leads Newton onto a neighbouring family with about twice the
    energy (the bar with 80 elements and 40 harmonics: mode 1 still holding 76-80 % of the energy,
    the frequency 2-4 % below the family's at that energy); with few harmonics the family is
    smooth. None without more harmonics, or if that sweep found fewer than three orbits."""
    s = problem.system
    if s.h.n_harmonics <= strategy.start_harmonics:
        return None
    h = type(s.h)(n_harmonics=strategy.start_harmonics, subharmonic=s.h.subharmonic)
    coarse = NonlinearModeProblem(model, h, problem.mode, reference_energy=problem.reference_energy,
                                  projection=s.projection)
    orbits, _, message = period_driven_sweep(model, coarse, 2.0 * energy_max, strategy, newton, spectrum=lm)
    log.info("period-driven sweep guided by the family with %d harmonics (%d orbits; %s)", h.n_harmonics,
             len(orbits), message)
    return Guide(model, problem, coarse, orbits, strategy, newton) if len(orbits) >= 3 else None


def _drop_off_curve(problem, orbits: list[_Orbit], tongues, lm, strategy, guide: Guide | None = None):
    """Orbits of a tongue that the sweep solved without noticing: the family's energy is a smooth,
    increasing function of the frequency, while a tongue's orbits lie off it by 10-40 % (an
    internal resonance feeds energy into another mode at nearly the same frequency). An orbit
    with more energy than one of the next three, then one whose ``log E`` departs by more than
    ``log(1 + strategy.off_curve)`` from the straight line through its accepted neighbours (in
    ``w``), the worst first, is moved to the tongues. With a ``guide`` (:func:`_coarse_family`)
    the line is drawn through ``log E`` less the coarse family's: where the family's energy grows
    steeply towards its asymptote its own curvature between neighbours far apart is not taken for
    a tongue's departure."""
    if len(orbits) < 3:
        return orbits, tongues
    w = np.array([o.omega for o in orbits])
    logE = np.log([o.energy for o in orbits])
    trend = np.array([guide.log_energy(x) for x in w]) if guide is not None else np.zeros_like(w)
    # first the lower envelope: a tongue's orbits carry the energy another mode took, above the
    # family's at the same frequency, and the family's energy rises with its frequency, so an orbit
    # with more energy than a later one is a tongue's
    # (judged against the next three orbits only: one low orbit far on must not cut the family)
    nxt = np.array([logE[i + 1: i + 4].min() if i + 1 < logE.size else np.inf for i in range(logE.size)])
    keep = logE <= nxt + 1e-12
    tol = math.log1p(strategy.off_curve)
    # (a guided sweep's orbits passed that test against the coarse family already, which, unlike
    # the line through two neighbours, holds across the gaps the tongues leave)
    while guide is None and keep.sum() >= 4:
        idx = np.flatnonzero(keep)
        dev = np.zeros(idx.size)
        for j in range(idx.size):
            # neighbours: the nearest kept orbits on each side (two on one side at the ends)
            a, b = [idx[j - 1], idx[j + 1]] if 0 < j < idx.size - 1 else (idx[1:3] if j == 0 else idx[-3:-1])
            d = logE - trend
            line = d[a] + (d[b] - d[a]) * (w[idx[j]] - w[a]) / (w[b] - w[a])
            dev[j] = abs(d[idx[j]] - line)
        worst = int(np.argmax(dev))
        if dev[worst] <= tol:
            break
        keep[idx[worst]] = False
    if keep.all():
        return orbits, tongues
    extra = [_tongue([(o.omega, o.energy, modal_energy_fractions(problem, o.x, lm.omega, lm.shapes))], lm, problem.mode)
             for o, k in zip(orbits, keep) if not k]
    return [o for o, k in zip(orbits, keep) if k], sorted(tongues + extra, key=lambda t: t.omega[0])


def _energy(problem: NonlinearModeProblem, x: np.ndarray) -> float:
    s = problem.system
    return float(s.energy(x[: s.size], float(x[s.size]))[0])


def captured_past_grazing(branch, problem: NonlinearModeProblem, model: StructuralModel, strategy: PeriodDriven,
                          energy_max: float, *, spectrum=None) -> str | None:
    """Why an energy continuation's branch is a grazing family past grazing, or None.

    Motions with a contact phase stiffen: at twice the grazing energy their frequency is several
    percent above the linear one (10 % for the clamped bar, 5 % for a cantilever, 1-DOF impact
    oscillators more). A branch whose orbits from ``1.5 E_g`` on all stay within
    ``strategy.grazing_shift`` of the linear frequency while their energy at least doubles past
    grazing only grazes the stop: an internal resonance takes the energy (on the bar, mode 4).
    A continuation that stopped past grazing is not trusted either, nor one that turned back in
    energy short of the span's end (a damped arch's: at 4.7 E_g, back to its start energy);
    ``strategy.always`` traces past grazing by frequency whatever the energy continuation did.
    ``spectrum``: the linear modes of :func:`_spectrum`, if already computed."""
    lm = spectrum if spectrum is not None else _spectrum(model, problem, strategy)
    try:
        eg = grazing_energy(model, problem.mode, modes=lm)
    except ValueError:  # the mode moves no contact: it never touches, nothing lies past grazing
        log.warning("nonlinear_mode: linear mode %d moves no contact DOF: its backbone is the linear mode's at every "
                    "energy (fm.grazing_energy names the modes that touch)", problem.mode)
        return None
    if energy_max <= 1.05 * eg or not len(branch):
        return None
    if strategy.always:
        return "PeriodDriven(always=True)"
    if not branch.success and branch.energy.max() > 1.05 * eg:
        return f"the energy continuation stopped past grazing ({branch.message})"
    if 1.05 * eg < branch.energy.max() < 0.99 * energy_max:  # turned back (a damped arch: at 4.7 E_g)
        return f"the energy continuation turned back at {branch.energy.max() / eg:.3g} E_g, short of {energy_max / eg:.3g} E_g"
    if energy_max <= 2.0 * eg or branch.energy.max() < 2.0 * eg:
        return None
    above = np.flatnonzero(branch.energy >= 1.5 * eg)
    shift = np.abs(branch.omega_truncated[above] / problem.omega0 - 1.0)
    if np.max(shift) >= strategy.grazing_shift:
        return None
    i = int(above[-1])
    x = problem.pack(branch.Q[i], branch.P[i], branch.omega_truncated[i], branch.xi[i])
    f = modal_energy_fractions(problem, x, lm.omega, lm.shapes)
    k = int(np.argmax(f))
    why = (f"the energy continuation grazed past grazing: from 1.5 to {branch.energy[i] / eg:.3g} E_g its frequency "
           f"stayed within {np.max(shift):.1e} of linear mode {problem.mode}'s, and at the end mode {k + 1} held "
           f"{100 * f[k]:.0f} % of the energy")
    if k + 1 != problem.mode:
        return why + " (an internal resonance)"
    why += " (its orbits barely touch the stop)"
    partner = close_partner(model, problem.mode, lm)
    if partner is not None:
        j, ratio, energies = partner
        why += (f"; mode {j}, a close pair with it (w_{j} / w_{problem.mode} = {ratio:.3f}), reaches the contacts at "
                f"{energies:.2g} of its grazing energy: the stop acts on mode {j}, whose backbone is "
                f"nonlinear_mode(model, {j}, ...)")
    return why


def family_caveat(branch: Branch) -> str | None:
    """Why a nonlinear mode is not the family that predicts the forced resonance, or None.

    :func:`continue_past_grazing` records in ``branch.meta["energy_continuation"]`` why the
    energy continuation is not trusted past grazing (:func:`captured_past_grazing`), and sets
    ``branch.meta["family"] = "contact phase"`` only when it replaced that part by the
    period-driven sweep. A branch with the first and not the second is the energy continuation's
    own past grazing (``past_grazing=None``, or a sweep that found no orbit): a grazing family,
    or a continuation that stopped there. Its error estimate may be small (it is honest about
    the truncation of the family traced), but the family is not the answer: it is never reported
    as converged (:attr:`femodes.results.ErrorEstimate.caveat`)."""
    meta = branch.meta
    why = meta.get("energy_continuation")
    if branch.kind != "nonlinear mode" or not why or meta.get("family") == "contact phase":
        return None
    return (f"grazing family: does not predict the forced resonance ({why}; nonlinear_mode's default "
            "past_grazing=PeriodDriven() traces the contact-phase family)")


def continue_past_grazing(branch: Branch, problem: NonlinearModeProblem, model: StructuralModel,
                          strategy: PeriodDriven | None, energy_max: float, newton: NewtonOptions | None) -> Branch:
    """The energy continuation's ``branch`` of a model with unilateral contacts, or, when it left the
    contact-phase family past grazing (:func:`captured_past_grazing`), its part up to grazing
    followed by the period-driven sweep. With ``strategy=None`` the branch is kept, but a grazing
    one says that it does not predict the forced resonance (meta and a logged warning)."""
    if not any(isinstance(c.item, UnilateralContact) for c in model.contacts) or not len(branch):
        return branch
    lm = _spectrum(model, problem, strategy or PeriodDriven())
    why = captured_past_grazing(branch, problem, model, strategy or PeriodDriven(), energy_max, spectrum=lm)
    if why is None:
        if ends_in := another_mode_at_end(branch, problem.mode, lm):
            branch.meta["ends_in"] = ends_in
            log.warning("nonlinear_mode: %s", ends_in)
        return branch
    if strategy is None:  # kept as asked, but said: it does not predict the forced resonance
        branch.meta["energy_continuation"] = why
        log.warning("nonlinear_mode: %s; this branch grazes past grazing and does not predict the forced resonance "
                    "(past_grazing=None keeps it; the default traces the contact-phase family)", why)
        return branch
    log.info("nonlinear_mode: %s; tracing the contact-phase family by frequency instead", why)
    orbits, tongues, message = period_driven_sweep(model, problem, energy_max, strategy, newton, spectrum=lm)
    if not orbits:
        log.warning("nonlinear_mode: %s, and the period-driven continuation found no orbit (%s); returning the "
                    "energy continuation's branch", why, message)
        branch.meta["energy_continuation"] = why
        return branch
    out = _compose(branch, problem, orbits, tongues, message, why, grazing_energy(model, problem.mode, modes=lm),
                   energy_max)
    if not out.success:  # as a continuation that stops short of its span says (a branch short of it)
        log.warning("nonlinear_mode: the contact-phase family ends at the energy %.6g, %.3g of the span's end %.6g "
                    "(success False): %s", float(out.energy.max()), float(out.energy.max()) / energy_max,
                    energy_max, message)
    return out


def _compose(below: Branch, problem: NonlinearModeProblem, orbits: list[_Orbit], tongues: list[InternalResonance],
             message: str, why: str, eg: float, energy_max: float) -> Branch:
    """One branch: the energy continuation's orbits up to the grazing energy ``eg``, then the
    period sweep's; successful when they reach ``energy_max``."""
    keep = np.cumsum(below.energy > eg) == 0  # the orbits before the first past grazing (not a way back)
    parts = [problem.unpack(o.x, 0.0) for o in orbits]
    energy = np.array([o.energy for o in orbits])
    residual = [float(np.max(np.abs(problem.residual(o.x, math.log10(o.energy))[0]))) for o in orbits]
    meta = dict(below.meta)
    meta.update({
        "family": "contact phase",
        "path": f"energy continuation up to the grazing energy {eg:.6g}, then period-driven continuation",
        "grazing_energy": eg,
        "energy_continuation": why,
        "internal_resonances": [t.as_dict() for t in tongues],
    })
    success = orbits[-1].energy >= energy_max
    return Branch(
        kind=below.kind, harmonics=below.harmonics, contacts=below.contacts,
        omega=np.concatenate([below.omega[keep], [u.omega for u in parts]]),
        Q=np.concatenate([below.Q[keep], [u.Q for u in parts]]),
        P=np.concatenate([below.P[keep], [u.P for u in parts]]),
        energy=np.concatenate([below.energy[keep], energy]),
        xi=np.concatenate([below.xi[keep], [u.xi for u in parts]]),
        residual_norm=np.concatenate([below.residual_norm[keep], residual]),
        nit=np.concatenate([below.nit[keep], [o.nit for o in orbits]]),
        parameter=np.concatenate([below.parameter[keep], np.log10(energy)]),
        folds=(), success=success, status=0 if success else 4, message=f"period-driven past grazing: {message}",
        model=below.model, meta=meta)
