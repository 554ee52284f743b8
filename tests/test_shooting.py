"""Time-domain Floquet multipliers: femodes/time/shooting.py (monodromy, shoot, trajectory).

Reference values from /work/shared/references.md ("Stability", "Forced Duffing", "Free Duffing").
The integration runs at rtol = 1e-11 (DOP853), so values known in closed form are asserted to
about 1e-9; comparisons with finite differences of the event-driven flow (central, step 1e-6)
carry their O(h^2) truncation and O(eps_int / h) round-off, about 1e-8 here, asserted to 1e-5.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import femodes as fm
from femodes.time.shooting import monodromy, shoot, trajectory

from .test_examples import load


def oscillator(c=0.1, k=1.0, amplitude=1.0):
    return fm.StructuralModel(M=[[1.0]], K=[[k]], C=[[c]]).with_forcing(fm.HarmonicForce(at=0, amplitude=amplitude))


def central_differences(model, omega, x, **kw):
    """``d x(T) / d x(0)`` of the event-driven flow by central differences (step 1e-6 relative)."""
    J = np.empty((x.size, x.size))
    for j in range(x.size):
        h = 1e-6 * max(1.0, abs(x[j]))
        e = np.zeros(x.size)
        e[j] = h
        plus, minus = monodromy(model, omega, x + e, **kw), monodromy(model, omega, x - e, **kw)
        J[:, j] = (plus.state_end - minus.state_end) / (2 * h)
    return J


# --------------------------------------------------------------------------------------------
# Smooth systems
# --------------------------------------------------------------------------------------------
def test_linear_damped_oscillator_multipliers_are_exact():
    zeta, w0, w = 0.05, 1.3, 0.9
    model = oscillator(c=2 * zeta * w0, k=w0**2)
    T = 2 * np.pi / w
    lam = -zeta * w0 + 1j * w0 * np.sqrt(1 - zeta**2)
    exact = np.exp(np.array([lam, np.conj(lam)]) * T)
    m = monodromy(model, w, [0.3, -0.2])  # independent of the state (linear) and of the forcing
    exact = exact[np.argsort(-exact.imag)]  # same order as m.multipliers: equal modulus, +imag first
    np.testing.assert_allclose(m.multipliers, exact, rtol=1e-9)
    assert m.impacts == [] and m.matrix.shape == (2, 2)
    # the periodic orbit: the linear response |1 / (w0^2 - w^2 + 2 i zeta w0 w)|
    r = shoot(model, w, [0.0, 0.0])
    assert r.success and r.nit <= 2  # linear: one Newton step (a second to see the residual drop)
    amp = 1 / abs(w0**2 - w**2 + 2j * zeta * w0 * w)
    np.testing.assert_allclose(np.hypot(r.u0[0], r.v0[0] / w), amp, rtol=1e-9)


def duffing_guesses(c=0.1, w=2.0):
    """States at t = 0 of the three one-harmonic balance solutions u = a cos(w t) + b sin(w t) of
    u'' + c u' + u + u^3 = cos(w t): A^2 = a^2 + b^2 solves (k^2 + (c w)^2) A^2 = 1 with
    k = 1 - w^2 + 3/4 A^2; then a = k / (k^2 + (c w)^2), b = c w / (k^2 + (c w)^2)."""
    A2 = np.sort(np.roots([9 / 16, 1.5 * (1 - w * w), (1 - w * w) ** 2 + (c * w) ** 2, -1]).real)
    out = []
    for a2 in A2:
        k = 1 - w * w + 0.75 * a2
        d = k * k + (c * w) ** 2
        out.append(np.array([k / d, w * c * w / d]))
    return out  # small, middle, large amplitude


def test_forced_duffing_three_coexisting_orbits():
    c, w = 0.1, 2.0
    model = oscillator(c=c).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
    T = 2 * np.pi / w
    t = np.linspace(0.0, T, 4001)
    found = {}
    for name, guess in zip(("small", "middle", "large"), duffing_guesses(c, w)):
        r = shoot(model, w, guess)
        assert r.success, r.message
        assert r.residual_norm < 1e-9
        found[name] = r
        # max |u| on a fine grid: references.md values (6 digits); the 4001-point grid adds
        # at most (w max|u| dt)^2 / 2 ~ 1e-6 relative at the peak
        umax = np.max(np.abs(trajectory(model, w, r.x, t)[:, 0]))
        expected = {"small": 0.342901, "middle": 1.842510, "large": 2.180126}[name]
        assert abs(umax - expected) < 1e-5, (name, umax)
        # Liouville: det = exp(-c T) (trace of the state Jacobian is -c)
        np.testing.assert_allclose(np.prod(r.multipliers).real, np.exp(-c * T), rtol=1e-8)
    # the middle orbit is a saddle (one real multiplier > 1), the others attract
    mid = found["middle"].multipliers
    assert abs(mid[0].imag) < 1e-12 and mid[0].real > 1.5  # measured 2.4887
    assert np.all(np.abs(found["small"].multipliers) < 1) and np.all(np.abs(found["large"].multipliers) < 1)


def test_free_duffing_orbit_period_is_exact():
    # u'' + u + u^3 = 0 from u(0) = A = 1 at rest: w = pi sqrt(1 + A^2) / (2 K(m)), references.md
    model = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
    r = shoot(model, 1.2, [1.0, 0.3])  # wrong frequency and velocity: the turning point is imposed
    assert r.success, r.message
    assert abs(r.omega - 1.317776064966) < 1e-9
    assert r.x[0] == 1.0 and r.v0[0] == 0.0  # amplitude kept, phase at the turning point
    np.testing.assert_allclose(r.period, 2 * np.pi / r.omega)
    # Conservative family: multiplier +1 twice, reported as computed. It is a Jordan block
    # (the period changes with the energy), so integration errors eps ~ 1e-12 move the
    # eigenvalues by sqrt(eps) ~ 1e-6 (a real pair 1 +/- d or a pair on the unit circle),
    # while their sum (trace) and product (det, Liouville) move by eps only.
    mu = r.multipliers
    assert np.all(np.abs(mu - 1) < 1e-5)
    assert abs(np.trace(r.monodromy) - 2) < 1e-9
    assert abs(np.linalg.det(r.monodromy) - 1) < 1e-9
    assert np.all(np.abs(np.abs(mu) - 1) < 1e-5)


# --------------------------------------------------------------------------------------------
# Impacts
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def impact_orbit():
    """Period-1 impacting orbit of u'' + 0.1 u' + u = 0.2 cos(t) against a stop at u = 1
    (Shi & Legrand 2016 case, w = 1: the free linear amplitude would be 2), from a transient."""
    model = oscillator(c=0.1, amplitude=0.2).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    x = np.zeros(2)
    for _ in range(20):  # 20 periods: the transient decays like exp(-0.05 t), to about 2e-3
        x = monodromy(model, 1.0, x).state_end
    return model, shoot(model, 1.0, x)


def test_impact_oscillator_liouville_across_impacts(impact_orbit):
    _, r = impact_orbit
    assert r.success and len(r.impacts) == 1, r.message
    T = 2 * np.pi
    # restitution 1: det S = e^2 = 1, so det Phi = exp(-c T) as without the stop
    np.testing.assert_allclose(np.prod(r.multipliers).real, np.exp(-0.1 * T), rtol=1e-8)
    assert np.all(np.abs(r.multipliers) < 1)  # attracting


def test_saltation_matrix_against_finite_differences(impact_orbit):
    model, r = impact_orbit
    m = monodromy(model, 1.0, r.x)
    J = central_differences(model, 1.0, r.x)
    # Without the saltation matrix, Phi would be off by O(1) (the impact reverses velocities)
    np.testing.assert_allclose(m.matrix, J, rtol=0, atol=1e-5 * np.abs(J).max())


def test_generalised_impact_law_with_consistent_mass():
    # 2 DOFs with a non-diagonal mass row at the contact DOF: the impulse acts along M^-1 e_c
    M = np.array([[2.0, 1.0], [1.0, 2.0]]) / 3
    K = np.array([[2.0, -1.0], [-1.0, 1.0]])
    free = fm.StructuralModel(M=M, K=K).with_contact(fm.UnilateralContact(at=1, gap=0.5))
    x0 = np.array([0.2, 0.3, 0.5, 0.9])
    m = monodromy(free, 1.1, x0)
    assert len(m.impacts) == 2
    # restitution 1 conserves the kinetic energy (v+ - v- is M-orthogonal to v+ + v-), so the
    # mechanical energy is conserved through the impacts to the integration tolerance
    energy = lambda x: 0.5 * x[2:] @ M @ x[2:] + 0.5 * x[:2] @ K @ x[:2]  # noqa: E731
    assert abs(energy(m.state_end) - energy(x0)) < 1e-9
    assert abs(np.linalg.det(m.matrix) - 1) < 1e-9  # conservative and elastic: volume preserved
    J = central_differences(free, 1.1, x0)
    np.testing.assert_allclose(m.matrix, J, rtol=0, atol=1e-5 * np.abs(J).max())
    # damped and forced: Liouville det = exp(-tr(M^-1 C) T) across impacts
    forced = (fm.StructuralModel(M=M, K=K, C=0.02 * K).with_forcing(fm.HarmonicForce(at=0, amplitude=0.3))
              .with_contact(fm.UnilateralContact(at=1, gap=0.5)))
    m = monodromy(forced, 1.1, x0)
    assert len(m.impacts) >= 1
    T = 2 * np.pi / 1.1
    np.testing.assert_allclose(np.linalg.det(m.matrix), np.exp(-np.trace(np.linalg.solve(M, 0.02 * K)) * T), rtol=1e-8)


def test_penalty_contact_kinks_are_stopped_at():
    # vector field continuous at the kink (saltation = identity) but its derivative jumps
    model = oscillator(c=0.1, amplitude=0.2).with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=50.0))
    r = shoot(model, 1.0, [0.8, 0.6])
    assert r.success, r.message
    m = monodromy(model, 1.0, r.x)
    assert len(m.kinks) == 2 and m.impacts == []  # in and out of the penalty spring once
    np.testing.assert_allclose(np.prod(r.multipliers).real, np.exp(-0.1 * 2 * np.pi), rtol=1e-8)
    J = central_differences(model, 1.0, r.x)
    np.testing.assert_allclose(m.matrix, J, rtol=0, atol=1e-5 * np.abs(J).max())


@pytest.fixture(scope="module")
def ex():
    return load("subharmonic_contact")


def test_subharmonic_example_multipliers(ex):
    model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[ex.DAMPING]])
             .with_forcing(fm.HarmonicForce(at=0, amplitude=ex.FORCE))
             .with_contact(fm.UnilateralContact(at=0, gap=ex.GAP)))
    period = ex.NU * 2 * np.pi / ex.OMEGA0
    # from the same end of transient as the example's own shooting
    r = shoot(model, ex.OMEGA0, ex.strobe_transient[-1], period=period)
    assert r.success and len(r.impacts) == 1, r.message
    np.testing.assert_allclose(r.x, ex.y_td, atol=1e-8)  # both converged to 1e-10
    # the example's multipliers are central differences (step 1e-7, rtol 1e-10): ~1e-7 accurate
    np.testing.assert_allclose(np.sort_complex(r.multipliers), np.sort_complex(ex.multipliers), atol=1e-5)
    np.testing.assert_allclose(np.abs(r.multipliers), np.exp(-ex.DAMPING * period / 2), rtol=1e-9)


# --------------------------------------------------------------------------------------------
# What event-driven integration cannot do, and bad input
# --------------------------------------------------------------------------------------------
def bouncing_on_a_stop():
    """Unit mass pushed by a constant force 2 onto a stop at 1 (static load, autonomous)."""
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_forcing(fm.HarmonicForce(at=0, amplitude=2.0, harmonic=0))
            .with_contact(fm.UnilateralContact(at=0, gap=1.0)))


@pytest.mark.parametrize("restitution", [0.5, 0.0])
def test_chattering_and_sticking_are_refused(restitution):
    # the static equilibrium u = 2 is behind the stop: bounces shrink by e each time, then stick
    with pytest.raises(ValueError, match=r'restitution=.*(accumulate|rest on the obstacle).*stability_methods.Hill\(\)'):
        monodromy(bouncing_on_a_stop(), 1.0, [0.5, 0.0], restitution=restitution)
    # restitution 1: the elastic bounce goes on, no refusal
    m = monodromy(bouncing_on_a_stop(), 1.0, [0.5, 0.0], restitution=1.0)
    assert len(m.impacts) >= 1


def test_massless_contact_dof_and_singular_mass_are_refused():
    K = np.array([[2.0, -1.0], [-1.0, 1.0]])
    model = fm.StructuralModel(M=np.diag([1.0, 0.0]), K=K)
    with pytest.raises(ValueError, match=r'UnilateralContact 0.*no mass.*stability_methods.Hill\(\)'):
        monodromy(model.with_contact(fm.UnilateralContact(at=1, gap=0.1)), 1.0, np.zeros(4))
    with pytest.raises(ValueError, match=r'M is singular.*massless DOFs.*stability_methods.Hill\(\)'):
        monodromy(model, 1.0, np.zeros(4))


def test_bad_input_names_the_argument():
    model = oscillator()
    with pytest.raises(ValueError, match=r"monodromy: period must be a positive finite number, got -1\.0"):
        monodromy(model, 1.0, [0.0, 0.0], period=-1.0)
    with pytest.raises(ValueError, match=r"shoot: x0 must have shape \(2,\).*got shape \(3,\)"):
        shoot(model, 1.0, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"shoot: omega must be a positive finite number, got 0"):
        shoot(model, 0, [0.0, 0.0])
    with pytest.raises(ValueError, match=r"monodromy: restitution must be in \[0, 1\], got 1\.5"):
        monodromy(model, 1.0, [0.0, 0.0], restitution=1.5)
    with pytest.raises(ValueError, match=r"shoot: period=3\.0 is .* forcing periods"):
        shoot(model, 1.0, [0.0, 0.0], period=3.0)  # a forced orbit needs nu * 2 pi / omega
    with pytest.raises(ValueError, match=r"phase_dof=0 is for autonomous models"):
        shoot(model, 1.0, [0.0, 0.0], phase_dof=0)
    with pytest.raises(TypeError, match=r"monodromy: model must be a StructuralModel"):
        monodromy("model", 1.0, [0.0, 0.0])
    stop = model.with_contact(fm.UnilateralContact(at=0, gap=1.0))
    with pytest.raises(ValueError, match=r"x0 starts inside the obstacle of contact 0"):
        monodromy(stop, 1.0, [1.5, 0.0])
    with pytest.raises(ValueError, match=r"trajectory: t must be .* >= t0"):
        trajectory(model, 1.0, [0.0, 0.0], [-1.0])


def test_nonconvergence_is_reported_not_raised():
    model = oscillator().with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))
    r = shoot(model, 2.0, [0.0, 2.0], max_iter=1)
    assert not r.success and r.status == 1 and r.nit == 1 and "max_iter=1" in r.message
    assert math.isfinite(r.residual_norm) and r.multipliers.shape == (2,)
