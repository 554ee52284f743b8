"""The names of :class:`~femodes.StructuralModel` that moved to its collaborators (issue 39): the
damping operator (``model.damping``), the map to the FE mesh (``model.mesh_map``) and
:func:`~femodes.model.declarations.nonlinear_dofs`. One table, read by the model's
``__getattr__``: an old name still gives what it gave, with a DeprecationWarning that names the
new spelling and points at the caller's line; it is removed in a later release."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from ..laws import Location
from ..solvers.checks import entry_point, named_by, user_stacklevel
from .declarations import nonlinear_dofs
from .dofs import deprecated_owner

__all__ = ["MOVED", "moved_attribute"]


@entry_point("probe")
def _probe(model: Any, at: Location, how: str = "mean", owner: str | None = None) -> np.ndarray:
    """The former ``model.probe(at, how, owner)``: ``owner`` (deprecated as before) names the errors."""
    with named_by(deprecated_owner(owner, f"{type(model).__name__}.probe")):
        return model.mesh_map.weights(at, how)


#: old name -> (new spelling, for the warning; what the old name gives on ``model``)
MOVED: dict[str, tuple[str, Callable[[Any], Any]]] = {
    "n_contacts": ("len(model.contacts)", lambda m: len(m.contacts)),
    "has_damping": ("model.damping.nonzero", lambda m: m.damping.nonzero),
    "apply_damping": ("model.damping.apply", lambda m: m.damping.apply),
    "nonlinear_dofs": ("femodes.model.nonlinear_dofs(model)", lambda m: functools.partial(nonlinear_dofs, m)),
    "probe": ("model.mesh_map.probe", lambda m: functools.partial(_probe, m)),
    "mesh_owner": ("model.mesh_map.owner", lambda m: m.mesh_map.owner),
    "to_owner": ("model.mesh_map.to_owner", lambda m: m.mesh_map.to_owner),
    "fe_dof": ("model.mesh_map.fe_dof", lambda m: m.mesh_map.fe_dof),
    "full_field": ("model.mesh_map.full_field", lambda m: m.mesh_map.full_field),
}


def moved_attribute(model: Any, name: str) -> Any:
    """What the moved ``name`` gives on ``model``, with its DeprecationWarning; an AttributeError
    for any other name (as Python's own lookup, which found nothing)."""
    if name not in MOVED:
        raise AttributeError(f"{type(model).__name__!r} object has no attribute {name!r}")
    new, value = MOVED[name]
    warnings.warn(f"{type(model).__name__}.{name} is deprecated and will be removed; use {new}",
                  DeprecationWarning, stacklevel=user_stacklevel())
    return value(model)
