"""Progress of a continuation: the command line's bar moves with every point (through folds too),
and a callable ``progress=`` receives every accepted point."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest

import femodes as fm
from femodes.app.progress import BranchProgress
from femodes.solvers import ContinuationPoint

OSC = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]])
       .with_contact(fm.UnilateralContact(at=0, gap=1.0))
       .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


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


_QUIET_RUN = """
import femodes as fm
osc = (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
       .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))
br = fm.frequency_response(osc, omega=(0.5, 2.0), harmonics=5, progress={progress}, stability=True)
print(len(br))
"""


@pytest.mark.parametrize("progress", [True, False])
def test_progress_true_is_shown_without_a_logging_configuration(progress):
    """``progress=True`` in a script that configures no logging (Python then shows warnings only):
    a line per point on stderr, and the stability pass's; ``progress=False`` prints nothing there."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-c", _QUIET_RUN.format(progress=progress)], capture_output=True, text=True,
                       timeout=120, check=True)
    n = int(r.stdout.split()[-1])
    lines = re.findall(r"frequency_response: point (\d+)", r.stderr)
    if progress:
        assert [int(k) for k in lines] == list(range(1, n + 1)), r.stderr
        assert "stability:" in r.stderr
    else:
        assert lines == [] and "stability:" not in r.stderr, r.stderr


def test_progress_true_leaves_the_logging_configuration_as_it_was(caplog):
    """Under a configuration that drops INFO (pytest's capture, root at WARNING), ``progress=True``
    lets femodes' records through for the call only."""
    import logging

    logger = logging.getLogger("femodes")
    before = (logger.level, list(logger.handlers))
    br = fm.frequency_response(OSC, omega=(0.5, 2.0), harmonics=5, progress=True)
    points = [r for r in caplog.records if r.name == "femodes.runs" and "point" in r.getMessage()]
    assert len(points) == len(br)
    assert (logger.level, list(logger.handlers)) == before
    caplog.clear()
    fm.frequency_response(OSC, omega=(0.5, 2.0), harmonics=5)
    assert not [r for r in caplog.records if r.levelno < logging.WARNING and r.name.startswith("femodes")]
