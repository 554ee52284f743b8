"""Checks of the semi-analytic impact-oscillator reference (tests/impact_reference.py).

``u'' + c u' + u = F cos(w t)``, stop at ``u = g``, restitution 1. The reference is built from
the closed-form linear flow alone; here it is checked against

* the exact free backbone ``w = pi / (pi - arccos(g / A))`` (conservative, unforced),
* femodes' event-driven shooting (DOP853 at rtol 1e-11 with event location), which shares no
  code with it: the orbits must be fixed points of femodes' period map to ~1e-9, and Newton
  from a perturbed guess must come back to them,
* quadrature of its own time histories (energies, extreme displacements),
* the definition of the fold: two orbits just below it, none just above, a Floquet multiplier
  +1 there (femodes' monodromy matrix with saltation).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import roots_legendre

import femodes as fm
from femodes.time.shooting import monodromy, shoot, trajectory

from . import impact_reference as ref

CASES = {"case1": (0.1, 0.2, 1.0), "case2": (0.2, 1.0, 2.5)}
#: One-orbit region (between the grazing frequencies), two-orbit region, and close to the fold.
FREQUENCIES = {"case1": (1.0, 1.2, 1.4), "case2": (0.9, 1.25, 1.42)}
#: Rough harmonic-balance extrapolations of the upper fold (w, max|u|): sanity only.
HBM_FOLD = {"case1": (1.419, 1.66), "case2": (1.42, 4.12)}


@pytest.fixture(scope="module")
def folds():
    # computed once: each upper_fold scans the discriminant on 4000 frequencies
    return {name: ref.upper_fold(*system) for name, system in CASES.items()}


def impact_model(c, F, g):
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[c]])
            .with_contact(fm.UnilateralContact(at=0, gap=g))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=F)))


def impacting(orbits):
    return [o for o in orbits if o.impacting]


# --------------------------------------------------------------------------------------------
# Free conservative system
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("g", [1.0, 2.5])
@pytest.mark.parametrize("v", [0.3, 1.0, 3.0, 10.0])
def test_free_orbit_period_matches_free_frequency(g, v):
    # from the stop with velocity -v, the closed-form flow (c = 0, F = 0) must come back to u = g
    # with velocity +v after 2 pi / free_frequency(E); the return time is found by root finding,
    # not by the arccos formula under test
    x0 = np.array([g, -v])

    def state(s):
        return ref.propagator(0.0, s) @ x0

    # u < g on the way out; the first upward crossing of g lies in (pi, 2 pi) (half a cosine
    # at least, one full cosine at most): bracket it on a grid, refine with brentq
    s = np.linspace(math.pi, 2 * math.pi, 2001)
    du = np.array([state(x)[0] - g for x in s])
    k = int(np.flatnonzero((du[:-1] < 0) & (du[1:] >= 0))[0])
    T = brentq(lambda x: state(x)[0] - g, s[k], s[k + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps)
    E = 0.5 * (v * v + g * g)  # conserved; at the stop u = g, u' = v
    assert 2 * math.pi / T == pytest.approx(ref.free_frequency(E, g), rel=1e-12)
    assert state(T)[1] == pytest.approx(v, rel=1e-12)  # it arrives with +v: periodic after the impact


def test_free_frequency_limits():
    assert ref.free_frequency(0.5 * 0.9**2, 1.0) == 1.0  # A < g: no impact, linear frequency
    assert ref.free_frequency(0.5 * 1e12, 1.0) == pytest.approx(2.0, rel=1e-5)  # A >> g: half-period flights
    # A = g sqrt(2) (E = g^2): arccos = pi/4, w = 4/3; A = 2 g (E = 2 g^2): arccos = pi/3, w = 3/2
    assert ref.free_frequency(1.0, 1.0) == pytest.approx(4.0 / 3.0, rel=1e-14)
    assert ref.free_frequency(2.0, 1.0) == pytest.approx(1.5, rel=1e-14)


# --------------------------------------------------------------------------------------------
# Against femodes' event-driven shooting
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", CASES)
def test_orbits_are_fixed_points_of_femodes_shooting(name):
    c, F, g = CASES[name]
    model = impact_model(c, F, g)
    n_tested = 0
    for w in FREQUENCIES[name]:
        orbits = impacting(ref.one_impact_orbits(c, F, g, w))
        assert 1 <= len(orbits) <= 2
        for orbit in orbits:
            x0 = np.array([orbit.u(0.0), orbit.v(0.0)])
            T = orbit.period
            # femodes' period map at the reference state: back to it, one impact at the predicted time
            m = monodromy(model, w, x0)
            assert np.max(np.abs(m.state_end - x0)) < 1e-9 * max(1.0, orbit.velocity)
            assert len(m.impacts) == 1
            assert m.impacts[0][0] == pytest.approx(orbit.impact_time, abs=1e-8 * T)
            # Newton from a perturbed guess converges to the same orbit (the orbit is isolated)
            r = shoot(model, w, x0 + np.array([-1e-3 * g, 1e-3 * orbit.velocity]))
            assert r.success, r.message
            np.testing.assert_allclose(r.x, x0, rtol=0, atol=1e-8 * max(1.0, orbit.velocity))
            # the time histories agree (away from the impact instant)
            t = np.linspace(0.0, T, 9)[1:-1] + 0.013 * T
            t = t[np.abs(t - orbit.impact_time) > 1e-3 * T]
            np.testing.assert_allclose(trajectory(model, w, x0, t)[:, 0], orbit.u(t), rtol=0, atol=1e-8 * g)
            n_tested += 1
    assert n_tested >= 4  # the two-orbit frequencies contributed both orbits


# --------------------------------------------------------------------------------------------
# Energies, extremes, grazing
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", CASES)
def test_energy_and_max_abs_u_against_quadrature(name):
    c, F, g = CASES[name]
    nodes, weights = roots_legendre(200)
    for w in FREQUENCIES[name]:
        for orbit in ref.one_impact_orbits(c, F, g, w):
            T = orbit.period
            # the integrand is analytic on the flight [t_i, t_i + T] (no impact inside), so
            # Gauss-Legendre converges to round-off
            t0 = orbit.impact_time if orbit.impacting else 0.0
            u, du = orbit.state(t0 + 0.5 * T * (nodes + 1.0))
            energy = 0.5 * np.sum(weights * 0.5 * (u * u + du * du))  # (T/2) sum(...) / T
            assert orbit.energy == pytest.approx(energy, rel=1e-12)
            # a fine grid can only under-estimate the extreme, by O((T/N)^2)
            dense = np.abs(orbit.u(np.linspace(t0, t0 + T, 100001)))
            assert orbit.max_abs_u - 1e-12 <= dense.max() + 1e-8 * orbit.max_abs_u
            assert dense.max() <= orbit.max_abs_u + 1e-12
            if orbit.impacting:
                # leaves the stop with -v, arrives with +v, u = g at the impact, below it elsewhere
                assert orbit.u(orbit.impact_time) == pytest.approx(g, rel=1e-13)
                assert orbit.v(orbit.impact_time) == pytest.approx(-orbit.velocity, rel=1e-12)
                assert orbit.v(orbit.impact_time + T * (1 - 1e-13)) == pytest.approx(orbit.velocity, rel=1e-9)
                assert np.max(orbit.u(np.linspace(t0, t0 + T, 10001)[1:-1])) < g


@pytest.mark.parametrize("name", CASES)
def test_grazing_frequencies(name):
    c, F, g = CASES[name]
    low, high = ref.grazing_frequencies(c, F, g)
    for wg in (low, high):
        assert F / math.hypot(1 - wg * wg, c * wg) == pytest.approx(g, rel=1e-12)
    # between them the linear orbit would penetrate: exactly one impacting orbit, born at
    # grazing with zero impact velocity
    just_in = ref.one_impact_orbits(c, F, g, low * (1 + 1e-6))
    assert len(just_in) == 1 and just_in[0].impacting and 0 < just_in[0].velocity < 1e-3
    mid = ref.one_impact_orbits(c, F, g, 0.5 * (low + high))
    assert len(mid) == 1 and mid[0].impacting
    # above the upper grazing frequency the linear orbit is back, with a slow impacting orbit
    # (the unstable branch, ending at grazing) and the resonant one
    above = ref.one_impact_orbits(c, F, g, high * (1 + 1e-6))
    assert [o.impacting for o in above] == [True, True, False]
    assert above[0].velocity < 1e-3 < above[1].velocity


# --------------------------------------------------------------------------------------------
# The upper fold
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", CASES)
def test_upper_fold(name, folds):
    c, F, g = CASES[name]
    fold = folds[name]
    wf = fold.w
    below = impacting(ref.one_impact_orbits(c, F, g, wf * (1 - 1e-6)))
    above = impacting(ref.one_impact_orbits(c, F, g, wf * (1 + 1e-6)))
    assert len(below) == 2 and above == []
    v1, v2 = below[0].velocity, below[1].velocity
    vf = fold.orbit.velocity
    # distinct, and close: the split grows like sqrt(w_f - w) (here ~1e-3 relative)
    assert 1e-5 * vf < v2 - v1 < 1e-2 * vf
    assert v1 < vf < v2
    # the fold is located to 1e-10: orbits exist 1e-10 below it and not 1e-10 above it, and
    # the double orbit is the midpoint of the two there
    near = impacting(ref.one_impact_orbits(c, F, g, wf * (1 - 1e-10)))
    assert len(near) == 2 and impacting(ref.one_impact_orbits(c, F, g, wf * (1 + 1e-10))) == []
    assert 0.5 * (near[0].max_abs_u + near[1].max_abs_u) == pytest.approx(fold.max_abs_u, rel=1e-8)
    assert 0.5 * (near[0].energy + near[1].energy) == pytest.approx(fold.energy, rel=1e-8)
    # robust to the scan that brackets it
    assert ref.upper_fold(c, F, g, n_scan=1000).w == pytest.approx(wf, rel=1e-13)
    # a saddle-node: femodes' monodromy matrix (saltation included) has a multiplier +1 there
    m = monodromy(impact_model(c, F, g), wf, [fold.orbit.u(0.0), fold.orbit.v(0.0)])
    assert len(m.impacts) == 1
    assert np.min(np.abs(m.multipliers - 1.0)) < 1e-6
    # the rough harmonic-balance extrapolation agrees to its own accuracy
    w_hbm, u_hbm = HBM_FOLD[name]
    assert wf == pytest.approx(w_hbm, rel=5e-3)
    assert fold.max_abs_u == pytest.approx(u_hbm, rel=1e-2)


@pytest.mark.parametrize("name", CASES)
def test_peak_response_lies_before_the_fold(name, folds):
    # the branch's largest response is on the resonant orbit below the fold frequency, larger
    # than the response at the fold (the fold is the turning point in w, not in max|u|)
    c, F, g = CASES[name]
    fold = folds[name]
    peak = ref.peak_response(c, F, g, n_scan=100)
    assert peak.w < fold.w and peak.max_abs_u > fold.max_abs_u
    for dw in (-1e-4, 1e-4):
        nearby = max(impacting(ref.one_impact_orbits(c, F, g, peak.w + dw)), key=lambda o: o.velocity)
        assert nearby.max_abs_u < peak.max_abs_u
