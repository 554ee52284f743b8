"""The documentation site builds without a warning (`make docs`: Sphinx with -W), its API reference
documents every public name of ``femodes``, every Python block of its pages runs as written, on
its own, from the repository root (as the README's blocks do, tests/test_readme.py), and the
docstrings of ``femodes`` stay short (issue 39: behaviour and sources; the why goes to docs/)."""

import ast
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import femodes

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
API = "\n".join(p.read_text(encoding="utf-8") for p in sorted((DOCS / "api").glob("*.rst")))
PAGES = sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.relative_to(DOCS).parts)
BLOCKS = [(page.relative_to(DOCS).as_posix(), block) for page in PAGES
          for block in re.findall(r"^```python\n(.*?)^```", page.read_text(encoding="utf-8"), flags=re.S | re.M)]


def test_api_reference_documents_every_public_name():
    """Each name of ``femodes.__all__`` has an autodoc entry (``io``, ``plot`` and the strategy
    modules are modules with a section of their own)."""
    documented = set(re.findall(r"^\.\. auto(?:class|function|data)::\s+(\w+)", API, flags=re.M))
    modules = {"io", "plot", "stability_methods", "error_methods", "predictors"}
    missing = sorted(set(femodes.__all__) - documented - modules)
    assert not missing, f"add {missing} to docs/api/*.rst"
    assert "femodes.plot" in API and "femodes.io" in API
    assert "femodes.stability_methods" in API and "femodes.error_methods" in API and "femodes.predictors" in API


def test_docs_pages_name_existing_files():
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for rel in sorted(set(re.findall(r"(?:examples|meshes|benchmarks)/[\w./-]+\.(?:toml|py|msh|md)", text))):
            assert (ROOT / rel).is_file(), f"{page.relative_to(ROOT)} names {rel}, which does not exist"


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=[f"{p}:{i}" for i, (p, _) in enumerate(BLOCKS)])
def test_docs_python_block_runs_on_its_own(index, tmp_path):
    page, block = BLOCKS[index]
    root = tmp_path / "repo"  # the repository's layout in a fresh folder: outputs (out/...) start empty
    root.mkdir()
    for name in ("meshes", "examples", "femodes"):
        (root / name).symlink_to(ROOT / name)
    script = tmp_path / "block.py"
    script.write_text(block, encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["MPLBACKEND"] = "Agg"
    # twice for blocks that write outputs: they must also run again over them
    writes = re.search(r"save|write|out/|Checkpoint|\.h5|\.npz", block) is not None
    for attempt in range(2 if writes else 1):
        r = subprocess.run([sys.executable, str(script)], cwd=root, capture_output=True, text=True, timeout=300, env=env)
        assert r.returncode == 0, f"{page}: block failed (run {attempt + 1}):\n{block}\n{r.stderr[-3000:]}"


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("sphinx") is None,
                    reason="sphinx is not installed: the docs extra (pip install -e '.[docs]', or `make docs`)")
def test_sphinx_build_has_no_warnings(tmp_path):
    r = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q", str(DOCS),
                        str(tmp_path / "html")], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"sphinx build failed:\n{r.stdout[-3000:]}\n{r.stderr[-5000:]}"
    assert (tmp_path / "html" / "index.html").is_file()


#: Longest docstring, in lines (the closing quotes' line included).
DOCSTRING_MAX_LINES = 40
#: Docstrings allowed up to 50 lines, with the reason.
DOCSTRING_EXCEPTIONS = {
    ("femodes/solvers/continuation_types.py", "ContinuationOptions"):
        "19 parameters, each with its type, default and behaviour in one to three lines",
}


def _docstrings(tree):
    """``(qualified name, docstring)`` of the module and of every class and function in it."""
    yield "<module>", ast.get_docstring(tree, clean=False)
    stack = [(node, "") for node in tree.body]
    while stack:
        node, prefix = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            name = prefix + node.name
            yield name, ast.get_docstring(node, clean=False)
            stack.extend((child, name + ".") for child in node.body)
        else:
            stack.extend((child, prefix) for child in ast.iter_child_nodes(node)
                         if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.If, ast.Try)))


def test_docstrings_are_at_most_40_lines():
    """Docstrings state behaviour and cite sources; measurements, history and reasons live in the
    guide and the benchmark notes (docs/). Long ones are named with their length."""
    too_long = []
    for path in sorted((ROOT / "femodes").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for name, doc in _docstrings(ast.parse(path.read_text(encoding="utf-8"))):
            if doc is None:
                continue
            lines = doc.count("\n") + 1
            limit = 50 if (rel, name) in DOCSTRING_EXCEPTIONS else DOCSTRING_MAX_LINES
            if lines > limit:
                too_long.append(f"{rel} {name}: {lines} lines (at most {limit})")
    assert not too_long, "docstrings too long:\n" + "\n".join(too_long)


def test_docstring_exceptions_are_still_needed():
    for (rel, name), reason in DOCSTRING_EXCEPTIONS.items():
        docs = dict(_docstrings(ast.parse((ROOT / rel).read_text(encoding="utf-8"))))
        assert name in docs and reason, f"{rel} {name}: no such object"
        assert docs[name].count("\n") + 1 > DOCSTRING_MAX_LINES, f"{rel} {name} fits now: drop its exception"
