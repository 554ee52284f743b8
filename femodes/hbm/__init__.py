"""Discretise layer: harmonic balance (Fourier layout, AFT, dynamic stiffness, HBM problems)."""

from .harmonics import Harmonics
from .problems import ForcedResponseProblem, NonlinearModeProblem
from .system import HBMSystem, default_contact_parameter

__all__ = ["Harmonics", "ForcedResponseProblem", "NonlinearModeProblem", "HBMSystem", "default_contact_parameter"]
