"""Linear modes and FE convergence against analytic results (shared/references.md).

Reference values: Blevins (1979) Table 8-1 for beams; fixed-free bar w_n = (2n-1) pi c / (2L).
Tolerances: convergence rates are asserted within 0.1 of the theoretical order from log-log
fits; tabulated FE errors (computed independently) within 1% where round-off is negligible.
"""

import numpy as np
import pytest
import scipy.sparse as sp

import femodes as fm

from .conftest import cantilever, fixed_free_bar

BETA_L = {
    "cantilever": [1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349],
    "clamped-clamped": [4.7300407449, 7.8532046241, 10.9956078380, 14.1371654913],
    "clamped-pinned": [3.9266023120, 7.0685827456, 10.2101761228, 13.3517687778],
    "pinned-pinned": [np.pi, 2 * np.pi, 3 * np.pi, 4 * np.pi],
}
SUPPORTS = {
    "cantilever": dict(clamped="left"),
    "clamped-clamped": dict(clamped=["left", "right"]),
    "clamped-pinned": dict(clamped="left", pinned="right"),
    "pinned-pinned": dict(pinned=["left", "right"]),
}


def two_dof_chain():
    return fm.StructuralModel(M=np.eye(2), K=[[2.0, -1.0], [-1.0, 1.0]])


def test_two_dof_chain_frequencies_and_shapes():
    modes = fm.linear_modes(two_dof_chain(), n=2)
    # exact (sqrt 5 -+ 1) / 2: the 10-digit literals were off by 5e-11, i.e. 0.8 of rtol=1e-10
    golden = (np.sqrt(5.0) + 1.0) / 2.0
    np.testing.assert_allclose(modes.omega, [golden - 1.0, golden], rtol=1e-10)
    ratios = modes.shapes[1] / modes.shapes[0]
    np.testing.assert_allclose(ratios, [golden, 1.0 - golden], rtol=1e-9)
    np.testing.assert_allclose(modes.shapes.T @ modes.shapes, np.eye(2), atol=1e-12)  # M = I


def test_mass_normalisation_fe(unit):
    model = cantilever(20)
    modes = fm.linear_modes(model, n=4)
    G = modes.shapes.T @ (model.M @ modes.shapes)
    np.testing.assert_allclose(G, np.eye(4), atol=1e-10)
    np.testing.assert_allclose(np.diag(modes.shapes.T @ (model.K @ modes.shapes)), modes.omega**2, rtol=1e-7)


@pytest.mark.parametrize("case", sorted(BETA_L))
def test_beam_frequencies_against_blevins(case):
    mesh = fm.line_mesh(length=1.0, n_elements=40)
    model = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), **SUPPORTS[case])
    omega = fm.linear_modes(model, n=4).omega
    beta = np.asarray(BETA_L[case])
    err = omega / beta**2 - 1
    # Hermite error ~ (beta h)^4 / 1440 (references.md), upper bounds; 1e-8 allows for round-off.
    bound = 1.2 * (beta / 40) ** 4 / 1440 + 1e-8
    assert np.all(err > -1e-8) and np.all(err < bound), (err, bound)


def test_hermite_sample_values_ne10():
    omega = fm.linear_modes(cantilever(10), n=4).omega
    np.testing.assert_allclose(omega, [3.5160182751, 22.0352208701, 61.7129229753, 121.0171300999], rtol=1e-9)


def test_hermite_convergence_rate_cantilever():
    ne = np.array([2, 4, 8, 16])
    exact = 1.8751040687**2
    err = np.array([fm.linear_modes(cantilever(n), n=1).omega[0] / exact - 1 for n in ne])
    np.testing.assert_allclose(err[:3], [4.8344e-4, 3.2708e-5, 2.0830e-6], rtol=1e-3)
    assert np.all(err > 0)  # consistent mass: upper bounds
    rate = -np.polyfit(np.log(ne), np.log(err), 1)[0]
    assert abs(rate - 4.0) < 0.1, rate


def test_hermite_convergence_rate_pinned_pinned_mode2():
    ne = np.array([4, 8, 16])
    errs = []
    for n in ne:
        mesh = fm.line_mesh(length=1.0, n_elements=int(n))
        model = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), pinned=["left", "right"])
        errs.append(fm.linear_modes(model, n=2).omega[1] / (2 * np.pi) ** 2 - 1)
    rate = -np.polyfit(np.log(ne), np.log(errs), 1)[0]
    assert abs(rate - 4.0) < 0.15, rate


def test_bar_p1_convergence_matches_table():
    ne = np.array([4, 8, 16, 32])
    err = np.array([fm.linear_modes(fixed_free_bar(int(n)), n=1).omega[0] / (np.pi / 2) - 1 for n in ne])
    np.testing.assert_allclose(err, [6.4373e-3, 1.6071e-3, 4.0164e-4, 1.0040e-4], rtol=2e-4)
    rate = -np.polyfit(np.log(ne), np.log(err), 1)[0]
    assert abs(rate - 2.0) < 0.02, rate


def test_bar_p1_lumped_is_lower_bound():
    ne = np.array([8, 16, 32])
    err = np.array([fm.linear_modes(fixed_free_bar(int(n), lumped=True), n=1).omega[0] / (np.pi / 2) - 1 for n in ne])
    assert np.all(err < 0)
    kh = (np.pi / 2) / ne
    np.testing.assert_allclose(err, -(kh**2) / 24, rtol=0.05)


def test_bar_p2_convergence_rate():
    ne = np.array([2, 4, 8])
    # mode 2, w = 3 pi / 2, so the error stays far above round-off
    err = np.array([fm.linear_modes(fixed_free_bar(int(n), order=2), n=2).omega[1] / (1.5 * np.pi) - 1 for n in ne])
    rate = -np.polyfit(np.log(ne), np.log(err), 1)[0]
    assert abs(rate - 4.0) < 0.2, rate
    kh = 1.5 * np.pi / ne
    np.testing.assert_allclose(err[-1], kh[-1] ** 4 / 1440, rtol=0.1)


def test_bar_fixed_free_higher_modes_with_material_scaling():
    # c = sqrt(E/rho) = 2, L = 2: w_n = (2n-1) pi c / (2 L)
    mesh = fm.line_mesh(length=2.0, n_elements=200, boundaries={"fixed": 0.0, "free": 2.0})
    model = fm.bar(mesh, fm.Material(E=4.0, rho=1.0), fm.Section(area=0.5), order=2, clamped="fixed")
    omega = fm.linear_modes(model, n=3).omega
    np.testing.assert_allclose(omega, [(2 * n - 1) * np.pi * 2 / 4 for n in (1, 2, 3)], rtol=1e-8)


def test_static_tip_deflection_uniform_load_exact():
    # q L^4 / (8 EI): Hermite elements reproduce it exactly at the nodes (consistent load).
    import skfem

    EI, q, L = 2.5, 3.0, 1.7
    mesh = fm.line_mesh(length=L, n_elements=3, boundaries={"clamp": 0.0, "tip": L})
    model = fm.beam(mesh, fm.Material(E=EI, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")

    @skfem.LinearForm
    def load(v, w):
        return q * v

    f_full = load.assemble(model.fe.basis)
    f = f_full[model.fe.free]
    import scipy.sparse.linalg as spla

    u = spla.spsolve(model.K.tocsc(), f)
    tip = model.dof("tip")
    assert u[tip] == pytest.approx(q * L**4 / (8 * EI), rel=1e-12)


def test_two_materials_equal_properties_match_single_material():
    mesh = fm.line_mesh(length=1.0, n_elements=20, subdomains={"a": (0.0, 0.5), "b": (0.5, 1.0)})
    mat, sec = fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0)
    m1 = fm.beam(mesh, {"a": mat, "b": mat}, sec, clamped="left")
    m2 = fm.beam(mesh, mat, sec, clamped="left")
    np.testing.assert_allclose(fm.linear_modes(m1, 3).omega, fm.linear_modes(m2, 3).omega, rtol=1e-12)
    stiff = fm.beam(mesh, {"a": fm.Material(E=10.0, rho=1.0), "b": mat}, sec, clamped="left")
    assert fm.linear_modes(stiff, 1).omega[0] > 1.2 * fm.linear_modes(m2, 1).omega[0]


def test_point_mass_and_spring_on_discrete_limit():
    # A massless-ish stiff bar with a tip mass m: w ~ sqrt(k / m) with k = EA/L.
    mesh = fm.line_mesh(length=1.0, n_elements=4, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1e-8), fm.Section(area=1.0), clamped="clamp", point_masses={"tip": 2.0})
    assert fm.linear_modes(model, 1).omega[0] == pytest.approx(np.sqrt(0.5), rel=1e-6)
    sprung = fm.bar(mesh, fm.Material(E=1.0, rho=1e-8), fm.Section(area=1.0), clamped="clamp",
                    point_masses={"tip": 2.0}, springs={"tip": 3.0})
    assert fm.linear_modes(sprung, 1).omega[0] == pytest.approx(np.sqrt(4.0 / 2.0), rel=1e-6)


def test_free_free_beam_has_rigid_body_modes():
    mesh = fm.line_mesh(length=1.0, n_elements=20)
    model = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0))
    omega = fm.linear_modes(model, n=3).omega
    # rigid-body modes: zero up to round-off (sqrt(eps * lambda_max) ~ 1e-4 here)
    assert omega[0] < 1e-3 and omega[1] < 1e-3
    assert omega[2] == pytest.approx(4.7300407449**2, rel=1e-5)  # free-free = clamped-clamped roots


def test_large_sparse_path_matches_dense():
    # above DENSE_LIMIT the shift-invert Lanczos path is used
    model = fixed_free_bar(800)
    omega = fm.linear_modes(model, n=3).omega
    exact = np.array([1, 3, 5]) * np.pi / 2
    kh = exact / 800
    np.testing.assert_allclose(omega / exact - 1, kh**2 / 24, rtol=1e-3)


def test_ill_conditioned_beam_warns():
    mesh = fm.line_mesh(length=1.0, n_elements=8000)
    model = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="left")
    with pytest.warns(fm.IllConditionedWarning, match="ill-conditioned"):
        fm.linear_modes(model, n=1)


def test_linear_response_single_dof_and_modal_damping():
    model = fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
    w = np.array([0.5, 1.0, 1.5])
    resp = fm.linear_response(model, w)
    expect = 0.2 / np.sqrt((1 - w**2) ** 2 + (0.1 * w) ** 2)
    np.testing.assert_allclose(resp.magnitude(0), expect, rtol=1e-12)
    # modal damping ratio 0.05 on a 1-DOF system is c = 2 zeta w = 0.1
    md = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(modal=0.05)
    np.testing.assert_allclose(md.damping_matrix().toarray(), [[0.1]], rtol=1e-12)


def test_rayleigh_damping_matrix():
    model = two_dof_chain().with_damping(alpha=0.1, beta=0.01)
    np.testing.assert_allclose(model.C.toarray(), 0.1 * np.eye(2) + 0.01 * np.array([[2, -1], [-1, 1]]))


@pytest.mark.parametrize("seed", range(6))
def test_free_free_beam_modes_do_not_depend_on_the_rounding_of_K(seed):
    """Whether Cholesky of a singular K passes is decided by round-off (it did pass once the beam
    was assembled with the 2-point rule, femodes/fe/quadrature.py, and the inverse eigenproblem then
    returned w3 1 % off). Perturbations of 64 eps relative, as different assembly orders give, must
    not change the answer beyond the direct solver's round-off, eps * lambda_max / lambda_3 ~ 1e-10."""
    mesh = fm.line_mesh(length=1.0, n_elements=20)
    model = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0))
    rng = np.random.default_rng(seed)
    K = model.K.tocoo()
    noise = sp.coo_matrix((K.data * 64 * np.finfo(float).eps * rng.uniform(-1, 1, K.nnz), (K.row, K.col)), K.shape)
    perturbed = fm.StructuralModel(M=model.M, K=model.K + 0.5 * (noise + noise.T))
    omega = fm.linear_modes(perturbed, n=3).omega
    assert omega[0] < 1e-3 and omega[1] < 1e-3
    assert omega[2] == pytest.approx(4.7300407449**2, rel=1e-5)


def test_lanczos_results_are_the_same_in_every_run():
    """Above the dense limit the modes come from ARPACK, whose start vector scipy draws from fresh
    OS entropy unless given one: the same model gave shapes that differed at round-off from call to
    call (and a conservative backbone's bifurcation list with them). femodes passes a seeded start
    (eigen.krylov_start): two calls, with another eigen-solve between them, agree to the bit."""
    from femodes.eigen import DENSE_LIMIT

    model = fixed_free_bar(2 * DENSE_LIMIT)
    first = fm.linear_modes(model, 4)
    fm.linear_modes(fixed_free_bar(DENSE_LIMIT + 10), 3)  # another solve in between
    again = fm.linear_modes(model, 4)
    np.testing.assert_array_equal(first.omega, again.omega)
    np.testing.assert_array_equal(first.shapes, again.shapes)


@pytest.mark.parametrize("fmt", ["csr", "csc", "coo"])
def test_one_norm_of_the_condition_estimate(fmt):
    """The condition estimate's ``||K||_1`` is the largest column sum of ``|K|`` from the stored
    entries (no copy of ``|K|``): equal to scipy's ``norm(K, 1)`` to the rounding of a different
    summation order (n eps of the norm), with empty columns in the middle and at the end."""
    import scipy.sparse.linalg as spla

    from femodes.eigen import _one_norm

    rng = np.random.default_rng(5)
    for shape in ((60, 45), (45, 60), (1, 1)):
        A = sp.random(*shape, density=0.1, random_state=rng, format="csc")
        A = (A - 2.0 * sp.random(*shape, density=0.05, random_state=rng, format="csc")).tolil()
        A[:, shape[1] // 2] = 0.0
        A[:, shape[1] - 1] = 0.0
        A = A.asformat(fmt)
        ref = spla.norm(sp.csc_matrix(A), 1)
        assert abs(_one_norm(A) - ref) <= shape[0] * np.finfo(float).eps * ref
    assert _one_norm(sp.csc_matrix((4, 4))) == 0.0
