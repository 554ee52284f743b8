"""Validators and small helpers shared by the solvers (and usable by every layer above).

Each validator checks one kind of value and raises with a message that names the argument and
quotes the bad value: ``"<owner>: <name> must be ..., got <value>"`` (the ``owner: `` prefix only
when ``owner`` is given, e.g. the public function or class that received the value).  Numpy
scalars are shown as the Python numbers they hold, so messages read the same whichever the
caller passed.  Validators return the value converted to the checked kind (``float``, ``int``,
``bool``, a read-only array), so ``self.x = check_positive("x", x)`` validates and normalises in
one line.

Besides the validators: :func:`is_operator` (the duck-typed test for structured Jacobians that
factorise themselves), :data:`LINSOLVE_ERRORS` (what a failed linear solve raises) and
:func:`available_memory` / :func:`check_memory` (an allocation that grows with the problem is
estimated and refused before it is made, naming its size and what to change).
"""

from __future__ import annotations

import math
import numbers
import os
from typing import Any
from collections.abc import Callable

import numpy as np

__all__ = [
    "LINSOLVE_ERRORS",
    "available_memory",
    "check_memory",
    "check_bool",
    "check_callable",
    "check_int",
    "check_nonnegative",
    "check_positive",
    "check_vector",
    "inf_norm",
    "is_operator",
    "is_real_number",
    "show",
    "start_vector",
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


def _prefix(owner: str | None) -> str:
    return f"{owner}: " if owner else ""


def check_finite(name: str, value: Any, *, owner: str | None = None) -> float:
    """``value`` as a float: TypeError if it is not a real number, ValueError if not finite."""
    if not is_real_number(value):
        raise TypeError(f"{_prefix(owner)}{name} must be a real number, got {show(value)}")
    if not math.isfinite(value):
        raise ValueError(f"{_prefix(owner)}{name} must be finite, got {show(value)}")
    return float(value)


def check_in_range(name: str, value: Any, lo: float, hi: float, *, owner: str | None = None) -> float:
    """``value`` as a float in ``[lo, hi]`` (:func:`check_finite` first, then ValueError)."""
    v = check_finite(name, value, owner=owner)
    if not lo <= v <= hi:
        raise ValueError(f"{_prefix(owner)}{name} must be in [{lo:g}, {hi:g}], got {show(value)}")
    return v


def check_positive(name: str, value: Any, *, owner: str | None = None) -> float:
    """``value`` as a float; ValueError unless it is a finite real number > 0."""
    if not is_real_number(value) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{_prefix(owner)}{name} must be a positive finite number, got {show(value)}")
    return float(value)


def check_nonnegative(name: str, value: Any, *, owner: str | None = None) -> float:
    """``value`` as a float; ValueError unless it is a finite real number >= 0."""
    if not is_real_number(value) or not math.isfinite(value) or value < 0:
        raise ValueError(f"{_prefix(owner)}{name} must be a finite number >= 0, got {show(value)}")
    return float(value)


def check_int(name: str, value: Any, minimum: int, *, owner: str | None = None) -> int:
    """``value`` as an int; TypeError unless it is an integer (bools and integral floats are
    not), ValueError if it is below ``minimum``."""
    if not isinstance(value, numbers.Integral) or isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{_prefix(owner)}{name} must be an integer >= {minimum}, got {show(value)}")
    if value < minimum:
        raise ValueError(f"{_prefix(owner)}{name} must be an integer >= {minimum}, got {show(value)}")
    return int(value)


def check_bool(name: str, value: Any, *, owner: str | None = None) -> bool:
    """``value`` as a bool; TypeError unless it is a Python or numpy bool (0 and 1 are not)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{_prefix(owner)}{name} must be a bool, got {show(value)}")
    return bool(value)


def check_callable(name: str, value: Any, *, owner: str | None = None, optional: bool = True) -> Callable | None:
    """``value`` unchanged; TypeError unless it is callable (or ``None`` when ``optional``)."""
    if (value is None and not optional) or (value is not None and not callable(value)):
        what = "callable or None" if optional else "callable"
        raise TypeError(f"{_prefix(owner)}{name} must be {what}, got {show(value)}")
    return value


def check_vector(name: str, value: Any, *, size: int | None = None, owner: str | None = None) -> np.ndarray:
    """``value`` as a read-only, finite, non-empty 1-D float array (of length ``size`` if given).

    An array that is already read-only is returned as is (no copy); otherwise a read-only copy.
    ValueError names the argument and what is wrong (type, shape, or non-finite entries).
    """
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{_prefix(owner)}{name} must be a real 1-D array, got {show(value)}") from exc
    if a.ndim != 1 or a.size == 0 or (size is not None and a.size != size):
        want = f"({size},)" if size is not None else "a non-empty 1-D array"
        raise ValueError(f"{_prefix(owner)}{name} has shape {a.shape}, expected {want}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{_prefix(owner)}{name} contains non-finite values (nan or inf)")
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


def check_memory(need: float, what: str, fix: str, *, owner: str | None = None) -> None:
    """ValueError when ``need`` bytes (the estimate of ``what``) exceed :func:`available_memory`:
    ``"<owner>: <what> needs about 41.5 GiB, more than the 7.2 GiB available; <fix>"``."""
    avail = available_memory()
    if avail is not None and need > avail:
        raise ValueError(f"{_prefix(owner)}{what} needs about {need / 2**30:.3g} GiB, more than the "
                         f"{avail / 2**30:.3g} GiB available; {fix}")
