"""The documentation site builds without a warning (`make docs`: Sphinx with -W), and its API
reference documents every public name of ``femodes``."""

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

import femodes

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
API = "\n".join(p.read_text(encoding="utf-8") for p in sorted((DOCS / "api").glob("*.rst")))


def test_api_reference_documents_every_public_name():
    """Each name of ``femodes.__all__`` has an autodoc entry (``io`` and ``plot`` are modules with
    a section of their own)."""
    documented = set(re.findall(r"^\.\. auto(?:class|function|data)::\s+(\w+)", API, flags=re.M))
    missing = sorted(set(femodes.__all__) - documented - {"io", "plot"})
    assert not missing, f"add {missing} to docs/api/*.rst"
    assert "femodes.plot" in API and "femodes.io" in API


def test_docs_pages_name_existing_files():
    for page in DOCS.rglob("*.md"):
        if "_build" in page.parts:
            continue
        text = page.read_text(encoding="utf-8")
        for rel in sorted(set(re.findall(r"(?:examples|meshes|benchmarks)/[\w./-]+\.(?:toml|py|msh|md)", text))):
            assert (ROOT / rel).is_file(), f"{page.relative_to(ROOT)} names {rel}, which does not exist"


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("sphinx") is None,
                    reason="sphinx is not installed: the docs extra (pip install -e '.[docs]', or `make docs`)")
def test_sphinx_build_has_no_warnings(tmp_path):
    r = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q", str(DOCS),
                        str(tmp_path / "html")], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"sphinx build failed:\n{r.stdout[-3000:]}\n{r.stderr[-5000:]}"
    assert (tmp_path / "html" / "index.html").is_file()
