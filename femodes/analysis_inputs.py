"""Analyses layer: the checks of what a user passes to an analysis (model, harmonics, spans,
options, a start vector), each error naming the argument, and the warnings on physics a run
cannot fix (an undamped forced model, rigid-body modes)."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from .eigen import normal_modes
from .hbm.harmonics import Harmonics
from .linear import rigid_body_message, rigid_body_modes
from .model import StructuralModel
from .solvers import ContinuationOptions
from .solvers.checks import InputTypeError, InputValueError

__all__ = ["check_harmonics", "check_span", "check_continuation_options", "check_model", "start_vector", "largest_unknown",
           "warn_rigid_body", "warn_undamped", "resonant_harmonics",
           "commensurate_modes"]


def check_harmonics(h: Any) -> Harmonics:
    if isinstance(h, Harmonics):
        return h
    if isinstance(h, (int, np.integer)) and not isinstance(h, bool):
        if h < 1:
            raise InputValueError(f"harmonics must be >= 1 (the number of harmonics), got {int(h)}")
        return Harmonics(int(h))
    raise InputTypeError(f"harmonics must be a femodes.Harmonics (or an int number of harmonics), got {h!r}")


def check_span(value: Any, name: str, *, positive: bool) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InputTypeError(f"{name} must be a pair (start, end) of numbers, got {value!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)) or a == b or (positive and (a <= 0 or b <= 0)):
        raise InputValueError(f"{name} must be two distinct finite{' positive' if positive else ''} numbers, got {value!r}")
    # (b - a) * (b - a): a Python float's ** raises OverflowError where * gives inf
    if not math.isfinite((b - a) * (b - a)) or (b - a) * (b - a) == 0.0 or (positive and not 1e-150 < min(a, b) <= max(a, b) < 1e150):
        raise InputValueError(f"{name} = {value!r} is out of the representable range (its width squared under- or "
                              "overflows); rescale the units")
    return a, b


def check_continuation_options(options: Any) -> ContinuationOptions | None:
    if options is not None and not isinstance(options, ContinuationOptions):
        raise InputTypeError(f"options must be a femodes.ContinuationOptions or None, got {type(options).__name__}")
    return options


def warn_rigid_body(model: StructuralModel) -> None:
    """A forced model free to move as a whole (no supports, or a floating mesh part): its static
    harmonic has no stiffness, so the mean position is whatever the contacts and the start make it.
    One eigen-solve of the lowest mode (about one Newton iteration of the branch)."""
    try:
        omega, _ = normal_modes(model.K, model.M, 1, check=False)
    except (RuntimeError, ValueError, np.linalg.LinAlgError):
        return
    rigid = rigid_body_modes(model, omega)
    if rigid.any():
        warnings.warn("frequency_response: " + rigid_body_message(1) + " (the mean position of the response is then "
                      "not determined by the structure)", UserWarning, stacklevel=3)


def warn_undamped(model: StructuralModel) -> None:
    """A forced model without damping has no finite resonance peak: each resonance is a pole the
    curve runs to infinity on, with no folds (a user's blade: 9 points, no fold)."""
    if model.forces and not model.damping.nonzero:
        warnings.warn("frequency_response: the model has no damping, so its forced response has no finite resonance "
                      "peak (the curve runs to infinity at each resonance); add damping, e.g. "
                      "model.with_damping(modal=0.01) or model.with_damping(beta=...)", UserWarning, stacklevel=2)


def check_model(model: Any) -> StructuralModel:
    if not isinstance(model, StructuralModel):
        raise InputTypeError(f"model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
    return model


def start_vector(x0, size: int, layout: str) -> np.ndarray:
    """``x0`` as a finite float vector of ``size`` unknowns, else a ValueError naming ``x0`` (not a
    derived quantity such as the scales computed from it)."""
    try:
        x = np.asarray(x0, dtype=float)
    except (TypeError, ValueError):
        raise InputTypeError(f"x0 must be a real vector of {size} unknowns ({layout}), got {x0!r}") from None
    if x.shape != (size,):
        raise InputValueError(f"x0 has shape {x.shape}, this problem has {size} unknowns ({layout}); pass an x0 "
                              "of that size (e.g. a point's unknowns from a branch on the same model and harmonics)")
    if not np.all(np.isfinite(x)):
        raise InputValueError("x0 contains non-finite values (nan or inf)")
    if np.max(np.abs(x), initial=0.0) > largest_unknown(size):
        raise InputValueError(f"x0 has entries up to {np.max(np.abs(x)):.3g}, whose squares overflow floating point "
                         f"(above {largest_unknown(size):.3g} for {size} unknowns); pass an x0 of the solution's size, "
                         "or rescale the units")
    return x


def largest_unknown(size: int) -> float:
    """Largest magnitude of an unknown whose square, summed over ``size`` unknowns, stays finite:
    the Newton merit ``|r|^2 / 2`` and the arclength norm square the unknowns (above it they
    overflow to inf and every step fails as a "non-finite residual")."""
    return math.sqrt(np.finfo(float).max / max(int(size), 1)) / 10.0


def resonant_harmonics(model: StructuralModel, omega: float, h: Harmonics, *, n_modes: int = 12,
                       rtol: float = 1e-6) -> str:
    """Why the harmonic balance's Jacobian can be singular at ``omega`` on a model without damping:
    ``"harmonic k of w = ... equals the natural frequency w_j = ... of mode j"`` for every harmonic
    ``k w / nu`` (k = 1..H) within ``rtol`` of one of the lowest ``n_modes`` natural frequencies;
    ``""`` for a damped model, a model whose modes cannot be computed, or none. An undamped forced
    response started at 0.5 rad/s on an oscillator of 1 rad/s stopped with "r_x singular at the
    start point p=0.5 (start exactly at a fold?)": its second harmonic is the resonance."""
    if model.damping.nonzero:
        return ""
    try:
        w = normal_modes(model.K, model.M, min(n_modes, model.n_dofs))[0]
    except Exception:  # noqa: BLE001 - a diagnosis for a message, never a new failure
        return ""
    found = []
    for k in range(1, h.n_harmonics + 1):
        wk = k * omega / h.subharmonic
        for j in np.flatnonzero(np.abs(w - wk) <= rtol * wk):
            found.append(f"harmonic {k} of w = {omega:.6g} rad/s is the natural frequency w_{j + 1} = {w[j]:.6g} "
                         f"rad/s of mode {j + 1}")
    return "; ".join(found)


def commensurate_modes(model: StructuralModel, mode: int, h: Harmonics, *, n_modes: int = 12,
                       rtol: float = 1e-6) -> str:
    """The natural frequencies at an integer multiple ``k <= H`` of mode ``mode``'s (to ``rtol``):
    ``"w_2 = 2 w_1 (2.0 rad/s)"``, ``""`` if none (or the modes cannot be computed). Such a mode
    makes the orbits of the start energy a continuum (an exact internal resonance), and the
    backbone's first tangent singular."""
    try:
        w = normal_modes(model.K, model.M, min(max(n_modes, mode + 1), model.n_dofs))[0]
    except Exception:  # noqa: BLE001 - a diagnosis for a message, never a new failure
        return ""
    w0 = w[mode - 1]
    found = [f"w_{j + 1} = {k} w_{mode} ({w[j]:.6g} rad/s)" for j in range(len(w)) if j != mode - 1 and w0 > 0
             for k in range(1, h.n_harmonics + 1) if abs(w[j] - k * w0) <= rtol * k * w0]
    return ", ".join(found)
