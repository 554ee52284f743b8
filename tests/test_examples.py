"""Examples are executable documentation: import them and assert their physical numbers."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
BENCHMARKS = EXAMPLES.parent / "benchmarks"


def load(name, folder=EXAMPLES):
    """The script ``folder/name.py`` as a module (examples by default; benchmarks, studies)."""
    spec = importlib.util.spec_from_file_location(name, Path(folder) / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_two_dof_modes_example():
    ex = load("two_dof_modes")
    # exact (sqrt 5 -+ 1) / 2: the 10-digit literals were off by 5e-11, i.e. 0.8 of rtol=1e-10
    golden = (np.sqrt(5.0) + 1.0) / 2.0
    np.testing.assert_allclose(ex.modes.omega, [golden - 1.0, golden], rtol=1e-10)
    np.testing.assert_allclose(ex.ratios, [golden, 1.0 - golden], rtol=1e-9)


def test_cantilever_reduction_example(tmp_path):
    ex = load("cantilever_reduction")
    # 40 Hermite elements: (beta h)^4/1440 <= 1.1e-6 for mode 3; round-off ~ 3e-8
    assert np.all(np.abs(ex.error_vs_analytic) < 1.2e-6)
    # Craig-Bampton with 10 modes: upper bounds within 0.1 %
    assert np.all(ex.error_cb > -1e-7) and np.all(ex.error_cb < 1e-3)
    # moving the tip mass (1/80 of the beam mass) raises w1 by ~0.3 %, O(h)
    assert 0 < ex.redistribution_shift[0] < 1e-2
    png = ex.main(tmp_path)
    assert png.stat().st_size > 10_000


@pytest.mark.slow
def test_cli_demo(tmp_path):
    """``femodes demo`` end to end through the CLI in its own process (about 35 s; the demo
    itself is checked in the fast suite by tests/test_demo.py, which runs it in-process)."""
    out = tmp_path / "demo"
    r = subprocess.run([sys.executable, "-m", "femodes.app.cli", "demo", "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert (out / "cantilever_modes.png").is_file() and (out / "summary.txt").is_file()
    assert "outputs written to" in r.stdout


def test_cli_help_and_bad_command():
    h = subprocess.run([sys.executable, "-m", "femodes.app.cli", "--help"], capture_output=True, text=True, timeout=60)
    assert h.returncode == 0 and "demo" in h.stdout
    bad = subprocess.run([sys.executable, "-m", "femodes.app.cli", "nonsense"], capture_output=True, text=True, timeout=60)
    assert bad.returncode != 0 and "invalid choice" in bad.stderr
