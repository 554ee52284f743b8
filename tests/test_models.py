"""StructuralModel, DofMap, declarations: construction, frozen updates and bad input."""

import math

import numpy as np
import pytest
import scipy.sparse as sp

import femodes as fm

from .conftest import cantilever, fixed_free_bar


def test_dense_and_sparse_matrices_accepted():
    K = np.array([[2.0, -1.0], [-1.0, 1.0]])
    a = fm.StructuralModel(M=np.eye(2), K=K)
    b = fm.StructuralModel(M=sp.eye(2), K=sp.csr_matrix(K), C=0.1 * np.eye(2))
    assert a.n_dofs == b.n_dofs == 2
    assert sp.issparse(a.K) and a.C.nnz == 0 and b.C.nnz == 2


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(M=np.eye(2), K=np.eye(3)), "K has shape"),
        (dict(M=np.ones((2, 3)), K=np.eye(2)), "square"),
        (dict(M=[[1.0, 0.5], [0.0, 1.0]], K=np.eye(2)), "M must be symmetric"),
        (dict(M=np.eye(2), K=[[1.0, 2.0], [0.0, 1.0]]), "K must be symmetric"),
        (dict(M=np.eye(2), K=[[1.0, 0.0], [0.0, -1.0]]), "K must be positive semidefinite"),
        (dict(M=-np.eye(2), K=np.eye(2)), "M must have positive mass"),
        (dict(M=[[1.0, 2.0], [2.0, 1.0]], K=np.eye(2)), "M must be positive semidefinite"),
        (dict(M=np.zeros((2, 2)), K=np.eye(2)), "M must have positive mass"),
        (dict(M=np.eye(2), K=[[1.0, np.nan], [np.nan, 1.0]]), "NaN"),
        (dict(M=np.eye(2), K=np.eye(2), C=-np.eye(2)), "C must be positive semidefinite"),
        (dict(M=np.eye(2), K=np.eye(2), C=np.eye(3)), "C has shape"),
        (dict(M=np.eye(1), K=np.eye(1), dof_names=["a", "b"]), "dof_names"),
        (dict(M=np.eye(2), K=np.eye(2), dof_names=["a", "a"]), "unique"),
        (dict(M=np.zeros(3), K=np.eye(3)), "2-D"),
    ],
)
def test_structural_model_rejects_bad_matrices(kwargs, match):
    with pytest.raises(ValueError, match=match):
        fm.StructuralModel(**kwargs)


def test_structural_model_rejects_non_matrix():
    with pytest.raises(TypeError, match="M must be a square real matrix"):
        fm.StructuralModel(M="mass", K=np.eye(1))


def test_frozen_and_with_methods_return_new_models():
    m0 = fm.StructuralModel(M=np.eye(2), K=np.eye(2), dof_names=["x1", "x2"])
    with pytest.raises(Exception):
        m0.K = None
    m1 = m0.with_contact(fm.UnilateralContact(at="x2", gap=0.5))
    m2 = m1.with_forcing(fm.HarmonicForce(at="x1", amplitude=0.3)).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
    assert m0.contacts == () and m1.contacts[0].dof == 1
    assert m2.forces[0].dof == 0 and m2.nonlinearities[0].dof == 0 and len(m2.contacts) == 1
    np.testing.assert_array_equal(fm.model.nonlinear_dofs(m2), [0, 1])
    assert m2.force_vectors()[1][0] == pytest.approx(0.3)
    assert m2.without_forcing().forces == ()


def test_dofmap_names_components_and_errors():
    model = cantilever(8)
    tip_w = model.dof("tip")
    assert model.dof(("tip", "w")) == tip_w == model.dof(("tip", "u_y"))
    assert model.dof(("tip", "theta")) == tip_w + 1 == model.dof(("tip", "w_x"))
    assert model.dofmap.label(tip_w) == "tip.w"
    with pytest.raises(ValueError, match="constrained by \"clamped='clamp'\"|constrained by 'clamped="):
        model.dof("clamp")
    with pytest.raises(ValueError, match="unknown location 'nose'"):
        model.dof("nose")
    with pytest.raises(ValueError, match="unknown component 'v'"):
        model.dof(("tip", "v"))
    with pytest.raises(ValueError, match="out of range"):
        model.dof(10_000)
    with pytest.raises(ValueError, match="negative DOF index"):
        model.dof(-1)
    with pytest.raises(TypeError, match="at must be"):
        model.dof(1.5)
    with pytest.raises(TypeError, match="at must be"):
        model.dof(True)


def test_contact_on_constrained_dof_rejected_early():
    with pytest.raises(ValueError, match="constrained"):
        cantilever(4).with_contact(fm.UnilateralContact(at="clamp", gap=0.1))
    with pytest.raises(ValueError, match="constrained"):
        fixed_free_bar(4).with_forcing(fm.HarmonicForce(at="clamp"))


def test_duplicate_contact_and_wrong_law_kind():
    m = fm.StructuralModel(M=np.eye(2), K=np.eye(2)).with_contact(fm.UnilateralContact(at=1, gap=0.1))
    with pytest.raises(ValueError, match="already has a contact"):
        m.with_contact(fm.PenaltyContact(at=1, gap=0.1, stiffness=10.0))
    with pytest.raises(TypeError, match="with_nonlinearity"):
        m.with_contact(fm.CubicSpring(at=0, k3=1.0))
    with pytest.raises(TypeError, match="with_contact"):
        m.with_nonlinearity(fm.UnilateralContact(at=0, gap=0.1))
    with pytest.raises(TypeError, match="HarmonicForce"):
        m.with_forcing("tip")
    with pytest.raises(ValueError, match="at least one"):
        m.with_contact()


@pytest.mark.parametrize(
    "factory, match",
    [
        (lambda: fm.UnilateralContact(at="tip", gap=-0.1), "gap must be a finite non-negative"),
        (lambda: fm.UnilateralContact(at="tip", gap=math.nan), "gap"),
        (lambda: fm.UnilateralContact(at="tip", gap=math.inf), "gap"),
        (lambda: fm.UnilateralContact(at="tip", gap=0.1, c=0.0), "c must be a finite positive"),
        (lambda: fm.UnilateralContact(at="", gap=0.1), "empty"),
        (lambda: fm.PenaltyContact(at=0, gap=0.1, stiffness=-1.0), "stiffness"),
        (lambda: fm.PenaltyContact(at=0, gap=-1.0, stiffness=1.0), "gap"),
        (lambda: fm.CubicSpring(at=0, k3=math.nan), "k3 must be finite"),
        (lambda: fm.CubicSpring(at=0, k3=0.0), "k3 must be non-zero"),
        (lambda: fm.HarmonicForce(at=0, amplitude=math.inf), "amplitude"),
        (lambda: fm.HarmonicForce(at=0, harmonic=-1), "harmonic"),
        (lambda: fm.HarmonicForce(at=0, harmonic=1.5), "harmonic"),
        (lambda: fm.Material(E=-1.0, rho=1.0), "E must be a finite positive"),
        (lambda: fm.Material(E=1.0, rho=0.0), "rho"),
        (lambda: fm.Section(area=math.nan), "area"),
        (lambda: fm.Section(area=1.0, inertia=-2.0), "inertia"),
    ],
)
def test_declarations_reject_bad_values(factory, match):
    with pytest.raises(ValueError, match=match):
        factory()


@pytest.mark.parametrize(
    "factory",
    [
        lambda: fm.UnilateralContact(at=1.5, gap=0.1),
        lambda: fm.UnilateralContact(at="tip", gap="0.1"),
        lambda: fm.CubicSpring(at=0, k3=True),
        lambda: fm.Material(E="steel", rho=1.0),
        lambda: fm.Section(area=1.0, rotary_inertia="yes"),
    ],
)
def test_declarations_reject_bad_types(factory):
    with pytest.raises(TypeError):
        factory()


def test_fe_constructors_reject_bad_input():
    mesh = fm.line_mesh(1.0, 4, boundaries={"clamp": 0.0, "tip": 1.0})
    mat, sec = fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0)
    with pytest.raises(TypeError, match="mesh must be a skfem.MeshLine"):
        fm.beam(np.linspace(0, 1, 5), mat, sec)
    with pytest.raises(ValueError, match="order must be 1 or 2"):
        fm.bar(mesh, mat, sec, order=3)
    with pytest.raises(ValueError, match="unknown|names location 'root'"):
        fm.beam(mesh, mat, sec, clamped="root")
    with pytest.raises(ValueError, match="inertia is required"):
        fm.beam(mesh, mat, fm.Section(area=1.0))
    with pytest.raises(ValueError, match="subdomain 'steel'"):
        fm.beam(mesh, {"steel": mat}, sec)
    with pytest.raises(TypeError, match="material must be a Material"):
        fm.bar(mesh, 210e9, sec)
    with pytest.raises(ValueError, match="point_masses"):
        fm.bar(mesh, mat, sec, point_masses={"tip": -1.0})
    with pytest.raises(ValueError, match="unknown component"):
        fm.beam(mesh, mat, sec, springs={("tip", "phi"): 1.0})
    sub = fm.line_mesh(1.0, 4, subdomains={"a": (0.0, 0.5), "b": (0.5, 1.0)})
    with pytest.raises(ValueError, match="does not cover"):
        fm.bar(sub, {"a": mat}, sec)
    with pytest.raises(ValueError, match="lumped"):
        fm.bar(mesh, mat, sec, order=2, lumped=True)


def test_damping_bad_input():
    m = fm.StructuralModel(M=np.eye(2), K=np.eye(2))
    with pytest.raises(ValueError, match="alpha"):
        m.with_damping(alpha=-1.0)
    with pytest.raises(ValueError, match="beta"):
        m.with_damping(beta=math.nan)
    with pytest.raises(ValueError, match="modal"):
        m.with_damping(modal=[-0.1, 0.1])
    with pytest.raises(ValueError, match="either Rayleigh"):
        m.with_damping(alpha=0.1, modal=0.02)
    # no DOF limit: modal damping is a sparse part plus a low-rank part (issue 16)
    big = fixed_free_bar(6000).with_damping(modal=0.01, n_modes=5)
    assert big.C.nnz == 0 and big.C_lowrank.U.shape == (6000, 5)


def test_linear_api_bad_input():
    m = fm.StructuralModel(M=np.eye(2), K=np.eye(2))
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        fm.linear_modes(m, n=0)
    with pytest.raises(ValueError, match="only 2 DOFs"):
        fm.linear_modes(m, n=3)
    with pytest.raises(TypeError, match="StructuralModel"):
        fm.linear_modes(np.eye(2))
    with pytest.raises(ValueError, match="no forcing"):
        fm.linear_response(m, 1.0)
    with pytest.raises(ValueError, match="omega"):
        fm.linear_response(m, [np.nan], force=[1.0, 0.0])
    with pytest.raises(ValueError, match="singular"):
        fm.linear_response(m, 1.0, force=[1.0, 0.0])
    with pytest.raises(ValueError, match="force must be"):
        fm.linear_response(m, 0.5, force=[1.0])
