"""Laws layer: pointwise nonlinear laws in time (contact complementarity, penalty, cubic spring).

Each law is a frozen declaration (where it acts, its parameters) plus its pointwise value and
generalized derivative. The same objects are used by the harmonic balance (``femodes.hbm``) and
by time integration; nothing here knows about harmonics or meshes.

Sign conventions (fixed once for the whole package)
---------------------------------------------------
Equation of motion ``M q'' + C q' + K q + f_nl(q) = f(t) - w_c p``.

Contact at a DOF ``i`` (direction vector ``w_c = e_i``): normal gap ``g_N = g0 - q_i >= 0`` and
contact force ``p >= 0`` (compression positive) acting on the structure along ``-w_c``, i.e. the
obstacle pushes the contact DOF back.

Signorini conditions ``g_N >= 0, p >= 0, g_N p = 0`` are written with the semismooth
complementarity function of Shi & Legrand (2016)::

    lambda + max(0, c (u - g) - lambda) = 0      (their variables: lambda = -p <= 0, u - g = -g_N)

which, in ours, is ``p - max(0, p - c g_N) = 0`` for any constant ``c > 0``. (Check: if
``p - c g_N <= 0`` the equation gives ``p = 0`` and then ``g_N >= 0``; otherwise it gives
``c g_N = 0`` with ``p >= 0``.) Its generalized derivative is taken with the convention
``d max(0, s)/ds = 1 if s > 0 else 0``.

The penalty law is ``p = k_p max(0, -g_N)`` and the cubic spring ``f = k3 q_i^3``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Union

import numpy as np

__all__ = [
    "UnilateralContact",
    "PenaltyContact",
    "CubicSpring",
    "Location",
    "check_location",
]

#: What ``at=`` accepts: a name ("tip"), a (name, component) pair, or a DOF index.
Location = Union[str, int, tuple]


def check_location(at: Any, owner: str) -> Any:
    """Validate the form of an ``at=`` argument (not whether it exists in a model)."""
    if isinstance(at, bool):
        raise TypeError(f"{owner}: at must be a location name, a (name, component) pair or a DOF index, got {at!r}")
    if isinstance(at, (int, np.integer)):
        if at < 0:
            raise ValueError(f"{owner}: at={at!r} is a negative DOF index; use 0 <= at < n_dofs")
        return int(at)
    if isinstance(at, str):
        if not at:
            raise ValueError(f"{owner}: at must not be an empty string")
        return at
    if isinstance(at, tuple) and len(at) == 2 and all(isinstance(a, str) for a in at):
        return at
    raise TypeError(
        f"{owner}: at must be a location name like 'tip', a (name, component) pair like "
        f"('tip', 'w'), or a DOF index, got {at!r}"
    )


def _positive(value: Any, name: str, owner: str, *, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{owner}: {name} must be a real number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        what = "a finite non-negative number" if allow_zero else "a finite positive number"
        raise ValueError(f"{owner}: {name} must be {what}, got {value!r}")
    return v


def _finite(value: Any, name: str, owner: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{owner}: {name} must be a real number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{owner}: {name} must be finite, got {value!r}")
    return v


@dataclass(frozen=True)
class UnilateralContact:
    """Rigid obstacle at a DOF, Signorini conditions by the complementarity function.

    ``p - max(0, p - c g_N) = 0`` with ``g_N = gap - q[at]`` (see the module docstring for the
    mapping to Shi & Legrand's ``lambda + max(0, c (u - g) - lambda) = 0``).

    Parameters
    ----------
    at : str, (str, str) or int
        Contact DOF: a location name (default component), a (location, component) pair or an
        index into the model's DOFs. Must not be a constrained DOF.
    gap : float
        Initial gap ``g0 >= 0`` (the obstacle sits at ``q[at] = gap``).
    c : float, optional
        Complementarity parameter (force per length). With a truncated Fourier basis the weak
        (Galerkin) solution depends on it: on the mission's 1-DOF case at w = 1.05, H = 20, max u
        is 1.0184, 1.0154, 1.0111 for c = 1, 10, 100 (tests/test_hbm.py), and for the sub-harmonic
        impact orbit of examples/subharmonic_contact.py the w/2 amplitude varies by 3 % for
        c = 10..300, half the truncation error. ``None`` picks the static stiffness seen at the
        contact DOF, ``1 / (K^-1)_cc``. For strongly impacting orbits a larger c (of the order of
        the dynamic stiffness of the high harmonics) can help Newton converge.
    """

    at: Location
    gap: float
    c: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "at", check_location(self.at, "UnilateralContact"))
        object.__setattr__(self, "gap", _positive(self.gap, "gap", "UnilateralContact", allow_zero=True))
        if self.c is not None:
            object.__setattr__(self, "c", _positive(self.c, "c", "UnilateralContact"))

    def gap_function(self, u):
        """Normal gap ``g_N = gap - u``."""
        return self.gap - np.asarray(u, dtype=float)

    def residual(self, p, u, c):
        """Complementarity function ``p - max(0, p - c g_N)`` and its generalized derivatives.

        Returns ``(r, dr_dp, dr_du)``, arrays shaped like ``p``.
        """
        p = np.asarray(p, dtype=float)
        s = p - c * self.gap_function(u)
        active = s > 0.0
        r = p - np.maximum(0.0, s)
        dr_dp = np.where(active, 0.0, 1.0)
        dr_du = np.where(active, -c, 0.0)
        return r, dr_dp, dr_du


@dataclass(frozen=True)
class PenaltyContact:
    """Regularized (penalty) contact: ``p = stiffness * max(0, -g_N)``, ``g_N = gap - q[at]``.

    The classic alternative to complementarity; it allows a penetration of order
    ``p / stiffness`` and approaches the Signorini solution as ``stiffness -> inf``.
    """

    at: Location
    gap: float
    stiffness: float

    def __post_init__(self):
        object.__setattr__(self, "at", check_location(self.at, "PenaltyContact"))
        object.__setattr__(self, "gap", _positive(self.gap, "gap", "PenaltyContact", allow_zero=True))
        object.__setattr__(self, "stiffness", _positive(self.stiffness, "stiffness", "PenaltyContact"))

    def force(self, u):
        """Contact force (compression positive) and its generalized derivative ``dp/du``."""
        pen = np.asarray(u, dtype=float) - self.gap
        active = pen > 0.0
        return self.stiffness * np.maximum(0.0, pen), np.where(active, self.stiffness, 0.0)

    def potential(self, u):
        """Stored energy ``stiffness/2 * max(0, u - gap)^2``."""
        pen = np.maximum(0.0, np.asarray(u, dtype=float) - self.gap)
        return 0.5 * self.stiffness * pen**2


@dataclass(frozen=True)
class CubicSpring:
    """Grounded cubic (Duffing) spring: internal force ``k3 q[at]^3`` added to ``K q``.

    ``k3 > 0`` hardens, ``k3 < 0`` softens.
    """

    at: Location
    k3: float

    def __post_init__(self):
        object.__setattr__(self, "at", check_location(self.at, "CubicSpring"))
        k3 = _finite(self.k3, "k3", "CubicSpring")
        if k3 == 0.0:
            raise ValueError("CubicSpring: k3 must be non-zero (a zero spring does nothing), got 0.0")
        object.__setattr__(self, "k3", k3)

    def force(self, u):
        """Internal force ``k3 u^3`` and its derivative ``3 k3 u^2``."""
        u = np.asarray(u, dtype=float)
        return self.k3 * u**3, 3.0 * self.k3 * u**2

    def potential(self, u):
        """Potential ``k3 u^4 / 4``."""
        u = np.asarray(u, dtype=float)
        return 0.25 * self.k3 * u**4
