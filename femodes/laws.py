"""Laws layer: pointwise nonlinear laws in time (contact complementarity, penalty, cubic spring).

Each law is a frozen declaration (where it acts, its parameters) plus its pointwise value and
generalized derivative. This module is the only place where their formulas are written: the
harmonic balance (``femodes.hbm``), time integration (``femodes.time``) and the results
(``femodes.results``) call the methods below; nothing here knows about harmonics or meshes.

Sign conventions (fixed once for the whole package; derivation: :doc:`/guide/contact`).
Equation of motion ``M q'' + C q' + K q + f_nl(q) = f(t) - w_c p``. Contact at a DOF ``i``
(``w_c = e_i``): normal gap ``g_N = g0 - q_i >= 0`` and contact force ``p >= 0`` (compression
positive) acting on the structure along ``-w_c``. The Signorini conditions are written with the
complementarity function of Shi & Legrand (2016), ``p - max(0, p - c g_N) = 0`` for any constant
``c > 0`` (their ``lambda + max(0, c (u - g) - lambda) = 0`` with ``lambda = -p``,
``u - g = -g_N``). The penalty law is ``p = k_p max(0, -g_N)``, the cubic spring ``f = k3 q_i^3``.
``d max(0, s)/ds = 1 if s > 0 else 0``: at a kink the inactive side is taken (an element of
Clarke's generalized gradient).

A law declared on a boundary of a meshed solid (``at="right"``, a ``direction`` or a callable
``gap``) is a template: ``StructuralModel.with_contact`` turns it into one law per boundary node,
each on a single DOF (an inclined or negative normal is the normal DOF ``u_n = n . u`` of a nodal
frame), so every formula below acts on one DOF.

Interface (vectorised: ``u`` and ``p`` are arrays of samples of any shape, results broadcast)
---------------------------------------------------------------------------------------------
``UnilateralContact``
    ``gap_function(u)`` normal gap ``g_N``; ``residual(p, u, c)`` the complementarity function
    and its generalized partial derivatives; ``positive_part_form(c)`` what an exact Galerkin
    projection of ``max(0, .)`` needs (slope and kink offset).
``PenaltyContact``
    ``gap_function(u)``; ``force(u)`` the contact force and ``dp/du``; ``potential(u)`` the stored
    energy (``potential' = force``); ``positive_part_form()`` (slope and kink offset).
``CubicSpring``
    ``force(u)`` the internal force and ``df/du``; ``potential(u)`` (``potential' = force``).
``Law.stack(laws)`` (each class)
    One object evaluating several laws of that class at once: its parameters are arrays with
    one entry per law (last axis), so ``stack(laws).force(u)`` takes ``u[..., j]`` at law ``j``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from .solvers.checks import InputTypeError, InputValueError, entry_point

__all__ = [
    "UnilateralContact",
    "PenaltyContact",
    "CubicSpring",
    "Location",
    "check_location",
]

#: What ``at=`` accepts: a name ("tip"), a (name, component) pair, or a DOF index.
Location = str | int | tuple


def check_location(at: Any) -> Any:
    """Validate the form of an ``at=`` argument (not whether it exists in a model)."""
    if isinstance(at, bool):
        raise InputTypeError(f"at must be a location name, a (name, component) pair or a DOF index, got {at!r}")
    if isinstance(at, (int, np.integer)):
        if at < 0:
            raise InputValueError(f"at={at!r} is a negative DOF index; use 0 <= at < n_dofs")
        return int(at)
    if isinstance(at, str):
        if not at:
            raise InputValueError("at must not be an empty string")
        return at
    if isinstance(at, tuple) and len(at) == 2 and all(isinstance(a, str) for a in at):
        return at
    raise InputTypeError(
        f"at must be a location name like 'tip', a (name, component) pair like "
        f"('tip', 'w'), or a DOF index, got {at!r}"
    )


def _positive(value: Any, name: str, *, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"{name} must be a real number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        what = "a finite non-negative number" if allow_zero else "a finite positive number"
        raise InputValueError(f"{name} must be {what}, got {value!r}")
    return v


def _finite(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"{name} must be a real number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise InputValueError(f"{name} must be finite, got {value!r}")
    return v


def _direction(value: Any):
    """``None`` or a unit vector (tuple of 1 to 3 floats) from ``direction=``."""
    if value is None:
        return None
    if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list, np.ndarray)):
        raise InputTypeError(f"direction must be a vector like (1.0, 0.0), got {value!r}")
    try:
        d = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputTypeError(f"direction must be a vector of real numbers like (1.0, 0.0), got {value!r}") from None
    if not 1 <= d.size <= 3 or not np.all(np.isfinite(d)):
        raise InputValueError(f"direction must have 1 to 3 finite components, got {value!r}")
    norm = float(np.linalg.norm(d))
    if norm == 0.0:
        raise InputValueError(f"direction must not be the zero vector, got {value!r}")
    return tuple(float(v) for v in d / norm)


def _gap(value: Any):
    """A non-negative gap, or a callable of node coordinates (evaluated by ``with_contact``)."""
    if callable(value):
        return value
    return _positive(value, "gap", allow_zero=True)


def _normal_gap(gap, u):
    """``g_N = gap - u`` (the one kinematic relation of every contact law)."""
    return gap - np.asarray(u, dtype=float)


class _Stackable:
    """``stack(laws)``: one evaluation object for several laws of the same class."""

    @classmethod
    def stack(cls, laws):
        """Several ``cls`` laws as one object whose parameters are arrays (one entry per law).

        ``at`` becomes the tuple of the laws' locations and every numeric field a float array
        (``None`` -> ``nan``), so the methods evaluate all laws at once with ``u[..., j]`` the
        value at law ``j``: the same formulas, vectorised over laws as well as samples. The
        result is for evaluation only (its fields are arrays: do not compare, hash or attach it
        to a model).
        """
        laws = tuple(laws)
        for law in laws:
            if type(law) is not cls:
                raise TypeError(f"{cls.__name__}.stack: expected {cls.__name__} laws, got {type(law).__name__}")
        out = object.__new__(cls)
        for f in fields(cls):
            vals = [getattr(law, f.name) for law in laws]
            if f.name == "at" or f.name == "direction":
                object.__setattr__(out, f.name, tuple(vals))
            else:
                object.__setattr__(out, f.name, np.array([math.nan if v is None else v for v in vals], dtype=float))
        return out


@dataclass(frozen=True)
class UnilateralContact(_Stackable):
    """Rigid obstacle at a DOF, Signorini conditions by the complementarity function.

    ``p - max(0, p - c g_N) = 0`` with ``g_N = gap - q[at]`` (see the module docstring for the
    mapping to Shi & Legrand's ``lambda + max(0, c (u - g) - lambda) = 0``).

    Parameters
    ----------
    at : str, (str, str) or int
        Contact DOF: a location name (default component), a (location, component) pair or an
        index into the model's DOFs. Must not be a constrained DOF.
    gap : float or callable
        Initial gap ``g0 >= 0`` (the obstacle sits at ``q[at] = gap``). On a meshed solid, a
        function of the node coordinates (a casing of any shape): called once as ``gap(x)``
        with ``x`` of shape ``(dim, n_nodes)`` (``x[0]``, ``x[1]`` the coordinates, as in
        scikit-fem) returning ``n_nodes`` gaps, or, if that fails or returns a scalar, once
        per node with ``x`` of shape ``(dim,)``.
    direction : tuple of float, optional
        Contact normal ``w_c`` of a meshed solid, e.g. ``(1.0, 0.0)`` (normalised): along +x, +y
        or +z the contact acts on that displacement component; an inclined or negative normal
        (``(0.8, 0.6)``, ``(-1.0, 0.0)``) acts on the normal DOF ``u_n`` of the node's rotated
        DOFs (a nodal frame, :meth:`femodes.StructuralModel.with_contact`). With a boundary name
        ``at="right"`` the law is expanded to one contact per node of that boundary by
        :meth:`femodes.StructuralModel.with_contact`.
    c : float, optional
        Complementarity parameter (force per length). With a truncated Fourier basis the weak
        (Galerkin) solution depends on it: for ``u'' + 0.1 u' + u = 0.2 cos(w t)`` against a stop at 1
        (Shi & Legrand 2016) at w = 1.05, H = 20, max u is 1.0184, 1.0154, 1.0111 for c = 1, 10,
        100, and for the sub-harmonic
        impact orbit of examples/subharmonic_contact.py the w/2 amplitude varies by 3 % for
        c = 10..300, half the truncation error. ``None`` picks the static stiffness seen at the
        contact DOF, ``1 / (K^-1)_cc``. For strongly impacting orbits a larger c (of the order of
        the dynamic stiffness of the high harmonics) can help Newton converge.
    """

    at: Location
    gap: Any
    c: float | None = None
    direction: tuple | None = None

    @entry_point("UnilateralContact")
    def __post_init__(self):
        object.__setattr__(self, "at", check_location(self.at))
        object.__setattr__(self, "gap", _gap(self.gap))
        object.__setattr__(self, "direction", _direction(self.direction))
        if self.c is not None:
            object.__setattr__(self, "c", _positive(self.c, "c"))

    def gap_function(self, u):
        """Normal gap ``g_N = gap - u`` (negative: penetration)."""
        return _normal_gap(self.gap, u)

    def residual(self, p, u, c):
        """Complementarity function ``r = p - max(0, p - c g_N)`` and its generalized derivatives.

        Returns ``(r, dr_dp, dr_du)``, arrays of the broadcast shape of ``p``, ``u`` (and ``c``):
        ``(0, -c)`` where ``p - c g_N > 0`` (contact), ``(1, 0)`` elsewhere, the kink included.
        """
        p = np.asarray(p, dtype=float)
        s = p - c * self.gap_function(u)
        active = s > 0.0
        r = p - np.maximum(0.0, s)
        dr_dp = np.where(active, 0.0, 1.0)
        dr_du = np.where(active, -c, 0.0)
        return r, dr_dp, dr_du

    def positive_part_form(self, c):
        """``(slope, offset)`` with ``r = p - max(0, p + slope (u - offset))``: ``(c, gap)``.

        The complementarity function as a positive part of an affine argument, for an exact
        Galerkin projection of ``max(0, .)`` on Fourier coefficients (``femodes.hbm``).
        """
        return float(c), self.gap


@dataclass(frozen=True)
class PenaltyContact(_Stackable):
    """Regularized (penalty) contact: ``p = stiffness * max(0, -g_N)``, ``g_N = gap - q[at]``.

    The classic alternative to complementarity; it allows a penetration of order
    ``p / stiffness`` and approaches the Signorini solution as ``stiffness -> inf``.
    ``gap`` (a number or a function of node coordinates) and ``direction`` as for
    :class:`UnilateralContact`; on a boundary each node gets the full ``stiffness``.
    """

    at: Location
    gap: Any
    stiffness: float
    direction: tuple | None = None

    @entry_point("PenaltyContact")
    def __post_init__(self):
        object.__setattr__(self, "at", check_location(self.at))
        object.__setattr__(self, "gap", _gap(self.gap))
        object.__setattr__(self, "stiffness", _positive(self.stiffness, "stiffness"))
        object.__setattr__(self, "direction", _direction(self.direction))

    def gap_function(self, u):
        """Normal gap ``g_N = gap - u`` (negative: penetration)."""
        return _normal_gap(self.gap, u)

    def force(self, u):
        """Contact force ``p = stiffness max(0, u - gap)`` (compression positive) and ``dp/du``.

        ``dp/du = stiffness`` where ``u > gap``, 0 elsewhere (at the kink ``u = gap`` the
        inactive side). Returns ``(p, dp_du)``.
        """
        pen = np.asarray(u, dtype=float) - self.gap  # -g_N
        active = pen > 0.0
        return self.stiffness * np.maximum(0.0, pen), np.where(active, self.stiffness, 0.0)

    def potential(self, u):
        """Stored energy ``stiffness/2 * max(0, u - gap)^2`` (its derivative is :meth:`force`)."""
        pen = np.maximum(0.0, np.asarray(u, dtype=float) - self.gap)
        return 0.5 * self.stiffness * pen**2

    def positive_part_form(self):
        """``(slope, offset)`` with ``p = slope max(0, u - offset)``: ``(stiffness, gap)``.

        For an exact Galerkin projection of ``max(0, .)`` on Fourier coefficients
        (``femodes.hbm``); the potential is then ``slope/2 max(0, u - offset)^2``.
        """
        return self.stiffness, self.gap


@dataclass(frozen=True)
class CubicSpring(_Stackable):
    """Grounded cubic (Duffing) spring: internal force ``k3 q[at]^3`` added to ``K q``.

    ``k3 > 0`` hardens, ``k3 < 0`` softens.
    """

    at: Location
    k3: float

    @entry_point("CubicSpring")
    def __post_init__(self):
        object.__setattr__(self, "at", check_location(self.at))
        k3 = _finite(self.k3, "k3")
        if k3 == 0.0:
            raise InputValueError("k3 must be non-zero (a zero spring does nothing), got 0.0")
        object.__setattr__(self, "k3", k3)

    def force(self, u):
        """Internal force ``k3 u^3`` and its derivative ``3 k3 u^2``. Returns ``(f, df_du)``."""
        u = np.asarray(u, dtype=float)
        return self.k3 * u**3, 3.0 * self.k3 * u**2

    def potential(self, u):
        """Potential ``k3 u^4 / 4`` (its derivative is :meth:`force`)."""
        u = np.asarray(u, dtype=float)
        return 0.25 * self.k3 * u**4
