"""Discretise layer: harmonic balance (Fourier layout, exact positive part, dynamic stiffness, HBM problems, block solver)."""

from .galerkin import GalerkinProjection
from .harmonic_layout import HarmonicLayout
from .harmonics import Harmonics
from .linsolve import AssembledSolver, BlockSolver, BlockSolverOptions, HarmonicBlockJacobian
from .positive_part import ExactProjection, SampledProjection
from .problems import ForcedResponseProblem, HBMUnknowns, NonlinearModeProblem, PeriodDrivenModeProblem
from .linear_part import LinearPart
from .system import HBMSystem, default_contact_parameter
from .time_grid import TimeGrid
from .time_operators import TimeOperators
from .trigroots import ColleagueRoots, CompanionRoots, GridRoots

__all__ = ["Harmonics", "HarmonicBlockJacobian", "ForcedResponseProblem", "NonlinearModeProblem", "PeriodDrivenModeProblem", "HBMUnknowns",
           "HBMSystem", "default_contact_parameter", "ExactProjection", "SampledProjection", "BlockSolver",
           "BlockSolverOptions", "AssembledSolver", "ColleagueRoots", "CompanionRoots", "GridRoots", "HarmonicLayout",
           "TimeGrid", "TimeOperators", "GalerkinProjection", "LinearPart"]
