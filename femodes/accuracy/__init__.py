"""Analyses layer: how far a harmonic balance branch is from the converged (``H -> inf``) answer.

Harmonic balance with ``H`` harmonics converges exponentially for smooth laws and only
algebraically for impacts (the upper fold of the seed's forced impact oscillator is 4.4, 2.4, 1.2,
0.67 % off at H = 10, 20, 40, 80). :func:`estimate_error` states that error for every point of a
branch (``branch.accuracy``), and the analyses' ``rtol=`` refines it (:func:`meet_tolerance`). The
theory and the measurements are in docs/guide/accuracy.md and benchmarks/README_accuracy.md.

Modules, one idea each:

* :mod:`.options`: :class:`AccuracyOptions` (the tuning, with the measurements behind it) and the
  checks of the estimate's arguments;
* :mod:`.protocol`: the estimators' protocol and the per-point record they fill;
* estimators: :mod:`.levels` (harmonic balance at other ``H``, extrapolated), :mod:`.shooting`
  (the exact orbits of the flow with rigid stops), :mod:`.exact_branch` (the folds of the exact
  branch over the span);
* the levels' machinery: :mod:`.points` (the branch's points), :mod:`.ladder` (the problem at any
  ``H``, hyperplane solves), :mod:`.extrapolation` (what the levels of a point say), :mod:`.walk`
  and :mod:`.level_trace` (tracing a level along the branch, by steps or by continuation);
* shooting's machinery: :mod:`.planes`, :mod:`.shooter` (Newton on the exact orbit),
  :mod:`.exact_fold` (the exact fold next to a fold of the branch);
* :mod:`.methods`: the strategies a user chooses (``femodes.error_methods``: ``Auto``,
  ``Shooting``, ``Levels``);
* :mod:`.estimate` (:func:`estimate_error`) and :mod:`.tolerance` (``rtol=``).

The tuning constants that were module globals (``RATE_MIN``, ``SHOOTING_FLOOR``, ...) are fields of
:class:`AccuracyOptions` now (lower case); the old names still read their defaults, with a
DeprecationWarning.
"""

from __future__ import annotations

import dataclasses
import warnings

from . import methods
from .estimate import estimate_error
from .extrapolation import estimate_levels
from .methods import check_estimate_method
from .options import ESTIMATE_METHODS, AccuracyOptions, check_options, refinement_options
from .shooting import GLANCING, shooting_unsupported, shooting_unsupported_for
from .tolerance import meet_tolerance, rtol_time_limit

__all__ = ["methods", "AccuracyOptions", "estimate_error", "estimate_levels", "meet_tolerance", "rtol_time_limit",
           "shooting_unsupported", "shooting_unsupported_for", "refinement_options", "check_estimate_method",
           "check_options", "ESTIMATE_METHODS", "GLANCING"]

#: The module constants of femodes.accuracy before issue 39 and the AccuracyOptions fields that replace them.
_DEPRECATED = {f.name.upper(): f.name for f in dataclasses.fields(AccuracyOptions)}
_DEPRECATED.pop("SHOOTING_FOLD_SEARCH")  # new: never a module constant


def __getattr__(name: str):
    field = _DEPRECATED.get(name)
    if field is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"femodes.accuracy.{name} is deprecated: it is AccuracyOptions().{field} now, and the estimate "
                  f"reads it from the options it is given (estimate_error(..., options=AccuracyOptions({field}=...)), "
                  f"frequency_response(..., error_options=...)); changing the module constant has no effect",
                  DeprecationWarning, stacklevel=2)
    return getattr(AccuracyOptions(), field)
