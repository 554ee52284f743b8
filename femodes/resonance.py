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
from collections.abc import Sequence

import numpy as np

from .results import Branch

__all__ = ["ResonancePeak", "compare_resonance", "TONGUE_MARGIN", "ON_BACKBONE"]


@dataclasses.dataclass(frozen=True)
class ResonancePeak:
    """One forced response's peak against the backbone.

    ``omega`` and ``energy``: the peak (the orbit of largest period-averaged energy on the forced
    branch); ``omega_backbone``: the backbone's frequency at that energy (linear interpolation in
    ``log E``), NaN when the energy is outside the backbone's range; ``distance``:
    ``omega / omega_backbone - 1``; ``index``: the peak's index on its branch; ``tongue``: the
    index in ``backbone.internal_resonances`` of the tongue of internal resonance whose
    frequencies (widened by :data:`TONGUE_MARGIN`) hold the peak, or None, with ``tongue_modes``
    the modes that take the energy there: a forced response caught by an internal resonance
    peaks there, not on the family that steps over it.
    """

    omega: float
    energy: float
    omega_backbone: float
    distance: float
    index: int
    tongue: int | None = None
    tongue_modes: tuple[int, ...] = ()

    @property
    def predicted(self) -> str:
        """One line: on the backbone (within :data:`ON_BACKBONE`, with the distance), else in a
        listed tongue, else off it or outside its energy range."""
        if np.isfinite(self.distance) and abs(self.distance) <= ON_BACKBONE:
            return f"on the backbone, {self.distance:+.2%}"
        if self.tongue is not None:
            modes = ", ".join(str(m) for m in self.tongue_modes) or "?"
            return (f"in the tongue of internal resonance {self.tongue} (modes {modes}) listed on the backbone, "
                    f"{self.distance:+.2%} from the family past it")
        if np.isfinite(self.distance):
            return f"off the backbone, {self.distance:+.2%}"
        return "outside the backbone's energy range"


#: A forced peak within this relative distance of a tongue's frequencies is held by that tongue.
TONGUE_MARGIN = 0.01

#: :attr:`ResonancePeak.predicted` calls a peak within this relative distance on the backbone.
ON_BACKBONE = 0.01


def compare_resonance(backbone: Branch, forced: Branch | Sequence[Branch]) -> tuple[ResonancePeak, ...]:
    """Distance, in frequency at equal energy, between each forced response's peak and the backbone.

    Parameters
    ----------
    backbone : Branch
        A nonlinear mode (``kind == "nonlinear mode"``) of the free system.
    forced : Branch or sequence of Branch
        Forced responses of the same structure (damped), e.g. at decreasing damping.

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
    order = np.argsort(backbone.energy, kind="stable")
    logE, wb = np.log(backbone.energy[order]), backbone.omega[order]
    out = []
    for b in branches:
        if not len(b):
            raise ValueError("compare_resonance: a forced branch has no point")
        i = int(np.argmax(b.energy))
        e = float(b.energy[i])
        inside = logE[0] <= np.log(e) <= logE[-1]
        w_bb = float(np.interp(np.log(e), logE, wb)) if inside else float("nan")
        w = float(b.omega[i])
        tongue: int | None = None
        modes: tuple[int, ...] = ()
        for k, t in enumerate(backbone.internal_resonances):
            ws = np.asarray(t.get("omega", ()), dtype=float)
            ws = ws[np.isfinite(ws)]
            if ws.size and ws.min() * (1 - TONGUE_MARGIN) <= w <= ws.max() * (1 + TONGUE_MARGIN):
                tongue, modes = k, tuple(int(m) for m in t.get("modes", ()))
                break
        out.append(ResonancePeak(omega=w, energy=e, omega_backbone=w_bb,
                                 distance=float(w / w_bb - 1.0) if inside else float("nan"), index=i,
                                 tongue=tongue, tongue_modes=modes))
    return tuple(out)
