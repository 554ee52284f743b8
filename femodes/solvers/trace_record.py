"""Solvers layer: the record of one continuation run that the parts of the tracer share: its
accepted points (:class:`TracePoint`), folds, and the two exceptions that steer the run
(:class:`StopRun` ends it, :class:`RetryStep` retries the step from the same point)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["TracePoint", "BranchRecord", "StopRun", "RetryStep", "contraction"]


@dataclass
class TracePoint:
    """Record of an accepted point: y = (x, p), unit tangent t."""

    y: np.ndarray
    t: np.ndarray
    nit: int
    rnorm: float
    step: float
    #: what the step that produced the point measured (step control): turn of the tangent
    #: [degrees], predictor-corrector distance, contraction of the first corrector iteration
    angle: float = math.nan
    dist: float = math.nan
    theta: float = math.nan
    #: phase delay of the step's predictor (radians; 0 for the tangent predictor)
    tau: float = 0.0


@dataclass
class BranchRecord:
    """The points accepted so far and the folds. A resumed run keeps its start point as
    ``pts[0]`` (the previous point of the first step) but does not return it (``skip = 1``): the
    branch index of ``pts[k]`` is ``i0 + k``."""

    i0: int = 0
    skip: int = 0
    pts: list[TracePoint] = field(default_factory=list)
    folds: list[int] = field(default_factory=list)
    #: folds located as turning points in this run
    located: list[int] = field(default_factory=list)

    def last_index(self) -> int:
        """Branch index of the last accepted point."""
        return self.i0 + len(self.pts) - 1


class StopRun(Exception):
    """End of the run with ``status`` (see :data:`STATUS_MESSAGES`) and a detail for the message."""

    def __init__(self, status: int, extra: str = "") -> None:
        super().__init__(extra)
        self.status, self.extra = status, extra


class RetryStep(Exception):
    """The step was rejected and halved: try again from the same point."""


def contraction(history: tuple[float, ...]) -> float:
    """Contraction ``|r_1| / |r_0|`` of the first corrector iteration (NaN without an iteration)."""
    if len(history) < 2:
        return math.nan
    r0, r1 = history[0], history[1]
    if not r0 > 0:
        return 0.0
    return r1 / r0
