"""Step control of the continuation (issue 16 item 1): the points a curve needs.

Bounds are measured counts (deterministic on one machine, benchmarks/README_steps.md) times 1.3,
a margin for round-off differences between machines that can move a step past a kink or a
rejection; fold frequencies are located by a root finder and compared with the code before the
change (commit 816b139) to 1e-6 relative.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import femodes as fm
from femodes.analyses import frequency_response_options

#: Upper fold of seed case 1 at H = 20 by the step control before issue 16 (commit 816b139,
#: 305 points): the fold is located by regula falsi on dp/ds, so it does not depend on the steps.
FOLD_H20 = 1.3849781277943227
#: Same at H = 40 (687 points before).
FOLD_H40 = 1.400964504


def seed_case1(law: str = "signorini") -> fm.StructuralModel:
    """u'' + 0.1 u' + u = 0.2 cos(w t) - p, rigid stop at u = 1 (or penalty k = 100)."""
    contact = (fm.UnilateralContact(at=0, gap=1.0) if law == "signorini"
               else fm.PenaltyContact(at=0, gap=1.0, stiffness=100.0))
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(contact)
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


def duffing() -> fm.StructuralModel:
    """u'' + 0.02 u' + u + 0.5 u^3 = 0.1 cos(w t): a smooth branch with two folds."""
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.02]]).with_nonlinearity(fm.CubicSpring(at=0, k3=0.5))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.1)))


@functools.cache
def seed_branch(H: int, law: str = "signorini"):
    return fm.frequency_response(seed_case1(law), (0.5, 2.0), fm.Harmonics(H))


def upper_fold(branch) -> float:
    return max(float(branch.omega[i]) for i in branch.folds)


@pytest.mark.parametrize("H, bound, fold", [(20, 118, FOLD_H20), (40, 208, FOLD_H40)])
def test_seed_case1_points_and_fold(H, bound, fold):
    """Measured 91 points at H = 20 (179 with the tangent predictor, 305 before the step control)
    and 160 at H = 40 (292, 687); x 1.3 margin.
    Both folds are located, the upper one equal to the reference."""
    br = seed_branch(H)
    assert br.success and br.omega[-1] == 2.0, br.message
    assert len(br) <= bound, len(br)
    assert len(br.folds) == 2
    assert upper_fold(br) == pytest.approx(fold, rel=1e-6)


def test_seed_case1_penalty_points():
    """Penalty k = 100 at H = 20: 66 points measured with the tangent predictor (63 before the step
    control, but 287 Newton iterations instead of 346), 54 with the phase predictor; bound 66 x 1.3;
    same upper fold as the old code (1.34830083)."""
    br = seed_branch(20, "penalty")
    assert br.success and len(br) <= 86, len(br)
    assert upper_fold(br) == pytest.approx(1.3483008315, rel=1e-6)


def test_duffing_not_more_points_than_before():
    """Smooth branch: 47 points at H = 3 and 9 with the tangent predictor (142 before with the
    iteration-count control), 32 with the phase predictor; the bound 61 is 47 x 1.3, well below
    the old count; folds equal to the old ones."""
    for H, folds in ((3, (1.904064889, 1.136924557)), (9, (1.904069256, 1.136924564))):
        br = fm.frequency_response(duffing(), (0.5, 2.5), fm.Harmonics(H))
        assert br.success and len(br) <= 61, (H, len(br))
        assert sorted((float(br.omega[i]) for i in br.folds), reverse=True) == pytest.approx(folds, rel=1e-8)


def test_iteration_count_control_is_the_old_rule():
    """Without the geometric, contraction and norm targets and the deadline, the step control is
    the rule before issue 16: the old 142 points of the Duffing branch with max_step 0.5."""
    opts = frequency_response_options(max_step=0.5, target_angle=None, target_contraction=None,
                                      corrector_deadline=None, target_norm_change=None)
    br = fm.frequency_response(duffing(), (0.5, 2.5), fm.Harmonics(3), options=opts)
    assert br.success and len(br) == 142


def test_step_control_recorded_and_resumable():
    """The step after each point depends only on the last step: a run resumed from any state
    computes the same points as the full run."""
    seen = []
    opts = frequency_response_options(callback=seen.append)
    full = fm.frequency_response(duffing(), (0.5, 2.5), fm.Harmonics(3), options=opts)
    state = seen[20].state
    problem = fm.ForcedResponseProblem(duffing(), fm.Harmonics(3))
    rest = fm.continuation(problem, (0.5, 2.5), start=state, options=frequency_response_options(
        x_scale=state.x_scale, p_scale=state.p_scale))
    assert rest.first_index == 21
    assert rest.p == pytest.approx(full.omega[21:], rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"target_angle": 0.0}, ValueError, r"target_angle must be a positive finite number, got 0\.0"),
    ({"target_angle": 60.0}, ValueError, r"target_angle must be in \(0, max_turn_angle=60\.0\) degrees or None, "
                                         r"got 60\.0"),
    ({"target_angle": 20.0, "max_turn_angle": 15.0}, ValueError, r"max_turn_angle=15\.0.*got 20\.0"),
    ({"target_angle": float("nan")}, ValueError, r"target_angle .* got nan"),
    ({"target_contraction": 1.0}, ValueError, r"target_contraction must be in \(0, 1\) or None, got 1\.0"),
    ({"target_contraction": -0.1}, ValueError, r"target_contraction must be a positive finite number, got -0\.1"),
    ({"corrector_deadline": 0}, ValueError, r"corrector_deadline must be an integer >= 1, got 0"),
    ({"corrector_deadline": 2.0}, TypeError, r"corrector_deadline must be an integer >= 1, got 2\.0"),
    ({"corrector_deadline": True}, TypeError, r"corrector_deadline must be an integer >= 1, got True"),
    ({"target_norm_change": 0.0}, ValueError, r"target_norm_change must be a positive finite number, got 0\.0"),
])
def test_option_validation(kwargs, error, match):
    with pytest.raises(error, match=match):
        fm.ContinuationOptions(**kwargs)


def test_curve_between_points_follows_the_response_off_contact():
    """With target_norm_change=0.3 (frequency_response's default) the size of the response changes by a
    bounded ratio per step, so lines drawn between points follow it where the tangent barely turns:
    on seed case 1 (H = 20) the midpoint of every chord between two points without contact is
    within 5 % of the linear response there (measured 3.5 %; the response off contact is the
    linear one, F / |1 - w^2 + i c w|, exactly); without it one step spans w = 1.21 -> 1.83 and its
    chord is 65 % off at mid-step."""
    def worst_chord(branch):
        w, A = branch.omega, np.abs(branch.Q[:, :, 0] @ fm.Harmonics(20).grid.synthesis(np.linspace(0, 2 * np.pi, 256, endpoint=False)).T).max(axis=1)
        mid, chord = 0.5 * (w[1:] + w[:-1]), 0.5 * (A[1:] + A[:-1])
        lin = 0.2 / np.abs(1 - mid ** 2 + 0.1j * mid)
        off = (lin < 0.98) & (A[1:] < 0.98) & (A[:-1] < 0.98)  # gap 1
        return float(np.max(np.abs(chord[off] / lin[off] - 1)))

    assert frequency_response_options().target_norm_change == 0.3
    assert worst_chord(seed_branch(20)) <= 0.05
    plain = fm.frequency_response(seed_case1(), (0.5, 2.0), fm.Harmonics(20),
                                  options=frequency_response_options(target_norm_change=None))
    assert worst_chord(plain) > 0.3


def test_options_disable_and_defaults():
    opts = fm.ContinuationOptions(target_angle=None, target_contraction=None, corrector_deadline=None)
    assert opts.target_angle is None and opts.target_contraction is None and opts.corrector_deadline is None
    d = fm.ContinuationOptions()
    assert (d.target_angle, d.target_contraction, d.corrector_deadline, d.predictor) == (10.0, 0.25, 3, fm.predictors.Phase())
    assert frequency_response_options().max_step == 3.0


def test_force_unit_does_not_change_the_curve():
    """The seed contact case written with a force unit 1e8 times smaller (M, C, K, F all x 1e8:
    same displacements, contact forces x 1e8, as a steel structure in N and m): the arclength
    scales the contact-force unknowns by the contact stiffness, so the same curve is traced with
    the same steps (with one scale for all unknowns it crawled at grazing: the force harmonics
    were the whole arclength). Same points; folds equal to the corrector's tolerance."""
    def case(a):
        return (fm.StructuralModel(M=[[a]], K=[[a]], C=[[0.1 * a]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
                .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2 * a)))

    ref = fm.frequency_response(case(1.0), (0.5, 2.0), 10)
    si = fm.frequency_response(case(1e8), (0.5, 2.0), 10)
    assert si.success and len(si) == len(ref)
    np.testing.assert_allclose(si.omega[list(si.folds)], ref.omega[list(ref.folds)], rtol=1e-8)
    np.testing.assert_allclose(si.P, 1e8 * ref.P, rtol=1e-6, atol=1e-6 * 1e8 * np.abs(ref.P).max())
