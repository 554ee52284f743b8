"""Solvers layer: what the continuation asks of a problem, as typing protocols.

A problem needs only ``residual(x, p)`` (:class:`ContinuationProblem`). Two optional hooks are
used when present: ``initial_guess(p)`` (a start without ``x0=``) and, for a periodic motion that
can be delayed in phase, the pair of :class:`SupportsPhaseShift` (the phase-following predictor,
``ContinuationOptions(predictor=femodes.predictors.Phase())``; :class:`~femodes.hbm.ForcedResponseProblem` has it).
The protocols are structural: a problem needs the methods, not the base class.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["ContinuationProblem", "SupportsPhaseShift", "phase_hook"]


@runtime_checkable
class ContinuationProblem(Protocol):
    """``residual(x, p) -> (r, dr_dx, dr_dp)``: ``r`` of shape ``(n,)``, ``dr_dx`` of shape ``(n, n)``
    (dense, ``scipy.sparse`` or an operator with ``factorize()``), ``dr_dp`` of shape ``(n,)``."""

    def residual(self, x: np.ndarray, p: float) -> tuple[np.ndarray, Any, np.ndarray]: ...


@runtime_checkable
class SupportsPhaseShift(Protocol):
    """The optional hook of a problem whose unknowns describe a periodic motion.

    ``phase_shift(x, tau)`` is the unknowns of the motion delayed by the phase ``tau`` (radians of
    the fundamental) and ``phase_generator(x)`` its derivative ``d/dtau`` at ``tau = 0``. With both,
    ``predictors.Phase()`` applies the phase part of the tangent as an exact delay.
    """

    def phase_shift(self, x: np.ndarray, tau: float) -> np.ndarray: ...

    def phase_generator(self, x: np.ndarray) -> np.ndarray: ...


def phase_hook(problem: Any) -> SupportsPhaseShift | None:
    """``problem`` if it provides :class:`SupportsPhaseShift` with callable methods, else None."""
    if isinstance(problem, SupportsPhaseShift) and callable(problem.phase_shift) \
            and callable(problem.phase_generator):
        return problem
    return None
