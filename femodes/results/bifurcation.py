"""Results layer: :class:`Bifurcation`, a bifurcation located on a branch, and its kinds."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

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
    bracket : (float, float)
        How well it is located: the frequencies (rad/s) of the two solutions between which the
        test function of :mod:`femodes.branch_stability` changes sign (the two branch points for a
        bracketed one; equal where the reported solution is the crossing itself, to the test's
        tolerance); NaN where not stated (folds, files written before it). On an error-controlled
        branch it is moved with :attr:`omega`.
    omega_truncated : float
        The frequency of the truncated series ``Q``, ``P``; :attr:`omega` differs from it on an
        error-controlled branch, which reports its bifurcations at the converged frequency
        (:attr:`Branch.bifurcations <femodes.Branch.bifurcations>`).
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
    bracket: tuple[float, float] = (math.nan, math.nan)
    # not a constructor argument: dataclasses.replace(b, omega=w) is a plain bifurcation at w
    omega_truncated: float = field(init=False)

    def __post_init__(self):
        if self.kind not in BIFURCATION_KINDS:
            raise ValueError(f"Bifurcation: kind must be one of {BIFURCATION_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "bracket", (float(self.bracket[0]), float(self.bracket[1])))
        object.__setattr__(self, "omega_truncated", float(self.omega))

    def at_frequency(self, omega: float) -> Bifurcation:
        """The same bifurcation reported at the (converged) frequency ``omega``; its series, and
        :attr:`omega_truncated`, unchanged."""
        shift = float(omega) - self.omega_truncated
        out = dataclasses.replace(self, omega=float(omega), bracket=(self.bracket[0] + shift, self.bracket[1] + shift))
        object.__setattr__(out, "omega_truncated", self.omega_truncated)
        return out

    def series(self) -> Bifurcation:
        """The bifurcation at the frequency of its series (itself when they are the same)."""
        if self.omega == self.omega_truncated:
            return self
        shift = self.omega_truncated - self.omega
        return dataclasses.replace(self, omega=self.omega_truncated,
                                   bracket=(self.bracket[0] + shift, self.bracket[1] + shift))

    def __repr__(self) -> str:
        return (f"Bifurcation({self.kind!r}, index={self.index}, omega={self.omega:.8g}, "
                f"multiplier={complex(self.multiplier):.4g}{'' if self.located else ', located=False'})")
