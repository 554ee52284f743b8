"""Models layer: Euler-Bernoulli beam ``rho A w_tt + (E I w_xx)_xx = f`` with cubic Hermite elements."""

from __future__ import annotations

from typing import Any
from collections.abc import Mapping

import numpy as np
import skfem
from skfem.helpers import dd, ddot, dot, grad

from ..model import StructuralModel
from ..solvers.checks import entry_point
from .assembly import check_mesh, support_names, build_fe_model, element_property, mass_basis, quad_field, stiffness_basis
from .material import Material, Section
from .checks import check_assembly

__all__ = ["beam"]


@skfem.BilinearForm
def _stiffness(u, v, w):
    # E I w'' v''
    return w["EI"] * ddot(dd(u), dd(v))


@skfem.BilinearForm
def _mass(u, v, w):
    # rho A w v (+ rho I w' v' with rotary inertia)
    return w["rhoA"] * u * v + w["rhoI"] * dot(grad(u), grad(v))




@entry_point("beam")
def beam(
    mesh: Any,
    material: Material | Mapping[str, Material],
    section: Section | Mapping[str, Section],
    *,
    clamped: Any = None,
    pinned: Any = None,
    point_masses: Mapping | None = None,
    springs: Mapping | None = None,
) -> StructuralModel:
    """Euler-Bernoulli beam: ``int rho A w v`` (mass) and ``int E I w'' v''`` (stiffness).

    Cubic Hermite elements (scikit-fem ``ElementLineHermite``): DOFs are the transverse
    displacement ``"w"`` (alias ``"u_y"``) and the rotation ``"theta" = w'`` (alias ``"w_x"``) at
    every node.

    Parameters
    ----------
    mesh : skfem.MeshLine
    material, section : Material / Section (``section.inertia`` required), or mappings {subdomain: ...}
    clamped : str or list of str
        Named points where ``w`` and ``theta`` are fixed.
    pinned : str or list of str
        Named points where ``w`` is fixed (rotation free).
    point_masses, springs : mapping {location or (location, component): value}, optional
        Lumped masses / grounded springs; a bare location acts on ``w``.

    Notes
    -----
    cond(K) grows like ``(N/2)^4`` with the number of DOFs N: near 1e5 DOFs it exceeds 1/eps and
    eigenvalues lose all accuracy (:func:`femodes.linear_modes` warns). Use bars for the largest
    scaling studies.

    Quadrature (:mod:`femodes.fe.quadrature`), exact on every element: 4-point Gauss for the
    mass (``w v``: degree 6), 2-point for the stiffness (``w'' v''``: degree 2).
    """
    check_mesh(mesh)
    check_assembly(mesh, skfem.ElementLineHermite())
    mats = element_property(mesh, material, Material, "material")
    secs = element_property(mesh, section, Section, "section")
    for s in set(secs):
        if s.inertia is None:
            raise ValueError("beam: section.inertia is required for beams, got Section(inertia=None)")
    # quadrature exact on each element (femodes.fe.quadrature): 4-point Gauss for M, 2-point for K
    kbasis = stiffness_basis(mesh, skfem.ElementLineHermite())
    basis = mass_basis(kbasis)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):  # overflow is reported by build_fe_model
        EI = quad_field(kbasis, [m.E * s.inertia for m, s in zip(mats, secs)])
        rhoA = quad_field(basis, [m.rho * s.area for m, s in zip(mats, secs)])
        rhoI = quad_field(basis, [m.rho * s.inertia if s.rotary_inertia else 0.0 for m, s in zip(mats, secs)])
        K = _stiffness.assemble(kbasis, EI=EI)
        M = _mass.assemble(basis, rhoA=rhoA, rhoI=rhoI)
    return build_fe_model(
        kind="beam",
        mesh=mesh,
        basis=basis,
        M=M,
        K=K,
        components=("w", "theta"),
        aliases={"u_y": "w", "w_x": "theta", "theta_z": "theta"},
        constraints=[
            ("clamped", support_names(clamped, "clamped"), ("w", "theta")),
            ("pinned", support_names(pinned, "pinned"), ("w",)),
        ],
        point_masses=point_masses,
        springs=springs,
    )
