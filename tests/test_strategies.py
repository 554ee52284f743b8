"""Strategies are objects, never strings (DESIGN.md, style 6): the stability methods
(``fm.stability_methods``) and the error methods (``fm.error_methods``); the old method names
still work for a release, with a DeprecationWarning, and give the same answer."""

import numpy as np
import pytest

import femodes as fm


@pytest.fixture(scope="module")
def duffing_branch():
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.05]]).with_nonlinearity(fm.CubicSpring(at=0, k3=0.5))
             .with_forcing(fm.HarmonicForce(at=0, amplitude=0.1)))
    return model, fm.frequency_response(model, (0.8, 1.6), 5)


def test_stability_method_names_are_deprecated_spellings_of_the_objects(duffing_branch):
    model, b = duffing_branch
    sol = b[len(b) // 2]
    new = fm.stability(sol, fm.stability_methods.Hill())
    with pytest.warns(DeprecationWarning, match=r"method='hill' is deprecated; pass method=femodes.stability_methods.Hill\(\)"):
        old = fm.stability(sol, "hill")
    assert old.method == new.method == "hill"
    np.testing.assert_array_equal(old.multipliers, new.multipliers)
    with pytest.warns(DeprecationWarning, match=r"stability='hill' is deprecated"):
        a = fm.frequency_response(model, (0.8, 1.6), 5, stability="hill")
    c = fm.frequency_response(model, (0.8, 1.6), 5, stability=fm.stability_methods.Hill())
    np.testing.assert_array_equal(a.stable, c.stable)
    assert [x.kind for x in a.bifurcations] == [x.kind for x in c.bifurcations]
    assert fm.StabilityOptions().method == fm.stability_methods.Auto()


def test_a_strategy_class_without_parentheses_is_refused_with_the_fix(duffing_branch):
    _, b = duffing_branch
    with pytest.raises(ValueError, match=r"femodes.stability_methods.Hill\(\) \(with the parentheses\)"):
        fm.stability(b[0], fm.stability_methods.Hill)
    with pytest.raises(ValueError, match=r"femodes.error_methods.Levels\(\) \(with the parentheses\)"):
        fm.estimate_error(b, method=fm.error_methods.Levels)


def test_a_user_strategy_is_called_at_every_point(duffing_branch):
    """Any callable with a ``name`` is a stability strategy: here one that counts its calls and
    delegates to Hill's method."""
    model, _ = duffing_branch

    class Counting:
        name = "counting"

        def __init__(self):
            self.calls = 0

        def __call__(self, orbit, tol):
            self.calls += 1
            return fm.stability_methods.Hill()(orbit, tol)

    counting = Counting()
    b = fm.frequency_response(model, (0.8, 1.6), 5, stability=fm.StabilityOptions(method=counting, locate=False))
    assert counting.calls == len(b)
    assert set(b.stability_method) == {"hill"}


def test_error_method_names_are_deprecated_spellings_of_the_objects(duffing_branch):
    _, b = duffing_branch
    new = fm.estimate_error(b, method=fm.error_methods.Levels()).accuracy.omega.copy()
    with pytest.warns(DeprecationWarning, match=r"method='levels' is deprecated; pass method=femodes.error_methods.Levels\(\)"):
        old = fm.estimate_error(b, method="levels").accuracy.omega
    np.testing.assert_array_equal(old, new)
    with pytest.raises(ValueError, match="method must be an error method"):
        fm.estimate_error(b, method="exact")


def test_the_shooting_error_method_says_before_any_work_what_it_cannot_take():
    penalty = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
               .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
               .with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=10.0)))
    with pytest.raises(ValueError, match="cannot take this model: the model has penalty contacts"):
        fm.error_methods.Shooting().check(penalty, fm.Harmonics(5), None)
    fm.error_methods.Levels().check(penalty, fm.Harmonics(5), None)
    fm.error_methods.Auto().check(penalty, fm.Harmonics(5), None)


def test_a_deprecated_name_warns_at_the_callers_line(duffing_branch):
    """The deprecation points at the user's line, not at femodes' decorators or a dataclass's
    generated __init__."""
    _, b = duffing_branch
    for call in (lambda: fm.stability(b[0], "hill"), lambda: fm.estimate_error(b, method="levels"),
                 lambda: fm.StabilityOptions(method="hill")):
        with pytest.warns(DeprecationWarning, match="is deprecated; pass") as rec:
            call()
        assert rec[0].filename == __file__
