"""How an error estimate finds the converged answer, as strategy objects (``fm.error_methods``):
``estimate_error(branch, method=Levels())``, ``frequency_response(..., rtol=1e-3,
error_method=Shooting())``.

:class:`Auto` (the default)
    The exact orbits of the flow with rigid stops, by shooting (:mod:`.shooting`, then the exact
    branch's folds, :mod:`.exact_branch`), where they apply: linear models with complementarity
    contacts of restitution 1 that shooting can take (:func:`~.shooting.shooting_unsupported`);
    the levels of harmonics (:mod:`.levels`) for the rest, and for the points shooting does not
    answer.
:class:`Shooting`
    As :class:`Auto`, but a model or branch that shooting cannot take is a ValueError (a
    deliberate choice that cannot hold is refused, not replaced).
:class:`Levels`
    The levels of harmonics only (``H``, ``2H``, ``4H``..., extrapolated): every model.

A strategy runs the part of the estimate before the levels (:meth:`shoot`) and says whether it
can take a model before any work is done (:meth:`check`). The names ``"auto"``, ``"shooting"``,
``"levels"`` are deprecated spellings of these objects (:func:`as_error_method`).
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any, ClassVar, Protocol

import numpy as np

from .exact_branch import ExactBranchCache, ExactFolds
from .ladder import Ladder
from .options import AccuracyOptions
from .protocol import PointErrors
from .shooting import Shooting as ShootingEstimator
from .shooting import shooting_unsupported, shooting_unsupported_for
from ..solvers.checks import InputValueError, strategy

__all__ = ["ErrorMethod", "Auto", "Shooting", "Levels", "as_error_method", "check_estimate_method", "by_name"]

log = logging.getLogger(__name__)


class ErrorMethod(Protocol):
    """The part of an error estimate before the levels of harmonics."""

    name: ClassVar[str]

    def check(self, model, harmonics, projection) -> None:
        """Raise ValueError when this strategy cannot take ``model`` (before any work)."""

    def shoot(self, lad: Ladder, errors: PointErrors, projection, options: AccuracyOptions) -> np.ndarray:
        """Fill ``errors`` where this strategy answers; the points left for the levels."""


@dataclasses.dataclass(frozen=True)
class Levels:
    """The levels of harmonics only (module docstring)."""

    name: ClassVar[str] = "levels"

    def check(self, model, harmonics, projection) -> None:
        return None

    def shoot(self, lad: Ladder, errors: PointErrors, projection, options: AccuracyOptions) -> np.ndarray:
        return np.ones(len(lad.branch), dtype=bool)


@dataclasses.dataclass(frozen=True)
class Auto:
    """Shooting where it applies, the levels elsewhere (module docstring)."""

    name: ClassVar[str] = "auto"

    def check(self, model, harmonics, projection) -> None:
        return None

    def shoot(self, lad: Ladder, errors: PointErrors, projection, options: AccuracyOptions) -> np.ndarray:
        return _shooting(lad, errors, projection, options, strict=False)


@dataclasses.dataclass(frozen=True)
class Shooting:
    """Shooting, refused where it does not apply (module docstring)."""

    name: ClassVar[str] = "shooting"

    def check(self, model, harmonics, projection) -> None:
        why = shooting_unsupported_for(model, harmonics, projection)
        if why:
            raise InputValueError(f"the shooting error method cannot take this model: {why}; use "
                                  "femodes.error_methods.Levels() (or Auto(), which picks)")

    def shoot(self, lad: Ladder, errors: PointErrors, projection, options: AccuracyOptions) -> np.ndarray:
        return _shooting(lad, errors, projection, options, strict=True)


_BY_NAME: dict[str, ErrorMethod] = {"auto": Auto(), "shooting": Shooting(), "levels": Levels()}


def as_error_method(value: Any, name: str = "method") -> ErrorMethod:
    """``value`` as a strategy (:func:`~femodes.solvers.checks.strategy`): None is :class:`Auto`;
    a strategy object as it is; one of the names ``"auto"``, ``"levels"``, ``"shooting"`` its
    object, with a DeprecationWarning; anything else a ValueError that lists the strategies."""
    if value is None:
        return _BY_NAME["auto"]
    return strategy(value, name, _BY_NAME, "femodes.error_methods", "an error method",
                    lambda v: isinstance(v, (Auto, Levels, Shooting)))


def check_estimate_method(method: Any, name: str = "method") -> ErrorMethod:
    """:func:`as_error_method` (the name this check had when methods were strings)."""
    return as_error_method(method, name)


def by_name(name: str) -> ErrorMethod:
    """The strategy of a case file's name (``"auto"``, ``"levels"``, ``"shooting"``)."""
    return _BY_NAME[name]


def _shooting(lad: Ladder, errors: PointErrors, projection, options: AccuracyOptions, strict: bool) -> np.ndarray:
    """Shooting, then the exact branch's folds (:class:`~.shooting.Shooting`,
    :class:`~.exact_branch.ExactFolds`) where they apply; the points left for the levels. A
    branch they cannot take goes to the levels whole, or, ``strict``, is a ValueError."""
    n = len(lad.branch)
    why = shooting_unsupported(lad.branch, projection)
    if why and strict:
        raise ValueError(f"estimate_error: the shooting error method cannot take this branch: {why}; use "
                         "femodes.error_methods.Levels() (or Auto())")
    if why:
        return np.ones(n, dtype=bool)
    exact = ExactBranchCache(lad)
    todo = np.ones(n, dtype=bool)
    try:
        for estimator in (ShootingEstimator(exact, options, auto=not strict), ExactFolds(exact, options)):
            todo = estimator.estimate(lad, errors, todo)
    except ValueError as exc:  # the flow itself (a nearly defective state matrix), or too stiff for auto
        if strict:
            raise ValueError(f"estimate_error: shooting: {exc}") from None
        log.info("accuracy: no shooting (%s); levels", exc)
        errors.clear()
        todo = np.ones(n, dtype=bool)
    if todo.any():
        log.info("accuracy: shooting found no exact orbit at %d point(s); levels there", int(todo.sum()))
    return todo
