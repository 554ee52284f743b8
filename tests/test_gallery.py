"""Gallery examples (duffing, travelling_resonance, penalty_vs_complementarity): assert their physics."""

import numpy as np
import pytest

from .test_examples import load


@pytest.fixture(scope="module")
def duffing():
    return load("duffing")


def test_duffing_backbone_converges_with_H(duffing):
    # exact elliptic frequency (shared/references.md), eps = 1
    np.testing.assert_allclose(duffing.exact_frequency(duffing.A_CHECK), duffing.W_CHECK_REF, rtol=1e-11)
    err = [duffing.backbone_error[H] for H in duffing.H_BACKBONE]
    assert err[0] > err[1] > err[2]  # H = 1, 3, 9
    assert 1e-2 < err[0] < 3e-2 and err[2] < 1e-6  # H = 1: 2 % at A = 5; H = 9: ~1e-7
    np.testing.assert_allclose(duffing.backbone_omega[9], duffing.W_CHECK_REF, rtol=1e-6)


def test_duffing_forced_folds_and_coexisting_cycles(duffing, tmp_path):
    for key, ref in duffing.CASES.items():
        # folds of the H = 9 branch vs the H = 21 converged references, 1e-5 relative
        np.testing.assert_allclose(duffing.folds[key], ref["folds"], rtol=1e-5)
        # the largest branch amplitude is a sampled point near the peak: within 1e-4 relative
        assert duffing.peaks[key] == pytest.approx(ref["peak"], rel=1e-4)
        assert duffing.peaks[key] <= ref["peak"] * (1 + 1e-6)
    # three coexisting solutions at w = 2.0 (c = 0.1, eps = 1), within 1e-3 absolute
    assert len(duffing.coexisting) == 3
    np.testing.assert_allclose(duffing.coexisting_amplitude, duffing.COEXIST_REF, atol=1e-3)
    assert all(sol.omega == 2.0 and sol.residual_norm < 1e-9 for sol in duffing.coexisting)
    # stability computed, not written in (references.md: the middle orbit is the unstable one),
    # by both methods; Hill and shooting agree on the largest multiplier to 1e-5 (H = 9 orbit)
    assert duffing.coexisting_stable == [True, False, True]
    for st in duffing.coexisting_stability:
        assert st["shooting"].stable == st["hill"].stable
        assert abs(st["hill"].multipliers[0]) == pytest.approx(abs(st["shooting"].multipliers[0]), abs=1e-5)
    for br in duffing.forced.values():  # every forced branch: unstable exactly between its folds
        lo, hi = sorted(br.folds)
        idx = np.arange(len(br))
        assert np.all(~br.stable[(idx > lo) & (idx < hi)]) and np.all(br.stable[(idx < lo) | (idx > hi)])
    png = duffing.main(tmp_path)
    assert png.stat().st_size > 10_000


def test_travelling_resonance(tmp_path):
    ex = load("travelling_resonance")
    br = ex.branch
    assert br.success and len(br.folds) == 2
    # the picked points are points of the branch, in the order they are met along it
    idx = list(ex.PICKS.values())
    assert idx == sorted(idx) and idx[2] == br.folds[0] and idx[4] == br.folds[1]
    for name, i in ex.PICKS.items():
        sol = ex.solutions[name]
        assert sol.omega == br.omega[i] and np.array_equal(sol.Q, br.Q[i])
    # folds as in examples/contact_oscillator.py (same model, H = 20)
    np.testing.assert_allclose(br.omega[list(br.folds)], [1.38497813, 1.08076953], rtol=1e-6)
    # no contact before first contact and after the resonance, a contact force at the folds
    assert ex.max_contact_force["before contact"] < 1e-9 and ex.max_contact_force["after resonance"] < 1e-9
    assert ex.amplitude[ex.PICKS["before contact"]] < 1.0 <= ex.amplitude[ex.PICKS["first contact"]]
    assert ex.max_contact_force["upper fold"] > 10.0  # ~13.6: one strong impact per period
    assert ex.max_contact_force["lower fold"] > 0.0 and ex.max_contact_force["unstable branch"] > 1.0
    assert max(ex.penetration.values()) < 0.05
    assert ex.main(tmp_path).stat().st_size > 10_000


def test_penalty_vs_complementarity(tmp_path):
    ex = load("penalty_vs_complementarity")
    ks = ex.STIFFNESSES
    assert all(ex.branch_success.values()) and ex.complementarity.success
    # penalty penetration at w = 1.05 (independently measured 0.1705, 0.0440, 0.0103, 0.00225), 2 %
    np.testing.assert_allclose([ex.penetration_at_w[k] for k in ks], [0.1705, 0.0440, 0.0103, 0.00225], rtol=2e-2)
    pen = [ex.max_penetration[k] for k in ks]
    assert all(a > b for a, b in zip(pen, pen[1:]))
    # penalty(k) approaches complementarity(c = k): 4.5-10x closer per decade of stiffness
    d = [ex.distance[k] for k in ks]
    ratios = [a / b for a, b in zip(d, d[1:])]
    assert all(4.5 < r < 10 for r in ratios), ratios
    # and the penalty response curves approach the complementarity one (upper fold, peak)
    gaps = [abs(ex.peak_amplitude[k] - ex.peak_amplitude_complementarity) for k in ks]
    assert gaps[-1] < 0.05 and gaps[-1] < gaps[0] / 2
    assert ex.main(tmp_path).stat().st_size > 10_000


@pytest.mark.slow
def test_period_doubling_example(tmp_path):
    """~50 s: stability by shooting at every point of a 136-point branch."""
    ex = load("period_doubling")
    kinds = [b.kind for b in ex.branch.bifurcations]
    assert kinds.count("fold") == 2 and kinds.count("period_doubling") == 1
    assert ex.doubling.omega == pytest.approx(0.996204, abs=2e-6)
    assert ex.doubled.meta["switched_from"]["omega_hbm"] == pytest.approx(0.95959, abs=1e-4)
    # the shot period-2 orbit is the HBM one up to the contact error, and truly period 2
    assert ex.shot.success and ex.orbit_correction < 0.06 and ex.half_period_gap > 0.1
    assert ex.main(tmp_path).stat().st_size > 10_000
