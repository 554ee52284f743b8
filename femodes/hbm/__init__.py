"""Discretise layer: harmonic balance (Fourier layout, AFT, dynamic stiffness, HBM problems, block solver)."""

from .harmonics import Harmonics
from .linsolve import HarmonicBlockJacobian
from .problems import ForcedResponseProblem, HBMUnknowns, NonlinearModeProblem
from .system import HBMSystem, default_contact_parameter

__all__ = ["Harmonics", "HarmonicBlockJacobian", "ForcedResponseProblem", "NonlinearModeProblem", "HBMUnknowns",
           "HBMSystem", "default_contact_parameter"]
