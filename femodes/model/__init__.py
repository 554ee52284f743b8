"""Models layer: ``StructuralModel`` (M, K, C plus declarations) and ``DofMap`` (naming of DOFs).

A model describes ``M q'' + C q' + K q + f_nl(q) = sum_k f_k cos(k w t + phi_k) - w_c p`` on its
free DOFs ``q`` (constrained DOFs are eliminated). Models are frozen: ``with_damping``,
``with_forcing``, ``with_contact`` and ``with_nonlinearity`` return new models. Only ``DofMap``
turns names into indices (``at="tip"``, ``at=("tip", "theta")``, ``at=3``).

Modules: ``structural`` (the model, thin methods), ``dofs`` (``DofMap``), ``declarations``
(``HarmonicForce``, ``Attached``), ``checks`` (matrices and fields), ``damping`` (Rayleigh and
modal, ``LowRankDamping``), ``forcing`` (forces on DOFs, boundaries, rotated nodes), ``contact``
(contact laws on DOFs and boundaries, normals), ``frames`` (nodal frames of inclined normals),
``contact_mass`` (the mass of contact DOFs), ``probes`` (responses at a location), ``mesh_map``
(``model.mesh_map``: where the DOFs sit on the mesh), ``deprecations`` (the model's moved names).
"""

from .checks import as_sparse_matrix
from .damping import DENSE_DAMPING_MAX_DOFS, Damping, LowRankDamping, low_rank_solver
from .declarations import CONTACT_LAWS, SMOOTH_LAWS, Attached, HarmonicForce, nonlinear_dofs
from .dofs import DofMap
from .frames import AXIS_TOL, NodalFrame, nodal_frame
from .mesh_map import MeshMap
from .structural import StructuralModel

__all__ = ["DofMap", "NodalFrame", "HarmonicForce", "Attached", "StructuralModel", "LowRankDamping", "as_sparse_matrix",
           "Damping", "MeshMap", "nonlinear_dofs", "low_rank_solver", "nodal_frame", "DENSE_DAMPING_MAX_DOFS", "AXIS_TOL", "CONTACT_LAWS", "SMOOTH_LAWS"]
