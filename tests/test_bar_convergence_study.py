"""The bar's convergence study (benchmarks/study_bar_convergence.py, issue 35 item 2) on its finest
mesh: the harmonic bias over H = 10-40 and the mesh rate at fixed frequencies up to 320 elements.
Slow (about 2 min of CPU): run with ``-m slow``."""

import numpy as np
import pytest

from .test_examples import BENCHMARKS, load


@pytest.fixture(scope="module")
def study():
    return load("study_bar_convergence", BENCHMARKS)


@pytest.mark.slow
def test_harmonic_bias_on_320_elements(study):
    """Measured with the guided sweep (issue 35): every run reaches 25 E_g on the contact-phase family,
    every orbit past 1.5 E_g within 0.81 % of the continuum; family means over 2-8 E_g of -0.38,
    -0.29, -0.46, -0.29, -0.36 % for H = 10, 15, 20, 30, 40 (+- 0.05-0.13 %): no measurable fall with
    H (q = 0.02 +- 0.23; the q = 0.69 +- 0.28 measured before came from runs that stopped at
    9-16 E_g). The bands fail if a run stops short or leaves the family, or if the bias grows."""
    records = [study.sweep(320, H, True) for H in (10, 15, 20, 30, 40)]
    for r in records:
        assert r["family"] == "contact phase"
        assert r["reached_E_over_Eg"] > 24.9, (r["H"], r["message"])
        w, E = np.array(r["orbits"]["omega"]), np.array(r["orbits"]["E_over_Eg"])
        err = w[E >= 1.5] / study.continuum_omega(E[E >= 1.5]) - 1.0
        assert np.max(np.abs(err)) < 1.2e-2, (r["H"], err)
        m, se, k = study.family_mean(r)
        assert -6e-3 < m < 0 and k >= 5, (r["H"], m, k)
    q, dq, Hs = study.harmonic_rate(records, 320)
    assert Hs == [10, 15, 20, 30, 40] and dq < 0.5, (q, dq)


@pytest.mark.slow
def test_mesh_rate_at_fixed_frequencies(study):
    """Measured (H = 10, 20 to 320 elements): median changes 0.39, 0.055, 0.029, 0.010 % (redistributed),
    0.40, 0.15, 0.049, 0.012 % (consistent): p = 1.67 +- 0.28 and 1.66 +- 0.09."""
    levels = [(20, 10), (40, 10), (80, 10), (160, 10), (320, 10)]
    rates = {}
    for redistribute, mass in ((True, "redistributed"), (False, "consistent")):
        records = list(study.fixed_frequency(levels, redistribute))
        p, dp, N, change = study.mesh_rate(records, mass)
        assert N == [20, 40, 80, 160]
        assert np.all(np.diff(change) < 0), change
        assert 1.0 < p < 2.5, (mass, p)
        rates[mass] = change
    # redistribution: smaller mesh error on 40-80 elements, the same limit
    assert rates["redistributed"][1] < 0.6 * rates["consistent"][1]
