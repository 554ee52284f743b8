"""The tuning of the error estimate (``femodes.AccuracyOptions``): its defaults are the module
constants of femodes.accuracy before issue 39, those names still read them (deprecated), bad
values are refused with a message that quotes them, and every name other code imported from
``femodes.accuracy`` still imports."""

import dataclasses
import math
import warnings

import numpy as np
import pytest

import femodes as fm
import femodes.accuracy as accuracy

#: The module constants of femodes/accuracy.py before issue 39 (commit d24711a), as written there.
OLD_CONSTANTS = {
    "RATE_MIN": 1.5, "BRACKET_RATE_MAX": 2.0, "SAME_POINT": 1e-8, "RTOL_BUDGET": 10.0, "RTOL_MIN_SECONDS": 60.0,
    "MIN_FRACTION": 1.0 / 16.0, "WALK_DEADLINE": 3, "SPLIT_GAIN": 0.75, "LEVEL_RESTARTS": 4, "RESTART_MIN_POINTS": 3,
    "PAST_LAST": 2, "LEVEL_POINTS_PER_POINT": 4, "LEVEL_POINTS_SLACK": 100, "SHOOTING_MAX_CORRECTION": 0.5,
    "SHOOTING_FLOOR": 1e-9, "SHOOTING_AUTO_MAX_WORK": 1e6, "SHOOTING_AUTO_MAX_DOFS": 120,
    "SHOOTING_AUTO_MAX_EVENTS": 8, "GLANCING_MAX": 3.0, "GLANCING_COS": 0.5, "SHOOTING_FOLD_SLACK": 1e-6,
    "SHOOTING_EXACT_AFTER": 3, "GRAZING_POINTS": 4, "FOLD_STEP_HALVINGS": 4, "SHOOTING_TOL": 1e-11,
    "SHOOTING_STEP": 1e-7, "SHOOTING_MAX_ITER": 40, "SHOOTING_STALL": 3, "SHOOTING_STALL_ALPHA": 2.0 ** -8,
}


def test_defaults_are_the_old_constants():
    options = fm.AccuracyOptions()
    for name, value in OLD_CONSTANTS.items():
        got = getattr(options, name.lower())
        assert got == value and type(got) is type(value), name
    assert options.shooting_fold_search is True
    assert options.shooting_clearance == 0.1  # added later (a shallow arch, 2026-12-01)
    assert {f.name for f in dataclasses.fields(options)} == ({n.lower() for n in OLD_CONSTANTS}
                                                            | {"shooting_fold_search", "shooting_clearance"})


@pytest.mark.parametrize("name", sorted(OLD_CONSTANTS))
def test_old_constants_read_the_defaults_with_a_warning(name):
    with pytest.warns(DeprecationWarning, match=f"AccuracyOptions\\(\\).{name.lower()}"):
        assert getattr(accuracy, name) == OLD_CONSTANTS[name]


def test_old_constants_import_with_a_warning():
    with pytest.warns(DeprecationWarning, match="rtol_budget"):
        from femodes.accuracy import RTOL_BUDGET
    assert RTOL_BUDGET == 10.0
    with pytest.raises(AttributeError, match="NO_SUCH_NAME"):
        accuracy.NO_SUCH_NAME  # noqa: B018


def test_names_other_code_imports_are_there():
    """The names the analyses, tests, examples and docs took from ``femodes.accuracy`` before it
    was a package, without a warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in ("estimate_error", "estimate_levels", "meet_tolerance", "rtol_time_limit",
                     "shooting_unsupported", "shooting_unsupported_for", "refinement_options",
                     "check_estimate_method", "ESTIMATE_METHODS", "GLANCING", "AccuracyOptions"):
            assert getattr(accuracy, name) is not None
    assert fm.estimate_error is accuracy.estimate_error and fm.AccuracyOptions is accuracy.AccuracyOptions
    assert accuracy.ESTIMATE_METHODS == ("auto", "levels", "shooting")


@pytest.mark.parametrize("field, bad", [("rate_min", 1.0), ("rate_min", math.nan), ("bracket_rate_max", 0.5),
                                        ("same_point", 0.0), ("rtol_budget", -1.0), ("rtol_min_seconds", math.inf),
                                        ("min_fraction", 1.5), ("walk_deadline", 0), ("walk_deadline", 2.0),
                                        ("level_restarts", -1), ("shooting_auto_max_dofs", True),
                                        ("glancing_cos", 1.5), ("shooting_stall_alpha", 0.0),
                                        ("shooting_tol", "1e-11"), ("shooting_fold_search", 1),
                                        ("shooting_clearance", -0.1)])
def test_bad_values_are_refused_quoting_them(field, bad):
    with pytest.raises(ValueError, match=f"AccuracyOptions: {field} must be .*got {bad!r}"
                       .replace("(", "\\(").replace(")", "\\)")):
        fm.AccuracyOptions(**{field: bad})


def test_options_are_frozen_and_keyword_only():
    options = fm.AccuracyOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.rate_min = 2.0
    with pytest.raises(TypeError):
        fm.AccuracyOptions(1.5)
    assert fm.AccuracyOptions(glancing_max=math.inf).glancing_max == math.inf  # keep every crossing


def test_options_must_be_accuracy_options():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    b = fm.frequency_response(model, (0.5, 0.6), 4)
    with pytest.raises(TypeError, match="estimate_error: options must be a femodes.AccuracyOptions, got dict"):
        fm.estimate_error(b, options={"rate_min": 2.0})
    with pytest.raises(TypeError, match="frequency_response: error_options must be a femodes.AccuracyOptions"):
        fm.frequency_response(model, (0.5, 0.6), 4, rtol=1e-3, error_options=1e-3)
    with pytest.raises(TypeError, match="nonlinear_mode: error_options must be a femodes.AccuracyOptions"):
        fm.nonlinear_mode(fm.StructuralModel(M=[[1.0]], K=[[1.0]]), 1, (1e-3, 1e-2), 4, error_options="levels")


def test_estimators_follow_the_protocol():
    """The three estimators are objects with ``estimate(lad, errors, todo) -> todo``."""
    import inspect

    from femodes.accuracy.exact_branch import ExactFolds
    from femodes.accuracy.levels import Levels
    from femodes.accuracy.protocol import Estimator
    from femodes.accuracy.shooting import Shooting

    want = list(inspect.signature(Estimator.estimate).parameters)
    for cls in (Levels, Shooting, ExactFolds):
        assert list(inspect.signature(cls.estimate).parameters) == want, cls.__name__


def test_levels_estimate_with_other_options_differs_as_told():
    """A larger ``rate_min`` (the clamp of the observed ratio) can only lower the levels' estimate
    ``d r / (r - 1)``: the options reach the estimator, and the default gives the default."""
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
    b = fm.frequency_response(model, (0.9, 1.5), 6)
    plain = fm.estimate_error(b, method=fm.error_methods.Levels()).accuracy
    default = fm.estimate_error(b, method=fm.error_methods.Levels(), options=fm.AccuracyOptions()).accuracy
    np.testing.assert_array_equal(plain.omega, default.omega)
    steep = fm.estimate_error(b, method=fm.error_methods.Levels(), options=fm.AccuracyOptions(rate_min=3.0)).accuracy
    ok = np.isfinite(plain.rate) & np.isfinite(steep.rate)
    assert ok.any() and np.all(steep.rate[ok] >= 3.0)
    assert np.all(steep.amplitude[ok] <= plain.amplitude[ok] * (1 + 1e-12))
