"""Where a model's coordinates sit on the finite-element mesh (:class:`MeshMap`, the
``mesh_map`` of a :class:`~femodes.StructuralModel`): the model that owns the mesh, the full FE
field of a vector of model DOFs, the FE DOF of one model DOF, and the weights that read a response
at a location. A reduced model answers through its parent (:mod:`femodes.reduction`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..laws import Location
from ..solvers.checks import entry_point
from .probes import probe_weights

__all__ = ["MeshMap"]


class MeshMap:
    """The map from the DOFs ``q`` of ``model`` to its FE mesh (``model.mesh_map``).

    For an FE model (:func:`femodes.bar`, :func:`femodes.beam`, :func:`femodes.solid`) the model
    owns the mesh; a discrete model has none (:attr:`owner` is None, :meth:`full_field` the
    identity). A Craig-Bampton model's map goes through its parent
    (:class:`femodes.reduction.ReducedMeshMap`, which answers the same questions through
    the parent's map).
    """

    def __init__(self, model: Any):
        self.model = model

    @property
    def owner(self) -> Any:
        """The model that owns the FE mesh: this one for FE models, None for discrete ones (a
        reduced model answers with its parent's owner)."""
        return self.model if self.model.fe is not None else None

    def to_owner(self, q: np.ndarray) -> np.ndarray:
        """Coordinates ``(..., n_dofs)`` on the DOFs of :attr:`owner` (identity here; a reduced
        model expands through every reduction level). These are the owner's model DOFs,
        nodal-frame components at rotated nodes; :meth:`full_field` gives the physical field."""
        return np.asarray(q)

    def fe_dof(self, dof: int) -> int | None:
        """Index in the full FE field of a DOF of this model; None for a discrete model (and for
        the modal coordinates of a reduced one). A DOF of a rotated node (``dofmap.frames``)
        occupies the FE DOF of its component slot; its physical direction is
        ``dofmap.axis(node, slot)``."""
        fe = self.model.fe
        return None if fe is None else int(np.asarray(fe.free)[dof])

    def full_field(self, q: np.ndarray) -> np.ndarray:
        """FE field with constrained DOFs set to zero, ``(..., n_fe_dofs)``; identity for discrete
        models.

        The field is physical: the DOFs of rotated nodes (``model.frame``) are turned back into
        their components along x, y(, z).
        """
        q = np.asarray(q)
        fe, frame = self.model.fe, self.model.frame
        if fe is None:
            return q
        if frame is not None:
            flat = q.reshape(-1, q.shape[-1])
            q = np.asarray(frame @ flat.T).T.reshape(q.shape)
        out = np.zeros(q.shape[:-1] + (fe.n_full,), dtype=q.dtype)
        out[..., fe.free] = q
        return out

    def weights(self, at: Location, how: str = "mean") -> np.ndarray:
        """:meth:`probe` with its errors left to the public function called (femodes' own use)."""
        return probe_weights(self.model.dofmap, at, how)

    @entry_point("probe")
    def probe(self, at: Location, how: str = "mean") -> np.ndarray:
        """Weights ``w`` that read a response at ``at`` from the model's DOFs: ``w @ q``.

        A DOF location gives its unit vector (shape ``(n_dofs,)``). A named boundary of a meshed
        solid (``"tip"`` or ``("tip", "u_z")``; first component by default) gives, with
        ``how="mean"``, its average displacement in that component (the consistent weights of
        :attr:`DofMap.group_weights`, supported nodes counting as zero; shape ``(n_dofs,)``),
        and with ``how="max"`` one row per free node (shape ``(k, n_dofs)``: take the largest).
        A Craig-Bampton model reads boundaries of its parent, kept or not (``w_parent @ T``), so
        responses anywhere need no new model.
        """
        return self.weights(at, how)

    def __repr__(self) -> str:
        return f"MeshMap(owner={'None' if self.owner is None else 'the model'})"
