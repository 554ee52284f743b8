"""Validators and small helpers shared by the solvers (and usable by every layer above).

Each validator checks one kind of value and raises with a message that names the argument and
quotes the bad value: ``"<name> must be ..., got <value>"``.  Numpy scalars are shown as the
Python numbers they hold, so messages read the same whichever the caller passed.  Validators
return the value converted to the checked kind (``float``, ``int``, ``bool``, a read-only array),
so ``self.x = check_positive("x", x)`` validates and normalises in one line.

Who names an error.  A bad argument raises :class:`InputValueError` or :class:`InputTypeError`
(subclasses of ``ValueError`` and ``TypeError``, so ``except ValueError`` still catches them),
without saying which public function received it: helpers and validators do not know, and take
no ``owner``.  The public function or method the user called is decorated with
:func:`entry_point`, which catches these errors on the way out and starts their message with its
name (``"simulate: dt must be a positive finite number, got -1"``), once: an error already named
by an inner entry point (a public function calling another) passes through unchanged, so the
innermost entry point names it.  A frozen options dataclass names its errors with an
``@entry_point("ClassName")`` on ``__post_init__``.  Warnings and log lines cannot be caught
that way: a helper that warns reads the name with :func:`entry_name` (the innermost entry point
running, or ``None``).  Other exceptions (a user callback's, a failed solve's) are never renamed.

A block that must be named apart uses ``with named_by("name"):`` (``with_contact`` names a
contact's errors ``"with_contact: UnilateralContact: ..."`` so). The ``owner`` arguments of
``StructuralModel.dof``/``probe`` and ``DofMap.index``/``node_dofs`` are deprecated: still
honoured that way for a release, with a DeprecationWarning.

Besides the validators: :func:`is_operator` (the duck-typed test for structured Jacobians that
factorise themselves), :data:`LINSOLVE_ERRORS` (what a failed linear solve raises) and
:func:`available_memory` / :func:`check_memory` (an allocation that grows with the problem is
estimated and refused before it is made, naming its size and what to change).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import math
import numbers
import os
import sys
import warnings
from types import FrameType
from typing import Any, TypeVar
from collections.abc import Callable, Iterator

import numpy as np

__all__ = [
    "InputError",
    "InputTypeError",
    "InputValueError",
    "LINSOLVE_ERRORS",
    "available_memory",
    "check_memory",
    "check_bool",
    "check_callable",
    "check_int",
    "check_nonnegative",
    "check_positive",
    "check_vector",
    "entry_name",
    "entry_point",
    "named_by",
    "inf_norm",
    "is_operator",
    "is_real_number",
    "show",
    "start_vector",
    "strategy",
    "user_stacklevel",
]

#: Exceptions of a linear solve that mean "singular / failed factorisation" (LAPACK raises
#: ``LinAlgError``, SuperLU ``RuntimeError``; user solvers may raise ``ArithmeticError``).
LINSOLVE_ERRORS = (np.linalg.LinAlgError, RuntimeError, ArithmeticError)


def show(value: Any) -> str:
    """Representation of ``value`` for error messages (numpy scalars unwrapped)."""
    if isinstance(value, np.generic):
        value = value.item()
    return repr(value)


def is_real_number(value: Any) -> bool:
    """A real scalar (Python or numpy), booleans excluded."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


class InputError(Exception):
    """Mixin of the errors a public entry point names (see the module docstring): a bad argument,
    or a failure the arguments cause, whose message does not yet say which function was called."""

    #: The entry point that named the error (``None`` until one did).
    entry_point: str | None = None


class InputValueError(InputError, ValueError):
    """A bad argument value (a ``ValueError``), named by the public entry point that received it."""


class InputTypeError(InputError, TypeError):
    """An argument of the wrong type (a ``TypeError``), named by the public entry point that received it."""


_ENTRY: contextvars.ContextVar[str | None] = contextvars.ContextVar("femodes_entry_point", default=None)

_F = TypeVar("_F", bound=Callable[..., Any])


def _name(exc: InputError, name: str) -> None:
    if exc.entry_point is None:
        exc.entry_point = name
        if exc.args and isinstance(exc.args[0], str):
            exc.args = (f"{name}: {exc.args[0]}", *exc.args[1:])


def entry_point(name: str) -> Callable[[_F], _F]:
    """Decorator of a public function or method that receives user arguments: an
    :class:`InputError` leaving it, not yet named by an inner entry point, has ``"name: "``
    put in front of its message (the same exception object is re-raised, traceback kept)."""

    def decorate(func: _F) -> _F:
        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            with named_by(name):
                return func(*args, **kwargs)

        return wrapper  # type: ignore[return-value]

    return decorate


def entry_name() -> str | None:
    """Name of the innermost :func:`entry_point` (or :func:`named_by` block) running, for
    warnings and log lines; ``None`` outside any."""
    return _ENTRY.get()


@contextlib.contextmanager
def named_by(name: str | None) -> Iterator[None]:
    """The block form of :func:`entry_point`: an :class:`InputError` raised inside (not yet named)
    is named ``name`` at once, and :func:`entry_name` answers ``name`` there (``None``: nothing
    changes, the entry point around names them). For a part of a public call
    named apart (``ContinuationState``'s arrays) and for the ``owner`` arguments still accepted
    while the last modules move to entry points (:meth:`femodes.DofMap.index`)."""
    token = _ENTRY.set(name) if name else None
    try:
        yield
    except InputError as exc:
        if name:
            _name(exc, name)
        raise
    finally:
        if token is not None:
            _ENTRY.reset(token)


def check_finite(name: str, value: Any) -> float:
    """``value`` as a float: TypeError if it is not a real number, ValueError if not finite."""
    if not is_real_number(value):
        raise InputTypeError(f"{name} must be a real number, got {show(value)}")
    if not math.isfinite(value):
        raise InputValueError(f"{name} must be finite, got {show(value)}")
    return float(value)


def check_in_range(name: str, value: Any, lo: float, hi: float) -> float:
    """``value`` as a float in ``[lo, hi]`` (:func:`check_finite` first, then ValueError)."""
    v = check_finite(name, value)
    if not lo <= v <= hi:
        raise InputValueError(f"{name} must be in [{lo:g}, {hi:g}], got {show(value)}")
    return v


def check_positive(name: str, value: Any) -> float:
    """``value`` as a float; ValueError unless it is a finite real number > 0."""
    if not is_real_number(value) or not math.isfinite(value) or value <= 0:
        raise InputValueError(f"{name} must be a positive finite number, got {show(value)}")
    return float(value)


def check_nonnegative(name: str, value: Any) -> float:
    """``value`` as a float; ValueError unless it is a finite real number >= 0."""
    if not is_real_number(value) or not math.isfinite(value) or value < 0:
        raise InputValueError(f"{name} must be a finite number >= 0, got {show(value)}")
    return float(value)


def check_int(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int; TypeError unless it is an integer (bools and integral floats are
    not), ValueError if it is below ``minimum``."""
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)):
        raise InputTypeError(f"{name} must be an integer >= {minimum}, got {show(value)}")
    if value < minimum:
        raise InputValueError(f"{name} must be an integer >= {minimum}, got {show(value)}")
    return int(value)


def check_bool(name: str, value: Any) -> bool:
    """``value`` as a bool; TypeError unless it is a Python or numpy bool (0 and 1 are not)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InputTypeError(f"{name} must be a bool, got {show(value)}")
    return bool(value)


def check_callable(name: str, value: Any, *, optional: bool = True) -> Callable | None:
    """``value`` unchanged; TypeError unless it is callable (or ``None`` when ``optional``)."""
    if (value is None and not optional) or (value is not None and not callable(value)):
        what = "callable or None" if optional else "callable"
        raise InputTypeError(f"{name} must be {what}, got {show(value)}")
    return value


def check_vector(name: str, value: Any, *, size: int | None = None) -> np.ndarray:
    """``value`` as a read-only, finite, non-empty 1-D float array (of length ``size`` if given).

    An array that is already read-only is returned as is (no copy); otherwise a read-only copy.
    ValueError names the argument and what is wrong (type, shape, or non-finite entries).
    """
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputValueError(f"{name} must be a real 1-D array, got {show(value)}") from exc
    if a.ndim != 1 or a.size == 0 or (size is not None and a.size != size):
        want = f"({size},)" if size is not None else "a non-empty 1-D array"
        raise InputValueError(f"{name} has shape {a.shape}, expected {want}")
    if not np.all(np.isfinite(a)):
        raise InputValueError(f"{name} contains non-finite values (nan or inf)")
    if a.flags.writeable:
        a = a.copy()
        a.flags.writeable = False
    return a


def start_vector(value: Any, name: str = "x0") -> np.ndarray:
    """A starting point as a fresh (writable) finite, non-empty 1-D float array; ValueError
    naming ``name`` otherwise."""
    try:
        x = np.array(value, dtype=float)  # copy
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real 1-D array, got {show(value)}") from exc
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} contains non-finite values (nan or inf)")
    return x


def user_stacklevel() -> int:
    """The ``stacklevel`` that makes a warning raised by the caller of this function point at the
    first frame outside femodes, the standard library's decorator wrappers (``contextlib``) and
    generated code (a dataclass's ``__init__``): the user's line, however many decorators and
    helpers lie between."""
    frame: FrameType | None = sys._getframe(1)
    level = 1
    while frame is not None:
        module = str(frame.f_globals.get("__name__", ""))
        if not (module == "femodes" or module.startswith("femodes.") or module == "contextlib"
                or frame.f_code.co_filename.startswith("<")):
            break
        frame, level = frame.f_back, level + 1
    return level


def strategy(value: Any, name: str, table: dict, module: str, kind: str, accepts: Callable[[Any], bool]) -> Any:
    """``value`` as a strategy object of ``module`` (``"femodes.stability_methods"``): as it is
    when ``accepts(value)``; one of the deprecated names of ``table`` (name -> object) its
    object, with a DeprecationWarning that names the object to pass; a strategy class given
    without its parentheses, or anything else, an :class:`InputValueError` that says so (``kind``
    reads "a stability strategy", "an error method")."""
    classes = tuple(type(v) for v in table.values())
    if isinstance(value, type) and issubclass(value, classes):
        raise InputValueError(f"{name} must be a strategy object: {module}.{value.__name__}() (with the parentheses), "
                              "got the class")
    if accepts(value):
        return value
    if isinstance(value, str) and value in table:
        warnings.warn(f"{entry_name() or 'femodes'}: {name}={value!r} is deprecated; pass "
                      f"{name}={module}.{type(table[value]).__name__}()", DeprecationWarning,
                      stacklevel=user_stacklevel())
        return table[value]
    names = [f"{type(v).__name__}()" for v in table.values()]
    raise InputValueError(f"{name} must be {kind}: {module}.{', '.join(names[:-1])} or {names[-1]}, got {value!r}")


def is_operator(J: Any) -> bool:
    """A structured Jacobian that factorises itself: it has callable ``factorize`` and ``matvec``
    (duck typing, so that the solvers import nothing from femodes)."""
    return callable(getattr(J, "factorize", None)) and callable(getattr(J, "matvec", None))


def inf_norm(v: np.ndarray) -> float:
    """``max |v_i|`` (0 for an empty vector)."""
    return float(np.max(np.abs(v))) if v.size else 0.0


#: Fraction of the physical memory assumed available where the system does not say how much is
#: free (no psutil, no /proc/meminfo): other processes and the page cache hold the rest.
MEMORY_FALLBACK_FRACTION = 0.5


def available_memory() -> float | None:
    """Bytes this process can still allocate: the system's available memory (psutil, else Linux
    ``MemAvailable``, else :data:`MEMORY_FALLBACK_FRACTION` of the physical memory), capped by the
    address-space limit (``ulimit -v``); ``None`` if nothing can be read."""
    avail = None
    try:
        import psutil

        avail = float(psutil.virtual_memory().available)
    except Exception:  # noqa: BLE001 - psutil missing or failing: the next source
        try:
            with open("/proc/meminfo", encoding="ascii") as f:
                avail = next(float(line.split()[1]) * 1024 for line in f if line.startswith("MemAvailable:"))
        except (OSError, StopIteration, ValueError, IndexError):
            try:
                avail = MEMORY_FALLBACK_FRACTION * os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
            except (ValueError, OSError, AttributeError):
                avail = None
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY and soft > 0:
            avail = float(soft) if avail is None else min(avail, float(soft))
    except (ImportError, ValueError, OSError):
        pass
    return avail


def check_memory(need: float, what: str, fix: str) -> None:
    """ValueError when ``need`` bytes (the estimate of ``what``) exceed :func:`available_memory`:
    ``"<what> needs about 41.5 GiB, more than the 7.2 GiB available; <fix>"``."""
    avail = available_memory()
    if avail is not None and need > avail:
        raise InputValueError(f"{what} needs about {need / 2**30:.3g} GiB, more than the "
                              f"{avail / 2**30:.3g} GiB available; {fix}")
