"""Stability of periodic solutions: Hill's method, shooting, bifurcations along branches.

References (``../shared/references.md``, "Stability"): the damped linear oscillator's exact
multipliers; the forced Duffing branch unstable exactly between its folds; Liouville's formula
``prod mu = exp(-c T)`` for damped 1-DOF systems.
"""

import dataclasses
import importlib
import math

import numpy as np
import pytest
import scipy.sparse as sp

import femodes as fm
from femodes.hbm import HBMSystem
from femodes.hbm import hill as hill_mod
from femodes.hbm.hill import hill_exponents


def oscillator(c=0.1, k3=0.0, force=1.0, gap=None, w0=1.0):
    m = fm.StructuralModel(M=sp.eye(1), K=w0 ** 2 * sp.eye(1), C=c * sp.eye(1))
    m = m.with_forcing(fm.HarmonicForce(at=0, amplitude=force))
    if k3:
        m = m.with_nonlinearity(fm.CubicSpring(at=0, k3=k3))
    if gap is not None:
        m = m.with_contact(fm.UnilateralContact(at=0, gap=gap))
    return m


@pytest.fixture(scope="module")
def duffing():
    """Forced Duffing c = 0.1, eps = 1 (references.md table), H = 9, with stability."""
    return fm.frequency_response(oscillator(k3=1.0), (0.5, 4.0), 9, stability=True)


def test_linear_oscillator_exact_multipliers_both_methods():
    # mu = exp((-zeta w0 +/- i w0 sqrt(1 - zeta^2)) T), whatever the forcing frequency.
    zeta, w0 = 0.05, 1.3
    model = oscillator(c=2 * zeta * w0, w0=w0)
    branch = fm.frequency_response(model, (0.8, 1.0), 5)
    sol = branch[len(branch) // 2]
    T = 2 * np.pi / sol.omega
    exact = np.exp((-zeta * w0 + 1j * w0 * math.sqrt(1 - zeta ** 2)) * T)
    for method, tol in ((fm.stability_methods.Hill(), 1e-10), (fm.stability_methods.Shooting(), 1e-8)):
        # Hill: the linear Hill problem is exact, round-off only; shooting: DOP853 at rtol 1e-11
        r = fm.stability(sol, method=method)
        assert r.method == method.name and r.stable
        assert sorted(r.multipliers.imag) == pytest.approx(sorted([exact.imag, -exact.imag]), abs=tol)
        assert np.allclose(r.multipliers.real, exact.real, atol=tol)


def test_duffing_unstable_exactly_between_its_folds(duffing):
    b = duffing
    assert b.stable is not None and len(b.folds) == 2
    lo, hi = sorted(b.folds)
    idx = np.arange(len(b))
    # the fold points themselves carry the multiplier +1 (|mu| - 1 within the 1e-4 tolerance)
    assert np.all(~b.stable[(idx > lo) & (idx < hi)])
    assert np.all(b.stable[(idx < lo) | (idx > hi)])
    kinds = [(z.kind, z.omega) for z in b.bifurcations]
    assert [k for k, _ in kinds] == ["fold", "fold"]
    # references.md (H = 21, confirmed by shooting): folds at 3.03905472 and 1.64624961; H = 9
    # is converged to about 1e-7 here (exponential convergence of the smooth Duffing)
    assert sorted(w for _, w in kinds) == pytest.approx([1.64624961, 3.03905472], rel=1e-6)
    # a real multiplier > 1 in between
    mid = (lo + hi) // 2
    mu = b.multipliers[mid]
    assert abs(mu[0].imag) < 1e-12 and mu[0].real > 1.0


@pytest.mark.parametrize("w", [2.0, 3.0])
def test_duffing_coexisting_orbits_middle_one_unstable(duffing, w):
    b = duffing
    amp = b.amplitude(0)
    found = []
    for i in np.flatnonzero(np.diff(np.sign(b.omega - w)) != 0):
        # the point of the crossing segment nearer to w (both ends share stability away from folds)
        j = i if abs(b.omega[i] - w) < abs(b.omega[i + 1] - w) else i + 1
        found.append((amp[j], bool(b.stable[j])))
    found.sort(reverse=True)
    assert len(found) == 3
    assert [s for _, s in found] == [True, False, True]  # references.md: the middle orbit is unstable


def test_hill_and_shooting_agree_on_a_smooth_orbit(duffing):
    # On the smooth Duffing both are accurate; the HBM orbit at H = 9 differs from the true one
    # by ~1e-7 (fold frequencies above), so the multipliers agree to a few 1e-6.
    # lower branch, upper branch before its fold, unstable middle branch
    f0, f1 = duffing.folds[:2]
    for i in (5, f0 - 3, (f0 + f1) // 2):
        sol = duffing[i]
        h = fm.stability(sol, method=fm.stability_methods.Hill()).multipliers
        s = fm.stability(sol, method=fm.stability_methods.Shooting()).multipliers
        assert np.sort_complex(h) == pytest.approx(np.sort_complex(s), abs=1e-5)


def test_hill_multipliers_obey_liouville(duffing):
    # prod mu = exp(-c T) for u'' + c u' + f(u) = F(t): the trace of the linearised system is -c.
    for i in range(0, len(duffing), 7):
        sol = duffing[i]
        mu = fm.stability(sol, method=fm.stability_methods.Hill()).multipliers
        assert np.prod(mu) == pytest.approx(math.exp(-0.1 * sol.period), rel=1e-9)


def test_period_doubling_of_the_seed_contact_case_by_shooting():
    """Seed case 1 (u'' + 0.1 u' + u = 0.2 cos wt - p, gap 1): the impacting resonance branch
    period-doubles at w = 0.996204 (shooting refines each HBM orbit into the true orbit, so the
    location does not depend on H: measured 0.99620415 at H = 10, 20 and 40)."""
    b = fm.frequency_response(oscillator(c=0.1, force=0.2, gap=1.0), (0.97, 1.02), 10, stability=True)
    pd = [z for z in b.bifurcations if z.kind == "period_doubling"]
    assert len(pd) == 1
    assert pd[0].omega == pytest.approx(0.996204, abs=2e-6)
    assert pd[0].multiplier == pytest.approx(-1.0, abs=1e-6)
    # a problem this small is located precisely (to 1e-7 of the segment, where |mu| + 1 vanishes to
    # 1e-9): the reported solution is the crossing itself
    assert pd[0].located and pd[0].bracket == (pd[0].omega, pd[0].omega)
    assert set(b.stability_method) == {"shooting"}
    below = b.omega < pd[0].omega
    assert np.all(~b.stable[below]) and np.all(b.stable[~below])


def test_seed_contact_case_bracketed_by_few_solves(cheap_location):
    """Seed case 1 at H = 20 with ``locate=True`` on a problem counted as large
    (PRECISE_MAX_UNKNOWNS lowered to 0): the grazing jump and the period doubling of the precise
    location, the jump told apart by bisecting its flat profile (at most JUMP_SOLVES solves), the
    period doubling with at most LOCATE_SOLVES, its bracket holding the precise location
    (0.996204, the true orbit's by shooting) and narrower than the segment."""
    from femodes import branch_stability as bs

    model = oscillator(c=0.1, force=0.2, gap=1.0)
    precise = fm.frequency_response(model, (0.9, 1.05), 20, stability=True)
    with cheap_location() as solves:
        cheap = fm.frequency_response(model, (0.9, 1.05), 20, stability=True)
    np.testing.assert_array_equal(cheap.stable, precise.stable)
    assert [(z.kind, z.index) for z in cheap.bifurcations] == [(z.kind, z.index) for z in precise.bifurcations]
    assert [z.kind for z in cheap.bifurcations] == ["nonsmooth", "period_doubling"]
    assert len(solves) <= bs.JUMP_SOLVES + bs.LOCATE_SOLVES
    pd, pd_precise = cheap.bifurcations[1], precise.bifurcations[1]
    assert pd_precise.omega == pytest.approx(0.996204, abs=2e-6)
    lo, hi = pd.bracket
    assert pd.located and pd.omega in (lo, hi) and lo < pd_precise.omega < hi
    assert hi - lo < cheap.omega[pd.index + 1] - cheap.omega[pd.index]


def test_stability_survives_save_and_load(duffing, tmp_path):
    path = duffing.save(tmp_path / "duffing.npz")
    back = fm.load_branch(path)
    assert np.array_equal(back.stable, duffing.stable)
    assert np.allclose(back.multipliers, duffing.multipliers, equal_nan=True)
    assert [(z.kind, z.index, z.omega) for z in back.bifurcations] == \
        [(z.kind, z.index, z.omega) for z in duffing.bifurcations]
    assert np.array_equal(back.bifurcations[0].Q, duffing.bifurcations[0].Q)


def test_conservative_backbone_is_stable():
    # free undamped Duffing: multipliers on the unit circle (the two trivial ones at +1 aside)
    model = fm.StructuralModel(M=sp.eye(1), K=sp.eye(1)).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
    b = fm.nonlinear_mode(model, energy=(1e-2, 1.0), harmonics=7, stability=fm.stability_methods.Hill())
    assert b.stable.all() and not b.bifurcations
    # conservative: every multiplier on the circle; the trivial double +1 is a Jordan block whose
    # computed pair splits by ~sqrt(Newton tolerance 1e-9 relative) ~ 3e-5, the others by round-off
    assert np.nanmax(np.abs(np.abs(b.multipliers) - 1.0)) < 1e-3
    assert np.nanmax(np.abs(b.multipliers - 1.0)) < 1e-3


@pytest.mark.parametrize("contact, H", [("penalty", 5), ("penalty", 10), ("unilateral", 10)])
def test_sparse_hill_finds_the_leading_exponents(monkeypatch, contact, H):
    """A clamped bar against a stop: the shift-invert path (used above DENSE_LIMIT unknowns)
    returns the dense solve's leading multiplier. Its leading exponent lies outside the band of
    the shifts (Im s ~ w + 0.07), so the shifts find a copy first and must follow it to the
    central member (a copy's real part is off by 13 % here; benchmarks/README_stability.md)."""
    mesh = fm.line_mesh(length=1.0, n_elements=10, boundaries={"clamp": 0.0, "tip": 1.0})
    law = (fm.PenaltyContact(at="tip", gap=0.05, stiffness=5.0) if contact == "penalty"
           else fm.UnilateralContact(at="tip", gap=0.05))
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_damping(beta=0.01)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.01))
             .with_contact(law, contact_mass=fm.ConsistentMass()))
    b = fm.frequency_response(model, (1.3, 1.9), H)
    sol = b[int(np.argmax(b.amplitude(model.n_dofs - 1)))]  # the deepest contact
    system = HBMSystem(model, sol.harmonics)
    y = system.join(sol.Q, sol.P)
    dense = hill_exponents(system, y, sol.omega)
    monkeypatch.setattr(hill_mod, "DENSE_LIMIT", 10)
    sparse = hill_exponents(system, y, sol.omega, reduce=False)  # the model itself, not a reduction
    assert dense.complete and not sparse.complete
    # ARPACK tol 1e-8 on the shifted-inverted Ritz values: the leading modulus to ~1e-8
    assert np.abs(sparse.multipliers[0]) == pytest.approx(np.abs(dense.multipliers[0]), rel=1e-7)
    # what the sparse path returns is a subset of the dense multipliers (conjugate pairs included)
    for mu in sparse.multipliers:
        assert np.min(np.abs(dense.multipliers - mu)) < 1e-6


def test_bad_input_names_the_argument(duffing):
    model = oscillator(k3=1.0)
    with pytest.raises(ValueError, match="stability must be True, False, a strategy"):
        fm.frequency_response(model, (0.5, 1.0), 3, stability="maybe")
    with pytest.raises(ValueError, match="method must be a stability strategy"):
        fm.stability(duffing[0], method="floquet")
    with pytest.raises(TypeError, match="PeriodicSolution"):
        fm.stability(duffing)
    sol = duffing[0]
    with pytest.raises(ValueError, match="attach"):
        fm.stability(dataclasses.replace(sol, model=None))


def test_shooting_refuses_a_massless_contact_dof():
    M = sp.diags([1.0, 0.0])
    K = sp.csr_matrix(np.array([[2.0, -1.0], [-1.0, 1.0]]))
    model = (fm.StructuralModel(M=M, K=K, C=0.05 * K).with_forcing(fm.HarmonicForce(at=0, amplitude=0.1))
             .with_contact(fm.UnilateralContact(at=1, gap=0.5)))
    b = fm.frequency_response(model, (0.5, 0.6), 3)
    with pytest.raises(ValueError, match=r"stability_methods.Hill\(\)"):
        fm.stability(b[0], method=fm.stability_methods.Shooting())
    assert fm.stability(b[0]).method == "hill"  # "auto" takes Hill for it


def test_switch_onto_the_period_doubled_branch_confirmed_by_shooting():
    """Seed case 1: from the period doubling (shooting-located at 0.996204) onto the HBM's own
    period-doubled branch (H = 20: born at w = 0.95959, the truncated series' doubling), traced
    on the harmonics of w/2; a point of it, shot over two forcing periods from the HBM state,
    converges to a true period-2 orbit of the impact oscillator close to the HBM one."""
    model = oscillator(c=0.1, force=0.2, gap=1.0)
    b = fm.frequency_response(model, (0.9, 1.05), 20, stability=True)
    pd = next(z for z in b.bifurcations if z.kind == "period_doubling")
    new = fm.switch_branch(b, pd, omega=(0.9, 1.05))
    assert new.success and new.harmonics.subharmonic == 2 and new.harmonics.n_harmonics == 40
    assert new.meta["switched_from"]["omega_hbm"] == pytest.approx(0.95959, abs=1e-4)
    assert new.omega.max() <= new.meta["switched_from"]["omega_hbm"] + 1e-6  # born there, runs downwards
    s = new[len(new) // 2]
    n = 512
    theta = 2 * np.pi * np.arange(n) / n
    t0 = theta[np.argmin(s.harmonics.grid.synthesis(theta) @ s.Q[:, 0])] / (2 * np.pi) * s.period  # away from the stop
    x0 = np.array([s.displacement([t0])[0, 0], s.velocity([t0])[0, 0]])
    half = np.array([s.displacement([t0 + s.period / 2])[0, 0], s.velocity([t0 + s.period / 2])[0, 0]])
    assert np.max(np.abs(half - x0)) > 0.1                      # the HBM orbit is period 2, not period 1
    r = fm.time.shoot(model, s.omega, x0, period=s.period, t0=t0)
    assert r.success
    # measured 3.5e-2 (the HBM's contact error at H = 20): the true orbit is this one
    assert np.max(np.abs(r.x - x0)) < 0.06 * np.max(np.abs(x0))
    xT = fm.time.trajectory(model, s.omega, r.x, [t0 + s.period / 2], t0=t0)[0]
    assert np.max(np.abs(xT - r.x)) > 0.1                      # and it is period 2 in the time domain too


def test_switch_branch_rejects_other_kinds(duffing):
    with pytest.raises(NotImplementedError, match="period doubling"):
        fm.switch_branch(duffing, duffing.bifurcations[0], omega=(1.0, 2.0))


def test_a_free_orbit_of_a_model_with_forcing_is_judged_as_free():
    """A nonlinear mode of a model that also declares a forcing: fm.stability goes by the
    solution's branch kind (free orbit: the trivial pair aside), not by the model's forcing."""
    model = (fm.StructuralModel(M=sp.eye(1), K=sp.eye(1)).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
             .with_forcing(fm.HarmonicForce(at=0, amplitude=1.0)))
    b = fm.nonlinear_mode(model, energy=(1e-2, 1.0), harmonics=7)
    r = fm.stability(b[3], method=fm.stability_methods.Hill())
    assert b[3].kind == "nonlinear mode" and r.stable


def test_shooting_a_free_orbit_of_the_backbone():
    """method="shooting" on a nonlinear mode shoots the free model (period unknown): the free
    Duffing orbit is stable, its trivial pair at +1 aside."""
    model = fm.StructuralModel(M=sp.eye(1), K=sp.eye(1)).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
    b = fm.nonlinear_mode(model, energy=(1e-2, 1.0), harmonics=9)
    r = fm.stability(b[len(b) // 2], method=fm.stability_methods.Shooting())
    assert r.method == "shooting" and r.stable
    assert np.max(np.abs(r.multipliers - 1.0)) < 1e-3
    with pytest.raises(TypeError, match="tol must be a number"):
        fm.stability(b[0], tol="small")


def test_auto_takes_hill_for_a_stiff_model(monkeypatch):
    """A fastest natural frequency far above the orbit's (here 1414 against 1: two masses joined by
    a spring of stiffness 1e6) makes shooting integrate thousands of fast periods per orbit; "auto"
    then takes Hill's method without trying (Auto.max_stiffness); a larger one shoots."""
    methods = importlib.import_module("femodes.stability_methods")
    k = 1e6
    model = (fm.StructuralModel(M=np.eye(2), K=[[1.0 + k, -k], [-k, k]], C=0.1 * np.eye(2))
             .with_contact(fm.UnilateralContact(at=1, gap=1.0)).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    assert methods.fastest_frequency(model) == pytest.approx(math.sqrt(1.0 + 2.0 * k), rel=1e-6)
    b = fm.frequency_response(model, (0.3, 0.35), 6)
    with monkeypatch.context() as m:
        m.setattr(methods, "shooting_multipliers", lambda *a, **kw: pytest.fail("shooting attempted"))
        assert fm.stability(b[0]).method == "hill"
        assert fm.stability(b[0], method=fm.stability_methods.Auto()).method == "hill"
    # a larger max_stiffness shoots: on a model whose fastest frequency is 47 times the orbit's
    # (k = 100; shooting the k = 1e6 model itself integrated 4700 fast periods: 140-160 s), the default
    # (50) shoots and max_stiffness=10 takes Hill
    soft = (fm.StructuralModel(M=np.eye(2), K=[[101.0, -100.0], [-100.0, 100.0]], C=0.1 * np.eye(2))
            .with_contact(fm.UnilateralContact(at=1, gap=1.0)).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    assert methods.fastest_frequency(soft) / 0.3 == pytest.approx(47.2, rel=1e-2)
    p = fm.frequency_response(soft, (0.3, 0.35), 6)[0]
    assert fm.stability(p).method == "shooting"
    assert fm.stability(p, method=fm.stability_methods.Auto(max_stiffness=10.0)).method == "hill"
    with pytest.raises(ValueError, match="max_stiffness must be a positive number"):
        fm.stability_methods.Auto(max_stiffness=0)


def test_auto_gives_shooting_up_along_a_branch(monkeypatch, caplog):
    """Shooting is given up for the whole branch once its failures took AUTO_MAX_FAILED_TIME (10 s):
    on a shallow arch's Craig-Bampton model every contact orbit but the grazing one failed, 6-11 s
    each, and stability=True took 650 s for a 0.7 s branch. The branch is then Hill's throughout
    (one method: bifurcations are looked for between every two points). Cheap failures keep
    shooting: the seed oscillator at H = 6 fails at 13 points in a row near its upper fold, then
    shoots its period doubling (tests/test_moved_names.py). Here failures take 0.5 s against a
    budget of 1.2 s (patched): the third one gives up (a point's own work, a few ms, would have to
    take 0.1 s to change that). Instant failures against a budget of 5 s (their points' work, under
    0.01 s each, was 0.12 s in all on a loaded machine) keep shooting."""
    import time
    methods = importlib.import_module("femodes.stability_methods")
    model = oscillator(gap=1.0, force=0.2)
    b = fm.frequency_response(model, (0.5, 2.0), 10)
    contact = [bool(np.any(b.P[i])) for i in range(len(b))]
    assert 5 < sum(contact) < len(b) - 5
    real = methods.shooting_multipliers

    def run(pause, budget):
        calls = []

        def fake(orbit, tol, max_iter=30):
            assert max_iter == methods.AUTO_MAX_ITER
            touching = bool(np.any(orbit.y[orbit.system.nq:]))
            calls.append(touching)
            if touching:
                time.sleep(pause)
                raise methods.ShootingFailed("no progress")
            return real(orbit, tol, max_iter)
        with monkeypatch.context() as m:
            m.setattr(methods, "shooting_multipliers", fake)
            m.setattr(methods, "AUTO_MAX_FAILED_TIME", budget)
            return fm.frequency_response(model, (0.5, 2.0), 10, stability=True), calls

    with caplog.at_level("INFO", logger="femodes"):
        s, calls = run(0.5, 1.2)
    assert set(s.stability_method) == {"hill"} and sum(calls) == 3 and len(calls) == contact.index(True) + 3
    assert "shooting failed at 3 of the first" in caplog.text and "Hill's method along the whole branch" in caplog.text
    s, calls = run(0.0, 5.0)  # instant failures: shooting goes on, Hill where it fails
    assert len(calls) == len(b) and list(s.stability_method).count("shooting") == len(b) - sum(contact)
