"""HBM nonlinear modes vs Moreau-Jean time integration and the exact impact oscillator.

Tolerances are measured values with a margin (see examples/validation_free_orbits.py and
examples/energy_frequency_harmonics.py for the tables):

* time integration (dt = 5e-4, trapezoidal, e = 1): frequency within 5e-4 of the exact impact
  oscillator (measured <= 1.7e-4; Moreau-Jean impact times are O(dt)), energy drift < 1e-9
  (measured ~1e-12);
* HBM vs time domain: the HBM frequency is *below* the reference and its relative error falls
  algebraically, ~H^-0.85 (measured -0.84 .. -0.86 over H = 10..40 and -0.82 over H = 5..40 vs the
  exact value): the velocity jump at impacts limits Fourier convergence to ~1/H (Gibbs), with the
  pre-asymptotic range still slightly slower; accepted range [-1.0, -0.7];
* per-H bands on the frequency error (H = 10: 5.0-7.0 %, H = 20: 2.8-4.0 %, H = 40: 1.5-2.2 %);
* penetration of the truncated orbit decreasing with H; artificial damping xi ~ 0 (< 1e-10).
"""

import numpy as np
import pytest

from .test_examples import load


@pytest.fixture(scope="module")
def orbits():
    return load("validation_free_orbits")


@pytest.fixture(scope="module")
def harmonics():
    return load("energy_frequency_harmonics")


def decreasing(a, axis=0):
    return bool(np.all(np.diff(a, axis=axis) < 0))


def test_time_integration_reference_1dof(orbits):
    assert np.all(np.abs(orbits.ts_error_exact) < 5e-4)
    for E in orbits.ENERGIES_1DOF:
        r = orbits.ts1[E]
        assert r["energy_drift"] < 1e-9
        assert r["period_spread"] < 1e-9  # the discrete orbit is exactly periodic
        assert r["penetration"] < 2 * orbits.DT_1DOF * np.sqrt(2 * E)  # O(h |v|)
        assert r["exact_orbit_error"] < 2e-3


def test_hbm_vs_time_domain_1dof(orbits):
    err = orbits.freq_error_ts  # (H = 10, 20, 40) x (E = 0.8, 2, 8)
    assert np.all(err < 0)  # truncation lowers the impact frequency
    assert decreasing(np.abs(err))
    bands = {10: (0.050, 0.070), 20: (0.028, 0.040), 40: (0.015, 0.022)}
    for a, H in enumerate(orbits.HS):
        lo, hi = bands[H]
        assert np.all((np.abs(err[a]) > lo) & (np.abs(err[a]) < hi)), (H, err[a])
    # time-domain and exact references agree far better than the HBM error
    np.testing.assert_allclose(orbits.freq_error_ts, orbits.freq_error_exact, atol=5e-4)
    assert np.all((orbits.rate_freq_1dof > -1.0) & (orbits.rate_freq_1dof < -0.7))
    # orbit and shape errors fall with H
    assert decreasing(orbits.orbit_error_1dof) and decreasing(orbits.shape_error_1dof)
    assert np.all(orbits.orbit_error_1dof[-1] < 0.1) and np.all(orbits.shape_error_1dof[-1] < 0.05)
    assert np.all((orbits.rate_orbit_1dof > -1.1) & (orbits.rate_orbit_1dof < -0.7))
    assert decreasing(orbits.penetration_1dof) and np.all(orbits.penetration_1dof > 0)
    assert np.all(np.abs(orbits.xi_1dof) < 1e-10)


def test_hbm_vs_time_domain_2dof(orbits):
    assert orbits.E_GRAZE_2DOF == pytest.approx(0.0659830056, rel=1e-8)
    err = orbits.freq_error_2dof
    assert np.all(err < 0) and decreasing(np.abs(err))
    assert np.all(np.abs(err[-1]) < 0.01)
    d1 = orbits.return_distance_2dof
    assert decreasing(d1) and np.all(d1[-1] < 0.1)  # converging to a periodic orbit as H grows
    assert decreasing(orbits.penetration_2dof)
    assert np.all(np.abs(orbits.xi_2dof) < 1e-10)
    assert np.all(orbits.energy_drift_2dof < 1e-9)
    # from the (approximate) H = 40 start the time-domain motion is not periodic: the state
    # returns vary between ~0 and ~0.2 of the energy norm over 20 periods
    ret = orbits.long_returns[:, 1]
    assert ret.max() > 0.1 and ret.min() < 0.03


def test_energy_frequency_harmonics(harmonics):
    ex = harmonics
    assert all(b["success"] for b in ex.backbones.values())
    # the chained continuation ends on the same solution as the public fm.nonlinear_mode
    direct = ex.fm.nonlinear_mode(ex.free, 1, energy=(0.1, 2.0), harmonics=ex.fm.Harmonics(10))
    assert direct.omega[-1] == pytest.approx(ex.at_energy[10][0].omega, rel=1e-7)
    assert np.all(ex.xi_max < 1e-10)
    err = ex.error  # (H = 1, 5, 10, 20, 40) x (E = 2, 8)
    assert np.all(err < 0) and decreasing(np.abs(err))
    assert np.all(np.abs(err[-1]) < 0.021)
    assert np.all((ex.rate > -1.0) & (ex.rate < -0.7))
    assert decreasing(ex.penetration) and np.all(ex.rate_penetration < -0.8)
    # every backbone lies left of the exact curve (HBM frequency below it) above grazing
    for H, b in ex.backbones.items():
        above = b["energy"] > 0.55
        assert np.all(b["omega"][above] < ex.impact_frequency(b["energy"][above])), H


def test_validation_plots(orbits, harmonics, tmp_path):
    assert orbits.main(tmp_path).stat().st_size > 10_000
    assert harmonics.main(tmp_path).stat().st_size > 10_000
