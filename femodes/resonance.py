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

__all__ = ["ResonancePeak", "compare_resonance"]


@dataclasses.dataclass(frozen=True)
class ResonancePeak:
    """One forced response's peak against the backbone.

    ``omega`` and ``energy``: the peak (the orbit of largest period-averaged energy on the forced
    branch); ``omega_backbone``: the backbone's frequency at that energy (linear interpolation in
    ``log E``), NaN when the energy is outside the backbone's range; ``distance``:
    ``omega / omega_backbone - 1``; ``index``: the peak's index on its branch.
    """

    omega: float
    energy: float
    omega_backbone: float
    distance: float
    index: int


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
        out.append(ResonancePeak(omega=float(b.omega[i]), energy=e, omega_backbone=w_bb,
                                 distance=float(b.omega[i] / w_bb - 1.0) if inside else float("nan"), index=i))
    return tuple(out)
