"""Results layer: :class:`Bifurcation`, a bifurcation located on a branch, and its kinds."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Bifurcation", "BIFURCATION_KINDS"]


#: The kinds of :class:`Bifurcation`: a fold (saddle-node; a multiplier crosses +1 where the
#: branch turns back), a branch point (a multiplier crosses +1 and another branch crosses this
#: one), period doubling (-1), Neimark-Sacker (a complex pair), and "nonsmooth": multipliers that
#: jump across the unit circle instead of crossing it (the contact pattern changes there: grazing).
BIFURCATION_KINDS = ("fold", "branch_point", "period_doubling", "neimark_sacker", "nonsmooth")


@dataclass(frozen=True, eq=False)
class Bifurcation:
    """A bifurcation located on a branch (``branch.bifurcations``).

    Attributes
    ----------
    kind : str
        One of :data:`BIFURCATION_KINDS`.
    index : int
        A fold: the index of the fold point of the branch; otherwise the point before the
        bifurcation (it lies between points ``index`` and ``index + 1``).
    omega, energy : float
        Where it is (rad/s; period-averaged energy).
    parameter : float
        The continuation parameter there (``omega``, or ``log10(energy)`` for nonlinear modes).
    multiplier : complex
        The Floquet multiplier that crosses the unit circle there (1 for a fold).
    Q, P : ndarray
        The periodic solution at the bifurcation (displacement and contact-force coefficients).
    xi : float
        Artificial damping (nonlinear modes).
    located : bool
        True when it was located between its two branch points (``omega``, ``Q``, ``P`` are
        there); False for a bracketed one (``StabilityOptions(locate=False)``), reported at the
        point of the bracket on its unstable side.
    """

    kind: str
    index: int
    omega: float
    energy: float
    parameter: float
    multiplier: complex
    Q: np.ndarray
    P: np.ndarray
    xi: float = 0.0
    located: bool = True

    def __post_init__(self):
        if self.kind not in BIFURCATION_KINDS:
            raise ValueError(f"Bifurcation: kind must be one of {BIFURCATION_KINDS}, got {self.kind!r}")

    def __repr__(self) -> str:
        return (f"Bifurcation({self.kind!r}, index={self.index}, omega={self.omega:.8g}, "
                f"multiplier={complex(self.multiplier):.4g}{'' if self.located else ', located=False'})")
