"""The type hints of the public face are checked: mypy on the modules of ``[tool.mypy]`` in
pyproject.toml (``make typecheck``) reports no error. A hint that disagrees with the code fails
here, not in a user's type checker."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_mypy_on_the_checked_modules(monkeypatch):
    monkeypatch.chdir(ROOT)  # the config's files are relative to the repository
    api = pytest.importorskip("mypy.api", reason="mypy is in the test extra: pip install -e .[test]")
    out, err, status = api.run(["--config-file", str(ROOT / "pyproject.toml"), "--cache-dir", "/dev/null",
                                "--no-error-summary"])
    assert status == 0, f"mypy found errors:\n{out}{err}"
