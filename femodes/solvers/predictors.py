"""Solvers layer: the predictor of a continuation step (``ContinuationOptions.predictor``).

The tangent predictor is ``y + ds t``. The phase predictor, for a problem with the optional hook
:class:`~femodes.solvers.protocols.SupportsPhaseShift`, splits the tangent's ``x`` part into a
phase rate ``alpha`` along ``g = phase_generator(x)`` (scaled inner product) and the rest ``r``
and predicts ``phase_shift(x + ds r, ds alpha)``: the same to first order in ``ds``, but harmonic
``k`` turns by ``k ds alpha`` exactly instead of along its chord.
"""

from __future__ import annotations

import math

import numpy as np

from .arclength import ArclengthSystem
from .continuation_types import ContinuationOptions
from .protocols import SupportsPhaseShift, phase_hook
from .trace_record import TracePoint

__all__ = ["Predictor"]


class Predictor:
    """Predictor of the steps of one run; :attr:`tau` is the phase delay of the last prediction
    (None for the tangent predictor, or where the phase predictor fell back to it)."""

    def __init__(self, system: ArclengthSystem, options: ContinuationOptions) -> None:
        self.sys = system
        self.n = system.n
        self.phase: SupportsPhaseShift | None = phase_hook(system.problem) if options.predictor == "phase" else None
        self.tau: float | None = None

    def predict(self, a: TracePoint, ds: float) -> np.ndarray:
        """The predictor of the step ``ds`` from ``a``; sets :attr:`tau`."""
        self.tau = None
        if self.phase is not None:
            n = self.n
            x, tx, w = a.y[:n], a.t[:n], self.sys.w[:n]
            g = np.asarray(self.phase.phase_generator(x), dtype=float)
            gg = float(np.sum(w * g * g))
            if gg > 0 and math.isfinite(gg):
                alpha = float(np.sum(w * tx * g)) / gg
                x_pred = np.asarray(self.phase.phase_shift(x + ds * (tx - alpha * g), ds * alpha), dtype=float)
                if x_pred.shape == (n,) and np.all(np.isfinite(x_pred)):
                    self.tau = ds * alpha
                    return np.append(x_pred, a.y[n] + ds * a.t[n])
        return a.y + ds * a.t

    def reference_tangent(self, a: TracePoint) -> np.ndarray:
        """``a``'s tangent delayed by the phase of the last prediction (unit length in the scaled
        norm): what a step that only moved the motion in phase would end with."""
        if self.tau is None or self.phase is None:
            return a.t
        n = self.n
        t = np.append(np.asarray(self.phase.phase_shift(a.t[:n], self.tau), dtype=float), a.t[n])
        norm = self.sys.norm(t)
        return t / norm if norm > 0 and math.isfinite(norm) else a.t
