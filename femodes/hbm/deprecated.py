"""Discretise layer: attributes that moved to a collaborator, still found under their old names for one
release (a DeprecationWarning names the new spelling and points at the user's line).

A class lists its moved names in one table, ``{old name: new path}``, and forwards its
``__getattr__`` (called only for names the class does not have) to :func:`moved_attribute`. A
path is a chain of attributes, ``"layout.cos_index"``; a link ``term("A2")`` is a call with one
string argument.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Mapping
from typing import Any

from ..solvers.checks import user_stacklevel

__all__ = ["moved_attribute"]

_CALL = re.compile(r'(\w+)\("(\w+)"\)')


def moved_attribute(owner: Any, name: str, moved: Mapping[str, str]) -> Any:
    """The attribute ``name`` of ``owner`` found at its new path ``moved[name]`` (relative to
    ``owner``), with a DeprecationWarning that names the new spelling; AttributeError, as usual,
    for a name that is not in ``moved``."""
    cls = type(owner).__name__
    path = moved.get(name)
    if path is None:
        raise AttributeError(f"{cls!r} object has no attribute {name!r}")
    warnings.warn(f"{cls}.{name} is deprecated and will be removed in the next release; use {cls}.{path}",
                  DeprecationWarning, stacklevel=user_stacklevel())
    value = owner
    for link in path.split("."):
        call = _CALL.fullmatch(link)
        value = getattr(value, call[1])(call[2]) if call else getattr(value, link)
    return value
