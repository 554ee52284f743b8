"""Tests of femodes.hbm.harmonics (Fourier layout, operators, exact positive part).

The references used here are independent of the module under test: an
explicit basis, FFT sampling on fine grids, root bracketing with
scipy.optimize.brentq and Gauss-Legendre quadrature on the positive intervals.
"""

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.fft import next_fast_len
from scipy.optimize import brentq

from femodes.hbm.harmonics import Harmonics
from femodes.hbm import ColleagueRoots, CompanionRoots, ExactProjection, GridRoots, SampledProjection

ROOTS = {"colleague": ColleagueRoots(), "companion": CompanionRoots(), "grid": GridRoots()}

TWO_PI = 2.0 * np.pi


# --------------------------------------------------------------- references
def basis(H, x):
    """[1, cos x, sin x, ..., cos Hx, sin Hx] written out independently."""
    x = np.asarray(x, dtype=float)
    cols = [np.ones_like(x)]
    for k in range(1, H + 1):
        cols += [np.cos(k * x), np.sin(k * x)]
    return np.stack(cols, axis=-1)


def series(phi, x):
    return basis((len(phi) - 1) // 2, x) @ phi


def series_derivative(phi, x):
    """d/dx of the series: sum_k k (-c_k sin kx + s_k cos kx)."""
    H = (len(phi) - 1) // 2
    k = np.arange(1, H + 1)
    x = np.asarray(x, dtype=float)[..., None]
    return (k * (-phi[1::2] * np.sin(k * x) + phi[2::2] * np.cos(k * x))).sum(axis=-1)


def norms(H):
    return np.r_[1.0 / TWO_PI, np.full(2 * H, 1.0 / np.pi)]


def fine_samples(phi, N):
    """Samples of the series on N equidistant phases via the inverse real FFT."""
    H = (phi.shape[0] - 1) // 2
    X = np.zeros((N // 2 + 1,) + phi.shape[1:], dtype=complex)
    X[0] = N * phi[0]
    X[1 : H + 1] = 0.5 * N * (phi[1::2] - 1j * phi[2::2])
    return np.fft.irfft(X, N, axis=0)


def fine_coefficients(u, H):
    """Trapezoidal-rule Fourier coefficients [c0, c1, s1, ...] of samples u."""
    N = u.shape[0]
    Y = np.fft.rfft(u, axis=0) / N
    out = np.empty((2 * H + 1,) + u.shape[1:])
    out[0] = Y[0].real
    out[1::2] = 2.0 * Y[1 : H + 1].real
    out[2::2] = -2.0 * Y[1 : H + 1].imag
    return out


def brute_force_positive(phi, N=2**18):
    """max(0, phi) projected with the rectangle rule on N points (error O(N^-2))."""
    H = (len(phi) - 1) // 2
    return fine_coefficients(np.maximum(fine_samples(phi, N), 0.0), H)


def reference_intervals(phi, n_grid=2**15):
    """Positive intervals: sign changes on a fine grid refined by brentq."""
    x = TWO_PI * np.arange(n_grid + 1) / n_grid
    f = series(phi, x)
    roots = [
        brentq(lambda t: series(phi, t), x[i], x[i + 1], xtol=1e-15, rtol=1e-15)
        for i in np.nonzero(np.sign(f[:-1]) * np.sign(f[1:]) < 0)[0]
    ]
    pts = np.concatenate([[0.0], roots, [TWO_PI]])
    return [(a, b) for a, b in zip(pts[:-1], pts[1:]) if series(phi, 0.5 * (a + b)) > 0]


def reference_gram(H, intervals, piece=0.25, n_gl=64):
    """G_ab = norm_a int_{intervals} b_a b_b by composite Gauss-Legendre.

    Pieces of length <= 0.25 with 64 nodes integrate trigonometric products of
    degree <= 2H = 120 to machine precision.
    """
    xg, wg = np.polynomial.legendre.leggauss(n_gl)
    M = np.zeros((2 * H + 1, 2 * H + 1))
    for a, b in intervals:
        edges = np.linspace(a, b, max(1, int(np.ceil((b - a) / piece))) + 1)
        for lo, hi in zip(edges[:-1], edges[1:]):
            B = basis(H, 0.5 * (hi + lo) + 0.5 * (hi - lo) * xg)
            M += (B * (0.5 * (hi - lo) * wg)[:, None]).T @ B
    return norms(H)[:, None] * M


def root_gram_tol(phi, roots):
    """Round-off allowed in G computed from the roots of phi (sharp near tangency).

    The module accepts a root once |phi| <= 8 eps sum|phi_k| (its rounding
    bound, see h.galerkin.positive_part), i.e. within 8 eps sum|phi_k| / |phi'|
    of the exact root; a second evaluation (the brentq reference on ``series``,
    evaluated to a few eps sum|phi_k|, or the module with another summation
    order) is held to the same bound, so the two roots differ by
    <= 16 eps sum|phi_k| / |phi'(root)|.  dG_ab / d root = -+ n_a b_a b_b with
    |n_a b_a b_b| <= 1/pi, hence |dG| <= sum over roots of
    16 eps sum|phi_k| / (pi |phi'(root)|); the same 16 eps / pi per root also
    covers the rounding of the antiderivative sums (terms of size <= 1).
    Measured (OpenBLAS 0.3.31, several kernels): <= 0.11 of it near tangency, <= 0.45 in 2.6e4
    random draws (G(7.5 phi) vs G(phi)), <= 0.04 batched vs single.
    """
    roots = np.asarray(roots, dtype=float)
    slopes = np.abs(series_derivative(phi, roots))
    return 16 * np.finfo(float).eps / np.pi * (np.abs(phi).sum() * np.sum(1.0 / slopes) + roots.size)


def interval_roots(iv):
    """End points of positive intervals (the sign changes); none for [[0, 2 pi]]."""
    iv = np.asarray(iv, dtype=float).reshape(-1, 2)
    if len(iv) == 1 and iv[0, 0] == 0.0 and iv[0, 1] == TWO_PI:
        return np.zeros(0)
    return iv.ravel()


def random_phi(rng, H, m=None, offset=0.0):
    shape = (2 * H + 1,) if m is None else (2 * H + 1, m)
    phi = rng.standard_normal(shape)
    phi[0] += offset
    return phi


# ------------------------------------------------------------- construction
@pytest.mark.parametrize(
    "kwargs, exc, words",
    [
        ({"n_harmonics": True}, TypeError, ["n_harmonics", "True"]),
        ({"n_harmonics": 3.0}, TypeError, ["n_harmonics", "3.0"]),
        ({"n_harmonics": "3"}, TypeError, ["n_harmonics", "'3'"]),
        ({"n_harmonics": -1}, ValueError, ["n_harmonics", "-1"]),
        ({"n_harmonics": 3, "n_time": 6}, ValueError, ["n_time", "6"]),
        ({"n_harmonics": 3, "n_time": 7.0}, TypeError, ["n_time", "7.0"]),
        ({"n_harmonics": 3, "subharmonic": 0}, ValueError, ["subharmonic", "0"]),
        ({"n_harmonics": 3, "subharmonic": 2.0}, TypeError, ["subharmonic", "2.0"]),
    ],
)
def test_invalid_arguments_are_rejected_with_name_and_value(kwargs, exc, words):
    with pytest.raises(exc) as info:
        Harmonics(**kwargs)
    for word in words:
        assert word in str(info.value)


def test_immutable_hashable_picklable():
    h = Harmonics(4, subharmonic=2)
    with pytest.raises(AttributeError):
        h.n_harmonics = 5
    with pytest.raises(AttributeError):
        h._H = 5
    with pytest.raises(ValueError):
        h.grid.synthesis()[0, 0] = 1.0  # cached operators are read-only
    assert h == Harmonics(4, subharmonic=2) and hash(h) == hash(Harmonics(4, subharmonic=2))
    assert h != Harmonics(4) and h != Harmonics(4, n_time=31, subharmonic=2)
    assert pickle.loads(pickle.dumps(h)) == h
    assert Harmonics(np.int64(3)).n_harmonics == 3
    assert "n_harmonics=4" in repr(h)


@pytest.mark.parametrize("H", range(1, 41))
def test_default_n_time_is_alias_free_for_cubic_and_fast(H):
    h = Harmonics(H)
    assert h.n_time >= 4 * H + 1
    assert h.n_time == next_fast_len(4 * H + 1, real=True)
    assert h.n_coef == 2 * H + 1
    assert Harmonics(H, n_time=2 * H + 1).n_time == 2 * H + 1


# ------------------------------------------------------------------- layout
def test_layout_indices_and_global_vector():
    H, n = 3, 4
    h = Harmonics(H)
    assert h.layout.cos_index(0) == 0
    assert [h.layout.cos_index(k) for k in range(1, H + 1)] == [1, 3, 5]
    assert [h.layout.sin_index(k) for k in range(1, H + 1)] == [2, 4, 6]
    np.testing.assert_array_equal(h.layout.cos_rows(np.arange(1, H + 1)), [1, 3, 5])
    np.testing.assert_array_equal(h.layout.sin_rows(np.arange(1, H + 1)), [2, 4, 6])
    with pytest.raises(TypeError, match="k must be an integer"):
        h.layout.cos_index(np.arange(1, H + 1))  # one harmonic, one row (several: cos_rows)
    np.testing.assert_array_equal(h.layout.harmonic_of, [0, 1, 1, 2, 2, 3, 3])
    np.testing.assert_array_equal(h.layout.is_sine, [0, 0, 1, 0, 1, 0, 1])
    for bad in (-1, H + 1):
        with pytest.raises(ValueError):
            h.layout.cos_index(bad)
    with pytest.raises(ValueError):
        h.layout.sin_index(0)

    Q = np.arange(h.n_coef * n, dtype=float).reshape(h.n_coef, n)
    x = h.layout.flatten(Q)
    for j in range(h.n_coef):
        for i in range(n):
            assert x[h.layout.global_index(j, i, n)] == Q[j, i]
    dofs = np.array([3, 1])
    idx = h.layout.global_index(np.arange(h.n_coef)[:, None], dofs, n)
    assert idx.shape == (h.n_coef, 2)
    np.testing.assert_array_equal(x[idx], Q[:, dofs])
    np.testing.assert_array_equal(h.layout.reshape(x, n), Q)
    assert h.layout.size(n) == x.size
    with pytest.raises(ValueError):
        h.layout.global_index(0, n, n)
    with pytest.raises(ValueError):
        h.layout.reshape(x[:-1], n)


def test_kron_convention_matches_harmonic_major_layout():
    rng = np.random.default_rng(0)
    h = Harmonics(2)
    n = 3
    A = rng.standard_normal((h.n_coef, h.n_coef))
    B = rng.standard_normal((n, n))
    Q = rng.standard_normal((h.n_coef, n))
    np.testing.assert_allclose(np.kron(A, B) @ h.layout.flatten(Q), h.layout.flatten(A @ Q @ B.T), atol=1e-13)


# --------------------------------------------------------- grids, operators
@pytest.mark.parametrize("H, N", [(1, None), (5, None), (5, 11), (5, 12), (20, None)])
def test_analysis_inverts_synthesis(H, N):
    h = Harmonics(H, n_time=N)
    E, P = h.grid.synthesis(), h.grid.analysis()
    assert E.shape == (h.n_time, h.n_coef) and P.shape == (h.n_coef, h.n_time)
    np.testing.assert_allclose(P @ E, np.eye(h.n_coef), atol=1e-13)
    np.testing.assert_allclose(E, basis(H, h.grid.phases()), atol=1e-14)
    np.testing.assert_allclose(h.grid.synthesis([0.3, 1.2]), basis(H, [0.3, 1.2]), atol=1e-14)


@settings(max_examples=60, deadline=None)
@given(
    H=st.integers(1, 30),
    n=st.integers(1, 4),
    extra=st.integers(0, 7),
    seed=st.integers(0, 2**32 - 1),
)
def test_time_round_trip(H, n, extra, seed):
    rng = np.random.default_rng(seed)
    h = Harmonics(H, n_time=2 * H + 1 + extra)
    Q = rng.standard_normal((h.n_coef, n))
    U = h.grid.to_time(Q)
    assert U.shape == (h.n_time, n)
    np.testing.assert_allclose(h.grid.from_time(U), Q, atol=1e-12 * (1 + np.abs(Q).max()))
    np.testing.assert_allclose(h.grid.from_time(h.grid.to_time(Q[:, 0])), Q[:, 0], atol=1e-12 * (1 + np.abs(Q).max()))
    np.testing.assert_allclose(U, fine_samples(Q, h.n_time), atol=1e-12 * (1 + np.abs(Q).max()))


@pytest.mark.parametrize("nu", [1, 2, 3])
def test_times_period_frequencies_and_evaluate(nu):
    rng = np.random.default_rng(nu)
    h = Harmonics(4, subharmonic=nu)
    omega = 2.7
    assert h.grid.period(omega) == pytest.approx(TWO_PI * nu / omega, rel=1e-15)
    np.testing.assert_allclose(h.grid.times(omega), h.grid.period(omega) * np.arange(h.n_time) / h.n_time)
    np.testing.assert_allclose(h.grid.frequencies(omega), h.layout.harmonic_of * omega / nu)
    Q = rng.standard_normal((h.n_coef, 2))
    np.testing.assert_allclose(h.grid.evaluate(Q, omega, h.grid.times(omega)), h.grid.to_time(Q), atol=1e-13)
    t = rng.uniform(0, 10, 7)
    np.testing.assert_allclose(
        h.grid.evaluate(Q, omega, t + h.grid.period(omega)), h.grid.evaluate(Q, omega, t), atol=1e-12
    )
    # explicit formula: u(t) = sum_k c_k cos(k omega t/nu) + s_k sin(...)
    u = Q[0, 0] + sum(
        Q[2 * k - 1, 0] * np.cos(k * omega * t / nu) + Q[2 * k, 0] * np.sin(k * omega * t / nu)
        for k in range(1, 5)
    )
    np.testing.assert_allclose(h.grid.evaluate(Q[:, 0], omega, t), u, atol=1e-13)
    with pytest.raises(ValueError):
        h.grid.period(0.0)


@pytest.mark.parametrize("nu", [1, 3])
def test_derivative_operator(nu):
    rng = np.random.default_rng(7)
    h = Harmonics(6, subharmonic=nu)
    omega = 1.9
    D = h.operators.derivative(omega)
    np.testing.assert_allclose(D, -D.T)
    # analytic: u = 3 cos(2Wt) - 0.5 sin(Wt) + 0.2, W = omega/nu
    W = omega / nu
    q = np.zeros(h.n_coef)
    q[0], q[h.layout.cos_index(2)], q[h.layout.sin_index(1)] = 0.2, 3.0, -0.5
    t = np.linspace(0, 5, 13)
    du = -6 * W * np.sin(2 * W * t) - 0.5 * W * np.cos(W * t)
    np.testing.assert_allclose(h.grid.evaluate(D @ q, omega, t), du, atol=1e-12)
    # central finite differences in time, random multi-signal coefficients
    Q = rng.standard_normal((h.n_coef, 3))
    dt = 1e-5
    fd = (h.grid.evaluate(Q, omega, t + dt) - h.grid.evaluate(Q, omega, t - dt)) / (2 * dt)
    np.testing.assert_allclose(h.grid.evaluate(D @ Q, omega, t), fd, rtol=1e-7, atol=1e-7 * np.abs(fd).max())
    # dD/domega (D is linear in omega)
    dw = 1e-6
    np.testing.assert_allclose(
        h.operators.derivative_domega(), (h.operators.derivative(omega + dw) - h.operators.derivative(omega - dw)) / (2 * dw), atol=1e-8
    )


def test_norm_weights_give_period_average_of_products():
    rng = np.random.default_rng(1)
    h = Harmonics(5)
    U, V = rng.standard_normal((2, h.n_coef))
    N = 64
    average = np.mean(fine_samples(U, N) * fine_samples(V, N))
    assert np.sum(h.galerkin.norm_weights() * U * V) == pytest.approx(average, rel=1e-13)
    # projection normalisation: coefficient = norm * int f b over a period
    np.testing.assert_allclose(h.galerkin.projection_norms(), norms(5))
    np.testing.assert_allclose(h.grid.analysis(), (TWO_PI / h.n_time) * norms(5)[:, None] * h.grid.synthesis().T)


@pytest.mark.parametrize("H", [1, 3, 8, 15])
def test_cubic_galerkin_is_alias_free_with_default_n_time(H):
    rng = np.random.default_rng(H)
    h = Harmonics(H)
    Q = rng.standard_normal((h.n_coef, 2))
    exact = fine_coefficients(fine_samples(Q, 32 * h.n_coef) ** 3, H)
    aft = h.grid.from_time(h.grid.to_time(Q) ** 3)
    np.testing.assert_allclose(aft, exact, atol=1e-12 * np.abs(exact).max())
    # N = 2H + 1 is enough to represent u but aliases u^3
    h_min = Harmonics(H, n_time=2 * H + 1)
    aliased = h_min.grid.from_time(h_min.grid.to_time(Q) ** 3)
    assert np.abs(aliased - exact).max() > 1e-2 * np.abs(exact).max()


# ------------------------------------------------------- exact positive part
@pytest.mark.parametrize("H", [1, 2, 5, 20, 40])
def test_positive_part_against_brute_force_grid(H):
    """Rectangle rule on 2^18 points converges like h^2 at the kinks:
    expected relative error ~1e-9 (measured: 0 for H = 0, <= 5e-11 for H <= 2,
    <= 2e-10 for H = 5, 1e-9..3e-9 for H = 20, 5e-9..8e-9 for H = 40)."""
    rng = np.random.default_rng(100 + H)
    h = Harmonics(H)
    for trial in range(3):
        phi = random_phi(rng, H, offset=0.3 * trial)
        proj, G = h.galerkin.positive_part(phi)
        ref = brute_force_positive(phi)
        assert np.abs(proj - ref).max() <= 2e-8 * np.abs(phi).max()
        assert proj.shape == phi.shape and G.shape == (h.n_coef, h.n_coef)


@pytest.mark.parametrize("method", ["colleague", "companion"])
@pytest.mark.parametrize("H", [1, 2, 5, 20, 40])
def test_positive_part_and_jacobian_against_quadrature_reference(H, method):
    rng = np.random.default_rng(H)
    h = Harmonics(H)
    for trial in range(2):
        phi = random_phi(rng, H, offset=0.5 * trial)
        iv = reference_intervals(phi)
        G_ref = reference_gram(H, iv)
        proj, G = h.galerkin.positive_part(phi, roots=ROOTS[method])
        # 1e-13: quadrature and brentq (xtol 1e-15) of the reference; root_gram_tol: the roots'
        # conditioning and G's sums over up to 2H roots (<= 3e-14 here; measured |G - G_ref| <= 2.6e-15)
        roots = [r for ab in iv for r in ab if 0.0 < r < TWO_PI]
        np.testing.assert_allclose(G, G_ref, rtol=0, atol=1e-13 + root_gram_tol(phi, roots))
        np.testing.assert_allclose(proj, G_ref @ phi, rtol=0, atol=1e-13 * np.abs(phi).max())


@settings(max_examples=60, deadline=None)
@given(H=st.integers(1, 12), seed=st.integers(0, 2**32 - 1), offset=st.floats(-3, 3), scale=st.floats(1e-6, 1e6))
def test_positive_part_structure(H, seed, offset, scale):
    """proj = G phi; diag(1/norm) G symmetric; normalised G is a projection-like
    operator with eigenvalues in [0, 1]; G[0, 0] is the contact fraction."""
    rng = np.random.default_rng(seed)
    h = Harmonics(H)
    phi = scale * random_phi(rng, H, offset=offset)
    proj, G = h.galerkin.positive_part(phi)
    np.testing.assert_allclose(proj, G @ phi, rtol=0, atol=1e-14 * np.abs(phi).max() * h.n_coef)
    M = G / norms(H)[:, None]
    np.testing.assert_allclose(M, M.T, atol=1e-13)
    s = np.sqrt(norms(H))
    eig = np.linalg.eigvalsh(s[:, None] * M * s[None, :])
    assert eig.min() >= -1e-12 and eig.max() <= 1 + 1e-12
    iv = h.galerkin.positive_intervals(phi)
    assert G[0, 0] == pytest.approx(np.sum(iv[:, 1] - iv[:, 0]) / TWO_PI, abs=1e-13)
    # positive homogeneity: G(a phi) = G(phi) for a > 0; 7.5 phi is rounded, so its roots move
    # by ~eps sum|phi_k| / |phi'| (large near tangency: 0.8e-13 seen in 2e4 random draws)
    np.testing.assert_allclose(h.galerkin.positive_part(7.5 * phi)[1], G, atol=1e-13 + root_gram_tol(phi, interval_roots(iv)))


@pytest.mark.parametrize("H", [1, 4, 20])
def test_positive_part_one_signed_and_zero(H):
    h = Harmonics(H)
    rng = np.random.default_rng(H)
    phi = 0.01 * random_phi(rng, H)
    phi[0] = 1.0 + np.abs(phi[1:]).sum()  # positive everywhere
    proj, G = h.galerkin.positive_part(phi)
    np.testing.assert_array_equal(G, np.eye(h.n_coef))
    np.testing.assert_array_equal(proj, phi)
    proj, G = h.galerkin.positive_part(-phi)
    np.testing.assert_array_equal(G, 0.0)
    np.testing.assert_array_equal(proj, 0.0)
    proj, G = h.galerkin.positive_part(np.zeros(h.n_coef))
    np.testing.assert_array_equal(G, 0.0)
    np.testing.assert_array_equal(proj, 0.0)
    assert h.galerkin.positive_intervals(phi).tolist() == [[0.0, TWO_PI]]
    assert h.galerkin.positive_intervals(-phi).shape == (0, 2)


@pytest.mark.parametrize("method", ["colleague", "companion"])
@pytest.mark.parametrize("theta0", [0.0, 1.0, 0.7390851332151607, np.pi])
@pytest.mark.parametrize("delta", [0.0, 1e-12, -1e-13, -1e-10, -1e-6, -1e-2])
def test_positive_part_near_tangency(theta0, delta, method):
    """phi = 1 + delta - cos(theta - theta0): double root at theta0 for delta = 0.

    The root positions are ill-conditioned, |d root| ~ eps / |phi'| with
    |phi'| = sqrt(2 |delta|): the tolerance is 1e-13 + root_gram_tol, i.e.
    ~14 eps / sqrt(|delta|) (measured errors up to 1.05 eps sum|phi_k| / |phi'|
    = 0.1 root_gram_tol, colleague, theta0 = 1, OpenBLAS 0.3.31).  A G = I
    answer (tangency missed) would be off by 2 beta / pi >= 23 tol."""
    h = Harmonics(5)
    phi = np.zeros(h.n_coef)
    phi[0], phi[1], phi[2] = 1.0 + delta, -np.cos(theta0), -np.sin(theta0)
    proj, G = h.galerkin.positive_part(phi, roots=ROOTS[method])
    if delta >= 0:
        np.testing.assert_array_equal(G, np.eye(h.n_coef))
        return
    beta = np.arccos(1.0 + delta)
    f = lambda t: series(phi, t)  # noqa: E731
    a = brentq(f, theta0 - 2 * beta, theta0, xtol=1e-16, rtol=1e-15)
    b = brentq(f, theta0, theta0 + 2 * beta, xtol=1e-16, rtol=1e-15)
    G_ref = np.eye(h.n_coef) - reference_gram(5, [(a, b)])
    tol = 1e-13 + root_gram_tol(phi, [a, b])
    np.testing.assert_allclose(G, G_ref, rtol=0, atol=tol)
    np.testing.assert_allclose(proj, G_ref @ phi, rtol=0, atol=tol)


def test_positive_part_higher_degree_tangency():
    """phi = (1 - cos(theta - 2))(2 + sin 3 theta) - 1e-9 (degree 4), short negative interval.

    The roots a < b are 7e-5 apart with |phi'(a)|, |phi'(b)| ~ 6e-5, so
    rounding moves them by ~eps sum|phi_k| / |phi'| = 2.6e-11 (not eps): the
    tolerance is root_gram_tol (2.7e-10 here).  Measured |G - G_ref| <= 1.2e-11
    (roots off by <= 1.3 eps sum|phi_k| / |phi'|) with OpenBLAS 0.3.31; a
    root off by 1e-8 moves G by 3.1e-9 > 10 tol (checked below).
    """
    h = Harmonics(6)
    x = TWO_PI * np.arange(64) / 64
    u = (1 - np.cos(x - 2.0)) * (2 + np.sin(3 * x)) - 1e-9
    phi = np.zeros(h.n_coef)
    phi[:9] = fine_coefficients(u, 4)
    f = lambda t: series(phi, t)  # noqa: E731
    a = brentq(f, 1.9, 2.0, xtol=1e-16, rtol=1e-15)
    b = brentq(f, 2.0, 2.1, xtol=1e-16, rtol=1e-15)
    assert 0 < b - a < 1e-4
    tol = root_gram_tol(phi, [a, b])
    G_ref = np.eye(h.n_coef) - reference_gram(6, [(a, b)])
    # the tolerance still resolves a root error of 1e-8
    assert np.abs(reference_gram(6, [(a + 1e-8, b)]) - reference_gram(6, [(a, b)])).max() > 10 * tol
    for method in ("colleague", "companion"):
        proj, G = h.galerkin.positive_part(phi, roots=ROOTS[method])
        np.testing.assert_allclose(G, G_ref, rtol=0, atol=tol)


@pytest.mark.parametrize("H", [1, 3, 10])
def test_positive_part_jacobian_matches_finite_differences(H):
    """Central differences with step 1e-6 |phi|: truncation O(step^2 / root gap),
    rounding O(eps / step); required agreement 1e-6 relative to max|G|."""
    rng = np.random.default_rng(11 + H)
    h = Harmonics(H)
    phi = random_phi(rng, H, offset=0.2)
    proj, G = h.galerkin.positive_part(phi)
    step = 1e-6 * np.abs(phi).max()
    J = np.empty_like(G)
    for b in range(h.n_coef):
        e = np.zeros(h.n_coef)
        e[b] = step
        J[:, b] = (h.galerkin.positive_part(phi + e)[0] - h.galerkin.positive_part(phi - e)[0]) / (2 * step)
    np.testing.assert_allclose(J, G, rtol=0, atol=1e-6 * np.abs(G).max())


@pytest.mark.parametrize("method", ["colleague", "companion"])
def test_positive_part_batched_equals_loop(method):
    rng = np.random.default_rng(5)
    H = 8
    h = Harmonics(H)
    phi = random_phi(rng, H, m=9)
    phi[:, 1] = 0.0  # identically zero
    phi[0, 2] = 50.0  # positive everywhere
    phi[0, 3] = -50.0  # negative everywhere
    phi[7:, 4] = 0.0  # effective degree 3
    phi[1:, 5] = 0.0  # constant
    phi[3:, 6] = 0.0  # effective degree 1
    phi[:, 7] *= 1e-9  # small scale
    proj, G = ExactProjection(roots=ROOTS[method])(h, phi)
    assert proj.shape == phi.shape and G.shape == (9, h.n_coef, h.n_coef)
    intervals = [h.galerkin.positive_intervals(phi[:, i], roots=ROOTS[method]) for i in range(phi.shape[1])]
    for i in range(phi.shape[1]):
        p_i, G_i = h.galerkin.positive_part(phi[:, i], roots=ROOTS[method])
        # batched and single calls sum in a different order (BLAS), so their roots differ at the
        # root conditioning and G by root_gram_tol, proj = G phi by that times sum|phi| (one-signed
        # and zero signals: no roots, tol = 0, G exactly I or 0); measured <= 9e-16 (was atol 1e-15)
        tol = root_gram_tol(phi[:, i], interval_roots(intervals[i]))
        np.testing.assert_allclose(G[i], G_i, rtol=0, atol=tol)
        np.testing.assert_allclose(proj[:, i], p_i, rtol=0, atol=tol * np.abs(phi[:, i]).sum())
    # one signal at a time is the single-signal API; a batch there is refused with the way to it
    with pytest.raises(ValueError, match="ExactProjection"):
        h.galerkin.positive_part(phi)
    with pytest.raises(ValueError, match="ExactProjection"):
        h.galerkin.positive_intervals(phi)


def test_positive_part_root_methods_agree_and_trailing_zeros_embed():
    rng = np.random.default_rng(9)
    h5, h12 = Harmonics(5), Harmonics(12)
    phi5 = random_phi(rng, 5, m=4)
    phi12 = np.zeros((h12.n_coef, 4))
    phi12[: h5.n_coef] = phi5
    p5, G5 = ExactProjection()(h5, phi5)
    p12, G12 = ExactProjection(roots=CompanionRoots())(h12, phi12)
    np.testing.assert_allclose(p12[: h5.n_coef], p5, atol=1e-14)
    # (the higher rows of p12 are non-zero: max(0, phi) generates harmonics)
    np.testing.assert_allclose(G12[:, : h5.n_coef, : h5.n_coef], G5, atol=1e-14)
    phi = random_phi(rng, 30, m=5)
    h30 = Harmonics(30)
    for a, b in zip(ExactProjection()(h30, phi), ExactProjection(roots=CompanionRoots())(h30, phi)):
        np.testing.assert_allclose(a, b, atol=1e-13 * np.abs(phi).max())
    with pytest.raises(TypeError, match="roots must be"):
        ExactProjection(roots="companion")


def test_positive_part_special_signals():
    """Symmetric signals (roots mirrored about 0), sin^3 (triple roots), a
    root at the colleague rotation angle, and heavily decaying spectra."""
    h = Harmonics(10)
    rng = np.random.default_rng(2)
    cases = []
    even = random_phi(rng, 10)
    even[2::2] = 0.0
    odd = random_phi(rng, 10)
    odd[0] = 0.0
    odd[1::2] = 0.0
    alpha = 0.7390851332151607
    at_alpha = np.zeros(h.n_coef)
    at_alpha[1], at_alpha[2] = -np.sin(alpha), np.cos(alpha)  # sin(theta - alpha)
    decay = random_phi(rng, 10) * 0.2 ** np.arange(h.n_coef)
    cases += [(even, 1e-13), (odd, 1e-13), (at_alpha, 1e-13), (decay, 1e-13)]
    for phi, tol in cases:
        G_ref = reference_gram(10, reference_intervals(phi))
        for method in ("colleague", "companion"):
            np.testing.assert_allclose(h.galerkin.positive_part(phi, roots=ROOTS[method])[1], G_ref, atol=tol)
    # sin^3: triple roots at 0 and pi are located to ~eps^(1/3)
    sin3 = np.zeros(h.n_coef)
    sin3[2], sin3[6] = 0.75, -0.25
    G_ref = reference_gram(10, [(0.0, np.pi)])
    for method in ("colleague", "companion"):
        np.testing.assert_allclose(h.galerkin.positive_part(sin3, roots=ROOTS[method])[1], G_ref, atol=1e-5)


@pytest.mark.parametrize("top", [1e-15, 1e-12, 1e-9, 1e-6])
def test_positive_part_tiny_leading_harmonics(top):
    """Leading coefficients far below the others (ill-scaled companion and
    colleague matrices; LAPACK balancing keeps the unit-circle roots accurate)."""
    rng = np.random.default_rng(21)
    h = Harmonics(10)
    phi = random_phi(rng, 10, m=3)
    phi[15:] *= top
    proj, G = ExactProjection()(h, phi)
    proj_c, G_c = ExactProjection(roots=CompanionRoots())(h, phi)
    for i in range(3):
        G_ref = reference_gram(10, reference_intervals(phi[:, i]))
        np.testing.assert_allclose(G[i], G_ref, atol=1e-13)
        np.testing.assert_allclose(G_c[i], G_ref, atol=1e-13)


def fejer_peak(H, depth):
    """Fejer kernel shifted down: one sharp contact interval around theta = 0."""
    k = np.arange(1, H + 1)
    phi = np.zeros(2 * H + 1)
    phi[0] = 1.0 / (H + 1)
    phi[1::2] = (1 - k / (H + 1)) * 2 / (H + 1)
    phi[0] -= depth * series(phi, 0.0)
    return phi


@pytest.mark.parametrize("depth", [0.95, 0.8, 0.5])
def test_sampled_positive_part_is_inaccurate_for_short_contact(depth):
    """AFT with N = 256 on a short contact interval versus the exact projection.

    Measured (H = 20): sampled errors 4.6e-5..1.8e-4 (proj, relative to
    max|phi|) and 4.7e-4..5.6e-3 (G); exact errors <= 3e-16 and <= 6e-16."""
    H = 20
    h = Harmonics(H)
    phi = fejer_peak(H, depth)
    iv = reference_intervals(phi)
    G_ref = reference_gram(H, iv)
    p_ref = G_ref @ phi
    scale = np.abs(phi).max()
    proj, G = h.galerkin.positive_part(phi)
    proj_s, G_s = h.galerkin.positive_part_sampled(phi, 256)
    assert np.abs(proj - p_ref).max() < 1e-13 * scale
    assert np.abs(G - G_ref).max() < 1e-13
    assert np.abs(proj_s - p_ref).max() > 1e-5 * scale
    assert np.abs(G_s - G_ref).max() > 1e-4
    np.testing.assert_allclose(proj_s, G_s @ phi, atol=1e-14 * scale)


def test_sampled_jacobian_jumps_exact_jacobian_is_continuous():
    """Lift phi by 2e-10 so that a grid sample crosses zero: the sampled G jumps
    by O(1/N), the exact G moves by O(2e-10 / |phi'|).

    Measured: sampled 1.6e-2 (= 4/N), exact 2.4e-11."""
    H, N = 20, 256
    h = Harmonics(H)
    phi = fejer_peak(H, 0.8)
    theta_s = TWO_PI * 4 / N  # first sample outside the contact interval
    assert series(phi, theta_s) < 0 < series(phi, TWO_PI * 3 / N)
    phi[0] -= series(phi, theta_s) + 1e-10  # phi(theta_s) = -1e-10
    phi2 = phi.copy()
    phi2[0] += 2e-10  # phi2(theta_s) = +1e-10
    d_sampled = np.abs(h.galerkin.positive_part_sampled(phi2, N)[1] - h.galerkin.positive_part_sampled(phi, N)[1]).max()
    d_exact = np.abs(h.galerkin.positive_part(phi2)[1] - h.galerkin.positive_part(phi)[1]).max()
    assert d_sampled > 1.0 / N
    assert d_exact < 1e-9


def test_positive_part_sampled_shapes_and_convergence():
    rng = np.random.default_rng(4)
    h = Harmonics(6)
    phi = random_phi(rng, 6, m=3)
    proj, G = ExactProjection()(h, phi)
    errs = []
    for N in (64, 512, 4096):
        ps, Gs = SampledProjection(N)(h, phi)
        assert ps.shape == phi.shape and Gs.shape == G.shape
        errs.append(np.abs(ps - proj).max())
    assert errs[0] > errs[1] > errs[2]
    p1, G1 = h.galerkin.positive_part_sampled(phi[:, 0])
    assert p1.shape == (h.n_coef,) and G1.shape == (h.n_coef, h.n_coef)
    # the same numbers batched or one at a time, to the rounding of the matrix products
    np.testing.assert_allclose(p1, SampledProjection()(h, phi)[0][:, 0], rtol=0,
                               atol=8 * np.finfo(float).eps * h.n_time * np.abs(phi[:, 0]).sum())
    with pytest.raises(ValueError):
        h.galerkin.positive_part_sampled(phi[:, 0], 5)


def test_positive_intervals_match_reference():
    rng = np.random.default_rng(12)
    h = Harmonics(7)
    for _ in range(5):
        phi = random_phi(rng, 7)
        iv = h.galerkin.positive_intervals(phi)
        ref = reference_intervals(phi)
        # merge the reference interval crossing 2 pi
        if len(ref) > 1 and ref[0][0] == 0.0 and ref[-1][1] == TWO_PI:
            ref = ref[1:-1] + [(ref[-1][0], ref[0][1] + TWO_PI)]
        ref = np.array(sorted(ref))
        np.testing.assert_allclose(iv, ref, atol=1e-13)
        assert np.all((iv[:, 0] >= 0) & (iv[:, 0] < TWO_PI) & (iv[:, 1] > iv[:, 0]))
        assert np.all(series(phi, iv.mean(axis=1)) > 0)


def test_input_validation_of_phi():
    h = Harmonics(3)
    with pytest.raises(ValueError):
        h.galerkin.positive_part(np.zeros(5))
    with pytest.raises(ValueError):
        h.galerkin.positive_part(np.full(7, np.nan))
    with pytest.raises(ValueError):
        h.grid.to_time(np.zeros((6, 2)))
    with pytest.raises(ValueError):
        h.grid.from_time(np.zeros(h.n_time + 1))


def test_grid_roots_equal_colleague_roots():
    """GridRoots (the default) against the colleague matrix: random signals with flat, 1/k and
    1/k^2 spectra (contact forces and displacements) and offsets that make 0 to 2H sign changes;
    and tangencies ``cos t - 1 + eps``: Gram matrices equal to round-off (100 eps of their scale)."""
    from femodes.hbm.positive_part import positive_gram

    rng = np.random.default_rng(0)
    for H in (1, 2, 3, 5, 10, 20, 40, 80):
        h = Harmonics(H)
        k = np.maximum(h.layout.harmonic_of, 1)
        for decay in (0, 1, 2):
            Phi = rng.standard_normal((100, h.n_coef)) / k ** decay
            Phi[:, 0] += rng.uniform(-2, 2, 100) * np.abs(Phi).max(axis=1)
            G1 = positive_gram(h, Phi, ColleagueRoots())[0]
            G2 = positive_gram(h, Phi, GridRoots())[0]
            np.testing.assert_allclose(G2, G1, atol=100 * np.finfo(float).eps * H)
    h = Harmonics(10)
    for eps in (1e-2, 1e-4, 1e-6, 1e-8):
        phi = np.zeros(h.n_coef)
        phi[0], phi[1] = eps - 1.0, 1.0
        G1 = positive_gram(h, phi[None], ColleagueRoots())[0]
        G2 = positive_gram(h, phi[None], GridRoots())[0]
        # the positive interval has width ~2 sqrt(2 eps): its roots are conditioned like 1/sqrt(eps)
        np.testing.assert_allclose(G2, G1, atol=1e-15 / np.sqrt(eps))
    with pytest.raises(ValueError, match="per_harmonic"):
        GridRoots(per_harmonic=2)


def _general_path(A):
    """Sign changes of the rows of ``A`` by the grid's candidates and the test points of
    :func:`sign_changes` (the path the grid's own reading falls back to)."""
    from femodes.hbm.trigroots import candidates, sign_changes

    heff = np.full(A.shape[0], (A.shape[1] - 1) // 2)
    return sign_changes(A, candidates(A, heff, GridRoots()))


def test_grid_sign_changes_equal_the_general_path():
    """GridRoots.sign_changes (roots read off the grid cells, Hermite start, plain Newton) against
    the candidates and test points of the general path, on random signals with 0 to 2H sign
    changes: the same roots (to 1e-12 rad: both polish to rounding, ~eps |phi| / |phi'|), interval
    ends and measure of the positive set for every row it decides, the same sign for those without
    roots; it decides at least 90 % of them (measured 95.5-100 %; a row is left when a sample or
    a dip is within rounding of zero)."""
    rng = np.random.default_rng(1)
    for H in (1, 3, 10, 20, 40):
        h = Harmonics(H)
        k = np.maximum(h.layout.harmonic_of, 1)
        for decay in (0, 1, 2):
            A = rng.standard_normal((200, h.n_coef)) / k ** decay
            A[:, 0] += rng.uniform(-2, 2, 200) * np.abs(A).max(axis=1)
            A /= np.abs(A).max(axis=1)[:, None]
            (rows, rho, w, wrap, sign_const), undecided = GridRoots().sign_changes(A)
            assert undecided.mean() <= 0.1
            g_rows, g_rho, g_w, g_wrap, g_sign = _general_path(A)
            decided = ~undecided
            constant = decided & ~np.isin(np.arange(A.shape[0]), g_rows)  # the sign of rows without roots
            assert np.array_equal(sign_const[constant], g_sign[constant])
            for i in np.flatnonzero(decided):
                mine, ref = rows == i, g_rows == i
                order = np.argsort(np.mod(g_rho[ref], TWO_PI))
                # the same roots, each the start (-1) or the end (+1) of a positive interval ...
                np.testing.assert_allclose(rho[mine], np.mod(g_rho[ref], TWO_PI)[order], rtol=0, atol=1e-12)
                assert np.array_equal(w[mine], g_w[ref][order])
                # ... and the same measure of the positive set (each path cuts the period elsewhere)
                if mine.any():
                    np.testing.assert_allclose(w[mine] @ rho[mine] + TWO_PI * wrap[i],
                                               g_w[ref] @ g_rho[ref] + TWO_PI * g_wrap[i], rtol=0, atol=1e-11)


def test_grid_sign_changes_leave_what_they_cannot_decide():
    """Rows the grid cannot decide go to the general path, in one batch with the decided ones:
    a sample at a root (cos t is zero at the grid point pi/2 to rounding), and a positive
    interval inside one grid cell (a dip of depth 1e-6, width 3e-3 against a cell of 0.02)."""
    from femodes.hbm.positive_part import positive_gram

    h = Harmonics(5)
    at_sample = np.zeros(h.n_coef)
    at_sample[1] = 1.0  # cos t: roots at pi/2 and 3 pi/2, both grid points
    dip = np.zeros(h.n_coef)
    dip[0], dip[1], dip[2] = 1e-6 - 1.0, np.cos(0.3), np.sin(0.3)  # cos(t - 0.3) - 1 + 1e-6
    plain = np.zeros(h.n_coef)
    plain[0], plain[3] = 0.2, 1.0  # 0.2 + cos 2t: four simple roots
    A = np.array([plain, at_sample, dip, plain])
    _, undecided = GridRoots().sign_changes(A)
    assert undecided.tolist() == [False, True, True, False]
    G = positive_gram(h, A, GridRoots())[0]
    np.testing.assert_allclose(G, positive_gram(h, A, ColleagueRoots())[0], atol=1e-12)
    # the dip's positive interval: 2 sqrt(2e-6) wide around t = 0.3
    iv = h.galerkin.positive_intervals(dip)
    np.testing.assert_allclose(iv, [[0.3 - np.arccos(1 - 1e-6), 0.3 + np.arccos(1 - 1e-6)]], atol=1e-9)


def test_grid_polish_falls_back_to_the_safeguarded_iteration():
    """A Newton step that leaves its cell (a start next to an extremum, phi' ~ 0) is polished
    again by the bisection-safeguarded iteration: the root of sin t in [pi/2, pi + 0.1] from
    pi/2 + 1e-3 (the first Newton step would jump by 1e3)."""
    from femodes.hbm.trigroots import _polish_in_cells

    A = np.array([[0.0, 0.0, 1.0]])  # sin t
    x = _polish_in_cells(A, np.array([np.pi / 2 + 1e-3]), np.array([np.pi / 2]), np.array([np.pi + 0.1]),
                         np.array([True]))
    assert abs(x[0] - np.pi) <= 4 * np.finfo(float).eps * np.pi
