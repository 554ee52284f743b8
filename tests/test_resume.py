"""Checkpoints and resume of long continuations (analyses layer).

A run with ``checkpoint=`` writes each converged point to a journal as it is found; a run
killed with SIGKILL at any moment is resumed with ``checkpoint=fm.Checkpoint(path, resume=True)``
and gives the branch of the uninterrupted run, every point exactly once. Damaged files, other
versions and checkpoints of a different run give clear errors naming the file and what differs.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import femodes as fm
from femodes.store import CHECKPOINT_VERSION, Checkpoint, CheckpointStore
from femodes.analyses import frequency_response_options
from femodes.solvers import ContinuationOptions, NewtonOptions

SPAN = (0.8, 1.6)
H = 10


def contact_oscillator(gap=1.0):
    """1-DOF oscillator against a stop: a branch with two located folds."""
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)).with_contact(fm.UnilateralContact(at=0, gap=gap)))


def options(callback=None):
    # the defaults of frequency_response, plus a callback
    return frequency_response_options(callback=callback)


@pytest.fixture(scope="module")
def model():
    return contact_oscillator()


@pytest.fixture(scope="module")
def reference(model):
    """The uninterrupted run."""
    ref = fm.frequency_response(model, omega=SPAN, harmonics=H)
    assert ref.success and len(ref) > 40 and len(ref.folds) == 2
    return ref


class Stop(Exception):
    pass


def interrupted(model, path, k, **kw):
    """Run with a checkpoint that dies (an exception in the callback) right after point k is saved."""

    def cb(point):
        if point.index == k:
            raise Stop

    with pytest.raises(Stop):
        fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=path, options=options(cb), **kw)
    return CheckpointStore(path)


def assert_same_branch(a, b):
    """No point lost or duplicated: same length, same points (to round-off), same folds."""
    assert len(a) == len(b)
    np.testing.assert_allclose(a.omega, b.omega, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.Q, b.Q, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.P, b.P, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(a.nit, b.nit)
    assert a.folds == b.folds
    assert (a.success, a.status) == (b.success, b.status)


SCRIPT = """
import sys, time
import femodes as fm
from femodes.analyses import frequency_response_options

model = (fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_damping(alpha=0.1)
         .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)).with_contact(fm.UnilateralContact(at=0, gap=1.0)))
# slowed down so that the parent can kill it in the middle of the branch
opts = frequency_response_options(callback=lambda point: time.sleep(0.03))
fm.frequency_response(model, omega={span}, harmonics={h}, options=opts, checkpoint=sys.argv[1])
"""


def test_sigkill_then_resume_loses_and_duplicates_no_point(model, reference, tmp_path):
    """SIGKILL a running continuation after >= 30 saved points, resume in-process: the final branch is
    the uninterrupted one (all points, both folds), the file loads back, the journal is gone."""
    script = tmp_path / "run.py"
    script.write_text(textwrap.dedent(SCRIPT.format(span=SPAN, h=H)))
    path = tmp_path / "frc.npz"
    ck = CheckpointStore(path)
    proc = subprocess.Popen([sys.executable, str(script), str(path)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 45.0
        while time.monotonic() < deadline and proc.poll() is None:
            if ck.journal.is_dir() and len(ck.indices()) >= 30:
                break
            time.sleep(0.01)
        assert proc.poll() is None, f"the run ended before it was killed: {proc.communicate()[1].decode()[-2000:]}"
        assert len(ck.indices()) >= 30, "the run did not reach 30 points in time"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    n_saved = len(ck.indices())
    assert 30 <= n_saved < len(reference) and not path.exists()

    resumed = fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(path, resume=True))
    assert_same_branch(resumed, reference)
    assert resumed.meta["checkpoint"]["analysis"] == "frequency_response"
    assert_same_branch(fm.load_branch(path), reference)
    assert sorted(os.listdir(tmp_path)) == ["frc.npz", "run.py"]  # the journal is removed


@pytest.mark.parametrize("where", ["fold", "end"])
def test_resume_after_fold_and_end_point(model, reference, tmp_path, where):
    """Interrupted right after the located fold point (the run continues from the point after
    it, so it is computed again) and the end point: same branch each time."""
    assert 0 < reference.folds[0] < len(reference) - 2
    k = reference.folds[0] if where == "fold" else len(reference) - 1
    path = tmp_path / "frc.npz"
    ck = interrupted(model, path, k)
    assert ck.indices() == list(range(k + 1))
    resumed = fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(path, resume=True))
    assert_same_branch(resumed, reference)


def test_resume_of_finished_run_returns_saved_branch(model, reference, tmp_path, monkeypatch):
    path = tmp_path / "frc.npz"
    first = fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=path)
    assert_same_branch(first, reference)
    assert os.listdir(tmp_path) == ["frc.npz"]
    # nothing is computed again
    monkeypatch.setattr("femodes.analyses.continuation", lambda *a, **k: pytest.fail("continuation called"))
    again = fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(path, resume=True))
    assert_same_branch(again, reference)
    assert again.model is model  # re-attached
    # an existing checkpoint is never overwritten by a new run (a path, or a Checkpoint without resume)
    for new_run in (path, str(path), fm.Checkpoint(path), fm.Checkpoint(path, resume=False)):
        with pytest.raises(FileExistsError, match=r"pass checkpoint=femodes\.Checkpoint\(path, resume=True\) to "
                                                  r"continue \(or return\) that run, or delete it to start over"):
            fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=new_run)


def test_resume_starts_a_new_run_when_there_is_no_checkpoint(tmp_path):
    m = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    ref = fm.nonlinear_mode(m, energy=(0.1, 10.0), harmonics=8)
    path = tmp_path / "nnm.npz"
    got = fm.nonlinear_mode(m, energy=(0.1, 10.0), harmonics=8, checkpoint=fm.Checkpoint(path, resume=True))
    assert_same_branch(got, ref)
    assert path.exists()


def test_nonlinear_mode_resume(tmp_path):
    m = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    kw = dict(energy=(0.1, 10.0), harmonics=8)
    ref = fm.nonlinear_mode(m, **kw)
    path = tmp_path / "nnm.npz"

    def cb(point):
        if point.index == 12:
            raise Stop

    # the defaults of nonlinear_mode (which keeps the iteration-count step control), plus a callback
    opts = ContinuationOptions(step=0.05, max_step=0.25, newton=NewtonOptions(atol=1e-9, max_iter=20), callback=cb,
                               target_angle=None, target_contraction=None, corrector_deadline=None)
    with pytest.raises(Stop):
        fm.nonlinear_mode(m, **kw, options=opts, checkpoint=path)
    got = fm.nonlinear_mode(m, **kw, checkpoint=fm.Checkpoint(path, resume=True))
    assert_same_branch(got, ref)
    np.testing.assert_allclose(got.energy, ref.energy, rtol=1e-12)
    # another mode (of another model) is another run
    other = fm.StructuralModel(M=np.eye(2), K=np.diag([1.0, 4.0]))
    with pytest.raises(ValueError, match="mode: 1 in the checkpoint, 2 in this call"):
        fm.nonlinear_mode(other, mode=2, **kw, checkpoint=fm.Checkpoint(path, resume=True))


def test_leftover_temporary_files_are_ignored(model, reference, tmp_path):
    """A kill during a write leaves a *.tmp file: never read, removed on resume."""
    path = tmp_path / "frc.npz"
    ck = interrupted(model, path, 10)
    (ck.journal / "00000011.npz.abc123.tmp").write_bytes(b"PK\x03\x04 half a point")
    resumed = fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(path, resume=True))
    assert_same_branch(resumed, reference)
    assert not ck.journal.exists()


@pytest.fixture
def journal(model, tmp_path):
    """A checkpoint interrupted after point 6."""
    return interrupted(model, tmp_path / "frc.npz", 6)


@pytest.mark.parametrize("how", ["truncated", "flipped", "empty", "wrong index"])
def test_damaged_point_file(model, journal, how):
    bad = journal.point_path(4)
    data = bytearray(bad.read_bytes())
    if how == "truncated":
        data = data[: len(data) // 2]
    elif how == "flipped":
        for i in range(len(data) // 2, len(data) // 2 + 8):  # inside the array data: the zip CRC catches it
            data[i] ^= 0xFF
    elif how == "empty":
        data = b""
    else:
        data = journal.point_path(5).read_bytes()
    bad.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="damaged") as info:
        fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(journal.path, resume=True))
    assert str(bad) in str(info.value)


def test_missing_point_file(model, journal):
    journal.point_path(3).unlink()
    with pytest.raises(ValueError, match="lacks point file 00000003.npz"):
        fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(journal.path, resume=True))


@pytest.mark.parametrize("change, pattern", [
    ({"version": CHECKPOINT_VERSION + 1}, "version"),
    ({"format": "something.else"}, "not a femodes checkpoint"),
    (None, "damaged"),
])
def test_damaged_or_other_version_header(model, journal, change, pattern):
    h = journal.header_path
    if change is None:
        h.write_text(h.read_text()[:20])
    else:
        h.write_text(json.dumps({**json.loads(h.read_text()), **change}))
    with pytest.raises(ValueError, match=pattern) as info:
        fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(journal.path, resume=True))
    assert str(h) in str(info.value)


@pytest.mark.parametrize("call, pattern", [
    (dict(harmonics=12), r"harmonics: \[10, \d+, 1\] in the checkpoint, \[12, \d+, 1\] in this call"),
    (dict(omega=(0.8, 1.7)), r"omega: \[0.8, 1.6\] in the checkpoint, \[0.8, 1.7\] in this call"),
    (dict(model=contact_oscillator(gap=0.9)), r"model.contacts"),
    (dict(model=contact_oscillator().with_damping(alpha=0.2)), r"model.matrices"),
    (dict(projection=fm.hbm.SampledProjection()), r"projection: 'ExactProjection\(roots=GridRoots\(per_harmonic=16\)\)' in the checkpoint"),
])
def test_resume_refuses_a_different_run(model, journal, call, pattern):
    kw = {**dict(model=model, omega=SPAN, harmonics=H), **call}
    with pytest.raises(ValueError, match=pattern) as info:
        fm.frequency_response(kw.pop("model"), **kw, checkpoint=fm.Checkpoint(journal.path, resume=True))
    assert "different run" in str(info.value) and str(journal.journal) in str(info.value)
    assert journal.indices() == list(range(7))  # nothing touched


def test_finished_file_of_a_different_run_or_damaged(model, tmp_path):
    m2 = fm.StructuralModel(M=[[1.0]], K=[[1.0]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    path = tmp_path / "nnm.npz"
    fm.nonlinear_mode(m2, energy=(0.1, 1.0), harmonics=4, checkpoint=path)
    with pytest.raises(ValueError, match="different run.*analysis: 'nonlinear_mode' in the checkpoint"):
        fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(path, resume=True))
    # a branch saved without a checkpoint is not taken for a finished run
    plain = tmp_path / "plain.npz"
    fm.load_branch(path).save(plain)
    data = np.load(plain)
    header = json.loads(str(data["header"]))
    header["meta"].pop("checkpoint")
    np.savez(plain, **{**{k: data[k] for k in data.files}, "header": np.array(json.dumps(header))})
    with pytest.raises(ValueError, match="not the result of a checkpointed run"):
        fm.nonlinear_mode(m2, energy=(0.1, 1.0), harmonics=4, checkpoint=fm.Checkpoint(plain, resume=True))
    # a damaged final file
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match="nnm.npz"):
        fm.nonlinear_mode(m2, energy=(0.1, 1.0), harmonics=4, checkpoint=fm.Checkpoint(path, resume=True))


def test_argument_errors(model, tmp_path):
    with pytest.raises(ValueError, match=r"frequency_response: checkpoint '.*frc\.txt': use a \.npz or \.h5"):
        fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=tmp_path / "frc.txt")
    with pytest.raises(TypeError, match=r"frequency_response: checkpoint must be a file name \(\.npz or \.h5\) or a "
                                        r"femodes\.Checkpoint.*got 3"):
        fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=3)
    with pytest.raises(TypeError, match="nonlinear_mode: checkpoint must be a file name.*got True"):
        fm.nonlinear_mode(model.without_forcing(), energy=(0.1, 1.0), harmonics=4, checkpoint=True)
    with pytest.raises(TypeError, match="unexpected keyword argument 'resume'"):  # one argument: checkpoint
        fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=tmp_path / "frc.npz", resume=True)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("args, kwargs, error, pattern", [
    ((3,), {}, TypeError, r"Checkpoint: path must be a file name \(\.npz or \.h5\), got 3"),
    ((None,), {}, TypeError, r"Checkpoint: path must be a file name .*got None"),
    (("out/frc.txt",), {}, ValueError, r"Checkpoint: path must be a \.npz or \.h5 file name .*got 'out/frc\.txt'"),
    (("out/frc",), {}, ValueError, r"Checkpoint: path must be a \.npz or \.h5 file name .*got 'out/frc'"),
    (("out/frc.npz",), {"resume": "yes"}, TypeError, r"Checkpoint: resume must be True or False, got 'yes'"),
    (("out/frc.npz",), {"resume": 1}, TypeError, r"Checkpoint: resume must be True or False, got 1"),
    (("out/frc.npz", True), {}, TypeError, r"positional argument"),  # resume is keyword-only
])
def test_checkpoint_spec_is_checked_at_construction(args, kwargs, error, pattern):
    with pytest.raises(error, match=pattern):
        fm.Checkpoint(*args, **kwargs)


def test_checkpoint_spec(tmp_path):
    ck = fm.Checkpoint(str(tmp_path / "frc.NPZ"))
    assert ck.path == tmp_path / "frc.NPZ" and isinstance(ck.path, Path) and ck.resume is False
    assert fm.Checkpoint(tmp_path / "a.h5", resume=True).resume is True
    assert fm.Checkpoint(tmp_path / "a.npz") == fm.Checkpoint(str(tmp_path / "a.npz"), resume=False)
    with pytest.raises(AttributeError):
        ck.resume = True  # frozen
    assert "Checkpoint" in fm.__all__ and fm.Checkpoint is Checkpoint


def test_h5_checkpoint(model, reference, tmp_path):
    pytest.importorskip("h5py")
    path = tmp_path / "frc.h5"
    interrupted(model, path, 20)
    resumed = fm.frequency_response(model, omega=SPAN, harmonics=H, checkpoint=fm.Checkpoint(path, resume=True))
    assert_same_branch(resumed, reference)
    assert_same_branch(fm.load_branch(path), reference)
