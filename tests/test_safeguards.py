"""Nothing silent, nothing lost (issue 37): results reattached, resumed or reused are checked
against what produced them; long runs can be interrupted and resumed; allocations that grow with
H, contacts or DOFs are estimated first; every failure is one sentence naming its cause."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import femodes as fm

SPAN = (0.8, 1.6)


def contact_oscillator(gap=1.0, alpha=0.1, amplitude=0.2):
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=alpha)
            .with_forcing(fm.HarmonicForce(at=0, amplitude=amplitude))
            .with_contact(fm.UnilateralContact(at=0, gap=gap)))


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A short branch of the gap-1.0 oscillator, saved to a file."""
    model = contact_oscillator()
    br = fm.frequency_response(model, omega=(0.8, 1.0), harmonics=5)
    path = tmp_path_factory.mktemp("saved") / "frc.npz"
    br.save(path)
    return model, br, path


# -- item 1: a saved branch is tied to its model --------------------------------------------------
def test_load_branch_refuses_a_model_with_another_gap(saved):
    model, _, path = saved
    with pytest.raises(ValueError, match=r"contact 0 \(DOF 0\): gap 1 .* 0\.5"):
        fm.load_branch(path, model=contact_oscillator(gap=0.5))


def test_attach_refuses_other_damping_and_forcing(saved):
    model, _, path = saved
    br = fm.load_branch(path)
    with pytest.raises(ValueError, match="damping"):
        br.attach(contact_oscillator(alpha=0.2))
    with pytest.raises(ValueError, match="forcing"):
        br.attach(contact_oscillator(amplitude=0.3))
    with pytest.raises(ValueError, match="contact 0.*penalty"):
        br.attach(fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
                  .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2))
                  .with_contact(fm.PenaltyContact(at=0, gap=1.0, stiffness=100.0)))
    assert br.attach(contact_oscillator()).model is not None  # an equal model (another object) is fine


def test_in_memory_branch_attach_refuses_another_model(saved):
    _, br, _ = saved
    with pytest.raises(ValueError, match="gap"):
        br.attach(contact_oscillator(gap=0.5))


def test_old_branch_file_without_fingerprint_loads_with_a_warning(saved, tmp_path):
    from femodes.store import read_record, write_record

    _, _, path = saved
    header, arrays = read_record(path)
    header.pop("model")
    old = write_record(tmp_path / "old.npz", header, arrays)
    with pytest.warns(UserWarning, match="cannot be checked"):
        br = fm.load_branch(old, model=contact_oscillator())
    assert br.model is not None
    with pytest.raises(ValueError, match="gap"):  # the contacts stored in every file are still compared
        fm.load_branch(old, model=contact_oscillator(gap=0.5))
