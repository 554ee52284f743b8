"""The phase-following predictor of the continuation (ContinuationOptions.predictor, issue 16).

An impact's contact force has harmonics of equal size up to H; when the impact moves in phase
along the branch, harmonic k turns k times faster than the first, and the tangent predictor
(a chord of that rotation) limited the steps. The phase predictor delays the motion by the phase
the tangent asks for (every harmonic turned exactly) and adds the rest of the tangent.
"""

from __future__ import annotations

import numpy as np
import pytest

import femodes as fm
from femodes.analyses import frequency_response_options
from femodes.hbm.problems import ForcedResponseProblem
from femodes.solvers import ContinuationOptions, continuation


def _seed(law="signorini"):
    """Seed forced contact case 1: u'' + 0.1 u' + u = 0.2 cos(w t) - p, stop at u = 1."""
    contact = (fm.UnilateralContact(at=0, gap=1.0) if law == "signorini"
               else fm.PenaltyContact(at=0, gap=1.0, stiffness=100.0))
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(contact)
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


def _counted(monkeypatch):
    calls = [0]
    original = ForcedResponseProblem.residual

    def residual(self, x, p):
        calls[0] += 1
        return original(self, x, p)

    monkeypatch.setattr(ForcedResponseProblem, "residual", residual)
    return calls


def test_time_shift_delays_the_signals():
    """time_shift(Q, tau) holds the coefficients of q(theta - tau) (to round-off of the
    synthesis, |Q| ~ 1, H = 6: 1e-14), its generator is d/dtau at 0 (central difference with
    step 1e-5: truncation ~ H^3 1e-10 ~ 2e-8), and a full turn is the identity."""
    h = fm.Harmonics(6)
    Q = np.random.default_rng(3).standard_normal((h.n_coef, 4))
    theta = np.linspace(0.0, 2 * np.pi, 17)
    for tau in (0.3, -1.1, 2.5):
        assert h.grid.synthesis(theta) @ h.operators.time_shift(Q, tau) == pytest.approx(h.grid.synthesis(theta - tau) @ Q, abs=1e-13)
    e = 1e-5
    fd = (h.operators.time_shift(Q, e) - h.operators.time_shift(Q, -e)) / (2 * e)
    assert h.operators.shift_generator(Q) == pytest.approx(fd, abs=1e-7)
    assert h.operators.time_shift(Q, 2 * np.pi) == pytest.approx(Q, abs=1e-13)
    with pytest.raises(ValueError):
        h.operators.time_shift(Q[:-1], 0.1)


def test_forced_problem_shifts_displacements_and_contact_forces():
    """ForcedResponseProblem.phase_shift delays Q and P alike (unknowns by name)."""
    pr = ForcedResponseProblem(_seed(), fm.Harmonics(5))
    x = np.random.default_rng(0).standard_normal(pr.size)
    u = pr.unpack(x, 1.0)
    v = pr.unpack(pr.phase_shift(x, 0.7), 1.0)
    h = pr.system.h
    assert v.Q == pytest.approx(h.operators.time_shift(u.Q, 0.7), abs=1e-15)
    assert v.P == pytest.approx(h.operators.time_shift(u.P, 0.7), abs=1e-15)
    assert pr.unpack(pr.phase_generator(x), 1.0).P == pytest.approx(h.operators.shift_generator(u.P), abs=1e-15)


def test_phase_predictor_takes_fewer_points_for_the_same_curve(monkeypatch):
    """Seed case 1 at H = 20 (complementarity law): the same folds (both located by the same
    regula falsi to |dp/ds| <= 1e-9: agree to 1e-7 relative), and fewer points and residual
    evaluations. Measured: 179 -> 91 points, 795 -> 436 evaluations; asserted: at most 0.8x."""
    calls = _counted(monkeypatch)
    model = _seed()
    out = {}
    for predictor in (fm.predictors.Tangent(), fm.predictors.Phase()):
        calls[0] = 0
        b = fm.frequency_response(model, (0.5, 2.0), 20, options=frequency_response_options(predictor=predictor))
        assert b.success and len(b.folds) == 2
        out[predictor.name] = (len(b), calls[0], np.sort(b.omega[list(b.folds)]))
    (n_t, e_t, f_t), (n_p, e_p, f_p) = out["tangent"], out["phase"]
    assert f_p == pytest.approx(f_t, rel=1e-7)
    assert f_p[1] == pytest.approx(1.38498, abs=1e-5)  # README_steps / bench_peers: upper fold at H = 20
    assert n_p <= 0.8 * n_t and e_p <= 0.8 * e_t


def test_a_fold_is_located_or_approached_with_shorter_steps():
    """A fold counts as located only where |dp/ds| is small; otherwise the step is halved.
    Seed case 1, penalty law, H = 40: a step of 0.83 across the lower fold (at grazing) once
    located it at w = 1.0854 (0.4 % off) from a single trial point whose |dp/ds| was 0.027.
    Now both predictors find the lower fold at the grazing amplitude, w = 1.0808685, within 1e-6,
    also with target_norm_change=0.3 (with the tangent predictor the fold is then a corner met at
    a short step: located after the halvings down to 1/64 of the initial step, marked 2e-4 off
    with 1/4)."""
    tangent, phase = fm.predictors.Tangent(), fm.predictors.Phase()
    for predictor, norm in ((tangent, None), (phase, None), (tangent, 0.3), (phase, 0.3)):
        b = fm.frequency_response(_seed("penalty"), (0.5, 2.0), 40,
                                  options=frequency_response_options(predictor=predictor, target_norm_change=norm))
        folds = np.sort(b.omega[list(b.folds)])
        assert b.success and folds == pytest.approx([1.0808685, 1.348299], rel=1e-6)


class _Circle:
    """r(x, p) = |x|^2 + p^2 - 1 along with x_2 = 0: a problem with no phase methods."""

    def residual(self, x, p):
        r = np.array([x[0] ** 2 + p ** 2 - 1.0, x[1]])
        J = np.array([[2 * x[0], 0.0], [0.0, 1.0]])
        return r, J, np.array([2 * p, 0.0])


def test_problems_without_phase_methods_get_the_tangent_predictor():
    """predictor="phase" needs phase_shift and phase_generator; without them the run is the
    tangent predictor's, bit for bit."""
    runs = [continuation(_Circle(), (-0.5, 0.5), x0=np.array([0.9, 0.0]), options=ContinuationOptions(predictor=p))
            for p in (fm.predictors.Phase(), fm.predictors.Tangent())]
    assert runs[0].success and runs[0].x.shape == runs[1].x.shape
    assert np.array_equal(runs[0].x, runs[1].x) and np.array_equal(runs[0].p, runs[1].p)


def test_bad_predictor_is_named():
    with pytest.raises(ValueError, match=r"ContinuationOptions: predictor must be a predictor: "
                                         r"femodes\.predictors\.Phase\(\) or Tangent\(\), got 'secant'"):
        ContinuationOptions(predictor="secant")
    with pytest.raises(ValueError, match=r"femodes\.predictors\.Tangent\(\) \(with the parentheses\)"):
        ContinuationOptions(predictor=fm.predictors.Tangent)


def test_predictor_names_are_deprecated_spellings_of_the_strategies():
    """``predictor="tangent"`` still works for a release: the same strategy, with a warning that
    names the object to pass and points at the caller's line."""
    with pytest.warns(DeprecationWarning, match=r"predictor='tangent' is deprecated; pass "
                                                r"predictor=femodes\.predictors\.Tangent\(\)") as rec:
        opts = ContinuationOptions(predictor="tangent")
    assert rec[0].filename == __file__
    assert opts.predictor == fm.predictors.Tangent() and ContinuationOptions().predictor == fm.predictors.Phase()


class _Secant:
    """A predictor of the user's own: the secant through the last two points (the tangent at the first)."""

    name = "secant"

    def bind(self, system):
        return _SecantStep()


class _SecantStep:
    tau = None

    def __init__(self):
        self.last = None
        self.calls = 0

    def predict(self, a, ds):
        self.calls += 1
        d = a.t if self.last is None else (a.y - self.last)
        self.last = a.y.copy()
        return a.y + ds * d / np.linalg.norm(d)

    def reference_tangent(self, a):
        return a.t


def test_a_predictor_of_the_users_own_is_used():
    """Any object with ``name`` and ``bind(system)`` is a predictor: it predicts every step and the
    run still ends on the circle (the corrector does the rest)."""
    pred = _Secant()
    steps = []
    orig = pred.bind
    pred.bind = lambda system: steps.append(orig(system)) or steps[-1]
    run = continuation(_Circle(), (-0.5, 0.5), x0=np.array([0.9, 0.0]), options=ContinuationOptions(predictor=pred))
    assert run.success and steps and steps[0].calls >= len(run.p) - 1
    np.testing.assert_allclose(run.x[:, 0] ** 2 + run.p ** 2, 1.0, atol=1e-8)


def test_level_start_between_two_points_follows_the_phase():
    """accuracy.level_trace.between: between a motion and the same motion delayed by tau, the point at a
    fraction theta is the motion delayed by theta tau, to round-off (the chord would shrink the
    high harmonics: at H = 20 harmonic 20 turned by 20 tau = 8 rad)."""
    from femodes.accuracy.level_trace import between

    pr = ForcedResponseProblem(_seed(), fm.Harmonics(20))
    x0 = np.random.default_rng(5).standard_normal(pr.size)
    tau, theta = 0.4, 0.3
    y0, y1 = np.append(x0, 1.0), np.append(pr.phase_shift(x0, tau), 1.2)
    got = between(pr, y0, y1, theta)
    assert got[:-1] == pytest.approx(pr.phase_shift(x0, theta * tau), abs=1e-12)
    assert got[-1] == pytest.approx(1.06, rel=1e-15)
    chord = y0 + theta * (y1 - y0)
    assert np.max(np.abs(chord[:-1] - got[:-1])) > 0.5  # what the chord start was off by
