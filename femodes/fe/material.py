"""Models layer: material data (bars, beams, solids) and cross-section data of 1-D members."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..solvers.checks import InputTypeError, InputValueError, entry_point
__all__ = ["Material", "Section"]


def _pos(name: str, v, *, allow_none: bool = False):
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"{name} must be a positive real number, got {v!r}")
    v = float(v)
    if not math.isfinite(v) or v <= 0:
        raise InputValueError(f"{name} must be a finite positive number, got {v!r}")
    return v


@dataclass(frozen=True)
class Material:
    """Linear elastic isotropic material: Young's modulus ``E``, density ``rho`` (consistent units)
    and Poisson's ratio ``nu``.

    ``nu`` (``-1 < nu < 0.5``, default 0.3) is used by meshed solids (:func:`femodes.solid`);
    bars and beams ignore it.
    """

    E: float
    rho: float
    nu: float = 0.3

    @entry_point("Material")
    def __post_init__(self):
        object.__setattr__(self, "E", _pos("E", self.E))
        object.__setattr__(self, "rho", _pos("rho", self.rho))
        nu = self.nu
        if isinstance(nu, bool) or not isinstance(nu, (int, float, np.integer, np.floating)):
            raise InputTypeError(f"nu must be a real number in (-1, 0.5), got {nu!r}")
        nu = float(nu)
        if not -1.0 < nu < 0.5:
            raise InputValueError(
                f"nu must satisfy -1 < nu < 0.5 (positive definite isotropic elasticity), got {self.nu!r}; "
                "for a nearly incompressible material use e.g. nu=0.49"
            )
        object.__setattr__(self, "nu", nu)

    @property
    def lame(self) -> tuple[float, float]:
        """Lame parameters ``(lambda, mu)`` of 3-D (and plane-strain) elasticity:
        ``lambda = E nu / ((1 + nu)(1 - 2 nu))``, ``mu = E / (2 (1 + nu))``."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu)), self.E / (2.0 * (1.0 + self.nu))

    @property
    def wave_speed(self) -> float:
        """Bar wave speed ``sqrt(E / rho)``."""
        return math.sqrt(self.E / self.rho)


@dataclass(frozen=True)
class Section:
    """Cross-section: ``area`` A (bars and beam mass) and second moment ``inertia`` I (beams).

    ``rotary_inertia=True`` adds the Rayleigh rotary inertia ``rho I w'^2`` to beam kinetic energy
    (off by default: classical Euler-Bernoulli).
    """

    area: float
    inertia: float | None = None
    rotary_inertia: bool = False

    @entry_point("Section")
    def __post_init__(self):
        object.__setattr__(self, "area", _pos("area", self.area))
        object.__setattr__(self, "inertia", _pos("inertia", self.inertia, allow_none=True))
        if isinstance(self.rotary_inertia, np.bool_):
            object.__setattr__(self, "rotary_inertia", bool(self.rotary_inertia))
        if not isinstance(self.rotary_inertia, bool):
            raise InputTypeError(f"rotary_inertia must be True or False, got {self.rotary_inertia!r}")
