"""Outputs layer: what the plots share: matplotlib imported on first use, the deprecation of
``ax`` by position, the Axes check, frequency units and the DOF or boundary a plot reads."""

from __future__ import annotations

import functools
import warnings
from typing import Any

import numpy as np

from ..solvers.checks import InputTypeError, InputValueError
from ..results import PeriodicSolution

__all__ = ["pyplot", "to_keywords", "positional_deprecated", "axes", "freq", "freq_label", "dof_index", "reader", "check_solution"]


def pyplot():
    try:
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("femodes.plot needs matplotlib: pip install 'femodes[plot]'") from exc
    return plt


def to_keywords(f, n_positional: int, names: tuple[str, ...], args: tuple, kwargs: dict, stacklevel: int):
    """Move the arguments past the first ``n_positional`` to the keywords ``names`` they used to
    fill by position, with a DeprecationWarning (``ax`` and those after it are keyword-only)."""
    if len(args) <= n_positional:
        return args, kwargs
    extra = args[n_positional:]
    if len(extra) > len(names):
        raise TypeError(f"{f.__name__}() takes at most {n_positional + len(names)} positional arguments "
                        f"({n_positional} without deprecation), got {len(args)}")
    given = names[:len(extra)]
    for name in given:
        if name in kwargs:
            raise TypeError(f"{f.__name__}() got multiple values for argument {name!r}")
    keywords = ", ".join(f"{n}=..." for n in given)
    warnings.warn(f"femodes.plot.{f.__name__}: passing {', '.join(given)} by position is deprecated; pass "
                  f"{keywords}", DeprecationWarning, stacklevel=stacklevel + 1)
    return args[:n_positional], {**kwargs, **dict(zip(given, extra))}


def positional_deprecated(n_positional: int, *names: str):
    """Decorator: ``names`` (keyword-only now) are still accepted by position after the first
    ``n_positional`` arguments, with a DeprecationWarning naming the keywords."""
    def decorate(f):
        @functools.wraps(f)
        def wrapper(*args, **kwargs):
            args, kwargs = to_keywords(f, n_positional, names, args, kwargs, stacklevel=2)
            return f(*args, **kwargs)
        wrapper.positional = (n_positional, names)
        return wrapper
    return decorate


def axes(ax: Any):
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(layout="constrained")
        return ax
    from matplotlib.axes import Axes

    if not isinstance(ax, Axes):
        raise InputTypeError(f"ax must be a matplotlib Axes or None, got {type(ax).__name__}")
    return ax


def freq(omega: np.ndarray, hz: bool) -> np.ndarray:
    return np.asarray(omega) / (2 * np.pi) if hz else np.asarray(omega)


def freq_label(hz: bool) -> str:
    return "frequency [Hz]" if hz else r"$\omega$ [rad/s]"


def dof_index(obj: Any, dof: Any, n_dofs: int) -> tuple[int, str]:
    """Resolve ``dof`` (index or location name) to a model DOF index and a label."""
    model = getattr(obj, "model", None)
    if isinstance(dof, (str, tuple)):
        if model is None:
            raise InputValueError(f"dof={dof!r} is a name but no model is attached; pass an integer DOF index")
        idx = model.dof(dof)
        return idx, model.dofmap.label(idx) if model.dofmap.labels else str(dof)
    if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)):
        raise InputTypeError(f"dof must be an integer index or a location name, got {type(dof).__name__}")
    if not -n_dofs <= dof < n_dofs:
        raise InputValueError(f"dof={dof} is out of range for {n_dofs} DOFs")
    idx = int(dof) % n_dofs
    label = model.dofmap.label(idx) if model is not None else f"dof {idx}"
    return idx, label


def reader(obj: Any, dof: Any, n_dofs: int, how: str) -> tuple[np.ndarray, str]:
    """Weights ``W`` (rows: responses, the largest amplitude taken) and a label: a DOF, or a
    named boundary read through :meth:`femodes.model.MeshMap.probe` (mean or max over its
    nodes; for a reduced model also boundaries it does not keep)."""
    model = getattr(obj, "model", None)
    if isinstance(dof, (str, tuple)) and model is not None:
        try:
            W = np.atleast_2d(model.mesh_map.probe(dof, how))
        except ValueError:
            W = None
        if W is not None and not (W.shape[0] == 1 and np.count_nonzero(W) == 1):
            return W, f"{dof}, {how} over its nodes" if not isinstance(dof, tuple) else f"{dof[0]} {dof[1]}, {how}"
    idx, label = dof_index(obj, dof, n_dofs)
    W = np.zeros((1, n_dofs))
    W[0, idx] = 1.0
    return W, label


def check_solution(solution: Any) -> PeriodicSolution:
    if not isinstance(solution, PeriodicSolution):
        raise InputTypeError(f"solution must be a PeriodicSolution (e.g. branch[i]), got {type(solution).__name__}")
    return solution
