"""Physics mistakes that used to pass silently get a warning that names the fix (issue 36, item 4)."""

import warnings

import pytest

import femodes as fm


def test_contact_on_a_solid_boundary_without_direction_warns():
    """A boundary of a 3-D solid without direction= acts along +x: said, with the fix."""
    model = fm.solid(fm.box_mesh(1.0, 0.2, 0.1, 4, 1, 1), fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left")
    with pytest.warns(UserWarning, match=r"no direction= for boundary 'top' of a 3-D solid.*direction=\(0.0, 0.0, 1.0\)"):
        model.with_contact(fm.UnilateralContact(at="top", gap=0.01))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.with_contact(fm.UnilateralContact(at="top", gap=0.01, direction=(0.0, 0.0, 1.0)))
        model.with_contact(fm.UnilateralContact(at=("top", "u_x"), gap=0.01))


def test_undamped_forced_response_warns():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]])
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.1)))
    with pytest.warns(UserWarning, match="no damping.*with_damping"):
        fm.frequency_response(model, omega=(0.5, 0.8), harmonics=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fm.frequency_response(model.with_damping(alpha=0.1), omega=(0.5, 0.8), harmonics=1)
