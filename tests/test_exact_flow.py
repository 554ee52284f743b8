"""The exact flow of a linear model with rigid stops (femodes.time.exact) and the shooting
refinement of error-controlled branches built on it (femodes.accuracy, method "shooting").

References: the event-driven DOP853 shooting of femodes.time.shooting (an independent
integration of the same orbit, tolerance 1e-12), the semi-analytic upper fold of
tests/impact_reference.py, and the grazing frequency of the linear response in closed form.
"""

import math

import numpy as np
import pytest

import femodes as fm
from femodes.accuracy import AccuracyOptions, estimate_error
from femodes.accuracy.exact_branch import ExactBranchCache
from femodes.accuracy.ladder import ladder_for
from femodes.accuracy.points import without_contact
from femodes.accuracy.shooter import Shooter
from femodes.accuracy.shooting import shoot_branch
from femodes.time import shoot
from femodes.time.exact import LinearImpactFlow, exact_flow_unsupported

from .impact_reference import upper_fold
from .massless_reference import MasslessContactReference

OPTIONS = AccuracyOptions()  # the defaults


def _forced(c=0.1, F=0.2, g=1.0):
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[c]]).with_contact(fm.UnilateralContact(at=0, gap=g))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=F)))


def _periodic(flow, x, t0):
    """Newton on x(t0 + T) - x0, halving steps that would start inside the obstacle."""
    for _ in range(40):
        run = flow.run(x, t0, variational=True)
        F = run.x_end - x
        if np.max(np.abs(F)) < 1e-13:
            return x, run
        d = -np.linalg.solve(run.Phi - np.eye(x.size), F)
        while np.any(flow.gaps - (x + d)[flow.dofs] < 0.0):
            d *= 0.5
        x = x + d
    raise AssertionError("no periodic orbit")


@pytest.fixture(scope="module")
def orbit():
    """The impacting orbit (a non-impacting one coexists) from a harmonic balance point below the
    upper fold, started at its most open phase."""
    model = _forced()
    b = fm.frequency_response(model, (0.5, 2.0), 10)
    i = max(b.folds, key=lambda j: b.omega[j]) - 5
    x, theta0 = Shooter(ladder_for(b, None, None), OPTIONS).start(i)
    w = float(b.omega[i])
    flow = LinearImpactFlow(model, w)
    x, run = _periodic(flow, x, theta0 / w)
    return model, flow, w, theta0 / w, x, run


def test_orbit_matches_event_driven_integration(orbit):
    """Same orbit and multipliers as the DOP853 event-driven shooting (rtol 1e-12): the state to
    1e-8 of its size (the integrator's error accumulates over the period), the multipliers to 1e-7."""
    model, flow, w, t0, x, run = orbit
    assert len(run.impacts) == 1
    ref = shoot(model, w, x, t0=t0, tol=1e-12, rtol=1e-12, atol=1e-13)
    assert ref.success
    np.testing.assert_allclose(x, ref.x, atol=1e-8 * np.max(np.abs(x)))
    mu = np.sort_complex(np.linalg.eigvals(run.Phi))
    np.testing.assert_allclose(mu, np.sort_complex(ref.multipliers), atol=1e-7)


def test_monodromy_matches_finite_differences(orbit):
    _, flow, _, t0, x, run = orbit
    eps = 1e-6
    fd = np.column_stack([(flow.run(x + eps * e, t0).x_end - flow.run(x - eps * e, t0).x_end) / (2 * eps)
                          for e in np.eye(2)])
    np.testing.assert_allclose(run.Phi, fd, atol=1e-7)  # central differences: O(eps^2) plus round-off / eps


def _omega_derivatives_against_central_differences(model, states, omegas, H=12):
    """Relative differences of FlowRun.x_end_omega and coefficient_omega(H) from central
    differences (step 1e-6 w) at the start phases 0 and 1, at the points where the runs at
    w +- dw have as many events as the run at w (a grazing in between has no derivative)."""
    flow = LinearImpactFlow(model, 1.0)
    errs = []
    for w, x in zip(omegas, states):
        for theta in (0.0, 1.0):
            run = flow.at(w).run(x, theta / w, variational=True)
            dw = 1e-6 * w
            side = [flow.at(w + s).run(x, theta / (w + s)) for s in (dw, -dw)]
            if any(len(r.impacts) + len(r.switches) != len(run.impacts) + len(run.switches) for r in side):
                continue
            fd_x = (side[0].x_end - side[1].x_end) / (2 * dw)
            fd_q = (side[0].coefficients(H)[0] - side[1].coefficients(H)[0]) / (2 * dw)
            errs.append((np.max(np.abs(run.x_end_omega - fd_x)) / np.max(np.abs(fd_x)),
                         np.max(np.abs(run.coefficient_omega(H) - fd_q)) / np.max(np.abs(fd_q)),
                         len(run.impacts) + len(run.switches)))
    return np.array(errs)


@pytest.mark.parametrize("massless", [False, True])
def test_frequency_derivatives_match_central_differences(massless):
    """d x_end / dw and d Q / dw at fixed start phase (analytic: the particular solution's change
    through the segments, saltation at impacts, the start and end times' moves; closed-form
    integrals of t times exponentials) equal central differences to 1e-6 (their truncation
    and round-off, eps / 1e-6 ~ 2e-10 times the orbit's sensitivity; measured <= 1.1e-9 on the
    seed case, the 2-DOF massless model and the cantilever), at orbits with and without events."""
    if massless:
        model = _massless_two_dof()
        span = (0.6, 1.6)
    else:
        model = _forced(c=0.2, F=1.0, g=2.5)
        span = (0.5, 2.0)
    b = fm.exact_frequency_response(model, span)
    pick = np.linspace(0, len(b) - 1, 9).astype(int)
    errs = _omega_derivatives_against_central_differences(model, b.states[pick], b.omega[pick])
    assert len(errs) >= 12 and np.sum(errs[:, 2] > 0) >= 4  # orbits with events among them
    assert errs[:, 0].max() <= 1e-6 and errs[:, 1].max() <= 1e-6


def _massless_two_dof():
    return (fm.StructuralModel(M=[[1.0, 0.0], [0.0, 0.0]], K=[[2.0, -1.0], [-1.0, 1.0]], C=[[0.1, 0.0], [0.0, 0.0]])
            .with_contact(fm.UnilateralContact(at=1, gap=1.0)).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


def test_t_integrals_series_and_closed_form_agree():
    """int_ta^tb t e^{mu (t - ta)} dt: the series below |mu D| = 1/2 and the closed form above
    against adaptive quadrature (relative 1e-12), on both sides of the switch."""
    from scipy.integrate import quad

    from femodes.time.exact_fourier import t_integrals

    ta, tb = 0.7, 1.1
    for mu in (0.0, 1e-9, 0.3 - 0.2j, -1.24 + 0.1j, 1.26j, -3.0 + 8.0j, -40.0):
        got = t_integrals(ta, tb, np.array([mu]))[0]
        re = quad(lambda t: t * (np.exp(mu * (t - ta))).real, ta, tb, epsabs=0, epsrel=1e-13)[0]
        im = quad(lambda t: t * (np.exp(mu * (t - ta))).imag, ta, tb, epsabs=0, epsrel=1e-13)[0]
        assert abs(got - (re + 1j * im)) <= 1e-12 * abs(re + 1j * im) + 1e-15


def test_fourier_coefficients_exact(orbit):
    """Closed-form coefficients against the trapezoid rule on 2^14 samples of the same orbit
    (q is continuous with kinks at the impacts: the rule's error is O(N^-2) ~ 1e-8 here), and the
    static balance ``K c0(q) = -c0(p)`` (no static load) to round-off."""
    _, flow, w, t0, x, run = orbit
    Q, P = run.coefficients(8)
    N = 2 ** 14
    T = 2 * math.pi / w
    t = t0 + np.arange(N) * T / N
    q = run.displacement(t)[:, 0]
    ref = [np.mean(q)] + [2 / N * np.sum(q * f(k * w * t)) for k in range(1, 9) for f in (np.cos, np.sin)]
    np.testing.assert_allclose(Q[:, 0], ref, atol=1e-7)
    assert abs(Q[0, 0] + P[0, 0]) <= 1e-13


def test_unsupported_models_named():
    cubic = _forced().with_nonlinearity(fm.CubicSpring(at=0, k3=0.5))
    assert "cubic" in exact_flow_unsupported(cubic)
    pen = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=50.0))
    assert "penalty" in exact_flow_unsupported(pen)
    with pytest.raises(ValueError, match="penalty"):
        LinearImpactFlow(pen, 1.0)
    with pytest.raises(ValueError, match="omega"):
        LinearImpactFlow(_forced(), -1.0)


@pytest.fixture(scope="module")
def shot10():
    branch = fm.frequency_response(_forced(), (0.5, 2.0), 10)
    return estimate_error(branch, rtol=1e-3, method=fm.error_methods.Shooting())


def test_shooting_folds_exact(shot10):
    """Upper fold: the semi-analytic reference to 1e-9 (the stated floor); lower fold: the grazing
    of the linear response, |1 - w^2 + 0.1 i w| = 0.2 in closed form (w^2 = (1.99 + sqrt(0.1201)) / 2)."""
    b = shot10
    acc = b.accuracy
    up, lo = sorted(b.folds, key=lambda i: -b.omega_truncated[i])
    ref = upper_fold(0.1, 0.2, 1.0).w
    assert abs(acc.omega_limit[up] / ref - 1.0) <= OPTIONS.shooting_floor
    graze = math.sqrt((1.99 + math.sqrt(1.99 ** 2 - 4 * 0.96)) / 2)
    assert abs(acc.omega_limit[lo] / graze - 1.0) <= OPTIONS.shooting_floor
    assert acc.met[[up, lo]].all() and acc.omega_limit_error[up] <= 1e-6
    # the estimate of the H = 10 fold's own error (relative to its frequency) is its true error
    # (4.7 %) plus the floor
    assert abs(acc.omega[up] - abs(b.omega_truncated[up] - ref) / b.omega_truncated[up]) <= 2 * OPTIONS.shooting_floor


def test_shooting_meets_rtol_where_the_orbit_is_a_counterpart(shot10):
    """Every point has an exact counterpart and meets rtol: on its hyperplane, or, next to the
    two grazings (w = 0.90649 and 1.08087 in closed form), where the exact curve crosses the
    planes obliquely (kappa outside (0, 3]), the exact orbit at the point's own frequency (its
    omega_limit is its frequency; one point next to each grazing at H = 10)."""
    b, acc = shot10, shot10.accuracy
    assert np.all(acc.method == "shooting") and acc.met.all()
    root = math.sqrt(1.99 ** 2 - 4 * 0.96)
    grazings = np.array([math.sqrt((1.99 - root) / 2), math.sqrt((1.99 + root) / 2)])
    contact = np.abs(b.P).reshape(len(b), -1).max(axis=1) > 0.0
    at_w = np.flatnonzero((acc.omega_limit == b.omega_truncated) & contact)
    assert 1 <= at_w.size <= 4
    assert np.all(np.min(np.abs(b.omega_truncated[at_w, None] / grazings - 1.0), axis=1) < 0.01)


def test_shooting_method_checked():
    duffing = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.05]]).with_nonlinearity(fm.CubicSpring(at=0, k3=0.5))
               .with_forcing(fm.HarmonicForce(at=0, amplitude=0.1)))
    b = fm.frequency_response(duffing, (0.8, 1.3), 3)
    with pytest.raises(ValueError, match="the shooting error method cannot take this branch"):
        estimate_error(b, method=fm.error_methods.Shooting())
    with pytest.raises(ValueError, match="method must be an error method"):
        estimate_error(b, method="exact")


def _bar(ne=6):
    """The FE bar with a tip mass and a stop of README_accuracy section 2 (consistent mass at the
    contact node: the impulse acts along M^-1 e_c, not on the tip DOF alone)."""
    mesh = fm.line_mesh(length=1.0, n_elements=ne, boundaries={"clamp": 0.0, "tip": 1.0})
    return (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp",
                   point_masses={"tip": 0.75})
            .with_damping(beta=0.02).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.05))
            .with_contact(fm.UnilateralContact(at="tip", gap=1.0), contact_mass=fm.ConsistentMass()))


def test_fe_bar_orbit_matches_event_driven_integration():
    """6-element bar near its upper fold (the exact orbit on the hyperplane of an H = 8 point): it
    is a periodic orbit of the DOP853 event-driven shooting too (rtol 1e-12), equal to 1e-7 of the
    state, with the same number of impacts; the impulse moves the neighbouring DOF too."""
    model = _bar()
    w1 = float(fm.linear_modes(model, n=1).omega[0])
    b = fm.frequency_response(model, (0.9 * w1, 1.25 * w1), 8)
    i = max(b.folds, key=lambda j: b.omega[j]) - 3
    # the exact orbit on the point's hyperplane (a plain Newton from the point lands on the
    # coexisting orbit without impacts)
    x, w, theta0, run = Shooter(ladder_for(b, None, None), OPTIONS).solve(i)[:4]
    flow = run.flow
    tip = model.dof("tip")
    assert len(run.impacts) >= 1 and np.max(np.abs(run.x_end - x)) <= 1e-10 * np.max(np.abs(x))
    assert np.count_nonzero(np.abs(flow.impact_dir[0]) > 1e-12) > 1  # consistent mass: not e_c alone
    assert abs(flow.impact_dir[0][tip] - 1.0) < 1e-14
    ref = shoot(model, w, x, t0=theta0 / w, tol=1e-12, rtol=1e-12, atol=1e-13)
    assert ref.success and len(ref.impacts) == len(run.impacts)
    np.testing.assert_allclose(x, ref.x, atol=1e-7 * np.max(np.abs(x)))


def _chain(gap=0.6):
    """Masses on DOFs 0 and 2, a massless contact DOF 1 between them (zero row of M and C):
    springs ground-0 (1), 0-1 (1), 1-2 (2), 2-ground (1); damping 0.05 M; forces on DOF 0 (first
    harmonic, a static part) and DOF 2 (second harmonic)."""
    K = [[2.0, -1.0, 0.0], [-1.0, 3.0, -2.0], [0.0, -2.0, 3.0]]
    M = np.diag([1.0, 0.0, 0.5])
    return (fm.StructuralModel(M=M, K=K, C=0.05 * M).with_contact(fm.UnilateralContact(at=1, gap=gap))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.6), fm.HarmonicForce(at=0, amplitude=0.1, harmonic=0),
                          fm.HarmonicForce(at=2, amplitude=0.2, harmonic=2, phase=0.3)))


@pytest.fixture(scope="module")
def massless_orbit():
    """The chain's periodic orbit by the independent reference (tests/massless_reference.py: DOP853
    in each mode with switching events, Newton with finite differences)."""
    model = _chain()
    w = 1.1
    ref = MasslessContactReference(model.M.toarray(), model.K.toarray(), model.damping_matrix().toarray(),
                                   model.force_vectors(), w, 1, 0.6)
    flow = LinearImpactFlow(model, w)
    x = ref.periodic_orbit(flow.particular(0.0), 0.0)
    return model, flow, ref, w, x


def test_massless_contact_orbit_matches_reference(massless_orbit):
    """A contact on a massless DOF closes and opens (no impact): the closed-form flow follows the
    reference's periodic orbit back to its start (the reference's Newton tolerance is 1e-10 of the
    state, DOP853 at rtol 1e-12: 1e-8 allowed, 3e-13 measured), with the same switches (times to
    1e-8, 1e-13 measured); massless entries of the start state are ignored and returned
    consistent; Phi equals central finite differences of the flow (step 1e-6: truncation ~1e-12,
    cancellation ~1e-10; 4e-9 measured, 1e-7 allowed)."""
    model, flow, ref, w, x = massless_orbit
    run = flow.run(x, 0.0, variational=True)
    r = ref.run(x, 0.0, 2 * math.pi / w)
    assert len(run.switches) == len(r.switches) == 2 and not run.impacts
    for (t, j, kind), (t_ref, kind_ref) in zip(run.switches, r.switches):
        assert j == 0 and kind == kind_ref and abs(t - t_ref) <= 1e-8
    scale = np.max(np.abs(x))
    np.testing.assert_allclose(run.x_end, r.x_end, rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose(run.x_end, x, rtol=0, atol=1e-8 * scale)
    wrong = x.copy()
    wrong[[1, 4]] = [5.0, -3.0]  # the massless DOF's entries: not part of the state
    np.testing.assert_array_equal(flow.run(wrong, 0.0).x_end, flow.run(x, 0.0).x_end)
    h = 1e-6
    fd = np.column_stack([(flow.run(x + h * e, 0.0).x_end - flow.run(x - h * e, 0.0).x_end) / (2 * h)
                          for e in np.eye(x.size)])
    np.testing.assert_allclose(run.Phi, fd, rtol=0, atol=1e-7)
    assert np.all(run.Phi[:, [1, 4]] == 0.0)


def test_massless_contact_coefficients_match_reference(massless_orbit):
    """Closed-form coefficients of the displacements and of the contact force (piecewise closed
    form, no impulse) against the reference's trapezoid rule on 2^14 samples (kinks at the
    switches: O(N^-2); measured 1.6e-9 for the displacements and 1.5e-8 for the force, relative to
    their largest coefficient; 1e-7 allowed)."""
    model, flow, ref, w, x = massless_orbit
    Q, P = flow.run(x, 0.0).coefficients(6)
    Q_ref, L_ref = ref.coefficients(x, 0.0, 6)
    np.testing.assert_allclose(Q, Q_ref, rtol=0, atol=1e-7 * np.max(np.abs(Q_ref)))
    np.testing.assert_allclose(P[:, 0], L_ref, rtol=0, atol=1e-7 * np.max(np.abs(L_ref)))
    assert P[0, 0] > 0.0


def _fold_frequencies(b):
    return np.sort(b.omega[list(b.folds)])


def test_massless_contact_folds_by_shooting():
    """2-DOF model, contact on the massless DOF: from H = 10 every point is estimated by shooting
    and the folds are those plain harmonic balance converges to: |shooting - H 80| below 2e-7
    (measured 2.2e-8 and 3.8e-8) and below the change from H 40 to H 80 (7e-8, 5.7e-7), on the
    same side. The lower fold is an ordinary fold, not the grazing of the linear response (which
    ends the impacting orbits of a contact with mass: 1.0808687 here)."""
    model = (fm.StructuralModel(M=[[1.0, 0.0], [0.0, 0.0]], K=[[2.0, -1.0], [-1.0, 1.0]], C=[[0.1, 0.0], [0.0, 0.0]])
             .with_contact(fm.UnilateralContact(at=1, gap=1.0)).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    assert exact_flow_unsupported(model) == ""
    b = estimate_error(fm.frequency_response(model, (0.9, 1.3), 10))
    assert set(b.accuracy.method) == {"shooting"}
    shot = np.sort(b.accuracy.omega_limit[list(b.folds)])
    plain = {H: _fold_frequencies(fm.frequency_response(model, (0.9, 1.3), H)) for H in (40, 80)}
    assert abs(shot[0] - 1.0808687) > 2e-3
    for k in range(2):
        assert abs(shot[k] - plain[80][k]) <= 2e-7 * shot[k]
        assert abs(shot[k] - plain[80][k]) < abs(plain[80][k] - plain[40][k])
        assert (shot[k] - plain[40][k]) * (plain[80][k] - plain[40][k]) > 0.0


def test_certified_search_same_as_fine_search(monkeypatch):
    """On a stiff model the event search samples a coarse grid and refines only where a bound on
    the modal terms cannot exclude an event: the 20-element bar's impacting orbit (fastest
    eigenvalue 65 times the forcing frequency) has the same impacts and end state, to round-off
    (measured: identical), as with the fine grid everywhere (REFINE huge), from 10 times fewer
    samples (223 against 2355; 5 required)."""
    import femodes.time.exact_events as exact_events

    model = _bar(20)
    w1 = float(fm.linear_modes(model, n=1).omega[0])
    b = fm.frequency_response(model, (0.9 * w1, 1.25 * w1), 6)
    i = max(b.folds, key=lambda j: b.omega[j]) - 2
    x, w, theta0, run = Shooter(ladder_for(b, None, None), OPTIONS).solve(i)[:4]
    flow = run.flow
    again = flow.run(x, theta0 / w, variational=True)
    monkeypatch.setattr(exact_events, "REFINE", 10 ** 9)
    fine = flow.run(x, theta0 / w, variational=True)
    assert len(again.impacts) == len(fine.impacts) >= 1
    assert again.samples * 5 < fine.samples
    for a, f in zip(again.impacts, fine.impacts):
        assert abs(a[0] - f[0]) <= 1e-13 * abs(f[0])
    np.testing.assert_allclose(again.x_end, fine.x_end, rtol=0, atol=1e-13 * np.max(np.abs(x)))
    np.testing.assert_allclose(again.Phi, fine.Phi, rtol=0, atol=1e-11 * np.max(np.abs(fine.Phi)))


def test_crossing_cosine_separates_glancing_points():
    """Seed case 1, H = 20: the first point with contact, whose plane the exact curve crosses
    12 % away at kappa 18, is glancing (cosine 0.27 measured, below ``glancing_cos``); a point half
    way to the upper fold crosses nearly at right angles (cosine above 0.9)."""
    b = fm.frequency_response(_forced(), (0.5, 2.0), 20)
    keep = AccuracyOptions(glancing_max=math.inf)  # keep the orbits of glancing points
    lad = ladder_for(b, None, None)
    sh = Shooter(lad, keep)
    solved = shoot_branch(sh, ExactBranchCache(lad), keep)
    first = int(np.flatnonzero(~without_contact(b))[0])
    mid = (first + max(b.folds, key=lambda j: b.omega[j])) // 2
    assert sh.glancing(first, solved[first]) > 3.0
    assert sh.crossing_cosine(first, solved[first]) < OPTIONS.glancing_cos
    assert sh.crossing_cosine(mid, solved[mid]) > 0.9


def test_massless_dof_with_damping_refused():
    model = (fm.StructuralModel(M=[[1.0, 0.0], [0.0, 0.0]], K=[[2.0, -1.0], [-1.0, 1.0]], C=[[0.1, 0.0], [0.0, 0.02]])
             .with_contact(fm.UnilateralContact(at=1, gap=1.0)).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    assert "zero rows of M and C" in exact_flow_unsupported(model)
    with pytest.raises(ValueError, match="damping"):
        LinearImpactFlow(model, 1.0)


def test_chattering_orbit_left_to_the_levels():
    """``auto`` leaves a model whose probe orbit has more events per period at one contact than
    ``shooting_auto_max_events`` to the levels; ``shooting`` asked for explicitly goes on."""
    b = fm.frequency_response(_forced(), (0.95, 1.05), 6)  # in contact: one impact per period
    assert np.abs(b.P).max() > 0.1
    options = AccuracyOptions(shooting_auto_max_events=0)
    assert set(estimate_error(b, options=options).accuracy.method) <= {"doubling", "failed"}
    assert "shooting" in set(estimate_error(b, method=fm.error_methods.Shooting(), options=options).accuracy.method)


def test_shooting_estimate_saved_and_loaded(shot10, tmp_path):
    path = tmp_path / "b.npz"
    shot10.save(path)
    back = fm.load_branch(path)
    assert list(back.accuracy.method) == list(shot10.accuracy.method)
    np.testing.assert_array_equal(back.accuracy.omega_limit, shot10.accuracy.omega_limit)
    np.testing.assert_array_equal(back.accuracy.finest, shot10.accuracy.finest)


def test_defective_state_matrix_falls_back_to_the_levels():
    """Critical damping (c = 2: a double eigenvalue of the state matrix) has no modal flow: "auto"
    estimates by the levels, "shooting" says why."""
    model = _forced(c=2.0, F=2.0)
    b = fm.frequency_response(model, (0.5, 0.7), 4)
    with pytest.raises(ValueError, match="defective"):
        estimate_error(b, method=fm.error_methods.Shooting())
    assert set(estimate_error(b).accuracy.method) <= {"doubling", "failed"}


def test_chunked_impact_search_same_orbit(orbit, monkeypatch):
    """A stiff model's impact search goes chunk by chunk (memory): with chunks of 5 grid points
    the run is the same to round-off."""
    import femodes.time.exact_events as exact_events

    _, flow, _, t0, x, run = orbit
    monkeypatch.setattr(exact_events, "CHUNK", 5)
    again = flow.run(x, t0, variational=True)
    assert len(again.impacts) == len(run.impacts)
    np.testing.assert_allclose(again.x_end, run.x_end, rtol=0, atol=1e-14 * np.max(np.abs(x)))
    np.testing.assert_allclose(again.Phi, run.Phi, rtol=0, atol=1e-12)


def test_auto_leaves_stiff_models_to_the_levels():
    """``auto`` shoots only if a period's impact search is small enough (``shooting_auto_max_work``);
    ``shooting`` asked for explicitly goes on."""
    b = fm.frequency_response(_forced(), (0.95, 1.05), 6)
    options = AccuracyOptions(shooting_auto_max_work=10.0)
    assert set(estimate_error(b, options=options).accuracy.method) <= {"doubling", "failed"}
    assert "shooting" in set(estimate_error(b, method=fm.error_methods.Shooting(), options=options).accuracy.method)


def test_auto_leaves_large_models_to_the_levels():
    """``auto`` shoots only models with at most ``shooting_auto_max_dofs`` DOFs with mass (dense
    modal algebra); ``shooting`` asked for explicitly goes on."""
    b = fm.frequency_response(_forced(), (0.95, 1.05), 6)
    options = AccuracyOptions(shooting_auto_max_dofs=0)
    assert set(estimate_error(b, options=options).accuracy.method) <= {"doubling", "failed"}
    assert "shooting" in set(estimate_error(b, method=fm.error_methods.Shooting(), options=options).accuracy.method)
