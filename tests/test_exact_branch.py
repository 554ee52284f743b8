"""The exact forced response by continuation of exact orbits (femodes.exact_frequency_response).

References: the semi-analytic upper folds of tests/impact_reference.py (seed cases), the folds
that the shooting refinement of femodes.accuracy locates on the 2-DOF massless-contact model
(themselves checked against plain harmonic balance at H = 80 in test_exact_flow.py), and, in the
slow test, a quasi-static sweep in the time domain (the stable orbits, period after period).
"""

import dataclasses
import math

import numpy as np
import pytest

import femodes as fm
from femodes.accuracy import AccuracyOptions, estimate_error
from femodes.solvers import ContinuationOptions
from femodes import ExactBranch, exact_frequency_response
from femodes.time.exact import LinearImpactFlow

from .impact_reference import upper_fold
from .test_examples import BENCHMARKS, load


def _oscillator(c, F, g):
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[c]]).with_contact(fm.UnilateralContact(at=0, gap=g))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=F)))


def _grazing(c, F, g):
    """The frequency above resonance where the linear response's amplitude
    ``F / sqrt((1 - w^2)^2 + (c w)^2)`` equals the gap: the exact lower fold of the forced
    impact oscillator (the impacting branch meets the linear one there)."""
    b = 2.0 - c * c
    return math.sqrt(0.5 * (b + math.sqrt(b * b - 4.0 * (1.0 - (F / g) ** 2))))


def _massless_two_dof():
    return (fm.StructuralModel(M=[[1.0, 0.0], [0.0, 0.0]], K=[[2.0, -1.0], [-1.0, 1.0]], C=[[0.1, 0.0], [0.0, 0.0]])
            .with_contact(fm.UnilateralContact(at=1, gap=1.0)).with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


def _residual(b: ExactBranch, i: int) -> float:
    """|x(T) - x(0)| of point i's inertial state."""
    S = b.flow.state_index
    return float(np.linalg.norm((b.orbit(i).x_end - b.states[i])[S]))


@pytest.fixture(scope="module")
def seed2():
    return exact_frequency_response(_oscillator(0.2, 1.0, 2.5), (0.5, 2.0))


def test_seed2_upper_fold_exact(seed2):
    """Seed case 2: one piece over the span; the upper fold equals the event-driven reference to
    1e-9 (measured 2.5e-13: the fold is located by the continuation on exact orbits); every
    point is periodic to about the Newton tolerance (``b.atol``: EXACT_BRANCH_RTOL = 1e-6 of the
    larger of the gap and the state without contact at the first frequency)."""
    b = seed2
    assert b.success and b.pieces == (0,)
    assert b.omega[0] == 0.5 and b.omega[-1] == pytest.approx(2.0, abs=1e-12)
    ref = upper_fold(0.2, 1.0, 2.5).w
    w = max(b.omega[list(b.folds)])
    assert abs(w / ref - 1.0) < 1e-9
    assert b.atol == pytest.approx(1e-6 * 2.5)  # the gap, above |[q; v]| = 1.49 without contact at w = 0.5
    # Newton also stops on a step below its xtol: residuals up to 1.1 atol measured
    assert max(_residual(b, i) for i in range(len(b))) <= 10 * b.atol
    top = []
    for i in range(0, len(b), 3):
        t = np.linspace(0.0, 2.0 * math.pi / b.omega[i], 2001)
        top.append(b.orbit(i).displacement(t)[:, 0].max())
    assert max(top) <= 2.5 * (1.0 + 1e-12)  # the orbits with impacts reach the stop, no further
    assert max(top) > 2.5 * (1.0 - 1e-3)
    assert b.amplitude(0).max() > 2.5  # max |q|: the far side of the swing, where there is no stop


def test_kept_orbits_are_the_points_runs(seed2):
    """orbit(i) returns the continuation's own run of point i (kept without its variational
    part): the same end state and events as a run from the stored state, to round-off of the
    state's size (the same arithmetic: measured 0)."""
    b = seed2
    assert all(o is not None and o.Phi is None and not o.sensitivities for o in b._orbits)
    for i in range(0, len(b), 7):
        fresh = b.flow.at(b.omega[i]).run(b.states[i], 0.0)
        kept = b.orbit(i)
        assert kept is b._orbits[i]
        assert len(kept.impacts) == len(fresh.impacts)
        assert np.max(np.abs(kept.x_end - fresh.x_end)) <= 1e3 * np.finfo(float).eps * np.max(np.abs(fresh.x_end))


def test_seed2_detected_lower_fold_refined_to_the_grazing(seed2):
    """The lower fold is a grazing: the corrector fails at the turn, so the continuation only
    detects it (1.1519541 before the refinement: 4.3e-6 off). The short-step continuations from
    both sides (_refine_fold) reach the closed-form grazing frequency within the stated error
    (EXACT_FOLD_RTOL = 1e-6; measured 9.3e-8)."""
    b = seed2
    k = int(np.argmin(b.fold_omega))
    wg = _grazing(0.2, 1.0, 2.5)
    assert not b.fold_upper[k]
    assert abs(b.fold_omega[k] / wg - 1.0) <= b.fold_error[k] == 1e-6


def test_seed1_grazing_traced_from_both_ends():
    """Seed case 1: the impacting branch ends at the grazing of the linear response (the flow's
    derivative is singular there), so the continuation stops there and the rest is traced back
    from the other end: two pieces that cover the span. Upper fold within 1e-6 of the reference
    (measured 3.2e-8); the pieces meet within 1 % of the grazing frequency 1.0808687 (the
    linear response's amplitude reaches the gap there)."""
    b = exact_frequency_response(_oscillator(0.1, 0.2, 1.0), (0.5, 2.0))
    assert b.success and len(b.pieces) == 2
    k = b.pieces[1]
    assert abs(b.omega[k - 1] - 1.0808687) < 1e-2
    # the back piece (reversed: in order along the branch) ends where the first one stopped
    assert b.omega[k] == pytest.approx(b.omega[k - 1], abs=1e-12) and b.omega[-1] == pytest.approx(2.0, abs=1e-12)
    ref = upper_fold(0.1, 0.2, 1.0).w
    assert abs(max(b.omega[list(b.folds)]) / ref - 1.0) < 1e-6
    assert not any(b.orbit(i).impacts for i in range(k, len(b)))  # the back piece: the linear response


def test_massless_contact_folds_match_the_shooting_refinement():
    """2-DOF model with its contact on the massless DOF: the exact branch's two folds equal those
    the shooting refinement of estimate_error locates from H = 10 (to 1e-7; measured below 1e-9)."""
    model = _massless_two_dof()
    b = exact_frequency_response(model, (0.9, 1.3))
    assert b.success and len(b.folds) == 2
    est = estimate_error(fm.frequency_response(model, (0.9, 1.3), 10))
    shot = np.sort(est.accuracy.omega_limit[list(est.folds)])
    np.testing.assert_allclose(np.sort(b.omega[list(b.folds)]), shot, rtol=1e-7)
    switches = [len(b.orbit(i).switches) for i in b.folds]
    assert all(s >= 2 for s in switches)  # the folds' orbits close and open the contact


def test_coefficients_are_those_of_the_orbit(seed2):
    """ExactBranch.coefficients: the exact Fourier series of an impacting orbit (the upper fold's)
    reproduces its displacement (H = 200: the tail decays like 1/k^2; atol 1e-3 of the gap)."""
    b = seed2
    i = max(b.folds, key=lambda j: b.omega[j])
    assert len(b.orbit(i).impacts) == 1
    Q, P = b.coefficients(i, 200)
    t = np.linspace(0.0, 2.0 * math.pi / b.omega[i], 64, endpoint=False)
    th = np.outer(b.omega[i] * t, np.arange(1, 201))
    series = Q[0, 0] + np.cos(th) @ Q[1::2, 0] + np.sin(th) @ Q[2::2, 0]
    np.testing.assert_allclose(series, b.orbit(i).displacement(t)[:, 0], atol=1e-3 * 2.5)
    assert P[0, 0] > 0.0  # a compressive mean contact force (the impulse per period)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(omega=(1.0, 1.0)), ValueError, "omega"),
    (dict(omega=(-1.0, 2.0)), ValueError, "omega"),
    (dict(omega=1.0), ValueError, "omega"),
    (dict(omega=(0.5, 2.0), x0=[0.0]), ValueError, "x0"),
    (dict(omega=(0.5, 2.0), options=3), TypeError, "options"),
    (dict(), TypeError, "omega"),
    (dict(omega=(0.5, 2.0), span=(0.5, 2.0)), TypeError, "not both"),
])
def test_bad_input(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        exact_frequency_response(_oscillator(0.2, 1.0, 2.5), **kwargs)
    with pytest.raises(TypeError, match="model must be a StructuralModel"):
        exact_frequency_response([[1.0]], (0.5, 2.0))


def test_span_keyword_is_deprecated_for_omega():
    """``span=`` was the name of the frequencies; ``omega=`` is, as in frequency_response. The old
    keyword still runs the same branch, with a DeprecationWarning naming the new one."""
    with pytest.warns(DeprecationWarning, match=r"omega="):
        old = exact_frequency_response(_oscillator(0.2, 1.0, 2.5), span=(0.5, 0.6))
    new = exact_frequency_response(_oscillator(0.2, 1.0, 2.5), omega=(0.5, 0.6))
    assert old.success and new.success
    np.testing.assert_array_equal(old.omega, new.omega)


def test_models_the_flow_cannot_take():
    unforced = fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    with pytest.raises(ValueError, match="no harmonic forcing"):
        exact_frequency_response(unforced, (0.5, 2.0))
    duffing = _oscillator(0.1, 0.2, 1.0).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
    with pytest.raises(ValueError, match="LinearImpactFlow"):
        exact_frequency_response(duffing, (0.5, 2.0))


def test_iterates_inside_the_obstacle_cut_the_step(monkeypatch):
    """A Newton iterate whose start state is inside the obstacle (the flow refuses it) is a
    non-finite residual that cuts the step, not an error: seed case 2 with target_angle = 20
    raised "the start state penetrates an obstacle" before; the branch now covers the span and
    its upper fold is within 1e-6 of the reference (measured 1.0e-7)."""
    import dataclasses

    refused = []
    real = LinearImpactFlow.run

    def run(self, *args, **kw):
        try:
            return real(self, *args, **kw)
        except ValueError as exc:
            refused.append(str(exc))
            raise

    opts = ContinuationOptions(max_points=3000, target_angle=20.0,
                               newton=dataclasses.replace(ContinuationOptions().newton, atol=2.5e-6))
    monkeypatch.setattr(LinearImpactFlow, "run", run)
    b = exact_frequency_response(_oscillator(0.2, 1.0, 2.5), (0.5, 2.0), options=opts)
    assert any("penetrates" in m for m in refused)
    assert b.success
    assert abs(max(b.fold_omega) / upper_fold(0.2, 1.0, 2.5).w - 1.0) < 1e-6


def test_start_inside_the_obstacle_reported_not_raised():
    """x0 inside the obstacle: no point, success False and the continuation's message."""
    b = exact_frequency_response(_oscillator(0.2, 1.0, 2.5), (0.5, 2.0), x0=[10.0, 0.0])
    assert len(b) == 0 and not b.success and "initial correction" in b.message
    assert b.states.shape == (0, 2) and b.fold_omega.size == 0


def test_options_passed_through():
    """max_points and the user's callback reach the continuation (the callback sees every point;
    the branch's own bookkeeping of the points' runs goes on behind it)."""
    seen = []
    b = exact_frequency_response(_oscillator(0.2, 1.0, 2.5), (0.5, 2.0),
                                 options=ContinuationOptions(max_points=10, callback=lambda pt: seen.append(pt.p)))
    assert len(b) == 10 and not b.success and "max_points" in b.message
    assert np.array_equal(seen, b.omega) and all(o is not None for o in b._orbits)


#: The fold search of the shooting refinement left out: the folds go to the exact branch's, as the
#: folds the fold search does not locate do (the cantilever below).
NO_FOLD_SEARCH = AccuracyOptions(shooting_fold_search=False)


def test_missed_folds_taken_from_the_exact_branch():
    """Seed case 2 at H = 10 with the fold search disabled: both folds are paired with the exact
    branch's (same turn, nearest), so the upper fold's limit is the reference to 1e-6 (the
    stated half-width EXACT_FOLD_RTOL; measured 2.5e-13) and the error estimate covers the
    H = 10 fold's true error (4.6 %) without overstating it by more than 2e-6."""
    model = _oscillator(0.2, 1.0, 2.5)
    b = fm.frequency_response(model, (0.5, 2.0), 10)
    assert len(b.folds) == 2
    acc = estimate_error(b, options=NO_FOLD_SEARCH).accuracy
    ref = upper_fold(0.2, 1.0, 2.5).w
    up = max(b.folds, key=lambda i: b.omega_truncated[i])
    assert acc.method[up] == "shooting" and acc.finest[up] == 0
    assert abs(acc.omega_limit[up] / ref - 1.0) <= acc.omega_limit_error[up] == 1e-6
    true = abs(b.omega_truncated[up] - ref) / b.omega_truncated[up]  # relative to the point's frequency, as the estimate
    assert true <= acc.omega[up] <= true + 2e-6
    low = min(b.folds, key=lambda i: b.omega_truncated[i])
    assert acc.method[low] == "shooting"
    assert abs(acc.omega_limit[low] / _grazing(0.2, 1.0, 2.5) - 1.0) <= acc.omega_limit_error[low] == 1e-6


def test_fold_without_exact_counterpart_gets_no_estimate(monkeypatch):
    """A fold of the truncation that the exact branch does not have (here: the exact branch
    stripped of its lower fold) is left without an estimate and marked "truncation" (never met),
    not sent to the levels; the other is paired."""
    import femodes.accuracy.exact_branch as exact_branch

    real = exact_branch.exact_frequency_response

    def upper_only(model, span, **kw):
        eb = real(model, span, **kw)
        keep = np.flatnonzero(eb.fold_upper)
        eb.folds = tuple(eb.folds[k] for k in keep)
        eb.fold_omega, eb.fold_error, eb.fold_upper = eb.fold_omega[keep], eb.fold_error[keep], eb.fold_upper[keep]
        return eb

    monkeypatch.setattr(exact_branch, "exact_frequency_response", upper_only)
    b = fm.frequency_response(_oscillator(0.2, 1.0, 2.5), (0.5, 2.0), 10)
    acc = estimate_error(b, options=NO_FOLD_SEARCH).accuracy
    up, low = max(b.folds, key=lambda i: b.omega[i]), min(b.folds, key=lambda i: b.omega[i])
    assert acc.method[up] == "shooting"
    assert acc.method[low] == "truncation" and not math.isfinite(acc.omega[low]) and acc.finest[low] == 0
    acc_r = dataclasses.replace(acc, rtol=1e-3)  # the same estimate, asked for rtol 1e-3
    assert not acc_r.met[low] and acc_r.met[up]


def test_points_without_an_orbit_start_from_the_exact_branch(monkeypatch):
    """Points where Newton from the branch found no orbit are solved again from the exact branch's
    crossing of their hyperplanes: with three points of seed case 2 (H = 10) made to fail, the
    same exact orbits come out (omega_limit to 1e-9 relative: the same Newton solve on the same
    hyperplane, from another start)."""
    model = _oscillator(0.2, 1.0, 2.5)
    b = fm.frequency_response(model, (0.5, 2.0), 10)
    plain = estimate_error(b).accuracy
    P = np.abs(b.P).reshape(len(b), -1).max(axis=1)
    lose = [i for i in np.flatnonzero(P > 0.1 * P.max()) if i not in b.folds and plain.method[i] == "shooting"][::5][:3]
    assert len(lose) == 3
    import femodes.accuracy.shooting as shooting

    real = shooting.shoot_branch

    def losing(sh, exact, options):
        out = real(sh, exact, options)
        for i in lose:
            out[i] = None
        return out

    monkeypatch.setattr(shooting, "shoot_branch", losing)
    again = estimate_error(b).accuracy
    for i in lose:
        assert again.method[i] == "shooting"
        assert abs(again.omega_limit[i] / plain.omega_limit[i] - 1.0) < 1e-9


@pytest.mark.slow
def test_cantilever_rtol_folds_from_the_exact_branch():
    """The cantilever with 3 % modal damping at H = 20: Newton from the points on the rising side
    finds no orbit, so the exact branch is traced and its folds are paired with the branch's:
    the main (largest-amplitude) fold, 3.843 at H = 20, gets the exact upper fold 3.91530 (the
    time-domain sweep's jump, slow test below), the lower fold 3.7193120 +- 1e-6 (a sharp fold,
    located by the continuation after one halving of its step; separate short-step
    continuations give 3.719311942, the fold search 3.7193120 +- 2.3e-7), and the loop of two
    folds at 3.822 and 3.902, which H = 40 and 80 do not have, no estimate (method
    "truncation")."""
    mesh = fm.line_mesh(length=1.0, n_elements=10, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = (beam.with_contact(fm.UnilateralContact(at="tip", gap=0.01)).with_damping(modal=0.03)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)))
    b = estimate_error(fm.frequency_response(model, (3.0, 4.2), 20))
    acc = b.accuracy
    amp = b.amplitude(model.dof("tip"), b.Q)  # the H = 20 series' (and its frequencies below)
    main = max(b.folds, key=lambda i: amp[i])
    assert abs(b.omega_truncated[main] - 3.8431) < 1e-3
    assert 3.915 < acc.omega_limit[main] < 3.916 and acc.omega_limit_error[main] <= 1e-6
    assert b.omega[main] == acc.omega_limit[main]  # what the branch shows: the answer
    low = min(b.folds, key=lambda i: b.omega_truncated[i])
    assert abs(acc.omega_limit[low] - 3.719311942) <= acc.omega_limit_error[low] * acc.omega_limit[low]
    assert acc.omega_limit_error[low] <= 1e-6
    loop = [i for i in b.folds if i not in (main, low)]
    assert len(loop) == 2 and all(acc.method[i] == "truncation" for i in loop)


@pytest.mark.slow
def test_cantilever_fold_is_where_the_time_domain_sweep_jumps():
    """The 10-element cantilever with a massless tip stop and 3 % modal damping
    (benchmarks/bench_cantilever_time.py): the exact branch's upper fold (3.91530, 7 s) lies
    where an upward quasi-static sweep of the exact flow in the time domain leaves the upper
    branch: still on it (tip amplitude above 0.0124) at w = 3.914 and 3.915, on the lower one
    (below 0.006) at 3.917. Harmonic balance places that fold at 3.843 (H = 20), 3.935 (H = 40)
    and 3.909 (H = 80)."""
    mesh = fm.line_mesh(length=1.0, n_elements=10, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = (beam.with_contact(fm.UnilateralContact(at="tip", gap=0.01)).with_damping(modal=0.03)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)))
    tip = model.dof("tip")
    b = exact_frequency_response(model, (3.0, 4.2))
    assert b.success
    w_fold = max(b.omega[list(b.folds)])
    assert 3.915 < w_fold < 3.917
    flow = LinearImpactFlow(model, 3.5)
    x = np.zeros(2 * model.n_dofs)
    amp = {}
    for k, w in enumerate(list(np.arange(3.5, 3.905, 0.01)) + [3.91, 3.914, 3.915, 3.917]):
        f = flow.at(float(w))
        for _ in range(300 if k == 0 or w > 3.9 else 100):
            run = f.run(x, 0.0)
            x = run.x_end
        amp[round(float(w), 3)] = float(np.max(np.abs(run.displacement(
            np.linspace(0.0, 2.0 * math.pi / w, 400))[:, tip])))
    assert amp[3.914] > 0.0124 and amp[3.915] > 0.0124
    assert amp[3.917] < 0.006


@pytest.fixture(scope="module")
def seed1():
    return exact_frequency_response(_oscillator(0.1, 0.2, 1.0), (0.5, 2.0))


@pytest.mark.parametrize("case, count, low", [("seed1", 4, 5e-4), ("seed2", 6, 1e-3)])
def test_points_just_above_grazing_get_the_exact_orbit_at_their_frequency(case, count, low, request):
    """The seed cases at H = 20: just above the rising side's grazing the exact curve crosses the
    points' hyperplanes obliquely (4 and 8 points that had no estimate); each now gets the exact
    orbit at its own frequency: omega_limit is its frequency and the amplitude error is the
    distance of its coefficients to that orbit's (8 H harmonics). Seed case 1's point at
    w = 0.906552, 6.3e-5 above the grazing, where Newton from the point stalls, from the linear
    orbit at its frequency. Checked against the orbit at that frequency found independently
    (Newton on x(T) = x at phase 0 from the exact branch's nearest state): the same error to 1e-6
    (both Newton solves converge to 1e-11; measured 5.7e-4 to 2.0e-2)."""
    eb = request.getfixturevalue(case)
    model = _oscillator(*{"seed1": (0.1, 0.2, 1.0), "seed2": (0.2, 1.0, 2.5)}[case])
    b = fm.frequency_response(model, (0.5, 2.0), 20)
    acc = estimate_error(b).accuracy
    assert not np.any(acc.method == "failed")
    at_w = [i for i in range(len(b)) if acc.omega_limit[i] == b.omega_truncated[i] and acc.amplitude[i] > 1e-6]
    assert len(at_w) >= count
    hk = fm.Harmonics(160)
    for i in at_w:
        w = float(b.omega_truncated[i])
        flow = eb.flow.at(w)
        x = eb.states[int(np.argmin(np.abs(eb.omega - w)))].copy()
        run = flow.run(x, 0.0, variational=True)
        F = run.x_end - x
        for _ in range(50):  # Newton, steps halved until |F| decreases (the flow is only piecewise smooth)
            if np.max(np.abs(F)) < 1e-12:
                break
            d = -np.linalg.solve(run.Phi - np.eye(2), F)
            for a in 0.5 ** np.arange(20):
                if flow.admissible(x + a * d):
                    r1 = flow.run(x + a * d, 0.0, variational=True)
                    if np.linalg.norm(r1.x_end - x - a * d) < np.linalg.norm(F):
                        break
            else:
                raise AssertionError(f"no step of Newton at w = {w} reduces |x(T) - x|")
            x = x + a * d
            run, F = r1, r1.x_end - x
        assert np.max(np.abs(F)) < 1e-12 and run.impacts
        dQ = fm.Harmonics(20).layout.convert(b.Q[i], hk) - run.coefficients(160)[0]
        ref = np.linalg.norm(dQ) / np.linalg.norm(b.Q[i])
        assert abs(acc.amplitude[i] - ref) <= 1e-6 and low <= ref <= 0.05


@pytest.mark.parametrize("old", ["femodes.time", "femodes.time.exact"])
def test_old_import_paths_warn_and_give_the_moved_names(old):
    """The exact branch moved from the time integration to the analyses (exact_frequency_response)
    and results (ExactBranch) layers: the old paths give the same objects, with a
    DeprecationWarning naming the new import."""
    import importlib

    import femodes.exact_branch as exact_branch
    import femodes.exact_response as exact_response

    module = importlib.import_module(old)
    for name, new in (("exact_frequency_response", exact_response), ("ExactBranch", exact_branch)):
        with pytest.warns(DeprecationWarning, match=rf"{old}\.{name} moved to femodes\.{name}"):
            assert getattr(module, name) is getattr(new, name)
    if old == "femodes.time.exact":
        for name, new in (("EXACT_BRANCH_RTOL", exact_response), ("EXACT_FOLD_RTOL", exact_branch),
                          ("FOLD_WINDOW", exact_branch), ("fold_is_upper", exact_branch)):
            with pytest.warns(DeprecationWarning, match=rf"moved to {new.__name__}\.{name}"):
                assert getattr(module, name) is getattr(new, name)
    with pytest.warns(DeprecationWarning):
        exec(f"from {old} import exact_frequency_response as f", {})
    with pytest.raises(AttributeError):
        getattr(module, "no_such_name")


@pytest.mark.parametrize("amplitude, clear", [(0.5, True), (0.95, False), (1.2, False)])
def test_an_orbit_clear_of_the_stop_is_no_counterpart(amplitude, clear):
    """The exact orbit found for a point with contact force counts as its counterpart only if it
    touches the stop or comes within ``shooting_clearance`` (10 %) of the gap, as just above
    grazing: the forced linear orbit of the seed oscillator (c = 0.2, F = 1, g = 2.5) at the
    frequency where its amplitude is ``amplitude`` times the gap stays 50 % clear (not a
    counterpart), 5 % clear (one), or runs into the stop (touches: one)."""
    from types import SimpleNamespace

    from femodes.accuracy.shooting import stays_clear
    c, F, g = 0.2, 1.0, 2.5
    # amplitude a g below resonance: (1 - w^2)^2 + (c w)^2 = (F / (a g))^2, the root with w < 1
    b, q = 2.0 - c * c, 1.0 - (F / (amplitude * g)) ** 2
    w = math.sqrt(0.5 * (b - math.sqrt(b * b - 4.0 * q)))
    flow = LinearImpactFlow(_oscillator(c, F, g), w)
    t = np.linspace(0.0, 2 * math.pi / w, 65)
    t0 = float(t[np.argmin(flow.particular(t)[:, 0])])  # start where the orbit is farthest from the stop
    run = flow.run(flow.particular(t0), t0)
    assert run.touches == (amplitude > 1.0)
    sh = SimpleNamespace(flow=flow)
    assert stays_clear(sh, 0, (run.x_end, w, 0.0, run, 0.0, None), AccuracyOptions()) is clear
    assert stays_clear(sh, 0, (run.x_end, w, 0.0, run, 0.0, None), AccuracyOptions(shooting_clearance=0.6)) is False


@pytest.mark.slow
def test_arch_contact_points_get_no_orbit_without_contact_as_exact_answer():
    """A shallow pinned arch (benchmarks/bench_arch.py: Craig-Bampton, 11 DOFs, a stop 1 mm under
    the crown, 1 % modal damping, 2 kN, H = 7): shooting found no exact orbit with contact near
    its contact points, but orbits without contact on their hyperplanes, up to 2.7 w2 away, and
    reported them as the points' exact answers (frequency error 1e-9, rtol met, the peak at
    1.228 w2 with a crown amplitude of 0.12 mm). Those orbits stay 13-100 % of the gap clear of the
    stop. Now no point with contact force takes such an orbit: every exact answer of a point with
    contact reaches within 10 % of the gap, and rtol is not met at the peak (the levels: 13-42 %,
    no convergence), where the time integration of the reduced and of the 802-DOF model falls off
    the branch within 5 periods."""
    bench = load("bench_arch", BENCHMARKS)
    forced = bench.forced_rom(bench.arch())
    w2 = fm.linear_modes(forced, 2).omega[1]
    frc = fm.frequency_response(forced, (0.9 * w2, 1.3 * w2), 7, rtol=1e-2)
    acc, d = frc.accuracy, forced.contacts[0].dof
    P = np.abs(frc.P).reshape(len(frc), -1).max(axis=1)
    exact = (acc.method == "shooting") & (P > 1e-12 * P.max())
    assert exact.any() and np.all(acc.amplitude_limit[exact, d] >= 0.9 * 1e-3)
    peak = int(np.argmax(frc.energy))
    assert frc.omega_truncated[peak] / w2 == pytest.approx(1.20, abs=0.01)
    assert not acc.met[peak] and acc.method[peak] != "shooting" and frc.omega[peak] / w2 < 1.21
    # the backbone rides mode 5's tongue 16 % below that peak: compare_resonance says the peak is not converged
    rom = fm.craig_bampton(bench.arch(), 10)
    eg = fm.grazing_energy(rom, 2)
    riding = fm.nonlinear_mode(rom, 2, energy=(0.5 * eg, 10.0 * eg), harmonics=7)
    res, = fm.compare_resonance(riding, frc)
    assert res.converged is False and res.backbone_held_by == 5 and "not converged" in res.predicted
