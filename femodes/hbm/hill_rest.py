"""HBM layer: Hill's problem of an orbit on which the nonlinear forces act as at rest.

Below the first contact (the start of a forced curve, a backbone below its grazing energy) every
contact of an orbit is open over the whole period and the nonlinear forces' Jacobian is the one
at rest: the linearised system is time-invariant, and its Floquet exponents are the eigenvalues of
the linear system, whatever the amplitude and the frequency (the copies of Hill's spectrum are
then exact: the harmonics decouple). :func:`at_rest` tells such an orbit; the exponents found at
one such orbit serve the others (:func:`femodes.hbm.hill.hill_exponents`: only the period, and
with it the folding and the multipliers, change). Measured along the forced
curves of examples/blade_casing.py and examples/user_blade_3d.py: 21 of 38 and 18 of 38 points.
"""

from __future__ import annotations

import numpy as np

from .nonlinear_forces import Triplets

__all__ = ["at_rest", "XI_TOL"]

#: Largest change of the artificial damping ``xi`` (times the period) between two orbits at rest
#: whose exponents are taken as the same: ``xi`` moves an exponent by about ``xi / 2``, so the
#: multipliers then agree to about 5e-13 (a conservative backbone's ``xi`` is round-off; a damped
#: one's is constant below the first contact).
XI_TOL = 1e-12


def _nonlinear_jacobian(system, x: np.ndarray):
    Q = x[: system.nq].reshape(system.h.n_coef, system.n)
    jac = Triplets()
    system.nonlinear.add(x, Q, np.zeros(system.size), jac)
    return jac.matrix(system.size)


def at_rest(system, x: np.ndarray) -> bool:
    """Whether the nonlinear forces' Jacobian at the unknowns ``x`` of ``system`` is the one at
    ``x = 0``: no contact force, every contact open over the whole period (the same active set as
    at rest) and no smooth law away from its linearisation at zero."""
    x = np.asarray(x, dtype=float)
    if getattr(system, "nonlinear", None) is None or x.size != system.size or np.any(x[system.nq:]):
        return False  # not an HBMSystem's orbit, or a contact force somewhere
    cache = getattr(system, "_cache", {})
    if "hill_rest_jacobian" not in cache:  # the same at every orbit of the system
        cache["hill_rest_jacobian"] = _nonlinear_jacobian(system, np.zeros_like(x))
    N, N0 = _nonlinear_jacobian(system, x), cache["hill_rest_jacobian"]
    return N.shape == N0.shape and (N != N0).nnz == 0
