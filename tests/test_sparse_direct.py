"""The sparse direct back-ends (femodes.sparse_direct, issue 38): every installed back-end agrees
with SuperLU to a tolerance derived from the conditioning, a back-end that is missing falls back
with one log record, a bad name is a clear error; forced through ``FEMODES_SPARSE_BACKEND``,
Craig-Bampton, linear modes, linear responses and the HBM block solver give SuperLU's results.
The fallback path runs everywhere; the CHOLMOD, MUMPS and PARDISO paths where they are installed
(``make venv`` installs them when it can)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import scipy.sparse as sp

import femodes as fm
from femodes import sparse_direct as sd
from femodes.sparse_schur import schur_complement
from tests.conftest import roundoff_rtol

OPTIONAL = [b for b in sd.BACKENDS if b != "superlu"]
INSTALLED = sd.available_backends()


def _box(nx=4, n=2):
    """A short P2 box whose harmonic blocks are too wide for the band LU (sparse back-end)."""
    mesh = fm.box_mesh(length=0.4, width=0.2, height=0.2, nx=nx, ny=n, nz=n)
    model = fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left", order=2)
    return model.with_damping(beta=0.02).with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0, 0)))


@pytest.fixture(scope="module")
def box():
    model = _box()
    K, M, C = (A.tocsc() for A in (model.K, model.M, model.C))
    w = 1.5
    Z = (K - w * w * M + 1j * w * C).tocsc()
    # forward error of a backward-stable solve: cond(A) eps; cond(K) <= lam_max / lam_min of
    # (K, I) ~ what roundoff_rtol(K) measures, and Z (between eigenfrequencies, damped) is
    # better conditioned than K's extremes allow: the same scale with a margin of 100
    tol = roundoff_rtol(K, multiple=100.0)
    return model, K, Z, tol


@pytest.fixture
def backend(monkeypatch):
    def use(name):
        monkeypatch.setenv(sd.ENV_VAR, name)
    return use


@pytest.fixture
def forced_box(box, backend, name):
    """``(model, tol)``: the box with a force at its right face, on the back-end ``name`` of the
    test's parametrisation (skipped when it is not installed)."""
    if name not in INSTALLED:
        pytest.skip(f"{name} not installed")
    model, K, Z, tol = box
    backend(name)
    return model.with_forcing(fm.HarmonicForce(at=("right", "u_x"), amplitude=1e-3)), tol


@pytest.mark.parametrize("name", OPTIONAL)
def test_backend_agrees_with_superlu(box, backend, name):
    if name not in INSTALLED:
        pytest.skip(f"{name} not installed (make venv installs it when it can)")
    model, K, Z, tol = box
    rng = np.random.default_rng(1)
    B = rng.standard_normal((K.shape[0], 3))
    backend("superlu")
    ref_k = sd.factorize(K, positive_definite=True).solve(B)
    ref_z = sd.factorize(Z).solve(B + 1j * B[::-1])
    ref_zt = sd.factorize(Z).solve(B[:, 0], trans=True)
    backend(name)
    fk = sd.factorize(K, positive_definite=True)
    assert fk.backend == name
    x = fk.solve(B)
    assert np.abs(x - ref_k).max() <= tol * np.abs(ref_k).max()
    # complex right-hand sides on a real factor, one vector
    xc = fk.solve(B[:, 0] + 2j * B[:, 1])
    assert xc.shape == (K.shape[0],)
    assert np.abs(xc - (ref_k[:, 0] + 2j * ref_k[:, 1])).max() <= tol * np.abs(ref_k).max()
    fz = sd.factorize(Z)
    assert fz.backend == ("superlu" if name == "cholmod" else name)  # CHOLMOD takes SPD only
    assert np.abs(fz.solve(B + 1j * B[::-1]) - ref_z).max() <= tol * np.abs(ref_z).max()
    assert np.abs(fz.solve(B[:, 0], trans=True) - ref_zt).max() <= tol * np.abs(ref_zt).max()


@pytest.mark.skipif("mumps" not in INSTALLED, reason="MUMPS not installed")
def test_mumps_unsymmetric_and_transposed(backend):
    rng = np.random.default_rng(2)
    A = (sp.random(300, 300, density=0.02, random_state=3) + 10 * sp.identity(300)).tocsc() * (1 + 0.5j)
    b = rng.standard_normal(300)
    backend("mumps")
    f = sd.factorize(A)
    assert f.backend == "mumps" and not sd.is_symmetric(A)
    assert np.abs(A @ f.solve(b) - b).max() < 1e-12 * np.abs(b).max() * 10
    assert np.abs(A.T @ f.solve(b, trans=True) - b).max() < 1e-12 * np.abs(b).max() * 10


@pytest.mark.parametrize("name", ["superlu"] + OPTIONAL)
def test_singular_raises_runtime_error(backend, name):
    if name not in INSTALLED:
        pytest.skip(f"{name} not installed")
    backend(name)
    A = sp.csc_matrix(np.diag([1.0, 2.0, 0.0]) + np.diag([0.0, 0.0], 1) + np.diag([0.0, 0.0], -1))
    with pytest.raises(RuntimeError):
        sd.factorize(A, positive_definite=True)


@pytest.mark.parametrize("name", OPTIONAL)
def test_forced_backend_reproduces_reduction_modes_and_response(box, backend, name):
    if name not in INSTALLED:
        pytest.skip(f"{name} not installed")
    model, K, Z, tol = box
    backend("superlu")
    rom0 = fm.craig_bampton(model, n_modes=8)
    om0 = fm.linear_modes(model, n=6).omega
    q0 = fm.linear_response(model.with_forcing(fm.HarmonicForce(at=("right", "u_x"), amplitude=1e-3)), 1.5).amplitude
    backend(name)
    rom = fm.craig_bampton(model, n_modes=8)
    om = fm.linear_modes(model, n=6).omega
    q = fm.linear_response(model.with_forcing(fm.HarmonicForce(at=("right", "u_x"), amplitude=1e-3)), 1.5).amplitude
    # the contact model's mass is singular (massless contact nodes): the scale of the pencil
    # from the same solid without them
    bare = fm.solid(fm.box_mesh(length=0.4, width=0.2, height=0.2, nx=4, ny=2, nz=2),
                    fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left", order=2)
    rtol = roundoff_rtol(bare.K, bare.M, multiple=100.0)
    assert np.abs(om / om0 - 1).max() <= rtol
    assert np.abs(rom.K.toarray() - rom0.K.toarray()).max() <= tol * np.abs(rom0.K.toarray()).max()
    assert np.abs(rom.M.toarray() - rom0.M.toarray()).max() <= tol * np.abs(rom0.M.toarray()).max()
    assert np.abs(q - q0).max() <= tol * np.abs(q0).max()


def test_forced_backend_in_hbm_blocks(box, backend):
    """The harmonic blocks of a 3-D solid go to the sparse back-end (not the band LU) and solve,
    plain and transposed, as with SuperLU."""
    from femodes.hbm.linsolve import BlockLU, build_pattern

    model, K, Z, tol = box
    bd = np.array(sorted({c.dof for c in model.contacts}))
    pat = build_pattern(model.M, model.K, model.C, bd)
    assert not pat.banded and pat.symmetric
    R = np.random.default_rng(4).standard_normal((pat.perm.size, 2)) + 0j
    backend("superlu")
    lu0 = BlockLU(pat, 1.5)
    ref = {trans: lu0.solve(R, trans=trans) for trans in (False, True)}
    for name in INSTALLED:
        backend(name)
        lu = BlockLU(pat, 1.5)
        assert lu.factor.backend == ("superlu" if name == "cholmod" else name)  # CHOLMOD: SPD only
        for trans in (False, True):
            assert np.abs(lu.solve(R, trans=trans) - ref[trans]).max() <= tol * np.abs(ref[trans]).max()


@pytest.mark.skipif("pardiso" not in INSTALLED, reason="PARDISO (mkl) not installed")
def test_pardiso_fallbacks_and_singular(backend):
    """PARDISO: a matrix given as positive definite that is not is factorised as symmetric
    indefinite (as CHOLMOD's rejection is); a singular indefinite matrix, which PARDISO would
    factorise with a perturbed pivot, raises SingularMatrixError; a symmetric matrix without some
    stored diagonal entries (which PARDISO's symmetric types need) solves."""
    backend("pardiso")
    rng = np.random.default_rng(7)
    n = 200
    A = sp.random(n, n, density=0.03, random_state=8)
    S = (A + A.T + 8 * sp.identity(n)).tocsc()
    b = rng.standard_normal(n)
    for M in (S - 9.5 * sp.identity(n), (S - 9.5 * sp.identity(n)) * (1 + 0.2j)):
        f = sd.factorize(M.tocsc(), positive_definite=True)
        assert f.backend == "pardiso"
        # forward error <= cond(M) eps; the residual of a backward-stable solve: a few eps ||M|| ||x||
        x = f.solve(b)
        assert np.abs(M @ x - b).max() <= 1e3 * np.finfo(float).eps * abs(M).max() * np.abs(x).max() * n
    Z = sp.csc_matrix(np.diag([1.0, -2.0, 0.0]))
    with pytest.raises(sd.SingularMatrixError, match="numerically singular"):
        sd.factorize(Z)
    P = sp.csc_matrix(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 2.0], [0.0, 2.0, 3.0]]))  # (0, 0) not stored
    P.eliminate_zeros()
    x = sd.factorize(P).solve(np.ones(3))
    assert np.abs(P @ x - 1).max() <= 1e-14 * 10


def test_auto_prefers_pardiso_for_complex_blocks_on_two_threads(monkeypatch):
    """auto's order for complex / indefinite matrices: PARDISO first when it may use two threads
    (MUMPS is sequential), MUMPS first on one; positive definite matrices keep CHOLMOD first."""
    from femodes import sparse_pardiso as spp

    monkeypatch.setenv(spp.ENV_VAR, "2")
    assert sd.auto_order(False) == sd.AUTO_INDEFINITE_THREADED == ("pardiso", "mumps")
    assert sd.auto_order(True) == sd.AUTO_POSITIVE_DEFINITE
    monkeypatch.setenv(spp.ENV_VAR, "1")
    assert sd.auto_order(False) == sd.AUTO_INDEFINITE == ("mumps", "pardiso")
    monkeypatch.setenv(sd.ENV_VAR, "auto")
    if "pardiso" in INSTALLED and "mumps" in INSTALLED:
        assert fm.sparse_backend_info().indefinite == "mumps"
        monkeypatch.setenv(spp.ENV_VAR, "2")
        assert fm.sparse_backend_info().indefinite == "pardiso"


def test_pardiso_thread_count_from_the_environment(monkeypatch):
    """PARDISO's own thread count (not femodes' BLAS limit): FEMODES_PARDISO_THREADS, else
    MKL_NUM_THREADS, else the available cores; a bad value names its variable."""
    from femodes import sparse_pardiso as spp

    monkeypatch.delenv(spp.ENV_VAR, raising=False)
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    assert spp.pardiso_threads() >= 1
    monkeypatch.setenv("MKL_NUM_THREADS", "2")
    assert spp.pardiso_threads() == 2
    monkeypatch.setenv(spp.ENV_VAR, "3")
    assert spp.pardiso_threads() == 3
    for bad in ("0", "two"):
        monkeypatch.setenv(spp.ENV_VAR, bad)
        with pytest.raises(ValueError, match="FEMODES_PARDISO_THREADS must be a positive integer"):
            spp.pardiso_threads()


@pytest.mark.parametrize("name", ["superlu"] + OPTIONAL)
def test_schur_complement_on_every_backend(box, backend, name):
    """schur_complement(A, keep) (femodes.sparse_schur) equals A_kk - A_ki A_ii^-1 A_ik computed densely, for the real
    stiffness, the complex symmetric block and an unsymmetric one, with ``keep`` unsorted, on every
    installed back-end (MUMPS returns a triangle of a symmetric Schur complement, PARDISO the rows
    in increasing order: the whole is checked in the caller's order), to
    the fixture's cond eps tolerance; bad ``keep`` is a ValueError that says what it must be."""
    if name not in INSTALLED:
        pytest.skip(f"{name} not installed")
    model, K, Z, tol = box
    keep = np.array(sorted({c.dof for c in model.contacts}))[::3][::-1]  # not sorted: the order is S's
    i = np.setdiff1d(np.arange(K.shape[0]), keep)
    backend(name)
    for A, pd in ((K, True), (Z, False), (Z + sp.triu(Z, 1) * 0.1, False)):  # the last one unsymmetric
        D = A.toarray()
        ref = D[np.ix_(keep, keep)] - D[np.ix_(keep, i)] @ np.linalg.solve(D[np.ix_(i, i)], D[np.ix_(i, keep)])
        S = schur_complement(A, keep, positive_definite=pd)
        assert S.shape == (keep.size, keep.size)
        assert np.abs(S - ref).max() <= tol * np.abs(ref).max()
    # a symmetric indefinite matrix given as positive definite (K shifted: 3 negative eigenvalues
    # of D_ii, cond 2e3 against K_II's 5e3, so the fixture's tolerance holds): LDL^T, as factorize does
    D = (K - 2e-3 * abs(K).max() * sp.identity(K.shape[0])).tocsc().toarray()
    ref = D[np.ix_(keep, keep)] - D[np.ix_(keep, i)] @ np.linalg.solve(D[np.ix_(i, i)], D[np.ix_(i, keep)])
    S = schur_complement(sp.csc_matrix(D), keep, positive_definite=True)
    assert np.abs(S - ref).max() <= tol * np.abs(ref).max()
    for bad in ([], [0, 0], [K.shape[0]], np.arange(K.shape[0])):
        with pytest.raises(ValueError, match="keep must hold"):
            schur_complement(K, bad)


def test_bad_backend_name_is_a_clear_error(backend):
    backend("umfpack")
    with pytest.raises(ValueError, match=r"FEMODES_SPARSE_BACKEND='umfpack'.*auto, superlu, cholmod, mumps, pardiso"):
        sd.factorize(sp.identity(3, format="csc"))
    with pytest.raises(ValueError, match="FEMODES_SPARSE_BACKEND"):
        fm.sparse_backend_info()


def test_missing_backend_falls_back_with_one_log_record(backend, monkeypatch, caplog):
    monkeypatch.setattr(sd, "backend_module", lambda name: sd.spla if name == "superlu" else None)
    monkeypatch.setattr(sd, "_logged", set())
    A = sp.diags([4.0, 5.0, 6.0]).tocsc()
    for name in OPTIONAL:
        backend(name)
        with caplog.at_level(logging.INFO, logger="femodes.sparse_direct"):
            caplog.clear()
            for _ in range(3):
                f = sd.factorize(A, positive_definite=True)
                assert f.backend == "superlu"
                assert np.allclose(f.solve(np.ones(3)), 1 / np.array([4.0, 5.0, 6.0]))
        assert len([r for r in caplog.records if name in r.getMessage()]) == 1, caplog.text
    info = fm.sparse_backend_info()
    assert info.available == ("superlu",) and info.positive_definite == "superlu" == info.indefinite


def test_auto_keeps_superlu_for_small_matrices(backend):
    backend("auto")
    A = sp.diags(np.arange(1.0, 11.0)).tocsc()
    assert sd.factorize(A, positive_definite=True).backend == "superlu"
    info = fm.sparse_backend_info()
    assert info.requested == "auto" and info.min_size == sd.AUTO_MIN_SIZE
    first = {kind: next((b for b in sd.auto_order(pd) if b in INSTALLED), "superlu")
             for kind, pd in (("pd", True), ("indef", False))}
    assert (info.positive_definite, info.indefinite) == (first["pd"], first["indef"])


@pytest.mark.skipif(not OPTIONAL or not set(OPTIONAL) & set(INSTALLED), reason="no optional back-end installed")
def test_backend_blas_follows_femodes_thread_limit():
    """A back-end first imported inside femodes' BLAS limit (an analysis) brings the system's
    OpenBLAS; the limit is applied to it too, and lifted with the others (fresh process: the
    libraries must not be loaded yet)."""
    import subprocess
    import sys
    import textwrap

    name = next(b for b in OPTIONAL if b in INSTALLED)
    code = textwrap.dedent(f"""
        import os
        os.environ["FEMODES_SPARSE_BACKEND"] = "{name}"
        os.environ.pop("OPENBLAS_NUM_THREADS", None)
        import scipy.sparse as sp
        from threadpoolctl import threadpool_info
        from femodes import sparse_direct as sd
        from femodes.solvers.threads import limit_blas_threads
        before = {{i["filepath"] for i in threadpool_info()}}
        with limit_blas_threads(1):
            sd.factorize(sp.identity(10, format="csc"), positive_definite=True)
            inside = threadpool_info()
        assert all(i["num_threads"] == 1 for i in inside), inside
        print(len({{i["filepath"] for i in inside}} - before))
    """)
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr


@pytest.mark.parametrize("name", ["superlu"] + OPTIONAL)
def test_pattern_factorizer_matches_factorize(box, backend, name):
    """Matrices of one pattern through a PatternFactorizer (CSC structure built once; MUMPS's
    analysis reused by the instances whose factors were released) solve as factorize() does, with
    dense and sparse right-hand sides; MUMPS reuses its analysis once a factor is released.
    Tolerance: a backward-stable solve's forward error, cond eps (the fixture's ``tol``); MUMPS
    with a reused analysis is its own threshold-pivoting LDL^T, bounded the same way."""
    if name not in INSTALLED:
        pytest.skip(f"{name} not installed")
    model, K, Z, tol = box
    Kc, Mc, Cc = (A.tocoo() for A in (model.K, model.M, model.C))
    U = (abs(model.K) + abs(model.M) + abs(model.C)).tocoo()
    r, c = U.row, U.col
    parts = [np.asarray(A.tocsr()[r, c]).ravel() for A in (model.K, model.M, model.C)]
    backend(name)
    pf = sd.PatternFactorizer(r, c, K.shape[0])
    assert pf.symmetric
    rng = np.random.default_rng(5)
    B = rng.standard_normal((K.shape[0], 3)) + 1j * rng.standard_normal((K.shape[0], 3))
    rows = np.sort(rng.choice(K.shape[0], 20, replace=False))
    Bs = sp.csc_matrix((rng.standard_normal((20, 2)).ravel(order="F") + 0j,
                        (np.tile(rows, 2), np.repeat(np.arange(2), 20))), shape=(K.shape[0], 2))
    alive = []
    for w in (1.5, 3.0, 1.515, 0.0):
        vals = parts[0] - w * w * parts[1] + 1j * w * parts[2] if w else parts[0]
        A = pf.matrix(vals)
        assert np.array_equal(A.toarray(), (model.K - w * w * model.M + 1j * w * model.C).toarray() if w else K.toarray())
        f = pf.factorize(vals, positive_definite=not w, superlu_options=dict(permc_spec="MMD_AT_PLUS_A"))
        ref = sd.factorize(A, positive_definite=not w, symmetric=True)
        assert f.backend == ref.backend
        for b in (B, B[:, 0]):
            x0 = ref.solve(b)
            assert np.abs(f.solve(b) - x0).max() <= tol * np.abs(x0).max()
        x0 = ref.solve(Bs.toarray())
        assert np.abs(f.solve(Bs) - x0).max() <= tol * np.abs(x0).max()
        if w == 1.5:
            alive.append(f)  # held: the next matrix needs an instance of its own
        del f, ref
    if name in ("mumps", "pardiso"):
        # 1.5 (held), 3.0 fresh; 1.515 reuses 3.0's instance; the real K another kind (CHOLMOD
        # is not the named back-end here: MUMPS LDL^T or PARDISO LL^T of K, a fresh real analysis)
        assert (pf.analyses, pf.reused) == (3, 1)
        pf.release()
        assert not any(pf._idle.values())
    with pytest.raises(ValueError, match="values expected"):
        pf.factorize(parts[0][:-1])


@pytest.mark.parametrize("name", ["superlu"] + OPTIONAL)
def test_hbm_steps_with_shared_analysis_and_harmonic_zero(forced_box, name):
    """Newton steps of one HBM system at several frequencies (harmonic 0's factors kept across
    frequencies, the other harmonics' analysis shared, the condensation columns solved as sparse
    right-hand sides) equal those of a fresh system at each frequency (none of it shared), to the
    block solver's refinement tolerance (a backward error of a few eps ||J||: cond(J) eps forward;
    the multiple 100 of the fixture's tol covers cond(J) / cond(K) of this small box)."""
    model, tol = forced_box
    H = fm.Harmonics(3)
    pr = fm.ForcedResponseProblem(model, H)
    x = pr.initial_guess(1.5)
    static = None
    for w in (1.5, 1.52, 1.54):
        r, J, _ = pr.residual(x, w)
        dx = J.factorize().solve(r)
        fresh = fm.ForcedResponseProblem(model, H)
        r0, J0, _ = fresh.residual(x, w)
        dx0 = J0.factorize().solve(r0)
        assert np.abs(dx - dx0).max() <= tol * np.abs(dx0).max()
        pat = pr.system.linear.block_pattern()
        assert not pat.banded
        blk0 = pr.system.linear.factors(w).blocks[0]
        assert static is None or blk0 is static  # harmonic 0 (Z = K) shared by the frequencies
        static = blk0
    # Z(0) = K at any xi too (the nonlinear-mode continuation's unknown): one entry, shared
    assert pr.system.linear.factors(1.54, 0.3).blocks[0] is static and len(pat.static) == 1
    if name in ("mumps", "pardiso"):
        assert pat.factorizer.reused > 0


@pytest.mark.parametrize("name", ["superlu"] + OPTIONAL)
def test_reuse_by_gmres_on_sparse_blocks(forced_box, name):
    """BlockSolver(reuse=True) on sparse-direct blocks solves by GMRES preconditioned with the
    factors of w0 (hbm.linsolve.krylov): the step equals the exact path's at w to the fixture's
    cond eps tolerance (GMRES stops at a hundredth of the exact path's backward-error test, below
    one eps); past its pass budget it refactorises and solves exactly."""
    from femodes.hbm.linsolve import BlockSolver
    from femodes.hbm.linsolve.krylov import KrylovReusedFactorization

    model, tol = forced_box
    H = fm.Harmonics(3)
    solver = BlockSolver(reuse=True, max_passes=60)
    pr = fm.ForcedResponseProblem(model, H, solver=solver)
    x = pr.initial_guess(1.5)
    r, J, _ = pr.residual(x, 1.5)
    x = x - J.factorize().solve(r)                   # the base factors at w0 = 1.5, contacts closed
    for w in (1.5 * (1 + 1e-3), 1.5 * (1 + 1e-2)):
        r, J, _ = pr.residual(x, w)
        fac = J.factorize()
        assert isinstance(fac, KrylovReusedFactorization) and fac.F.omega == 1.5
        dx = fac.solve(r)
        r0, J0, _ = fm.ForcedResponseProblem(model, H).residual(x, w)
        dx0 = J0.factorize().solve(r0)
        assert np.abs(dx - dx0).max() <= tol * np.abs(dx0).max()
    assert solver.stats["refactorized"] == 0 and solver.stats["passes"] >= 4
    # a budget of 2 passes at a 10 % offset: refactorised at w, the exact solution
    solver2 = BlockSolver(reuse=True, max_passes=2, reuse_window=0.2)
    pr2 = fm.ForcedResponseProblem(model, H, solver=solver2)
    pr2.residual(x, 1.5)[1].factorize()
    r, J, _ = pr2.residual(x, 1.65)
    fac = J.factorize()
    dx = fac.solve(r)
    assert solver2.stats["refactorized"] == 1 and fac.refactored is not None and fac.refactored.exact
    r0, J0, _ = fm.ForcedResponseProblem(model, H).residual(x, 1.65)
    dx0 = J0.factorize().solve(r0)
    assert np.abs(dx - dx0).max() <= tol * np.abs(dx0).max()


def test_auto_reuse_follows_the_blocks_kind_and_size(box):
    """BlockSolver's default reuse="auto" reuses factors on sparse-direct blocks of at least
    ``reuse_auto_min_rows`` interior rows (GMRES with the last frequency's factors), and not below
    it: the small box below the default limit factorises at every frequency, and with the limit
    lowered under its size the next frequency is solved with the factors of the first."""
    from femodes.hbm.linsolve import BlockSolver, BlockSolverOptions
    from femodes.hbm.linsolve.krylov import KrylovReusedFactorization

    model, K, Z, tol = box
    forced = model.with_forcing(fm.HarmonicForce(at=("right", "u_x"), amplitude=1e-3))
    H = fm.Harmonics(3)
    for limit, reused in ((None, False), (100, True)):
        solver = BlockSolver() if limit is None else BlockSolver(options=BlockSolverOptions(reuse_auto_min_rows=limit))
        pr = fm.ForcedResponseProblem(forced, H, solver=solver)
        x = pr.initial_guess(1.5)
        J = pr.residual(x, 1.5)[1]
        assert solver.reuses(J) is reused and J.system.linear.block_pattern().perm.size < 10000
        J.factorize()
        fac = pr.residual(x, 1.5 * (1 + 1e-3))[1].factorize()
        assert isinstance(fac, KrylovReusedFactorization) is reused


def test_block_pattern_pickles_without_its_factorisations(box):
    """A pattern that has factorised (its PatternFactorizer and harmonic 0's factors attached)
    pickles without them; the copy factorises anew and solves alike."""
    import pickle

    from femodes.hbm.linsolve import BlockLU, build_pattern

    model, K, Z, tol = box
    bd = np.array(sorted({c.dof for c in model.contacts}))
    pat = build_pattern(model.M, model.K, model.C, bd)
    lu = BlockLU(pat, 1.5)
    pat.static = {True: object()}
    assert pat.factorizer is not None
    copy = pickle.loads(pickle.dumps(pat))
    assert copy.factorizer is None and copy.static is None and pat.factorizer is not None
    R = np.random.default_rng(6).standard_normal((pat.perm.size, 2)) + 0j
    ref = lu.solve(R)
    assert np.abs(BlockLU(copy, 1.5).solve(R) - ref).max() <= tol * np.abs(ref).max()
