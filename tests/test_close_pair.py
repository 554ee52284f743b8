"""A close pair of modes with a stop that loads one of them (a rod of circular section with a tip
stop, as two DOFs): the backbone of the other grazes, and femodes says which mode to trace.

Two DOFs with ``M = I`` and ``K = R diag(1, 1.02) R^T`` (``R`` a rotation by 15 deg), a stop at
gap 1 on DOF 1: mode 1 moves the stop's DOF by ``sin 15``, mode 2 by ``cos 15``, so mode 2 reaches
it at ``E_g2 / E_g1 = 1.02 tan^2 15 = 0.0732`` of mode 1's grazing energy."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import femodes as fm

TH = math.radians(15.0)
R = np.array([[math.cos(TH), -math.sin(TH)], [math.sin(TH), math.cos(TH)]])
PAIR = fm.StructuralModel(M=np.eye(2), K=R @ np.diag([1.0, 1.02]) @ R.T).with_contact(fm.UnilateralContact(at=1, gap=1.0))


def test_close_partner_is_the_mode_the_stop_acts_on():
    lm = fm.linear_modes(PAIR, 2)
    j, ratio, energies = fm.resonance.close_partner(PAIR, 1, lm)
    # closed forms; the tolerance is round-off of a 2 x 2 eigenproblem
    assert j == 2
    assert ratio == pytest.approx(math.sqrt(1.02), rel=1e-12)
    assert energies == pytest.approx(1.02 * math.tan(TH) ** 2, rel=1e-10)
    assert fm.resonance.close_partner(PAIR, 2, lm) is None  # mode 2 reaches the stop first
    far = fm.StructuralModel(M=np.eye(2), K=R @ np.diag([1.0, 1.5]) @ R.T).with_contact(fm.UnilateralContact(at=1, gap=1.0))
    assert fm.resonance.close_partner(far, 1, fm.linear_modes(far, 2)) is None  # 22 % apart: not a pair


def test_the_grazing_backbone_and_the_forced_peak_name_the_partner(caplog):
    eg1 = fm.grazing_energy(PAIR, 1)
    bb1 = fm.nonlinear_mode(PAIR, 1, energy=(0.5 * eg1, 20 * eg1), harmonics=5)
    said = r"barely touch the stop\); mode 2, a close pair with it \(w_2 / w_1 = 1\.010\), reaches the contacts at " \
           r"0\.073 of its grazing energy.*nonlinear_mode\(model, 2, \.\.\.\)"
    assert re.search(said, bb1.meta["energy_continuation"])
    assert any(r.levelname == "WARNING" and re.search(said, r.getMessage()) for r in caplog.records)
    assert np.max(bb1.omega) < 1.001  # the grazing family: it does not stiffen
    eg2 = fm.grazing_energy(PAIR, 2)
    bb2 = fm.nonlinear_mode(PAIR, 2, energy=(0.5 * eg2, 20 * eg2), harmonics=5)
    assert np.max(bb2.omega) / math.sqrt(1.02) > 1.05  # mode 2's backbone stiffens on the stop
    forced = fm.frequency_response(PAIR.with_forcing(fm.HarmonicForce(at=1, amplitude=0.02)).with_damping(modal=0.01),
                                   (0.9, 1.4), 5)
    peak1 = fm.compare_resonance(bb1, [forced])[0]
    assert peak1.captured_by == 2
    assert "modes 1 and 2 are a close pair (w_2 / w_1 = 1.010) and the force drives mode 2" in peak1.predicted
    peak2 = fm.compare_resonance(bb2, [forced])[0]
    assert peak2.predicted.startswith("on the backbone"), peak2.predicted


def test_a_forced_branch_without_a_peak_is_said_to_have_none(caplog):
    """A span that stops before the resonance (a curved P2 bracket, forced to 1.4 w1 while its peak
    lies beyond, read "on the backbone, -0.73 %" at the span's end): no peak, and the fix."""
    eg2 = fm.grazing_energy(PAIR, 2)
    bb2 = fm.nonlinear_mode(PAIR, 2, energy=(0.5 * eg2, 20 * eg2), harmonics=5)
    model = PAIR.with_forcing(fm.HarmonicForce(at=1, amplitude=0.02)).with_damping(modal=0.01)
    short = fm.frequency_response(model, (0.8, 0.95), 5)
    assert np.argmax(short.energy) == len(short) - 1  # the response still rises at the span's end
    peak = fm.compare_resonance(bb2, short)[0]
    assert peak.at_end and peak.predicted.startswith("no peak: the forced branch's largest energy is at its end")
    assert any("forced branch 0 has no peak" in r.getMessage() and "widen" in r.getMessage() for r in caplog.records)
    whole = fm.compare_resonance(bb2, fm.frequency_response(model, (0.9, 1.4), 5))[0]
    assert not whole.at_end and whole.predicted.startswith("on the backbone")
