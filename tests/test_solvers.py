"""Tests of the solvers layer (semismooth Newton and pseudo-arclength continuation).

Every test states its tolerance; the whole file runs in a few seconds.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
import scipy.optimize
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from femodes.solvers import (
    ContinuationOptions,
    ContinuationPoint,
    ContinuationResult,
    NewtonOptions,
    NewtonResult,
    continuation,
    semismooth_newton,
)

# --------------------------------------------------------------------------- #
# test problems
# --------------------------------------------------------------------------- #
N_SMOOTH = 50
A_SMOOTH = sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(N_SMOOTH, N_SMOOTH)).toarray()
B_SMOOTH = np.linspace(1.0, 3.0, N_SMOOTH)


def smooth_fun(x, sparse=False):
    """r(x) = A x + x**3 - b (A tridiagonal SPD): smooth, unique root."""
    r = A_SMOOTH @ x + x**3 - B_SMOOTH
    J = A_SMOOTH + np.diag(3.0 * x**2)
    return r, (sp.csr_matrix(J) if sparse else J)


def make_lcp(n=40, seed=0):
    """LCP min(x, M x + q) = 0 with M a P-matrix and a known solution x*."""
    rng = np.random.default_rng(seed)
    M = sp.diags([-1.0, 4.0, -1.5], [-1, 0, 1], shape=(n, n)).toarray()
    active = rng.random(n) < 0.5
    x_star = np.where(active, 0.0, rng.random(n) + 0.1)
    w_star = np.where(active, rng.random(n) + 0.1, 0.0)
    q = w_star - M @ x_star

    def fun(x, sparse=False):
        F = M @ x + q
        pick_x = x <= F
        r = np.where(pick_x, x, F)
        J = np.where(pick_x[:, None], np.eye(n), M)
        return r, (sp.csr_matrix(J) if sparse else J)

    return fun, x_star


def contact_chain(n=30, c=10.0, seed=1):
    """Chain of springs against obstacles, contact law lam - max(0, lam - c*gap) = 0.

    Unknowns y = (u, lam):  K u - f + lam = 0,  lam_i - max(0, lam_i - c (g0_i - u_i)) = 0.
    The exact solution is built first (active set chosen at random), f from it.
    """
    rng = np.random.default_rng(seed)
    K = sp.diags([-1.0, 2.2, -1.0], [-1, 0, 1], shape=(n, n), format="csr")
    g0 = 0.5 + rng.random(n)
    active = rng.random(n) < 0.4
    u_star = np.where(active, g0, g0 - 0.2 - rng.random(n))
    lam_star = np.where(active, 0.1 + rng.random(n), 0.0)
    f = K @ u_star + lam_star

    def fun(y):
        u, lam = y[:n], y[n:]
        gap = g0 - u
        act = lam - c * gap > 0.0
        r = np.concatenate([K @ u - f + lam, np.where(act, c * gap, lam)])
        # generalized Jacobian of lam - max(0, lam - c gap): active -> (-c, 0), inactive -> (0, 1)
        d_du = sp.diags(np.where(act, -c, 0.0))
        d_dl = sp.diags(np.where(act, 0.0, 1.0))
        J = sp.bmat([[K, sp.eye(n)], [d_du, d_dl]], format="csr")
        return r, J

    return fun, np.concatenate([u_star, lam_star])


class SCurve:
    """r(x, p) = x**3 - x - p for every component (n copies, uncoupled)."""

    def __init__(self, n=1, sparse=False):
        self.n, self.sparse = n, sparse
        self.calls = 0

    def residual(self, x, p):
        self.calls += 1
        d = 3.0 * x**2 - 1.0
        J = sp.diags(d, format="csr") if self.sparse else np.diag(d)
        return x**3 - x - p, J, -np.ones(self.n)


P_FOLD = 2.0 / (3.0 * math.sqrt(3.0))  # fold values p = +-2/(3 sqrt 3)
X_END = 1.324717957244746  # real root of x^3 - x - 1 (plastic number)


class Duffing:
    """Single-harmonic balance of x'' + c x' + x + eps x^3 = F cos(w t), unknowns (a_c, a_s), p = w."""

    def __init__(self, c, eps, F, sparse=False):
        self.c, self.k, self.F, self.sparse = c, 0.75 * eps, F, sparse

    def residual(self, x, w):
        ac, as_ = x
        c, k, F = self.c, self.k, self.F
        d = 1.0 - w * w + k * (ac * ac + as_ * as_)
        r = np.array([d * ac + c * w * as_ - F, d * as_ - c * w * ac])
        J = np.array(
            [
                [d + 2 * k * ac * ac, c * w + 2 * k * ac * as_],
                [2 * k * ac * as_ - c * w, d + 2 * k * as_ * as_],
            ]
        )
        rp = np.array([-2 * w * ac + c * as_, -2 * w * as_ - c * ac])
        return r, (sp.csr_matrix(J) if self.sparse else J), rp


class SpringObstacle:
    """k u - p + lam = 0, lam - max(0, lam - c (g0 - u)) = 0: branch with a kink at p = k g0."""

    k, g0, c = 1.0, 1.0, 1.0

    def residual(self, x, p):
        u, lam = x
        gap = self.g0 - u
        act = lam - self.c * gap > 0.0
        r = np.array([self.k * u - p + lam, lam - max(0.0, lam - self.c * gap)])
        J = np.array([[self.k, 1.0], [-self.c, 0.0] if act else [0.0, 1.0]])
        return r, sp.csr_matrix(J), np.array([-1.0, 0.0])


def scurve_residuals(res):
    return np.abs(res.x**3 - res.x - res.p[:, None]).max(axis=1)


# --------------------------------------------------------------------------- #
# semismooth_newton
# --------------------------------------------------------------------------- #
def test_newton_quadratic_convergence_and_dense_sparse_agree():
    """Smooth system: r_{k+1} <= C r_k^2 with C = 1 in the asymptotic range; dense/sparse x equal to 1e-13."""
    dense = semismooth_newton(smooth_fun, np.zeros(N_SMOOTH))
    sparse = semismooth_newton(lambda x: smooth_fun(x, True), np.zeros(N_SMOOTH))
    assert dense.success and sparse.success and dense.status == 0
    assert dense.residual_norm <= 1e-10
    assert np.max(np.abs(dense.x - sparse.x)) <= 1e-13
    h = dense.history
    assert len(h) == dense.nit + 1
    asymptotic = [(h[k], h[k + 1]) for k in range(len(h) - 1) if h[k] < 1e-1 and h[k + 1] > 1e-14]
    assert len(asymptotic) >= 2
    for rk, rk1 in asymptotic:
        assert rk1 <= 1.0 * rk**2, (rk, rk1)
    assert dense.nit <= 10


@pytest.mark.parametrize("sparse", [False, True])
@pytest.mark.parametrize("start", ["zeros", "ones", "minus5", "random"])
def test_newton_lcp_finite_termination(sparse, start):
    """min(x, Mx+q)=0 (piecewise linear): exact solution (1e-12) in <= 6 iterations from several starts."""
    fun, x_star = make_lcp()
    n = x_star.size
    x0 = {
        "zeros": np.zeros(n),
        "ones": np.ones(n),
        "minus5": -5 * np.ones(n),
        "random": 10 * np.random.default_rng(3).normal(size=n),
    }[start]
    res = semismooth_newton(lambda x: fun(x, sparse), x0)
    assert res.success and res.status == 0
    assert res.nit <= 6
    assert np.max(np.abs(res.x - x_star)) <= 1e-12
    assert res.residual_norm <= 1e-12


@pytest.mark.parametrize("start", [0.0, 1.0, -2.0])
def test_newton_contact_law_chain(start):
    """Spring chain with the contact complementarity function: exact (1e-10) in <= 15 iterations."""
    fun, y_star = contact_chain()
    res = semismooth_newton(fun, np.full(y_star.size, start))
    assert res.success, res.message
    assert res.nit <= 15
    assert np.max(np.abs(res.x - y_star)) <= 1e-10


@settings(max_examples=60, deadline=None)
@given(
    k=st.floats(0.1, 10.0),
    c=st.floats(0.1, 10.0),
    f=st.floats(-10.0, 10.0),
    g0=st.floats(0.0, 2.0),
    u0=st.floats(-10.0, 10.0),
    l0=st.floats(-10.0, 10.0),
)
def test_newton_contact_law_property(k, c, f, g0, u0, l0):
    """1-DOF spring against an obstacle: exact solution u = min(f/k, g0), lam = max(0, f - k g0) to 1e-9."""

    def fun(y):
        u, lam = y
        gap = g0 - u
        act = lam - c * gap > 0.0
        r = np.array([k * u - f + lam, c * gap if act else lam])
        J = np.array([[k, 1.0], [-c, 0.0] if act else [0.0, 1.0]])
        return r, J

    res = semismooth_newton(fun, [u0, l0])
    assert res.success, res.message
    assert res.nit <= 10
    u_exact, lam_exact = min(f / k, g0), max(0.0, f - k * g0)
    assert abs(res.x[0] - u_exact) <= 1e-9 * (1 + abs(u_exact))
    assert abs(res.x[1] - lam_exact) <= 1e-9 * (1 + abs(lam_exact))


def _arctan(x):
    return np.arctan(x), np.diag(1.0 / (1.0 + x**2))


def test_newton_line_search_globalizes_arctan():
    """arctan(x)=0 from x0=3: plain Newton diverges (failure reported), damped Newton converges (|x| <= 1e-10)."""
    damped = semismooth_newton(_arctan, [3.0])
    assert damped.success and damped.status == 0
    assert abs(damped.x[0]) <= 1e-10
    plain = semismooth_newton(_arctan, [3.0], options=NewtonOptions(line_search=False, max_iter=5))
    assert not plain.success
    assert plain.status != 0
    assert plain.message


def test_newton_max_iter_reported():
    """max_iter=2 on the arctan problem: success False, status 1, message mentions max_iter."""
    res = semismooth_newton(_arctan, [3.0], options=NewtonOptions(max_iter=2))
    assert not res.success and res.status == 1
    assert "max_iter" in res.message
    assert res.nit == 2 and len(res.history) == 3


def test_newton_no_root_reports_no_progress():
    """r(x) = x^2 + 1 has no root: status 2 (no progress), not an exception, well before max_iter."""
    res = semismooth_newton(lambda x: (x**2 + 1.0, np.diag(2.0 * x)), [0.7])
    assert not res.success and res.status == 2
    assert "no progress" in res.message
    assert res.nit < 30
    assert res.residual_norm == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize("sparse", [False, True])
def test_newton_singular_jacobian_status3(sparse):
    """Exactly singular Jacobian (splu RuntimeError / LinAlgError) -> status 3, no exception."""

    def fun(x):
        J = np.array([[1.0, 1.0], [1.0, 1.0]])
        return np.array([1.0, 2.0]) + 0 * x, (sp.csc_matrix(J) if sparse else J)

    res = semismooth_newton(fun, [0.0, 0.0])
    assert res.status == 3 and not res.success
    assert "singular" in res.message


def test_newton_nonfinite_residual_status3():
    """Residual NaN at x0 -> status 3."""
    res = semismooth_newton(lambda x: (np.full(2, np.nan), np.eye(2)), [1.0, 2.0])
    assert res.status == 3 and not res.success


def test_newton_backward_error_product_only_near_convergence(monkeypatch):
    """The product |J| |x| of the rtol test is formed only when the residual is within
    TOLERANCE_RECHECK of the last tolerance or |x| has more than doubled: the same iterates and
    decisions as forming it at every iterate, fewer products. From x0 = 0 (|J||x| = 0, the
    tolerance atol) the rtol test must still accept x = 1 on its 1e-6 noise floor."""
    import femodes.solvers.newton as newton

    calls = []
    real = newton._tolerance

    def counting(*args, **kw):
        calls.append(1)
        return real(*args, **kw)

    monkeypatch.setattr(newton, "_tolerance", counting)
    opts = NewtonOptions(atol=1e-300, rtol=1e-14)  # only the backward-error test can converge
    x0 = np.full(N_SMOOTH, 3.0)
    res = semismooth_newton(smooth_fun, x0, options=opts)
    n_skip = len(calls)
    monkeypatch.setattr(newton, "TOLERANCE_RECHECK", math.inf)  # the product at every iterate
    calls.clear()
    ref = semismooth_newton(smooth_fun, x0, options=opts)
    assert res.success and ref.success and "rtol" in res.message
    assert res.history == ref.history and np.array_equal(res.x, ref.x)
    assert n_skip < len(calls) == ref.nit + 1

    def noisy(x):
        return 1e6 * (x - 1.0) + 1e-6 * np.cos(1e15 * x), np.array([[1e6]])

    monkeypatch.setattr(newton, "TOLERANCE_RECHECK", 16.0)
    rel = semismooth_newton(noisy, [0.0], options=NewtonOptions(rtol=1e-12))
    assert rel.success and "rtol" in rel.message


def test_newton_xtol_convergence_on_roundoff_floor():
    """Residual with a 1e-6 noise floor and J = 1e6: accepted as converged by the xtol test (|r| <= sqrt(atol))."""

    def fun(x):
        noise = 1e-6 * np.cos(1e15 * x)
        return 1e6 * (x - 1.0) + noise, np.array([[1e6]])

    res = semismooth_newton(fun, [0.0], options=NewtonOptions(rtol=0.0))
    assert res.success and res.status == 0
    assert "xtol" in res.message
    # the backward-error test accepts it with rtol=1e-12: |r| <= 1e-12 * |J||x| = 1e-6
    rel = semismooth_newton(fun, [0.0], options=NewtonOptions(rtol=1e-12))
    assert rel.success and "rtol" in rel.message and abs(rel.x[0] - 1.0) <= 1e-11
    assert res.residual_norm <= math.sqrt(1e-10)
    assert abs(res.x[0] - 1.0) <= 1e-11


def test_newton_bad_x0():
    with pytest.raises(ValueError, match="x0"):
        semismooth_newton(_arctan, [np.nan])
    with pytest.raises(ValueError, match="x0"):
        semismooth_newton(_arctan, [1.0, np.inf])
    with pytest.raises(ValueError, match="x0"):
        semismooth_newton(_arctan, np.ones((2, 2)))
    with pytest.raises(ValueError, match="x0"):
        semismooth_newton(_arctan, [])


def test_newton_wrong_shapes():
    with pytest.raises(ValueError, match=r"\(3,\).*\(2,\)"):
        semismooth_newton(lambda x: (np.zeros(3), np.eye(2)), [1.0, 2.0])
    with pytest.raises(ValueError, match=r"\(3, 3\).*\(2, 2\)"):
        semismooth_newton(lambda x: (np.ones(2), np.eye(3)), [1.0, 2.0])
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        semismooth_newton(lambda x: (np.ones(2), sp.eye(3, format="csr")), [1.0, 2.0])


@pytest.mark.parametrize(
    ("kwargs", "exc", "pattern"),
    [
        ({"atol": -1.0}, ValueError, r"atol must be a positive finite number, got -1\.0"),
        ({"atol": float("nan")}, ValueError, r"atol .* got nan"),
        ({"xtol": 0.0}, ValueError, r"xtol .* got 0\.0"),
        ({"max_iter": 0}, ValueError, r"max_iter .* got 0"),
        ({"max_iter": 2.5}, TypeError, r"max_iter .* got 2\.5"),
        ({"min_alpha": 2.0}, ValueError, r"min_alpha .* got 2\.0"),
        ({"line_search": "yes"}, TypeError, r"line_search .* got 'yes'"),
        ({"linear_solver": 3}, TypeError, r"linear_solver .* got 3"),
        ({"callback": "f"}, TypeError, r"callback .* got 'f'"),
        ({"watchdog": -1}, ValueError, r"watchdog .* got -1"),
        ({"nonmonotone_memory": 0}, ValueError, r"nonmonotone_memory .* got 0"),
        ({"stagnation_window": 1.0}, TypeError, r"stagnation_window .* got 1\.0"),
    ],
)
def test_newton_options_validation(kwargs, exc, pattern):
    with pytest.raises(exc, match=pattern):
        NewtonOptions(**kwargs)


def test_newton_linear_solver_and_callback_are_used(caplog):
    """Custom linear solver called once per step; callback gets (0..nit, x, |r|) matching history; no stdout."""
    solves, calls = [], []

    def solver(J, b):
        solves.append(J.shape)
        return np.linalg.solve(J, b)

    opts = NewtonOptions(linear_solver=solver, callback=lambda i, x, rn: calls.append((i, x.copy(), rn)))
    with caplog.at_level(logging.DEBUG, logger="femodes.solvers.newton"):
        res = semismooth_newton(smooth_fun, np.zeros(N_SMOOTH), options=opts)
    assert res.success
    assert len(solves) == res.nit
    assert [c[0] for c in calls] == list(range(res.nit + 1))
    assert tuple(c[2] for c in calls) == res.history
    assert np.array_equal(calls[-1][1], res.x)
    assert res.nfev >= res.nit + 1
    assert any("newton it=" in rec.getMessage() for rec in caplog.records)
    assert isinstance(res, NewtonResult)
    np.testing.assert_allclose(res.fun, smooth_fun(res.x)[0], rtol=0, atol=0)


# --------------------------------------------------------------------------- #
# continuation
# --------------------------------------------------------------------------- #
def _check_scurve(res, increasing=True):
    assert isinstance(res, ContinuationResult)
    assert res.success and res.status == 0, res.message
    assert "reached end of span" in res.message
    assert np.all(scurve_residuals(res) <= 1e-9)
    assert len(res.folds) == 2
    fold_p = res.p[list(res.folds)]
    expected = [P_FOLD, -P_FOLD] if increasing else [-P_FOLD, P_FOLD]
    np.testing.assert_allclose(fold_p, expected, rtol=1e-6)
    assert res.p[-1] == (1.0 if increasing else -1.0)  # exactly the span end
    np.testing.assert_allclose(res.x[-1], X_END if increasing else -X_END, rtol=1e-9)


@pytest.mark.parametrize("sparse", [False, True])
def test_continuation_scurve_passes_two_folds(sparse):
    """x^3 - x - p over p in (-1, 1) from x0=-1.3: 2 folds at p=+-2/(3 sqrt3) (located, rtol 1e-6), ends at p=1, x=1.3247."""
    res = continuation(SCurve(sparse=sparse), (-1.0, 1.0), x0=[-1.3])
    _check_scurve(res, increasing=True)
    assert res.located == res.folds  # both inserted as turning points
    assert res.p[0] == -1.0
    assert res.x[0, 0] == pytest.approx(-X_END, rel=1e-9)


@pytest.mark.parametrize("sparse", [False, True])
def test_continuation_scurve_decreasing_span(sparse):
    """Same curve with p_span=(1, -1) from x0=1.3: folds at -p_f then +p_f, ends exactly at p=-1, x=-1.3247."""
    res = continuation(SCurve(sparse=sparse), (1.0, -1.0), x0=[1.3])
    _check_scurve(res, increasing=False)


def test_continuation_scurve_unlocated_folds_nearest_point():
    """Without fold localisation (max_step 0.05) the nearest points are within 1e-2 relative of the folds."""
    res = continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(locate_folds=False, max_step=0.05))
    assert res.success and len(res.folds) == 2 and res.located == ()  # detected only
    np.testing.assert_allclose(res.p[list(res.folds)], [P_FOLD, -P_FOLD], rtol=1e-2)
    assert res.p[-1] == 1.0


def test_continuation_scaled_norm_independent_of_n():
    """RMS-scaled arclength: n identical uncoupled copies give the same p-sequence as n=1 (1e-12) and x to 1e-6."""
    one = continuation(SCurve(), (-1.0, 1.0), x0=[-1.3])
    many = continuation(SCurve(n=40, sparse=True), (-1.0, 1.0), x0=np.full(40, -1.3))
    assert many.success and one.n_points == many.n_points
    np.testing.assert_allclose(many.p, one.p, rtol=0, atol=1e-12)
    np.testing.assert_allclose(many.x, np.repeat(one.x, 40, axis=1), rtol=0, atol=1e-6)
    assert many.folds == one.folds


def _duffing_peak(c, eps, F):
    """Exact maximum of a(w): 1 - w^2 + k a^2 = c^2/2 and a^2 c^2 (1 + k a^2 - c^2/4) = F^2 (k = 3 eps/4)."""
    k = 0.75 * eps
    A, B, C = k * c * c, c * c * (1 - c * c / 4), -F * F
    u = (-B + math.sqrt(B * B - 4 * A * C)) / (2 * A)
    return math.sqrt(u), math.sqrt(1 + k * u - c * c / 2)


@pytest.mark.parametrize("sparse", [False, True])
def test_continuation_duffing_frequency_response(sparse):
    """Duffing single-harmonic FRF over w in (0.5, 2.5): peak amplitude within 1e-3 relative of the exact peak
    (and never above it by more than 1e-9), two folds matching the exact fold conditions to 1e-6."""
    c, eps, F = 0.05, 1.0, 0.1
    prob = Duffing(c, eps, F, sparse=sparse)
    res = continuation(prob, (0.5, 2.5), x0=[F / (1 - 0.25), 0.0])
    assert res.success and res.status == 0, res.message
    assert res.p[-1] == 2.5
    for xi, wi in zip(res.x, res.p):
        assert np.max(np.abs(prob.residual(xi, wi)[0])) <= 1e-9
    amp = np.hypot(res.x[:, 0], res.x[:, 1])
    a_peak, w_peak = _duffing_peak(c, eps, F)
    assert amp.max() <= a_peak * (1 + 1e-9)
    assert amp.max() >= a_peak * (1 - 1e-3)
    assert res.p[np.argmax(amp)] == pytest.approx(w_peak, rel=1e-2)

    # folds: G(u, w) = u((1-w^2+k u)^2 + c^2 w^2) - F^2 = 0 and dG/du = 0
    assert len(res.folds) == 2
    k = 0.75 * eps

    def fold_eqs(z):
        u, w = z
        d = 1 - w * w + k * u
        return [u * (d * d + c * c * w * w) - F * F, d * d + c * c * w * w + 2 * k * u * d]

    for i in res.folds:
        u_f, w_f = scipy.optimize.fsolve(fold_eqs, [amp[i] ** 2, res.p[i]])
        assert np.max(np.abs(fold_eqs([u_f, w_f]))) <= 1e-10
        assert res.p[i] == pytest.approx(w_f, rel=1e-6)
        assert amp[i] ** 2 == pytest.approx(u_f, rel=1e-4)
    # the first fold (jump-down) is near the peak, the second (jump-up) at lower frequency
    assert res.p[res.folds[0]] > res.p[res.folds[1]]


def test_continuation_passes_kink_of_semismooth_branch():
    """Spring against an obstacle, p in (0, 2): kink at p=1 passed with <= 3 rejections; u=min(p,1), lam=max(0,p-1) to 1e-12."""
    res = continuation(SpringObstacle(), (0.0, 2.0), x0=[0.0, 0.0])
    assert res.success and res.status == 0, res.message
    assert res.n_rejected <= 3
    np.testing.assert_allclose(res.x[:, 0], np.minimum(res.p, 1.0), atol=1e-12)
    np.testing.assert_allclose(res.x[:, 1], np.maximum(res.p - 1.0, 0.0), atol=1e-12)
    assert res.p[-1] == 2.0 and res.folds == ()


def test_continuation_callback_stops_cleanly():
    """Callback returning False at the 5th point: exactly 5 points, status 3, success True, points consistent."""
    seen = []

    def cb(pt):
        assert isinstance(pt, ContinuationPoint)
        seen.append(pt)
        return len(seen) < 5

    res = continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(callback=cb))
    assert res.status == 3 and res.success
    assert "callback" in res.message
    assert res.n_points == 5 == len(seen)
    assert [pt.index for pt in seen] == list(range(5))
    np.testing.assert_array_equal(res.p, [pt.p for pt in seen])
    for pt in seen:
        assert pt.tangent.shape == (2,)
        assert pt.residual_norm <= 1e-9
    assert seen[0].step == 0.0 and all(pt.step > 0 for pt in seen[1:])


def test_continuation_callback_none_return_continues():
    """A callback returning None does not stop the run."""
    res = continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(callback=lambda pt: None))
    assert res.status == 0


@pytest.mark.parametrize("max_points", [2, 7, 12])
def test_continuation_max_points_respected(max_points):
    """max_points bounds the branch length exactly (fold insertion included): status 2, success True."""
    res = continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(max_points=max_points))
    assert res.n_points == max_points
    assert res.status == 2 and res.success
    assert "max_points" in res.message
    assert np.all(scurve_residuals(res) <= 1e-9)


def test_continuation_initial_correction_failure_reported():
    """No solution at p_span[0] (x^2 + 1 + p = 0 at p=0): success False, status 5, no exception, no points."""

    class NoRoot:
        def residual(self, x, p):
            return x**2 + 1.0 + p, np.diag(2 * x), np.ones(1)

    res = continuation(NoRoot(), (0.0, 1.0), x0=[0.5])
    assert not res.success and res.status == 5
    assert "initial correction" in res.message
    assert res.n_points == 0 and res.x.shape == (0, 1)


def test_continuation_uses_linear_solver_for_bordered_systems():
    """NewtonOptions.linear_solver is used for corrector and tangent solves (all of size n+1)."""
    shapes = []

    def solver(A, b):
        shapes.append(A.shape)
        return np.linalg.solve(A.toarray() if sp.issparse(A) else A, b)

    opts = ContinuationOptions(newton=NewtonOptions(atol=1e-9, max_iter=12, linear_solver=solver))
    res = continuation(SCurve(n=3, sparse=True), (-1.0, 1.0), x0=np.full(3, -1.3), options=opts)
    assert res.success
    assert (4, 4) in shapes and set(shapes) <= {(3, 3), (4, 4)}
    assert sum(s == (4, 4) for s in shapes) >= res.n_points


def test_continuation_store_tangents_unit_scaled_norm():
    """store_tangents: unit tangents in the scaled norm (1e-12) and dp/ds changes sign exactly at the folds."""
    res = continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(store_tangents=True))
    T = res.tangents
    assert T.shape == (res.n_points, 2)
    w = np.array([1.0 / res.x_scale[0] ** 2, 1.0 / res.p_scale**2])
    np.testing.assert_allclose(np.sqrt((w * T**2).sum(axis=1)), 1.0, atol=1e-12)
    assert res.p_scale == 2.0 and res.x_scale[0] == pytest.approx(X_END)
    for i in res.folds:
        assert abs(T[i, 1]) <= 1e-6


def test_continuation_direction_minus_one_leaves_span():
    """direction=-1 walks out of the span at once: 1 point, status 1 (left through p_span[0])."""
    res = continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(direction=-1))
    assert res.success and res.status == 1 and res.n_points == 1


def test_continuation_logs_progress_without_printing(capsys, caplog):
    with caplog.at_level(logging.INFO, logger="femodes.solvers.continuation"):
        continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(max_step=0.1))
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
    assert any("continuation: point 10" in rec.getMessage() for rec in caplog.records)


@pytest.mark.parametrize(
    ("kwargs", "exc", "pattern"),
    [
        ({"step": -0.1}, ValueError, r"step must be a positive finite number, got -0\.1"),
        ({"step": 1.0}, ValueError, r"step must satisfy .* got step=1\.0"),
        ({"min_step": 1.0, "max_step": 0.5}, ValueError, r"min_step must be <= max_step"),
        ({"max_points": 1}, ValueError, r"max_points .* got 1"),
        ({"target_iterations": 0}, ValueError, r"target_iterations .* got 0"),
        ({"max_growth": 0.5}, ValueError, r"max_growth must be >= 1, got 0\.5"),
        ({"direction": 0}, ValueError, r"direction must be \+1 or -1, got 0"),
        ({"direction": True}, ValueError, r"direction .* got True"),
        ({"x_scale": -1.0}, ValueError, r"x_scale .* got -1\.0"),
        ({"x_scale": [1.0, 0.0]}, ValueError, r"x_scale"),
        ({"p_scale": 0.0}, ValueError, r"p_scale .* got 0\.0"),
        ({"newton": {"atol": 1e-9}}, TypeError, r"newton must be a NewtonOptions"),
        ({"callback": 1}, TypeError, r"callback .* got 1"),
        ({"max_turn_angle": 200.0}, ValueError, r"max_turn_angle .* got 200\.0"),
    ],
)
def test_continuation_options_validation(kwargs, exc, pattern):
    with pytest.raises(exc, match=pattern):
        ContinuationOptions(**kwargs)


def test_continuation_input_validation():
    with pytest.raises(ValueError, match="p_span"):
        continuation(SCurve(), (1.0, 1.0), x0=[1.0])
    with pytest.raises(ValueError, match="p_span"):
        continuation(SCurve(), (0.0, np.inf), x0=[1.0])
    with pytest.raises(ValueError, match="x0"):
        continuation(SCurve(), (0.0, 1.0), x0=[np.nan])
    with pytest.raises(ValueError, match="x_scale"):
        continuation(SCurve(), (0.0, 1.0), x0=[1.0], options=ContinuationOptions(x_scale=[1.0, 2.0]))
    with pytest.raises(TypeError, match="residual"):
        continuation(object(), (0.0, 1.0), x0=[1.0])

    class BadShape:
        def residual(self, x, p):
            return np.zeros(2), np.eye(2), np.zeros(2)

    with pytest.raises(ValueError, match=r"\(2,\).*\(1,\)"):
        continuation(BadShape(), (0.0, 1.0), x0=[1.0])


@pytest.mark.parametrize("sigma_min", [1.0, 1e-8, 0.0])
def test_bordered_solver_matches_dense_solve(sigma_min):
    """Block elimination + refinement (sparse) equals a dense LU solve to 1e-9 relative, also for a nearly
    (1e-8) or exactly singular A (fold), where it falls back to the full LU of the bordered matrix."""
    from femodes.solvers.continuation import bordered_solver

    rng = np.random.default_rng(7)
    n = 60
    Q1, _ = np.linalg.qr(rng.normal(size=(n, n)))
    Q2, _ = np.linalg.qr(rng.normal(size=(n, n)))
    s = np.linspace(1.0, 3.0, n)
    s[0] = sigma_min
    A = Q1 @ np.diag(s) @ Q2.T
    b, c, h = rng.normal(size=n), rng.normal(size=n + 1), rng.normal(size=n + 1)
    M = np.block([[A, b[:, None]], [c[None, :]]])
    z_ref = np.linalg.solve(M, h)
    z = bordered_solver(sp.csc_matrix(M), h)
    assert np.max(np.abs(z - z_ref)) <= 1e-9 * np.max(np.abs(z_ref))
    np.testing.assert_allclose(bordered_solver(M, h), z_ref, rtol=1e-10, atol=0)


def test_bordered_solver_exactly_singular_block():
    """A with an exactly zero column (SuperLU 'singular'): falls back to the full LU, residual at round-off."""
    from femodes.solvers.continuation import bordered_solver

    A = sp.eye(5, format="lil")
    A[2, 2] = 0.0
    M = sp.bmat(
        [[A.tocsr(), sp.csr_matrix(np.ones((5, 1)))], [sp.csr_matrix(np.arange(1.0, 6.0)[None, :]), None]],
        format="csc",
    )
    h = np.arange(6.0)
    z = bordered_solver(M, h)
    # backward-stable LU: residual <= n eps |M||z| (|M||z| ~ 23 here, so the former 1e-14 was 2 eps |M||z|)
    assert np.max(np.abs(M @ z - h)) <= 6 * np.finfo(float).eps * np.max(abs(M) @ np.abs(z))


@pytest.mark.parametrize("gap", [1e-3, 1e-5])
@pytest.mark.parametrize("max_step", [0.5, 0.05])
def test_continuation_span_end_just_below_fold(gap, max_step):
    """p_span ends just before the fold: stop exactly at p_end on the lower branch (x < -1/sqrt3), no fold,
    no point beyond p_end."""
    p_end = P_FOLD - gap
    res = continuation(SCurve(), (-1.0, p_end), x0=[-1.3], options=ContinuationOptions(max_step=max_step))
    assert res.status == 0 and res.p[-1] == p_end
    assert res.folds == ()
    assert np.all(res.p <= p_end)
    assert res.x[-1, 0] < -1.0 / math.sqrt(3.0)
    assert np.all(scurve_residuals(res) <= 1e-9)


def test_newton_watchdog_contact_chain_large_c():
    """Contact chain with c in [100, 1000] from 40 random starts: all converge (1e-9) in <= 8 iterations
    with the default watchdog; the plain non-monotone line search (watchdog=0) needs strictly more in total."""
    rng = np.random.default_rng(11)
    total = {3: 0, 0: 0}
    for trial in range(40):
        fun, y_star = contact_chain(n=30, c=10 ** rng.uniform(2, 3), seed=100 + trial)
        y0 = rng.normal(size=60) * 10 ** rng.uniform(-1, 1)
        res = semismooth_newton(fun, y0)
        assert res.success, res.message
        assert res.nit <= 8
        assert np.max(np.abs(res.x - y_star)) <= 1e-9
        total[3] += res.nit
        total[0] += semismooth_newton(fun, y0, options=NewtonOptions(watchdog=0)).nit
    assert total[3] < total[0]


def test_newton_stagnation_window_option():
    """arctan from x0=100 (very flat merit) with the non-monotone search: stops with status 2, converges with stagnation_window=0.

    (The default monotone Armijo search converges directly from x0=100.)"""
    assert semismooth_newton(_arctan, [100.0]).success
    res = semismooth_newton(_arctan, [100.0], options=NewtonOptions(nonmonotone_memory=5))
    assert res.status == 2
    res = semismooth_newton(_arctan, [100.0], options=NewtonOptions(nonmonotone_memory=5, stagnation_window=0, max_iter=200))
    assert res.success and abs(res.x[0]) <= 1e-10


# --------------------------------------------------------------------------- #
# resuming a run from a saved state (continuation(start=...))
# --------------------------------------------------------------------------- #
RESUME_CASES = {
    "scurve, located folds": (lambda: SCurve(), (-1.0, 1.0), [-1.3], {}),
    "scurve, unlocated folds": (lambda: SCurve(), (-1.0, 1.0), [-1.3], {"locate_folds": False}),
    "scurve sparse, decreasing span": (lambda: SCurve(3, sparse=True), (1.0, -1.0), [1.3] * 3, {"every": 4}),
    "duffing": (lambda: Duffing(0.1, 1.0, 0.3), (0.5, 2.5), [0.3, 0.0], {}),
    "duffing, unlocated folds": (lambda: Duffing(0.1, 1.0, 0.3), (0.5, 2.5), [0.3, 0.0], {"locate_folds": False}),
    "kink": (lambda: SpringObstacle(), (0.0, 2.0), [0.0, 0.0], {}),
}


@pytest.mark.parametrize("case", list(RESUME_CASES))
def test_continuation_resume_from_every_point_equals_uninterrupted_run(case):
    """Stop after point k (callback returns False), resume with start=point.state: the two parts together
    are the uninterrupted branch, point for point (bitwise: same steps, tangents, folds, counters), the
    start point not repeated. For every k, through folds (located or not) and kinks."""
    make, span, x0, kw = RESUME_CASES[case]
    kw = dict(kw)
    every = kw.pop("every", 1)  # the sparse case is slower: every 4th point
    full = continuation(make(), span, x0=x0, options=ContinuationOptions(**kw))
    assert full.status == 0
    n_resumed = 0
    for k in [*range(0, full.n_points - 1, every), full.n_points - 1]:
        seen = []

        def stop_at_k(pt):
            seen.append(pt)
            return pt.index < k

        part = continuation(make(), span, x0=x0, options=ContinuationOptions(callback=stop_at_k, **kw))
        assert [pt.index for pt in seen] == list(range(part.n_points))
        state = seen[-1].state
        if k == full.n_points - 1:
            assert state is None and part.status == 0  # the end point: nothing to continue
            continue
        if state is None:  # an inserted fold point: the run continues from the point before it
            assert seen[-1].is_fold and kw.get("locate_folds", True)
            state = seen[-2].state
        rest = continuation(make(), span, start=state, options=ContinuationOptions(**kw))
        assert rest.first_index == state.index + 1
        X = np.vstack([part.x[: state.index + 1], rest.x])
        P = np.concatenate([part.p[: state.index + 1], rest.p])
        np.testing.assert_array_equal(X, full.x)
        np.testing.assert_array_equal(P, full.p)
        np.testing.assert_array_equal(rest.nit, full.nit[state.index + 1 :])
        assert rest.folds == full.folds and rest.status == full.status
        assert (rest.n_newton, rest.n_rejected) == (full.n_newton, full.n_rejected)
        n_resumed += 1
    assert n_resumed >= (full.n_points - 1) // every - len(full.folds)


def test_continuation_state_of_points():
    """Every regular point carries a state (next step in bounds, scales of the run, folds so far);
    inserted fold points and the end point do not."""
    seen = []
    res = continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(callback=seen.append))
    assert res.folds == (5, 12)  # indices depend on the step control (issue 16: (6, 10) -> (5, 12))
    for pt in seen:
        st = pt.state
        if pt.is_fold or pt.index == res.n_points - 1:
            assert st is None
            continue
        assert st.index == pt.index and st.p == pt.p and st.x is pt.x
        np.testing.assert_array_equal(st.tangent, pt.tangent)
        assert 1e-6 <= st.step <= 0.5 and st.dp_sign == np.sign(pt.tangent[-1])
        np.testing.assert_array_equal(st.x_scale, res.x_scale)
        assert st.p_scale == res.p_scale
        assert st.folds == tuple(i for i in res.folds if i <= pt.index)
        assert not st.x.flags.writeable and not st.tangent.flags.writeable


def test_continuation_resume_respects_max_points_and_new_step_bounds():
    """max_points counts the whole branch; a resumed run may change the options (the step is clipped)."""
    seen = []
    continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(callback=seen.append, max_points=4))
    state = seen[-1].state
    assert state.index == 3
    rest = continuation(SCurve(), (-1.0, 1.0), start=state, options=ContinuationOptions(max_points=4))
    assert rest.status == 2 and rest.n_points == 0 and rest.first_index == 4
    rest = continuation(SCurve(), (-1.0, 1.0), start=state, options=ContinuationOptions(max_points=8, max_step=0.01,
                                                                                         step=0.01))
    assert rest.status == 2 and rest.n_points == 4 and np.all(rest.step <= 0.01 + 1e-15)
    assert np.all(scurve_residuals(rest) <= 1e-9)


def test_continuation_start_validation():
    from femodes.solvers.continuation import ContinuationState

    seen = []
    continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], options=ContinuationOptions(callback=seen.append, max_points=3))
    st = seen[-1].state
    with pytest.raises(ValueError, match="either x0= .* or start="):
        continuation(SCurve(), (-1.0, 1.0), x0=[-1.3], start=st)
    with pytest.raises(TypeError, match="start must be a ContinuationState"):
        continuation(SCurve(), (-1.0, 1.0), start={"x": [1.0]})
    with pytest.raises(ValueError, match="outside p_span"):
        continuation(SCurve(), (0.5, 1.0), start=st)
    good = dict(x=[1.0], p=0.0, tangent=[0.6, 0.8], step=0.1, index=3, folds=(), dp_sign=1, x_scale=[1.0], p_scale=2.0)
    assert ContinuationState(**good).folds == ()
    for change, pattern in [
        ({"tangent": [1.0]}, r"tangent has shape \(1,\), expected \(2,\)"),
        ({"x_scale": [0.0]}, "x_scale must be positive"),
        ({"x": [np.nan]}, "x contains non-finite"),
        ({"step": 0.0}, r"ContinuationState.step must be a positive"),
        ({"folds": (5,)}, r"folds must be indices in \[0, index=3\]"),
        ({"dp_sign": 0.0}, "dp_sign must be"),
        ({"p": "a"}, "p must be a finite real number"),
    ]:
        with pytest.raises(ValueError, match=pattern):
            ContinuationState(**{**good, **change})
    with pytest.raises(TypeError, match="ContinuationState.index"):
        ContinuationState(**{**good, "index": 1.5})
