"""With ``rtol``, what a user reads first is the answer that meets it, with its error bar (issue 39,
item 4): ``branch.omega``, ``branch[i].omega``, the folds, the plot, the summary and the saved file
give the converged frequency; the truncated harmonic balance stays under ``omega_truncated``, and
everything that treats ``(Q, P, omega)`` as a harmonic-balance solution (stability, a new error
estimate, the syntheses of a solution) uses that one.

The case: seed case 1 (``u'' + 0.1 u' + u = 0.2 cos(w t) - p``, stop at 1) at H = 20 with
``rtol=1e-3``: the truncated upper fold is 1.384978 (2.4 % low), the event-driven reference
1.419158 (``tests/impact_reference.py``, independent of femodes); the exact orbits by shooting give
it to the stated half-width 1e-9.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import femodes as fm
from femodes.app.cases.reporting import summary_lines
from femodes.store import read_record, write_record

from .impact_reference import upper_fold

REF = upper_fold(0.1, 0.2, 1.0).w  # 1.4191583...
H20_FOLD = 1.3849781  # the truncated series' upper fold (README, test_hbm)


def _oscillator():
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
            .with_contact(fm.UnilateralContact(at=0, gap=1.0))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


@pytest.fixture(scope="module")
def plain():
    return fm.frequency_response(_oscillator(), (0.5, 2.0), 20)


@pytest.fixture(scope="module")
def controlled():
    return fm.frequency_response(_oscillator(), (0.5, 2.0), 20, rtol=1e-3)


def _upper(b):
    return max(b.folds, key=lambda i: b.omega_truncated[i])


def test_branch_omega_is_the_converged_answer_with_its_error_bar(controlled, plain):
    b = controlled
    up = _upper(b)
    assert b.accuracy.method[up] == "shooting" and b.accuracy.met[up]
    # the answer, within its stated error bar (1e-9 half-width; the reference is exact to ~1e-12)
    assert abs(b.omega[up] / REF - 1.0) <= b.omega_error[up] <= 1e-3
    # the truncated series where a name says so: the plain branch's own fold, 2.4 % low
    assert b.omega_truncated[up] == pytest.approx(H20_FOLD, abs=1e-6)
    np.testing.assert_array_equal(b.omega_truncated, plain.omega)
    assert plain.omega_error is None and plain.amplitude_error is None
    np.testing.assert_array_equal(plain.omega, plain.omega_truncated)
    # the amplitude too: shooting found the exact fold orbit, whose max |u| is the event-driven
    # reference's to its error bar (measured 5.5e-8 against a bar of 1.9e-5, the sampling bound);
    # the truncated series' amplitude is 4 % high (b.amplitude(0, Q=b.Q))
    ref = upper_fold(0.1, 0.2, 1.0).max_abs_u
    assert abs(b.amplitude(0)[up] / ref - 1.0) <= b.amplitude_error[up] <= 1e-4
    assert b.amplitude(0, b.Q)[up] / ref - 1.0 > 0.03
    np.testing.assert_array_equal(b.amplitude(0, b.Q), plain.amplitude(0))
    # error_estimate: the larger of the two bars, both within rtol where shooting answered
    np.testing.assert_array_equal(b.error_estimate, np.fmax(b.omega_error, b.amplitude_error))
    assert b.accuracy.converged_amplitude[up]
    assert np.all(b.omega_error[b.accuracy.met] <= 1e-3)
    assert np.all(b.error_estimate[b.accuracy.converged_amplitude] <= 1e-3)


def test_a_point_reads_the_answer_and_synthesises_the_series(controlled, plain):
    b = controlled
    up = _upper(b)
    sol, ref = b[up], plain[up]
    assert sol.omega == b.omega[up] and sol.omega_truncated == b.omega_truncated[up]
    assert sol.omega_error == b.omega_error[up] and sol.amplitude_error == b.amplitude_error[up]
    # (the series on its own grid against the branch's: both sample the same maximum, 1e-6 apart at most)
    assert sol.amplitude(0) == b.amplitude(0)[up] and ref.amplitude(0) == pytest.approx(plain.amplitude(0)[up], rel=1e-6)
    # the Fourier series is the truncated one, at its own frequency and period
    assert sol.period == pytest.approx(2 * math.pi / b.omega_truncated[up], rel=4 * np.finfo(float).eps)
    t = np.linspace(0.0, sol.period, 7)
    np.testing.assert_array_equal(sol.displacement(t), ref.displacement(t))
    np.testing.assert_array_equal(sol.contact_force(t), ref.contact_force(t))
    # dataclasses.replace gives a plain series at the frequency it is given (no stale correction)
    moved = dataclasses.replace(sol, omega=1.3)
    assert moved.omega_truncated == 1.3 and moved.omega_error is None


def test_stability_and_a_new_estimate_use_the_truncated_series(controlled, plain):
    """Floquet multipliers of an error-controlled point are those of the same series (identical
    arithmetic); estimating again gives the same converged frequencies (the estimate starts from
    the series, not from the answer it produced)."""
    up = _upper(controlled)
    i = up - 3  # on the upper branch, in contact
    st_c, st_p = fm.stability(controlled[i]), fm.stability(plain[i])
    np.testing.assert_array_equal(st_c.multipliers, st_p.multipliers)
    again = fm.estimate_error(fm.frequency_response(_oscillator(), (0.5, 2.0), 20, rtol=1e-3), rtol=1e-3)
    np.testing.assert_allclose(again.omega, controlled.omega, rtol=0, atol=1e-9 * REF)


def test_saved_file_holds_the_answer_and_the_series(controlled, tmp_path):
    path = controlled.save(tmp_path / "frc.npz")
    header, arrays = read_record(path)
    np.testing.assert_array_equal(arrays["omega"], controlled.omega)
    np.testing.assert_array_equal(arrays["omega_truncated"], controlled.omega_truncated)
    back = fm.load_branch(path)
    np.testing.assert_array_equal(back.omega, controlled.omega)
    np.testing.assert_array_equal(back.omega_truncated, controlled.omega_truncated)
    np.testing.assert_array_equal(back.omega_error, controlled.omega_error)
    np.testing.assert_array_equal(back.amplitude(0), controlled.amplitude(0))
    np.testing.assert_array_equal(back.amplitude_error, controlled.amplitude_error)
    # a file of an older femodes has no omega_truncated: its "omega" was the series' frequency
    del arrays["omega_truncated"]
    old = write_record(tmp_path / "old.npz", header, {**arrays, "omega": controlled.omega_truncated})
    np.testing.assert_array_equal(fm.load_branch(old).omega_truncated, controlled.omega_truncated)
    np.testing.assert_array_equal(fm.load_branch(old).omega, controlled.omega)


def test_plot_and_summary_show_the_answer(controlled):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.container import ErrorbarContainer

    ax = fm.plot.frequency_amplitude(controlled, 0)
    np.testing.assert_array_equal(ax.lines[0].get_xdata(), controlled.omega)
    np.testing.assert_array_equal(ax.lines[0].get_ydata(), controlled.amplitude(0))
    assert any(isinstance(c, ErrorbarContainer) for c in ax.containers)
    plt.close(ax.figure)
    case = type("Case", (), {"name": "seed1"})()
    lines = summary_lines(case, _oscillator(), controlled)
    folds = next(line for line in lines if line.startswith("folds at w = "))
    assert f"{controlled.omega[_upper(controlled)]:.6g}" in folds and "+-" in folds
    assert any("truncated series" in line and f"{H20_FOLD:.6g}" in line for line in lines)
    assert any("amplitude largest" in line and "exact orbits at" in line for line in lines)


def test_bifurcations_are_reported_at_the_converged_frequency(tmp_path):
    """With stability and rtol: the folds' Bifurcation objects read the converged frequency, as
    branch.omega does (their series, and omega_truncated, stay the truncated ones); one between
    two points is moved by the correction interpolated between them; the file keeps the series'
    frequency and the loaded branch reports the same converged one."""
    b = fm.frequency_response(_oscillator(), (0.5, 2.0), 10, rtol=1e-3, stability=True)  # H = 10: cheaper, as exact
    folds = [x for x in b.bifurcations if x.kind == "fold"]
    assert sorted(x.index for x in folds) == sorted(b.folds)
    for x in folds:
        assert x.omega == b.omega[x.index] and x.omega_truncated == b.omega_truncated[x.index]
        np.testing.assert_array_equal(x.Q, b.Q[x.index])
    up = _upper(b)
    assert abs(next(x for x in folds if x.index == up).omega / REF - 1.0) <= 1e-6
    # a bifurcation between two points (put in by hand: this branch has none), halfway in the series
    i = up - 3
    mid = 0.5 * (b.omega_truncated[i] + b.omega_truncated[i + 1])
    pd = fm.Bifurcation(kind="period_doubling", index=i, omega=mid, energy=1.0, parameter=mid, multiplier=-1.0,
                        Q=b.Q[i], P=b.P[i], bracket=(b.omega_truncated[i], b.omega_truncated[i + 1]))
    b = b.with_stability(stable=b.stable, multipliers=b.multipliers, bifurcations=list(b.bifurcations) + [pd],
                         methods=b.stability_method, tol=b.meta["stability_tol"])
    moved = next(x for x in b.bifurcations if x.kind == "period_doubling" and x.omega_truncated == mid)
    c = b.omega - b.omega_truncated
    assert moved.omega == pytest.approx(mid + 0.5 * (c[i] + c[i + 1]), rel=4 * np.finfo(float).eps)
    assert moved.omega_truncated == mid and moved.series().omega == mid
    shift = moved.omega - mid  # the bracket moves with it, and back
    np.testing.assert_allclose(moved.bracket, np.array([b.omega_truncated[i], b.omega_truncated[i + 1]]) + shift,
                               rtol=4 * np.finfo(float).eps)
    np.testing.assert_allclose(moved.series().bracket, [b.omega_truncated[i], b.omega_truncated[i + 1]],
                               rtol=4 * np.finfo(float).eps)
    back = fm.load_branch(b.save(tmp_path / "b.npz"))
    assert [x.omega for x in back.bifurcations] == [x.omega for x in b.bifurcations]
    assert [x.omega_truncated for x in back.bifurcations] == [x.omega_truncated for x in b.bifurcations]
    np.testing.assert_array_equal([x.bracket for x in back.bifurcations], [x.bracket for x in b.bifurcations])
