"""Pointwise laws (femodes.laws): vectorised values, generalized derivatives, potentials, stacking,
and the rule that their formulas are written only there (DESIGN section 1, "laws").

References are scalar formulas written with ``math`` from the module docstring of
:mod:`femodes.laws` (``g_N = gap - u``, ``p = k max(0, -g_N)``, ``f = k3 u^3``,
``r = p - max(0, p - c g_N)``); derivatives are checked by finite differences away from the
kinks and one-sided at them (the generalized derivative takes the inactive side).
"""

from __future__ import annotations

import inspect
import io
import re
import tokenize
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import femodes as fm
from femodes.app.sweep import max_penetration

ROOT = Path(__file__).resolve().parents[1] / "femodes"
FD = 1e-6  # finite-difference step; central differences of these polynomials are exact to ~1e-9

finite = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False)


def laws_settings(n):
    return settings(max_examples=n, deadline=None, derandomize=True, database=None)


# ------------------------------------------------------------------------------- scalar references
def penalty_ref(u, gap, k):
    pen = u - gap
    return k * max(0.0, pen), (k if pen > 0.0 else 0.0), 0.5 * k * max(0.0, pen) ** 2


def cubic_ref(u, k3):
    return k3 * u**3, 3.0 * k3 * u**2, 0.25 * k3 * u**4


def complementarity_ref(p, u, gap, c):
    s = p - c * (gap - u)
    return p - max(0.0, s), (0.0 if s > 0.0 else 1.0), (-c if s > 0.0 else 0.0)


SAMPLES = np.array([[-2.0, -0.3, 0.0, 0.4], [0.999, 1.0, 1.001, 2.5]])  # (2, 4): "time x something"


# ------------------------------------------------------------------------------- vectorised values
def test_penalty_vectorised_against_scalar_reference():
    law = fm.PenaltyContact(at=0, gap=1.0, stiffness=7.5)
    p, dp = law.force(SAMPLES)
    V = law.potential(SAMPLES)
    assert p.shape == dp.shape == V.shape == SAMPLES.shape
    for idx, u in np.ndenumerate(SAMPLES):
        ref = penalty_ref(u, 1.0, 7.5)
        assert (p[idx], dp[idx], V[idx]) == ref  # the same formula, bit for bit
    np.testing.assert_array_equal(law.gap_function(SAMPLES), 1.0 - SAMPLES)
    # scalars in, 0-d arrays out
    assert law.force(2.0)[0] == pytest.approx(7.5) and law.force(0.0)[1] == 0.0


def test_cubic_vectorised_against_scalar_reference():
    for k3 in (1.3, -0.4):
        law = fm.CubicSpring(at="tip", k3=k3)
        f, df = law.force(SAMPLES)
        V = law.potential(SAMPLES)
        assert f.shape == df.shape == V.shape == SAMPLES.shape
        for idx, u in np.ndenumerate(SAMPLES):
            assert (f[idx], df[idx], V[idx]) == cubic_ref(u, k3)


def test_complementarity_vectorised_against_scalar_reference():
    law = fm.UnilateralContact(at=0, gap=0.5)
    P = np.array([[0.0, 0.2, -0.1, 3.0], [1.0, 0.0, 0.5, 0.0]])
    for c in (1.0, 40.0):
        r, drp, dru = law.residual(P, SAMPLES, c)
        assert r.shape == drp.shape == dru.shape == P.shape
        for idx, p in np.ndenumerate(P):
            assert (r[idx], drp[idx], dru[idx]) == complementarity_ref(p, SAMPLES[idx], 0.5, c)
    np.testing.assert_array_equal(law.gap_function(SAMPLES), 0.5 - SAMPLES)
    # broadcasting: one force history against one displacement history
    r, _, _ = law.residual(P[0], SAMPLES[0], 2.0)
    assert r.shape == (4,)


@laws_settings(60)
@given(p=finite, g=st.floats(min_value=-2.0, max_value=2.0, allow_nan=False), c=st.floats(0.1, 100.0))
def test_complementarity_function_zero_iff_signorini(p, g, c):
    """``r = 0`` exactly on ``{g_N >= 0, p >= 0, g_N p = 0}`` (for any c > 0)."""
    law = fm.UnilateralContact(at=0, gap=1.0)
    u = 1.0 - g  # so that g_N = g up to rounding
    gN = float(law.gap_function(u))
    r = float(law.residual(p, u, c)[0])
    # r = min(p, c g_N) (equivalently), up to the rounding of p - c g_N
    assert r == pytest.approx(min(p, c * gN), abs=4e-16 * (abs(p) + c * abs(gN) + 1.0))
    if p == 0.0 and gN >= 0.0 or gN == 0.0 and p >= 0.0:
        assert r == 0.0  # Signorini holds: exactly zero
    if p < 0.0 or gN < 0.0:
        assert r < 0.0  # tension or penetration
    if p > 0.0 and c * gN > 1e-12:
        assert r > 0.0  # force without contact


# ------------------------------------------------------------------------ generalized derivatives
def fd(fun, x, h=FD):
    return (fun(x + h) - fun(x - h)) / (2 * h)


def right(fun, x, h=FD):
    return (fun(x + h) - fun(x)) / h


def left(fun, x, h=FD):
    return (fun(x) - fun(x - h)) / h


def test_penalty_derivative_and_potential_by_finite_differences():
    law = fm.PenaltyContact(at=0, gap=0.3, stiffness=12.0)
    u = np.array([-1.0, 0.0, 0.29, 0.31, 0.8, 2.0])  # away from the kink u = 0.3
    p, dp = law.force(u)
    np.testing.assert_allclose(dp, fd(lambda x: law.force(x)[0], u), rtol=1e-7, atol=1e-7)
    # potential' = force, also across the kink (the potential is C^1)
    uu = np.r_[u, 0.3]
    np.testing.assert_allclose(fd(law.potential, uu), law.force(uu)[0], rtol=1e-7, atol=12.0 * FD)  # O(k h) at the kink
    # at the kink: one-sided slopes 0 (left) and k (right); the generalized derivative is the
    # inactive (left) one
    kink = law.gap
    assert law.force(kink)[1] == 0.0
    assert left(lambda x: law.force(x)[0], kink) == pytest.approx(0.0, abs=1e-12)
    assert right(lambda x: law.force(x)[0], kink) == pytest.approx(12.0, rel=1e-6)


def test_cubic_derivative_and_potential_by_finite_differences():
    law = fm.CubicSpring(at=0, k3=-2.5)
    u = np.linspace(-2.0, 2.0, 9)
    f, df = law.force(u)
    np.testing.assert_allclose(df, fd(lambda x: law.force(x)[0], u), rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(fd(law.potential, u), f, rtol=1e-7, atol=1e-7)


def test_complementarity_generalized_derivative():
    law = fm.UnilateralContact(at=0, gap=1.0)
    c = 4.0
    # away from the kink s = p - c g_N = 0: both branches
    p = np.array([0.5, -0.2, 2.0, 0.0])
    u = np.array([1.2, 0.4, 0.9, 0.5])  # s = 1.3, -2.6, 1.6, -2.0
    r, drp, dru = law.residual(p, u, c)
    np.testing.assert_allclose(drp, fd(lambda x: law.residual(x, u, c)[0], p), atol=1e-8)
    np.testing.assert_allclose(dru, fd(lambda x: law.residual(p, x, c)[0], u), atol=1e-7)
    np.testing.assert_array_equal(drp, [0.0, 1.0, 0.0, 1.0])
    np.testing.assert_array_equal(dru, [-c, 0.0, -c, 0.0])
    # at the kink (p = c g_N): the inactive side, (dr/dp, dr/du) = (1, 0), which is the one-sided
    # derivative in the direction that lowers s
    p0, u0 = 1.0, 0.75  # s = 1 - 4 * 0.25 = 0 exactly
    assert p0 - c * float(law.gap_function(u0)) == 0.0
    _, drp0, dru0 = law.residual(p0, u0, c)
    assert (float(drp0), float(dru0)) == (1.0, 0.0)
    assert left(lambda x: float(law.residual(x, u0, c)[0]), p0) == pytest.approx(1.0, rel=1e-6)
    assert right(lambda x: float(law.residual(x, u0, c)[0]), p0) == pytest.approx(0.0, abs=1e-6)
    assert left(lambda x: float(law.residual(p0, x, c)[0]), u0) == pytest.approx(0.0, abs=1e-6)
    assert right(lambda x: float(law.residual(p0, x, c)[0]), u0) == pytest.approx(-c, rel=1e-6)


# ------------------------------------------------------------------ the exactly projected HBM form
def test_positive_part_forms_restate_the_laws():
    pen = fm.PenaltyContact(at=0, gap=0.7, stiffness=30.0)
    slope, offset = pen.positive_part_form()
    assert (slope, offset) == (30.0, 0.7)
    u = np.linspace(-1.0, 3.0, 41)
    np.testing.assert_array_equal(slope * np.maximum(0.0, u - offset), pen.force(u)[0])
    uc = fm.UnilateralContact(at=0, gap=0.7)
    slope, offset = uc.positive_part_form(4.0)
    assert (slope, offset) == (4.0, 0.7)
    p = np.linspace(-0.5, 2.0, 41)
    np.testing.assert_allclose(p - np.maximum(0.0, p + slope * (u - offset)), uc.residual(p, u, 4.0)[0],
                               atol=1e-14)


def test_hbm_penalty_term_is_the_projection_of_the_law():
    """The exact projection in hbm/system.py equals the Galerkin projection of law.force on a fine
    grid (a quadrature of the same integral), for a signal entering contact."""
    law = fm.PenaltyContact(at=0, gap=0.5, stiffness=9.0)
    model = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(law)
    h = fm.Harmonics(3)
    from femodes.hbm.system import HBMSystem

    s = HBMSystem(model, h)
    Q = np.zeros((h.n_coef, 1))
    Q[0, 0], Q[h.layout.cos_index(1), 0], Q[h.layout.sin_index(1), 0] = 0.1, 0.8, 0.3
    r_nl = s.residual(s.join(Q), 1.0, forced=False)[0] - s.linear.apply(Q.ravel(), 1.0)
    N = 2**16
    E = h.grid.synthesis(2 * np.pi * np.arange(N) / N)
    weights = np.where(h.layout.harmonic_of == 0, 1.0 / N, 2.0 / N)
    ref = weights * (E.T @ law.force(E @ Q[:, 0])[0])
    np.testing.assert_allclose(r_nl, ref, atol=1e-7)  # midpoint-type quadrature of a kinked integrand


# ------------------------------------------------------------------------------------- stacking
def test_stacked_laws_evaluate_like_each_law():
    u = np.random.default_rng(3).uniform(-2.0, 2.0, size=(5, 3))
    groups = [
        [fm.PenaltyContact(at=0, gap=0.1, stiffness=2.0), fm.PenaltyContact(at="tip", gap=0.5, stiffness=7.0),
         fm.PenaltyContact(at=("tip", "w"), gap=0.0, stiffness=1.0)],
        [fm.CubicSpring(at=0, k3=1.0), fm.CubicSpring(at=1, k3=-0.5), fm.CubicSpring(at=1, k3=3.0)],
    ]
    for laws in groups:
        stacked = type(laws[0]).stack(laws)
        assert stacked.at == tuple(law.at for law in laws)
        f, df = stacked.force(u)
        V = stacked.potential(u)
        for j, law in enumerate(laws):
            np.testing.assert_array_equal(f[:, j], law.force(u[:, j])[0])
            np.testing.assert_array_equal(df[:, j], law.force(u[:, j])[1])
            np.testing.assert_array_equal(V[:, j], law.potential(u[:, j]))
    ucs = [fm.UnilateralContact(at=0, gap=0.2), fm.UnilateralContact(at=1, gap=1.0, c=5.0)]
    stacked = fm.UnilateralContact.stack(ucs)
    np.testing.assert_array_equal(stacked.gap_function(u[:, :2]), np.column_stack([ucs[0].gap_function(u[:, 0]),
                                                                                   ucs[1].gap_function(u[:, 1])]))
    assert np.isnan(stacked.c[0]) and stacked.c[1] == 5.0
    with pytest.raises(TypeError, match="PenaltyContact"):
        fm.PenaltyContact.stack([fm.CubicSpring(at=0, k3=1.0)])


def test_declarations_unchanged():
    with pytest.raises(ValueError, match="stiffness must be a finite positive number"):
        fm.PenaltyContact(at=0, gap=1.0, stiffness=0.0)
    with pytest.raises(ValueError, match="k3 must be non-zero"):
        fm.CubicSpring(at=0, k3=0.0)
    with pytest.raises(ValueError, match="gap must be a finite non-negative number"):
        fm.UnilateralContact(at=0, gap=-1.0)
    assert fm.UnilateralContact(at=0, gap=1.0) == fm.UnilateralContact(at=0, gap=1.0, c=None)
    assert hash(fm.CubicSpring(at=0, k3=2.0)) == hash(fm.CubicSpring(at=0, k3=2))


# ------------------------------------------------------------- one source for each formula
#: Law formulas as they were written out in the consumers before laws.py held them, matched on the
#: token stream of the code (comments and strings removed, tokens joined by one space).
FORMULAS = {
    "cube or quartic power (cubic spring)": r"\*\* [34]\b",
    "product with k3 (cubic spring)": r"\bk3\b (\[ [^]]* \] )?\*|\* (\w+ \. )*k3\b",
    "product with a stiffness (penalty)": r"\b(stiffness|kp_k)\b (\[ [^]]* \] )?\*|\* (\w+ \. )*(stiffness|kp_k)\b",
    "positive part maximum(0, .) (penalty, complementarity)": r"\bmaximum \( 0(\.0*)? ,",
    "arithmetic on a gap (gap function)": r"\b\w*gaps?\b (\[ [^]]* \] )?-(?!=)|(-|-=|\*) (\w+ \. )*\w*gaps?\b",
}
#: Lines of the former consumers: each pattern must catch at least one (the check is not vacuous).
FORMER = [
    "f = self.k3 * qS**3",
    "df = 3.0 * self.k3 * qS**2",
    "E += np.sum(0.25 * st.k3 * US**4, axis=1)",
    "np.add.at(f, self.kp_loc, np.where(act, self.kp_k * pen, 0.0))",
    "E += float(np.sum(0.5 * self.kp_k * np.maximum(0.0, qS[self.kp_loc] - self.kp_g) ** 2))",
    "r[idx] += law.stiffness * proj",
    "phi[0] -= ct.c * ct.law.gap",
    "out[:, j] = ci.stiffness[j] * np.maximum(0.0, u[:, ci.dofs[j]] - ci.gaps[j])",
    "G = st.c_gap[None, :] - U[:, st.c_dof]",
    "worst = max(float(np.max(E @ br.Q[:, :, dof].T)) - gap for dof, gap in zip(ci.dofs, ci.gaps))",
]


def code_tokens(text: str) -> str:
    """The code of ``text`` without comments and strings (docstrings state the formulas in words)."""
    skip = (tokenize.COMMENT, tokenize.STRING, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
            tokenize.ENDMARKER)
    return " ".join(t.string for t in tokenize.generate_tokens(io.StringIO(text).readline) if t.type not in skip)


def test_formula_patterns_are_meaningful():
    for name, pattern in FORMULAS.items():
        assert any(re.search(pattern, code_tokens(line)) for line in FORMER), name
    assert all(any(re.search(p, code_tokens(line)) for p in FORMULAS.values()) for line in FORMER)
    # and laws.py, where the formulas live, is caught by them
    laws = code_tokens((ROOT / "laws.py").read_text())
    assert sum(bool(re.search(p, laws)) for p in FORMULAS.values()) >= 4


@pytest.mark.parametrize("path", ["hbm/system.py", "time/moreau.py", "results/contacts.py", "results/solution.py"])
def test_consumers_do_not_restate_law_formulas(path):
    code = code_tokens((ROOT / path).read_text())
    found = {name: [m.group(0) for m in re.finditer(p, code)] for name, p in FORMULAS.items()}
    assert not any(found.values()), f"{path} writes law formulas itself: {found}"


def test_sweep_uses_the_branch_penetration():
    code = code_tokens(inspect.getsource(max_penetration))
    assert "penetration" in code and "synthesis" not in code
    assert not any(re.search(p, code) for p in FORMULAS.values())
