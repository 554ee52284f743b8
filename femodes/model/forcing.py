"""Harmonic forces on a model's DOFs (:meth:`~femodes.StructuralModel.with_forcing`): a force on a
DOF or named point, a resultant on a named boundary of a meshed solid shared by its nodes with the
consistent weights, and forces given in physical components at nodes whose DOFs are rotated into
a nodal frame (``R^T f``)."""

from __future__ import annotations

import dataclasses
import logging
import warnings

import numpy as np

from ..laws import Location
from .declarations import Attached, HarmonicForce
from .dofs import DofMap
from .frames import frame_forces
from ..solvers.checks import named_by, user_stacklevel

__all__ = ["bind_forces"]

log = logging.getLogger(__name__)


def bind_forces(model, forces) -> list[Attached]:
    """The harmonic ``forces`` bound to the DOFs of ``model`` (one or more ``Attached`` each)."""
    if not forces:
        raise ValueError("with_forcing: give at least one HarmonicForce")
    new: list[Attached] = []
    dm = model.dofmap
    implicit: list[str] = []
    for f in forces:
        if not isinstance(f, HarmonicForce):
            raise TypeError(f"with_forcing: expected HarmonicForce, got {type(f).__name__}")
        framed = _frame_group(dm, f)
        if framed is not None:
            dofs, weights = framed
            new.extend(Attached(dataclasses.replace(f, at=int(d), amplitude=f.amplitude * float(w)), int(d))
                       for d, w in zip(dofs, weights) if w != 0.0)
            continue
        group = dm.group_of(f.at)
        if isinstance(f.at, str) and model.fe is not None and len(dm.displacement) > 1:
            implicit.append(f.at)  # said once the forces are bound (a bad name is an error first)
        if group is None:
            rotated = _rotated_point(dm, f.at)
            if rotated is None:
                with named_by("with_forcing: HarmonicForce"):
                    new.append(Attached(f, dm.find(f.at)))
            else:
                new.extend(_rotated_force(dm, f, *rotated, 1.0))
            continue
        name, c = group
        nodes = np.asarray(dm.groups[name])
        dofs = dm.node_dof[nodes, c]
        weights = np.asarray(dm.group_weights[name], dtype=float)
        framed_nodes = np.array([int(k) in dm.frames for k in nodes], dtype=bool)  # their DOFs: _rotated_force
        if np.any((dofs == -2) & ~framed_nodes):
            raise ValueError(f"with_forcing: HarmonicForce(at={f.at!r}): boundary {name!r} is not kept in this "
                             f"reduced model; attach the force before reducing")
        lost = float(weights[dofs == -1].sum())
        if lost > 0:
            log.info("with_forcing: %.3g %% of the force on %r acts on supported nodes", 100 * lost, name)
        for node, d, w, rot in zip(nodes, dofs, weights, framed_nodes):
            if w == 0.0 or (d < 0 and not rot) or (rot and np.all(dm.node_dof[node] == -1)):
                continue  # no share, or a supported node
            if rot:
                new.extend(_rotated_force(dm, f, int(node), c, float(w)))
            else:
                new.append(Attached(dataclasses.replace(f, at=int(d), amplitude=f.amplitude * float(w)), int(d)))
    for at in dict.fromkeys(implicit):  # a bare name on a 2-D/3-D solid: +x, without a word (a contact says so)
        n_d = len(dm.displacement)
        warnings.warn(f"with_forcing: HarmonicForce(at={at!r}) names no component on a {n_d}-D solid; the force acts "
                      f"along +x ({dm.displacement[0]!r}). Give one, e.g. at=({at!r}, {dm.displacement[n_d - 1]!r}), "
                      f"or at=({at!r}, {dm.displacement[0]!r}) to keep +x and silence this", UserWarning,
                      stacklevel=user_stacklevel())
    return new


def force_label(f: HarmonicForce) -> str:
    """How the messages of :meth:`~femodes.StructuralModel.with_forcing` name a force."""
    return f"with_forcing: HarmonicForce(at={f.at!r})"


def _frame_group(dm: DofMap, f: HarmonicForce) -> tuple[np.ndarray, np.ndarray] | None:
    """``(dofs, weights)`` of a force at ``at=(boundary, nodal-frame component)`` (e.g.
    ``("right", "u_n")``), else None; every free node of the boundary must be rotated."""
    at = f.at
    if not (dm.frames and isinstance(at, tuple) and len(at) == 2 and at[0] in dm.groups
            and at[0] not in dm.locations and at[1] not in dm.components and at[1] not in dm.aliases):
        return None
    name, comp = at
    nodes = np.asarray(dm.groups[name])
    weights = np.asarray(dm.group_weights[name], dtype=float)
    dofs = np.full(nodes.size, -1, dtype=int)
    for j, k in enumerate(nodes):
        row = dm.node_dof[k]
        if np.all(row == -1):
            continue  # a supported node: its share goes to the support
        frame = dm.frames.get(int(k))
        if frame is None or comp not in frame.components:
            raise ValueError(
                f"{force_label(f)}: node {int(k)} of {name!r} has no nodal-frame component {comp!r} (only nodes rotated "
                f"by a contact with an inclined or negative normal have u_n, u_t...); give a physical component "
                f"of {list(dm.components)}"
            )
        dofs[j] = row[frame.components.index(comp)]
        if dofs[j] == -2:
            raise ValueError(f"{force_label(f)}: boundary {name!r} is not kept in this reduced model; attach the force "
                             "before reducing")
    lost = float(weights[dofs < 0].sum())
    if lost > 0:
        log.info("with_forcing: %.3g %% of the force on %r acts on supported nodes", 100 * lost, name)
    return dofs[dofs >= 0], weights[dofs >= 0]


def _rotated_point(dm: DofMap, at: Location) -> tuple[int, int] | None:
    """``(node, physical component)`` if ``at`` names a physical component (or only the point,
    i.e. its first component) of a named point whose DOFs are rotated, else None."""
    if not dm.frames:
        return None
    if isinstance(at, str) and at in dm.locations and at not in dm.dof_names:
        loc, comp = at, dm.components[0]
    elif isinstance(at, tuple) and len(at) == 2 and at[0] in dm.locations:
        loc, comp = at
    else:
        return None
    node = int(dm.locations[loc])
    if node not in dm.frames or comp in dm.frames[node].components:
        return None
    return node, dm.component_index(comp)


def _rotated_force(dm: DofMap, f: HarmonicForce, node: int, c: int, weight: float) -> list:
    """The share ``weight`` of force ``f`` along physical component ``c`` of rotated ``node``, on
    the node's nodal-frame DOFs (``R^T e_c``)."""
    dofs = dm.node_dof[node]
    R = dm.frames[node].rotation
    # a reduced model keeps a contact node's normal DOF only: a force along the normal (no share on
    # the dropped tangential DOFs, to round-off of the unit rotation) acts on what is kept
    lost = (dofs < 0) & (np.abs(R[c]) > 1e-12)
    if np.any(lost):
        raise ValueError(f"{force_label(f)}: the force has a share {float(np.abs(R[c][lost]).max()):.3g} on DOFs of rotated "
                         f"node {node} that this reduced model does not keep (it keeps "
                         f"{[dm.label(int(d)) for d in dofs[dofs >= 0]]}); attach the force before reducing, keep the "
                         f"node (craig_bampton(keep=...)), or force it along the contact normal (component 'u_n')")
    return frame_forces(f, R, dofs, c, weight)
