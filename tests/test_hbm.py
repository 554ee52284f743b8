"""Tests of the harmonic balance layer: HBMSystem, the HBM problems and the analyses.

References are independent of the code under test: finite differences for every analytic
derivative, the exact elliptic-function frequency of the free Duffing oscillator, the
closed-form frequency of an impacting oscillator, single-harmonic balance in closed form,
shooting-confirmed fold/peak values of the forced Duffing oscillator (H = 21, see the
values below), the linear response, and hand-solved static contact problems (LCPs).

Conventions: ``M q'' + C q' + K q + f_nl(q) = f cos(w t) - p`` at a contact DOF, gap
``g_N = gap - q >= 0``, contact force ``p >= 0``.

Expensive branches are computed once per session through ``functools.lru_cache``; a branch
is never mutated by a test.
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import minimize_scalar
from scipy.special import ellipk

import femodes as fm
from femodes.hbm.system import HBMSystem, default_contact_parameter
from femodes.solvers import ContinuationOptions, NewtonOptions, semismooth_newton


# ============================================================================ models
def duffing(eps=1.0):
    """Free undamped Duffing oscillator u'' + u + eps u^3 = 0."""
    return fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_nonlinearity(fm.CubicSpring(at=0, k3=eps))


def forced_duffing(c=0.1, eps=1.0, F=1.0):
    return (
        fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[c]])
        .with_nonlinearity(fm.CubicSpring(at=0, k3=eps))
        .with_forcing(fm.HarmonicForce(at=0, amplitude=F))
    )


def oscillator(c=0.1, F=0.2):
    return fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[c]]).with_forcing(fm.HarmonicForce(at=0, amplitude=F))


def contact_case(n, c=None):
    """Case 1: c = 0.1, gap 1, F = 0.2; case 2: c = 0.2, gap 2.5, F = 1 (both M = K = 1)."""
    damp, gap, F = {1: (0.1, 1.0, 0.2), 2: (0.2, 2.5, 1.0)}[n]
    return oscillator(damp, F).with_contact(fm.UnilateralContact(at=0, gap=gap, c=c))


def penalty_case1(stiffness):
    return oscillator(0.1, 0.2).with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=stiffness))


def chain4():
    """4-DOF damped chain with a non-diagonal M and non-proportional C, and all four laws:
    cubic spring (DOF 0), penalty contact (DOF 1), two complementarity contacts (DOFs 2, 3; one
    with an explicit c, one with the default), forcing on DOF 3."""
    K = np.array([[2.0, -1, 0, 0], [-1, 2, -1, 0], [0, -1, 2, -1], [0, 0, -1, 1.5]])
    M = np.array([[2.0, 0.5, 0, 0], [0.5, 1.5, 0.2, 0], [0, 0.2, 1.0, 0.1], [0, 0, 0.1, 1.2]])
    C = 0.03 * K + 0.02 * M + np.diag([0.05, 0, 0, 0.02])
    return (
        fm.StructuralModel(M=M, K=K, C=C)
        .with_nonlinearity(fm.CubicSpring(at=0, k3=0.7))
        .with_contact(
            fm.PenaltyContact(at=1, gap=0.3, stiffness=5.0),
            fm.UnilateralContact(at=2, gap=0.2, c=3.0),
            fm.UnilateralContact(at=3, gap=0.1),
        )
        .with_forcing(fm.HarmonicForce(at=3, amplitude=1.0, phase=0.3))
    )


def elliptic_duffing_omega(A, eps=1.0):
    """Exact frequency of u'' + u + eps u^3 = 0 with amplitude A (u(0) = A, u'(0) = 0)."""
    A = np.asarray(A, dtype=float)
    m = eps * A**2 / (2.0 * (1.0 + eps * A**2))
    return np.pi * np.sqrt(1.0 + eps * A**2) / (2.0 * ellipk(m))


def impact_omega(E, gap=1.0):
    """Exact frequency of u'' + u = -p with a rigid stop at u = gap, restitution 1, energy E."""
    A = np.sqrt(2.0 * np.asarray(E, dtype=float))
    return np.where(A > gap, np.pi / (np.pi - np.arccos(np.minimum(gap / A, 1.0))), 1.0)


def fd_jacobian(fun, x, h=1e-6):
    """Central-difference Jacobian of a vector function."""
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h
        cols.append((fun(x + e) - fun(x - e)) / (2.0 * h))
    return np.column_stack(cols)


def true_max_abs(h, Q):
    """max_t |u(t)| of one signal, to ~1e-12 relative: fine grid, then Brent polish."""
    th = 2.0 * np.pi * np.arange(4096) / 4096
    u = h.grid.synthesis(th) @ Q
    k = int(np.argmax(np.abs(u)))
    sg = np.sign(u[k])
    d = 2.0 * np.pi / 4096
    r = minimize_scalar(lambda t: -sg * (h.grid.synthesis(np.array([t])) @ Q)[0],
                        bracket=(th[k] - d, th[k], th[k] + d), tol=1e-12)
    return max(-r.fun, abs(u[k]))


def crossings(omega, w0):
    """Indices i with omega[i], omega[i+1] on opposite sides of w0."""
    s = np.sign(omega - w0)
    return np.nonzero(s[:-1] * s[1:] < 0)[0]


# ===================================================================== cached runs
@functools.cache
def contact_branch(n, n_time=None, exact=True):
    h = fm.Harmonics(20) if n_time is None else fm.Harmonics(20, n_time=n_time)
    return fm.frequency_response(contact_case(n), (0.5, 2.0), h,
                                 projection=fm.hbm.ExactProjection() if exact else fm.hbm.SampledProjection())


# Newton tolerance of nonlinear_mode's corrector (femodes.analyses.nonlinear_mode_options): every
# point has |r|_inf <= MODE_ATOL; r contains log10(E) - p unscaled, so a branch ends at
# E = E1 (1 +- ln(10) MODE_ATOL), and the dynamic equations divided by k_phi a_ref,
# a_ref = sqrt(2 sqrt(E0 E1)) / w0 (NonlinearModeProblem reference_energy).
MODE_ATOL = 1e-9
EPS = np.finfo(float).eps


@functools.cache
def duffing_backbone(H):
    # energy 200 reaches A = 5 for every H >= 1 (A^2/2 + A^4/4 = 168.75 at A = 5)
    return fm.nonlinear_mode(duffing(), 1, energy=(1e-3, 200.0), harmonics=fm.Harmonics(H))


@functools.cache
def forced_branch(c, eps, H, max_step=None, span=(0.5, 4.0)):
    opts = None
    if max_step is not None:
        opts = ContinuationOptions(step=max_step, max_step=max_step, newton=NewtonOptions(atol=1e-11, max_iter=20))
    return fm.frequency_response(forced_duffing(c, eps), span, fm.Harmonics(H), options=opts)


@functools.cache
def case1_at_105(law, param):
    """Case 1 at w = 1.05 (below the lower fold 1.081, so the solution there is unique on the
    branch) for complementarity parameter c or penalty stiffness; traced from w = 0.9 (linear
    amplitude 0.95 < gap: the start has no contact). Returns the displacement coefficients."""
    model = contact_case(1, c=param) if law == "c" else penalty_case1(param)
    br = fm.frequency_response(model, (0.9, 1.05), fm.Harmonics(20))
    assert br.success and br.omega[-1] == 1.05, br.message
    return br.Q[-1][:, 0].copy(), br


# ============================================================ 1. analytic derivatives
@pytest.mark.parametrize("harmonics", [fm.Harmonics(4), fm.Harmonics(3, subharmonic=2)], ids=["H4", "H3-sub2"])
@pytest.mark.parametrize("exact", [True, False], ids=["exact", "sampled"])
def test_system_jacobian_matches_central_differences(harmonics, exact):
    model = chain4()
    s = HBMSystem(model, harmonics, projection=fm.hbm.ExactProjection() if exact else fm.hbm.SampledProjection())
    rng = np.random.default_rng(7)
    x = 0.4 * rng.standard_normal(s.size)
    Q, P = s.split(x)
    # Guard: the point must exercise partially active contacts (phi changes sign), otherwise
    # G is 0 or I and the test would not see the projection.
    h = s.h
    phis = [Q[:, 1] - 0.3 * np.eye(h.n_coef)[0]]  # penalty: q - gap
    for ct in s.unilateral:  # complementarity: P + c (q - gap)
        phis.append(P[:, ct.slot] + ct.c * Q[:, ct.dof] - ct.c * ct.law.gap * np.eye(h.n_coef)[0])
    for phi in phis:
        frac = sum(e - b for b, e in h.galerkin.positive_intervals(phi)) / (2 * np.pi)
        assert 0.05 < frac < 0.95, frac
        if not exact:
            # sampled law is piecewise linear: no grid sample may cross zero within the FD step
            assert np.min(np.abs(h.grid.synthesis() @ phi)) > 1e-4
    w, xi = 1.3, 0.07
    r, J, dr_dw, dr_dxi = s.residual(x, w, xi=xi)
    assert J.shape == (s.size, s.size) and sp.issparse(J.tocsr())
    Jfd = fd_jacobian(lambda y: s.residual(y, w, xi=xi)[0], x)
    # central differences: truncation O(h^2 r''') and rounding eps |r| / h ~ 1e-9 absolute;
    # 1e-6 relative to max|J| (~1e2) leaves two orders of margin (measured ~5e-11 relative).
    scale = np.abs(Jfd).max()
    np.testing.assert_allclose(J.toarray(), Jfd, rtol=0, atol=1e-6 * scale)
    e = 1e-6
    fd_w = (s.residual(x, w + e, xi=xi)[0] - s.residual(x, w - e, xi=xi)[0]) / (2 * e)
    fd_xi = (s.residual(x, w, xi=xi + e)[0] - s.residual(x, w, xi=xi - e)[0]) / (2 * e)
    np.testing.assert_allclose(dr_dw, fd_w, rtol=0, atol=1e-6 * np.abs(fd_w).max())
    np.testing.assert_allclose(dr_dxi, fd_xi, rtol=0, atol=1e-6 * np.abs(fd_xi).max())
    # the unforced residual differs exactly by the force vector
    r0 = s.residual(x, w, xi=xi, forced=False)[0]
    np.testing.assert_allclose(r - r0, -np.r_[s.linear.force(), np.zeros(s.np)], atol=1e-14)


def test_small_systems_take_the_dense_linear_residual(monkeypatch):
    """Below DENSE_MAX_SIZE unknowns the linear part of the residual and its derivatives come from
    the cached dense operators; they equal the sparse products to rounding (a few eps times the
    largest term; measured 1.4e-14 on terms ~10), with and without artificial damping and
    forcing. The Jacobian itself is checked against differences above on such a system."""
    import femodes.hbm.system as system

    s = HBMSystem(chain4(), fm.Harmonics(5))
    assert s.nq <= system.DENSE_MAX_SIZE
    x = np.random.default_rng(3).standard_normal(s.size)
    Q = x[: s.nq].reshape(s.h.n_coef, s.n)
    for xi in (0.0, 0.3):
        for forced in (True, False):
            dense = s._linear_residual(Q, 1.3, xi, forced)
            with monkeypatch.context() as mp:
                mp.setattr(system, "DENSE_MAX_SIZE", 0)
                sparse = s._linear_residual(Q, 1.3, xi, forced)
            for a, b in zip(dense, sparse):
                np.testing.assert_allclose(a, b, rtol=0, atol=64 * np.finfo(float).eps * np.abs(b).max())


def test_nonlinear_part_reuses_its_sparse_pattern():
    """The nonlinear Jacobian's CSR pattern is built once per system and refilled: the same matrix
    as a fresh COO conversion at two different points, and a new pattern when the triplets
    change (duplicates summed either way)."""
    from femodes.hbm.nonlinear_forces import Triplets

    s = HBMSystem(chain4(), fm.Harmonics(4))
    rng = np.random.default_rng(5)
    for _ in range(2):
        x = 0.4 * rng.standard_normal(s.size)
        N = s.residual(x, 1.3)[1].N
        assert "triplets" in s._cache
        jac = Triplets()
        Q = x[: s.nq].reshape(s.h.n_coef, s.n)
        r = np.zeros(s.size)
        s.nonlinear.cubic_springs(Q, r, jac)
        s.nonlinear.penalty_contacts(Q, r, jac)
        s.nonlinear.complementarity_contacts(x, Q, r, jac)
        ref = jac.matrix(s.size)
        assert (N != ref).nnz == 0 and N.has_sorted_indices
    cache: dict = {}
    a, b = Triplets(), Triplets()
    a.entries(np.array([0, 1, 0]), np.array([1, 1, 1]), np.array([1.0, 2.0, 3.0]))
    b.entries(np.array([2, 2]), np.array([0, 0]), np.array([1.0, 5.0]))
    np.testing.assert_array_equal(a.matrix(3, cache).toarray(), [[0, 4, 0], [0, 2, 0], [0, 0, 0]])
    np.testing.assert_array_equal(b.matrix(3, cache).toarray(), [[0, 0, 0], [0, 0, 0], [6, 0, 0]])
    np.testing.assert_array_equal(a.matrix(3, cache).toarray(), [[0, 4, 0], [0, 2, 0], [0, 0, 0]])


def test_energy_gradient_matches_central_differences():
    model = chain4()
    s = HBMSystem(model, fm.Harmonics(4))
    x = 0.4 * np.random.default_rng(3).standard_normal(s.size)
    w = 1.1
    E, grad, dE_dw = s.energy(x, w)
    gfd = fd_jacobian(lambda y: np.array([s.energy(y, w)[0]]), x)[0]
    np.testing.assert_allclose(grad, gfd, rtol=0, atol=1e-7 * np.abs(gfd).max())
    e = 1e-6
    np.testing.assert_allclose(dE_dw, (s.energy(x, w + e)[0] - s.energy(x, w - e)[0]) / (2 * e), rtol=1e-7)
    # complementarity contacts store no energy: P does not enter
    assert np.all(grad[s.nq:] == 0.0)


def test_energy_of_linear_mode_guess_is_exact():
    """Period-averaged energy of a*phi*cos(w0 t) at w0 is a^2 w0^2 / 2 = E (mass-normalised phi)."""
    K = np.array([[2.0, -1], [-1, 1]])
    model = fm.StructuralModel(M=np.eye(2), K=K).with_contact(fm.UnilateralContact(at=1, gap=10.0))
    pr = fm.NonlinearModeProblem(model, fm.Harmonics(5), mode=2)
    x = pr.linear_guess(0.37)
    s = pr.system
    assert s.energy(x[: s.size], x[s.size])[0] == pytest.approx(0.37, rel=1e-13)
    assert x[s.size] == pytest.approx(np.sqrt((3 + np.sqrt(5)) / 2), rel=1e-12)  # mode 2 of the chain
    r = pr.residual(x, math.log10(0.37))[0]
    assert np.abs(r).max() < 1e-12  # below grazing the linear mode solves the EPMC system


@pytest.mark.parametrize("kind", ["nonlinear_mode", "forced"])
def test_problem_jacobians_match_central_differences(kind):
    model = chain4()
    h = fm.Harmonics(4)
    rng = np.random.default_rng(11)
    if kind == "nonlinear_mode":
        pr = fm.NonlinearModeProblem(model, h, mode=2)
        x = 0.4 * rng.standard_normal(pr.size)
        x[-2], x[-1] = 1.2, 0.05  # omega, xi
        p = 0.3
    else:
        pr = fm.ForcedResponseProblem(model, h)
        x = 0.4 * rng.standard_normal(pr.size)
        p = 1.3
    r, J, dr_dp = pr.residual(x, p)
    assert J.shape == (pr.size, pr.size)
    Jfd = fd_jacobian(lambda y: pr.residual(y, p)[0], x)
    J = J.toarray() if hasattr(J, "toarray") else np.asarray(J)
    np.testing.assert_allclose(J, Jfd, rtol=0, atol=1e-6 * np.abs(Jfd).max())  # measured 1e-10 rel.
    e = 1e-6
    fd_p = (pr.residual(x, p + e)[0] - pr.residual(x, p - e)[0]) / (2 * e)
    np.testing.assert_allclose(dr_dp, fd_p, rtol=0, atol=1e-7 * max(np.abs(fd_p).max(), 1.0))
    if kind == "nonlinear_mode":
        assert np.array_equal(dr_dp, np.r_[np.zeros(pr.size - 1), -1.0])


def test_generalized_jacobian_at_the_contact_kink_is_the_separation_side():
    """At phi = P + c (Q - g) == 0 (static touching, zero force) the projected contact law is not
    differentiable (max(0, .) of the zero polynomial). The generalized Jacobian uses
    d max(0, s)/ds = 0 at s = 0, i.e. it is the one-sided derivative from the separating side:
    forward differences towards separation match it exactly (the law is piecewise linear along a
    ray), towards penetration they differ by exactly -c on the complementarity row."""
    model = contact_case(1, c=2.0)
    s = HBMSystem(model, fm.Harmonics(3))
    Q = np.zeros((s.h.n_coef, 1))
    Q[0, 0] = 1.0  # at the gap, P = 0
    x = s.join(Q, np.zeros((s.h.n_coef, 1)))
    w = 0.8
    r, J, _, _ = s.residual(x, w)
    J = J.toarray()
    i_q0, i_p0 = s.q_index(0)[0], s.p_index(0)[0]
    t = 1e-3  # exact for a piecewise-linear law along a ray (no truncation error)
    for sign in (-1.0, +1.0):
        d = np.zeros(s.size)
        d[i_q0] = sign
        fwd = (s.residual(x + t * d, w)[0] - r) / t
        expected = J @ d
        if sign > 0:  # penetration: max(0, c t) = c t is active
            expected[i_p0] += -2.0 * sign
        np.testing.assert_allclose(fwd, expected, atol=1e-9)
    # direction in P alone: P > 0 activates the law (derivative I - I = 0), J says I
    d = np.zeros(s.size)
    d[i_p0] = 1.0
    fwd = (s.residual(x + t * d, w)[0] - r) / t
    assert fwd[i_p0] == pytest.approx(0.0, abs=1e-9) and J[i_p0, i_p0] == 1.0
    fwd = (s.residual(x - t * d, w)[0] - r) / (-t)
    np.testing.assert_allclose(fwd, J @ d, atol=1e-9)
    # penalty law at q == gap (phi == 0): same convention, J is the separating-side derivative;
    # towards penetration the residual grows by k max(0, q - gap) -> +k on the q0 row
    sp_ = HBMSystem(penalty_case1(5.0), fm.Harmonics(3))
    xp = sp_.join(Q)
    rp, Jp, _, _ = sp_.residual(xp, w)
    Jp = Jp.toarray()
    for sign in (-1.0, +1.0):
        d = np.zeros(sp_.size)
        d[0] = sign
        fwd = (sp_.residual(xp + t * d, w)[0] - rp) / t
        expected = Jp @ d
        if sign > 0:
            expected[0] += 5.0 * sign
        np.testing.assert_allclose(fwd, expected, atol=1e-9)


# ============================================================ 2. free Duffing backbone
def test_elliptic_reference_values():
    np.testing.assert_allclose(
        elliptic_duffing_omega([0.5, 1.0, 2.0, 5.0]),
        [1.089158178779, 1.317776064966, 1.976016364071, 4.357461856523], rtol=0, atol=1e-11)


def _backbone_amplitude(br):
    """A = u(0): the phase condition and the symmetry of the Duffing orbit make every sine
    coefficient vanish, so u is even in t and |u| is maximal at t = 0."""
    h = br.harmonics
    assert np.abs(br.Q[:, h.layout.is_sine, 0]).max() < 1e-12
    A = br.Q[:, ~h.layout.is_sine, 0].sum(axis=1)
    return np.abs(A)


def test_duffing_backbone_single_harmonic_closed_form():
    br = duffing_backbone(1)
    assert br.success and br.energy[-1] == pytest.approx(200.0, rel=math.log(10) * MODE_ATOL)  # end: see MODE_ATOL
    a = np.hypot(br.Q[:, 1, 0], br.Q[:, 2, 0])
    # single-harmonic balance: w^2 = 1 + 3/4 a^2.  The cosine residual is ((1 - w^2) a + 3/4 a^3) / a_ref
    # (k_phi = 1), solved to MODE_ATOL, so |w^2 - 1 - 3/4 a^2| <= MODE_ATOL a_ref / a (+ round-off): a
    # bound from the stopping test (measured up to 0.97 of it), not a margin over one run (was rtol=1e-10)
    a_ref = math.sqrt(2.0 * math.sqrt(1e-3 * 200.0))
    assert np.all(np.abs(br.omega**2 - (1.0 + 0.75 * a**2)) <= MODE_ATOL * a_ref / a + 16 * EPS * br.omega**2)
    # energy of a cos(wt): <KE> = w^2 a^2 / 4, <PE> = a^2 / 4 + 3 a^4 / 32
    np.testing.assert_allclose(br.energy, br.omega**2 * a**2 / 4 + a**2 / 4 + 3 * a**4 / 32, rtol=1e-12)
    assert np.abs(br.xi).max() < 1e-10
    # odd nonlinearity: no mean, up to the rounding of the cubic force's mean (~eps k3 a^3, here k = k3 = 1;
    # measured 4.6e-16 <= 0.01 of this; was 1e-14 < eps a^3 at a = 5)
    assert np.all(np.abs(br.Q[:, 0, 0]) < 8 * EPS * (1.0 + a**3))


def test_duffing_backbone_converges_exponentially_in_H():
    Hs = (1, 3, 5, 7)
    err_at_1 = []
    max_err = {}
    energy_err = {}
    for H in Hs:
        br = duffing_backbone(H)
        assert br.success, br.message
        assert np.abs(br.xi).max() < 1e-10  # conservative system: the EPMC damping vanishes
        A = _backbone_amplitude(br)
        assert A.max() > 4.8  # the branch reaches A ~ 5
        w_ex = elliptic_duffing_omega(A)
        err = np.abs(br.omega - w_ex) / w_ex
        max_err[H] = err.max()
        energy_err[H] = np.abs(br.energy / (A**2 / 2 + A**4 / 4) - 1).max()
        order = np.argsort(A)
        err_at_1.append(float(np.exp(np.interp(0.0, np.log(A[order]), np.log(np.maximum(err[order], 1e-300))))))
        # the frequency increases with energy (hardening)
        assert np.all(np.diff(br.omega) > 0)
    # measured max relative errors over A in [0.045, 5]: 1.98e-2, 1.66e-3, 7.0e-5, 2.8e-6
    bounds = {1: 2.5e-2, 3: 2.5e-3, 5: 1e-4, 7: 4e-6}
    for H in Hs:
        assert max_err[H] < bounds[H], (H, max_err[H])
    # errors at A = 1 (measured 3.87e-3, 1.39e-4, 2.52e-6, 4.50e-8): factor per extra odd
    # harmonic measured 28, 55, 56 -> require > 20 for each step
    ratios = np.array(err_at_1[:-1]) / np.array(err_at_1[1:])
    assert np.all(ratios > 20), ratios
    # exponential convergence: log(err) linear in H; fitted factor per +2 harmonics ~ 44
    slope, icpt = np.polyfit(Hs, np.log(err_at_1), 1)
    fit = np.polyval([slope, icpt], Hs)
    assert math.exp(-2 * slope) > 30
    assert np.abs(fit - np.log(err_at_1)).max() < 0.5  # within a factor 1.65 of the fitted line
    # energy vs the exact A^2/2 + A^4/4: measured 0.115, 6.9e-3, 2.9e-4, 1.15e-5
    ee = [energy_err[H] for H in Hs]
    assert np.all(np.diff(ee) < 0) and ee[-1] < 2e-5


# =========================================================== 3. forced Duffing
FOLD_REFS = {  # (c, eps): (upper fold, lower fold), H = 21 and shooting
    (0.1, 1.0): (3.03905472, 1.64624961),
    (0.2, 1.0): (2.21316595, 1.63530555),
    (0.1, 0.1): (1.81839650, 1.33474639),
}


@pytest.mark.parametrize("c,eps", list(FOLD_REFS))
def test_forced_duffing_folds(c, eps):
    br = forced_branch(c, eps, 9)
    assert br.success and br.omega[-1] == 4.0
    assert len(br.folds) == 2
    # references are rounded to 1e-8; H = 9 truncation moves the folds by < 4e-9 relative
    # (H = 9 vs 15 below); the fold is located to 1e-9. Measured deviation <= 3.7e-9.
    np.testing.assert_allclose(br.omega[list(br.folds)], FOLD_REFS[(c, eps)], rtol=1e-7)
    # a fold is a turning point of omega along the branch
    for i in br.folds:
        d_before = br.omega[i] - br.omega[i - 1]
        d_after = br.omega[i + 1] - br.omega[i]
        assert d_before * d_after < 0


def test_forced_duffing_folds_converged_in_H():
    f9 = forced_branch(0.1, 1.0, 9)
    f15 = forced_branch(0.1, 1.0, 15)
    f3 = forced_branch(0.1, 1.0, 3)
    w9, w15, w3 = (b.omega[list(b.folds)] for b in (f9, f15, f3))
    np.testing.assert_allclose(w9, w15, rtol=1e-8)  # measured 1.4e-12
    # H = 3 is visibly not converged (measured 1.08e-5 on the upper fold)
    assert 1e-6 < np.abs(w3 / w15 - 1).max() < 1e-4


def test_forced_duffing_H5_starts():
    """Near the 1:3 superharmonic resonance (w = 0.5, H = 5) Newton from the linear guess stalls
    (||r|| = 0.389); frequency_response then grows the forcing by continuation from 1 %."""
    br = fm.frequency_response(forced_duffing(), (0.5, 4.0), fm.Harmonics(5))
    assert br.success and len(br.folds) == 2


def test_forced_duffing_peak():
    """Peak of max|u| (3.37896402 at w = 3.03809479) lies just past the upper fold on the
    unstable branch. Refine: dense local continuation around the fold from an upper-branch
    point, accurate max|u| per point, then a parabola in chord length through the 3 points
    around the maximum."""
    h = fm.Harmonics(9)
    coarse = forced_branch(0.1, 1.0, 9)
    i_fold = coarse.folds[0]
    up = [j for j in range(i_fold) if coarse.omega[j] < 3.0][-1]  # upper branch, below 3.0
    opts = ContinuationOptions(step=0.02, max_step=0.02, newton=NewtonOptions(atol=1e-12, max_iter=20))
    loc = fm.frequency_response(forced_duffing(), (3.0, 3.05), h, x0=coarse.Q[up].ravel(), options=opts)
    # goes up to the fold and comes back through 3.0 (status 1: left through p_span[0])
    assert loc.success and loc.status == 1 and len(loc.folds) == 1
    assert loc.omega[loc.folds[0]] == pytest.approx(3.03905472, rel=1e-8)
    a = np.array([true_max_abs(h, Q[:, 0]) for Q in loc.Q])
    j = int(np.argmax(a))
    assert 0 < j < len(loc) - 1
    X = np.column_stack([loc.omega, loc.Q.reshape(len(loc), -1)])
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))]
    pa = np.polyfit(s[j - 1:j + 2], a[j - 1:j + 2], 2)
    pw = np.polyfit(s[j - 1:j + 2], loc.omega[j - 1:j + 2], 2)
    sm = -pa[1] / (2 * pa[0])
    # measured: amplitude 6.3e-8 and omega 4.2e-6 relative to the H = 21 references
    assert np.polyval(pa, sm) == pytest.approx(3.37896402, rel=1e-6)
    assert np.polyval(pw, sm) == pytest.approx(3.03809479, rel=2e-5)
    assert loc.omega[j] < loc.omega[loc.folds[0]]  # the peak is past the fold


COEXIST = {2.0: (2.180126, 1.842510, 0.342901), 3.0: (3.344423, 3.312930, 0.125102)}


@pytest.mark.parametrize("w0", list(COEXIST))
def test_forced_duffing_coexisting_solutions(w0):
    h = fm.Harmonics(9)
    # dense branch (max_step 0.02) over (1.5, 3.5): starts below the lower fold 1.646, so the
    # whole S-shaped part is traced
    br = forced_branch(0.1, 1.0, 9, max_step=0.02, span=(1.5, 3.5))
    assert br.success and len(br.folds) == 2
    idx = crossings(br.omega, w0)
    assert len(idx) == 3  # three coexisting periodic solutions on the S-shaped branch
    a = br.amplitude(0)
    interp, polished = [], []
    pr = fm.ForcedResponseProblem(forced_duffing(), h)
    for i in idx:
        f = (w0 - br.omega[i]) / (br.omega[i + 1] - br.omega[i])
        interp.append(a[i] + f * (a[i + 1] - a[i]))
        x0 = (1 - f) * br.Q[i].ravel() + f * br.Q[i + 1].ravel()
        res = semismooth_newton(lambda x: pr.residual(x, w0)[:2], x0, options=NewtonOptions(atol=1e-12))
        assert res.success
        polished.append(true_max_abs(h, res.x))
    # branch order: upper (stable), middle (unstable), lower (stable) -> sort descending
    ref = np.array(COEXIST[w0])
    # linear interpolation on a max_step = 0.02 branch: measured <= 4.3e-4 relative
    np.testing.assert_allclose(np.sort(interp)[::-1], ref, rtol=1e-3)
    # Newton-polished at w0 exactly: measured <= 3.5e-6 (references rounded to 1e-6 abs)
    np.testing.assert_allclose(np.sort(polished)[::-1], ref, rtol=1e-5)
    # the three solutions are distinct
    assert np.min(np.diff(np.sort(polished))) > 1e-2


# ============================================================ 4. contact cases
CONTACT_FOLDS = {1: (1.38497813, 1.08076953), 2: (1.38893996, 1.15167700)}


@pytest.mark.parametrize("n", [1, 2])
def test_contact_case_traced_through_two_folds(n):
    br = contact_branch(n)
    assert br.success and br.status == 0 and br.omega[-1] == 2.0, br.message
    assert len(br.folds) == 2
    wf = br.omega[list(br.folds)]
    if n == 1:
        np.testing.assert_allclose(wf, (1.385, 1.081), atol=1e-3)  # values of the issue
    # regression of our own measurement (folds located to 1e-9)
    np.testing.assert_allclose(wf, CONTACT_FOLDS[n], rtol=1e-6)
    # Newton iterations per point: measured mean 2.32 / max 4 (case 1), 2.96 / 5 (case 2)
    assert br.nit.mean() <= 4.0 and br.nit.max() <= 8
    assert np.all(br.residual_norm <= 1e-9)
    assert np.all(br.converged)
    # Signorini on the solutions: exact projection keeps penetration / tension small
    gap = {1: 1.0, 2: 2.5}[n]
    assert br.amplitude(0).max() > gap  # the obstacle is hit
    assert br.P.shape == (len(br), 41, 1)


@pytest.mark.parametrize("n", [1, 2])
def test_contact_case_far_from_resonance_is_linear(n):
    br = contact_branch(n)
    lr = fm.linear_response(contact_case(n), [br.omega[0], br.omega[-1]])
    for i, k in ((0, 0), (-1, 1)):
        Q = br.Q[i][:, 0]
        Z = lr.amplitude[k, 0]  # q = Re(Z e^{iwt}) = Re Z cos - Im Z sin
        assert abs(Q[1] - Z.real) < 1e-10 and abs(Q[2] + Z.imag) < 1e-10
        assert np.abs(np.r_[Q[0], Q[3:]]).max() < 1e-10
        assert np.abs(br.P[i]).max() <= 1e-14
    assert br.omega[0] == 0.5


def _interp_amplitudes(br, w0):
    amp = br.amplitude(0)
    out = []
    for i in crossings(br.omega, w0):
        f = (w0 - br.omega[i]) / (br.omega[i + 1] - br.omega[i])
        out.append(amp[i] + f * (amp[i + 1] - amp[i]))
    return np.array(out)


def test_exact_projection_is_independent_of_n_time():
    a = contact_branch(1)
    assert a.harmonics.n_time == 81  # default next_fast_len(4H + 1)
    # 1) equations: residual and Jacobian on the N = 81 and N = 512 grids agree at points of the
    #    branch in and out of contact, folds included (the grid only enters the cubic terms)
    s81 = HBMSystem(contact_case(1), fm.Harmonics(20))
    s512 = HBMSystem(contact_case(1), fm.Harmonics(20, n_time=512))
    for i in sorted(set(range(0, len(a), 25)) | set(a.folds)):
        x = s81.join(a.Q[i], a.P[i])
        r1, J1, d1, _ = s81.residual(x, a.omega[i])
        r2, J2, d2, _ = s512.residual(x, a.omega[i])
        assert np.abs(r1 - r2).max() <= 1e-14 and abs(J1.toarray() - J2.toarray()).max() <= 1e-14
    # 2) traced results at fixed w: a sub-span trace takes other steps (the arclength scale is
    #    the span), so linear interpolation differs by O(step^2) (measured 5e-4); polish the
    #    interpolated point of each branch by Newton at w0 on its own grid, then compare: 1e-8
    b = fm.frequency_response(contact_case(1), (0.5, 1.2), fm.Harmonics(20, n_time=512))
    assert b.success and b.omega[-1] == 1.2
    h = fm.Harmonics(20)
    for w0 in (0.8, 0.95, 1.1):
        amps = []
        for br in (a, b):
            i = crossings(br.omega, w0)[0]  # first crossing: the rising branch before the folds
            f = (w0 - br.omega[i]) / (br.omega[i + 1] - br.omega[i])
            x0 = np.r_[(1 - f) * br.Q[i].ravel() + f * br.Q[i + 1].ravel(),
                       (1 - f) * br.P[i].ravel() + f * br.P[i + 1].ravel()]
            pr = fm.ForcedResponseProblem(contact_case(1), br.harmonics)
            res = semismooth_newton(lambda x: pr.residual(x, w0)[:2], x0, options=NewtonOptions(atol=1e-12))
            assert res.success, res.message
            amps.append(true_max_abs(h, res.x[: h.n_coef]))
        assert abs(amps[0] - amps[1]) <= 1e-8, (w0, amps)
    assert len(crossings(b.omega, 1.1)) == 1


@pytest.mark.slow
def test_exact_projection_is_independent_of_n_time_full_span():
    a = contact_branch(1)
    b = contact_branch(1, n_time=512)
    assert b.harmonics.n_time == 512
    assert b.success and len(b.folds) == 2
    for w0 in (0.8, 1.0, 1.2, 1.5, 1.9):
        va, vb = _interp_amplitudes(a, w0), _interp_amplitudes(b, w0)
        assert len(va) == len(vb) >= 1
        assert np.abs(va - vb).max() <= 1e-8  # measured: bitwise identical branches
    assert len(a) == len(b) and np.abs(a.Q - b.Q).max() <= 1e-12


def test_sampled_contact_projection_stalls():
    """The naive AFT projection (sampled on N = 256 points) is piecewise linear with Jacobian
    jumps; the continuation of case 1 stalls (measured: status 4, 'step size fell below
    min_step' at w = 1.2175 with a cycling corrector) where the exact projection traces the
    whole span."""
    sampled = contact_branch(1, n_time=256, exact=False)
    exact = contact_branch(1)
    assert exact.success and exact.omega[-1] == 2.0
    assert not (sampled.success and sampled.omega[-1] == 2.0)
    assert not sampled.success and sampled.status == 4
    assert sampled.omega[-1] < 1.5
    # before the stall both describe the same physics (same rising branch, folds aside) to the
    # sampling error of the projection: compare amplitudes where both pass w = 1.0 first
    i, j = crossings(sampled.omega, 1.0)[0], crossings(exact.omega, 1.0)[0]
    assert abs(sampled.amplitude(0)[i] - exact.amplitude(0)[j]) < 0.05


# ============================================== 5. penalty vs complementarity, c
C_ISSUE = {1.0: 1.0184, 10.0: 1.0153, 100.0: 1.0108}  # max_t u(t) at w = 1.05, H = 20, other code
C_OURS = {1.0: 1.01842717, 10.0: 1.01535874, 100.0: 1.01110633}


def _max_u(Q):
    h = fm.Harmonics(20)
    th = 2 * np.pi * np.arange(8192) / 8192
    return float((h.grid.synthesis(th) @ Q).max())


def test_complementarity_parameter_sensitivity():
    vals = {}
    for c in C_ISSUE:
        Q, br = case1_at_105("c", c)
        vals[c] = _max_u(Q)
        assert br.contacts.c == (c,)
        # "max displacement" of the issue is max_t u(t) = gap + penetration
        assert vals[c] == pytest.approx(1.0 + br[-1].penetration, abs=1e-6)
    for c in C_ISSUE:
        assert vals[c] == pytest.approx(C_ISSUE[c], abs=2e-3)  # other code: 4-digit values
        assert vals[c] == pytest.approx(C_OURS[c], abs=1e-6)  # our regression
    # larger c -> smaller penetration of the truncated solution
    assert vals[1.0] > vals[10.0] > vals[100.0] > 1.0


def test_default_complementarity_parameter_is_static_stiffness():
    assert default_contact_parameter(contact_case(1), 0) == pytest.approx(1.0, rel=1e-14)
    Qd, brd = case1_at_105("c", None)
    Q1, _ = case1_at_105("c", 1.0)
    assert brd.contacts.c[0] == pytest.approx(1.0, rel=1e-14)
    np.testing.assert_allclose(Qd, Q1, atol=1e-12)
    # chain: c = 1 / (K^-1)_dd; for K = [[2,-1],[-1,1]] at DOF 1: (K^-1)_11 = 2 -> c = 0.5
    m = fm.StructuralModel(M=np.eye(2), K=[[2.0, -1], [-1, 1]]).with_contact(fm.UnilateralContact(at=1, gap=0.5))
    assert default_contact_parameter(m, 1) == pytest.approx(0.5, rel=1e-13)


def test_penalty_approaches_complementarity_limit():
    """Penalty k -> inf and complementarity c -> inf tend to the same truncated-series solution
    (zero projected penetration). NOTE: the c = 1 (default) complementarity solution is NOT that
    limit (the truncated weak solution depends on c), so the distance of the penalty solution to
    it is not monotone in k (measured max u differences +0.152, +0.026, -0.008, -0.016); the
    monotone comparison is penalty(k) vs complementarity(c = k)."""
    ks = (1e1, 1e2, 1e3, 1e4)
    pen = {k: _max_u(case1_at_105("k", k)[0]) for k in ks}
    com = {k: _max_u(case1_at_105("c", k)[0]) for k in ks}
    # penetration of the penalty solution, measured 0.1705, 0.0440, 0.0103, 0.00225
    penetration = np.array([pen[k] - 1.0 for k in ks])
    assert np.all(penetration > 0) and np.all(np.diff(penetration) < 0)
    rate = -np.diff(np.log10(penetration))  # decades per decade of k: 0.59, 0.63, 0.66
    assert np.all((rate > 0.5) & (rate < 1.0)), rate
    # distance penalty(k) <-> complementarity(c = k): 0.155, 0.033, 0.0048, 0.00053
    d = np.array([abs(pen[k] - com[k]) for k in ks])
    assert np.all(np.diff(d) < 0) and d[-1] < 1e-3, d
    assert np.all(d[:-1] / d[1:] > 4), d[:-1] / d[1:]  # measured 4.7, 6.8, 9.0 per decade
    # relative distance of the whole coefficient vector decreases likewise (0.22, 0.043, 0.0058, 0.00063)
    dq = [np.linalg.norm(case1_at_105("k", k)[0] - case1_at_105("c", k)[0]) for k in ks]
    assert np.all(np.diff(dq) < 0)
    # vs the default c = 1 solution: not monotone (documented above)
    d1 = [abs(pen[k] - C_OURS[1.0]) for k in ks]
    assert d1[3] > d1[2]


@pytest.mark.slow  # 1-7 s
def test_stiff_penalty_frequency_response_passes_grazing():
    """Penalty k = 1e4 on case 1 (H = 20) with frequency_response's defaults: the whole span,
    113 points. It passes since the steps are also bounded by the change of the response's size
    (target_norm_change=0.3): no step lands on the grazing point where the corrector cycles (the
    test below, without it, still stops there)."""
    br = fm.frequency_response(penalty_case1(1e4), (0.5, 2.0), fm.Harmonics(20))
    assert br.success and br.omega[-1] == 2.0


@pytest.mark.slow  # 1-7 s
@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "frequency_response(case 1 with PenaltyContact(at=0, gap=1, stiffness=1e4), (0.5, 2.0), Harmonics(20)) "
    "without target_norm_change stops with success=False, status 4 at w=0.906489 (the grazing point, "
    "max u - gap ~ -2e-7): the pseudo-arclength corrector's semismooth Newton cycles (2-cycle, then 'no "
    "progress' at ||r|| ~ 3e-7..6e-6 >> atol 1e-9) for every step down to min_step=1e-6. A fixed-frequency "
    "Newton from the last point at w+1e-6..1e-3 converges in 7-8 iterations, and the same curve traced from "
    "w=0.8 or 0.9 succeeds"))
def test_stiff_penalty_stalls_at_grazing_without_the_norm_target():
    from femodes.analyses import frequency_response_options

    br = fm.frequency_response(penalty_case1(1e4), (0.5, 2.0), fm.Harmonics(20),
                               options=frequency_response_options(target_norm_change=None))
    assert br.success and br.omega[-1] == 2.0


# ========================================== 6. free impacting oscillator
@functools.cache
def impact_mode(H, e0, e1):
    model = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    return fm.nonlinear_mode(model, 1, energy=(e0, e1), harmonics=fm.Harmonics(H))


def test_impact_oscillator_backbone():
    br = impact_mode(20, 0.1, 5.0)
    assert br.success and br.energy[-1] == pytest.approx(5.0, rel=math.log(10) * MODE_ATOL)  # end: see MODE_ATOL
    assert np.abs(br.xi).max() < 1e-10
    below = br.energy < 0.5 * (1 - 1e-9)  # grazing at A = gap: E = 1/2
    above = br.energy > 0.6
    assert below.sum() >= 3 and above.sum() >= 5
    assert np.abs(br.omega[below] - 1.0).max() < 1e-12  # linear below grazing
    assert np.abs(br.P[below]).max() == 0.0
    # above grazing the frequency rises with energy, and stays below the exact value
    w, E = br.omega[above], br.energy[above]
    assert np.all(np.diff(w) > 0) and w[0] > 1.0
    err = w - impact_omega(E)
    assert np.all(err < 0) and np.abs(err).max() < 0.06  # measured max 0.059 (H = 20)


def _impact_error_at_2(H):
    br = impact_mode(H, 0.4, 2.0)
    assert br.success and br.energy[-1] == pytest.approx(2.0, rel=math.log(10) * MODE_ATOL)  # end: see MODE_ATOL
    assert np.abs(br.xi).max() < 1e-10
    return br.omega[-1] - float(impact_omega(2.0))


def test_impact_oscillator_converges_algebraically():
    # measured errors at E = 2 (exact w = 1.5): -0.0912 (H=10), -0.0513 (H=20), -0.0280 (H=40)
    e10, e20, e40 = (_impact_error_at_2(H) for H in (10, 20, 40))
    assert e10 < 0 and e20 < 0 and e40 < 0  # the truncated solution penetrates: lower frequency
    assert abs(e40) < abs(e20) < abs(e10)
    assert abs(e10) < 0.095 and abs(e20) < 0.053 and abs(e40) < 0.029
    # algebraic convergence ~H^-0.85 (measured orders 0.83, 0.87 per doubling of H), far from
    # the exponential rate of smooth problems (a factor ~50 per two harmonics, see Duffing)
    for a, b in ((e10, e20), (e20, e40)):
        order = math.log2(abs(a) / abs(b))
        assert 0.6 < order < 1.2, order


# ================================================================ 7. 2-DOF chain
def test_two_dof_chain_contact_mode():
    model = fm.StructuralModel(M=np.eye(2), K=[[2.0, -1], [-1, 1]]).with_contact(fm.UnilateralContact(at=1, gap=0.5))
    br = fm.nonlinear_mode(model, 1, energy=(1e-2, 2.0), harmonics=fm.Harmonics(10))
    assert br.success, br.message
    w1 = (math.sqrt(5) - 1) / 2  # 0.618034, linear mode 1
    lm = fm.linear_modes(model, 1)
    E_graze = 0.5 * w1**2 * (0.5 / abs(lm.shapes[1, 0])) ** 2  # a * phi_2 = gap: 0.06598
    assert np.abs(br.xi).max() < 1e-10
    below = br.energy < E_graze * (1 - 1e-6)
    assert below.sum() >= 2
    assert np.abs(br.omega[below] - w1).max() < 1e-12
    assert br.omega[0] == pytest.approx(0.618034, abs=1e-6)
    assert np.all(np.diff(br.omega) >= -1e-12)  # frequency rises with energy
    # measured w(E=2) = 0.77967 (H=10; 0.78061 with H=20)
    assert 0.75 < br.omega[-1] < 0.80
    assert br.omega[br.energy > 1.2 * E_graze].min() > w1 + 0.03


# ================================================================ 8. static contact
def test_static_contact_single_dof():
    m = fm.StructuralModel(M=[[1.0]], K=[[2.0]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    r = fm.static_contact(m, [3.0])
    assert r.success and r.x[0] == pytest.approx(1.0, abs=1e-12) and r.contact_force[0] == pytest.approx(1.0, abs=1e-12)
    assert r.penetration <= 1e-12
    r = fm.static_contact(m, [1.0])
    assert r.success and r.x[0] == pytest.approx(0.5, abs=1e-12) and r.contact_force[0] == 0.0
    assert r.gap[0] == pytest.approx(0.5, abs=1e-12)
    # default load: the amplitude of the declared harmonic-1 force (quasi-static)
    r = fm.static_contact(m.with_forcing(fm.HarmonicForce(at=0, amplitude=3.0)))
    assert r.x[0] == pytest.approx(1.0, abs=1e-12) and r.contact_force[0] == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("gaps,f,q_ref,p_ref", [
    # both active: q1 = 0.5, q2 = 2 -> q0 = q1/2 = 0.25; row 1: -0.25 + 1 - 2 + p1 = 0 -> p1 = 1.25;
    # row 2: -0.5 + 2 + p2 = 2 -> p2 = 0.5
    ((0.5, 2.0), (0.0, 0.0, 2.0), (0.25, 0.5, 2.0), (1.25, 0.5)),
    # only DOF 1 active: q0 = 0.25, q2 - q1 = 1.5 -> q2 = 2 < 3 (inactive), p1 = 1.25
    ((0.5, 3.0), (0.0, 0.0, 1.5), (0.25, 0.5, 2.0), (1.25, 0.0)),
    # pulled away from both obstacles: linear solution q = K^-1 f
    ((0.5, 3.0), (0.0, 0.0, -1.0), (-1.0, -2.0, -3.0), (0.0, 0.0)),
])
def test_static_contact_three_dof_lcp(gaps, f, q_ref, p_ref):
    K = np.array([[2.0, -1, 0], [-1, 2, -1], [0, -1, 1]])
    m = fm.StructuralModel(M=np.eye(3), K=K).with_contact(
        fm.UnilateralContact(at=1, gap=gaps[0]), fm.UnilateralContact(at=2, gap=gaps[1]))
    r = fm.static_contact(m, np.array(f))
    assert r.success
    np.testing.assert_allclose(r.x, q_ref, atol=1e-10)
    np.testing.assert_allclose(r.contact_force, p_ref, atol=1e-10)
    # LCP conditions independently: equilibrium, gaps >= 0, p >= 0, complementarity
    W = np.zeros((3, 2))
    W[1, 0] = W[2, 1] = 1.0
    np.testing.assert_allclose(K @ r.x + W @ r.contact_force, f, atol=1e-10)
    g = np.array(gaps) - r.x[[1, 2]]
    assert np.all(g >= -1e-12) and np.all(r.contact_force >= -1e-12)
    assert np.abs(g * r.contact_force).max() < 1e-12


def test_static_penalty_converges_to_contact():
    q = []
    for k in (1e1, 1e2, 1e3, 1e6):
        m = fm.StructuralModel(M=[[1.0]], K=[[2.0]]).with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=k))
        r = fm.static_contact(m, [3.0])
        assert r.success
        # 2 q + k (q - 1) = 3 -> q = 1 + 1/(2 + k), p = k/(2 + k)
        assert r.x[0] == pytest.approx(1 + 1 / (2 + k), rel=1e-12)
        # p = k (q - 1) with q - 1 = 1/(2 + k): one ulp of q is eps (2 + k) relative in p (2e-10 at
        # k = 1e6, measured 0.2-0.6 of that); 1e-10 is static_contact's Newton atol
        assert r.contact_force[0] == pytest.approx(k / (2 + k), rel=1e-10 + 8 * EPS * (2 + k))
        q.append(r.x[0])
    assert np.all(np.diff(q) < 0) and q[-1] - 1 < 1.1e-6


# ================================================================ 9. bad input
def test_frequency_response_requires_forcing():
    with pytest.raises(ValueError, match="with_forcing"):
        fm.frequency_response(duffing(), (0.5, 2.0), fm.Harmonics(3))


@pytest.mark.parametrize("omega,exc", [
    ((-1.0, 2.0), ValueError), ((1.0, 1.0), ValueError), ((float("nan"), 2.0), ValueError),
    ((0.0, 2.0), ValueError), ((1.0, float("inf")), ValueError),
    ("ab", TypeError), (3.0, TypeError), ((1.0,), TypeError), ((1.0, 2.0, 3.0), TypeError),
    (None, TypeError), (("a", "b"), TypeError),
])
def test_frequency_response_bad_omega(omega, exc):
    with pytest.raises(exc, match="omega"):
        fm.frequency_response(forced_duffing(), omega, fm.Harmonics(3))


@pytest.mark.parametrize("harmonics", [3.0, "3", None, True, [3]])
def test_bad_harmonics_type(harmonics):
    with pytest.raises(TypeError, match="harmonics"):
        fm.frequency_response(forced_duffing(), (0.5, 2.0), harmonics)
    with pytest.raises(TypeError, match="harmonics"):
        fm.nonlinear_mode(duffing(), 1, energy=(1e-3, 1.0), harmonics=harmonics)


@pytest.mark.parametrize("mode", [0, -1, 2, 1.0, True, "1"])
def test_nonlinear_mode_bad_mode(mode):
    with pytest.raises(ValueError, match="mode"):
        fm.nonlinear_mode(duffing(), mode, energy=(1e-3, 1.0), harmonics=3)


@pytest.mark.parametrize("energy,exc", [
    ((0.0, 1.0), ValueError), ((-1.0, 1.0), ValueError), ((1.0, 1.0), ValueError),
    ((1.0, float("nan")), ValueError), ("x", TypeError), (5.0, TypeError),
])
def test_nonlinear_mode_bad_energy(energy, exc):
    with pytest.raises(exc, match="energy"):
        fm.nonlinear_mode(duffing(), 1, energy=energy, harmonics=3)


def test_forcing_harmonic_beyond_truncation():
    m = duffing().with_forcing(fm.HarmonicForce(at=0, amplitude=1.0, harmonic=2))
    with pytest.raises(ValueError, match="harmonic 2"):
        fm.frequency_response(m, (0.5, 2.0), fm.Harmonics(1))
    with pytest.raises(ValueError, match="n_harmonics >= 3"):
        HBMSystem(forced_duffing(), fm.Harmonics(2, subharmonic=3)).linear.force()
    with pytest.raises(TypeError, match="model"):
        fm.frequency_response("model", (0.5, 2.0), 3)


def test_force_placement_subharmonic_and_phase():
    h = fm.Harmonics(6, subharmonic=3)
    F = HBMSystem(forced_duffing(F=1.7), h).linear.force().reshape(h.n_coef, 1)[:, 0]
    expected = np.zeros(h.n_coef)
    expected[h.layout.cos_index(3)] = 1.7  # forcing at w is harmonic 3 of the base frequency w/3
    assert h.layout.cos_index(3) == 5
    np.testing.assert_array_equal(F, expected)
    # phase and a static load: compare with the Fourier projection of f(t) sampled in time
    m = duffing().with_forcing(fm.HarmonicForce(at=0, amplitude=0.8, phase=0.4),
                               fm.HarmonicForce(at=0, amplitude=0.3, harmonic=2, phase=-1.1),
                               fm.HarmonicForce(at=0, amplitude=0.25, harmonic=0))
    h = fm.Harmonics(4, subharmonic=2)
    F = HBMSystem(m, h).linear.force()
    th = 2 * np.pi * np.arange(64) / 64  # base phase; w t = 2 theta
    f = 0.8 * np.cos(2 * th + 0.4) + 0.3 * np.cos(4 * th - 1.1) + 0.25
    E = h.grid.synthesis(th)
    coef = np.linalg.lstsq(E, f, rcond=None)[0]
    np.testing.assert_allclose(F, coef, atol=1e-13)


# ============================================================ 10. sparsity at scale
def test_large_beam_residual_is_sparse():
    mesh = fm.line_mesh(1.0, 5000, boundaries={"clamp": 0.0, "tip": 1.0})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # conditioning advice of large beams is not under test
        beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
        model = (beam.with_damping(alpha=0.01, beta=1e-4)
                 .with_contact(fm.UnilateralContact(at="tip", gap=0.01))
                 .with_forcing(fm.HarmonicForce(at="tip", amplitude=1.0)))
        s = HBMSystem(model, fm.Harmonics(10))
    assert model.n_dofs == 10000 and s.size == 21 * 10000 + 21
    rng = np.random.default_rng(0)
    x = 1e-2 * rng.standard_normal(s.size)
    r, J, dr_dw, _ = s.residual(x, 3.0)
    assert J.shape == (s.size, s.size) and sp.issparse(J.tocsr())
    assert np.all(np.isfinite(r))
    # Hermite beam rows have <= 6 entries in K, M, C; per harmonic row the Kronecker structure
    # couples the cos/sin pair -> <= 12 per row, plus the contact blocks. Measured 11.71.
    assert J.tocsr().nnz < 12 * s.size
    # directional derivative check of the big Jacobian (the contact is partially active at x)
    d = rng.standard_normal(s.size)
    e = 1e-7
    fd = (s.residual(x + e * d, 3.0)[0] - s.residual(x - e * d, 3.0)[0]) / (2 * e)
    np.testing.assert_allclose(J @ d, fd, rtol=0, atol=1e-6 * np.abs(fd).max())


def test_monotone_line_search_default_starts_forced_duffing():
    """Why NewtonOptions.nonmonotone_memory defaults to 1 (measured while building the solver).

    Forced Duffing (c = 0.1, eps = 1, F = 1), H = 9, at w = 0.5 from the linear guess: the
    monotone Armijo search converges; the non-monotone one with memory 5 cycles and stalls.
    """
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
             .with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
             .with_forcing(fm.HarmonicForce(at=0, amplitude=1.0)))
    pr = fm.ForcedResponseProblem(model, fm.Harmonics(9))
    x0 = pr.linear_guess(0.5)

    def fun(x):
        return pr.residual(x, 0.5)[:2]

    mono = fm.semismooth_newton(fun, x0, options=fm.NewtonOptions(max_iter=60))
    assert mono.success and mono.residual_norm < 1e-10
    nonmono = fm.semismooth_newton(fun, x0, options=fm.NewtonOptions(max_iter=60, nonmonotone_memory=5, watchdog=0))
    assert not nonmono.success


def test_low_level_api_without_x0_as_in_the_design():
    """fm.continuation(problem, p_span, options=...) works with the HBM problems (no x0)."""
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
             .with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
             .with_forcing(fm.HarmonicForce(at=0, amplitude=1.0)))
    res = fm.continuation(fm.ForcedResponseProblem(model, fm.Harmonics(7)), (1.0, 4.0),
                          options=fm.ContinuationOptions(step=0.05, max_step=0.5))
    assert res.success and len(res.folds) == 2
    duff = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
    res = fm.continuation(fm.NonlinearModeProblem(duff, fm.Harmonics(5)), (-2.0, 0.0))
    assert res.success and res.p[-1] == 0.0
    with pytest.raises(TypeError, match="initial_guess"):
        fm.continuation(object.__new__(type("P", (), {"residual": lambda self, x, p: None})), (0.0, 1.0))
