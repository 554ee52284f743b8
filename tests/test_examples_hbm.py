"""HBM examples as executable documentation: import them and assert their physical numbers."""

import numpy as np
import pytest

from .test_examples import load


@pytest.fixture(scope="module")
def contact():
    return load("contact_oscillator")


def test_contact_backbone_grazes_at_half_and_rises(contact):
    bb = contact.backbone
    assert bb.success
    below = bb.energy < 0.49  # grazing at E = gap^2 / 2 = 0.5
    np.testing.assert_allclose(bb.omega[below], 1.0, atol=1e-9)
    assert np.all(np.abs(bb.xi) < 1e-10)
    above = bb.energy > 0.6
    assert np.all(np.diff(bb.omega[above]) > 0)
    # HBM with H = 20 against the exact impact oscillator: algebraic convergence in H, so the
    # error is a few percent (measured 3.4 % at E = 1, 3.4 % at E = 2, 3.6 % at E = 8)
    err = np.abs(contact.backbone_error[bb.energy > 0.7])
    assert err.max() < 0.05


def test_contact_forced_cases_trace_both_folds(contact):
    for br, folds in ((contact.forced1, (1.38498, 1.08077)), (contact.forced2, (1.38894, 1.15168))):
        assert br.success and len(br.folds) == 2
        np.testing.assert_allclose(sorted(br.omega[list(br.folds)]), sorted(folds), rtol=1e-4)
        assert br.nit.mean() <= 4.0 and br.nit.max() <= 8


@pytest.mark.slow  # the example's whole study: 100-160 s on 2 cores, a sixth of the suite (CI's slow step runs it)
def test_bar_refinement_against_the_continuum(tmp_path):
    """The bar's first nonsmooth mode against the continuum's (d'Alembert), with the rates the example
    measures (benchmarks/README_bar_convergence.md has the full study).

    Measured (160 elements, mass redistributed): mean errors over 2-8 E_g of -0.37, -0.29, -0.19 %
    for H = 10, 20, 40 (+- 0.13, 0.07, 0.06 %), q = 0.50 +- 0.33; every orbit in 2-20 E_g within
    0.87 % (these are the guided sweeps of issue 35, which reach 25 E_g; before them -0.17, -0.10 %
    and q = 0.92 for H = 20, 40, from runs that stopped at 13-29 E_g).
    Mesh at H = 10 (fixed frequencies): median changes 0.39, 0.055, 0.029 % (redistributed) and
    0.40, 0.15, 0.049 % (consistent) for 20->40, 40->80, 80->160; p = 1.87 +- 0.56 and 1.51 +- 0.07.
    """
    ex = load("bar_contact_refinement")
    # every orbit between 2 and 8 E_g within 1 %: the tongues pull single orbits by up to ~1 %
    for H in ex.HARMONICS:
        r, e = ex.orbit_errors(ex.branches[H])
        assert np.all(np.abs(e[(r >= 2) & (r <= 8)]) < 1e-2), H
        assert r.max() > 8.0  # the family's mean is taken over 2-8 E_g
    # the harmonic truncation: the family's frequency too low, less so with more harmonics
    assert np.all(ex.mean_error < 0)
    # (by half from H = 10 to 40: 0.51 measured)
    assert abs(ex.mean_error[-1]) < 0.75 * abs(ex.mean_error[0])
    # its rate: 0.50 +- 0.33 measured; the band (0.3, 1.6) holds a first-order-or-slower rate (the
    # contact force is a rectangular pulse, its harmonics fall as 1/j) and fails on no convergence
    assert 0.3 < ex.q < 1.6 and ex.q_sigma < 0.6
    # the mesh at H = 10: second-order-like convergence at fixed frequencies, both contact masses
    for redistribute in (True, False):
        p, dp = ex.mesh_rate[redistribute]
        assert 1.0 < p < 2.5, (redistribute, p)
        # on 160 elements the mesh error is below the harmonic one (0.03-0.05 % against 0.1-0.4 %)
        assert ex.mesh_change[redistribute][-1] < abs(ex.mean_error[-1])
    # mass redistribution: the same limit, reached sooner (40->80: 0.055 % against 0.15 %)
    assert ex.mesh_change[True][1] < 0.6 * ex.mesh_change[False][1]
    png = ex.figure(tmp_path / "bar.png")
    assert png.stat().st_size > 20_000


def test_cantilever_reduced_and_full_backbones_agree(tmp_path):
    ex = load("cantilever_tip_stop")
    ex.main(tmp_path)
    import meshio

    full = meshio.read(tmp_path / "cantilever_mode1_full_0000.vtu")
    cb = meshio.read(tmp_path / "cantilever_mode1_cb10_0000.vtu")
    # same mesh, reduced solution expanded to it; tip deflections agree to the CB error
    assert full.points.shape == cb.points.shape == (41, 3)
    tip_full, tip_cb = full.point_data["displacement"][-1, 1], cb.point_data["displacement"][-1, 1]
    assert tip_cb == pytest.approx(tip_full, rel=1e-3)
    full = ex.omega_at["full"]
    # CB with 10 modes: linear w1 error 7e-8, backbone within 1e-5 relative
    np.testing.assert_allclose(ex.omega_at["CB 10 modes"], full, rtol=1e-5)
    np.testing.assert_allclose(ex.omega_at["CB 4 modes"], full, rtol=1e-3)
    for b in ex.backbones.values():
        assert b.success and np.all(np.abs(b.xi) < 1e-10)
    assert ex.forced.success and ex.forced.penetration.max() < 0.3 * ex.GAP
