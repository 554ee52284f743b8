"""HBM vs time integration: FE cantilever nonlinear mode and the forced contact oscillator.

Tolerances are the measured values of examples/validation_cantilever.py and
examples/validation_forced.py with margins (see their docstrings for the tables).
"""

import numpy as np
import pytest

from .test_examples import load


@pytest.fixture(scope="module")
def cant():
    return load("validation_cantilever")


@pytest.fixture(scope="module")
def forced():
    return load("validation_forced")


def test_cantilever_setup(cant):
    assert cant.TIP_MASS == 0.0  # massless contact DOF (default redistribution)
    assert np.all(np.abs(cant.xi_hbm) < 1e-8)
    # equal-energy start differs from the HBM turning point by < 1 % (v ~ 0 there)
    for x in cant.ts.values():
        assert abs(x["scale"] - 1) < 0.012 and x["v_turning"] < 1e-10
        assert x["penetration_ts"] < 1e-12  # position-level Signorini on the massless tip


def test_cantilever_hbm_vs_time(cant):
    # H >= 10: HBM and time-domain (mode-1 coordinate) frequencies agree within 7 % (measured <= 5.7 %)
    assert np.all(np.abs(cant.freq_error[1:]) < 0.07)
    # HBM frequency converges with H (H = 10 -> 20 changes < 2 %), H = 5 is far off (> 10 % above)
    assert np.all(np.abs(cant.omega_hbm[2] / cant.omega_hbm[1] - 1) < 0.02)
    assert np.all(cant.omega_hbm[0] / cant.omega_hbm[2] - 1 > 0.1)
    # time-domain frequency is uncertain to a few % (dt sensitivity, H = 20 starts)
    w = np.array([cant.omega_ts_sens[d] for d in sorted(cant.omega_ts_sens)])
    assert np.all(np.ptp(w, axis=0) / w.mean(axis=0) < 0.06)
    # Not asserted: the orbit error against the time-domain motion. That motion is not periodic
    # (first-return distance 0.40-0.54 of the amplitude, printed by the example), so a bound on
    # the orbit error could only be loose enough to pass whatever HBM computes.


def test_cantilever_energy_drift(cant):
    # energy errors at contact switches fall with dt (measured 7 %, 1.7-2.8 %, 0.6-0.9 %)
    d = [cant.drift_sens[k] for k in sorted(cant.drift_sens)]
    assert np.all(d[2] < d[0])
    assert np.all(d[2] < 0.02) and np.all(cant.energy_drift[1:] < 0.05)


@pytest.mark.slow  # the forced example takes ~35 s (steady states by time stepping)
def test_forced_linear_points(forced):
    # no-contact points: trapezoidal rule O(dt^2) vs the exact linear steady state
    assert forced.linear_error[forced.DT] < 2e-6
    assert 1.9 < forced.linear_rate < 2.1
    assert forced.hbm_linear_error < 1e-6
    for k, p in enumerate(forced.points):
        if not forced.contact[k]:
            assert p["converged"]
            assert np.all(p["orbit_error"] < 1e-5) and np.all(p["penetration_hbm"] == 0)


@pytest.mark.slow
def test_forced_contact_points(forced):
    pts = {(p["omega"], p["label"]): p for p in forced.points}
    assert set(pts) >= {(0.95, "single"), (1.2, "lower"), (1.2, "upper")}
    # both stable branches at w = 1.2: the upper one impacts, the lower does not
    assert pts[(1.2, "upper")]["amp_ts"] > 1.0 > pts[(1.2, "lower")]["amp_ts"]
    # HBM penetration falls with H at the contact point w = 0.95 (an HBM-only quantity)
    assert np.all(np.diff(pts[(0.95, "single")]["penetration_hbm"]) < 0)
    # Not asserted: HBM-vs-time errors at w = 0.95 and on the upper branch at w = 1.2, because the
    # time-stepping runs there do not reach a periodic steady state (relative change 6.6e-4 and
    # 0.11 after 400 periods); comparing with them would test nothing. Open in issue 4.
