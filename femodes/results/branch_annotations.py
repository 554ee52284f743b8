"""Results layer: what a :class:`~femodes.results.Branch` carries besides its points, checked per
point, and the answer it gives. The error estimate (:class:`ErrorEstimate`) turns the frequencies
of the truncated series into the answer (the converged frequency where one was found, with its
error bars) and moves the bifurcations onto the converged curve; the stability holds a verdict,
the multipliers and the method of every point, and the bifurcations between them. A branch is
built with them (:meth:`Branch.with_accuracy`, :meth:`Branch.with_stability` give a new branch),
so these arrays are computed once, here."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..hbm.harmonics import Harmonics
from .bifurcation import Bifurcation
from .error_estimate import ErrorEstimate

__all__ = ["Answer", "answer", "checked_accuracy", "checked_stability", "point_harmonics"]


@dataclass(frozen=True)
class Answer:
    """The values a branch reports per point (docs/guide/accuracy.md, "What the branch shows").

    ``omega``: the converged frequency where the error estimate gives one
    (``accuracy.omega_limit``), elsewhere the truncated series' own; ``omega_error``,
    ``amplitude_error``, ``error_estimate``: the estimate's ``frequency_error``,
    ``amplitude_error`` and ``value`` (``None`` without an estimate); ``bifurcations``: at the
    frequency the branch reports."""

    omega: np.ndarray
    omega_error: np.ndarray | None
    amplitude_error: np.ndarray | None
    error_estimate: np.ndarray | None
    bifurcations: tuple


def answer(omega_truncated: np.ndarray, accuracy: ErrorEstimate | None, bifurcations: tuple) -> Answer:
    """The :class:`Answer` of a branch whose series sit at ``omega_truncated``, with the error
    estimate ``accuracy`` and the ``bifurcations`` at the frequencies of their series.

    A bifurcation is moved by its points' correction ``omega - omega_truncated`` (a fold by its
    own point's; one between two points by the correction interpolated in the truncated
    frequency), so that it sits on the converged curve; ``b.omega_truncated``, ``b.Q`` and
    ``b.P`` stay the truncated series'."""
    if accuracy is None:
        return Answer(omega_truncated, None, None, None, bifurcations)
    omega = omega_truncated
    if accuracy.omega_limit is not None:
        limit = np.asarray(accuracy.omega_limit, float)
        omega = np.where(np.isfinite(limit), limit, omega_truncated)
    moved = bifurcations
    if bifurcations and accuracy.omega_limit is not None:
        wt, c, n = omega_truncated, omega - omega_truncated, omega_truncated.size
        out = []
        for b in bifurcations:
            i = min(int(b.index), n - 1)
            shift = c[i]
            if b.kind != "fold" and i + 1 < n and wt[i + 1] != wt[i]:
                theta = min(max((b.omega_truncated - wt[i]) / (wt[i + 1] - wt[i]), 0.0), 1.0)
                shift = (1.0 - theta) * c[i] + theta * c[i + 1]
            out.append(b.at_frequency(b.omega_truncated + shift) if shift else b)
        moved = tuple(out)
    return Answer(omega, accuracy.frequency_error, accuracy.amplitude_error, accuracy.value, moved)


def checked_accuracy(accuracy: Any, n: int, n_harmonics: int, name: str) -> ErrorEstimate:
    """``accuracy`` if it is an error estimate of ``n`` points on at most ``n_harmonics``
    harmonics; errors start with ``name``."""
    if not isinstance(accuracy, ErrorEstimate):
        raise TypeError(f"{name}: expected an ErrorEstimate, got {type(accuracy).__name__}")
    if np.asarray(accuracy.omega).shape != (n,):
        raise ValueError(f"{name}: one value per point ({n}) expected")
    if np.any(np.asarray(accuracy.harmonics) > n_harmonics):
        raise ValueError(f"{name}: a point uses more harmonics than the branch stores")
    return accuracy


def checked_stability(n: int, stable: Any, multipliers: Any, bifurcations: Any, methods: Any,
                      name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
    """The stability of ``n`` points as arrays (verdicts, multipliers ``(n, m)``, methods) and
    the bifurcations at the frequencies of their series; errors start with ``name``."""
    stable = np.asarray(stable, dtype=bool)
    multipliers = np.asarray(multipliers, dtype=complex).reshape(n, -1)
    methods = np.asarray(methods, dtype=str)
    if stable.shape != (n,) or methods.shape != (n,):
        raise ValueError(f"{name}: one value per point ({n}) expected")
    for b in bifurcations:
        if not isinstance(b, Bifurcation):
            raise TypeError(f"{name}: bifurcations must be Bifurcation objects, got {type(b).__name__}")
    return stable, multipliers, methods, tuple(b.series() for b in bifurcations)


def point_harmonics(harmonics: Harmonics, accuracy: ErrorEstimate | None, i: int) -> Harmonics:
    """The harmonics of point ``i`` of a branch stored on ``harmonics`` (error control may refine
    some points more than others; the branch stores every point on its largest, zero-padded)."""
    if accuracy is None:
        return harmonics
    H = int(accuracy.harmonics[i])
    if H == harmonics.n_harmonics:
        return harmonics
    return Harmonics(H, subharmonic=harmonics.subharmonic)
