"""Structured HBM solver (per-harmonic factorisations + Schur complement) against SuperLU.

Criterion: the structured and the generic (SuperLU on the assembled matrix) solutions of the same
Newton systems agree to round-off: normwise backward error <= 1e-13 (a few hundred ulps; the
refinement stops at 64 eps) and forward difference <= 100 eps cond_1(J) relative (both are
backward stable, so they can differ by that much and no more).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse.linalg as spla

import femodes as fm
from femodes.hbm.linsolve import (AssembledFactorization, BlockSolverOptions, DenseFactorization, ForceSchur,
                                  HarmonicBlockJacobian, StructuredFactorization)
from femodes.hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from femodes.hbm import AssembledSolver, BlockSolver
from femodes.solvers.continuation import bordered_matrix, bordered_solver

#: Small systems normally go to LAPACK (dense_max_size) or SuperLU (structured_min_size): the
#: solvers of this module take the structured path at any size
STRUCTURED = BlockSolverOptions(structured_min_size=0, structured_min_size_narrow=0, dense_max_size=0)


def structured(**kw) -> BlockSolver:
    """A block solver with the :data:`STRUCTURED` options (changed by ``options=dict(...)``)."""
    return BlockSolver(options=dataclasses.replace(STRUCTURED, **kw.pop("options", {})), **kw)


def forced(model, h, solver=None) -> ForcedResponseProblem:
    """The forced-response problem of ``model`` solved by ``solver`` (default :func:`structured`)."""
    return ForcedResponseProblem(model, h, solver=structured() if solver is None else solver)


def test_small_systems_use_lapack_then_superlu():
    model, h = CASES["chain"]()
    pr = forced(model, h)
    x = state(pr, 1, 0.5)
    _, J, _ = pr.residual(x, 1.1)
    assert J.shape[0] <= 500
    F = BlockSolver(options=BlockSolverOptions(dense_max_size=500)).factorize(J)
    assert isinstance(F, DenseFactorization)
    # the dense assembly is the sparse one, entry for entry (bordered too)
    Jb = J.bordered(np.ones((J.shape[0], 1)), np.ones((1, J.shape[0])), np.array([[2.0]]))
    for A in (J, 2.5 * J, Jb):
        np.testing.assert_array_equal(A.toarray(), A.tocsr().toarray())
    b = np.linspace(-1.0, 1.0, J.shape[0])
    assert backward_error(J, F.solve(b), b) < 1e3 * np.finfo(float).eps
    assert isinstance(BlockSolver(options=BlockSolverOptions(dense_max_size=10)).factorize(J), AssembledFactorization)
    assert isinstance(J.factorize(), StructuredFactorization)  # the problem's solver: STRUCTURED


def backward_error(J, x, b):
    A = J.tocsr()
    return float(np.max(np.abs(A @ x - b)) / (abs(A).sum(axis=1).max() * np.max(np.abs(x)) + np.max(np.abs(b))))


def forward_tol(Jg):
    """Forward error allowed by the conditioning: 100 eps cond_1(J) (1-norm estimate)."""
    A = Jg.tocsc()
    lu = spla.splu(A)
    inv = spla.LinearOperator(A.shape, matvec=lu.solve, rmatvec=lambda v: lu.solve(v, trans="T"))
    cond = spla.onenormest(A) * spla.onenormest(inv)
    return 100 * np.finfo(float).eps * cond


def bar_model(n_el=400, n_contacts=5, damping=True):
    mesh = fm.line_mesh(length=1.0, n_elements=n_el, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    if damping:
        model = model.with_damping(alpha=0.02, beta=1e-4)
    n = model.n_dofs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for d in np.linspace(n // 5, n - 1, n_contacts).astype(int):
            model = model.with_contact(fm.UnilateralContact(at=int(d), gap=1e-3))
    return model.with_forcing(fm.HarmonicForce(at="tip", amplitude=1.0))


def beam_model():
    mesh = fm.line_mesh(length=1.0, n_elements=60, boundaries={"clamp": 0.0, "mid": 0.5, "tip": 1.0})
    model = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    return (model.with_damping(alpha=0.01, beta=1e-4)
            .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.01))
            .with_contact(fm.UnilateralContact(at="tip", gap=1e-3))
            .with_contact(fm.PenaltyContact(at="mid", gap=1e-3, stiffness=50.0))
            .with_nonlinearity(fm.CubicSpring(at=("mid", "w"), k3=1e3)))


def chain(n_dofs=2):
    K = np.diag(np.full(n_dofs, 2.0)) - np.diag(np.ones(n_dofs - 1), 1) - np.diag(np.ones(n_dofs - 1), -1)
    return (fm.StructuralModel(M=np.eye(n_dofs), K=K, C=0.05 * np.eye(n_dofs))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=1.0))
            .with_contact(fm.UnilateralContact(at=n_dofs - 1, gap=0.5)))


CASES = {
    "bar": lambda: (bar_model(), fm.Harmonics(10)),
    "bar-undamped": lambda: (bar_model(damping=False), fm.Harmonics(6)),
    "beam-mixed-laws": lambda: (beam_model(), fm.Harmonics(5)),
    "chain": lambda: (chain(5), fm.Harmonics(7)),
    "one-dof": lambda: (chain(1) if False else fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
                        .with_forcing(fm.HarmonicForce(at=0, amplitude=1.0))
                        .with_contact(fm.UnilateralContact(at=0, gap=0.5)), fm.Harmonics(8)),
    "subharmonic": lambda: (chain(4), fm.Harmonics(6, subharmonic=2)),
}


def state(pr, seed, amp):
    rng = np.random.default_rng(seed)
    x = amp * rng.standard_normal(pr.size)
    return x


@pytest.mark.parametrize("name", sorted(CASES))
def test_structured_solve_matches_superlu(name):
    model, h = CASES[name]()
    pr = forced(model, h)
    pg = ForcedResponseProblem(model, h, solver=AssembledSolver())
    x = state(pr, 1, 1e-3 if "bar" in name or "beam" in name else 0.5)
    r, J, rp = pr.residual(x, 1.3)
    rg, Jg, rpg = pg.residual(x, 1.3)
    assert isinstance(J, HarmonicBlockJacobian)
    np.testing.assert_array_equal(r, rg)
    np.testing.assert_array_equal(rp, rpg)
    assert abs(J.toarray() - Jg.toarray()).max() == 0.0
    b = np.random.default_rng(2).standard_normal(pr.size)
    xs = J.factorize().solve(b)
    xg = spla.splu(Jg.tocsc()).solve(b)
    assert backward_error(J, xs, b) < 1e-13
    tol = forward_tol(Jg)
    assert np.max(np.abs(xs - xg)) <= tol * np.max(np.abs(xg))
    # matrix right-hand sides, and the matrix-vector product
    B = np.random.default_rng(3).standard_normal((pr.size, 3))
    XB = spla.splu(Jg.tocsc()).solve(B)
    np.testing.assert_allclose(J.factorize().solve(B), XB, rtol=0, atol=tol * np.abs(XB).max())
    np.testing.assert_allclose(J @ b, Jg @ b, rtol=1e-13, atol=1e-13 * np.abs(Jg @ b).max())


@pytest.mark.parametrize("name", ["bar", "beam-mixed-laws", "chain"])
def test_bordered_systems_match(name):
    """Nonlinear-mode border (w, xi) plus the continuation's arclength border, at xi != 0."""
    model, h = CASES[name]()
    nn = NonlinearModeProblem(model, h, solver=structured())
    x = nn.linear_guess(1e-4)
    x[:-2] += 1e-4 * np.random.default_rng(4).standard_normal(nn.size - 2)
    x[-1] = 0.03  # xi
    r, J, rp = nn.residual(x, -4.0)
    ng = NonlinearModeProblem(model, h, solver=AssembledSolver())
    _, Jg, _ = ng.residual(x, -4.0)
    assert abs(J.toarray() - Jg.toarray()).max() == 0.0
    c = np.random.default_rng(5).standard_normal(nn.size + 1)
    Jb = bordered_matrix(J, rp, c)
    Jbg = bordered_matrix(Jg, rp, c)
    assert Jb.shape == (nn.size + 1,) * 2 and abs(Jb.toarray() - Jbg.toarray()).max() == 0.0
    b = np.random.default_rng(6).standard_normal(nn.size + 1)
    xs = bordered_solver(Jb, b)
    xg = spla.splu(Jbg.tocsc()).solve(b)
    assert backward_error(Jb, xs, b) < 1e-13
    assert np.max(np.abs(xs - xg)) <= forward_tol(Jbg) * np.max(np.abs(xg))


def test_fold_border_is_solved_accurately():
    """At a fold J (without border) is singular; the border lives in the dense Schur part."""
    model = chain(3)
    pr = forced(model, fm.Harmonics(5))
    x = state(pr, 7, 0.3)
    _, J, rp = pr.residual(x, 1.0)
    # make the core exactly singular: duplicate a column direction through the border instead
    A = J.toarray()
    u, sv, vt = np.linalg.svd(A)
    # border with the left/right null directions of the nearly-singular part -> well-posed
    Jb = J.bordered(u[:, -1:], vt[-1:, :], np.zeros((1, 1)))
    b = np.random.default_rng(8).standard_normal(pr.size + 1)
    xs = Jb.factorize().solve(b)
    assert backward_error(Jb, xs, b) < 1e-13


def test_free_structure_is_held_by_its_contact():
    """Free-free bar: K is singular, but the interior (contact DOF held) is not: structured path."""
    mesh = fm.line_mesh(length=1.0, n_elements=20, boundaries={"left": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0))
             .with_damping(alpha=0.05)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=1.0))
             .with_contact(fm.UnilateralContact(at="tip", gap=0.0, c=1.0)))
    pr = forced(model, fm.Harmonics(3))
    s = pr.system
    P = np.zeros((s.h.n_coef, 1))
    P[0] = 10.0  # contact closed all period: the contact holds the rigid-body motion
    _, J, _ = pr.residual(s.join(np.zeros((s.h.n_coef, s.n)), P), 1.0)
    fac = J.factorize()
    assert not isinstance(fac, AssembledFactorization)
    b = np.random.default_rng(9).standard_normal(pr.size)
    assert backward_error(J, fac.solve(b), b) < 1e-13


def test_interior_resonance_falls_back_to_superlu():
    """k w exactly at the eigenfrequency of the structure with its contact DOF held (here
    Z_00 = 4 - (1 * 2)^2 = 0): the interior block is singular, the whole Jacobian is not."""
    model = (fm.StructuralModel(M=np.eye(2), K=[[4.0, -1.0], [-1.0, 1.0]])
             .with_forcing(fm.HarmonicForce(at=0, amplitude=1.0))
             .with_contact(fm.UnilateralContact(at=1, gap=0.1)))
    pr = forced(model, fm.Harmonics(3))
    _, J, _ = pr.residual(state(pr, 1, 0.3), 2.0)
    fac = J.factorize()
    assert isinstance(fac, AssembledFactorization)
    b = np.random.default_rng(9).standard_normal(pr.size)
    assert backward_error(J, fac.solve(b), b) < 1e-13



def test_assembled_fallback_takes_the_sparse_backend():
    """The assembled LU (the structured solver's fallback, AssembledSolver) factorises with the
    back-end ``sparse_direct`` picks for a matrix of its size (an unsymmetric LU of MUMPS or
    PARDISO above 5000 rows where installed, SuperLU otherwise) and solves to round-off."""
    from femodes import sparse_direct as sd

    pr = forced(bar_model(n_el=600, n_contacts=3), fm.Harmonics(5), solver=AssembledSolver())
    _, J, _ = pr.residual(state(pr, 3, 1e-3), 1.3)
    assert J.shape[0] > sd.AUTO_MIN_SIZE
    fac = J.factorize()
    assert isinstance(fac, AssembledFactorization)
    assert fac.lu.backend == sd.chosen_backend(J.shape[0], False)
    b = np.random.default_rng(4).standard_normal(pr.size)
    assert backward_error(J, fac.solve(b), b) < 1e-13

def test_singular_jacobian_raises():
    model, h = CASES["chain"]()
    pr = forced(model, h)
    _, J, _ = pr.residual(state(pr, 1, 0.5), 1.1)
    Jb = J.bordered(np.zeros((pr.size, 1)), np.zeros((1, pr.size)), np.zeros((1, 1)))
    with pytest.raises(RuntimeError):
        Jb.factorize().solve(np.ones(pr.size + 1))


def test_factorisations_are_reused_at_the_same_frequency():
    model, h = CASES["bar"]()
    pr = forced(model, h)
    s = pr.system
    F1 = s.linear.factors(1.3)
    assert s.linear.factors(1.3) is F1
    assert s.linear.factors(1.31) is not F1
    # a Newton iteration at fixed w after another x: same factors object
    _, J, _ = pr.residual(state(pr, 1, 1e-3), 1.31)
    J.factorize()
    F2 = s.linear.factors(1.31)
    _, J, _ = pr.residual(state(pr, 2, 1e-3), 1.31)
    J.factorize()
    assert s.linear.factors(1.31) is F2


def test_threads_give_identical_results():
    model, h = CASES["bar"]()
    b = np.random.default_rng(10).standard_normal(forced(model, h).size)
    out = []
    for threads in (1, 2):
        pr = forced(model, h, structured(options=dict(thread_min_size=0)))
        pr.system.threads = threads
        _, J, _ = pr.residual(state(pr, 1, 1e-3), 1.2)
        out.append(J.factorize().solve(b))
        assert pr.system.linear.factors(1.2).threads == threads
    np.testing.assert_array_equal(out[0], out[1])


def test_superlu_interior_path():
    """Wide-band interiors (reduced models, 2-D patterns) use SuperLU per harmonic: same result."""
    model, h = CASES["beam-mixed-laws"]()
    pr = forced(model, h, structured(options=dict(band_max_fill=0.0)))  # no band is narrow enough
    _, J, _ = pr.residual(state(pr, 1, 1e-3), 1.3)
    assert not pr.system.linear.block_pattern().banded
    b = np.random.default_rng(11).standard_normal(pr.size)
    assert backward_error(J, J.factorize().solve(b), b) < 1e-13


def solid_model(dim):
    """A P2 strip of triangles (2-D) or a P2 box (3-D) with a stop on the tip face: wide blocks."""
    if dim == 2:
        mesh, direction = fm.rectangle_mesh(1.0, 0.1, 20, 4, quadrilaterals=False), [1.0, 0.0]
        mat = fm.Material(E=1.0, rho=1.0, nu=0.3)
    else:
        mesh, direction = fm.box_mesh(1.0, 0.2, 0.1, 6, 2, 1), [1.0, 0.0, 0.0]
        mat = fm.Material(E=1.0, rho=1.0)
    model = fm.solid(mesh, mat, clamped="left", order=2).with_damping(beta=0.02)
    model = model.with_contact(fm.UnilateralContact(at="right", direction=direction, gap=0.01))
    return model.with_forcing(fm.HarmonicForce(at=model.contacts[0].dof, amplitude=1e-3))


def test_band_or_superlu_from_the_pattern():
    """Line meshes and the dense interiors of reduced models keep the band LU; 2-D/3-D meshes, whose
    band storage is 10x their nonzeros, go to SuperLU (BlockSolverOptions.band_max_fill)."""
    import femodes.hbm.linsolve as ls

    def pattern(model):
        bd = np.array(sorted({c.dof for c in model.contacts}))
        p = ls.build_pattern(model.M, model.K, model.C, bd)
        return p, (3 * p.kl + 1) * p.perm.size / p.rows.size

    for model in (bar_model(), beam_model()):
        p, ratio = pattern(model)
        assert p.banded and ratio < 3.5
    # the reduced beam's interior (30 fixed-interface modes) is exactly diagonal: M, K and the
    # Rayleigh C are diagonal in the orthonormal modes, and the projection drops their round-off by
    # its own scale (reduction.ZERO_ULPS), not by what one BLAS kernel happened to leave
    p, _ = pattern(fm.craig_bampton(beam_model(), n_modes=30))
    assert p.banded and p.kl == 0 and p.rows.size == 30
    for dim in (2, 3):
        p, ratio = pattern(solid_model(dim))
        assert not p.banded and ratio > 8


@pytest.mark.parametrize("dim", [2, 3])
def test_superlu_interior_of_solids_matches_band_and_assembled(dim):
    """The SuperLU interior (minimum degree on Z + Z^T, diagonal pivots preferred) solves the Newton
    system of a meshed solid to round-off, at a frequency whose harmonic blocks are indefinite (kw
    between eigenfrequencies), and agrees with the band LU and with SuperLU on the assembled J."""
    model, h, w = solid_model(dim), fm.Harmonics(4), 2.3
    lam = np.sort(fm.linear_modes(model, 8).omega)
    assert any(lam[0] < k * w < lam[-1] for k in range(1, 5))  # indefinite blocks
    out = []
    for band in (False, True):
        # any band is narrow enough, or none is
        pr = forced(model, h, structured(options=dict(band_max_fill=np.inf if band else 0.0)))
        x = state(pr, 1, 1e-3)
        _, J, _ = pr.residual(x, w)
        assert isinstance(J, HarmonicBlockJacobian)
        assert pr.system.linear.block_pattern().banded == band
        b = np.random.default_rng(2).standard_normal(pr.size)
        out.append(J.factorize().solve(b))
        assert backward_error(J, out[-1], b) < 1e-13
    Jg = J.tocsr()
    xg = spla.splu(Jg.tocsc()).solve(b)
    tol = forward_tol(Jg)
    for xs in out:
        assert np.max(np.abs(xs - xg)) <= tol * np.max(np.abs(xg))
    assert np.max(np.abs(out[0] - out[1])) <= tol * np.max(np.abs(xg))


def test_reduced_model_uses_structure():
    model = beam_model()
    rom = fm.craig_bampton(model, n_modes=8)
    pr = forced(rom, fm.Harmonics(6))
    _, J, _ = pr.residual(state(pr, 1, 1e-3), 2.0)
    b = np.random.default_rng(12).standard_normal(pr.size)
    xs = J.factorize().solve(b)
    assert backward_error(J, xs, b) < 1e-13


def test_continuation_structured_equals_assembled():
    """The whole forced-response branch is the same with either linear algebra."""
    model = bar_model(n_el=40, n_contacts=2).with_damping(alpha=0.1)
    h = fm.Harmonics(5)
    opts = fm.ContinuationOptions(step=0.05, max_step=0.2, max_points=40,
                                  newton=fm.NewtonOptions(atol=1e-10, max_iter=20))
    out = []
    for solver in (structured(), AssembledSolver()):
        pr = ForcedResponseProblem(model, h, solver=solver)
        out.append(fm.continuation(pr, (1.0, 2.5), options=opts))
    a, b = out
    assert a.n_points == b.n_points >= 10
    np.testing.assert_allclose(a.p, b.p, rtol=1e-9)
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9 * np.abs(b.x).max())


# --------------------------------------------------------------------------------------------
# reuse of the per-harmonic factors of a nearby frequency (BlockSolver(reuse=True))
# --------------------------------------------------------------------------------------------
def _reused_pair(model, h, w0, w, solver, seed=1, amp=1e-3, bordered=True, x=None):
    """The Jacobian at ``w`` (bordered like a corrector's) at the state ``x`` (default random),
    factorised by ``solver`` after it factorised the one at ``w0``: returns (J, its
    factorisation, the assembled J)."""
    pr = ForcedResponseProblem(model, h, solver=solver)
    pg = ForcedResponseProblem(model, h, solver=AssembledSolver())
    x = state(pr, seed, amp) if x is None else x
    _, J0, _ = pr.residual(x, w0)
    J0.factorize()                                   # the base factors at w0
    _, J, rp = pr.residual(x, w)
    _, Jg, rpg = pg.residual(x, w)
    if bordered:
        c = np.random.default_rng(seed + 1).standard_normal(pr.size + 1)
        J, Jg = bordered_matrix(J, rp, c), bordered_matrix(Jg, rpg, c)
    return J, J.factorize(), Jg


@pytest.mark.parametrize("dw", [1e-7, 1e-5, 1e-3])
@pytest.mark.parametrize("bordered", [False, True])
def test_reused_factors_solve_like_a_fresh_factorisation(dw, bordered):
    """Solves with the factors of w0 (refined against J(w)) agree with SuperLU on J(w) within
    the forward error its conditioning allows, at the backward error of a fresh factorisation."""
    model, h = CASES["bar"]()
    solver = structured(reuse=True, max_passes=60)  # no cost budget: the refinement itself is tested
    J, fac, Jg = _reused_pair(model, h, 1.3, 1.3 * (1 + dw), solver, bordered=bordered)
    assert not fac.exact and fac.F.omega == 1.3
    b = np.random.default_rng(2).standard_normal(J.shape[0])
    xs = fac.solve(b)
    assert solver.stats["refactorized"] == 0 and solver.stats["passes"] >= 2
    xg = spla.splu(Jg.tocsc()).solve(b)
    assert backward_error(J, xs, b) < 1e-13
    assert np.max(np.abs(xs - xg)) <= forward_tol(Jg) * np.max(np.abs(xg))
    # the fresh factorisation at w agrees with it to the same tolerance
    xf = structured(reuse=False).factorize(J).solve(b)
    assert np.max(np.abs(xs - xf)) <= forward_tol(Jg) * np.max(np.abs(xg))


def test_reuse_refactorises_across_an_interior_eigenfrequency(caplog):
    """The tip stop closed all period holds the tip: the interior is a fixed-fixed bar and the
    Jacobian is that of the held bar. From w0 just below its first eigenfrequency to w just
    above, P(w0)^-1 J(w) is far from the identity: the refinement cannot contract (q >= 1/2), the
    safeguard factorises at w, and the solution is the exact one."""
    mesh = fm.line_mesh(length=1.0, n_elements=200, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_damping(alpha=1e-3)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=1.0))
             .with_contact(fm.UnilateralContact(at="tip", gap=1e-3)))
    h = fm.Harmonics(3)
    pat = forced(model, h).system.linear.block_pattern()
    M, K = model.M.tocsr(), model.K.tocsr()
    I = pat.interior
    lam1 = sla.eigh(K[I][:, I].toarray(), M[I][:, I].toarray(), eigvals_only=True, subset_by_index=[0, 0])[0]
    w1 = np.sqrt(lam1)                               # first interior eigenfrequency (~ pi)
    s = forced(model, h).system
    P = np.zeros((s.h.n_coef, 1))
    P[0] = 10.0                                      # contact force > 0 all period: stop closed
    x = s.join(np.zeros((s.h.n_coef, s.n)), P)
    solver = structured(reuse=True, max_passes=60)  # no cost budget: only the contraction decides
    J, fac, Jg = _reused_pair(model, h, w1 * (1 - 2e-3), w1 * (1 + 2e-3), solver, x=x)
    assert not fac.exact
    b = np.random.default_rng(3).standard_normal(J.shape[0])
    with caplog.at_level("DEBUG", logger="femodes.hbm.linsolve"):
        xs = fac.solve(b)
    assert solver.stats["refactorized"] == 1 and solver.stats["passes"] <= 3
    assert "refactorising" in caplog.text
    assert fac.refactored is not None and fac.refactored.exact
    xg = spla.splu(Jg.tocsc()).solve(b)
    assert backward_error(J, xs, b) < 1e-13
    assert np.max(np.abs(xs - xg)) <= forward_tol(Jg) * np.max(np.abs(xg))
    # the factors at w are the new base: a Jacobian at w is factorised exactly, without a pass
    assert J.factorize().exact and solver.stats["factorizations"] == 2


def test_reuse_switch_and_options():
    model, h = CASES["bar"]()
    solver = BlockSolver(reuse=False)
    J, fac, _ = _reused_pair(model, h, 1.3, 1.3 * (1 + 1e-6), solver)
    assert fac.exact and fac.F.omega == J.omega and solver.stats["reused"] == 0
    assert solver.stats["factorizations"] == 2
    assert repr(BlockSolver()) == "BlockSolver()" and repr(BlockSolver(reuse=True)) == "BlockSolver(reuse=True)"
    assert repr(solver) == "BlockSolver(reuse=False)"
    assert repr(BlockSolver(options=BlockSolverOptions(dense_max_size=10))) == (
        f"BlockSolver(options={BlockSolverOptions(dense_max_size=10)!r})")
    # "auto": not on band blocks (measured slower on the bars of benchmarks/README_corrector.md)
    assert BlockSolver().reuse == "auto" and not BlockSolver().reuses(J)
    with pytest.raises(TypeError, match="'auto'"):
        BlockSolver(reuse="yes")
    # beyond the window: factorised afresh
    solver = BlockSolver(reuse=True, reuse_window=1e-3)
    _, fac, _ = _reused_pair(model, h, 1.3, 1.3 * (1 + 2e-3), solver)
    assert fac.exact
    with pytest.raises(TypeError):
        BlockSolver(reuse=1)
    with pytest.raises(ValueError):
        BlockSolver(reuse_window=-0.1)
    with pytest.raises(ValueError):
        BlockSolver(max_passes=0)
    with pytest.raises(TypeError):
        BlockSolver(options=dict(dense_max_size=10))
    with pytest.raises(ValueError, match="dense_fill must be a non-negative number, got -0.1"):
        BlockSolverOptions(dense_fill=-0.1)
    with pytest.raises(TypeError, match="superlu_symmetric_mode must be True or False"):
        BlockSolverOptions(superlu_symmetric_mode=1)
    assert BlockSolverOptions().superlu_options == dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1,
                                                        options=dict(SymmetricMode=True))


def test_kept_condensation_columns_change_nothing_but_round_off():
    """W = Z_II^-1 Z_Ib kept (back substitution by products) or not (a second band solve)."""
    model, h = CASES["bar"]()
    out = []
    for keep in (True, False):
        pr = forced(model, h, structured(reuse=False, options={} if keep else dict(keep_w_max_bytes=0)))
        _, J, rp = pr.residual(state(pr, 1, 1e-3), 1.3)
        Jb = bordered_matrix(J, rp, np.random.default_rng(4).standard_normal(pr.size + 1))
        fac = Jb.factorize()
        assert (fac.F.blocks[1].W is not None) == keep
        b = np.random.default_rng(5).standard_normal(pr.size + 1)
        out.append(fac.solve(b))
        assert backward_error(Jb, out[-1], b) < 1e-13
    Jg = ForcedResponseProblem(model, h, solver=AssembledSolver())
    tol = forward_tol(bordered_matrix(Jg.residual(state(pr, 1, 1e-3), 1.3)[1], rp,
                                      np.random.default_rng(4).standard_normal(pr.size + 1)))
    assert np.max(np.abs(out[0] - out[1])) <= tol * np.max(np.abs(out[1]))


def test_continuation_same_branch_with_and_without_reuse():
    """A forced-response branch of a 500-DOF bar with two stops: the same points (to the Newton
    tolerance) whether the corrector reuses factors or factorises at every iteration, and the
    reuse did serve some solves (a generous pass budget, so that it is tried on most of them)."""
    model = bar_model(n_el=500, n_contacts=2).with_damping(alpha=0.1)
    h = fm.Harmonics(5)
    opts = fm.ContinuationOptions(step=0.05, max_step=0.2, max_points=30,
                                  newton=fm.NewtonOptions(atol=1e-10, max_iter=20))
    out, solvers = [], []
    for reuse in (False, True):
        solver = structured(reuse=reuse, max_passes=8)
        out.append(fm.continuation(ForcedResponseProblem(model, h, solver=solver), (1.0, 2.5), options=opts))
        solvers.append(solver)
    a, b = out
    assert a.n_points == b.n_points >= 10 and a.n_newton == b.n_newton
    np.testing.assert_allclose(b.p, a.p, rtol=1e-9)
    np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-9 * np.abs(a.x).max())
    st = solvers[1].stats
    assert solvers[0].stats["reused"] == 0
    assert st["solves_reused"] - st["refactorized"] > 0
    assert st["factorizations"] < solvers[0].stats["factorizations"]


def test_block_solver_factorises_half_full_systems_densely(monkeypatch):
    """Above dense_max_size, a system whose nonlinear block fills at least dense_fill of the
    matrix (a 1-DOF contact at H = 80: two dense 161 x 161 blocks in 322 unknowns) is factorised
    by LAPACK, a sparse one of similar size (20-DOF cantilever, one contact, H = 10: 441
    unknowns) by SuperLU; both solve as the assembled matrix does (to 1e-10 relative: the
    systems' condition numbers are below 1e5)."""
    defaults = BlockSolverOptions()
    one = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
           .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    mesh = fm.line_mesh(length=1.0, n_elements=10, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = (fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
            .with_contact(fm.UnilateralContact(at="tip", gap=0.01)).with_damping(alpha=0.01)
            .with_forcing(fm.HarmonicForce(at="tip", amplitude=1.0)))
    rng = np.random.default_rng(2)
    for model, H, kind in ((one, 80, DenseFactorization), (beam, 10, AssembledFactorization)):
        prob = ForcedResponseProblem(model, fm.Harmonics(H))  # the default solver and options
        x = 0.3 * rng.standard_normal(prob.size)
        J = prob.residual(x, 1.1)[1]
        n = J.shape[0]
        assert n > defaults.dense_max_size
        assert (J.N.nnz >= defaults.dense_fill * n * n) == (kind is DenseFactorization)
        F = BlockSolver().factorize(J)
        assert type(F) is kind
        if kind is DenseFactorization:  # assembled from the cached dense operators (no CSR matrix), entry for entry
            Jb = J.bordered(np.ones((n, 1)), np.ones((1, n)), np.array([[2.0]]))
            sparse = [A.tocsr().toarray() for A in (J, 2.5 * J, Jb)]
            with monkeypatch.context() as m:
                m.setattr(HarmonicBlockJacobian, "tocsr", lambda self: pytest.fail("toarray built a CSR matrix"))
                for A, S in zip((J, 2.5 * J, Jb), sparse):
                    np.testing.assert_array_equal(A.toarray(), S)
        b = rng.standard_normal(n)
        y = F.solve(b)
        np.testing.assert_allclose(y, AssembledSolver().factorize(J).solve(b), rtol=0, atol=1e-10 * np.abs(y).max())


def _one_dof(damping=0.1, cubic=False):
    m = fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[damping]] if damping else None)
    m = m.with_contact(fm.UnilateralContact(at=0, gap=1.0)).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
    return m.with_nonlinearity(fm.CubicSpring(at=0, k3=0.5)) if cubic else m


def test_dense_solve_eliminates_displacements_first():
    """Half-full systems without displacement-displacement nonlinear terms (complementarity
    contacts only) eliminate the displacements harmonic by harmonic and factorise the Schur
    complement on the contact forces (half the size for a 1-DOF contact): the same solution as
    the LU of the whole matrix, to the backward-error test of the structured solver (64 eps
    ||J|| |x|); several right-hand sides, a border, EPMC's xi."""
    rng = np.random.default_rng(5)
    # the defaults: a 1-DOF contact at H = 120 (483 unknowns) goes to LAPACK with the elimination
    prob = ForcedResponseProblem(_one_dof(), fm.Harmonics(120))
    F = BlockSolver().factorize(prob.residual(0.3 * rng.standard_normal(prob.size), 1.1)[1])
    assert type(F) is DenseFactorization and F.schur is not None
    always = BlockSolverOptions(schur_min_size=0)  # down to the small systems of the test
    for H, xi in ((80, 0.0), (40, 0.03)):
        prob = ForcedResponseProblem(_one_dof(), fm.Harmonics(H))
        x = 0.3 * rng.standard_normal(prob.size)
        J = prob.residual(x, 1.1)[1]
        if xi:
            J = HarmonicBlockJacobian(J.system, J.omega, xi, J.N, scale=J.scale)
        n = J.shape[0]
        Jb = J.bordered(rng.standard_normal((n, 1)), rng.standard_normal((1, n)), np.array([[2.0]]))
        F = DenseFactorization(Jb, always)
        assert isinstance(F.schur, ForceSchur) and F.lu is None
        assert F.schur.lu[0].shape[0] == prob.system.np + 1  # forces and the border only
        A = Jb.toarray()
        B = rng.standard_normal((n + 1, 3))
        X = F.solve(B)
        assert F.schur is not None  # no fallback was needed
        res = np.abs(A @ X - B).max(axis=0)
        assert np.all(res <= 64 * np.finfo(float).eps * (np.abs(A).sum(axis=1).max() * np.abs(X).max(axis=0)
                                                         + np.abs(B).max(axis=0)))
        np.testing.assert_allclose(X, sla.lu_solve(sla.lu_factor(A), B), rtol=0,
                                   atol=1e-9 * np.abs(X).max())  # cond(A) < 1e5 here
        np.testing.assert_allclose(F.solve(B[:, 0]), X[:, 0], rtol=0, atol=1e-12 * np.abs(X).max())


def test_dense_solve_keeps_the_whole_lu_where_elimination_does_not_apply(monkeypatch):
    """A cubic spring couples the displacements (no elimination); a harmonic block at or next to
    an undamped resonance (k w = 1) is singular or makes the Schur complement grow (no
    elimination: the whole matrix is pivoted); an inaccurate solve falls back to the LU of the
    whole matrix."""
    always = BlockSolverOptions(schur_min_size=0)
    rng = np.random.default_rng(6)
    prob = ForcedResponseProblem(_one_dof(cubic=True), fm.Harmonics(40))
    J = prob.residual(0.3 * rng.standard_normal(prob.size), 1.1)[1]
    F = DenseFactorization(J, always)
    assert F.schur is None and F.lu is not None
    undamped = ForcedResponseProblem(_one_dof(damping=0.0), fm.Harmonics(40))
    x = 0.3 * rng.standard_normal(undamped.size)
    for w, blocked in ((1.0, True), (1.0 + 1e-10, True), (0.5 + 0.1234, False)):
        J = undamped.residual(x, w)[1]
        assert (DenseFactorization(J, always).schur is None) == blocked
    # a solve that the refinement cannot make accurate (here: an elimination that returns
    # zeros) is redone by the LU of the whole matrix, which is kept from then on
    J = undamped.residual(x, 0.5 + 0.1234)[1]
    F = DenseFactorization(J, always)
    assert F.schur is not None
    monkeypatch.setattr(ForceSchur, "_solve", lambda self, B: np.zeros_like(B))
    b = rng.standard_normal(J.shape[0])
    y = F.solve(b)
    A = J.toarray()
    assert F.schur is None and F.lu is not None
    assert np.abs(A @ y - b).max() <= 64 * np.finfo(float).eps * (np.abs(A).sum(axis=1).max() * np.abs(y).max()
                                                                  + np.abs(b).max())


def test_module_constants_are_deprecated_names_of_the_options():
    """femodes 0.1's module constants read the defaults of BlockSolverOptions, with a warning; the
    former BlockLU signature (a = f^2, b = f) gives the same factorisation, with a warning."""
    import femodes.hbm.linsolve as ls

    defaults = BlockSolverOptions()
    for name, option in ls._DEPRECATED_CONSTANTS.items():
        with pytest.warns(DeprecationWarning, match=f"linsolve.{name} is deprecated"):
            assert getattr(ls, name) == getattr(defaults, option)
    assert len(ls._DEPRECATED_CONSTANTS) == 15
    model, h = CASES["beam-mixed-laws"]()
    pat = forced(model, h).system.linear.block_pattern()
    R = np.random.default_rng(7).standard_normal((pat.perm.size, 2)) + 0j
    with pytest.warns(DeprecationWarning, match="BlockLU"):
        old = ls.BlockLU(pat, 1.5 ** 2, 1.5, 0.02)
    np.testing.assert_array_equal(old.solve(R), ls.BlockLU(pat, 1.5, 0.02).solve(R))


def test_block_solver_path_by_size_mesh_and_damping():
    """The structured factorisation from ``structured_min_size`` (500) unknowns on 2-D/3-D meshes and
    with modal damping; without modal damping, bars and beams (band width at most
    ``narrow_band_kl``) and models whose DOFs are mostly nonlinear (a reduced model with many
    contacts: its structured path is a large dense Schur complement) keep SuperLU's assembled LU up
    to ``structured_min_size_narrow`` (2000), where it stays ahead (benchmarks/README_solver_paths.md:
    40-point frequency responses, a 3-D box 0.37 s instead of 0.79, a modally damped beam 0.73
    instead of 1.96; the user's blade reduced to 37 DOFs with 27 contacts took 2.1 s structured
    against 0.88 s). Each path solves to round-off (backward error below 1e-13, as the other tests of
    this module)."""
    o = BlockSolverOptions()
    assert (o.structured_min_size, o.structured_min_size_narrow, o.narrow_band_kl, o.narrow_boundary_share) == (
        500, 2000, 3, 0.25)
    mesh = fm.line_mesh(1.0, 20, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = (fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
            .with_contact(fm.UnilateralContact(at="tip", gap=0.01)).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.01)))
    box = (fm.solid(fm.box_mesh(1.0, 0.1, 0.1, 4, 1, 1, hexahedra=True), fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left")
           .with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0, 0.0)))
           .with_forcing(fm.HarmonicForce(at=("right", "u_y"), amplitude=0.01)).with_damping(beta=1e-3))
    rng = np.random.default_rng(5)
    A = rng.standard_normal((12, 12))
    dense = (fm.StructuralModel(M=np.eye(12), K=A @ A.T + 12.0 * np.eye(12), C=0.01 * np.eye(12))  # a reduced model's blocks
             .with_contact(*[fm.UnilateralContact(at=k, gap=0.1) for k in range(6)])
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.01)))
    for model, H, kind in ((beam.with_damping(beta=1e-3), 10, AssembledFactorization),
                           (beam.with_damping(modal=0.01), 10, StructuredFactorization),
                           (box, 5, StructuredFactorization),
                           (dense, 30, AssembledFactorization)):
        prob = ForcedResponseProblem(model, fm.Harmonics(H))
        J = prob.residual(1e-3 * rng.standard_normal(prob.size), 1.3)[1]
        assert o.structured_min_size <= J.shape[0] < o.structured_min_size_narrow
        F = BlockSolver().factorize(J)
        assert type(F) is kind
        b = rng.standard_normal(J.shape[0])
        assert backward_error(J, F.solve(b), b) < 1e-13
