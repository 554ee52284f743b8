"""Rules the test suite keeps about itself (issue 34): round-off-level assertions are rerun under
other BLAS kernels, and tolerances at that level come from the problem, not from one run."""

import re
from pathlib import Path

from .conftest import NUMERICS_MODULES

#: A literal tolerance or bound at the round-off level: 1e-9 and below.
TIGHT = re.compile(r"(rtol|atol|rel|abs)=[0-9.]*e-(9|1[0-9])\b|<=? *[0-9.]*e-(9|1[0-9])\b")
TESTS = Path(__file__).parent


def tight_literals(path: Path) -> int:
    return sum(1 for line in path.read_text().splitlines() if TIGHT.search(line))


def test_modules_with_round_off_level_literals_are_rerun_under_other_kernels():
    """A module with five or more round-off-level literal tolerances carries the `numerics` marker,
    so `make test-kernels` (and CI) runs it again under other OpenBLAS kernels and thread counts."""
    missing = sorted(p.stem for p in TESTS.glob("test_*.py") if tight_literals(p) >= 5 and p.stem not in NUMERICS_MODULES)
    assert not missing, f"add {missing} to NUMERICS_MODULES in tests/conftest.py"


def test_the_listed_modules_exist():
    stems = {p.stem for p in TESTS.glob("test_*.py")}
    assert NUMERICS_MODULES <= stems, sorted(NUMERICS_MODULES - stems)
