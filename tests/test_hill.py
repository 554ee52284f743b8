"""Hill's method on its own: the Mathieu equation's transition curves.

``u'' + (delta + eps cos t) u = 0`` (period 2 pi) is a linear Hill equation: its harmonic balance
Jacobian is exact, so :func:`femodes.hbm.hill.hill_exponents` must reproduce the classical
transition curves between stable and unstable regions (references.md, "Stability"; Nayfeh and
Mook, *Nonlinear Oscillations*, 1979, sec. 5.2.1):

    delta = 1/4 +- eps/2 - eps^2/8 + O(eps^3)     (period 4 pi, multiplier -1)
    delta = 1 - eps^2/12 + O(eps^4),  1 + 5 eps^2/12 + O(eps^4)   (period 2 pi, multiplier +1)
    delta = -eps^2/2 + O(eps^4)

The test double below is the smallest "system" Hill's method reads: harmonics, ``M``, ``C``,
``D1``, the block operators ``I x M``, ``I x C``, ``D1 x M`` and the Jacobian of ``u'' + (delta + eps cos t) u`` (the multiplication by ``cos t`` is
projected on the harmonics with the same synthesis/analysis as the HBM, exact at this sampling).
"""

import numpy as np
import pytest
import scipy.sparse as sp

from femodes.dynamic_stiffness import CoefficientStiffness, DynamicStiffness

from femodes.hbm import Harmonics
from femodes.hbm.hill import hill_exponents

EPS = 0.1


class _Jacobian:
    def __init__(self, A):
        self.A = sp.csr_matrix(A)

    def tocsr(self):
        return self.A


class MathieuSystem:
    """``u'' + (delta + eps cos t) u = 0`` in the HBM layout (one DOF, no contact)."""

    def __init__(self, delta, eps, H=12):
        self.h = Harmonics(H)
        self.n, self.n_uc = 1, 0
        self.nq = self.size = self.h.n_coef
        self.M = sp.identity(1, format="csr")
        self.C = sp.csr_matrix((1, 1))
        self.D1 = sp.csr_matrix(np.asarray(self.h.operators.derivative_domega()))
        self.stiffness = CoefficientStiffness(DynamicStiffness(sp.csr_matrix((1, 1)), self.M, self.C), self.D1)
        self.nonlinear_dofs = np.array([0])
        E, Pa = np.asarray(self.h.grid.synthesis()), np.asarray(self.h.grid.analysis())
        self.cos = Pa @ (np.cos(self.h.grid.phases())[:, None] * E)
        self.delta, self.eps = delta, eps

    def residual(self, x, omega, *, xi=0.0, forced=True):
        D = omega * self.D1.toarray()
        J = D @ D + self.delta * np.eye(self.size) + self.eps * self.cos
        return None, _Jacobian(J), None, None


def unstable(delta, eps=EPS):
    mu = hill_exponents(MathieuSystem(delta, eps), np.zeros(0), 1.0).multipliers
    return np.max(np.abs(mu)) > 1.0 + 1e-9


def transition(a, b, eps=EPS):
    """Bisection on delta between a stable and an unstable value (to 1e-10)."""
    ua = unstable(a, eps)
    assert unstable(b, eps) != ua
    while b - a > 1e-10:
        m = 0.5 * (a + b)
        if unstable(m, eps) == ua:
            a = m
        else:
            b = m
    return 0.5 * (a + b)


def test_mathieu_stable_and_unstable_regions_are_conservative():
    # stable: every multiplier on the unit circle (Hamiltonian); unstable: a real pair mu, 1/mu
    mu = hill_exponents(MathieuSystem(0.5, EPS), np.zeros(0), 1.0).multipliers
    assert mu.size == 2 and np.allclose(np.abs(mu), 1.0, atol=1e-12)
    mu = hill_exponents(MathieuSystem(0.25, EPS), np.zeros(0), 1.0).multipliers
    assert mu[0].real < -1.0 and abs(mu[0].imag) < 1e-9          # period doubling tongue: mu < -1
    assert np.prod(mu) == pytest.approx(1.0, abs=1e-10)         # Liouville: no damping


@pytest.mark.parametrize("bracket, series", [
    ((0.15, 0.25), 0.25 - EPS / 2 - EPS ** 2 / 8),
    ((0.25, 0.35), 0.25 + EPS / 2 - EPS ** 2 / 8),
    ((0.95, 1.0), 1.0 - EPS ** 2 / 12),
    ((1.0, 1.05), 1.0 + 5 * EPS ** 2 / 12),
    ((-0.05, 0.05), -EPS ** 2 / 2),
])
def test_mathieu_transition_curves(bracket, series):
    # The series is truncated after eps^2: its error is the next term, |eps^3/32| = 3.1e-5 for
    # the first tongue and O(eps^4) ~ 1e-5 for the others; the Hill computation itself (H = 12,
    # spectral) is far more accurate. Tolerance 1e-4.
    assert transition(*bracket) == pytest.approx(series, abs=1e-4)


def test_mathieu_transition_converges_with_the_next_series_term():
    # first tongue with the eps^3 term (Nayfeh & Mook eq. 5.2.30): 1/4 - eps/2 - eps^2/8 + eps^3/32
    eps = 0.05
    d = transition(0.2, 0.25, eps)
    assert d == pytest.approx(0.25 - eps / 2 - eps ** 2 / 8 + eps ** 3 / 32, abs=5e-7)  # O(eps^4) = 6e-6 / 12
