"""Craig-Bampton invariants and accuracy against the full FE model (shared/references.md)."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import femodes as fm

from .conftest import cantilever, fixed_free_bar, roundoff_rtol


def dense_craig_bampton_omega(model, kept, k, n):
    """Independent reference: Craig-Bampton written out densely with scipy.linalg.eigh.

    T = [[I, 0], [-K_II^-1 K_IB, Phi_I]] with the k lowest fixed-interface modes Phi_I; the
    lowest n frequencies of (T^T K T, T^T M T)."""
    import scipy.linalg as sla

    K, M = model.K.toarray(), model.M.toarray()
    inner = np.setdiff1d(np.arange(model.n_dofs), kept)
    T = np.zeros((model.n_dofs, len(kept) + k))
    T[kept, np.arange(len(kept))] = 1.0
    T[inner, : len(kept)] = -np.linalg.solve(K[np.ix_(inner, inner)], K[np.ix_(inner, kept)])
    if k:
        T[inner, len(kept):] = sla.eigh(K[np.ix_(inner, inner)], M[np.ix_(inner, inner)], subset_by_index=[0, k - 1])[1]
    lam = sla.eigh(T.T @ K @ T, T.T @ M @ T, eigvals_only=True)
    return np.sqrt(lam[:n])


def test_bar_guyan_is_exactly_sqrt3():
    """k = 0 (static condensation on the tip of a P1 bar): the static shape x/L is exact in P1, so
    the reduced stiffness is EA/L and the reduced mass rho A L / 3: w = sqrt(3) c / L whatever
    the mesh (the table's 1.027e-1 is sqrt(3) / (pi/2) - 1 to 3 digits)."""
    for ne in (10, 200):
        rom = fm.craig_bampton(fixed_free_bar(ne), 0, keep=["tip"])
        assert fm.linear_modes(rom, 1).omega[0] == pytest.approx(np.sqrt(3.0), rel=1e-12)


def test_tables_against_an_independent_dense_craig_bampton():
    """The tabulated errors come from femodes itself; here each reduced frequency is checked
    against a dense textbook implementation, to the round-off scale of each model's eigenvalues
    (conftest.roundoff_rtol: eps lambda_max / lambda_1, 4e-11 for the bar, 6e-6 for the beam,
    whose Hermite stiffness grows like h^-4; the two implementations differ by 1e-9 there)."""
    bar = fixed_free_bar(200)
    for k in (1, 2, 4, 8):
        rom = fm.craig_bampton(bar, k, keep=["tip"])
        ref = dense_craig_bampton_omega(bar, [bar.dof("tip")], k, 1)
        np.testing.assert_allclose(fm.linear_modes(rom, 1).omega, ref, rtol=roundoff_rtol(bar.K, bar.M))
    beam = cantilever(100)
    kept = [beam.dof("tip"), beam.dof(("tip", "theta"))]
    for k in (2, 4, 8):
        rom = fm.craig_bampton(beam, k, keep=["tip"])
        np.testing.assert_allclose(fm.linear_modes(rom, 3).omega, dense_craig_bampton_omega(beam, kept, k, 3),
                                   rtol=roundoff_rtol(beam.K, beam.M))


def test_bar_w1_error_against_table():
    model = fixed_free_bar(200)
    w_full = fm.linear_modes(model, 1).omega[0]
    ref = {0: 1.027e-1, 1: 4.465e-3, 2: 1.029e-3, 4: 1.821e-4, 8: 2.725e-5}
    for k, e in ref.items():
        rom = fm.craig_bampton(model, k, keep=["tip"])
        err = fm.linear_modes(rom, 1).omega[0] / w_full - 1
        assert err == pytest.approx(e, rel=2e-3), (k, err)


def test_cantilever_first_three_within_0p1_percent_with_10_modes():
    model = cantilever(100)
    w_full = fm.linear_modes(model, 3).omega
    rom = fm.craig_bampton(model, 10, keep=["tip", ("tip", "theta")])
    w_rom = fm.linear_modes(rom, 3).omega
    err = w_rom / w_full - 1
    assert np.all(err >= -1e-9) and np.all(err < 1e-3), err


def test_cantilever_errors_against_table_and_monotone():
    model = cantilever(100)
    w_full = fm.linear_modes(model, 3).omega
    ref = {2: [5.850e-5, 1.091e-3, 3.698e-3], 4: [5.533e-6, 1.401e-4, 7.098e-4], 8: [4.401e-7, 9.982e-6, 6.304e-5]}
    prev = np.full(3, np.inf)
    for k, e in ref.items():
        rom = fm.craig_bampton(model, k, keep=["tip", ("tip", "theta")])
        w = fm.linear_modes(rom, 3).omega
        err = w / w_full - 1
        # The full model's own round-off (cond(K) of a 200-DOF Hermite beam) is ~1e-7 relative in w1,
        # so errors are compared with 3% relative tolerance plus 3e-7 absolute.
        np.testing.assert_allclose(err, e, rtol=3e-2, atol=3e-7)
        assert np.all(w <= prev * (1 + 1e-12))  # adding modes lowers the upper bounds
        assert np.all(err > -3e-7)  # upper bounds (to round-off)
        prev = w


def test_identity_on_kept_dofs_and_expand_roundtrip(rng):
    model = cantilever(30).with_contact(fm.UnilateralContact(at="tip", gap=0.1))
    rom = fm.craig_bampton(model, 6)
    tip = model.dof("tip")
    assert rom.n_kept == 1 and rom.kept.tolist() == [tip]
    assert rom.contacts[0].dof == 0 and rom.dof("tip") == 0
    np.testing.assert_array_equal(rom.basis[tip], np.eye(rom.n_dofs)[0])
    r = rng.standard_normal(rom.n_dofs)
    q = rom.expand(r)
    assert q[tip] == pytest.approx(r[0])
    # T has full column rank and T^T M T is the reduced mass: least squares recovers r
    r_back = np.linalg.lstsq(rom.basis, q, rcond=None)[0]
    np.testing.assert_allclose(r_back, r, atol=1e-10)
    Q = rom.expand(rng.standard_normal((5, rom.n_dofs)))
    assert Q.shape == (5, model.n_dofs)


def test_exact_with_all_modes():
    model = fixed_free_bar(40)
    n_interior = model.n_dofs - 1
    rom = fm.craig_bampton(model, n_interior, keep=["tip"])
    np.testing.assert_allclose(fm.linear_modes(rom, 10).omega, fm.linear_modes(model, 10).omega, rtol=1e-10)


def test_static_response_to_loads_at_kept_dofs_is_exact():
    model = cantilever(40)
    rom = fm.craig_bampton(model, 3, keep=["tip", ("tip", "theta")])
    f = np.zeros(model.n_dofs)
    f[model.dof("tip")] = 1.0
    f[model.dof(("tip", "theta"))] = -0.3
    q_full = spla.spsolve(model.K.tocsc(), f)
    r = np.linalg.solve(rom.K.toarray(), rom.basis.T @ f)
    # exact in exact arithmetic; both sides come from solves with K (cond_1 ~ 8e7 for 40 Hermite
    # elements), each backward stable: forward error <= ~eps cond_1(K) max|q| (measured 0.013 of
    # it; was rtol=1e-9, atol=1e-12 max|q|, measured at 0.3 of that)
    tol = 2 * np.finfo(float).eps * np.linalg.cond(model.K.toarray(), 1) * abs(q_full).max()
    np.testing.assert_allclose(rom.expand(r), q_full, rtol=0, atol=tol)


def test_declarations_reindexed_and_names_kept():
    model = (
        cantilever(20)
        .with_contact(fm.UnilateralContact(at="tip", gap=0.01))
        .with_forcing(fm.HarmonicForce(at=("tip", "theta"), amplitude=2.0))
        .with_nonlinearity(fm.CubicSpring(at="tip", k3=5.0))
        .with_damping(alpha=0.01)
    )
    rom = fm.craig_bampton(model, 4)
    assert rom.n_kept == 2
    assert rom.dof(("tip", "theta")) == rom.forces[0].dof
    assert rom.dof("tip") == rom.contacts[0].dof == rom.nonlinearities[0].dof
    assert rom.C.nnz > 0
    with pytest.raises(ValueError, match="constrained"):
        rom.dof(("clamp", "w"))  # constrained in the parent stays constrained
    # a DOF that exists but was not kept names the fix
    m2 = fm.beam(fm.line_mesh(1.0, 4, boundaries={"clamp": 0.0, "mid": 0.5, "tip": 1.0}),
                 fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    r2 = fm.craig_bampton(m2, 2, keep=["tip"])
    with pytest.raises(ValueError, match="keep="):
        r2.dof("mid")


def test_reduced_model_is_a_model_and_reduces_again():
    model = fixed_free_bar(50).with_contact(fm.UnilateralContact(at="tip", gap=0.0))
    rom = fm.craig_bampton(model, 8)
    assert isinstance(rom, fm.StructuralModel) and rom.is_reduced
    rom2 = rom.with_damping(modal=0.02)
    assert rom2.parent is model and rom2.damping.nonzero and rom2.damping_matrix().nnz > 0
    rr = fm.craig_bampton(rom, 4)
    assert rr.n_dofs == 5


def test_craig_bampton_bad_input():
    model = fixed_free_bar(10)
    with pytest.raises(ValueError, match="no DOF to keep"):
        fm.craig_bampton(model, 2)
    with pytest.raises(ValueError, match="n_modes"):
        fm.craig_bampton(model, -1, keep=["tip"])
    with pytest.raises(ValueError, match="n_modes must be an integer >= 0, got -1"):
        fm.craig_bampton(model, -1)  # its own error, not "no DOF to keep"
    with pytest.raises(ValueError, match="n_modes"):
        fm.craig_bampton(model, 100, keep=["tip"])
    with pytest.raises(ValueError, match="constrained"):
        fm.craig_bampton(model, 2, keep=["clamp"])
    with pytest.raises(TypeError, match="StructuralModel"):
        fm.craig_bampton(np.eye(3), 2)
    free_beam = fm.beam(fm.line_mesh(1.0, 10), fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0))
    with pytest.raises(ValueError, match="singular"):
        fm.craig_bampton(free_beam, 2, keep=[("left", "w")])  # rigid rotation about the kept w DOF remains
    # a named point keeps the whole node (w and theta): the free beam is then clamped there
    rom = fm.craig_bampton(free_beam, 2, keep=["left"])
    assert rom.n_kept == 2 and {rom.dofmap.label(i) for i in range(2)} == {
        free_beam.dofmap.label(free_beam.dof(("left", "w"))), free_beam.dofmap.label(free_beam.dof(("left", "theta")))}


def test_large_sparse_reduction_no_dense_full_matrices():
    # 2e4-DOF bar: the reduction must go through sparse factorizations (a dense 2e4^2 matrix
    # would be 3.2 GB); checked by the result, the memory by the benchmark.
    model = fixed_free_bar(20000)
    rom = fm.craig_bampton(model, 5, keep=["tip"])
    w_full = fm.linear_modes(model, 2).omega
    np.testing.assert_allclose(w_full, [np.pi / 2, 1.5 * np.pi], rtol=1e-7)  # P1 error (kh)^2/24 < 3e-8
    err = fm.linear_modes(rom, 2).omega / w_full - 1
    # between the tabulated errors for 4 and 8 modes (1.821e-4 and 2.725e-5, 200-element bar)
    assert 2.7e-5 < err[0] < 1.83e-4, err


def test_projection_drops_round_off_by_its_own_scale(rng):
    """Which entries of a reduced matrix are exact zeros must not depend on the BLAS kernel (issue
    34): perturbing the basis by 64 eps relative (far more than a kernel's different summation
    order) leaves the sparsity of every reduced matrix unchanged, and the modal blocks of M, K and
    the Rayleigh C are exactly diagonal, the kept rows coupling to the modes."""
    import femodes.reduction as red

    mesh = fm.line_mesh(length=1.0, n_elements=60, boundaries={"clamp": 0.0, "mid": 0.5, "tip": 1.0})
    beam = (fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
            .with_damping(alpha=0.01, beta=1e-4)
            .with_contact(fm.UnilateralContact(at="tip", gap=1e-3)))
    kept = red.kept_dofs(beam, ["mid"])
    interior = np.setdiff1d(np.arange(beam.n_dofs), kept)
    T, _, _ = red._reduction_basis(beam.K.tocsr(), beam.M.tocsr(), kept, interior, 20)
    nB = kept.size
    eps = np.finfo(float).eps
    for A in (beam.M, beam.K, beam.C):
        R = red._project(A.tocsr(), T, nB).toarray()
        modal = R[nB:, nB:]
        assert np.count_nonzero(modal - np.diag(np.diag(modal))) == 0
        assert np.all(np.diag(modal) > 0)
        for _ in range(3):
            Tp = T * (1.0 + 64 * eps * rng.standard_normal(T.shape))
            Rp = red._project(A.tocsr(), Tp, nB).toarray()
            np.testing.assert_array_equal(Rp != 0, R != 0)


def test_rayleigh_damping_reduced_from_the_reduced_mass_and_stiffness():
    """Rayleigh damping is reduced as ``alpha Mr + beta Kr`` (no third projection): equal to the
    projection ``T^T C T`` to the round-off of the products (the projections' own 1e3-ulp scale,
    ``_project``); a damping matrix replaced after ``with_damping`` is projected as it is."""
    import dataclasses

    import femodes.reduction as red

    model = (fixed_free_bar(200).with_contact(fm.UnilateralContact(at="tip", gap=0.01))
             .with_damping(alpha=0.03, beta=2e-4))
    assert red._rayleigh_coefficients(model) == (0.03, 2e-4)
    rom = fm.craig_bampton(model, 8)
    ref = red._project(model.C.tocsr(), rom.basis, rom.kept.size).toarray()
    assert np.abs(rom.C.toarray() - ref).max() <= 1e3 * np.finfo(float).eps * np.abs(ref).max()
    other = dataclasses.replace(model, C=2.0 * model.C)  # no longer alpha M + beta K of its spec
    assert red._rayleigh_coefficients(other) is None
    rom2 = fm.craig_bampton(other, 8)
    assert np.allclose(rom2.C.toarray(), 2.0 * ref, rtol=0, atol=1e3 * np.finfo(float).eps * np.abs(ref).max())


def test_stiffness_kept_block_is_the_schur_complement_when_well_conditioned(monkeypatch):
    """Craig-Bampton forms the reduced stiffness's kept block as the Schur complement
    ``K_bb + K_bI Psi`` where ``cond(K_II) eps <= SCHUR_COND_EPS`` (the quadratic form's
    ``n x n_b`` product is the largest cost with many kept DOFs). On a 2-D solid with 20 kept
    contact DOFs it equals ``T^T K T`` within 8 cond(K_II) eps of its largest entry (the two
    differ by ``Psi^T r``, first order in the solve's error), and the mode blocks are the
    projection's own; a 1000-element beam (cond 5e12) keeps the quadratic form."""
    import femodes.reduction as red

    strip = fm.solid(fm.rectangle_mesh(1.0, 0.1, 20, 4), fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left")
    model = strip.with_contact(fm.UnilateralContact(at="top", gap=0.01, direction=(0.0, 1.0)))
    kept = red.kept_dofs(model)
    interior = np.setdiff1d(np.arange(model.n_dofs), kept)
    T, _, cond = red._reduction_basis(model.K.tocsr(), model.M.tocsr(), kept, interior, 6)
    assert cond * np.finfo(float).eps <= red.SCHUR_COND_EPS
    nB = kept.size
    quad = red._project(model.K.tocsr(), T, nB).toarray()
    schur = red._project(model.K.tocsr(), T, nB, schur_rows=kept).toarray()
    # the mode columns come from a product of another shape (BLAS may sum in another order): equal
    # to the drop threshold of the projection's round-off (ZERO_ULPS eps of the scale)
    eps = np.finfo(float).eps
    assert np.abs(schur[:, nB:] - quad[:, nB:]).max() <= red.ZERO_ULPS * eps * np.abs(quad).max()
    assert np.abs(schur - quad).max() <= 8 * cond * eps * np.abs(quad).max()
    assert np.array_equal(schur, schur.T)
    rom = fm.craig_bampton(model, 6)
    np.testing.assert_array_equal(rom.K.toarray(), schur)

    mesh = fm.line_mesh(length=1.0, n_elements=1000, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = (fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
            .with_contact(fm.UnilateralContact(at="tip", gap=0.01)))
    used = []
    project = red._project
    monkeypatch.setattr(red, "_project", lambda *a, **k: used.append(k.get("schur_rows")) or project(*a, **k))
    fm.craig_bampton(beam, 4)
    assert used == [None, None]  # mass and stiffness, both quadratic


def test_lower_half_and_the_parts_of_the_interior():
    """``_lower_half`` splits a symmetric matrix exactly (``H + H^T == A``, entry by entry: halving
    a diagonal entry and adding it back is exact in binary floating point), with empty rows; and
    the interior's parts come from ``K_II``'s pattern unless the mass couples what the stiffness
    does not (then from both)."""
    import scipy.sparse as sp

    import femodes.reduction as red

    A = sp.random(40, 40, density=0.1, random_state=1, format="csr")
    A = (A + A.T).tolil()
    A[7, :] = 0.0
    A[:, 7] = 0.0
    A = sp.csr_matrix(A)
    A.eliminate_zeros()
    H = red._lower_half(A)
    assert sp.triu(H, 1).nnz == 0
    assert (H + H.T != A).nnz == 0
    K = sp.csc_matrix(sp.block_diag([np.array([[2.0, -1.0], [-1.0, 2.0]])] * 2))
    M = sp.identity(4, format="csr")
    assert red._parts(K, M)[0] == 2
    M = sp.csr_matrix(np.eye(4) + 0.1 * (np.eye(4, k=2) + np.eye(4, k=-2)))  # couples the two
    assert red._parts(K, M)[0] == 1
    # an explicit zero stored between the parts does not couple them
    coo = K.tocoo()
    Kz = sp.csc_matrix((np.r_[coo.data, 0.0, 0.0], (np.r_[coo.row, 1, 2], np.r_[coo.col, 2, 1])), shape=K.shape)
    assert Kz.nnz == K.nnz + 2 and np.count_nonzero(Kz.data) == K.nnz
    assert red._parts(Kz, sp.identity(4, format="csr"))[0] == 2
