"""Discretise layer: Newton steps of the HBM equations by harmonic blocks and a Schur complement.

The Jacobian keeps its structure (:mod:`.jacobian`): the dynamic stiffness block diagonal over
harmonics, a nonlinear part on the nonlinear DOFs, dense borders. :class:`BlockSolver`
(:mod:`.solver`) solves a Newton step by

1. splitting the unknowns into the interior (linear DOFs) and the boundary (nonlinear DOFs,
   contact forces, modal coordinates, border unknowns) and factorising each harmonic's interior
   block, band LU or sparse direct (:mod:`.blocks`, :mod:`.factors`);
2. condensing onto the boundary: a dense Schur complement, factorised by LU with partial
   pivoting (:mod:`.schur`; modal damping's low-rank part in :mod:`.lowrank`);
3. back substitution (:mod:`.elimination`), then iterative refinement against the true ``J``
   with a sparse direct LU of the assembled matrix as the fallback (:mod:`.factorization`, :mod:`.assembled`);
4. optionally reusing the factors of a nearby frequency (:mod:`.reuse`; GMRES on sparse-direct
   blocks, :mod:`.krylov`).

Small and half-full systems go to LAPACK on the dense matrix, mid-size ones to SuperLU
(:mod:`.assembled`). The tuning is one frozen :class:`BlockSolverOptions` (:mod:`.options`),
passed as ``BlockSolver(options=...)``. The module constants of femodes 0.1 (``DENSE_MAX_SIZE``,
``SUPERLU_OPTIONS``, ...) still read the defaults, with a ``DeprecationWarning``; setting them no
longer changes anything: pass options instead.
"""

from __future__ import annotations

import warnings

from .assembled import AssembledSolver
from .jacobian import BlockStructure, HarmonicBlockJacobian
from .blocks import StructureFailure
from .options import DEFAULT_OPTIONS, BlockSolverOptions, solver_memory
from .solver import BlockSolver

# the internals that scripts, tests and benchmarks import from here (femodes 0.1's single module)
from .assembled import AssembledFactorization, DenseFactorization, ForceSchur, refinement_tolerance  # noqa: F401
from .blocks import BlockLU, BlockPattern, build_pattern, real_times_complex  # noqa: F401
from .factorization import StructuredFactorization  # noqa: F401
from .factors import HarmonicFactors, LinearFactors  # noqa: F401
from .reuse import ReusedFactorization  # noqa: F401
from .solver import STAT_KEYS  # noqa: F401

__all__ = ["HarmonicBlockJacobian", "StructureFailure", "BlockSolver", "AssembledSolver", "BlockStructure",
           "BlockSolverOptions", "solver_memory"]

# the names of femodes 0.1's single module, for scripts that imported them (not part of the API)
_Dense = DenseFactorization
_ForceSchur = ForceSchur
_Generic = AssembledFactorization
_Factorization = StructuredFactorization
_Pattern = BlockPattern
_Harmonic = HarmonicFactors
_real_times_complex = real_times_complex
_refinement_tolerance = refinement_tolerance

#: The module constants of femodes 0.1 and the option each one became.
_DEPRECATED_CONSTANTS = {
    "STRUCTURED_MIN_SIZE": "structured_min_size",
    "DENSE_MAX_SIZE": "dense_max_size",
    "DENSE_FILL": "dense_fill",
    "DENSE_OPERATORS_MAX": "dense_operators_max",
    "SCHUR_MIN_SIZE": "schur_min_size",
    "SCHUR_MAX_GROWTH": "schur_max_growth",
    "KEEP_W_MAX_BYTES": "keep_w_max_bytes",
    "REUSE_LU_COST": "reuse_lu_cost",
    "REUSE_LU_COST_SPARSE": "reuse_lu_cost_sparse",
    "REUSE_PASS_OVERHEAD": "reuse_pass_overhead",
    "REUSE_MATVEC_COST": "reuse_matvec_cost",
    "REUSE_FORWARD_TOL": "reuse_forward_tol",
    "BAND_MAX_FILL": "band_max_fill",
    "SUPERLU_OPTIONS": "superlu_options",
    "THREAD_MIN_SIZE": "thread_min_size",
}


def __getattr__(name: str):
    option = _DEPRECATED_CONSTANTS.get(name)
    if option is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"femodes.hbm.linsolve.{name} is deprecated: it is BlockSolverOptions().{option} (pass "
                  f"BlockSolver(options=BlockSolverOptions({option}=...)) to change it)", DeprecationWarning,
                  stacklevel=2)
    return getattr(DEFAULT_OPTIONS, option)


def __dir__():
    return sorted(set(globals()) | set(_DEPRECATED_CONSTANTS))
