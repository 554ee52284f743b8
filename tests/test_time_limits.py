"""Long work that returns: the error estimate's time limit (``estimate_error(time_limit=)``, the
analyses' ``rtol=`` at ``AccuracyOptions.rtol_budget`` times the plain branch) and the progress of
stability runs."""

import logging

import numpy as np
import pytest

import femodes as fm
from femodes import accuracy


def _oscillator():
    """The seed's impact oscillator: u'' + 0.1 u' + u = 0.2 cos(w t) against a stop at 1."""
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
            .with_contact(fm.UnilateralContact(at=0, gap=1.0)))


@pytest.fixture(scope="module")
def branch():
    return fm.frequency_response(_oscillator(), (0.8, 1.3), fm.Harmonics(10),
                                 options=fm.ContinuationOptions(max_points=40))


def test_estimate_stops_at_its_time_limit_and_says_so(branch, caplog):
    b = branch
    with caplog.at_level(logging.WARNING, logger="femodes.accuracy"):
        fm.estimate_error(b, rtol=1e-6, method=fm.error_methods.Levels(), time_limit=1e-6)
    acc = b.accuracy
    assert np.all(acc.method == "failed") and not acc.met.any()
    text = " ".join(r.getMessage() for r in caplog.records)
    assert "time limit" in text and "time_limit" in text


def test_time_limit_is_checked(branch):
    for bad in (0, -1.0, True, "10"):
        with pytest.raises(ValueError, match="time_limit"):
            fm.estimate_error(branch, time_limit=bad)


def test_rtol_of_an_analysis_is_bounded_by_the_branch_time(caplog):
    """``rtol=`` gives the estimate ``rtol_budget`` times the plain branch's time, at least
    ``rtol_min_seconds``: with a budget of almost nothing it returns the branch with its warning
    instead of refining."""
    default = fm.AccuracyOptions()
    assert accuracy.rtol_time_limit(0.1) == default.rtol_min_seconds == 60.0
    assert accuracy.rtol_time_limit(100.0) == 100.0 * default.rtol_budget == 1000.0
    hurried = fm.AccuracyOptions(rtol_budget=1e-9, rtol_min_seconds=1e-9)
    assert accuracy.rtol_time_limit(0.1, hurried) == 1e-9
    with caplog.at_level(logging.WARNING, logger="femodes.accuracy"):
        b = fm.frequency_response(_oscillator(), (0.8, 1.3), fm.Harmonics(10), rtol=1e-4, error_method=fm.error_methods.Levels(),
                                  options=fm.ContinuationOptions(max_points=40), error_options=hurried)
    assert b.accuracy is not None and not b.accuracy.met.all()
    assert any("time limit" in r.getMessage() for r in caplog.records)


def test_stability_run_logs_an_estimate_and_progress(caplog):
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
             .with_nonlinearity(fm.CubicSpring(at=0, k3=0.5)))
    with caplog.at_level(logging.INFO, logger="femodes.floquet"):
        b = fm.frequency_response(model, (0.5, 2.0), fm.Harmonics(3), stability=fm.stability_methods.Hill(),
                                  options=fm.ContinuationOptions(max_points=30))
    text = [r.getMessage() for r in caplog.records]
    assert any(t.startswith(f"stability: {len(b)} points, about") for t in text)
    assert any(t.startswith(f"stability: {len(b)} of {len(b)} points") for t in text)
