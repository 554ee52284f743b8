"""Models layer: axial bar ``rho A u_tt - (E A u_x)_x = f`` with P1 or P2 Lagrange elements."""

from __future__ import annotations

from typing import Any
from collections.abc import Mapping

import numpy as np
import skfem
from skfem.helpers import dot, grad

from ..model import StructuralModel
from ..solvers.checks import entry_point
from .assembly import check_mesh, support_names, build_fe_model, element_property, mass_basis, quad_field, stiffness_basis
from .material import Material, Section
from .checks import check_assembly

__all__ = ["bar"]


@skfem.BilinearForm
def _stiffness(u, v, w):
    # E A u' v'
    return w["EA"] * dot(grad(u), grad(v))


@skfem.BilinearForm
def _mass(u, v, w):
    # rho A u v
    return w["rhoA"] * u * v




@entry_point("bar")
def bar(
    mesh: Any,
    material: Material | Mapping[str, Material],
    section: Section | Mapping[str, Section],
    *,
    order: int = 1,
    clamped: Any = None,
    point_masses: Mapping | None = None,
    springs: Mapping | None = None,
    lumped: bool = False,
) -> StructuralModel:
    """Axial bar: ``int rho A u v`` (mass) and ``int E A u' v'`` (stiffness).

    Parameters
    ----------
    mesh : skfem.MeshLine
        From :func:`femodes.line_mesh` or :func:`femodes.load_mesh`.
    material, section : Material / Section, or mappings {subdomain: ...}
    order : {1, 2}
        Lagrange element order (P1 or P2).
    clamped : str or list of str
        Named points where the axial displacement is fixed.
    point_masses, springs : mapping {location: value}, optional
        Lumped masses and grounded springs at named points.
    lumped : bool
        Row-sum lumped mass (P1 only; its frequency error is ``-(k h)^2/24`` instead of
        ``+(k h)^2/24``).

    Returns
    -------
    StructuralModel
        DOF component ``"u"`` (alias ``"u_x"``) at each node; P2 interior DOFs are unnamed.

    Notes
    -----
    Quadrature (:mod:`femodes.fe.quadrature`), exact on every element: Gauss with 2 (P1) or 3
    (P2) points for the mass (``u v``: degree 2 p), 2 points for the stiffness (degree 2 p - 2).
    """
    check_mesh(mesh)
    if isinstance(order, (bool, np.bool_)) or not isinstance(order, (int, np.integer)) or order not in (1, 2):
        raise ValueError(f"bar: order must be 1 or 2, got {order!r}")
    if not isinstance(lumped, bool):
        raise TypeError(f"bar: lumped must be True or False, got {lumped!r}")
    if lumped and order != 1:
        raise ValueError("bar: lumped=True is only available for order=1 (P2 row-sum lumping gives zero masses)")
    mats = element_property(mesh, material, Material, "material")
    check_assembly(mesh, skfem.ElementLineP1() if order == 1 else skfem.ElementLineP2())
    secs = element_property(mesh, section, Section, "section")
    element = skfem.ElementLineP1() if order == 1 else skfem.ElementLineP2()
    kbasis = stiffness_basis(mesh, element)  # quadrature exact on each element (femodes.fe.quadrature)
    basis = mass_basis(kbasis)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):  # overflow is reported by build_fe_model
        EA = quad_field(kbasis, [m.E * s.area for m, s in zip(mats, secs)])
        rhoA = quad_field(basis, [m.rho * s.area for m, s in zip(mats, secs)])
        K = _stiffness.assemble(kbasis, EA=EA)
        M = _mass.assemble(basis, rhoA=rhoA)
    if lumped:
        import scipy.sparse as sp

        M = sp.diags(np.asarray(M.sum(axis=1)).ravel())
    return build_fe_model(
        kind="bar",
        mesh=mesh,
        basis=basis,
        M=M,
        K=K,
        components=("u",),
        aliases={"u_x": "u"},
        constraints=[("clamped", support_names(clamped, "clamped"), ("u",))],
        point_masses=point_masses,
        springs=springs,
    )
