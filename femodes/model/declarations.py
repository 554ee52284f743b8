"""What is declared on a model: harmonic point forces, laws bound to model DOFs (``Attached``),
the kinds of law each ``with_*`` accepts, and the binding of smooth laws (``with_nonlinearity``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..laws import CubicSpring, Location, PenaltyContact, UnilateralContact, check_location
from ..solvers.checks import InputValueError, entry_point, named_by

__all__ = ["HarmonicForce", "Attached", "CONTACT_LAWS", "SMOOTH_LAWS", "show_vector", "bind_nonlinearities",
           "nonlinear_dofs"]

#: The laws of :meth:`~femodes.StructuralModel.with_contact`.
CONTACT_LAWS = (UnilateralContact, PenaltyContact)
#: The laws of :meth:`~femodes.StructuralModel.with_nonlinearity`.
SMOOTH_LAWS = (CubicSpring,)


@dataclass(frozen=True)
class HarmonicForce:
    """Point force ``amplitude * cos(harmonic * w t + phase)`` at a DOF.

    ``harmonic`` is the multiple of the forcing frequency ``w`` (1 = primary forcing).
    """

    at: Location
    amplitude: float = 1.0
    harmonic: int = 1
    phase: float = 0.0

    @entry_point("HarmonicForce")
    def __post_init__(self):
        object.__setattr__(self, "at", check_location(self.at))
        for name in ("amplitude", "phase"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise InputValueError(f"{name} must be a finite real number, got {v!r}")
            object.__setattr__(self, name, float(v))
        h = self.harmonic
        if isinstance(h, bool) or not isinstance(h, (int, np.integer)) or h < 0:
            raise InputValueError(f"harmonic must be an integer >= 0 (0 = static load), got {h!r}")
        object.__setattr__(self, "harmonic", int(h))


@dataclass(frozen=True)
class Attached:
    """A declaration (law or force) bound to a model DOF index."""

    item: Any
    dof: int


def show_vector(v) -> str:
    """A vector in messages: ``(0.8, 0.6)``."""
    return "(" + ", ".join(f"{float(x):.6g}" for x in v) + ")"


def bind_nonlinearities(model, laws) -> list[Attached]:
    """The smooth nonlinear ``laws`` (e.g. CubicSpring) bound to the DOFs of ``model``."""
    if not laws:
        raise ValueError("with_nonlinearity: give at least one law, e.g. CubicSpring(at=0, k3=1.0)")
    new = []
    for law in laws:
        if not isinstance(law, SMOOTH_LAWS):
            raise TypeError(
                f"with_nonlinearity: expected CubicSpring, got {type(law).__name__}"
                + (" (use with_contact for contact laws)" if isinstance(law, CONTACT_LAWS) else "")
            )
        with named_by("with_nonlinearity: CubicSpring"):
            new.append(Attached(law, model.dofmap.find(law.at)))
    return new


def nonlinear_dofs(model) -> np.ndarray:
    """Sorted unique DOFs of ``model`` that carry contact or nonlinear laws."""
    d = [a.dof for a in model.contacts] + [a.dof for a in model.nonlinearities]
    return np.unique(np.asarray(d, dtype=int))
