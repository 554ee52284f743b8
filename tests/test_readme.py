"""README.md: every Python block runs as written, on its own, from the repository root (a fresh
copy of its layout, so that earlier outputs do not interfere).

Each block is written to a script of its own and run in a fresh interpreter (as a user who pastes
it into a file would), so a block that depends on an earlier one, lacks an import, or needs an
``if __name__ == "__main__":`` guard fails here. The files the README names exist, and the case
files it uses are accepted by the commands it shows them with, and the documentation pages it
links to exist. (The longer blocks moved to the documentation pages, whose blocks
tests/test_docs.py runs the same way; so did the `femodes scaling` command checked below.)
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
BLOCKS = re.findall(r"^```python\n(.*?)^```", README, flags=re.S | re.M)


def test_readme_has_python_blocks():
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_readme_python_block_runs_on_its_own(index, tmp_path):
    # the repository's layout (meshes/, examples/, femodes/) in a fresh folder, so that the
    # blocks' outputs (out/...) start empty whatever earlier runs left in the working tree
    root = tmp_path / "repo"
    root.mkdir()
    for name in ("meshes", "examples", "femodes"):
        (root / name).symlink_to(ROOT / name)
    script = tmp_path / f"readme_block_{index}.py"
    script.write_text(BLOCKS[index], encoding="utf-8")
    env = {k: v for k, v in __import__("os").environ.items() if k != "PYTHONPATH"}
    env["MPLBACKEND"] = "Agg"
    # twice for blocks that write outputs: they must also run again over them
    writes = re.search(r"save|write|out/|savefig|Checkpoint|animate|\.h5|\.npz", BLOCKS[index]) is not None
    for attempt in range(2 if writes else 1):
        r = subprocess.run([sys.executable, str(script)], cwd=root, capture_output=True, text=True, timeout=300,
                           env=env)
        assert r.returncode == 0, f"README block {index} failed (run {attempt + 1}):\n{BLOCKS[index]}\n{r.stderr[-3000:]}"


def test_readme_names_existing_files():
    for rel in sorted(set(re.findall(r"(?:examples|meshes|benchmarks)/[\w./-]+\.(?:toml|py|msh|md)", README))):
        assert (ROOT / rel).is_file(), f"README names {rel}, which does not exist"


def test_readme_links_exist():
    for rel in sorted(set(re.findall(r"\]\(((?:docs|examples|benchmarks)/[\w./-]+|CHANGELOG\.md)\)", README))):
        assert (ROOT / rel).is_file(), f"README links to {rel}, which does not exist"


def test_scaling_case_in_docs_accepts_elements(tmp_path):
    """The `femodes scaling` command of the how-to page (docs/howto/scaling-and-sweeps.md, where it
    moved from the README) uses a shipped case that --elements can vary."""
    page = (ROOT / "docs" / "howto" / "scaling-and-sweeps.md").read_text(encoding="utf-8")
    cmd = re.search(r"^femodes scaling (\S+\.toml) --elements", page, flags=re.M)
    assert cmd, "docs/howto/scaling-and-sweeps.md shows no `femodes scaling CASE --elements ...` command"
    r = subprocess.run([sys.executable, "-m", "femodes.app.cli", "scaling", cmd.group(1), "--elements", "10,20",
                        "--harmonics", "3", "--repeat", "1", "--points", "2", "--out", str(tmp_path), "--no-progress"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "| 10 |" in r.stdout and "| 20 |" in r.stdout
