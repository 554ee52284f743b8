"""Hill's truncation check: the verdict of Hill's method with the perturbation cut to fewer harmonics.

Hill's problem truncates the perturbation of an orbit to the orbit's own ``H`` harmonics. Its
exponents converge with that truncation spectrally for smooth laws and slowly for complementarity
contacts (the Jacobian jumps at every contact event). :func:`femodes.hbm.hill.coarse_multipliers`
solves the block of the same pencil on the harmonics up to ``floor(0.75 H)``; a verdict that differs
between the two is not converged in the harmonics, and the stability runs say so.

References: the Mathieu equation (linear, smooth: converged at 9 harmonics for ``eps <= 1``); the
forced Duffing oscillator (smooth); the FE cantilever with a tip stop of
examples/cantilever_tip_stop.py reduced to 4 modes, whose Hill verdicts at H = 10, 20 and 30 do not
agree with each other (docs/guide/stability.md, "Hill's truncation check"; shooting there gives
|mu| = 2.89 at a point Hill's method calls stable at H = 20).
"""

import logging
import sys
from pathlib import Path

import numpy as np
import pytest

import femodes as fm
from femodes.hbm import HBMSystem
from femodes.hbm.hill import coarse_multipliers, hill_exponents
from femodes.stability_methods import checked_lead

sys.path.insert(0, str(Path(__file__).parent))
from test_hill import MathieuSystem  # noqa: E402

HERE = Path(__file__).parent


@pytest.mark.parametrize("delta", [0.2, 0.25, 1.0, 1.5])
@pytest.mark.parametrize("eps", [0.1, 1.0])
def test_mathieu_is_converged_at_the_coarse_truncation(delta, eps):
    # H = 12 against 9: the Mathieu exponents' truncation error at 9 harmonics is of order
    # (eps/4)^9 / (9!)^2 (far below round-off); the two eigen-solves of about 50 unknowns agree to
    # round-off, measured 1e-14 (the bound: 1e4 eps on multipliers of modulus up to 12)
    system = MathieuSystem(delta, eps)
    full = hill_exponents(system, np.zeros(0), 1.0).multipliers
    coarse = coarse_multipliers(system, np.zeros(0), 1.0, 0.0, None)
    assert coarse.size == 2  # one DOF: the central pair, selected as in the whole solve
    assert abs(abs(coarse[0]) - abs(full[0])) <= 1e4 * np.finfo(float).eps * max(1.0, abs(full[0]))


def test_too_few_harmonics_are_not_checked():
    assert coarse_multipliers(MathieuSystem(0.5, 0.1, H=1), np.zeros(0), 1.0, 0.0, None).size == 0


def oscillator_duffing():
    import scipy.sparse as sp

    m = fm.StructuralModel(M=sp.eye(1), K=sp.eye(1), C=0.1 * sp.eye(1))
    return m.with_forcing(fm.HarmonicForce(at=0, amplitude=1.0)).with_nonlinearity(fm.CubicSpring(at=0, k3=1.0))


def test_smooth_duffing_verdicts_pass_the_check(caplog):
    """The forced Duffing oscillator, H = 9 against 6: no verdict changes. Its unstable stretch
    between the folds holds one real multiplier above 1, the sign of the whole Jacobian's
    determinant, which the check leaves out (checked_lead): it compares the others."""
    with caplog.at_level(logging.WARNING, logger="femodes"):
        b = fm.frequency_response(oscillator_duffing(), (0.5, 4.0), 9, stability=fm.stability_methods.Hill())
    unstable = np.flatnonzero(~b.stable)
    assert unstable.size >= 3
    assert "not converged in the harmonics" not in caplog.text
    assert b.stability_unconverged == [] and "stability_checked" not in b.meta  # a real pair: nothing compared
    mid = int(unstable[unstable.size // 2])
    r = fm.stability(b[mid], fm.stability_methods.Hill())
    # one DOF: a real pair (1.86 and 0.42 here), both left out, at both truncations
    assert np.all(np.abs(r.multipliers.imag) <= 1e-8) and np.abs(r.multipliers[0]) > 1.5
    assert checked_lead(r.multipliers, False) == 0.0 and r.coarse == 0.0 and not r.unconverged(1e-4, False)
    # the smooth Duffing converges exponentially: 6 harmonics hold this point's multipliers to
    # 5e-5 (2e-9 to 2e-4 along the unstable stretch, largest near the upper fold, whose multiplier
    # +1 is the most sensitive), far below the check's threshold
    sol = b[mid]
    system = HBMSystem(sol.model, sol.harmonics)
    coarse = coarse_multipliers(system, system.join(sol.Q, sol.P), sol.omega, 0.0, None)
    assert np.abs(coarse) == pytest.approx(np.abs(r.multipliers), abs=1e-4)


@pytest.fixture(scope="module")
def cantilever_backbone():
    sys.path.insert(0, str(HERE.parent / "examples"))
    import cantilever_tip_stop as ct  # the model, its grazing energy and continuation options

    rom, eg = ct.MODELS["CB 4 modes"], ct.E_GRAZE
    return lambda: fm.nonlinear_mode(rom, 1, energy=(0.5 * eg, 20 * eg), harmonics=10, options=ct.OPTIONS,
                                     stability=fm.StabilityOptions(method=fm.stability_methods.Hill(), locate=False))


def test_a_contact_backbone_with_unconverged_verdicts_is_flagged(cantilever_backbone, caplog, tmp_path):
    """The cantilever reduced to 4 modes, H = 10: its Hill verdicts scatter (unstable at isolated
    points, |mu| up to 11.6) and change when the perturbation is cut to 7 harmonics: the run warns
    and lists them, and each listed point's own check agrees."""
    with caplog.at_level(logging.WARNING, logger="femodes"):
        b = cantilever_backbone()
    warnings = [r.getMessage() for r in caplog.records if "not converged in the harmonics" in r.getMessage()]
    assert len(warnings) == 1, caplog.text
    msg = warnings[0]
    n_bad, n_checked = (int(w) for w in msg.split("at ")[1].split(" points")[0].split(" of "))
    # measured 9 of 16: a branch whose verdicts are not worth much at H = 10
    assert n_bad >= 3 and n_checked >= n_bad
    listed = [int(part.split(" (")[0]) for part in msg.split("coarser truncation: ")[1].split("), ")[:3]]
    # kept with the branch, saved with it, and reported in a case's summary.txt
    assert b.stability_unconverged[:3] == listed and len(b.stability_unconverged) == n_bad
    assert b.meta["stability_checked"] == n_checked
    back = fm.load_branch(b.save(tmp_path / "cantilever.npz"))
    assert back.stability_unconverged == b.stability_unconverged
    from femodes.app.cases.reporting import stability_lines

    line = stability_lines(back)[1]
    assert line.startswith(f"Hill's truncation check: the verdict of {n_bad} of the {n_checked} points checked")
    caplog.clear()
    for i in listed:
        with caplog.at_level(logging.WARNING, logger="femodes"):
            r = fm.stability(b[i], fm.stability_methods.Hill())
        assert r.unconverged(1e-4, True), (i, r.coarse, np.abs(r.multipliers[:3]))
        assert "not converged in the harmonics" in caplog.text
        caplog.clear()


def test_shooting_results_are_not_checked():
    from femodes.stability_methods import StabilityResult, harmonic_check

    r = StabilityResult(multipliers=np.array([2.0 + 0j]), stable=False, method="shooting")
    assert harmonic_check(None, r) is r  # type: ignore[arg-type]
    assert not r.unconverged(1e-4, False)


def test_the_check_can_be_turned_off(caplog):
    """StabilityOptions(check=False): no truncation check, nothing kept; a bad value is refused."""
    sys.path.insert(0, str(HERE.parent / "examples"))
    import cantilever_tip_stop as ct

    eg = ct.E_GRAZE
    with caplog.at_level(logging.WARNING, logger="femodes"):
        b = fm.nonlinear_mode(ct.MODELS["CB 4 modes"], 1, energy=(0.5 * eg, 20 * eg), harmonics=10, options=ct.OPTIONS,
                              stability=fm.StabilityOptions(method=fm.stability_methods.Hill(), locate=False, check=False))
    assert not b.stable.all()  # unstable points there were, and none was checked
    assert "not converged in the harmonics" not in caplog.text
    assert b.stability_unconverged == [] and "stability_checked" not in b.meta
    with pytest.raises(TypeError, match="check must be True or False"):
        fm.StabilityOptions(check="yes")
