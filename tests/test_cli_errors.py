"""The command line's mistakes are one sentence: a bad or unwritable ``--out`` (exit 2), and a
sweep script without the ``if __name__ == "__main__":`` guard."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from femodes.app.cli import main

ROOT = Path(__file__).resolve().parents[1]


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
