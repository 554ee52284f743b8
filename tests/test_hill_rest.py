"""Hill's problem of orbits on which the nonlinear forces act as at rest (femodes/hbm/hill_rest.py):
below the first contact the linearised system is time-invariant, so the exponents found at one such
orbit serve all the others, at their own periods."""

import numpy as np

import femodes as fm
from femodes.hbm.hill_rest import at_rest

from .conftest import fixed_free_bar


def _forced(n=20):
    model = (fixed_free_bar(n).with_contact(fm.UnilateralContact(at="tip", gap=0.05))
             .with_damping(beta=0.01).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.01)))
    return fm.frequency_response(model, (1.3, 1.85), 5, stability=True)


def test_points_below_contact_take_the_exponents_of_the_first():
    """The multipliers along the curve at the points without contact (reused from the first such
    point) equal those of a fresh solve at each point (fm.stability builds its own system) to
    round-off: the exponents of a time-invariant system do not depend on the frequency, only the
    period that exponentiates them does (measured: 2e-15 here; 6e-14 on examples/blade_casing.py's
    forced curve)."""
    f = _forced()
    rest = [i for i in range(len(f)) if not np.any(f.P[i])]
    contact = [i for i in range(len(f)) if np.any(f.P[i])]
    assert len(rest) >= 3 and contact
    for i in rest:
        fresh = fm.stability(f[i]).multipliers
        along = np.asarray(f.multipliers[i])
        along = along[np.isfinite(along)]
        k = min(fresh.size, along.size)
        assert k >= 2
        top_a, top_f = np.sort(np.abs(along))[::-1][:k], np.sort(np.abs(fresh))[::-1][:k]
        # |mu| <= 1 from the same eigen-solve at another period: a multiple of eps (measured 10 eps)
        assert np.allclose(top_a, top_f, rtol=0, atol=1e3 * np.finfo(float).eps), (i, top_a, top_f)


def test_at_rest_tells_contact_and_smooth_laws_apart():
    f = _forced(10)
    problem = fm.hbm.ForcedResponseProblem(f.model, f.harmonics)
    s = problem.system
    for i in range(len(f)):
        x = problem.pack(f.Q[i], f.P[i], f.omega[i])[: s.size]
        assert at_rest(s, x) == (not np.any(f.P[i])), i
    # a cubic spring: never at rest away from zero amplitude
    duff = (fixed_free_bar(5).with_nonlinearity(fm.CubicSpring(at="tip", k3=1.0))
            .with_forcing(fm.HarmonicForce(at="tip", amplitude=0.1)).with_damping(beta=0.01))
    p = fm.hbm.ForcedResponseProblem(duff, fm.Harmonics(3))
    x = np.zeros(p.system.size)
    assert at_rest(p.system, x)
    x[p.system.h.n_coef] = 1e-3  # some motion
    assert not at_rest(p.system, x + 1e-3)
