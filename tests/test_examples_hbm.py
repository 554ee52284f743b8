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


@pytest.mark.slow
def test_bar_refinement_against_the_continuum():
    """The bar's backbone (contact-phase family, mass redistributed) at 2 E_g within 0.5 % of the
    continuum's first nonsmooth mode on 20, 40 and 80 elements (0.38, 0.07, 0.03 % measured: the
    error falls with the mesh there); at 5 and 20 E_g, where reached, within 1 % (the harmonic
    truncation and the gaps the tongues leave dominate: no rate is claimed there)."""
    ex = load("bar_contact_refinement")
    err = ex.errors[True]
    assert np.all(np.abs(err[:, 0]) < 5e-3) and np.all(np.diff(np.abs(err[:, 0])) < 0)
    assert np.isfinite(err[:, 1]).sum() >= 2  # 5 E_g reached on at least two meshes
    finite = np.isfinite(err)
    assert np.all(np.abs(err[finite]) < 1e-2)


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
