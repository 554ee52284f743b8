"""Nonsmooth modes of a continuous structure (issue 35): the clamped bar whose tip hits a stop.

Reference: the continuum's first nonsmooth mode from d'Alembert's solution with the Signorini end
(``tests/bar_stop_reference.py``: ``w / w1 = 4 / (3 + 2 sqrt(2) / (pi sqrt(E / E_g)))``),
confirmed by a CFL-1 finite-difference integration of the wave equation that shares no code with
it nor with femodes (``tests/bar_stop_fd_check.py``).
"""

import contextlib
import json
import logging
import math
import re

import numpy as np
import scipy.linalg
import pytest

import femodes as fm

from .bar_stop_fd_check import fd_period_and_return_error
from .bar_stop_reference import REFERENCE, first_nonsmooth_mode, period
from .test_examples import BENCHMARKS, load

GAP = 0.01
W1 = math.pi / 2


@contextlib.contextmanager
def caplog_warning():
    """The warnings femodes logs inside the block."""
    records = []

    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record)

    handler, logger = Keep(level=logging.WARNING), logging.getLogger("femodes")
    logger.addHandler(handler)
    try:
        yield records
    finally:
        logger.removeHandler(handler)


def bar(n_elements=20, beta=None, force=None):
    mesh = fm.line_mesh(length=1.0, n_elements=n_elements, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    model = model.with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    if beta is not None:
        model = model.with_damping(beta=beta)
    if force is not None:
        model = model.with_forcing(fm.HarmonicForce(at="tip", amplitude=force))
    return model


@pytest.fixture(scope="module")
def model():
    return bar(20)


@pytest.fixture(scope="module")
def backbone(model):
    eg = fm.grazing_energy(model)
    return fm.nonlinear_mode(model, mode=1, energy=(0.5 * eg, 25 * eg), harmonics=10)


def test_reference_formula_against_its_finite_difference_check():
    """The closed-form period against the leapfrog's at 400 cells: the scheme releases the tip one
    step late, a first-order error in h = 1/400 (measured 7.3e-4 at E = 2 E_g, 4.7e-4 at 5 E_g);
    2.5e-3 = 1/400 is the step itself."""
    for rho in (2, 5):
        fd = fd_period_and_return_error(rho, 400, n_periods=2)
        assert fd["period"] / period(rho) - 1 == pytest.approx(0.0, abs=1.0 / 400)
        assert REFERENCE[rho]["omega"] == pytest.approx(first_nonsmooth_mode(rho)[0], rel=1e-12)


def test_grazing_energy_of_the_bar():
    """pi^2 g^2 / 16 for the continuum; the P1 mesh's mode 1 is 1e-3 stiff at 20 elements and its
    mass-normalised tip amplitude 1e-3 off: 1 % covers both."""
    assert fm.grazing_energy(bar(20)) == pytest.approx(math.pi ** 2 * GAP ** 2 / 16, rel=1e-2)
    with pytest.raises(ValueError, match="no contact with a positive gap"):
        fm.grazing_energy(fm.StructuralModel(M=[[1.0]], K=[[1.0]]))


def test_backbone_is_the_contact_phase_family(model, backbone):
    """Past grazing the default backbone follows the motions with a contact phase (their frequency
    rises with energy), not the grazing family at w1 that a continuation in the energy climbs.
    Every point from 1.5 to 25 E_g within 1 % of the continuum's mode (20 P1 elements, H = 10:
    the truncation of the velocity jump at contact and the mesh; 0.7 % measured, largest just
    above grazing where the contact phase is shortest)."""
    eg = fm.grazing_energy(model)
    assert backbone.meta["family"] == "contact phase" and backbone.success
    assert "grazed" in backbone.meta["energy_continuation"]
    past = backbone.energy >= 1.5 * eg
    assert past.sum() >= 10 and backbone.energy.max() >= 25 * eg
    ref = first_nonsmooth_mode(backbone.energy[past] / eg)[0]
    err = backbone.omega[past] / ref - 1
    assert np.max(np.abs(err)) < 1e-2, err
    # the tongues stepped over are listed, with the modes that take the energy there
    assert backbone.internal_resonances
    assert all(t["modes"] and all(k != 1 for k in t["modes"]) for t in backbone.internal_resonances
               if np.isfinite(t["energy"][0]))


def test_energy_continuation_alone_grazes(model):
    """past_grazing=None keeps the energy continuation's branch: the grazing family, at w1 within
    1e-2 at every energy (issue 35 measured 1.4e-3), frequency far below the forced peak; the
    branch says so (meta and a logged warning)."""
    eg = fm.grazing_energy(model)
    with caplog_warning() as records:
        grazing = fm.nonlinear_mode(model, mode=1, energy=(0.5 * eg, 25 * eg), harmonics=10, past_grazing=None)
    assert "family" not in grazing.meta and "grazed" in grazing.meta["energy_continuation"]
    assert any("does not predict the forced resonance" in r.getMessage() for r in records)
    assert np.max(np.abs(grazing.omega / W1 - 1)) < 1e-2


def test_forced_peak_lies_on_the_backbone(backbone):
    """The bar with beta = 0.02 (examples/cases/bar_stop_frc.toml's damping, 20 elements here):
    its peak is within 1 % of the backbone at the peak's energy (0.3 % measured; against 10-20 %
    for the grazing family)."""
    forced = fm.frequency_response(bar(20, beta=0.02, force=0.004), omega=(1.0, 2.3), harmonics=10)
    (peak,) = fm.compare_resonance(backbone, forced)
    assert peak.omega > 1.15 * W1  # the resonance bends right...
    assert abs(peak.distance) < 1e-2, peak  # ...onto the backbone


@pytest.mark.slow
def test_forced_peaks_approach_the_backbone_as_damping_decreases(backbone):
    """beta = 0.02, 0.01, 0.005 (force scaled with beta): peaks within 0.5 % of the backbone
    (0.28, 0.39, 0.17 % measured)."""
    forced = [fm.frequency_response(bar(20, beta=b, force=0.2 * b), omega=(1.0, 2.3), harmonics=10)
              for b in (0.02, 0.01, 0.005)]
    peaks = fm.compare_resonance(backbone, forced)
    assert all(abs(p.distance) < 5e-3 for p in peaks), peaks


def test_compare_resonance_bad_input(backbone):
    with pytest.raises(TypeError, match="backbone must be a Branch from femodes.nonlinear_mode"):
        fm.compare_resonance("x", backbone)
    with pytest.raises(TypeError, match="forced must be a Branch from femodes.frequency_response"):
        fm.compare_resonance(backbone, backbone)


def test_compare_resonance_reports_distances_when_the_modes_fail(backbone, monkeypatch, caplog):
    """The shares at the peaks need the forced model's linear modes; when they fail, the distances
    are still reported (without shares), and the log says why."""
    import femodes.resonance as res

    forced = fm.frequency_response(bar(20, beta=0.02, force=0.004), omega=(1.0, 1.6), harmonics=3)
    (ok,) = fm.compare_resonance(backbone, forced)
    assert len(ok.shares) == 12 and ok.shares[0] > 0.5 and abs(sum(ok.shares) - 1) <= 64 * np.finfo(float).eps

    def fail(*a, **k):
        raise RuntimeError("no modes")

    monkeypatch.setattr(res, "linear_modes", fail)
    (peak,) = fm.compare_resonance(backbone, forced)
    assert peak.shares == () and peak.captured_by is None and peak.distance == ok.distance
    assert "compare_resonance: no modal energy shares (linear_modes failed: no modes)" in caplog.text


def test_modal_energy_shares_analytic():
    """Two modes of a 2-DOF system, ``q(t) = a phi_1 cos(w t) + b phi_2 sin(3 w t)``: mode k's
    period-averaged energy is ``(A_k^2 / 4)(w_k^2 + (j_k w)^2)`` (its kinetic and potential parts
    averaged over the period), so the shares are known in closed form; round-off tolerance (16 eps)."""
    from femodes.resonance import modal_energy_shares

    M = np.diag([2.0, 1.0])
    K = np.array([[6.0, -2.0], [-2.0, 4.0]])
    lam, phi = scipy.linalg.eigh(K, M)
    omegas = np.sqrt(lam)
    h = fm.Harmonics(n_harmonics=3)
    w, a, b = 1.3, 0.7, 0.2
    Q = np.zeros((h.n_coef, 2))
    Q[h.layout.cos_index(1)] = a * phi[:, 0]
    Q[h.layout.sin_index(3)] = b * phi[:, 1]
    e = np.array([a**2 * (omegas[0] ** 2 + w**2), b**2 * (omegas[1] ** 2 + (3 * w) ** 2)]) / 4
    got = modal_energy_shares(h, Q, w, M, omegas, phi)
    assert np.allclose(got, e / e.sum(), rtol=0, atol=16 * np.finfo(float).eps)  # O(1) shares, a few products
    assert np.all(modal_energy_shares(h, 0 * Q, w, M, omegas, phi) == 0)


def test_period_driven_options_are_checked():
    with pytest.raises(ValueError, match="step must be a number in"):
        fm.PeriodDriven(step=0.0)
    with pytest.raises(TypeError, match="past_grazing must be a femodes.PeriodDriven or None"):
        m = bar(10)
        eg = fm.grazing_energy(m)
        fm.nonlinear_mode(m, 1, (0.5 * eg, 4 * eg), 5, past_grazing="period")


def test_guided_sweep_reaches_the_end_of_the_span():
    """With more harmonics than ``PeriodDriven.start_harmonics`` the sweep is guided by the family
    traced first with that many (issue 35). 40 elements with H = 20 used to stop at 18.9 E_g: past a
    cluster of tongues the secant through the last orbits led onto a neighbouring family with about
    twice the energy, whose orbits the lower envelope then removed. Now it reaches 25 E_g on the
    contact-phase family, mode 1 holding most of the energy. Its orbits past 1.5 E_g follow the
    continuum: their median within 0.5 % (the harmonic bias is 0.3-0.5 % at H = 10-40), each within
    2 % (an orbit beside a tongue of internal resonance is pulled by it: every orbit of the grid of
    benchmarks/README_bar_convergence.md lies within 1.5 %; where the sweep's steps fall next to
    the tongues depends on round-off, and this run's largest was 0.6 % on one machine, 1.45 % on
    another)."""
    from femodes.hbm import NonlinearModeProblem
    from femodes.nonsmooth_modes import modal_energy_fractions

    model = bar(40)
    eg = fm.grazing_energy(model)
    br = fm.nonlinear_mode(model, 1, energy=(0.5 * eg, 25 * eg), harmonics=20)
    assert br.success and br.meta["family"] == "contact phase", br.message
    assert br.energy.max() >= 25 * eg
    past = br.energy >= 1.5 * eg
    assert past.sum() >= 15
    err = br.omega[past] / first_nonsmooth_mode(br.energy[past] / eg)[0] - 1
    assert np.median(np.abs(err)) < 5e-3, err
    assert np.max(np.abs(err)) < 2e-2, err
    # the family's energy rises with its frequency: no neighbouring family on the branch
    assert np.all(np.diff(br.energy[past]) > 0)
    problem = NonlinearModeProblem(model, fm.Harmonics(n_harmonics=20), 1, reference_energy=eg)
    lm = fm.linear_modes(model, n=12)
    shares = [modal_energy_fractions(problem, problem.pack(Q, P, w, xi), lm.omega, lm.shapes)[0]
              for Q, P, w, xi in zip(br.Q[past], br.P[past], br.omega[past], br.xi[past])]
    assert min(shares) > 0.5, shares
    with pytest.raises(ValueError, match="family_tol must be in"):
        fm.PeriodDriven(family_tol=0.0)



def test_end_orbit_judged_by_the_guide_slope():
    """The orbit past the end of the span continues the branch if its frequency at its energy lies
    within ``family_tol`` of the line through the last orbit with the coarse family's slope. 80
    elements with H = 40 stopped at 19 E_g: its last two orbits (1.95077 and 1.95688 rad/s, 18.0
    and 19.0 E_g) gave a secant of half the family's slope (8.8 against the continuum's 15.6 per
    rad/s there), and the family's orbit at 1.97084 rad/s, 27.2 E_g (0.49 % from the continuum),
    was taken for a tongue's. The numbers are that run's."""
    from femodes.nonsmooth_modes import _continues, _Orbit

    class Guide:  # the coarse family's d log E / d w at the last orbit
        def slope(self, w):
            return 15.6

    eg = math.pi ** 2 * 1e-4 / 16
    a, b = _Orbit(None, 1.95077, 17.97 * eg, 3), _Orbit(None, 1.95688, 18.95 * eg, 3)
    st = fm.PeriodDriven()
    assert _continues(a, b, _Orbit(None, 1.97084, 27.23 * eg, 3), Guide(), st)
    assert not _continues(a, b, _Orbit(None, 1.97084, 27.23 * eg, 3), None, st)
    # 40 % more energy at the same frequency: 1.6 % off the line in frequency, a neighbouring family's
    assert not _continues(a, b, _Orbit(None, 1.97084, 39.0 * eg, 3), Guide(), st)

def test_period_sweep_start_from_fewer_harmonics(model):
    """The sweep's start when Newton from the linear mode fails (H = 80 on 160 elements, 67 s: in
    benchmarks/README_bar_convergence.md): the orbit with ``start_harmonics`` harmonics, doubled up
    to H. Here with 5 -> 10 -> 20 harmonics on 20 elements, where the direct start works too: both
    reach the same orbit (to Newton's tolerance), and a start that cannot succeed is reported."""
    from femodes.hbm import NonlinearModeProblem, PeriodDrivenModeProblem
    from femodes.nonsmooth_modes import _start_coarse
    from femodes.solvers import NewtonOptions, semismooth_newton

    with pytest.raises(ValueError, match="start_harmonics must be a positive integer"):
        fm.PeriodDriven(start_harmonics=0)
    eg = fm.grazing_energy(model)
    problem = NonlinearModeProblem(model, fm.Harmonics(n_harmonics=20), 1, reference_energy=eg)
    pd = PeriodDrivenModeProblem(model, fm.Harmonics(n_harmonics=20), 1, reference_energy=eg)
    w = 1.02 * problem.omega0
    seed = problem.linear_guess(1.02 * eg)
    newton = NewtonOptions(atol=1e-9, max_iter=30)
    x0 = seed.copy()
    x0[pd.system.size] = w
    direct = semismooth_newton(lambda z: pd.residual(z, w)[:2], x0, options=newton)
    staged = _start_coarse(model, problem, w, seed, fm.PeriodDriven(start_harmonics=5), newton, None)
    assert direct.success and staged.success
    np.testing.assert_allclose(staged.x, direct.x, atol=1e-8 * np.max(np.abs(direct.x)))
    # no stage can succeed without iterations: the failed result handed in comes back
    failed = object()
    assert _start_coarse(model, problem, w, seed, fm.PeriodDriven(start_harmonics=5),
                         NewtonOptions(atol=1e-9, max_iter=1), failed) is failed


def test_saved_backbone_keeps_its_family_and_tongues(backbone, tmp_path):
    path = tmp_path / "bb.npz"
    backbone.save(path)
    back = fm.load_branch(path)
    assert back.meta["family"] == "contact phase"
    # (a failed solve in a tongue has energy NaN: compared as text)
    assert json.dumps(back.internal_resonances) == json.dumps(backbone.internal_resonances)
    np.testing.assert_array_equal(back.omega, backbone.omega)


def test_short_contact_phase_family_is_said(model, caplog):
    """A period-driven sweep that ends short of the span (here its frequency budget) returns the
    branch with success False and says so at WARNING level, as a continuation that stops short
    does (a 2-D blade's sweep stopped at 3.4 of 20 E_g with only an INFO line)."""
    eg = fm.grazing_energy(model)
    with caplog.at_level(logging.WARNING, logger="femodes"):
        br = fm.nonlinear_mode(model, 1, energy=(0.5 * eg, 25 * eg), harmonics=10,
                               past_grazing=fm.PeriodDriven(max_points=5))
    assert not br.success and br.energy.max() < 25 * eg
    assert any("contact-phase family ends at the energy" in r.getMessage() and "success False" in r.getMessage()
               for r in caplog.records), [r.getMessage() for r in caplog.records]


def test_arch_backbone_riding_a_tongue_the_forced_peak_does_not_follow():
    """A structure nobody tuned this for: a shallow pinned arch (40 x 2 Q2 quadrilaterals, 40 deg,
    R = 1 m, 20 mm thick, steel, plane stress), a stop 1 mm under the crown, Craig-Bampton with 10
    modes. Mode 1 is antisymmetric: it never touches (its crown component is the eigen-solver's
    round-off, 7e-12 of its largest), and grazing_energy says so instead of returning 1e23 J.
    Mode 2's energy continuation shifts 3.4 % (above PeriodDriven.grazing_shift = 3 %: trusted, as
    the cantilever's 5.4 % is) and rides a 4:1 tongue where mode 5 takes its energy; the forced
    peak (1 % modal damping, 2 kN at the crown, H = 7) lies at 1.20 w2, 16 % off. That peak is a
    truncation artefact (at H = 15 and 21 the peak lies at 1.033-1.035 w2, 0.2-0.4 % from this
    backbone; rtol finds it unconverged: tests/test_exact_branch.py), so compare_resonance asks
    first for the peak's convergence, then names the call that traces the contact-phase family,
    which at H = 7 holds the H = 7 peak (0.06 % measured, 1 % allowed: the family's points bracket
    the peak's energy 0.5 % apart in frequency). The damped model's energy continuation turns back
    at 4.7 E_g to its start energy, "successful": it is not trusted (traced by frequency)."""
    bench = load("bench_arch", BENCHMARKS)
    model = bench.arch()  # the arch the benchmark times, built in code
    rom = fm.craig_bampton(model, 10)
    with pytest.raises(ValueError, match=r"linear mode 1 does not move any contact DOF.*modes \[2, 3, 5\] move it"):
        fm.grazing_energy(rom, 1)
    with caplog_warning() as records:
        flat = fm.nonlinear_mode(rom, 1, energy=(1.0, 10.0), harmonics=3)
    assert np.ptp(flat.omega) / flat.omega[0] < 1e-12 and any("mode 1 moves no contact" in r.getMessage() for r in records)
    w2, eg = fm.linear_modes(rom, 2).omega[1], fm.grazing_energy(rom, 2)
    with caplog_warning() as records:
        riding = fm.nonlinear_mode(rom, 2, energy=(0.5 * eg, 10 * eg), harmonics=7)
    assert "family" not in riding.meta and 0.03 < riding.omega.max() / w2 - 1 < 0.04
    # it ends in mode 5's 4:1 tongue, and says so (measured: 93 % of the last orbit's energy, w_5 / w = 3.99)
    assert re.match(r"mode 5 holds 9\d% of the energy of the last orbit \(w_5 / w = 3\.9", riding.meta["ends_in"])
    assert any("climbs an internal resonance" in r.getMessage() for r in records) and "ends_in" not in flat.meta
    forced = bench.forced_rom(model)
    frc = fm.frequency_response(forced, (0.9 * w2, 1.3 * w2), 7)
    with caplog_warning() as records:
        peak, = fm.compare_resonance(riding, frc)
    assert peak.omega / w2 == pytest.approx(1.20, abs=0.01) and peak.distance > 0.1 and peak.backbone_held_by == 5
    assert "PeriodDriven(always=True)" in peak.predicted and any("mode 5's" in r.getMessage() for r in records)
    assert peak.converged is None and "check first that the peak is converged" in peak.predicted
    family = fm.nonlinear_mode(rom, 2, energy=(0.5 * eg, 10 * eg), harmonics=7, past_grazing=fm.PeriodDriven(always=True))
    assert family.meta["family"] == "contact phase" and family.omega.max() / w2 > 1.2
    peak, = fm.compare_resonance(family, frc)
    assert abs(peak.distance) < 1e-2 and peak.predicted.startswith("on the backbone")
    damped = fm.nonlinear_mode(forced, 2, energy=(0.5 * eg, 10 * eg), harmonics=7)
    assert "turned back at 4.7" in damped.meta["energy_continuation"] and damped.meta["family"] == "contact phase"
    below = damped.energy[damped.energy < eg]
    assert np.all(np.diff(below) > 0) and np.all(np.diff(damped.omega[damped.energy > eg]) > 0)
    assert abs(fm.compare_resonance(damped, frc)[0].distance) < 1e-2
