"""The dynamic stiffness, written once (femodes/dynamic_stiffness.py): its harmonic block is
``K - f^2 M + i f (C - xi M) + i f U diag(d) U^T``, and its form on the Fourier coefficients is the
same operator harmonic by harmonic, in every evaluation (applied, assembled, dense, derivatives,
the change between two frequencies, Hill's expansion). Tolerances: a few eps times the size of
the terms (the evaluations group the same products differently)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import femodes as fm
from femodes.dynamic_stiffness import CoefficientStiffness, DynamicStiffness
from femodes.model import LowRankDamping

EPS = np.finfo(float).eps


def matrices(n=7, seed=0):
    rng = np.random.default_rng(seed)

    def spd(shift):
        A = sp.random(n, n, density=0.4, random_state=rng)
        return sp.csr_matrix(A @ A.T + shift * sp.identity(n))
    U = rng.standard_normal((n, 3))
    return spd(2.0), spd(1.0), spd(0.1), LowRankDamping(U, np.array([0.3, 0.0, 1.2]))


def close(a, b, scale):
    a = a.toarray() if sp.issparse(a) else np.asarray(a)
    b = b.toarray() if sp.issparse(b) else np.asarray(b)
    assert np.max(np.abs(a - b), initial=0.0) <= 64 * EPS * scale


@pytest.mark.parametrize("xi", [0.0, 0.15])
def test_one_harmonic_is_the_formula(xi):
    K, M, C, lr = matrices()
    Z = DynamicStiffness(K, M, C, lr)
    f = 1.7
    Kd, Md, Cd, Ud = K.toarray(), M.toarray(), C.toarray(), lr.toarray()
    scale = np.abs(Kd).max() + f * f * np.abs(Md).max() + f * (np.abs(Cd).max() + np.abs(Ud).max())
    whole = Z.harmonic(f, xi) + lr.U @ np.diag(Z.lowrank_gain(f)) @ lr.U.T
    close(whole, Kd - f * f * Md + 1j * f * (Cd + Ud - xi * Md), scale)
    # the same block on values, dense blocks and with the mass shift c = f^2 + i f xi
    dense = DynamicStiffness(Kd, Md, Cd)
    close(dense.harmonic(f, xi), Z.harmonic(f, xi), scale)
    close(dense.harmonic(f, xi), Kd - Z.mass_shift(f, xi) * Md + 1j * f * Cd, scale)
    # real form on [c; s] of c cos + s sin: the complex block acting on c - i s
    rng = np.random.default_rng(1)
    c, s = rng.standard_normal(K.shape[0]), rng.standard_normal(K.shape[0])
    z = Z.harmonic(f, xi) @ (c - 1j * s)
    close(Z.real_block(f, xi) @ np.concatenate([c, s]), np.concatenate([z.real, -z.imag]), scale * 3)
    # the row-sum bound
    rows = [float(abs(A).sum(axis=1).max()) for A in (K, M, C)]
    assert DynamicStiffness(*rows).abs_bound(f, xi) >= np.abs(Z.harmonic(f, xi).toarray()).sum(axis=1).max()


@pytest.mark.parametrize("lowrank", [False, True])
@pytest.mark.parametrize("xi", [0.0, 0.15])
def test_coefficient_form_is_the_harmonic_form_block_by_block(lowrank, xi):
    K, M, C, lr = matrices()
    h = fm.Harmonics(4, subharmonic=2)
    D = sp.csr_matrix(np.asarray(h.operators.derivative_domega()))
    Z = DynamicStiffness(K, M, C, lr if lowrank else None)
    S = CoefficientStiffness(Z, D)
    w = 1.3
    n = K.shape[0]
    Q = np.random.default_rng(2).standard_normal((h.n_coef, n))
    SQ = S.apply(Q, w, xi)
    scale = (1 + w * w) * np.abs(Q).max() * sum(float(abs(A).sum(axis=1).max()) for A in (K, M, C, lr.toarray()))
    close(SQ[0], K @ Q[0], scale)
    for k in range(1, h.n_harmonics + 1):
        f = k * w / h.subharmonic
        c, s = h.layout.cos_index(k), h.layout.sin_index(k)
        z = Z.harmonic(f, xi) @ (Q[c] - 1j * Q[s])
        if lowrank:
            z = z + lr.U @ (Z.lowrank_gain(f) * (lr.U.T @ (Q[c] - 1j * Q[s])))
        close(SQ[c], z.real, scale)
        close(SQ[s], -z.imag, scale)
    # assembled, dense and residual evaluations of the same operator
    close(S.operator(w, xi) @ Q.ravel(), SQ.ravel(), scale)
    close(S.dense_operator(w, xi) @ Q.ravel(), SQ.ravel(), scale)
    r, dw, dxi = S.residual(Q, w, xi)
    close(r, SQ, scale)
    dw_fd = (S.apply(Q, w + 1e-6, xi) - S.apply(Q, w - 1e-6, xi)) / 2e-6
    assert np.abs(dw - dw_fd).max() <= 1e-6 * np.abs(dw).max()
    close(dxi, (S.apply(Q, w, xi + 1.0) - SQ), scale)   # linear in xi
    assert np.all(S.apply(np.abs(Q), w, xi, absolute=True) >= np.abs(SQ) * (1 - 1e-12))
    if lowrank:  # the low-rank part as a border: S = S_sparse + B (I x U^T)
        B, Ur = S.lowrank_border(w)
        close(S.operator(w, xi, lowrank=False) @ Q.ravel() + B @ (Ur @ Q.ravel()), SQ.ravel(), scale)
    else:  # the change between two frequencies (reused factors); K cancels
        Qk = np.stack([Q, 2 * Q], axis=2)
        ch = S.change(Qk, 1.1, w, xi)
        close(ch[:, 1], 2 * (S.apply(Q, 1.1, xi) - SQ).ravel(), 2 * scale)
    # Hill's expansion: S(w) at d/dt + s is S + s J1 + s^2 J2 (the derivative operator shifted)
    sigma = 0.37
    J1, J2 = S.exponent_terms(w, xi)
    shifted = CoefficientStiffness(Z, D + (sigma / w) * sp.identity(h.n_coef), damping_matrix=None)
    close(shifted.operator(w, xi), S.operator(w, xi) + sigma * J1 + sigma ** 2 * J2, scale)


def test_linear_response_and_hbm_system_use_it():
    """The HBM system's operators and a linear response at one frequency are those of the formula."""
    mesh = fm.line_mesh(1.0, 30, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_damping(alpha=0.05, beta=1e-3).with_forcing(fm.HarmonicForce(at="tip", amplitude=1.0)))
    Z = DynamicStiffness.of(model)
    w = 2.1
    q = fm.linear_response(model, w).amplitude[0]
    F = model.force_vectors()[1]
    assert np.abs(Z.harmonic(w) @ q - F).max() <= 1e3 * EPS * np.abs(F).max()
    s = fm.hbm.HBMSystem(model, fm.Harmonics(3))
    x = np.random.default_rng(3).standard_normal(s.nq)
    np.testing.assert_array_equal(s.linear.apply(x, w), s.stiffness.apply(x.reshape(s.h.n_coef, s.n), w).ravel())
    assert s.stiffness.Z.K is s.K
