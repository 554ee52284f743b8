"""Contact declarations (:meth:`~femodes.StructuralModel.with_contact`): the checks of each law,
the expansion of a named boundary into one law per node (its gap evaluated there), the component
of a contact ``direction`` or the nodal frame of an inclined or negative normal, one normal per
node; then the rotation into nodal frames (:mod:`.frames`), the contact mass
(:mod:`.contact_mass`) and the damping given before the contact (:mod:`.damping`).
"""

from __future__ import annotations

import dataclasses
import logging
import warnings

import numpy as np

from ..fe.checks import outward_normal
from ..laws import PenaltyContact, UnilateralContact
from .contact_mass import redistributed_mass
from .damping import redamped_after_contact
from .declarations import CONTACT_LAWS, SMOOTH_LAWS, Attached, show_vector
from .frames import AXIS_TOL, nodal_frame, rotated_model, same_normal
from ..solvers.checks import named_by, user_stacklevel

__all__ = ["add_contacts", "bind_contacts", "contact_label", "expand_contact", "two_normals"]

log = logging.getLogger(__name__)

#: Frames from :func:`expand_contact` up to ``StructuralModel.with_contact`` (``with_contact`` ->
#: :func:`add_contacts` -> :func:`bind_contacts` -> :func:`expand_contact`): the warnings name the
#: caller's line.
_DEPTH = 4


def add_contacts(model, laws, contact_mass=None):
    """``model`` with the contact ``laws`` added (:meth:`~femodes.StructuralModel.with_contact`)."""
    if contact_mass is not None and not callable(getattr(contact_mass, "apply", None)):
        raise TypeError(f"with_contact: contact_mass must be fm.RedistributeMass() or fm.ConsistentMass(), "
                        f"got {contact_mass!r}")
    if not laws:
        raise ValueError("with_contact: give at least one UnilateralContact or PenaltyContact")
    node_of, comp_of = model.dofmap.dof_nodes()
    added, pending = bind_contacts(model, laws, node_of, comp_of)
    base = rotated_model(model, pending, node_of, comp_of) if pending else model
    M, reports = redistributed_mass(base, added, node_of, contact_mass)
    new = tuple(model.contacts) + tuple(added)
    if any(isinstance(a.item, UnilateralContact) for a in new) and any(isinstance(a.item, PenaltyContact) for a in new):
        log.info("model mixes complementarity and penalty contacts")
    out = dataclasses.replace(base, contacts=new, M=M,
                              mass_redistribution=tuple(model.mass_redistribution) + tuple(reports))
    return redamped_after_contact(model, out, M is not base.M)


def bind_contacts(model, laws, node_of: np.ndarray, comp_of: np.ndarray) -> tuple[list, dict]:
    """``(new Attached contacts, {node: NodalFrame} to rotate)`` of the contact ``laws`` on
    ``model`` (node and component slot of each DOF: ``node_of``, ``comp_of``): one contact per
    DOF, one normal per node."""
    dm = model.dofmap
    new: list = []
    used = {a.dof for a in model.contacts}
    frames = dict(dm.frames)
    pending: dict = {}  # nodes rotated by this call
    normals: dict[int, np.ndarray] = {}  # node -> normal of its first contact
    for a in model.contacts:
        k = int(node_of[a.dof])
        if k >= 0:
            normals.setdefault(k, dm.axis(k, int(comp_of[a.dof])))
    rot: dict  # node -> NodalFrame of each law
    for law in laws:
        if not isinstance(law, CONTACT_LAWS):
            raise TypeError(
                f"with_contact: expected UnilateralContact or PenaltyContact, got {type(law).__name__}"
                + (" (use with_nonlinearity for smooth springs)" if isinstance(law, SMOOTH_LAWS) else "")
            )
        if law.direction is None and not callable(law.gap) and dm.group_of(law.at) is None:
            with named_by(f"with_contact: {type(law).__name__}"):
                pairs, rot = [(law, dm.find(law.at))], {}
            if isinstance(law.at, str) and model.fe is not None and len(dm.displacement) > 1:
                # a named point of a 2-D/3-D solid: +x without a word (a boundary says so, below)
                warnings.warn(_implicit_x(contact_label(law), "point", law.at, dm), UserWarning,
                              stacklevel=user_stacklevel())
        else:
            pairs, rot = expand_contact(model, law)
        for k, frame in rot.items():
            old = frames.get(k)
            if old is not None:
                if not same_normal(old, frame):
                    raise ValueError(two_normals(dm, law, k, old.normal, frame.normal))
            elif k in normals:
                raise ValueError(two_normals(dm, law, k, normals[k], frame.normal))
            else:
                pending[k] = frames[k] = frame
        for item, dof in pairs:
            k, c = int(node_of[dof]), int(comp_of[dof])
            if k in pending and k not in rot:  # a component of a node this call rotates
                raise ValueError(two_normals(dm, law, k, pending[k].normal, dm.axis(k, c)))
            if dof in used:
                what = f"{pending[k].components[c]!r} of node {k}" if k in pending else repr(dm.label(dof))
                raise ValueError(f"with_contact: {type(law).__name__}(at={law.at!r}): DOF {what} already has a "
                                 "contact law (one contact per DOF)")
            used.add(dof)
            new.append(Attached(item, dof))
            if k >= 0:
                normals.setdefault(k, frames[k].rotation[:, c] if k in frames else dm.axis(k, c))
    return new, pending


def expand_contact(model, law) -> tuple[list, dict]:
    """``([(law on one DOF, dof)], {node: NodalFrame})`` of a contact law: one law per node of a
    boundary, with its direction resolved to a component and a callable gap evaluated at the
    node. An inclined or negative normal acts on the normal DOF of a nodal frame; the nodes to
    rotate come second (empty for a positive axis)."""
    dm = model.dofmap
    label = contact_label(law)
    at = law.at
    if law.direction is not None:
        _warn_direction_into_body(model, law)
        comp = _direction_component(dm, law)
        if comp is None:
            return _expand_inclined(model, law)
        if isinstance(at, tuple):
            if dm.component_index(at[1]) != comp:
                raise ValueError(f"{label}: direction={law.direction} selects {dm.displacement[comp]!r} but at= names "
                                 f"component {at[1]!r}; give one of them")
            at = at[0]
        if not isinstance(at, str):
            raise ValueError(f"{label}: direction= needs a named location (boundary or point), not a DOF index")
        at = (at, dm.components[comp])
    group = dm.group_of(at)
    if law.direction is None and isinstance(at, str) and group is not None and len(dm.displacement) > 1:
        # a boundary of a 2-D/3-D solid without a direction: the contact acts along +x, which is
        # rarely what was meant (a stop above a blade tip is along z)
        warnings.warn(_implicit_x(label, "boundary", at, dm), UserWarning,
                      stacklevel=_DEPTH + 2)  # the frame above the caller of with_contact, as before the split
    if group is None:
        with named_by(label):
            dof = dm.find(at)
        nodes, dofs = None, np.array([dof])
    else:
        name, c = group
        nodes = np.asarray(dm.groups[name])
        dofs = dm.node_dof[nodes, c]
        if np.any(dofs == -2):
            raise ValueError(f"{label}: boundary {name!r} is not kept in this reduced model; attach the contact "
                             "before reducing (craig_bampton keeps contact DOFs)")
        held = dofs < 0
        if held.all():
            support = dm.constrained_by.get((int(nodes[0]), c), "a support")
            raise ValueError(f"{label}: every node of {name!r} is constrained ({support!r}) in {dm.components[c]!r}; "
                             "contact cannot act on a constrained DOF")
        if held.any():
            log.info("with_contact: %d of %d nodes of %r are constrained in %r and get no contact",
                     int(held.sum()), held.size, name, dm.components[c])
        nodes, dofs = nodes[~held], dofs[~held]
        for k in nodes:
            if int(k) in dm.frames:
                raise ValueError(two_normals(dm, law, int(k), dm.frames[int(k)].normal, dm.axis(int(k), c)))
    gaps = _contact_gaps(dm, law, nodes, dofs)
    return [(dataclasses.replace(law, at=int(d), gap=float(g), direction=None), int(d)) for d, g in zip(dofs, gaps)], {}


def _expand_inclined(model, law) -> tuple[list, dict]:
    """:func:`expand_contact` of a law whose normal is not a positive coordinate axis: each of
    its nodes gets the nodal frame of the normal; the law acts on the normal DOF ``u_n``."""
    dm = model.dofmap
    label = contact_label(law)
    direction = law.direction
    if model.fe is None:
        raise ValueError(f"{label}: direction={direction} is not along +x, +y or +z: the contact acts on the normal "
                         "DOF of a nodal rotation, which is done on the meshed solid itself; attach the contact "
                         "before reducing (craig_bampton keeps contact DOFs)")
    at = law.at
    if isinstance(at, tuple):
        raise ValueError(f"{label}: direction={direction} is not along +x, +y or +z: the contact acts on the normal "
                         f"DOF 'u_n' of rotated nodes, not on a component; give at= a boundary or point name only "
                         f"(at={at[0]!r})")
    if not isinstance(at, str):
        raise ValueError(f"{label}: direction= needs a named location (boundary or point), not a DOF index")
    if at in dm.groups and at not in dm.locations:
        name, nodes = at, np.asarray(dm.groups[at], dtype=int)
    elif at in dm.locations:
        name, nodes = None, np.array([int(dm.locations[at])])
    else:
        with named_by(label):
            dm.find(at)  # raises: unknown location
        raise AssertionError("unreachable")  # pragma: no cover
    frame = nodal_frame(direction)
    node_dof = dm.node_dof[nodes]  # (k, dim)
    held = node_dof < 0
    every = held.all(axis=1)
    partial = held.any(axis=1) & ~every
    if partial.any():
        k = int(nodes[np.argmax(partial)])
        c = int(np.argmax(dm.node_dof[k] < 0))
        support = dm.constrained_by.get((k, c), "a support")
        free = [dm.components[j] for j in range(dm.node_dof.shape[1]) if dm.node_dof[k, j] >= 0]
        raise ValueError(
            f"{label}: node {k} at {show_vector(dm.node_coordinates[:, k])} is constrained in {dm.components[c]!r} by "
            f"{support} but free in {free}: the contact normal {show_vector(frame.normal)} rotates the node's DOFs, "
            "which would mix constrained and free DOFs; constrain that node fully (clamped=...) or not at all"
        )
    if every.all():
        support = dm.constrained_by.get((int(nodes[0]), 0), "a support")
        where = f"every node of {name!r} is" if name is not None else f"{at!r} is"
        raise ValueError(f"{label}: {where} constrained ({support!r}); contact cannot act on a constrained DOF")
    if every.any():
        log.info("with_contact: %d of %d nodes of %r are constrained and get no contact", int(every.sum()),
                 every.size, name)
    nodes = nodes[~every]
    dofs = dm.node_dof[nodes, frame.slot]
    gaps = _contact_gaps(dm, law, nodes, dofs)
    pairs = [(dataclasses.replace(law, at=int(d), gap=float(g), direction=None), int(d)) for d, g in zip(dofs, gaps)]
    return pairs, {int(k): frame for k in nodes}


def contact_label(law) -> str:
    """How the messages of :meth:`~femodes.StructuralModel.with_contact` name a contact law."""
    return f"with_contact: {type(law).__name__}(at={law.at!r})"


def two_normals(dm, law, node: int, old, new) -> str:
    """The message of a node that ``law`` would give a second contact normal."""
    label = contact_label(law)
    X = dm.node_coordinates
    where = f" at {show_vector(X[:, node])}" if X is not None else ""
    return (f"{label}: node {node}{where} would get two contact normals, {show_vector(old)} and {show_vector(new)}: a node "
            "with an inclined or negative normal has its DOFs rotated into one nodal frame (u_n along the normal), "
            "so all contacts of that node must share that normal (or act on its tangent DOF, at=(point, 'u_t')); "
            "give the stops the same direction or put them on different nodes")


def _warn_direction_into_body(model, law) -> None:
    """A stop along ``direction`` from a boundary whose outward normal points the other way sits
    inside the material (``direction`` is the way the structure moves towards the stop)."""
    name = law.at[0] if isinstance(law.at, tuple) else law.at
    mesh = getattr(model.fe, "mesh", None)
    if not isinstance(name, str) or mesh is None or model.fe.kind != "solid":
        return
    n = outward_normal(mesh, name)
    d = np.asarray(law.direction, dtype=float)
    if n is None or d.shape != n.shape or not np.all(np.isfinite(d)) or not np.any(d):
        return
    cos = float(d @ n / np.linalg.norm(d))
    if cos < -0.5:
        def show(v):
            return "(" + ", ".join(f"{float(x) + 0.0:.4g}" for x in v) + ")"

        warnings.warn(f"{contact_label(law)}: direction={show(d)} points into the body at boundary {name!r} (its outward "
                      f"normal is {show(n)}), so the stop sits inside the material; give the direction in which "
                      f"{name!r} moves towards the stop, e.g. direction={show(-d)}", UserWarning,
                      stacklevel=_DEPTH + 2)  # the caller of with_contact


def _direction_component(dm, law) -> int | None:
    """Component of a contact law's ``direction`` along a positive coordinate axis, or None for an
    inclined or negative normal (a nodal rotation, :func:`_expand_inclined`)."""
    label, direction = contact_label(law), law.direction
    if not dm.displacement:
        raise ValueError(f"{label}: direction= needs a meshed solid (femodes.solid); for bars, beams and discrete "
                         "models give the DOF with at=(name, component), whose stop sits on its positive side "
                         "(q <= gap): a stop on the negative side or on both sides of such a DOF is not available "
                         "(of a discrete model, flip the DOF's sign in M, K and C for the negative side)")
    dim = len(dm.displacement)
    if len(direction) != dim:
        raise ValueError(f"{label}: direction={direction} has {len(direction)} components, this model is {dim}-D "
                         f"(give {dim} components, e.g. {tuple([1.0] + [0.0] * (dim - 1))})")
    d = np.asarray(direction, dtype=float)
    if not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
        raise ValueError(f"{label}: direction={direction} must be a finite non-zero vector")
    axis = int(np.argmax(np.abs(d)))
    if d[axis] >= 1.0 - AXIS_TOL:
        return dm.component_index(dm.displacement[axis])
    return None


def _implicit_x(label: str, kind: str, name: str, dm) -> str:
    """The warning for a contact without ``direction=`` at a named ``kind`` ("boundary" or "point")
    of a 2-D/3-D solid: it acts along +x, which is rarely what was meant (a stop above a blade tip
    is along z)."""
    n_d = len(dm.displacement)
    return (f"{label}: no direction= for {kind} {name!r} of a {n_d}-D solid; the contact acts along +x "
            f"({dm.displacement[0]!r}). Give the stop's direction, e.g. "
            f"direction={tuple(1.0 if i == n_d - 1 else 0.0 for i in range(n_d))}, or at=({name!r}, "
            f"{dm.displacement[0]!r}) to keep +x and silence this")


def _same_per_node(gap, x: np.ndarray, g: np.ndarray) -> bool:
    """Does the vectorised result ``g`` of the gap function agree with its value at the first and
    last node called one at a time? A function written per node (``0.01 + 0.5 * np.dot(x, n)``)
    also runs on the ``(dim, n)`` array when ``n == dim``, as a matrix product: a boundary of 2
    nodes in 2-D got gaps [0.51, 0.06] instead of [0.01, 0.06]. A function that cannot take one
    node counts as vectorised."""
    for k in {0, g.size - 1}:
        try:
            with np.errstate(all="ignore"):
                one = float(np.asarray(gap(x[:, k]), dtype=float).reshape(()))
        except Exception:  # noqa: BLE001 - vectorised only
            return True
        if not abs(one - g[k]) <= 1e-12 * max(abs(one), abs(g[k]), 1e-300):
            return False
    return True


def _contact_gaps(dm, law, nodes, dofs) -> np.ndarray:
    """The gap of each contact DOF: the law's number, or its callable at the nodes' coordinates."""
    label, gap = contact_label(law), law.gap
    n = len(dofs)
    if not callable(gap):
        return np.full(n, float(gap))
    X = dm.node_coordinates
    if X is None:
        raise ValueError(f"{label}: a callable gap needs a meshed model with node coordinates; give a number")
    X = np.asarray(X, dtype=float)
    if nodes is None:  # a named point or a (point, component) pair
        loc = dm.node_dof
        nodes = np.array([int(np.argwhere(loc == dofs[0])[0, 0])])
    x = X[:, nodes]
    g = None
    try:
        with np.errstate(all="ignore"):
            v = np.asarray(gap(x), dtype=float)
        if v.shape in ((n,), (1, n)):
            g = v.reshape(n)
    except Exception:  # noqa: BLE001 - a pointwise function may fail on arrays; it is called per node below
        g = None
    if g is not None and not _same_per_node(gap, x, g):
        g = None  # a per-node function that also ran on the (dim, n) array, with another meaning (n == dim)
    if g is None:
        try:
            g = np.array([float(gap(x[:, k])) for k in range(n)])
        except Exception as exc:  # noqa: BLE001 - report any error of the user's function
            raise ValueError(f"{label}: the gap function failed at node {tuple(x[:, 0])}: {exc!r}; it must map "
                             "coordinates of shape (dim,) or (dim, n) to gaps") from exc
    bad = np.flatnonzero(~np.isfinite(g) | (g < 0))
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"{label}: the gap function gives {g[k]!r} at node {tuple(float(v) for v in x[:, k])}; "
                         "gaps must be finite and >= 0")
    return g
