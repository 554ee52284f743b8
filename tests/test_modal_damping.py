"""Modal damping stays sparse (issue 16, item 4).

``with_damping(modal=...)`` keeps ``C = M Phi diag(2 zeta w) Phi^T M`` as a zero sparse part plus
a low-rank part ``C_lowrank = (U = M Phi, d = 2 zeta w)``. Every path that uses the damping is
checked against the same model given the assembled matrix explicitly
(``dataclasses.replace(model, C=dense, C_lowrank=None)`` runs the ``StructuralModel(C=...)``
constructor), and against the undamped model, so that a path that ignored the low-rank part
would fail: HBM residual, Jacobian and Newton steps (dense, SuperLU, structured and assembled
solvers, with borders and artificial damping), linear solves, frequency responses, time
stepping (dense and sparse steppers), shooting and Hill multipliers, Craig-Bampton reduction,
checkpoint fingerprints and the scaling study's dense-Jacobian warning.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools

import numpy as np
import pytest
import scipy.sparse as sp

import femodes as fm
from femodes.app.scaling.child import _nnz
from femodes.app.scaling.records import ScalingRecord, _note
from femodes.hbm.linsolve import AssembledFactorization, AssembledSolver, BlockSolver, StructuredFactorization
from femodes.hbm.system import HBMSystem
from femodes.model import DENSE_DAMPING_MAX_DOFS, LowRankDamping, low_rank_solver
from femodes.runs import model_fingerprint
from femodes.time.exact import exact_flow_unsupported


def bar_case(ne: int, zeta=0.02, n_modes=10):
    """Clamped P1 bar (E = rho = A = L = 1) with a tip stop and a tip force; modal damping."""
    mesh = fm.line_mesh(1.0, ne, boundaries={"clamp": 0.0, "tip": 1.0})
    bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    model = (bar.with_contact(fm.UnilateralContact(at="tip", gap=1e-3))
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=1e-3)))
    if np.ndim(zeta):
        n_modes = None
    return model.with_damping(modal=zeta, n_modes=n_modes)


def chain_case(n=4, zeta=(0.05, 0.1), penalty=True):
    """Discrete spring-mass chain (definite M: shooting works) with a stop at the last mass."""
    K = 2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    K[-1, -1] = 1.0
    model = fm.StructuralModel(M=np.diag(np.linspace(1.0, 2.0, n)), K=K)
    law = (fm.PenaltyContact(at=n - 1, gap=0.5, stiffness=5.0) if penalty
           else fm.UnilateralContact(at=n - 1, gap=0.5))
    return model.with_contact(law).with_forcing(fm.HarmonicForce(at=n - 1, amplitude=0.3)).with_damping(
        modal=list(zeta))


def assembled(model):
    """The same model with the damping given as an explicit (dense) matrix C."""
    return dataclasses.replace(model, C=model.damping_matrix().toarray(), C_lowrank=None)


def undamped(model):
    return dataclasses.replace(model, C=None, C_lowrank=None)


def rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(np.max(np.abs(b)), 1e-300))


# ----------------------------------------------------------------------------- the model
def test_representation_and_api():
    model = bar_case(100, zeta=[0.01, 0.02, 0.03])
    lr = model.C_lowrank
    assert model.C.nnz == 0 and lr.U.shape == (100, 3) and lr.rank == 3 and model.damping.nonzero
    modes = fm.linear_modes(model, n=3)
    # Phi^T C Phi = diag(2 zeta w) on the damped modes
    phi = modes.shapes
    Cm = phi.T @ model.damping_matrix().toarray() @ phi
    np.testing.assert_allclose(np.diag(Cm), 2 * np.array([0.01, 0.02, 0.03]) * modes.omega, rtol=1e-8)
    v = np.random.default_rng(1).standard_normal((100, 2))
    np.testing.assert_allclose(model.damping.apply(v), model.damping_matrix() @ v, rtol=1e-12, atol=1e-15)
    # Rayleigh damping replaces the modal part (and the other way round)
    ray = model.with_damping(alpha=0.1)
    assert ray.C_lowrank is None and ray.C.nnz == model.M.nnz
    assert ray.damping_matrix() is ray.C
    assert "modal zeta=0.01..0.03 on 3 modes" in repr(model)
    # the damping matrix is refused where it would be huge
    with pytest.raises(ValueError, match="low-rank"):
        _big_dense_refused()


def _big_dense_refused():
    n = DENSE_DAMPING_MAX_DOFS + 1
    m = fm.StructuralModel(M=sp.identity(n), K=sp.identity(n), C_lowrank=LowRankDamping(np.ones((n, 1)), [1.0]))
    m.damping_matrix()


def test_fingerprint_sees_the_lowrank_part():
    model = chain_case()
    assert model_fingerprint(model)["matrices"] != model_fingerprint(undamped(model))["matrices"]
    assert model_fingerprint(model)["matrices"] != model_fingerprint(model.with_damping(modal=0.01))["matrices"]


# ----------------------------------------------------------------------------- harmonic balance
def two_stops():
    """Two masses, a stop on each: no interior DOF (the Schur complement is everything)."""
    m = fm.StructuralModel(M=np.diag([1.0, 2.0]), K=[[2.0, -1.0], [-1.0, 1.0]])
    return (m.with_contact(fm.UnilateralContact(at=0, gap=0.1), fm.UnilateralContact(at=1, gap=0.2))
            .with_forcing(fm.HarmonicForce(at=1, amplitude=0.1)).with_damping(modal=[0.05, 0.1]))


@pytest.mark.parametrize("ne, H, solver", [
    (20, 5, BlockSolver()),       # <= 500 unknowns: dense LAPACK
    (30, 5, BlockSolver()),       # < 500: SuperLU on the augmented sparse matrix
    (200, 5, BlockSolver()),      # structured: modal coordinates in the Schur complement
    (200, 5, AssembledSolver()),
    (0, 4, BlockSolver()),        # no interior DOF at all
])
def test_hbm_residual_jacobian_newton_step(ne, H, solver):
    """Each solver path, and the structured factorisation called directly whatever the size."""
    model = bar_case(ne) if ne else two_stops()
    ref, und = assembled(model), undamped(model)
    h = fm.Harmonics(H)
    s1, s2, s0 = (HBMSystem(m, h, solver=solver) for m in (model, ref, und))
    rng = np.random.default_rng(ne)
    x = 1e-3 * rng.standard_normal(s1.size)
    w = 1.7
    for xi in (0.0, 0.3):
        r1, J1, dw1, dx1 = s1.residual(x, w, xi=xi)
        r2, J2, dw2, dx2 = s2.residual(x, w, xi=xi)
        r0, *_ = s0.residual(x, w, xi=xi)
        assert rel(r1, r2) < 1e-12 and rel(dw1, dw2) < 1e-12 and rel(dx1, dx2) < 1e-12
        assert rel(r0, r2) > 1e-6  # the damping matters: ignoring it would fail the checks
        v = rng.standard_normal(s1.size)
        assert rel(J1 @ v, J2 @ v) < 1e-12
        if s1.size <= 1000:
            assert rel(J1.toarray(), J2.toarray()) < 1e-12
        assert np.all(J1.abs_matvec(np.abs(v)) >= np.abs(J1 @ v) * (1 - 1e-12))
        # Newton step, plain and bordered (continuation), with a scaled Jacobian
        b = rng.standard_normal(s1.size)
        x2 = J2.factorize().solve(b)
        assert rel(J1.factorize().solve(b), x2) < 1e-9
        assert rel(StructuredFactorization(J1, None).solve(b), x2) < 1e-9
        assert rel(AssembledFactorization(J1).solve(b), x2) < 1e-9
        cols, rows = rng.standard_normal((s1.size, 2)), rng.standard_normal((2, s1.size))
        corner = rng.standard_normal((2, 2))
        B1, B2 = (3.0 * J1).bordered(cols, rows, corner), (3.0 * J2).bordered(cols, rows, corner)
        bb = rng.standard_normal(s1.size + 2)
        z1 = B1.factorize().solve(bb)
        assert rel(z1, B2.factorize().solve(bb)) < 1e-9
        assert rel(B1 @ z1, bb) < 1e-9
        assert rel(StructuredFactorization(B1, None).solve(bb), z1) < 1e-9
    # the linear solve of the forced structure (initial guesses)
    assert rel(s1.linear.solve(s1.linear.force(), w), s2.linear.solve(s2.linear.force(), w)) < 1e-9
    # the Jacobian stays sparse: its stored entries are those of the undamped one plus U and d
    _, J0, _, _ = s0.residual(x, w)
    _, J1, _, _ = s1.residual(x, w)
    assert J1.nnz == J0.nnz + model.C_lowrank.nnz


def test_structured_solver_is_used_and_handles_a_singular_interior(monkeypatch):
    """Pure modal damping leaves the interior blocks undamped (K - a M, real band LU): at an
    interior resonance the structured solver falls back to the augmented SuperLU."""
    model = bar_case(200)
    ref = assembled(model)
    h = fm.Harmonics(5)
    s1, s2 = HBMSystem(model, h), HBMSystem(ref, h)
    x = np.zeros(s1.size)
    _, J1, _, _ = s1.residual(x, 2.0)
    assert type(J1.factorize()) is StructuredFactorization
    F = s1.linear.factors(2.0)
    assert F.rank == 10 and F.blocks[1].Zc.shape == (11, 11)
    assert not F.blocks[1].lu.complex  # the sparse part is undamped: real band LU
    # an interior eigenfrequency (clamped bar with the tip held): w = pi * 1 (k = 1), slightly off
    w = np.pi * (1 + 1e-13)
    b = np.random.default_rng(0).standard_normal(s1.size)
    _, J1, _, _ = s1.residual(x, w)
    _, J2, _, _ = s2.residual(x, w)
    assert rel(J1.factorize().solve(b), J2.factorize().solve(b)) < 1e-7


@functools.cache
def _frc(kind: str):
    model = chain_case(penalty=False)
    m = {"modal": model, "dense": assembled(model)}[kind]
    return fm.frequency_response(m, omega=(0.3, 0.6), harmonics=fm.Harmonics(6),
                                 options=fm.ContinuationOptions(max_points=25))


def test_frequency_response_and_hill_match_the_dense_damping():
    a, b = _frc("modal"), _frc("dense")
    n = min(len(a), len(b))
    assert n >= 10
    np.testing.assert_allclose(a.omega[:n], b.omega[:n], rtol=1e-8)
    np.testing.assert_allclose(a.energy[:n], b.energy[:n], rtol=1e-7)
    for i in (2, n - 2):
        h1 = fm.stability(a[i], method=fm.stability_methods.Hill())
        h2 = fm.stability(b[i], method=fm.stability_methods.Hill())
        np.testing.assert_allclose(np.abs(h1.multipliers[:4]), np.abs(h2.multipliers[:4]), rtol=1e-6)


def test_shooting_multipliers_match_the_dense_damping():
    model = chain_case()
    sols = []
    for m, damped in ((model, True), (assembled(model), True), (undamped(model), False)):
        # the undamped model is said to have no finite peak (issue 36): expected here
        with contextlib.nullcontext() if damped else pytest.warns(UserWarning, match="no damping"):
            frc = fm.frequency_response(m, omega=(0.4, 0.45), harmonics=fm.Harmonics(8),
                                        options=fm.ContinuationOptions(max_points=4))
        sols.append(fm.stability(frc[1], method=fm.stability_methods.Shooting()).multipliers)
    np.testing.assert_allclose(np.abs(sols[0]), np.abs(sols[1]), rtol=1e-6)
    assert rel(np.abs(sols[2]), np.abs(sols[1])) > 1e-3


# ----------------------------------------------------------------------------- other consumers
def test_linear_response():
    model = bar_case(300, n_modes=5)
    w = [1.0, np.pi / 2 * 0.999, 4.0]  # near the first eigenfrequency pi/2 of the clamped-free bar
    a = fm.linear_response(model, w).amplitude
    b = fm.linear_response(assembled(model), w).amplitude
    c = fm.linear_response(undamped(model), w).amplitude
    assert rel(a, b) < 1e-9 and rel(c, b) > 1e-2
    # exactly at an eigenfrequency the undamped sparse part is singular; the modal damping is not
    small = bar_case(30, n_modes=5)
    lam = fm.linear_modes(small, n=1).omega[0]
    np.testing.assert_allclose(fm.linear_response(small, lam).amplitude,
                               fm.linear_response(assembled(small), lam).amplitude, rtol=1e-8)
    # K - w^2 M exactly singular (w = 1): the sparse augmented system
    two = fm.StructuralModel(M=np.eye(2), K=np.diag([1.0, 4.0])).with_damping(modal=[0.1, 0.2])
    np.testing.assert_allclose(fm.linear_response(two, 1.0, force=[1.0, 1.0]).amplitude,
                               fm.linear_response(assembled(two), 1.0, force=[1.0, 1.0]).amplitude, rtol=1e-12)


@pytest.mark.parametrize("n", [6, 260])  # dense stepper (<= 200 DOFs), sparse stepper + Woodbury
def test_time_stepping(n):
    model = chain_case(n, zeta=(0.05, 0.1, 0.08))
    u0 = np.zeros(n)
    u0[-1] = 0.3
    kw = dict(t_end=3.0, dt=0.01, u0=u0, omega=0.5)
    a = fm.simulate(model, **kw)
    b = fm.simulate(assembled(model), **kw)
    c = fm.simulate(undamped(model), **kw)
    assert rel(a.u, b.u) < 1e-9 and rel(a.v, b.v) < 1e-9
    assert rel(c.u, b.u) > 1e-4


def test_craig_bampton_projects_the_whole_damping():
    model = bar_case(120, n_modes=8)
    rom = fm.craig_bampton(model, 6)
    ref = fm.craig_bampton(assembled(model), 6)
    np.testing.assert_allclose(rom.C.toarray(), ref.C.toarray(), rtol=1e-9, atol=1e-12 * abs(ref.C).max())
    assert rom.C_lowrank is None and rom.C.nnz > 0
    # modal damping of a reduced model, truncated: the leading block of its damping
    rd = rom.with_damping(modal=0.05, n_modes=3)
    t = rd.truncated(4)
    np.testing.assert_allclose(t.damping_matrix().toarray(), rd.damping_matrix().toarray()[:5, :5], rtol=1e-12)


def test_scaling_warns_about_a_dense_jacobian():
    dense = ScalingRecord(n_elements=10, H=5, N=10, unknowns=110, nnz_J=8000, iteration_median_s=1e-3)
    sparse = ScalingRecord(n_elements=10, H=5, N=10, unknowns=110, nnz_J=600, iteration_median_s=1e-3)
    assert dense.dense_jacobian and "dense Jacobian" in _note(dense)
    assert not sparse.dense_jacobian and _note(sparse) == ""
    # the HBM Jacobian of a modal-damped bar is sparse, that of the same bar given the dense C is not
    model = bar_case(60)
    for m, dense_expected in ((model, False), (assembled(model), True)):
        s = HBMSystem(m, fm.Harmonics(3))
        _, J, _, _ = s.residual(np.zeros(s.size), 1.0)
        rec = ScalingRecord(n_elements=60, H=3, unknowns=s.size, nnz_J=_nnz(J))
        assert rec.dense_jacobian is dense_expected
    assert _nnz(J) == J.tocsr().nnz  # without a low-rank part: the assembled count, as before


def test_lowrank_solver_zero_gains_and_blocks():
    rng = np.random.default_rng(3)
    A = np.diag(rng.uniform(1, 2, 30))
    U = rng.standard_normal((30, 4))
    g = np.array([0.0, 1.0, 2.0, 0.0])
    solve = low_rank_solver(lambda b: np.linalg.solve(A, b), U, g, U, matvec=lambda x: A @ x)
    B = rng.standard_normal((30, 3))
    np.testing.assert_allclose(solve(B), np.linalg.solve(A + (U * g) @ U.T, B), rtol=1e-12)


@pytest.mark.parametrize("path", ["modes", "modes at a resonance", "mass changed after damping", "general"])
def test_structured_condensation_paths(path):
    """The condensation through the modes (``K Phi = U diag(w^2)``, checked), with a mode exactly
    at ``k w`` (solved for), with the mass changed on a few rows after the modes of the low-rank
    part were computed (the tip mass redistributed), and the general path
    (a sparse damping part besides the modal one) all give the dense answer."""
    mesh = fm.line_mesh(1.0, 200, boundaries={"clamp": 0.0, "tip": 1.0})
    bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    if path == "mass changed after damping":
        # the low-rank part of the bar before its tip mass was redistributed (with_contact now
        # recomputes the damping: set by hand, as a user-given C_lowrank would be)
        damped = bar.with_damping(modal=0.02, n_modes=10)
        model = dataclasses.replace(bar.with_contact(fm.UnilateralContact(at="tip", gap=1e-3))
                                    .with_forcing(fm.HarmonicForce(at="tip", amplitude=1e-3)),
                                    C_lowrank=damped.C_lowrank, damping_info=damped.damping_info)
    elif path == "general":
        model = bar_case(200)
        model = dataclasses.replace(model, C=0.01 * model.M)
    else:
        model = bar_case(200)
    w = fm.linear_modes(model, n=1).omega[0] if path == "modes at a resonance" else 1.3
    s1, s2 = HBMSystem(model, fm.Harmonics(5)), HBMSystem(assembled(model), fm.Harmonics(5))
    assert (s1.stiffness.Z.lowrank_modes() is None) == (path == "general")
    if path == "mass changed after damping":
        assert 0 < s1.stiffness.Z.lowrank_modes()[2].size <= 3
    x = 1e-3 * np.random.default_rng(5).standard_normal(s1.size)
    b = np.random.default_rng(6).standard_normal(s1.size)
    for xi in (0.0, 0.2):
        _, J1, _, _ = s1.residual(x, w, xi=xi)
        _, J2, _, _ = s2.residual(x, w, xi=xi)
        F = J1.factorize()
        assert type(F) is StructuredFactorization
        assert (F.F.modes is None) == (path == "general")
        assert F.ymodal is not None  # the modal coordinates eliminated harmonic by harmonic
        assert rel(F.solve(b), J2.factorize().solve(b)) < 1e-8



@pytest.mark.parametrize("border", [False, True])
def test_modal_elimination_solves_the_schur_complement(border):
    """The modal coordinates eliminated harmonic by harmonic (each pair's block inverted as the
    complex matrix of its real form) solve the Schur complement ``T`` itself, before any
    refinement: against a dense solve of ``T``, to its condition number times eps."""
    model = bar_case(200)
    s = HBMSystem(model, fm.Harmonics(5))
    x = 1e-3 * np.random.default_rng(5).standard_normal(s.size)
    _, J, _, _ = s.residual(x, 1.3)
    if border:  # one border row and column, as the arclength corrector adds
        rng = np.random.default_rng(8)
        J = J.bordered(rng.standard_normal((s.size, 1)), rng.standard_normal((1, s.size)), np.ones((1, 1)))
    F = J.factorize()
    S = F.schur
    assert S.ymodal is not None and S.L.mr == 10 and S.L.m == (1 if border else 0)
    rhs = np.random.default_rng(7).standard_normal((S.T.shape[0], 2))
    ref = np.linalg.solve(S.T, rhs)
    tol = 10 * np.linalg.cond(S.T) * np.finfo(float).eps
    assert rel(S.solve(rhs), ref) < tol < 1e-6


@pytest.mark.parametrize("mass_changed", [False, True])
def test_linear_response_through_the_modes(mass_changed):
    """The linear (starting) response with modal damping takes ``(K - f^2 M)^-1 U`` from the modes
    relation (no ``m`` solves per harmonic), with one solve per mass row changed after the damping
    (the contact's redistribution): the same response as the assembled dense damping, to 1e-9
    (these blocks' condition numbers are 1e3-1e5, the solves backward stable)."""
    mesh = fm.line_mesh(1.0, 200, boundaries={"clamp": 0.0, "tip": 1.0})
    bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    contact, force = fm.UnilateralContact(at="tip", gap=1e-3), fm.HarmonicForce(at="tip", amplitude=1e-3)
    model = bar_case(200)
    if mass_changed:  # the damping of the bar before with_contact moved its tip mass (set by hand)
        damped = bar.with_damping(modal=0.02, n_modes=10)
        model = dataclasses.replace(bar.with_contact(contact).with_forcing(force),
                                    C_lowrank=damped.C_lowrank, damping_info=damped.damping_info)
    s1, s2 = HBMSystem(model, fm.Harmonics(5)), HBMSystem(assembled(model), fm.Harmonics(5))
    em = s1.stiffness.Z.lowrank_modes()
    assert em is not None and (em[2].size > 0) == mass_changed
    for w in (0.7, 1.3, 2.9):
        q1 = s1.linear.solve(s1.linear.force(), w)
        assert rel(q1, s2.linear.solve(s2.linear.force(), w)) < 1e-9

def _beam_contact():
    mesh = fm.line_mesh(1.0, 10, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    return beam, fm.UnilateralContact(at="tip", gap=0.01)


@pytest.mark.parametrize("damping", [dict(alpha=0.02), dict(alpha=0.02, beta=1e-3), dict(modal=0.03),
                                     dict(modal=[0.01, 0.02, 0.03])])
def test_damping_before_or_after_the_contact_is_the_same(damping):
    """``with_damping`` before ``with_contact`` (which redistributes the tip's mass) is recomputed
    from the new mass and modes: the same damping as after it (same inputs to the same
    computation: equal to round-off of the eigensolver, 1e-12 of the largest entry)."""
    beam, contact = _beam_contact()
    before = beam.with_damping(**damping).with_contact(contact)
    after = beam.with_contact(contact).with_damping(**damping)
    Cb, Ca = before.damping_matrix().toarray(), after.damping_matrix().toarray()
    assert np.abs(Cb - Ca).max() <= 1e-12 * np.abs(Ca).max()
    assert before.damping_info == after.damping_info
    tip = after.dof("tip")
    assert after.M.diagonal()[tip] == 0.0  # redistributed: the old C = alpha M had mass on this row
    if "beta" not in damping:  # mass-proportional and modal damping have no row at a massless DOF
        assert not np.any(Cb[tip])
        assert not exact_flow_unsupported(before.with_forcing(fm.HarmonicForce(at="tip", amplitude=1e-3)))


def test_modal_damping_counts_only_the_modes_of_dofs_with_mass():
    """A model with a massless DOF has one mode fewer than DOFs: the scalar default takes what
    there is (it used to fail on a shape mismatch); asking for more names the count."""
    beam, contact = _beam_contact()
    model = beam.with_contact(contact)
    assert model.n_dofs == 20
    assert model.with_damping(modal=0.03).damping_info == "modal zeta=0.03 on 19 modes"
    with pytest.raises(ValueError, match=r"only 19 modes \(1 of its 20 DOFs have no mass\); give at most 19"):
        model.with_damping(modal=0.03, n_modes=20)
    with pytest.raises(ValueError, match="only 19 modes"):
        model.with_damping(modal=[0.01] * 20)


def test_damping_replaced_after_with_damping_is_kept_with_a_warning(caplog):
    """A damping matrix put in by ``dataclasses.replace`` after ``with_damping`` is not overwritten
    by the spec when ``with_contact`` redistributes mass: it is kept, the spec dropped, and a
    warning says so; without the replace the spec is applied (the test above)."""
    beam, contact = _beam_contact()
    damped = beam.with_damping(alpha=0.02)
    own = sp.identity(beam.n_dofs, format="csr") * 0.5
    replaced = dataclasses.replace(damped, C=own)
    with caplog.at_level("WARNING", logger="femodes.model"):
        out = replaced.with_contact(contact)
    assert "damping matrices changed after with_damping(alpha=0.02, beta=0.0)" in caplog.text
    assert abs(out.C - own).max() == 0.0 and out.damping_spec == ()
    assert dict(beam.with_damping(alpha=0.02).with_contact(contact).damping_spec)["alpha"] == 0.02
