"""What a new user meets in the first hour: natural mistakes get errors that say what to change,
downward spans cost what upward ones do, progress moves with the work, outputs are what they say.
"""

from __future__ import annotations

import io
import os
import re
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import femodes as fm
from femodes.app.cli import main
from femodes.app.progress import BranchProgress
from femodes.solvers import ContinuationPoint

ROOT = Path(__file__).resolve().parents[1]
OSC = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
       .with_contact(fm.UnilateralContact(at=0, gap=1.0))
       .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
FREE = OSC.without_forcing().with_damping()


# ---------------------------------------------------------------------------------------------
# spans, harmonics, indices
# ---------------------------------------------------------------------------------------------
def test_downward_span_costs_what_upward_costs():
    """Same curve both ways (shi & Legrand case 1, H = 10): the folds agree and the point counts
    are within 20 % (the step control sizes each step from the last one, so the two directions
    place their points differently: 53 up and 62 down measured; before the arclength scale was
    made direction-independent, downwards took 3.8x the points: 1146 against 305 at H = 20)."""
    up = fm.frequency_response(OSC, omega=(0.5, 2.0), harmonics=10)
    down = fm.frequency_response(OSC, omega=(2.0, 0.5), harmonics=10)
    assert up.success and down.success
    assert abs(len(down) - len(up)) <= 0.2 * len(up), (len(up), len(down))
    # folds are located to the continuation's fold tolerance (1e-9 relative in the tangent)
    np.testing.assert_allclose(np.sort(down.omega[list(down.folds)]), np.sort(up.omega[list(up.folds)]), rtol=1e-6)


def test_reversed_energy_span_is_refused_with_the_fix():
    with pytest.raises(ValueError, match=r"energy must increase.*energy=\(0\.1, 20\)"):
        fm.nonlinear_mode(FREE, mode=1, energy=(20.0, 0.1), harmonics=5)


def test_failed_start_of_a_backbone_says_what_to_change():
    br = fm.nonlinear_mode(FREE, mode=1, energy=(200.0, 1000.0), harmonics=10)  # Newton fails from the linear mode
    assert not br.success and len(br) == 0
    assert "start energy 200" in br.message and "lower energy" in br.message


@pytest.mark.parametrize("fn", [lambda h: fm.frequency_response(OSC, omega=(0.5, 2.0), harmonics=h),
                                lambda h: fm.nonlinear_mode(FREE, mode=1, energy=(0.1, 1.0), harmonics=h)],
                         ids=["frequency_response", "nonlinear_mode"])
def test_zero_harmonics_named(fn):
    with pytest.raises(ValueError, match=r"\bharmonics must be >= 1"):
        fn(0)


def test_harmonics_zero_refused():
    with pytest.raises(ValueError, match="n_harmonics must be >= 1"):
        fm.Harmonics(0)


def test_branch_index_error_names_the_length():
    br = fm.frequency_response(OSC, omega=(0.5, 0.6), harmonics=3)
    with pytest.raises(IndexError, match=rf"branch index 1000 is out of range for a branch of {len(br)} points"):
        br[1000]
    assert br[-1].omega == pytest.approx(0.6)


# ---------------------------------------------------------------------------------------------
# progress
# ---------------------------------------------------------------------------------------------
def _point(p, step, fold=False):
    return ContinuationPoint(x=np.zeros(1), p=p, tangent=np.zeros(2), nit=1, residual_norm=0.0, step=step,
                             is_fold=fold, index=0)


def test_progress_moves_through_a_fold():
    """Through a fold the parameter goes back; the display still changes with every point."""
    s = io.StringIO()
    bar = BranchProgress((0.5, 2.0), "w", stream=s, width=30)
    ps = [0.5, 1.0, 1.3, 1.38, 1.385, 1.3, 1.2, 1.08, 1.1, 1.5, 2.0]
    folds = {4, 7}
    lines = [bar.update(_point(p, 0.1 * (i > 0), i in folds)) for i, p in enumerate(ps)]
    assert len(set(lines)) == len(lines)  # every point changes what the user sees
    assert [int(re.search(r"point (\d+)", ln).group(1)) for ln in lines] == list(range(1, len(ps) + 1))
    arc = [float(re.search(r"s = ([0-9.]+)", ln).group(1)) for ln in lines]
    assert np.all(np.diff(arc) > 0)
    assert "<" in lines[6] and "back" in lines[6] and "fold 1 at 1.385" in lines[6]  # travelling back
    assert ">" in lines[-1] and "fold 2 at 1.08" in lines[-1]
    assert lines[-1].count("#") == 29  # the whole span reached (the cursor is the last cell)
    bar.close()
    assert s.getvalue().endswith("\n")


def test_progress_callable_receives_every_point():
    seen = []
    br = fm.frequency_response(OSC, omega=(0.5, 2.0), harmonics=5, progress=seen.append)
    assert len(seen) == len(br) and all(isinstance(p, ContinuationPoint) for p in seen)
    with pytest.raises(TypeError, match="progress must be"):
        fm.frequency_response(OSC, omega=(0.5, 2.0), harmonics=5, progress="yes")


# ---------------------------------------------------------------------------------------------
# the command line: a bad --out is one line, exit 2
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv", [["demo"], ["run", str(ROOT / "examples/cases/oscillator_frc.toml")],
                                  ["scaling", str(ROOT / "examples/cases/oscillator_frc.toml")],
                                  ["sweep", str(ROOT / "examples/cases/oscillator_frc.toml"), "--set",
                                   "contact.0.gap=1.0"]], ids=["demo", "run", "scaling", "sweep"])
def test_bad_out_is_one_line(argv, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main([*argv, "--out", str(blocker / "sub")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "--out" in err and "is a file, not a folder" in err


def test_unwritable_out_is_one_line(capsys):
    # /proc refuses new entries even to root (a chmod-based test would pass as root)
    assert main(["run", str(ROOT / "examples/cases/oscillator_frc.toml"), "--out", "/proc/femodes_test_out"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "is not writable" in err and "choose another --out" in err


# ---------------------------------------------------------------------------------------------
# small ones
# ---------------------------------------------------------------------------------------------
def test_damping_matrix_reported():
    assert "damping=matrix C" in repr(OSC)
    assert "damping=none" in repr(fm.StructuralModel(M=[[1.0]], K=[[1.0]]))


def test_modal_damping_repr_is_short():
    mesh = fm.line_mesh(1.0, 30, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    r = repr(model.with_damping(modal=0.02))
    assert "modal zeta=0.02 on 20 modes" in r and len(r) < 200
    r = repr(model.with_damping(modal=[0.01, 0.02, 0.05]))
    assert "modal zeta=0.01..0.05 on 3 modes" in r


def test_saved_files_follow_the_umask(tmp_path):
    br = fm.frequency_response(OSC, omega=(0.5, 0.6), harmonics=3)
    old = os.umask(0o022)
    try:
        for name in ("b.npz", "b.h5"):
            path = br.save(tmp_path / name)
            assert stat.S_IMODE(path.stat().st_mode) == 0o644, name
            plain = tmp_path / f"plain_{name}"
            plain.write_bytes(b"")
            assert stat.S_IMODE(plain.stat().st_mode) == 0o644
    finally:
        os.umask(old)


def test_unguarded_sweep_script_fails_in_one_sentence(tmp_path):
    script = tmp_path / "my_sweep.py"
    script.write_text(textwrap.dedent(f"""
        from femodes.app.sweep import run_sweep
        run_sweep({str(ROOT / "examples/cases/oscillator_frc.toml")!r}, {{"contact.0.gap": [1.0]}},
                  out={str(tmp_path / "out")!r})
    """))
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert r.returncode != 0
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("RuntimeError: run_sweep starts worker processes")
    assert 'if __name__ == "__main__":' in last
    assert len(r.stderr.splitlines()) < 15  # not the ~430 lines of Dask traceback
    assert not (tmp_path / "out").exists()  # refused before anything ran
