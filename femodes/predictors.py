"""Solvers layer: the predictors of a continuation step, ``femodes.predictors``
(:mod:`femodes.solvers.predictors`): ``Phase()`` (default), ``Tangent()``, for
``ContinuationOptions(predictor=...)``.
"""

from .solvers.predictors import Phase, PredictorStrategy, StepPredictor, Tangent, as_predictor

__all__ = ["Phase", "Tangent", "PredictorStrategy", "StepPredictor", "as_predictor"]
