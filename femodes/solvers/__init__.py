"""Solvers layer: generic nonlinear solvers that know only ``residual(x, p)``; imports nothing from femodes.

* :func:`semismooth_newton` -- globalised (non-monotone line search)
  semismooth Newton method for ``r(x) = 0`` with dense or sparse generalized
  Jacobians.
* :func:`continuation` -- pseudo-arclength continuation of ``r(x, p) = 0``
  through folds, with step control and exact stops at the span ends; a run
  resumes exactly from a saved :class:`ContinuationState`.
* Jacobians may be dense, ``scipy.sparse`` or structured operators that
  factorise themselves (``J.factorize().solve(b)``, duck-typed).

Modules: ``newton`` (semismooth Newton), ``continuation`` (the driver),
``tracing`` (one run: the tracer) and its parts ``predictors`` (strategies, public as ``femodes.predictors``), ``step_control``, ``guard``
(branch jumping), ``folds``, ``span_ends`` and ``trace_record`` (the run's points),
``protocols`` (what a problem provides, with the optional phase hook),
``continuation_types`` (options, points, states, results),
``arclength`` (the problem's evaluation, scaled geometry, tangent and corrector
solves), ``bordered`` (bordered matrices and their solver), ``roots`` (a bracketed
scalar root by Illinois regula falsi: folds, stability changes), ``checks`` (the
argument validators shared by the solvers and the layers above), ``threads`` (how many BLAS
threads the analyses' loops use: :func:`limit_blas_threads`, ``FEMODES_BLAS_THREADS``).
"""

from .continuation import ContinuationOptions, ContinuationPoint, ContinuationResult, ContinuationState, continuation
from .newton import NewtonOptions, NewtonResult, semismooth_newton
from .threads import limit_blas_threads

__all__ = [
    "NewtonOptions",
    "NewtonResult",
    "semismooth_newton",
    "ContinuationOptions",
    "ContinuationPoint",
    "ContinuationResult",
    "ContinuationState",
    "continuation",
    "limit_blas_threads",
]
