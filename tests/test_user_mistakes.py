"""Natural mistakes of a new user get errors that say what to change (spans, harmonics, indices);
downward spans cost what upward ones do; reprs and saved files are what they say.

(The progress display is in tests/test_progress.py, the command line's one-line errors in
tests/test_cli_errors.py.)
"""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

import femodes as fm

OSC = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
       .with_contact(fm.UnilateralContact(at=0, gap=1.0))
       .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
FREE = OSC.without_forcing().with_damping()


# ---------------------------------------------------------------------------------------------
# spans, harmonics, indices
# ---------------------------------------------------------------------------------------------
def test_downward_span_costs_what_upward_costs():
    """Same curve both ways (shi & Legrand case 1, H = 10): the folds agree and the point counts
    are within 20 % (the step control sizes each step from the last one, so the two directions
    place their points differently: 53 up and 62 down measured; before the arclength scale was
    made direction-independent, downwards took 3.8x the points: 1146 against 305 at H = 20)."""
    up = fm.frequency_response(OSC, omega=(0.5, 2.0), harmonics=10)
    down = fm.frequency_response(OSC, omega=(2.0, 0.5), harmonics=10)
    assert up.success and down.success
    assert abs(len(down) - len(up)) <= 0.2 * len(up), (len(up), len(down))
    # folds are located to the continuation's fold tolerance (1e-9 relative in the tangent)
    np.testing.assert_allclose(np.sort(down.omega[list(down.folds)]), np.sort(up.omega[list(up.folds)]), rtol=1e-6)


def test_reversed_energy_span_is_refused_with_the_fix():
    with pytest.raises(ValueError, match=r"energy must increase.*energy=\(0\.1, 20\)"):
        fm.nonlinear_mode(FREE, mode=1, energy=(20.0, 0.1), harmonics=5)


def test_failed_start_of_a_backbone_says_what_to_change():
    br = fm.nonlinear_mode(FREE, mode=1, energy=(200.0, 1000.0), harmonics=10)  # Newton fails from the linear mode
    assert not br.success and len(br) == 0
    assert "start energy 200" in br.message and "lower energy" in br.message


@pytest.mark.parametrize("fn", [lambda h: fm.frequency_response(OSC, omega=(0.5, 2.0), harmonics=h),
                                lambda h: fm.nonlinear_mode(FREE, mode=1, energy=(0.1, 1.0), harmonics=h)],
                         ids=["frequency_response", "nonlinear_mode"])
def test_zero_harmonics_named(fn):
    with pytest.raises(ValueError, match=r"\bharmonics must be >= 1"):
        fn(0)


def test_harmonics_zero_refused():
    with pytest.raises(ValueError, match="n_harmonics must be >= 1"):
        fm.Harmonics(0)


def test_branch_index_error_names_the_length():
    br = fm.frequency_response(OSC, omega=(0.5, 0.6), harmonics=3)
    with pytest.raises(IndexError, match=rf"branch index 1000 is out of range for a branch of {len(br)} points"):
        br[1000]
    assert br[-1].omega == pytest.approx(0.6)


# ---------------------------------------------------------------------------------------------
# progress
# ---------------------------------------------------------------------------------------------
# small ones
# ---------------------------------------------------------------------------------------------
def test_damping_matrix_reported():
    assert "damping=matrix C" in repr(OSC)
    assert "damping=none" in repr(fm.StructuralModel(M=[[1.0]], K=[[1.0]]))


def test_modal_damping_repr_is_short():
    mesh = fm.line_mesh(1.0, 30, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    r = repr(model.with_damping(modal=0.02))
    assert "modal zeta=0.02 on 20 modes" in r and len(r) < 200
    r = repr(model.with_damping(modal=[0.01, 0.02, 0.05]))
    assert "modal zeta=0.01..0.05 on 3 modes" in r


def test_saved_files_follow_the_umask(tmp_path):
    br = fm.frequency_response(OSC, omega=(0.5, 0.6), harmonics=3)
    old = os.umask(0o022)
    try:
        for name in ("b.npz", "b.h5"):
            path = br.save(tmp_path / name)
            assert stat.S_IMODE(path.stat().st_mode) == 0o644, name
            plain = tmp_path / f"plain_{name}"
            plain.write_bytes(b"")
            assert stat.S_IMODE(plain.stat().st_mode) == 0o644
    finally:
        os.umask(old)
