"""Contact on named boundaries of meshed solids: expansion to one law per node, callable gaps,
errors, surface mass redistribution, and a smoke run of the harmonic balance."""

import logging

import warnings

import numpy as np
import pytest
import scipy.sparse.linalg as sla

import femodes as fm
from femodes.fe.redistribution import redistribute_surface_mass


def strip(nx=20, ny=4, *, quad=False, order=1, nu=0.0, **kw):
    return fm.solid(fm.rectangle_mesh(1.0, 0.1, nx, ny, quadrilaterals=quad), fm.Material(E=1.0, rho=1.0, nu=nu),
                    clamped="left", order=order, **kw)


def dof_coordinates(model):
    """Coordinates (dim, n_dofs) and component of every model DOF."""
    fe = model.fe
    X = np.zeros((fe.dim, fe.n_full))
    comp = np.zeros(fe.n_full, dtype=int)
    for c in range(fe.nodal.shape[0]):
        X[:, fe.nodal[c]] = fe.node_coordinates
        comp[fe.nodal[c]] = c
    return X[:, fe.free], comp[fe.free]


# -- expansion -------------------------------------------------------------------------------------
@pytest.mark.parametrize("order", [1, 2])
def test_one_contact_per_boundary_node(order):
    model = strip(order=order)
    c = model.with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0)))
    nodes = model.dofmap.groups["right"]
    assert len(c.contacts) == nodes.size == (4 + 1 if order == 1 else 2 * 4 + 1)  # P2: mid-side nodes too
    assert [a.dof for a in c.contacts] == [int(d) for d in model.dofmap.node_dof[nodes, 0]]
    X, comp = dof_coordinates(model)
    dofs = [a.dof for a in c.contacts]
    assert np.all(comp[dofs] == 0) and np.allclose(X[0, dofs], 1.0)
    assert all(a.item.gap == 0.01 and a.item.direction is None and a.item.at == a.dof for a in c.contacts)
    # the same by (boundary, component), and a penalty law
    same = model.with_contact(fm.UnilateralContact(at=("right", "u_x"), gap=0.01))
    assert [a.dof for a in same.contacts] == dofs
    pen = model.with_contact(fm.PenaltyContact(at="right", gap=0.01, stiffness=10.0, direction=(1.0, 0.0)))
    assert [a.dof for a in pen.contacts] == dofs and np.allclose(pen.M.toarray(), model.M.toarray())


def test_constrained_nodes_are_skipped_with_a_log(caplog):
    model = strip()
    with caplog.at_level(logging.INFO, logger="femodes.model"):
        c = model.with_contact(fm.UnilateralContact(at="bottom", gap=0.01, direction=(0.0, -1.0)))
    assert len(c.contacts) == 20  # 21 nodes, the one on the clamped edge skipped
    assert "1 of 21 nodes of 'bottom' are constrained" in caplog.text
    X, comp = dof_coordinates(model)
    d = [a.dof for a in c.contacts]
    assert np.all(comp[d] == 1) and np.allclose(X[1, d], 0.0)


def test_callable_gap_at_node_coordinates():
    model = strip()
    casing = lambda x: 0.01 + 0.5 * (x[0] - 0.5) ** 2  # noqa: E731 - vectorised, x of shape (dim, n)
    c = model.with_contact(fm.UnilateralContact(at="top", gap=casing, direction=(0.0, 1.0)))
    X, _ = dof_coordinates(model)
    for a in c.contacts:
        assert a.item.gap == pytest.approx(casing(X[:, a.dof]))
    calls = []

    def pointwise(x):  # math on scalars only: called per node
        calls.append(x.shape)
        return 0.02 + float(x[0])

    p = model.with_contact(fm.UnilateralContact(at="top", gap=pointwise, direction=(0.0, 1.0)))
    assert {s for s in calls[1:]} == {(2,)}
    assert [a.item.gap for a in p.contacts] == pytest.approx([0.02 + X[0, a.dof] for a in p.contacts])
    with pytest.raises(ValueError, match="gaps must be finite and >= 0"):
        model.with_contact(fm.UnilateralContact(at="top", gap=lambda x: x[0] - 0.5, direction=(0.0, 1.0)))


def test_one_dimensional_contact_unchanged():
    bar = fm.bar(fm.line_mesh(1.0, 10), fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="left")
    c = bar.with_contact(fm.UnilateralContact(at="right", gap=0.1))
    assert len(c.contacts) == 1 and c.contacts[0].item.at == "right" and c.contacts[0].dof == bar.dof("right")
    with pytest.raises(ValueError, match="needs a meshed solid"):
        bar.with_contact(fm.UnilateralContact(at="right", gap=0.1, direction=(1.0,)))
    # a stop on the negative side (a beam between two stops): not available, and said so
    with pytest.raises(ValueError, match=r"stop sits on its positive side \(q <= gap\): a stop on the negative side or "
                                         r"on both sides of such a DOF is not available"):
        bar.with_contact(fm.UnilateralContact(at="right", gap=0.1, direction=(-1.0,)))


def test_contact_errors():
    model = strip()
    with pytest.raises(ValueError, match="2 components"):
        model.with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match="zero vector"):
        fm.UnilateralContact(at="right", gap=0.01, direction=(0.0, 0.0))
    with pytest.raises(TypeError, match="direction"):
        fm.PenaltyContact(at="right", gap=0.01, stiffness=1.0, direction="x")
    # inclined and negative normals rotate the DOFs of the contact nodes (tests/test_inclined_contact.py)
    # (a normal into the body is accepted with a warning that names the outward one)
    for direction in ((1.0, 1.0), (-1.0, 0.0)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            inclined = model.with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=direction))
        into = [w for w in caught if "points into the body" in str(w.message)]
        assert len(into) == (1 if direction == (-1.0, 0.0) else 0)
        assert inclined.frame is not None and len(inclined.contacts) == 5 and len(inclined.dofmap.frames) == 5
    with pytest.raises(ValueError, match="unknown location 'casing'.*'bottom', 'left', 'right', 'top'"):
        model.with_contact(fm.UnilateralContact(at="casing", gap=0.01, direction=(1.0, 0.0)))
    with pytest.raises(ValueError, match="every node of 'left' is constrained"):
        model.with_contact(fm.UnilateralContact(at="left", gap=0.01, direction=(-1.0, 0.0)))
    with pytest.raises(ValueError, match="selects 'u_y'"):
        model.with_contact(fm.UnilateralContact(at=("right", "u_x"), gap=0.01, direction=(0.0, 1.0)))
    once = model.with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0)))
    with pytest.raises(ValueError, match="already has a contact law"):
        once.with_contact(fm.UnilateralContact(at="right", gap=0.02, direction=(1.0, 0.0)))


# -- mass redistribution ---------------------------------------------------------------------------
@pytest.mark.parametrize("quad, order, at, direction", [
    (False, 1, "right", (1.0, 0.0)), (True, 1, "top", (0.0, 1.0)), (False, 2, "right", (1.0, 0.0)),
    (True, 2, "top", (0.0, 1.0)),
])
def test_surface_redistribution_invariants(quad, order, at, direction):
    model = strip(quad=quad, order=order)
    c = model.with_contact(fm.UnilateralContact(at=at, gap=0.01, direction=direction))
    S = np.array([a.dof for a in c.contacts])
    X, comp = dof_coordinates(model)
    M0, M1 = model.M, c.M
    assert abs(M1 - M1.T).max() == 0.0
    assert np.all(M1[S].toarray() == 0.0)  # exactly the contact DOFs are massless
    rest = np.setdiff1d(np.arange(model.n_dofs), S)
    assert np.all(M1.diagonal()[rest] > 0)
    # positive definite on the other DOFs
    assert sla.eigsh(M1[rest][:, rest], 1, which="SA", tol=1e-8)[0][0] > 0
    rep = c.mass_redistribution[-1]
    assert rep["dofs"] == sorted(S.tolist()) and rep["com_shift"] < 1e-12
    for k in range(2):  # total mass of each rigid translation conserved
        r = (comp == k).astype(float)
        assert r @ M1 @ r == pytest.approx(r @ M0 @ r, rel=1e-12)
        for x in X * r:  # and its first moments (centre of mass)
            assert abs(r @ M1 @ x - r @ M0 @ x) < 1e-12 * (r @ M0 @ r)
    if order == 2 and not quad:  # P2 vertices (zero row sums) are merged with their neighbours
        assert rep["lumps"] < S.size


def test_redistribution_cost_is_near_linear():
    """Hundreds of contact nodes on a larger model: no dense n x n work (a few seconds at most)."""
    import time

    model = strip(nx=400, ny=20, quad=True)  # 16800 DOFs, 401 nodes on "bottom" (one clamped)
    t = time.perf_counter()
    c = model.with_contact(fm.UnilateralContact(at="bottom", gap=0.01, direction=(0.0, -1.0)))
    assert len(c.contacts) == 400 and time.perf_counter() - t < 5.0  # measured 0.1 s
    assert c.M.nnz < 1.1 * model.M.nnz  # local fill only


def test_redistribute_surface_mass_without_contacts_is_identity():
    model = strip()
    M, rep = redistribute_surface_mass(model.fe, model.M, [])
    assert (M != model.M).nnz == 0 and rep["dofs"] == []


@pytest.mark.parametrize("quad, order", [(False, 1), (True, 1), (False, 2), (True, 2)])
def test_strip_held_at_the_stop_against_the_bar(quad, order):
    """nu = 0 strip (rollers on top and bottom), stop on the whole "right" face: with the contact
    DOFs held (sticking) its first mode is the fixed-fixed bar's, like the 1-D bar with its
    redistributed tip. Measured at 20 elements: 2-D 9.7e-4 (P1/Q1) and 4e-7 (P2/Q2) above pi, the
    1-D P1 bar 2.0e-3 above pi (so 2-D vs 1-D within 2.0e-3)."""
    nx = 20

    def held(m):
        S = [a.dof for a in m.contacts]
        keep = np.setdiff1d(np.arange(m.n_dofs), S)
        return np.sqrt(sla.eigsh(m.K[keep][:, keep], 1, m.M[keep][:, keep], sigma=0.0, which="LM")[0][0])

    bar = fm.bar(fm.line_mesh(1.0, nx), fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="left")
    w_bar = held(bar.with_contact(fm.UnilateralContact(at="right", gap=0.01)))
    model = strip(nx=nx, ny=1, quad=quad, order=order, supports={"bottom": ("u_y",), "top": ("u_y",)})
    w = held(model.with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0))))
    assert w / np.pi - 1 == pytest.approx(0.0, abs=1.5e-3 if order == 1 else 1e-5)
    assert w / w_bar - 1 == pytest.approx(0.0, abs=2.5e-3)


# -- harmonic balance accepts it ---------------------------------------------------------------------
def test_frequency_response_smoke():
    model = fm.solid(fm.rectangle_mesh(1.0, 0.1, 6, 1, quadrilaterals=True), fm.Material(E=1.0, rho=1.0, nu=0.0), clamped="left")
    model = (model.with_damping(beta=1e-3)
             .with_forcing(fm.HarmonicForce(at=("right", "u_x"), amplitude=0.02))
             .with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0))))
    assert model.n_dofs == 24 and len(model.contacts) == 2
    frc = fm.frequency_response(model, omega=(1.2, 1.8), harmonics=3,
                                options=fm.ContinuationOptions(step=0.05, max_step=0.2, max_points=6))
    assert len(frc.omega) >= 3 and np.all(frc.converged)
    assert np.all(np.isfinite(frc.energy))
    sol = frc[len(frc.omega) - 1]
    assert np.all(np.isfinite(sol.contact_force(np.linspace(0.0, 1.0, 5))))


@pytest.mark.parametrize("order", [1, 2])
def test_contact_on_a_face_in_3d(order):
    model = fm.solid(fm.box_mesh(1.0, 0.2, 0.1, 6, 2, 1), fm.Material(E=1.0, rho=1.0), clamped="left", order=order)
    c = model.with_contact(fm.UnilateralContact(at="right", gap=lambda x: 0.01 + x[1], direction=(1.0, 0.0, 0.0)))
    nodes = model.dofmap.groups["right"]
    assert len(c.contacts) == nodes.size == (3 * 2 if order == 1 else 5 * 3)
    X, comp = dof_coordinates(model)
    S = [a.dof for a in c.contacts]
    assert np.all(comp[S] == 0) and np.allclose(X[0, S], 1.0)
    assert [a.item.gap for a in c.contacts] == pytest.approx(0.01 + X[1, S])
    assert np.all(c.M[S].toarray() == 0.0)
    rest = np.setdiff1d(np.arange(model.n_dofs), S)
    assert np.linalg.eigvalsh(c.M[rest][:, rest].toarray())[0] > 0
    r = (comp == 0).astype(float)
    assert r @ c.M @ r == pytest.approx(r @ model.M @ r, rel=1e-12)


def test_default_contact_parameters_batched_equal_one_by_one():
    """One factorisation of K for all contacts of a boundary (a 3-D face has hundreds; one
    factorisation per contact took 2 s each on a 14.5k-DOF box): the same values as the
    single-DOF rule c = 1 / (K^-1)_dd, to round-off of the solve (cond(K) ~ 1e4 here: 1e-10)."""
    from femodes.hbm.system import default_contact_parameter, default_contact_parameters

    m = fm.solid(fm.rectangle_mesh(2.0, 0.2, 20, 2, quadrilaterals=True), fm.Material(E=1.0, rho=1.0, nu=0.3),
                 clamped="left").with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0)))
    dofs = [a.dof for a in m.contacts]
    batched = default_contact_parameters(m, dofs)
    single = np.array([default_contact_parameter(m, d) for d in dofs])
    np.testing.assert_allclose(batched, single, rtol=1e-10)
    assert np.all(batched > 0)
    # a free structure (singular K): the diagonal stiffness, as before
    free = fm.StructuralModel(M=np.eye(2), K=[[1.0, -1.0], [-1.0, 1.0]])
    np.testing.assert_allclose(default_contact_parameters(free, [0, 1]), [1.0, 1.0])
    assert default_contact_parameters(m, []).shape == (0,)
