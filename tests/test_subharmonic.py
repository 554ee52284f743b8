"""Sub-harmonic (period-2) resonance of the impact oscillator: examples/subharmonic_contact.py.

Tolerances are from the measured values (see the example's docstring), with margin: the HBM
of an impacting motion converges algebraically (~1/H) because the velocity jumps at impacts.
"""

import numpy as np
import pytest

import femodes as fm

from .test_examples import load


@pytest.fixture(scope="module")
def ex():
    return load("subharmonic_contact")


def test_time_domain_orbit_is_an_attracting_period_2_orbit(ex):
    # Poincare section: fixed point of the 2-period map (shooting converged), not of the 1-period map
    assert ex.shoot_residual < 1e-10
    assert ex.period2_mismatch < 1e-8
    assert ex.period1_mismatch > 1.0  # measured 2.64: the two strobe points are far apart
    assert ex.n_impacts_td == 1  # one impact per sub-harmonic period
    # attracting: complex pair with |mu|^2 = det = exp(-c T) (linear flow, area-preserving elastic impact)
    mu = np.abs(ex.multipliers)
    assert np.all(mu < 1)
    np.testing.assert_allclose(mu, np.exp(-ex.DAMPING * ex.NU * np.pi / ex.OMEGA0), rtol=1e-4)


def test_hbm_point_against_time_integration(ex):
    assert ex.newton0.success and ex.newton0.residual_norm < 1e-10
    assert ex.sub_hbm > 1.0  # genuinely sub-harmonic (1-periodic solutions have c1 = s1 = 0)
    # w/2 amplitude: measured error +0.094 (7.5 %) at H = 20
    assert abs(ex.sub_hbm - ex.sub_td) < 0.12
    # algebraic convergence in H: errors 0.156, 0.094, 0.054 for H = 10, 20, 40 (~1/H)
    err = {H: v[1] - ex.sub_td for H, v in ex.sub_vs_H.items()}
    assert all(v[0] for v in ex.sub_vs_H.values())
    assert err[10] > err[20] > err[40] > 0
    assert err[40] < 0.07
    assert 1.4 < err[20] / err[40] < 2.4
    # extreme displacement (measured 7 %) and impact phase (measured 0.009 rad)
    assert abs(ex.min_u_hbm / ex.min_u_td - 1) < 0.1
    assert abs(ex.impact_phase_hbm - ex.impact_phase_td) < 0.03
    # truncation artefacts: penetration 0.029, tension 0.12 of the peak contact force
    assert ex.sol0.penetration < 0.05
    assert ex.sol0.tension < 0.2 * np.max(ex.sol0.contact_force(ex.t_fine))
    # the HBM contact does no work over a period, like restitution 1
    assert abs(ex.contact_work0) < 1e-6


def test_branch_is_a_closed_isola_with_two_folds(ex):
    for b in ex.branches:
        assert b.success and len(b) > 20
        assert np.all(b.converged) and np.max(b.residual_norm) < 1e-8
        assert len(b.folds) == 1
        assert np.all(np.hypot(b.Q[:, 1, 0], b.Q[:, 2, 0]) > 0.8)  # sub-harmonic all along
    assert ex.closure_gap < 1e-8  # both runs end on the same point of the lower part
    lo, hi = ex.fold_omegas
    # low fold (grazing end of the isola): HBM 2.0657, time integration in (2.050, 2.075)
    assert min(ex.td_fold_low) - 0.01 < lo < max(ex.td_fold_low) + 0.01
    # high fold: HBM H=20 at 3.606, time integration in (3.677, 3.702); the HBM fold moves
    # up with H (3.646 at H = 40), a truncation error of 2-3 %
    assert 0.02 < min(ex.td_fold_high) - hi < 0.12
    # the primary branch is the small linear non-impacting response there
    assert ex.primary.success and ex.primary.amplitude(0).max() < ex.GAP


def test_branch_points_validated_by_shooting(ex):
    checks = [c for c in ex.checks if c["omega"] < 3.3]
    assert len(checks) >= 5
    for c in checks:
        assert c["found"], c["omega"]
        # upper part attracting, lower part a saddle
        assert c["stable"] == (c["part"] == "upper"), (c["omega"], c["part"], c["multipliers"])
        # measured: at most 13.7 % (w = 3.19, amplitude grows with w, error with impact velocity)
        assert abs(c["sub_hbm"] / c["sub_td"] - 1) < 0.15
        assert abs(c["phase_hbm"] - c["phase_td"]) < 0.04


def test_shooting_multipliers_reproduced_through_fm_stability(ex):
    """fm.stability(method=fm.stability_methods.Shooting()) on the HBM points reproduces the example's own Floquet
    multipliers (finite differences of its event-driven map, step 1e-7: ~1e-6 accurate); the
    monodromy's eigenvalues do not depend on the start time of the shooting."""
    checks = [c for c in ex.checks if c["omega"] < 3.3 and c["found"]]
    assert len(checks) >= 5
    for c in checks:
        b = min(ex.branches, key=lambda br: np.min(np.abs(br.omega - c["omega"])))
        i = int(np.argmin(np.abs(b.omega - c["omega"])))
        assert b.omega[i] == c["omega"]
        r = fm.stability(b[i], method=fm.stability_methods.Shooting())
        assert r.method == "shooting" and r.stable == c["stable"]
        assert np.sort_complex(r.multipliers) == pytest.approx(np.sort_complex(np.asarray(c["multipliers"])), abs=1e-5)
