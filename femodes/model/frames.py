"""Nodal frames of contacts with inclined or negative normals on meshed solids.

A contact whose ``direction`` is not a positive coordinate axis acts on the normal DOF ``u_n`` of
a rotated node: ``u_node = R q_node`` with a proper rotation ``R`` whose column ``slot`` is the
normal (:func:`nodal_frame`). :func:`rotated_model` turns a model's DOFs at such nodes: matrices
``T^T A T``, forces ``T^T f``, ``frame`` composed, DOF labels renamed.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
import scipy.sparse as sp

from .damping import LowRankDamping, damping_spec_fresh, fingerprinted
from .declarations import Attached, show_vector

__all__ = ["AXIS_TOL", "NodalFrame", "nodal_frame", "same_normal", "block_rotation", "frame_forces", "rotated_model"]

log = logging.getLogger(__name__)

#: A contact ``direction`` whose largest component is at least ``1 - AXIS_TOL`` (unit vector) is
#: along that positive coordinate axis: the contact acts on that displacement DOF, no rotation.
AXIS_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class NodalFrame:
    """Orthonormal frame of the DOFs of one node of a meshed solid: ``u_node = rotation @ q_node``.

    ``rotation`` is a proper rotation (``det = +1``, columns = the nodal axes in physical
    coordinates); column ``slot`` is the contact normal ``n``, so that the model DOF in that
    component slot is ``u_n = n . u`` and a contact acts on it with ``g_N = gap - u_n``. The other
    columns are tangents (``u_t`` in 2-D; ``u_t1``, ``u_t2`` in 3-D, in slot order).
    """

    rotation: np.ndarray
    slot: int

    @property
    def normal(self) -> np.ndarray:
        return self.rotation[:, self.slot]

    @property
    def components(self) -> tuple:
        """Names of the nodal-frame components, one per slot (``("u_n", "u_t")``, ...)."""
        dim = self.rotation.shape[0]
        tangents = iter(("u_t",) if dim == 2 else tuple(f"u_t{k + 1}" for k in range(dim - 1)))
        return tuple("u_n" if j == self.slot else next(tangents) for j in range(dim))


def nodal_frame(normal: Sequence[float]) -> NodalFrame:
    """The nodal frame of a contact normal (a proper rotation whose column ``slot`` is ``normal``).

    ``slot`` is the component of largest magnitude of ``normal`` (the coordinate axis nearest to
    it, so that a normal near an axis keeps that axis' slot). 2-D: the other column is ``n``
    turned by -90 or +90 degrees, whichever gives ``det = +1`` (``(-1, 0)`` gives the rotation by
    180 degrees, not the reflection ``diag(-1, 1)``). 3-D: the Householder reflection
    ``H = I - 2 v v^T / v^T v``, ``v = n + sign(n_s) e_s`` (no cancellation: ``|v|^2 >= 2``),
    maps ``e_s`` to ``-sign(n_s) n``; its column ``s`` is rescaled to ``n`` and, where that leaves
    ``det = -1``, the first tangent is negated.
    """
    n = np.asarray(normal, dtype=float).reshape(-1)
    n = n / np.linalg.norm(n)
    dim = n.size
    s = int(np.argmax(np.abs(n)))
    if dim == 2:
        t = np.array([-n[1], n[0]])  # n turned by +90 degrees
        R = np.column_stack([n, t]) if s == 0 else np.column_stack([-t, n])
    elif dim == 3:
        sigma = 1.0 if n[s] >= 0 else -1.0
        v = n.copy()
        v[s] += sigma
        R = np.eye(3) - (2.0 / (v @ v)) * np.outer(v, v)
        R[:, s] = n
        if sigma < 0:  # det(H) = -1 and column s was multiplied by -sigma = +1
            R[:, 0 if s != 0 else 1] *= -1.0
    else:
        raise ValueError(f"nodal_frame: a normal of a 2-D or 3-D solid is needed, got {tuple(normal)}")
    R.flags.writeable = False
    return NodalFrame(rotation=R, slot=s)


def same_normal(a: NodalFrame, b: NodalFrame) -> bool:
    """Whether two nodal frames are the same (slot and normal, to 1e-12)."""
    return a.slot == b.slot and bool(np.allclose(a.normal, b.normal, rtol=0.0, atol=1e-12))


def block_rotation(node_dof: np.ndarray, n: int, nodes: ArrayLike, rotations: ArrayLike) -> sp.csr_matrix:
    """Sparse orthogonal ``n x n`` matrix: ``rotations[k]`` on the DOFs ``node_dof[nodes[k]]`` (all
    free), the identity on every other DOF."""
    node_idx = np.asarray(nodes, dtype=int)
    rotation = np.asarray(rotations, dtype=float).reshape(node_idx.size, node_dof.shape[1], node_dof.shape[1])
    dofs = node_dof[node_idx]  # (k, dim)
    other = np.ones(n, dtype=bool)
    other[dofs.ravel()] = False
    eye = np.flatnonzero(other)
    dim = dofs.shape[1]
    rows = np.concatenate([eye, np.repeat(dofs, dim, axis=1).ravel()])
    cols = np.concatenate([eye, np.tile(dofs, (1, dim)).ravel()])
    vals = np.concatenate([np.ones(eye.size), rotation.ravel()])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def frame_forces(f, R: np.ndarray, dofs: np.ndarray, c: int, weight: float) -> list[Attached]:
    """``weight`` times the force ``f`` along physical component ``c`` of a node with nodal frame
    ``R`` (model DOFs ``dofs``), as forces on the node's DOFs: ``R^T e_c`` (nonzero parts only)."""
    out = []
    for j, d in enumerate(dofs):
        share = float(R[c, j]) * weight
        if share != 0.0:
            out.append(Attached(dataclasses.replace(f, at=int(d), amplitude=f.amplitude * share), int(d)))
    return out


def rotated_model(model, pending: Mapping[int, NodalFrame], node_of: np.ndarray, comp_of: np.ndarray):
    """``model`` with the DOFs of the nodes ``pending`` rotated into their nodal frames:
    ``q = T^T q_old``, matrices ``T^T A T``, forces ``T^T f``, ``frame`` composed, labels."""
    dm = model.dofmap
    for a in model.nonlinearities:
        k = int(node_of[a.dof])
        if k in pending:
            raise ValueError(
                f"with_contact: {type(a.item).__name__}(at={a.item.at!r}) acts on DOF {dm.label(a.dof)!r} of node {k}, "
                f"whose DOFs the contact normal {show_vector(pending[k].normal)} rotates; add the contact first and "
                f"attach the nonlinearity to the rotated DOFs (at=(point, 'u_n'), ...)"
            )
    nodes = sorted(pending)
    T = block_rotation(dm.node_dof, model.n_dofs, nodes, [pending[k].rotation for k in nodes])

    def rotate(A):
        B = (T.T @ A @ T).tocsr()
        return (0.5 * (B + B.T)).tocsr()

    lr = model.C_lowrank
    if lr is not None:
        lr = LowRankDamping(T.T @ lr.U, lr.d, modes=None if lr.modes is None else T.T @ lr.modes,
                            eigenvalues=lr.eigenvalues)
    forces = []
    for a in model.forces:
        k = int(node_of[a.dof])
        if k in pending:
            forces.extend(frame_forces(a.item, pending[k].rotation, dm.node_dof[k], int(comp_of[a.dof]), 1.0))
        else:
            forces.append(a)
    labels = list(dm.labels)
    for k in nodes:
        names = pending[k].components
        for j, d in enumerate(dm.node_dof[k]):
            old, comp = labels[d], dm.components[j]
            if old.startswith(comp + "@"):
                lab = names[j] + old[len(comp):]
            elif old.endswith("." + comp):
                lab = old[: -len(comp)] + names[j]
            else:
                lab = f"{old} {names[j]}"
            labels[d] = f"{lab} (rotated node {k})"
    dofmap = dataclasses.replace(dm, frames={**dm.frames, **pending}, labels=tuple(labels))
    frame = T if model.frame is None else (model.frame @ T).tocsr()
    log.info("with_contact: %d nodes rotated into the nodal frames of their contact normals", len(nodes))
    out = dataclasses.replace(model, M=rotate(model.M), K=rotate(model.K), C=rotate(model.C) if model.C.nnz else model.C,
                              C_lowrank=lr, forces=tuple(forces), dofmap=dofmap, frame=frame)
    # the spec's matrices in the new frame: its fingerprint follows them (a stale one stays stale)
    return fingerprinted(out) if out.damping_spec and damping_spec_fresh(model) else out
