"""Models layer: the quadrature order of every element femodes assembles (mass and stiffness).

This module states, per element, the polynomial degree of the mass and stiffness integrands on an
*affine* element (a simplex, a parallelogram or a parallelepiped: constant Jacobian) and the
lowest scikit-fem rule that integrates it exactly (``skfem.Basis(..., intorder=...)``;
``skfem.quadrature.get_quadrature`` builds the rule), instead of scikit-fem's default rule, which
is exact for twice the *total* degree and so far too fine on quadrilaterals and hexahedra.

``intorder`` is the degree scikit-fem's rule integrates exactly: the total degree on lines,
triangles and tetrahedra, the degree *per direction* on quadrilaterals and hexahedra (tensor
Gauss with ``ceil((intorder + 1) / 2)`` points per direction).

*Non-affine elements.* A quadrilateral or hexahedron whose vertices do not form a parallelogram
or parallelepiped has a bilinear/trilinear geometry map with a varying Jacobian. The rule chosen
here is then the standard *full integration* of Q_p elements, ``(p + 1)``-point Gauss per
direction (Hughes, *The Finite Element Method*, 2000, sec. 4.1 and table 3.I.1; Zienkiewicz,
Taylor & Zhu, 7th ed., sec. 6.12). Meshes with curved (quadratic) geometry (``skfem.MeshTri2``,
``MeshQuad2``, ``MeshTet2``, ``MeshHex2``) keep scikit-fem's default rule (:func:`orders` returns
None). The points per element before and after, and the accuracy on distorted cells:
:doc:`/guide/solids` (Design notes).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import skfem

__all__ = ["Orders", "orders", "facet_order"]


class Orders(NamedTuple):
    """``intorder`` (degree integrated exactly) of the mass and of the stiffness form."""

    mass: int
    stiffness: int


# Degree of the integrand on an affine element (constant Jacobian, so d/dx is d/dxi times a
# constant matrix and dx is a constant times dxi): a degree-p Lagrange field u has gradient of
# degree p - 1, so mass u.v has degree 2p and stiffness grad u : grad v has degree 2p - 2.
# On Q_p elements these are degrees per direction: u.v is 2p; d_xi u d_eta v is (p - 1) + p
# in xi, so the stiffness is also of degree 2p per direction (same rule as the mass).
_ORDERS = {
    skfem.ElementLineP1: Orders(mass=2, stiffness=0),  # u v: 2; u' v': 0 (2-point Gauss is the least)
    skfem.ElementLineP2: Orders(mass=4, stiffness=2),  # u v: 4 (3-point Gauss); u' v': 2 (2-point)
    # rho A w v: 3 + 3 = 6 (4-point Gauss); rho I w' v': 4; E I w'' v'': 1 + 1 = 2 (2-point Gauss)
    skfem.ElementLineHermite: Orders(mass=6, stiffness=2),
    skfem.ElementTriP1: Orders(mass=2, stiffness=0),  # 2 (3 points); 0 (scikit-fem's least is 3 points)
    skfem.ElementTriP2: Orders(mass=4, stiffness=2),  # 4 (6 points); 2 (3 points)
    skfem.ElementTetP1: Orders(mass=2, stiffness=0),  # 2 (4 points); 0 (1 point)
    skfem.ElementTetP2: Orders(mass=4, stiffness=2),  # 4 (11 points); 2 (4 points)
    skfem.ElementQuad1: Orders(mass=2, stiffness=2),  # 2 per direction: 2 x 2 Gauss
    skfem.ElementQuad2: Orders(mass=4, stiffness=4),  # 4 per direction: 3 x 3 Gauss
    skfem.ElementHex1: Orders(mass=2, stiffness=2),  # 2 per direction: 2 x 2 x 2 Gauss
    skfem.ElementHex2: Orders(mass=4, stiffness=4),  # 4 per direction: 3 x 3 x 3 Gauss
}

# geometry elements of meshes with straight edges (affine simplices, bi/trilinear Q1 maps)
_STRAIGHT = (skfem.ElementLineP1, skfem.ElementTriP1, skfem.ElementQuad1, skfem.ElementTetP1, skfem.ElementHex1)


def _scalar(element: Any) -> Any:
    """The scalar element of an ``ElementVector`` (the element itself otherwise)."""
    return element.elem if isinstance(element, skfem.ElementVector) else element


def orders(mesh: Any, element: Any) -> Orders | None:
    """The lowest ``intorder`` exact for mass and stiffness of ``element`` on affine cells of ``mesh``.

    None for an element not in the table or a mesh with curved geometry: scikit-fem's default
    rule (degree ``2 * element.maxdeg``) is used then.
    """
    if getattr(mesh, "elem", None) not in _STRAIGHT:
        return None
    return _ORDERS.get(type(_scalar(element)))


def facet_order(mesh: Any, element: Any) -> int | None:
    """``intorder`` of ``int N_k ds`` over affine facets: the degree ``p`` of the shape functions
    (per direction on quadrilateral faces). None where :func:`orders` is None."""
    o = orders(mesh, element)
    return None if o is None else o.mass // 2
