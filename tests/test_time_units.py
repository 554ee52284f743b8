"""Units of the time integration (femodes.time) and of the solver options it relies on.

* the small-array reductions of ``semismooth_newton`` (the same floats as numpy's);
* the options added for the time stepper (``rtol_x``, ``accept_factor``), defaults unchanged;
* ``success``/``status``/``message`` of ``TimeHistory`` and ``SteadyState`` (forced failures);
* ``contact_force(t)`` of both results (the average force over the step containing ``t``).
"""

import math

import numpy as np
import pytest

import femodes as fm
from femodes.solvers import NewtonOptions, semismooth_newton
from femodes.solvers.newton_linalg import all_finite as _finite, max_abs as _inf
from femodes.time import moreau
from femodes.time.impact import fischer_burmeister, solve_lcp
from femodes.time.stepper import LOCAL_NEWTON

T_IMPACT = 2 * np.pi / 1.5


def oscillator(**kw):
    return fm.StructuralModel(M=[[1.0]], K=[[1.0]], **kw)


def impacting():
    return oscillator().with_contact(fm.UnilateralContact(at=0, gap=1.0))


def duffing():
    return oscillator().with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))


def two_stops():
    return (fm.StructuralModel(M=np.eye(2), K=[[2.0, -1.0], [-1.0, 2.0]])
            .with_contact(fm.UnilateralContact(at=0, gap=0.2)).with_contact(fm.UnilateralContact(at=1, gap=0.2)))


# ------------------------------------------------------------------ the solver's small-array norms
@pytest.mark.parametrize("n", [1, 2, 5, 16, 17, 40])
def test_small_array_reductions_equal_numpy(n):
    """The inf-norm and finiteness test of the solver reduce small arrays in Python floats (a numpy
    reduction costs ~2 us, several per iteration of thousands of tiny local solves): they must give
    numpy's values exactly, nan propagation and signed zeros included."""
    rng = np.random.default_rng(n)
    cases = [rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n), np.full(n, -0.0), np.zeros(n)]
    for bad in (np.nan, np.inf, -np.inf):
        for k in {0, n // 2, n - 1}:
            v = rng.standard_normal(n)
            v[k] = bad
            cases.append(v)
    v = rng.standard_normal(n)
    v[0], v[-1] = np.inf, -np.inf  # inf - inf = nan in a sum: must still give inf
    cases.append(v)
    for v in cases:
        ref = float(np.max(np.abs(v)))
        got = _inf(v)
        assert (math.isnan(ref) and math.isnan(got)) or got == ref, (v, got, ref)
        assert _finite(v) == bool(np.all(np.isfinite(v)))
        assert _finite(v.reshape(1, -1)) == bool(np.all(np.isfinite(v)))
    assert _inf(np.zeros(0)) == 0.0


def _lcp_fun(seed, n=4):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    W = A @ A.T + 0.1 * np.eye(n)
    q = rng.standard_normal(n)
    d = np.diag(W)

    def fun(x):
        r, da, db = fischer_burmeister(x, (W @ x + q) / d)
        return r, np.diag(da) + (db / d)[:, None] * W

    return fun, np.zeros(n)


# ------------------------------------------------------------- options added for the time stepper
def test_new_options_default_off_and_validated():
    o = NewtonOptions()
    assert o.rtol_x == 0.0 and o.accept_factor == 0.0
    for name in ("rtol_x", "accept_factor"):
        for bad in (-1.0, math.nan, math.inf, "a"):
            with pytest.raises(ValueError, match=name):
                NewtonOptions(**{name: bad})


def test_rtol_x_is_relative_to_the_iterate():
    # a residual floor of 5e-8 (no root): converged where 5e-8 <= rtol_x |x|, not elsewhere
    fun = lambda x: (np.full(1, 5e-8), np.eye(1))  # noqa: E731
    opts = NewtonOptions(atol=1e-30, rtol=0.0, rtol_x=1e-13, max_iter=3)
    big = semismooth_newton(fun, np.array([1e6]), options=opts)
    assert big.success and big.nit == 0 and big.message.startswith("converged")
    assert not semismooth_newton(fun, np.array([1.0]), options=opts).success
    assert not semismooth_newton(fun, np.array([1e6]), options=NewtonOptions(atol=1e-30, rtol=0.0, max_iter=3)).success


def test_accept_factor_turns_a_round_off_stall_into_success():
    # r(x) = x^2 + eps: no root, minimum eps at 0 -> stalls at a residual ~1e-12
    fun = lambda x: (x**2 + 1e-12, np.diag(2 * x + 1e-300))  # noqa: E731
    base = dict(atol=1e-14, rtol=0.0, max_iter=60)
    fail = semismooth_newton(fun, np.array([1.0]), options=NewtonOptions(**base))
    assert not fail.success and fail.status in (1, 2)
    ok = semismooth_newton(fun, np.array([1.0]), options=NewtonOptions(accept_factor=1e3, **base))
    assert ok.success and ok.status == 0 and ok.message.startswith("converged (accepted)")
    assert fail.message in ok.message  # says why the iteration stopped
    np.testing.assert_array_equal(ok.x, fail.x)
    tight = semismooth_newton(fun, np.array([1.0]), options=NewtonOptions(accept_factor=10.0, **base))
    assert not tight.success  # 1e-12 > 10 * 1e-14


def test_solve_lcp_is_scale_free():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((4, 4))
    W = A @ A.T + 0.1 * np.eye(4)
    q = rng.standard_normal(4)
    x1, r1 = solve_lcp(W, q, np.zeros(4), LOCAL_NEWTON)
    x2, r2 = solve_lcp(W, 1e6 * q, np.zeros(4), LOCAL_NEWTON)
    assert r1.success and r2.success
    np.testing.assert_allclose(x2, 1e6 * x1, rtol=1e-10, atol=1e-6)
    w = W @ x1 + q
    assert np.all(x1 >= 0) and np.all(w >= -1e-12) and abs(x1 @ w) < 1e-12


# ---------------------------------------------------------------------- status of time results
def test_time_history_reports_success():
    th = fm.simulate(duffing(), 5.0, 0.01, u0=[1.0])
    assert th.success and th.status == 0 and "every local problem solved" in th.message


def test_forced_local_failure_is_reported_not_raised(caplog):
    opts = NewtonOptions(max_iter=1, atol=1e-15, rtol=0.0)
    with caplog.at_level("WARNING", logger="femodes.time"):
        th = fm.simulate(duffing(), 5.0, 0.01, u0=[1.0], options=fm.TimeSteppingOptions(newton=opts))
    assert not th.success and th.status == 1
    assert "t = 0:" in th.message and "max_iter=1" in th.message and "of 500 steps" in th.message
    assert th.t.size == 501 and np.all(np.isfinite(th.u))  # the run went on and returned what it computed
    assert any("not solved" in r.getMessage() for r in caplog.records)
    # the same run with the default options agrees to the accuracy of one Newton step per time step
    ref = fm.simulate(duffing(), 5.0, 0.01, u0=[1.0])
    assert np.max(np.abs(th.u - ref.u)) < 1e-6


def test_forced_failure_of_the_complementarity_problem():
    ok = fm.simulate(two_stops(), 10.0, 0.01, v0=[1.0, 1.0])
    assert ok.success
    bad = fm.simulate(two_stops(), 10.0, 0.01, v0=[1.0, 1.0],
                      options=fm.TimeSteppingOptions(newton=NewtonOptions(max_iter=1, atol=1e-15, rtol=0)))
    assert not bad.success and bad.status == 1 and "not solved" in bad.message


def test_steady_state_statuses():
    model = oscillator(C=[[0.1]]).with_forcing(fm.HarmonicForce(at=0, amplitude=1.0))
    ss = fm.steady_state(model, 0.8, dt=0.05)
    assert ss.success and ss.status == 0 and ss.converged and ss.nit == ss.n_periods
    assert f"after {ss.n_periods} periods" in ss.message
    short = fm.steady_state(model, 0.8, dt=0.05, options=fm.TimeSteppingOptions(n_periods_max=3, tol=1e-14))
    assert not short.success and short.status == 2 and not short.converged
    assert "n_periods_max=3" in short.message and short.nit == 3
    stiff = oscillator(C=[[0.1]]).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0)).with_forcing(
        fm.HarmonicForce(at=0, amplitude=1.0))
    failed = fm.steady_state(stiff, 0.8, dt=0.05,
                             options=fm.TimeSteppingOptions(n_periods_max=3, newton=NewtonOptions(max_iter=1, atol=1e-15, rtol=0.0)))
    assert not failed.success and failed.status == 1  # local failures take precedence ...
    assert "(period 1)" in failed.message and "n_periods_max=3" in failed.message  # ... both are said


def test_newton_argument_is_checked():
    with pytest.raises(TypeError, match="newton"):
        fm.simulate(duffing(), 1.0, 0.1, options=fm.TimeSteppingOptions(newton={"max_iter": 3}))
    with pytest.raises(TypeError, match="newton"):
        fm.steady_state(duffing().with_forcing(fm.HarmonicForce(at=0, amplitude=1.0)), 1.0, dt=0.1,
                        options=fm.TimeSteppingOptions(newton=3))


# -------------------------------------------------------------------------------- contact_force
def test_contact_force_is_the_step_average():
    dt = 1e-3
    th = fm.simulate(impacting(), 2 * T_IMPACT, dt, v0=[2.0])
    hits = np.flatnonzero(th.impulse[:, 0] > 0)
    assert hits.size == 2
    i = hits[0]
    inside = th.t[i - 1] + np.array([1e-9, 0.5, 1.0]) * th.dt  # (t_{i-1}, t_i]
    np.testing.assert_allclose(th.contact_force(inside)[:, 0], th.impulse[i, 0] / th.dt, rtol=1e-12)
    assert th.contact_force(th.t[i - 1])[0, 0] == 0.0  # t_{i-1} belongs to the step before
    assert th.contact_force(th.t[0]).shape == (1, 1) and th.contact_force(th.t[0])[0, 0] == 0.0
    # integrating the piecewise constant force over the run gives the total impulse
    mid = 0.5 * (th.t[1:] + th.t[:-1])
    assert np.sum(th.contact_force(mid)[:, 0] * np.diff(th.t)) == pytest.approx(th.impulse.sum(), rel=1e-12)
    np.testing.assert_array_equal(th.contact_force(th.t[1:]), th.mean_contact_force[1:])
    assert np.all(th.mean_contact_force[0] == 0)
    for bad in (-1e-3, th.t[-1] + 1e-3, np.nan):
        with pytest.raises(ValueError, match="t"):
            th.contact_force([0.1, bad])


def test_contact_force_with_store_every_averages_over_the_stored_interval():
    th1 = fm.simulate(impacting(), T_IMPACT, 1e-3, v0=[2.0])
    th5 = fm.simulate(impacting(), T_IMPACT, 1e-3, v0=[2.0], options=fm.TimeSteppingOptions(store_every=5))
    t = np.linspace(0.0, th5.t[-1], 777)
    k = np.clip(np.searchsorted(th5.t, t), 1, th5.t.size - 1)
    assert th5.impulse.sum() == pytest.approx(th1.impulse.sum(), rel=1e-12)
    np.testing.assert_allclose(th5.contact_force(t)[:, 0], th5.impulse[k, 0] / (th5.t[k] - th5.t[k - 1]))


def test_steady_state_contact_force_is_periodic():
    model = oscillator(C=[[0.1]]).with_contact(fm.UnilateralContact(at=0, gap=1.0)).with_forcing(
        fm.HarmonicForce(at=0, amplitude=0.2))
    ss = fm.steady_state(model, 1.0, dt=1e-2,
                         options=fm.TimeSteppingOptions(n_periods_max=30))  # impacting: the last period, converged or not
    assert ss.impulse.sum() > 0
    t = np.linspace(0.0, ss.period, 501)
    np.testing.assert_array_equal(ss.contact_force(t + 3 * ss.period), ss.contact_force(t))
    np.testing.assert_array_equal(ss.contact_force(0.0), ss.contact_force(ss.period))
    np.testing.assert_array_equal(ss.contact_force(ss.t[1:]), ss.mean_contact_force[1:])
    assert ss.contact_force(t).shape == (t.size, 1)


# --------------------------------------------------------------------------------------- layout
def test_public_names_from_moreau_and_time():
    for name in ("TimeHistory", "SteadyState", "simulate", "steady_state"):
        assert getattr(moreau, name) is getattr(fm.time, name) is getattr(fm, name)


def test_open_penalty_contacts_need_no_local_solve():
    """A step that leaves every penalty contact open is the free step: bit for bit the motion of
    the model without the contact."""
    free = fm.simulate(oscillator(), 10.0, 0.01, u0=[0.5])
    pen = fm.simulate(oscillator().with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=1e3)), 10.0, 0.01,
                      u0=[0.5])
    np.testing.assert_array_equal(pen.u, free.u)
    assert pen.success and np.all(pen.impulse == 0)
