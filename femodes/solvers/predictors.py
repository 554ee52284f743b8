"""Solvers layer: the predictor of a continuation step, a strategy object (``ContinuationOptions.predictor``).

:class:`Tangent` is the Euler predictor ``y + ds t``. :class:`Phase`, for a problem with the
optional hook :class:`~femodes.solvers.protocols.SupportsPhaseShift`, splits the tangent's ``x``
part into a phase rate ``alpha`` along ``g = phase_generator(x)`` (scaled inner product) and the
rest ``r`` and predicts ``phase_shift(x + ds r, ds alpha)``: the same to first order in ``ds``, but
harmonic ``k`` turns by ``k ds alpha`` exactly instead of along its chord. Without the hook it is
the tangent predictor.

A predictor of the user's own is any object with a ``name`` and a method ``bind(system)`` that
returns a :class:`StepPredictor` for one run (``system`` is the run's
:class:`~femodes.solvers.arclength.ArclengthSystem`: ``problem``, ``n``, the scale weights ``w``
and ``norm``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from .checks import strategy
from .protocols import SupportsPhaseShift, phase_hook
from .trace_record import TracePoint

__all__ = ["Phase", "PredictorStrategy", "StepPredictor", "Tangent", "as_predictor"]


@runtime_checkable
class StepPredictor(Protocol):
    """The predictor of one run. ``predict(a, ds)`` is the predicted ``y = (x, p)`` of the step
    ``ds`` from the point ``a`` and sets ``tau``, the phase delay of that prediction (None when
    it delays nothing); ``reference_tangent(a)`` is ``a``'s tangent as a step that only followed
    the prediction would end with (the turn angle of the step guards is measured from it)."""

    tau: float | None

    def predict(self, a: TracePoint, ds: float) -> np.ndarray: ...

    def reference_tangent(self, a: TracePoint) -> np.ndarray: ...


@runtime_checkable
class PredictorStrategy(Protocol):
    """What ``ContinuationOptions(predictor=...)`` takes: a ``name`` and ``bind(system)``."""

    name: ClassVar[str]

    def bind(self, system: Any) -> StepPredictor: ...


class _TangentStep:
    tau: float | None = None

    def predict(self, a: TracePoint, ds: float) -> np.ndarray:
        return a.y + ds * a.t

    def reference_tangent(self, a: TracePoint) -> np.ndarray:
        return a.t


class _PhaseStep:
    """The phase-following predictor of one run (the tangent one where the delay is not finite)."""

    def __init__(self, system: Any, hook: SupportsPhaseShift) -> None:
        self.sys, self.n, self.phase = system, system.n, hook
        self.tau: float | None = None

    def predict(self, a: TracePoint, ds: float) -> np.ndarray:
        self.tau = None
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
        if self.tau is None:
            return a.t
        n = self.n
        t = np.append(np.asarray(self.phase.phase_shift(a.t[:n], self.tau), dtype=float), a.t[n])
        norm = self.sys.norm(t)
        return t / norm if norm > 0 and math.isfinite(norm) else a.t


@dataclasses.dataclass(frozen=True)
class Tangent:
    """The Euler predictor ``y + ds t`` (Allgower & Georg 2003, sec. 2.2)."""

    name: ClassVar[str] = "tangent"

    def bind(self, system: Any) -> StepPredictor:
        return _TangentStep()


@dataclasses.dataclass(frozen=True)
class Phase:
    """The tangent with its phase part applied as an exact delay (module docstring); the default.

    An impact's contact force has harmonics of equal size up to ``H``; when the impact moves in
    phase along the branch they turn ``k`` times faster than the first one, so in Fourier
    coordinates the branch is a helix whose turning grows with ``H``, and the tangent predictor
    needs a number of points proportional to ``H`` (measurements: ``benchmarks/README_steps.md``).
    """

    name: ClassVar[str] = "phase"

    def bind(self, system: Any) -> StepPredictor:
        hook = phase_hook(system.problem)
        return _TangentStep() if hook is None else _PhaseStep(system, hook)


#: the deprecated names of the predictors (``ContinuationOptions(predictor="phase")``)
NAMES: dict[str, PredictorStrategy] = {"phase": Phase(), "tangent": Tangent()}


def as_predictor(value: Any) -> PredictorStrategy:
    """``value`` as a predictor strategy (a deprecated name mapped to its object, with a warning)."""
    return strategy(value, "predictor", NAMES, "femodes.predictors", "a predictor",
                    lambda v: not isinstance(v, type) and callable(getattr(v, "bind", None))
                    and isinstance(getattr(v, "name", None), str))
