"""Unit tests of the solvers' building blocks: the shared validators (femodes.solvers.checks) and the
layering of femodes/solvers (bottom layer: imports nothing from femodes, no module reads another's
private names). Runs in well under a second."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import numpy as np
import pytest

from femodes.solvers.checks import (
    check_bool,
    check_callable,
    check_int,
    check_nonnegative,
    check_positive,
    check_vector,
    entry_point,
    is_operator,
    is_real_number,
    named_by,
    show,
    start_vector,
)

SOLVERS = Path(importlib.import_module("femodes.solvers").__file__).parent


# --------------------------------------------------------------------------- #
# validators
# --------------------------------------------------------------------------- #
def test_show_unwraps_numpy_scalars():
    assert show(np.float64(-1.0)) == "-1.0" and show(np.int64(3)) == "3" and show("a") == "'a'"


@pytest.mark.parametrize("value", [True, np.bool_(False), "1", None, 1j])
def test_is_real_number_rejects_bools_and_non_numbers(value):
    assert not is_real_number(value)


def test_validators_return_the_normalised_value():
    assert check_positive("a", np.float32(2.0)) == 2.0 and type(check_positive("a", 2)) is float
    assert check_nonnegative("a", 0) == 0.0
    assert check_int("n", np.int64(4), 1) == 4 and type(check_int("n", np.int64(4), 1)) is int
    assert check_bool("b", np.bool_(True)) is True
    assert check_callable("f", None) is None and check_callable("f", len) is len


@pytest.mark.parametrize(
    ("call", "exc", "message"),
    [
        (lambda: check_positive("atol", np.float64(-1.0)), ValueError,
         "atol must be a positive finite number, got -1.0"),
        (lambda: entry_point("Foo")(check_positive)("step", "x"), ValueError,
         "Foo: step must be a positive finite number, got 'x'"),
        (lambda: check_nonnegative("rtol", float("nan")), ValueError, "rtol must be a finite number >= 0, got nan"),
        (lambda: check_int("n", 2.0, 1), TypeError, "n must be an integer >= 1, got 2.0"),
        (lambda: check_int("n", True, 0), TypeError, "n must be an integer >= 0, got True"),
        (lambda: entry_point("bar")(check_int)("n", 0, 1), ValueError, "bar: n must be an integer >= 1, got 0"),
        (lambda: check_bool("flag", 1), TypeError, "flag must be a bool, got 1"),
        (lambda: check_callable("cb", 3), TypeError, "cb must be callable or None, got 3"),
        (lambda: check_callable("cb", None, optional=False), TypeError, "cb must be callable, got None"),
    ],
)
def test_validator_messages_name_the_argument_and_quote_the_value(call, exc, message):
    with pytest.raises(exc) as info:
        call()
    assert str(info.value) == message


def test_check_vector_read_only_and_shapes():
    a = check_vector("x", [1.0, 2.0])
    assert not a.flags.writeable and a.dtype == float
    assert check_vector("x", a) is a  # already read-only: no copy
    with pytest.raises(ValueError, match=r"^S: t has shape \(1,\), expected \(2,\)$"):
        with named_by("S"):
            check_vector("t", [1.0], size=2)
    with pytest.raises(ValueError, match="x has shape .* non-empty 1-D array"):
        check_vector("x", [[1.0]])
    with pytest.raises(ValueError, match="x contains non-finite values"):
        check_vector("x", [np.inf])
    with pytest.raises(ValueError, match="x must be a real 1-D array"):
        check_vector("x", ["a"])


def test_start_vector_is_a_fresh_writable_copy():
    x0 = np.array([1.0, 2.0])
    x = start_vector(x0)
    assert x is not x0 and x.flags.writeable and np.array_equal(x, x0)
    with pytest.raises(ValueError, match="u0 must be a non-empty 1-D array"):
        start_vector([], name="u0")


def test_is_operator_is_duck_typed():
    class Op:
        def factorize(self): ...
        def matvec(self, v): ...

    assert is_operator(Op()) and not is_operator(np.eye(2))


# --------------------------------------------------------------------------- #
# layering
# --------------------------------------------------------------------------- #
def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            yield node.level, node.module or "", [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield 0, a.name, []


@pytest.mark.parametrize("path", sorted(SOLVERS.glob("*.py")), ids=lambda p: p.name)
def test_solvers_import_nothing_from_femodes_and_no_private_names(path):
    for level, module, names in _imports(path):
        assert not module.startswith("femodes"), f"{path.name} imports {module}"
        assert level <= 1, f"{path.name} imports from outside femodes/solvers ({'.' * level}{module})"
        if level == 1:
            private = [n for n in names if n.startswith("_")]
            assert not private, f"{path.name} imports private names {private} from .{module}"


def test_illinois_finds_a_smooth_root_superlinearly():
    from femodes.solvers.roots import illinois

    calls = []

    def f(x):
        calls.append(x)
        return x ** 3 - 2.0

    br = illinois(f, 0.0, 2.0, -2.0, 6.0, max_iter=50, ftol=1e-14)
    root = 2.0 ** (1 / 3)
    x = br.lo if abs(br.f_lo) <= abs(br.f_hi) else br.hi
    assert abs(x - root) < 1e-13 and br.nfev == len(calls) < 15  # plain regula falsi needs ~40 here
    assert br.lo <= root <= br.hi


def test_illinois_stops_on_failed_evaluation_and_brackets_a_jump():
    from femodes.solvers.roots import illinois

    br = illinois(lambda x: None, 0.0, 1.0, -1.0, 1.0, max_iter=10)
    assert (br.lo, br.hi, br.nfev) == (0.0, 1.0, 1)
    # a jump at 0.3: the bracket closes on it; |f| stays 1 at both ends
    br = illinois(lambda x: -1.0 if x < 0.3 else 1.0, 0.0, 1.0, -1.0, 1.0, max_iter=100, xtol=1e-9,
                  bisect_if_slow=True)
    assert br.lo < 0.3 <= br.hi and br.hi - br.lo <= 2e-9 and (br.f_lo, br.f_hi) == (-1.0, 1.0)
