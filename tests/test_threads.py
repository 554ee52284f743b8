"""BLAS threads inside femodes' hot loops (femodes.solvers.threads, issue 16 item 3): the count
threadpoolctl reports inside a loop is the chosen one (FEMODES_BLAS_THREADS, default 1), bad
values are refused with the variable's name, and the libraries' setting comes back afterwards,
also after an exception and after nested limits."""

from __future__ import annotations

import threading

import numpy as np
import pytest

threadpoolctl = pytest.importorskip("threadpoolctl")

import femodes as fm  # noqa: E402
from femodes.solvers import threads as th  # noqa: E402
from femodes.solvers import ContinuationOptions, NewtonOptions  # noqa: E402


def blas_counts() -> list[int]:
    """Thread counts of the BLAS libraries, as threadpoolctl reports them (not via femodes)."""
    return [d["num_threads"] for d in threadpoolctl.threadpool_info() if d["user_api"] == "blas"]


@pytest.fixture
def outside(monkeypatch):
    """Two threads outside femodes (what OpenBLAS does by default on the 2-core machine), so that
    a limit of 1 is visible; the environment variable unset."""
    monkeypatch.delenv(th.ENV_VAR, raising=False)
    if not blas_counts():
        pytest.skip("no BLAS library found by threadpoolctl")
    with threadpoolctl.threadpool_limits(2, user_api="blas"):
        yield blas_counts()


def contact_oscillator():
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
            .with_contact(fm.UnilateralContact(at=0, gap=1.0))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


def response(record: list, **kw):
    """A short forced response whose callback records the BLAS threads at every point."""
    opts = ContinuationOptions(step=0.05, max_step=0.5, max_points=8, callback=lambda p: record.append(blas_counts()),
                               newton=NewtonOptions(atol=1e-9, max_iter=20))
    return fm.frequency_response(contact_oscillator(), omega=(0.5, 2.0), harmonics=5, options=opts, **kw)


def test_frequency_response_runs_on_one_thread_by_default(outside):
    seen: list = []
    branch = response(seen)
    assert len(branch) == 8 and seen
    assert all(c == [1] * len(outside) for c in seen), seen
    assert blas_counts() == outside  # restored


@pytest.mark.parametrize("value, expected", [("2", 2), (" 3 ", 3)])
def test_environment_variable_chooses_the_count(outside, monkeypatch, value, expected):
    monkeypatch.setenv(th.ENV_VAR, value)
    seen: list = []
    response(seen)
    assert all(c == [expected] * len(outside) for c in seen), seen
    assert blas_counts() == outside


def test_off_leaves_the_libraries_alone(outside, monkeypatch):
    monkeypatch.setenv(th.ENV_VAR, "OFF")
    seen: list = []
    response(seen)
    assert all(c == outside for c in seen), seen


@pytest.mark.parametrize("value", ["0", "-1", "two", "1.5"])
def test_invalid_value_names_the_variable(outside, monkeypatch, value):
    monkeypatch.setenv(th.ENV_VAR, value)
    with pytest.raises(ValueError, match="FEMODES_BLAS_THREADS must be a positive integer") as err:
        response([])
    assert repr(value) in str(err.value)
    assert blas_counts() == outside


def test_nonlinear_mode_is_limited(outside):
    free = contact_oscillator().without_forcing().with_damping()
    seen: list = []
    opts = ContinuationOptions(max_points=4, callback=lambda p: seen.append(blas_counts()))
    fm.nonlinear_mode(free, mode=1, energy=(0.1, 20.0), harmonics=5, options=opts)
    assert seen and all(c == [1] * len(outside) for c in seen)
    assert blas_counts() == outside


def test_static_contact_is_limited(outside, monkeypatch):
    inside: list = []
    residual = fm.UnilateralContact.residual

    def spy(self, *a, **k):  # the contact law, evaluated inside static_contact's Newton loop
        inside.append(blas_counts())
        return residual(self, *a, **k)

    monkeypatch.setattr(fm.UnilateralContact, "residual", spy)
    model = contact_oscillator()
    res = fm.static_contact(model, force=np.array([2.0]))
    assert res.success and inside and all(c == [1] * len(outside) for c in inside)
    assert blas_counts() == outside


def test_simulate_is_limited(outside, monkeypatch):
    from femodes.time import drivers, stepper

    inside: list = []
    integrate = stepper.integrate

    def spy(*a, **k):
        inside.append(blas_counts())
        return integrate(*a, **k)

    monkeypatch.setattr(drivers, "integrate", spy)
    hist = fm.simulate(contact_oscillator(), t_end=1.0, dt=0.1, omega=1.0)
    assert hist.success and inside == [[1] * len(outside)]
    assert blas_counts() == outside


def test_limit_restored_after_an_exception(outside):
    def boom(point):
        assert blas_counts() == [1] * len(outside)
        raise KeyboardInterrupt  # what a user's Ctrl-C in a long run does

    opts = ContinuationOptions(max_points=8, callback=boom)
    with pytest.raises(KeyboardInterrupt):
        fm.frequency_response(contact_oscillator(), omega=(0.5, 2.0), harmonics=5, options=opts)
    assert blas_counts() == outside


def test_nested_limits_restore_the_enclosing_one(outside):
    with th.limit_blas_threads():
        assert blas_counts() == [1] * len(outside)
        with th.limit_blas_threads(2):
            assert blas_counts() == [2] * len(outside)
            with th.limit_blas_threads(1):  # e.g. an analysis called inside another
                assert blas_counts() == [1] * len(outside)
            assert blas_counts() == [2] * len(outside)
        assert blas_counts() == [1] * len(outside)
    assert blas_counts() == outside


def test_limits_held_by_two_python_threads(outside):
    """The limit is process-wide: one thread leaving must not lift it under another still inside."""
    entered, leave_first, first_left = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def first():
        with th.limit_blas_threads():
            entered.set()
            leave_first.wait(10)
        first_left.set()

    t = threading.Thread(target=first)
    t.start()
    entered.wait(10)
    with th.limit_blas_threads():
        leave_first.set()
        first_left.wait(10)
        seen["inside"] = blas_counts()
    t.join()
    assert seen["inside"] == [1] * len(outside)
    assert blas_counts() == outside


def test_decorator_reads_the_variable_at_each_call(outside, monkeypatch):
    @th.limit_blas_threads()
    def counts():
        return blas_counts()

    assert counts() == [1] * len(outside)
    monkeypatch.setenv(th.ENV_VAR, "2")
    assert counts() == [2] * len(outside)
    assert counts.__name__ == "counts"


def test_bad_argument_and_parsing():
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        with th.limit_blas_threads(0):
            pass
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        with th.limit_blas_threads(True):
            pass


def test_a_limit_in_place_costs_microseconds(outside):
    import time

    with th.limit_blas_threads():
        t0 = time.perf_counter()
        for _ in range(200):
            with th.limit_blas_threads():
                pass
        per_call = (time.perf_counter() - t0) / 200
    assert per_call < 1e-3, per_call  # ~10 us measured; one continuation point costs ms


def test_results_do_not_depend_on_the_count(outside, monkeypatch):
    a = response([])
    monkeypatch.setenv(th.ENV_VAR, "2")
    b = response([])
    np.testing.assert_allclose(a.omega, b.omega, rtol=1e-10)


def test_without_threadpoolctl_the_analysis_runs_unlimited(outside, monkeypatch, caplog):
    import sys

    monkeypatch.setitem(sys.modules, "threadpoolctl", None)  # import threadpoolctl -> ImportError
    monkeypatch.setattr(th, "_controller", None)
    monkeypatch.setattr(th, "_warned", False)
    with caplog.at_level("WARNING", logger=th.__name__):
        branch = response([])
    assert len(branch) == 8 and "threadpoolctl is not installed" in caplog.text
