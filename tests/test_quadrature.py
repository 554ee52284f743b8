"""Quadrature of the FE assembly (femodes/fe/quadrature.py): the lowest rule exact for mass and
stiffness on affine elements gives the matrices of scikit-fem's default (much larger) rule to
round-off; on distorted (non-affine) quadrilaterals and hexahedra, where it is the standard full
integration, the frequencies move far less than the discretisation error."""

import dataclasses
import importlib

import numpy as np
import pytest
import scipy.sparse.linalg as sla
import skfem

import femodes as fm
from femodes.fe.quadrature import facet_order, orders

assembly = importlib.import_module("femodes.fe.assembly")
EPS = np.finfo(float).eps
MAT = fm.Material(E=2.0, rho=3.0, nu=0.3)

# an affine map that is not a scaling (shear + rotation): parallelograms / parallelepipeds with
# no edge along an axis, so no entry of the element matrices is zero by symmetry
SHEAR_2D = np.array([[1.0, 0.4], [0.3, 1.1]])
SHEAR_3D = np.array([[1.0, 0.4, 0.1], [0.3, 1.1, -0.2], [0.2, -0.1, 0.9]])


def affine(mesh):
    """``mesh`` under a fixed affine map (its cells stay affine images of the reference cell)."""
    A = SHEAR_2D if mesh.p.shape[0] == 2 else SHEAR_3D
    return dataclasses.replace(mesh, doflocs=A @ mesh.p)


AFFINE = {
    "tri": lambda: affine(fm.rectangle_mesh(1.0, 0.3, 5, 3)),
    "quad": lambda: affine(fm.rectangle_mesh(1.0, 0.3, 5, 3, quadrilaterals=True)),
    "tet": lambda: affine(fm.box_mesh(1.0, 0.3, 0.2, 3, 2, 2)),
    "hex": lambda: affine(fm.box_mesh(1.0, 0.3, 0.2, 3, 2, 2, hexahedra=True)),
}

# quadrature points per element, (mass, stiffness): scikit-fem's default was (2, 2) (3, 3), (4, 4);
# (3, 3), (6, 6); (9, 9), (25, 25); (4, 4), (11, 11); (64, 64), (343, 343) (femodes/fe/quadrature.py)
POINTS = {("tri", 1): (3, 3), ("tri", 2): (6, 3), ("quad", 1): (4, 4), ("quad", 2): (9, 9),
          ("tet", 1): (4, 1), ("tet", 2): (11, 4), ("hex", 1): (8, 8), ("hex", 2): (27, 27)}


def round_off_bound(A):
    """Entrywise bound on the difference of two assemblies of the same matrix by two exact rules.

    Each entry is a sum of at most 343 quadrature terms per element over at most 24 elements
    (a vertex of the tetrahedral box), each term a product of a few shape-function values
    computed to a few eps of relative error. Rounding errors of such sums grow like sqrt(n) eps
    times the largest term (about 20 eps here), and scikit-fem's tabulated rules are themselves
    exact only to round-off: its 6-point degree-4 triangle rule integrates monomials with a
    relative error of 17 eps (measured on every monomial of degree <= 4). 64 eps times the largest
    entry covers both with a factor of about 4 (observed, in units of eps times the largest entry:
    P2 triangle stiffness 16.8, the old rule's error; every other matrix 0 to 7.3, the largest the
    Q2 hexahedron mass, 343 -> 27 points).
    """
    return 64 * EPS * abs(A).max()


@pytest.mark.parametrize("kind, order", sorted(POINTS))
def test_points_per_element(kind, order):
    mesh = AFFINE[kind]()
    scalar = mesh.elem() if order == 1 else _p2(mesh)
    stiffness = assembly.stiffness_basis(mesh, skfem.ElementVector(scalar))
    mass = assembly.mass_basis(stiffness)
    assert (mass.X.shape[1], stiffness.X.shape[1]) == POINTS[kind, order]
    model = fm.solid(mesh, MAT, order=order)
    assert model.fe.basis.X.shape[1] == POINTS[kind, order][0]


def _p2(mesh):
    return {skfem.MeshTri1: skfem.ElementTriP2, skfem.MeshQuad1: skfem.ElementQuad2, skfem.MeshTet1: skfem.ElementTetP2,
            skfem.MeshHex1: skfem.ElementHex2}[type(mesh)]()


@pytest.mark.parametrize("kind, order", sorted(POINTS))
def test_solid_matrices_equal_default_quadrature_on_affine_meshes(kind, order, monkeypatch):
    mesh = AFFINE[kind]()
    new = fm.solid(mesh, MAT, order=order)
    monkeypatch.setattr(assembly, "orders", lambda mesh, element: None)  # scikit-fem's default rule, as before
    old = fm.solid(mesh, MAT, order=order)
    for A_new, A_old in ((new.K, old.K), (new.M, old.M)):
        assert abs(A_new - A_old).max() <= round_off_bound(A_old)
    for name in new.dofmap.groups:
        np.testing.assert_allclose(new.dofmap.group_weights[name], old.dofmap.group_weights[name], rtol=0,
                                   atol=64 * EPS)  # weights sum to 1: the same bound, relative to 1


def test_plane_strain_and_subdomains_equal_default_quadrature(monkeypatch):
    mesh = AFFINE["quad"]()
    mesh = mesh.with_subdomains({"a": lambda x: x[0] < 0.7, "b": lambda x: x[0] >= 0.7})
    mats = {"a": MAT, "b": fm.Material(E=5.0, rho=1.0, nu=0.2)}
    new = fm.solid(mesh, mats, order=2, plane="strain", thickness=0.3)
    monkeypatch.setattr(assembly, "orders", lambda mesh, element: None)
    old = fm.solid(mesh, mats, order=2, plane="strain", thickness=0.3)
    for A_new, A_old in ((new.K, old.K), (new.M, old.M)):
        assert abs(A_new - A_old).max() <= round_off_bound(A_old)


LINES = {
    "bar P1": lambda m: fm.bar(m, MAT, fm.Section(area=0.2), order=1, clamped="left"),
    "bar P2": lambda m: fm.bar(m, MAT, fm.Section(area=0.2), order=2, clamped="left"),
    "beam": lambda m: fm.beam(m, MAT, fm.Section(area=0.2, inertia=0.01), clamped="left"),
    "beam rotary": lambda m: fm.beam(m, MAT, fm.Section(area=0.2, inertia=0.01, rotary_inertia=True), clamped="left"),
}


@pytest.mark.parametrize("name", sorted(LINES))
def test_bar_and_beam_matrices_equal_default_quadrature(name, monkeypatch):
    mesh = fm.line_mesh(2.0, 7, grading=3.0)  # unequal element lengths
    new = LINES[name](mesh)
    monkeypatch.setattr(assembly, "orders", lambda mesh, element: None)
    old = LINES[name](mesh)
    for A_new, A_old in ((new.K, old.K), (new.M, old.M)):
        assert abs(A_new - A_old).max() <= round_off_bound(A_old)


def test_line_points_per_element():
    mesh = fm.line_mesh(1.0, 4)
    for element, points in ((skfem.ElementLineP1(), (2, 2)), (skfem.ElementLineP2(), (3, 2)),
                            (skfem.ElementLineHermite(), (4, 2))):
        stiffness = assembly.stiffness_basis(mesh, element)
        mass = assembly.mass_basis(stiffness)
        assert (mass.X.shape[1], stiffness.X.shape[1]) == points


def test_curved_meshes_keep_the_default_rule():
    """Quadratic geometry (MeshTri2, ...) is not affine: scikit-fem's default rule, as before."""
    curved = skfem.MeshTri2.init_circle(1)
    assert orders(curved, skfem.ElementVector(skfem.ElementTriP2())) is None
    assert facet_order(curved, skfem.ElementTriP2()) is None
    stiffness = assembly.stiffness_basis(curved, skfem.ElementVector(skfem.ElementTriP2()))
    mass = assembly.mass_basis(stiffness)
    assert mass is stiffness and mass.X.shape[1] == 6  # default: degree 4
    assert orders(fm.rectangle_mesh(), skfem.ElementVector(skfem.ElementTriP2())) == (4, 2)


# -- non-affine elements: a tapered, sheared (and, in 3-D, twisted) plate -----------------------
def tapered_plate(n, hexahedra):
    """A plate 1.5 long, 0.4 wide at the clamp and 0.2 at the tip, sheared by 0.1 along y (and in
    3-D 0.1 thick, twisted by z += 0.2 x y). The map of the rectangle/box is bilinear in (x, y), so
    the Q1 geometry of every mesh represents the same domain exactly, and no cell is affine."""
    m = fm.box_mesh(1.5, 0.4, 0.1, 6 * n, 2 * n, n, hexahedra=True) if hexahedra else \
        fm.rectangle_mesh(1.5, 0.4, 6 * n, 2 * n, quadrilaterals=True)
    p = m.p.copy()
    x, y = m.p[0], m.p[1]
    p[1] = y * (1.0 - 0.5 * x / 1.5) + 0.1 * x
    if hexahedra:
        p[2] = p[2] + 0.2 * x * y
    return dataclasses.replace(m, doflocs=p)


def six_frequencies(mesh, order):
    model = fm.solid(mesh, MAT, clamped="left", order=order)
    return np.sort(np.sqrt(sla.eigsh(model.K, 6, model.M, sigma=0.0, which="LM")[0]))


@pytest.mark.parametrize("hexahedra", [False, True], ids=["quad", "hex"])
@pytest.mark.parametrize("order", [1, 2])
def test_distorted_cells_frequencies_move_less_than_discretisation_error(hexahedra, order, monkeypatch):
    coarse, fine = tapered_plate(1, hexahedra), tapered_plate(2, hexahedra)
    w_full = six_frequencies(coarse, order)  # (p + 1)-point Gauss per direction
    w_fine = six_frequencies(fine, order)
    monkeypatch.setattr(assembly, "orders", lambda mesh, element: None)
    w_default = six_frequencies(coarse, order)  # scikit-fem's default: (2p + 1)^dim points (Q2 hex: 343)
    quadrature = np.abs(w_full - w_default) / w_default
    discretisation = np.abs(w_full - w_fine) / w_fine  # an underestimate of the coarse mesh's error
    # measured: the quadrature change is 2e-4 to 2e-3 of the discretisation error (7e-7..8e-4 relative)
    assert np.all(quadrature < 0.01 * discretisation), (quadrature, discretisation)
    assert np.all(quadrature > 0)  # non-affine: the rules differ (else the check would be vacuous)


@skfem.LinearForm
def _first_component(v, w):
    return v[0]


@pytest.mark.parametrize("kind, order", sorted(POINTS))
def test_group_weights_from_the_scalar_element_equal_the_vector_elements(kind, order):
    """fm.solid integrates int N_k ds with the scalar element's facet basis and maps node k to
    scalar DOF nodal[0, k] // dim; the vector element's first component, scikit-fem's default
    rule, gives the same weights (they sum to 1: 64 eps, as round_off_bound)."""
    mesh = AFFINE[kind]()
    model = fm.solid(mesh, MAT, order=order)
    fe, groups = model.fe, model.dofmap.groups
    assert set(groups) == set(mesh.boundaries)
    for name, nodes in groups.items():
        b = _first_component.assemble(skfem.FacetBasis(mesh, fe.basis.elem, facets=mesh.boundaries[name]))
        w = b[fe.nodal[0, nodes]]
        np.testing.assert_allclose(model.dofmap.group_weights[name], w / w.sum(), rtol=0, atol=64 * EPS)


@pytest.mark.parametrize("hexahedra", [False, True])
def test_assembly_in_blocks_equals_one_assembly(monkeypatch, hexahedra):
    # a large mesh is assembled in blocks of elements (femodes.fe.assembly.assemble_blocks); forced
    # here on a small one: the same K and M to round-off, the same DOFs, and a basis built on demand
    import pickle

    from femodes.fe import checks

    mesh = fm.box_mesh(1.0, 0.1, 0.1, 12, 2, 2, hexahedra=hexahedra)
    one = fm.solid(mesh, MAT, clamped="left", order=2)
    monkeypatch.setattr(checks, "ASSEMBLY_BLOCK_BYTES", 3e6)
    assert checks.assembly_block(mesh, one.fe.element) < mesh.nelements
    blocks = fm.solid(mesh, MAT, clamped="left", order=2)
    for name in ("K", "M"):
        A, B = getattr(one, name), getattr(blocks, name)
        assert abs(A - B).max() <= 8 * EPS * abs(A).max()
    np.testing.assert_array_equal(one.fe.doflocs, blocks.fe.doflocs)
    np.testing.assert_array_equal(one.fe.element_dofs, blocks.fe.element_dofs)
    assert blocks.dofmap.labels == one.dofmap.labels
    contact = blocks.with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0, 0.0)))
    assert "_basis" not in blocks.fe.__dict__  # nothing above needed the shape functions of all elements
    assert blocks.fe.basis.X.shape == one.fe.basis.X.shape  # built on first use, with the mass rule
    assert "_basis" not in pickle.loads(pickle.dumps(contact)).fe.__dict__
