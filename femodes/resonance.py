"""Analyses layer: does a backbone predict the forced resonance? (:func:`compare_resonance`).

The backbone of the free system (:func:`femodes.nonlinear_mode`) predicts where the forced,
lightly damped system resonates: at small damping the peak of each forced response lies on the
backbone, at the frequency the backbone has at the peak's energy (the peak is a phase resonance:
there the forcing balances the damping and the motion is close to a free periodic motion; Peeters
et al., Mech. Syst. Signal Process. 23, 2009; Kerschen et al. 2009). The distance between the two
measures how far a backbone can be trusted for a structure: it shrinks with the damping.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence

import numpy as np

from .linear import grazing_energy, linear_modes
from .results import Branch
from .solvers.checks import entry_name, entry_point

log = logging.getLogger(__name__)

__all__ = ["ResonancePeak", "compare_resonance", "modal_energy_shares", "point_shares", "another_mode_at_end",
           "TONGUE_MARGIN", "ON_BACKBONE", "CAPTURED",
           "CLOSE_PAIR", "close_partner"]


def modal_energy_shares(harmonics, Q: np.ndarray, omega: float, M, omegas: np.ndarray, shapes: np.ndarray) -> np.ndarray:
    """Share of the period-averaged energy of each linear mode (mass-normalised ``shapes``,
    frequencies ``omegas``) in the motion of harmonic coefficients ``Q`` (``n_coef x n_dofs``) at
    the frequency ``omega``: ``E_k = <eta_k'^2 + w_k^2 eta_k^2> / 2`` with the modal coordinate
    ``eta_k = phi_k^T M q``, divided by the sum over the modes given."""
    eta = np.asarray(Q) @ np.asarray(M @ shapes)                 # (n_coef, n_modes) modal coefficients
    w = np.asarray(harmonics.galerkin.norm_weights())[:, None]
    D1 = np.asarray(harmonics.operators.derivative_domega())
    e = 0.5 * omega ** 2 * np.sum(w * (D1 @ eta) ** 2, axis=0) + 0.5 * omegas ** 2 * np.sum(w * eta ** 2, axis=0)
    total = float(np.sum(e))
    return e / total if total > 0 else np.zeros_like(e)


@dataclasses.dataclass(frozen=True)
class ResonancePeak:
    """One forced response's peak against the backbone.

    ``omega`` and ``energy``: the peak (the orbit of largest period-averaged energy on the forced
    branch); ``omega_backbone``: the backbone's frequency at that energy (linear interpolation in
    ``log E``), NaN when the energy is outside the backbone's range; ``distance``:
    ``omega / omega_backbone - 1``; ``index``: the peak's index on its branch; ``tongue``: the
    index in ``backbone.internal_resonances`` of the tongue of internal resonance whose
    frequencies (from the backbone's orbits on either side of it, widened by
    :data:`TONGUE_MARGIN`) hold the peak, or None, with ``tongue_modes`` the modes that take the
    energy there: a forced response caught by an internal resonance peaks there, not on the
    family that steps over it. ``shares``: the share of the peak's energy in each of the forced
    model's lowest linear modes (:func:`modal_energy_shares`), and ``ratios`` their ``w_k / w``;
    ``captured_by``: the mode other than the backbone's ``mode`` holding the largest share, when
    it holds at least :data:`CAPTURED` (the peak is an internal resonance's), else None.
    ``on_tongue`` and ``tongue_distance``: of the tongue branches given to
    :func:`compare_resonance` (:func:`femodes.tongue_branch`), the index of the one nearest the
    peak in frequency at its energy and that distance (None and NaN without one covering it).
    ``at_end``: the largest energy is at an end of the forced branch, so its span holds no peak.
    ``backbone_held_by``: off the backbone and not captured, the mode other than ``mode`` that
    holds most of the energy of the backbone's orbit nearest the peak's energy (the energy
    continuation rides an internal resonance the forced response does not follow), else None.
    ``converged``: whether the forced branch's error estimate meets its ``rtol`` at the peak (None
    without one): a peak off the backbone may be a truncation artefact.
    """

    omega: float
    energy: float
    omega_backbone: float
    distance: float
    index: int
    tongue: int | None = None
    tongue_modes: tuple[int, ...] = ()
    mode: int = 1
    shares: tuple[float, ...] = ()
    ratios: tuple[float, ...] = ()
    captured_by: int | None = None
    on_tongue: int | None = None
    tongue_distance: float = float("nan")
    at_end: bool = False
    backbone_held_by: int | None = None
    converged: bool | None = None

    @property
    def predicted(self) -> str:
        """One line: on the backbone (within :data:`ON_BACKBONE`, with the distance), else caught
        by an internal resonance (the mode, its share and frequency ratio) and whether the backbone
        lists its tongue, else in a listed tongue, else off it or outside its energy range; first of
        all, whether the forced branch has a peak at all (``at_end``)."""
        if self.at_end:
            return (f"no peak: the forced branch's largest energy is at its end (w = {self.omega:.6g}); "
                    "widen its frequency span past the resonance")
        if np.isfinite(self.distance) and abs(self.distance) <= ON_BACKBONE:
            return f"on the backbone, {self.distance:+.2%}"
        where = (f"{self.distance:+.2%} from the backbone's family" if np.isfinite(self.distance)
                 else "outside the backbone's energy range")
        if np.isfinite(self.tongue_distance) and abs(self.tongue_distance) <= ON_BACKBONE:
            listed = f", the backbone's tongue {self.tongue}" if self.tongue is not None else ""
            inside = f"; mode {self.captured_by} holds {self.shares[self.captured_by - 1]:.0%} of the energy" \
                if self.captured_by is not None else ""
            return (f"on a tongue's branch (tongues[{self.on_tongue}]{listed}), {self.tongue_distance:+.2%}{inside}; "
                    f"{where}")
        if self.captured_by is not None:
            k = self.captured_by
            r = self.ratios[k - 1]
            pair = r / self.ratios[self.mode - 1] if len(self.ratios) >= self.mode else math.nan
            if abs(pair - 1.0) <= CLOSE_PAIR:
                # a near-degenerate pair (an axisymmetric section's two bending modes): the force
                # loads the other member, whose own backbone is the one to compare with
                return (f"mode {k} holds {self.shares[k - 1]:.0%} of the energy: modes {self.mode} and {k} are a close "
                        f"pair (w_{k} / w_{self.mode} = {pair:.3f}) and the force drives mode {k}; compare with its "
                        f"backbone, nonlinear_mode(model, {k}, ...); {where}")
            listed = (f"in the tongue {self.tongue} listed on the backbone" if self.tongue is not None
                      else "a tongue the backbone does not list")
            return (f"caught by an internal resonance: mode {k} holds {self.shares[k - 1]:.0%} of the energy "
                    f"(w_{k} / w = {r:.2f}, near {round(r)}:1), {listed}; {where}")
        if self.tongue is not None:
            modes = ", ".join(str(m) for m in self.tongue_modes) or "?"
            return f"in the tongue of internal resonance {self.tongue} (modes {modes}) listed on the backbone, {where}"
        if np.isfinite(self.distance) and self.backbone_held_by is not None:
            return off_family(self)
        if np.isfinite(self.distance):
            unconverged = " (the peak is not converged in the harmonics: rtol not met there)"
            return f"off the backbone, {self.distance:+.2%}" + (unconverged if self.converged is False else "")
        return "outside the backbone's energy range"


#: A forced peak within this relative distance of a tongue's frequencies is held by that tongue.
TONGUE_MARGIN = 0.01

#: :attr:`ResonancePeak.predicted` calls a peak within this relative distance on the backbone.
ON_BACKBONE = 0.01

#: Share of a forced peak's energy in a mode other than the backbone's from which the peak is an
#: internal resonance's, when it is off the backbone (`examples/resonance_on_backbones.py`: the
#: 2-D blade's peaks in its 5:1 tongue 28-72 % at H = 7 and 31-74 % at H = 10; on the backbone,
#: the bar's largest other share 10-13 %, the 3-D blade's 21-39 % near its own 5:1 resonance, the
#: beam's 95-98 % where its backbone rides the 6:1 one with mode 2).
CAPTURED = 0.25

#: :attr:`ResonancePeak.predicted`: a mode that captures the peak with a linear frequency within
#: this relative distance of the backbone mode's makes a close pair with it (a tip stop on a rod of
#: circular section, P2 tetrahedra: w_2 / w_1 = 1.011; the forced peak, 79 % in mode 2, lies on
#: mode 2's backbone to 0.04 %, while mode 1's barely loads the stop).
CLOSE_PAIR = 0.05

#: Lowest linear modes over which a forced peak's energy shares are taken.
SHARE_MODES = 12


def close_partner(model, mode: int, modes) -> tuple[int, float, float] | None:
    """The mode of a close pair with ``mode`` (linear frequencies of ``modes`` within
    :data:`CLOSE_PAIR`) that reaches the contacts of ``model`` first, as ``(j, w_j / w_mode,
    E_g(j) / E_g(mode))``, or None when every such mode needs more energy (or there is none). On a
    rod of circular section with a tip stop (P2 tetrahedra) the bending mode across the stop's
    normal needs 13 times the grazing energy of its partner 1.1 % away: its orbits mix in a little
    of the partner and barely touch the stop, and the forced peak follows the partner's backbone."""
    w = float(modes.omega[mode - 1])
    eg = grazing_energy(model, mode, modes=modes)
    best = None
    for j in range(modes.omega.size):
        if j + 1 == mode or abs(float(modes.omega[j]) / w - 1.0) > CLOSE_PAIR:
            continue
        try:
            ej = grazing_energy(model, j + 1, modes=modes)
        except ValueError:  # mode j + 1 moves no contact
            continue
        if ej < eg and (best is None or ej / eg < best[2]):
            best = (j + 1, float(modes.omega[j]) / w, float(ej / eg))
    return best


def _tongue_band(backbone: Branch, ws: np.ndarray) -> tuple[float, float]:
    """Frequencies a tongue spans: from the backbone's last orbit below its points to its first
    above (the tongue's own points are only where the sweep tried)."""
    below = backbone.omega[backbone.omega < ws.min()]
    above = backbone.omega[backbone.omega > ws.max()]
    return (float(below.max()) if below.size else float(ws.min()),
            float(above.min()) if above.size else float(ws.max()))


def point_shares(branch: Branch, i: int, cache: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Energy shares (:func:`modal_energy_shares`) of the :data:`SHARE_MODES` lowest linear modes of
    ``branch.model`` at the branch's point ``i``, and their ``w_k / w``; empty without a model or
    when its modes fail (logged). ``cache``: a dict keeping the modes of each model between calls."""
    model = branch.model
    cache = {} if cache is None else cache
    if model is not None and id(model) not in cache:
        try:
            cache[id(model)] = linear_modes(model, n=int(min(SHARE_MODES, model.n_dofs)))
        except (ValueError, RuntimeError) as exc:  # what needs the shares goes on without them
            log.warning("%s: no modal energy shares (linear_modes failed: %s)", entry_name() or "point_shares", exc)
            cache[id(model)] = None
    lm = cache.get(id(model)) if model is not None else None
    if lm is None:
        return np.zeros(0), np.zeros(0)
    w = float(branch.omega[i])
    return modal_energy_shares(branch.harmonics, branch.Q[i], w, model.M, lm.omega, lm.shapes), lm.omega / w


def off_family(peak: ResonancePeak) -> str:
    """What :attr:`ResonancePeak.predicted` says of a peak off a backbone whose orbit at its
    energy is another mode's (``backbone_held_by``): first whether the peak itself is converged in
    the harmonics (a shallow arch's peak 16 % off at H = 7 was a truncation artefact: at H = 15
    and 21 it lies on that backbone, 0.2-0.4 %), then the call that traces the contact-phase family."""
    k, m = peak.backbone_held_by, peak.mode
    held = (f"off the backbone, {peak.distance:+.2%}: at the peak's energy the backbone's orbit is mode {k}'s "
            f"(it rides an internal resonance), the peak mode {m}'s ({peak.shares[m - 1]:.0%} of its energy); ")
    family = f"nonlinear_mode(model, {m}, ..., past_grazing=fm.PeriodDriven(always=True))"
    if peak.converged is False:
        return held + ("but the peak is not converged in the harmonics (rtol not met there): it predicts nothing "
                       f"yet; raise the harmonics before tracing mode {m}'s contact-phase family ({family})")
    if peak.converged is None:
        return held + ("check first that the peak is converged in the harmonics (frequency_response(..., "
                       "rtol=1e-2) or more harmonics): such a peak can be a truncation artefact; if it holds, "
                       f"trace mode {m}'s contact-phase family: {family}")
    return held + f"the forced response does not follow it; trace mode {m}'s contact-phase family: {family}"


#: A backbone orbit whose energy is at least this share in one mode other than the backbone's is
#: that mode's (:attr:`ResonancePeak.backbone_held_by`): the energy continuation of a shallow
#: arch's mode 2 ends with mode 5 holding 100 % (its 4:1 tongue), 16 % below the forced peak at H = 7
#: (a truncation artefact: :func:`off_family`).
HELD = 0.5


def _held_by(backbone: Branch, e: float, mode: int, cache: dict) -> int | None:
    """The mode other than ``mode`` holding at least :data:`HELD` of the energy of the backbone's
    orbit nearest (in ``log E``) the energy ``e``, or None."""
    j = int(np.argmin(np.abs(np.log(backbone.energy) - np.log(e))))
    return _holder(point_shares(backbone, j, cache)[0], mode)


def _holder(shares: np.ndarray, mode: int) -> int | None:
    """The mode other than ``mode`` holding at least :data:`HELD` of the ``shares``, or None."""
    if not shares.size:
        return None
    k = int(np.argmax(shares))
    return k + 1 if k != mode - 1 and shares[k] >= HELD else None


def another_mode_at_end(backbone: Branch, mode: int, lm) -> str | None:
    """What to say when a mode other than ``mode`` holds at least :data:`HELD` of the energy of the
    backbone's last orbit (linear modes ``lm`` of its model): it climbed an internal resonance (a
    curved 3-D beam's mode 1: mode 3 with 100 % at 4:1 past 1.25 w1 at H = 5 and 10, mode 5 with
    97 % at 14:1 and 1.047 w1 at H = 15), else None."""
    shares, ratios = point_shares(backbone, len(backbone) - 1, {id(backbone.model): lm})
    k = _holder(shares, mode)
    if k is None:
        return None
    return (f"mode {k} holds {shares[k - 1]:.0%} of the energy of the last orbit (w_{k} / w = {ratios[k - 1]:.2f}): "
            f"the backbone of mode {mode} climbs an internal resonance, which a forced response may or may not follow "
            f"(compare_resonance says; past_grazing=fm.PeriodDriven(always=True) traces mode {mode}'s contact-phase "
            "family)")


def _omega_at(branch: Branch, e: float) -> float:
    """The frequency of ``branch`` at the energy ``e`` (linear interpolation in ``log E`` between its
    orbits in energy order), NaN outside its energies."""
    if not len(branch):
        return float("nan")
    order = np.argsort(branch.energy, kind="stable")
    logE = np.log(branch.energy[order])
    if not logE[0] <= np.log(e) <= logE[-1]:
        return float("nan")
    return float(np.interp(np.log(e), logE, branch.omega[order]))


@entry_point("compare_resonance")
def compare_resonance(backbone: Branch, forced: Branch | Sequence[Branch], *,
                      tongues: Sequence[Branch] = ()) -> tuple[ResonancePeak, ...]:
    """Distance, in frequency at equal energy, between each forced response's peak and the backbone,
    and whether an internal resonance caught the peak.

    Parameters
    ----------
    backbone : Branch
        A nonlinear mode (``kind == "nonlinear mode"``) of the free system.
    forced : Branch or sequence of Branch
        Forced responses of the same structure (damped), e.g. at decreasing damping.
    tongues : sequence of Branch, optional
        Branches inside the backbone's tongues (:func:`femodes.tongue_branch`); each peak is also
        measured against the nearest of them (``on_tongue``, ``tongue_distance``).

    Returns
    -------
    tuple of ResonancePeak
        One per forced branch, in the order given.
    """
    if not isinstance(backbone, Branch) or backbone.kind != "nonlinear mode":
        raise TypeError("compare_resonance: backbone must be a Branch from femodes.nonlinear_mode, got "
                        f"{getattr(backbone, 'kind', type(backbone).__name__)!r}")
    branches = [forced] if isinstance(forced, Branch) else list(forced)
    if not branches or not all(isinstance(b, Branch) and b.kind == "forced" for b in branches):
        raise TypeError("compare_resonance: forced must be a Branch from femodes.frequency_response, or a list of them")
    if len(backbone) < 2:
        raise ValueError("compare_resonance: the backbone has fewer than two points; trace it over an energy span")
    tongues = list(tongues)
    if not all(isinstance(t, Branch) and t.kind == "nonlinear mode" for t in tongues):
        raise TypeError("compare_resonance: tongues must be Branches from femodes.tongue_branch")
    mode = int(backbone.meta.get("mode", 1))
    bands = []
    for t in backbone.internal_resonances:
        ws = np.asarray(t.get("omega", ()), dtype=float)
        ws = ws[np.isfinite(ws)]
        bands.append(_tongue_band(backbone, ws) if ws.size else None)
    out: list[ResonancePeak] = []
    cache: dict = {}
    for b in branches:
        if not len(b):
            raise ValueError("compare_resonance: a forced branch has no point")
        i = int(np.argmax(b.energy))
        e, w = float(b.energy[i]), float(b.omega[i])
        at_end = i in (0, len(b) - 1)
        if at_end:
            log.warning("compare_resonance: forced branch %d has no peak: its largest energy is at its end "
                        "(w = %.6g); widen its frequency span past the resonance", len(out), w)
        w_bb = _omega_at(backbone, e)
        tongue: int | None = None
        modes: tuple[int, ...] = ()
        for k, (t, band) in enumerate(zip(backbone.internal_resonances, bands)):
            if band is not None and band[0] * (1 - TONGUE_MARGIN) <= w <= band[1] * (1 + TONGUE_MARGIN):
                tongue, modes = k, tuple(int(m) for m in t.get("modes", ()))
                break
        shares, ratios = point_shares(b, i, cache)
        others = [k for k in np.argsort(shares)[::-1] if k != mode - 1]
        captured = int(others[0]) + 1 if others and shares[others[0]] >= CAPTURED else None
        near = [(abs(d), j, d) for j, d in ((j, w / _omega_at(t, e) - 1.0) for j, t in enumerate(tongues))
                if np.isfinite(d)]
        _, on_tongue, d_tongue = min(near) if near else (0.0, None, float("nan"))
        held = None
        if (not at_end and captured is None and tongue is None and len(shares) >= mode and np.isfinite(w_bb)
                and abs(w / w_bb - 1.0) > ON_BACKBONE and backbone.meta.get("family") != "contact phase"):
            held = _held_by(backbone, e, mode, cache)
        acc = b.accuracy
        converged = bool(acc.met[i]) if acc is not None and acc.rtol is not None else None
        peak = ResonancePeak(omega=w, energy=e, omega_backbone=w_bb, distance=w / w_bb - 1.0, index=i,
                             tongue=tongue, tongue_modes=modes, mode=mode,
                             shares=tuple(float(v) for v in shares), ratios=tuple(float(v) for v in ratios),
                             captured_by=captured, on_tongue=on_tongue, tongue_distance=d_tongue, at_end=at_end,
                             backbone_held_by=held, converged=converged)
        if held is not None:
            log.warning("compare_resonance: forced branch %d: %s", len(out), off_family(peak))
        out.append(peak)
    return tuple(out)
