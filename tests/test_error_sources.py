"""Error estimates say what they cover (issue 35 item 4).

A branch's estimate names its sources (harmonic truncation always when estimated; the mesh when
:func:`femodes.estimate_mesh_error` ran), the mesh estimate (Richardson over two or three meshes,
at equal energy) is checked against closed forms on the clamped bar, and a backbone that is the
grazing family past grazing is never reported as converged.

References: the continuum's linear frequency of the clamped-free bar ``pi / 2`` (references.md:
P1 with consistent mass converges at order 2, error ``+(k h)^2 / 24``) and its first nonsmooth
mode (``tests/bar_stop_reference.py``, d'Alembert; confirmed by ``bar_stop_fd_check.py``).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import types

import numpy as np
import pytest

import femodes as fm
from .bar_stop_reference import first_nonsmooth_mode

GAP = 0.01
W1 = math.pi / 2
#: the continuum's grazing energy: the meshes are compared at the same physical energies
E_G = math.pi ** 2 * GAP ** 2 / 16


def bar(n_elements, mass=None):
    mesh = fm.line_mesh(length=1.0, n_elements=n_elements, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    extra = {} if mass is None else {"contact_mass": mass}
    return model.with_contact(fm.UnilateralContact(at="tip", gap=GAP), **extra)


@pytest.fixture(scope="module")
def linear_backbones():
    """Below grazing the backbone is the linear mode: 10, 20, 40 P1 elements, consistent mass."""
    out = {}
    for ne in (10, 20, 40):
        m = bar(ne, fm.ConsistentMass())
        eg = fm.grazing_energy(m)
        out[ne] = fm.nonlinear_mode(m, 1, energy=(0.05 * eg, 0.5 * eg), harmonics=3)
    return out


@pytest.fixture(scope="module")
def nonsmooth_backbones():
    """Past grazing: the first nonsmooth mode on 10, 20, 40 P1 elements (mass redistributed at the
    contact node, the default), H = 10, up to 6 E_g (about 6 s)."""
    out = {}
    for ne in (10, 20, 40):
        m = bar(ne)
        eg = fm.grazing_energy(m)
        out[ne] = fm.nonlinear_mode(m, 1, energy=(0.5 * eg, 6 * eg), harmonics=10)
    return out


def copy(branch):
    """A fresh branch with the same points (the estimators attach to the branch they are given)."""
    return fm.Branch(kind=branch.kind, harmonics=branch.harmonics, contacts=branch.contacts, omega=branch.omega,
                     Q=branch.Q, P=branch.P, energy=branch.energy, xi=branch.xi, residual_norm=branch.residual_norm,
                     nit=branch.nit, parameter=branch.parameter, success=branch.success, message=branch.message,
                     model=branch.model, meta=dict(branch.meta))


def test_harmonic_estimate_names_its_source(linear_backbones):
    """estimate_error alone covers the harmonic truncation, and says the mesh is not estimated;
    its numbers are those of before (frequency_error is the harmonic one)."""
    b = fm.estimate_error(copy(linear_backbones[10]), rtol=1e-3)
    acc = b.accuracy
    assert list(acc.sources) == ["harmonics"] and acc.mesh is None and acc.caveat is None
    assert acc.covers == "harmonic truncation only; mesh not estimated"
    assert np.array_equal(acc.frequency_error, acc.harmonic_frequency_error, equal_nan=True)
    assert np.array_equal(acc.value, np.fmax(acc.omega, acc.amplitude), equal_nan=True)
    assert acc.met.all()
    assert "covers harmonic truncation only; mesh not estimated" in acc.summary()
    assert "mesh not estimated" in repr(acc) and "points" in repr(acc)


def test_mesh_error_of_a_smooth_backbone_measures_order_two(linear_backbones):
    """Three meshes measure the order of the P1 bar's linear frequency (2, references.md) and the
    Richardson estimate of the 40-element error is the true one (against pi / 2) within 1 %;
    two meshes with the order stated within 2 %. Points of the fine branch outside the coarse
    branches' energies (each mesh has its own grazing energy) have no mesh estimate (NaN)."""
    fine = copy(linear_backbones[40])
    true = np.abs(fine.omega / W1 - 1)
    fm.estimate_mesh_error(fine, linear_backbones[20], coarser=linear_backbones[10])
    acc, info = fine.accuracy, fine.meta["mesh_error"]
    assert info["order_measured"] and info["order"] == pytest.approx(2.0, abs=0.01)
    assert info["sizes"] == pytest.approx([1 / 40, 1 / 20, 1 / 10])
    has = np.isfinite(acc.mesh)
    assert has.sum() >= len(fine) - 1 and info["extrapolated"] == has.sum()
    np.testing.assert_allclose(acc.mesh[has], true[has], rtol=1e-2)
    assert list(acc.sources) == ["mesh"] and not acc.harmonics_estimated
    assert acc.covers.startswith("mesh only (Richardson from 40, 20, 10 elements, order 2 measured")
    assert acc.covers.endswith("harmonic truncation not estimated")
    assert not acc.met.any()  # no rtol asked
    two = fm.estimate_mesh_error(copy(linear_backbones[40]), linear_backbones[20], order=2)
    np.testing.assert_allclose(two.accuracy.mesh[has], true[has], rtol=2e-2)
    assert "order 2 stated" in two.accuracy.mesh_method


def test_harmonic_and_mesh_sources_together(linear_backbones, tmp_path):
    """A harmonic estimate computed after the mesh's keeps it (and the other way round); the
    frequency error is their sum, met is judged on it, and both survive save and load."""
    fine = fm.estimate_mesh_error(copy(linear_backbones[40]), linear_backbones[20], order=2)
    fm.estimate_error(fine, rtol=1e-3)
    acc = fine.accuracy
    assert list(acc.sources) == ["harmonics", "mesh"]
    assert acc.covers.startswith("harmonic truncation and mesh (Richardson from 40, 20 elements, order 2 stated")
    total = acc.harmonic_frequency_error + acc.mesh
    np.testing.assert_array_equal(acc.frequency_error, total)
    assert np.array_equal(acc.met, np.isfinite(total) & (total <= 1e-3))
    np.testing.assert_array_equal(fine.error_estimate, np.fmax(acc.omega + acc.mesh, acc.amplitude))
    assert "(harmonic truncation " in acc.summary() and ", mesh " in acc.summary()
    # rtol 1e-5 is below the mesh error (6.4e-5 at 40 elements): met nowhere though H is converged
    tight = dataclasses.replace(acc, rtol=1e-5)
    assert np.nanmax(tight.harmonic_frequency_error) < 1e-5 and not tight.met.any()
    back = fm.load_branch(fine.save(tmp_path / "b.npz"))
    assert back.accuracy.covers == acc.covers and back.accuracy.caveat is None
    np.testing.assert_array_equal(back.accuracy.mesh, acc.mesh)
    again = fm.estimate_mesh_error(fine, linear_backbones[20], coarser=linear_backbones[10])
    assert list(again.accuracy.sources) == ["harmonics", "mesh"] and "measured" in again.accuracy.mesh_method


def _at(branch, values, rho):
    """``values`` over the branch's points, linear in log E at ``rho`` continuum grazing energies."""
    sel = (branch.energy > 1.5 * E_G) & (branch.energy < 6.5 * E_G) & np.isfinite(values)
    return float(np.interp(math.log(rho * E_G), np.log(branch.energy[sel]), values[sel]))


def test_mesh_error_of_the_nonsmooth_mode_against_the_continuum(nonsmooth_backbones):
    """The bar's first nonsmooth mode past grazing, H = 10, against the d'Alembert reference at 2
    and 5 E_g. The true error there (1.7e-3 and 7.2e-4 at 40 elements) includes the harmonic
    truncation, and the frequency error oscillates by about 3e-3 with the energy next to the
    internal-resonance tongues, so these meshes are not in an asymptotic range:

    * 40 against 20 elements, order 2 stated: the estimate is 1.1x and 0.54x the true error
      (tolerance: a factor 3 either way);
    * 40, 20 and 10 elements: most points past grazing are not extrapolated (changes of opposite
      sign, or growing: the estimate says how many) and their estimate is the larger change, on
      the safe side: 3.4x and 4.7x the true error (tolerance: at least 1x, at most 6x).

    This is no bound in general (issue 35's closing note has the table): 20 against 10 elements
    gives 0.09x at 2 E_g, and at 80 elements the truncation at H = 10 dominates the true error
    (3.7e-3 at 2 E_g), which a mesh estimate does not cover (0.19x).
    """
    fine = nonsmooth_backbones[40]
    rho = fine.energy / E_G
    ref = np.array([first_nonsmooth_mode(r)[0] if r > 0.82 else np.nan for r in rho])
    signed = fine.omega / ref - 1
    true = {r: abs(_at(fine, signed, r)) for r in (2, 5)}
    assert 5e-4 < true[2] < 3e-3 and 3e-4 < true[5] < 2e-3  # well above round-off (and the interpolation's 1e-4)

    two = fm.estimate_mesh_error(copy(fine), nonsmooth_backbones[20], order=2)
    for r in (2, 5):
        est = _at(two, two.accuracy.mesh, r)
        assert true[r] / 3 < est < 3 * true[r], (r, est, true[r])

    three = fm.estimate_mesh_error(copy(fine), nonsmooth_backbones[20], coarser=nonsmooth_backbones[10])
    info = three.meta["mesh_error"]
    assert info["extrapolated"] < info["compared"]
    assert f"{info['compared'] - info['extrapolated']} of {info['compared']} points not in the asymptotic range" in \
        three.accuracy.mesh_method
    for r in (2, 5):
        est = _at(three, three.accuracy.mesh, r)
        assert true[r] <= est < 6 * true[r], (r, est, true[r])


def test_grazing_family_is_never_converged(caplog):
    """past_grazing=None keeps the energy continuation's grazing family: its estimate of the
    harmonic truncation may meet rtol, but the branch is not the family that predicts the forced
    resonance: met nowhere, and the summary (and summary.txt) says why."""
    from femodes.app.cases import _summary_lines

    m = bar(10)
    eg = fm.grazing_energy(m)
    with caplog.at_level(logging.WARNING, logger="femodes"):
        g = fm.nonlinear_mode(m, 1, energy=(0.5 * eg, 6 * eg), harmonics=5, past_grazing=None, rtol=1e-2)
    acc = g.accuracy
    assert "family" not in g.meta and acc.caveat.startswith("grazing family: does not predict the forced resonance")
    assert not acc.met.any()
    assert "grazing family: does not predict the forced resonance" in acc.summary()
    assert any("met at no point: grazing family" in r.getMessage() for r in caplog.records)
    lines = _summary_lines(types.SimpleNamespace(name="bar"), m, g)
    assert any(line.startswith("error estimate (harmonic truncation): frequency largest") and
               "covers harmonic truncation only; mesh not estimated" in line for line in lines)
    assert any(line.startswith("grazing family: does not predict the forced resonance") for line in lines)
    # the same without an error estimate: summary.txt still says it
    plain = fm.nonlinear_mode(m, 1, energy=(0.5 * eg, 6 * eg), harmonics=5, past_grazing=None)
    assert any(line.startswith("grazing family") for line in _summary_lines(types.SimpleNamespace(name="bar"), m,
                                                                            plain))
    # the default traces the contact-phase family: no caveat
    b = fm.nonlinear_mode(m, 1, energy=(0.5 * eg, 6 * eg), harmonics=5)
    assert b.meta["family"] == "contact phase" and fm.estimate_error(b).accuracy.caveat is None
    # a mesh estimate between the two families is refused (checked before the meshes are)
    with pytest.raises(ValueError, match="different families"):
        fm.estimate_mesh_error(b, g, order=2)


def test_mesh_error_bad_input(linear_backbones):
    f, c = linear_backbones[40], linear_backbones[20]
    with pytest.raises(ValueError, match="give order="):
        fm.estimate_mesh_error(copy(f), c)
    with pytest.raises(ValueError, match="order must be a positive number"):
        fm.estimate_mesh_error(copy(f), c, order=-1)
    with pytest.raises(ValueError, match="from fine to coarse"):
        fm.estimate_mesh_error(copy(c), f, order=2)
    with pytest.raises(ValueError, match="sizes must be 2 positive"):
        fm.estimate_mesh_error(copy(f), c, order=2, sizes=[1.0])
    with pytest.raises(TypeError, match="femodes.Branch"):
        fm.estimate_mesh_error(copy(f), "coarse", order=2)
    m = bar(10, fm.ConsistentMass())
    other_h = fm.nonlinear_mode(m, 1, energy=(0.05 * fm.grazing_energy(m), 0.5 * fm.grazing_energy(m)), harmonics=5)
    with pytest.raises(ValueError, match="same harmonics"):
        fm.estimate_mesh_error(copy(f), other_h, order=2)
    forced = fm.frequency_response(bar(10).with_damping(beta=0.02).with_forcing(fm.HarmonicForce(at="tip",
                                                                                               amplitude=1e-4)),
                                   omega=(1.0, 1.2), harmonics=3)
    with pytest.raises(ValueError, match="only nonlinear modes"):
        fm.estimate_mesh_error(forced, forced, order=2)
    loaded = copy(c)
    loaded.model = None
    with pytest.raises(ValueError, match="give sizes="):
        fm.estimate_mesh_error(copy(f), loaded, order=2)


def test_period_driven_backbone_estimate_is_the_truncation_not_the_other_family():
    """Past grazing the levels of a period-driven backbone are solved from the branch's own orbits:
    the estimate is of the size of the truncation error (the bar, 20 elements, H = 10: 6e-4 to
    1.6e-2, against errors of 3e-4 to 7e-3 from the continuum's mode, which also hold the mesh's
    share), not the distance to the grazing family (0.06 to 0.6 when the levels were continued in
    the energy). Bound: a tenth of the distance between the families at 2 E_g (0.1 x 0.1)."""
    mesh = fm.line_mesh(1.0, 20, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_contact(fm.UnilateralContact(at="tip", gap=0.01)))
    eg = fm.grazing_energy(model)
    b = fm.nonlinear_mode(model, 1, energy=(0.5 * eg, 10 * eg), harmonics=10)
    assert b.meta["family"] == "contact phase"
    fm.estimate_error(b)
    eg_c = math.pi ** 2 * 0.01 ** 2 / 16
    past = (b.energy > 1.5 * eg_c) & np.isfinite(b.accuracy.omega)
    assert past.sum() >= 3
    assert np.all(b.accuracy.omega[past] < 0.05)  # not the 0.06-0.6 of the grazing family
    true = np.abs(b.omega[past] / first_nonsmooth_mode(b.energy[past] / eg_c)[0] - 1)
    assert np.median(b.accuracy.omega[past]) < 0.05 and np.all(true < 1e-2)
