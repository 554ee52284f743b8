"""femodes: nonlinear vibration modes of finite-element structures with unilateral contact.

The public face of the package. Layers, from the bottom: solvers, laws, models (fe, model,
reduction, linear, eigen, sparse_direct, dynamic_stiffness), discretise (hbm, time), results
(results, store, exact_branch), analyses, outputs (fields, plot, io, viz), application (app); README
"How the code is organised".
"""

from .fe import Material, Section, bar, beam, box_mesh, line_mesh, load_mesh, rectangle_mesh, solid
from .fe.redistribution import ConsistentMass, RedistributeMass
from .laws import CubicSpring, PenaltyContact, UnilateralContact
from .linear import IllConditionedWarning, LinearModes, LinearResponse, grazing_energy, linear_modes, linear_response
from .model import DofMap, HarmonicForce, StructuralModel
from .reduction import ReducedModel, craig_bampton
from .sparse_direct import SparseBackendInfo, sparse_backend_info
from .hbm import ForcedResponseProblem, Harmonics, NonlinearModeProblem
from .solvers import (ContinuationOptions, ContinuationResult, ContinuationState, NewtonOptions, NewtonResult,
                      continuation, semismooth_newton)
from .results import Bifurcation, Branch, ErrorEstimate, PeriodicSolution, load_branch
from .exact_branch import ExactBranch
from .analyses import StaticContactResult, frequency_response, nonlinear_mode, static_contact
from .exact_response import exact_frequency_response
from .nonsmooth_modes import InternalResonance, PeriodDriven
from .resonance import ResonancePeak, compare_resonance
from .tongues import tongue_branch
from .floquet import StabilityOptions, StabilityResult, stability
from .accuracy import AccuracyOptions, estimate_error
from .mesh_error import estimate_mesh_error
from .switching import switch_branch
from .store import Checkpoint
from .time import SteadyState, TimeHistory, TimeSteppingOptions, simulate, steady_state
from . import io, plot  # outputs; matplotlib is imported lazily inside plot functions
from . import error_methods, predictors, stability_methods  # strategies: stability=stability_methods.Hill(), ...

__version__ = "0.1.0"

__all__ = [
    "stability_methods",
    "predictors",
    "error_methods",
    "Material",
    "Section",
    "bar",
    "beam",
    "solid",
    "line_mesh",
    "load_mesh",
    "rectangle_mesh",
    "box_mesh",
    "RedistributeMass",
    "ConsistentMass",
    "CubicSpring",
    "PenaltyContact",
    "UnilateralContact",
    "IllConditionedWarning",
    "LinearModes",
    "LinearResponse",
    "linear_modes",
    "linear_response",
    "grazing_energy",
    "PeriodDriven",
    "InternalResonance",
    "ResonancePeak",
    "compare_resonance",
    "tongue_branch",
    "DofMap",
    "HarmonicForce",
    "StructuralModel",
    "Bifurcation",
    "StabilityOptions",
    "StabilityResult",
    "stability",
    "switch_branch",
    "ReducedModel",
    "craig_bampton",
    "SparseBackendInfo",
    "sparse_backend_info",
    "Harmonics",
    "ForcedResponseProblem",
    "NonlinearModeProblem",
    "ContinuationOptions",
    "ContinuationResult",
    "ContinuationState",
    "NewtonOptions",
    "NewtonResult",
    "continuation",
    "semismooth_newton",
    "Branch",
    "ExactBranch",
    "ErrorEstimate",
    "estimate_error",
    "AccuracyOptions",
    "estimate_mesh_error",
    "PeriodicSolution",
    "load_branch",
    "Checkpoint",
    "frequency_response",
    "exact_frequency_response",
    "nonlinear_mode",
    "static_contact",
    "StaticContactResult",
    "SteadyState",
    "TimeHistory",
    "simulate",
    "steady_state",
    "TimeSteppingOptions",
    "io",
    "plot",
]


def __getattr__(name):
    # fm.viz imports lazily: pyvista/VTK are optional (pip install "femodes[render]")
    if name == "viz":
        import importlib

        return importlib.import_module(".viz", __name__)
    raise AttributeError(f"module 'femodes' has no attribute {name!r}")
