"""Reading a response at a location: the weights ``w`` with ``w @ q`` the displacement of a DOF,
or the mean (or each node) of a named boundary of a meshed solid (:meth:`~femodes.model.MeshMap.probe`, ``model.mesh_map.probe``)."""

from __future__ import annotations

import numpy as np

from ..laws import Location
from ..solvers.checks import InputValueError
from .dofs import DofMap

__all__ = ["probe_weights"]


def probe_weights(dm: DofMap, at: Location, how: str = "mean") -> np.ndarray:
    """Weights that read ``at`` from the DOFs of ``dm``: the unit vector of a DOF, the consistent
    mean of a boundary's nodes (``how="mean"``, shape ``(n_dofs,)``) or one row per free node
    (``how="max"``, shape ``(k, n_dofs)``); its errors are named by the public function called."""
    if how not in ("mean", "max"):
        raise InputValueError(f"how must be 'mean' or 'max' (over the boundary's nodes), got {how!r}")
    group = dm.group_of(at)
    if group is None:
        w = np.zeros(dm.n_dofs)
        w[dm.find(at)] = 1.0
        return w
    name, c = group
    dofs = dm.node_dof[np.asarray(dm.groups[name]), c]
    weights = np.asarray(dm.group_weights[name], dtype=float)
    if np.any(dofs == -2):
        raise InputValueError(f"boundary {name!r} is not kept in this model; read it on the full model")
    free = dofs >= 0
    if not free.any():
        raise InputValueError(f"every node of boundary {name!r} is supported in that component")
    if how == "max":
        W = np.zeros((int(free.sum()), dm.n_dofs))
        W[np.arange(W.shape[0]), dofs[free]] = 1.0
        return W
    w = np.zeros(dm.n_dofs)
    np.add.at(w, dofs[free], weights[free] / weights.sum())
    return w
