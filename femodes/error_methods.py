"""Analyses layer: the strategies of an error estimate, ``femodes.error_methods``
(:mod:`femodes.accuracy.methods`): ``Auto()`` (default), ``Shooting()``, ``Levels()``, for
``estimate_error(branch, method=...)`` and ``frequency_response(..., error_method=...)``.
"""

from .accuracy.methods import Auto, ErrorMethod, Levels, Shooting, as_error_method

__all__ = ["Auto", "Shooting", "Levels", "ErrorMethod", "as_error_method"]
