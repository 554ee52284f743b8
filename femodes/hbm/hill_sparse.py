"""Discretise layer: Hill's exponents by shift-invert near the stability boundary (the sparse path
of :mod:`femodes.hbm.hill`, for Hill problems with more than ``DENSE_LIMIT`` unknowns with mass or
damping).

:class:`ShiftInvert` finds the exponents nearest a shift (ARPACK on the linearised pencil, one
sparse LU per shift); :func:`sparse_exponents` takes them at shifts along ``Re s = 0`` and follows
each shifted copy to the central member of its family. The selection that follows is
:func:`femodes.hbm.hill._hill`'s. Accuracy and cost: :doc:`/guide/stability` (Hill's method).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..eigen import krylov_start
from ..sparse_direct import factorize

__all__ = ["ShiftInvert", "sparse_exponents", "FOLLOW"]

log = logging.getLogger(__name__)

#: Shifted copies followed to their central member, rightmost first.
FOLLOW = 3

#: A member taken as central with a harmonic centroid farther than this from 0 (its content split
#: between two harmonics, where the choice of the central copy is ambiguous) is kept only if its
#: copy on the other side of the centre is found (:func:`_has_copy`).
EDGE = 0.4

#: ... found: an exponent near ``s + i m w/nu`` whose multiplier equals the member's to this
#: relative difference (the threshold of Hill's truncation check,
#: ``stability_methods.HARMONIC_CHANGE``: a multiplier that its own copy does not reproduce to
#: 1 % is not resolved by the truncation).
COPY_TOL = 1e-2


class ShiftInvert:
    """ARPACK shift-invert on the linearised Hill pencil, one sparse LU of ``J(sigma)`` per shift."""

    def __init__(self, J0, J1, J2):
        self.N = J0.shape[0]
        self.J0, self.J1, self.J2 = (sp.csc_matrix(A).astype(complex) for A in (J0, J1, J2))

    def near(self, sigma: complex, k: int):
        N, J1, J2 = self.N, self.J1, self.J2
        lu = factorize(self.J0 + sigma * J1 + sigma * sigma * J2)
        S1 = J1 + sigma * J2

        def op(y):
            y1, y2 = y[:N], y[N:]
            z1 = lu.solve(-(J2 @ y2) - S1 @ y1)
            return np.concatenate([z1, y1 + sigma * z1])

        L = spla.LinearOperator((2 * N, 2 * N), matvec=op, dtype=complex)
        # tol 1e-8 on the Ritz values of the shifted-inverted operator: the exponents to ~1e-8 of
        # their distance from the shift, far below what decides stability (measured: multipliers
        # unchanged to 1e-9 against tol 1e-12, at a tenth of the Arnoldi steps)
        theta, Z = spla.eigs(L, k=min(k, 2 * N - 2), which="LM", tol=1e-8, v0=krylov_start(2 * N, complex_=True))
        good = np.abs(theta) > 0
        return sigma + 1.0 / theta[good], Z[:N, good]


def sparse_exponents(J0, J1, J2, base: float, n_shifts: int, k: int, centroids: Callable[[np.ndarray], np.ndarray]):
    """Exponents nearest to shifts along the stability boundary, each replaced by the central
    member of its family.

    A shift finds some families only through a shifted copy (an exponent with ``Im s`` beyond
    ``w/2nu`` is nearest the shifts as ``s - i w/nu``), whose real part carries the truncation
    error of the harmonic it lost (measured: 13 % on a bar with a penalty stop). Each copy is
    therefore followed to its central member by one more shift-invert at
    ``s + i round(c) w/nu`` (``c`` its harmonic centroid: the copy whose content sits at
    harmonic ``c`` becomes central when multiplied by ``e^{-i c w t / nu}``), until ``|c| <= 1/2``.
    ``centroids(V)`` gives the harmonic centroids of the vectors ``V`` (:func:`femodes.hbm.hill._centroids`).
    """
    si = ShiftInvert(J0, J1, J2)
    found_s, found_V = [], []
    for j in range(n_shifts):
        # slightly right of the boundary (the boundary itself holds the trivial exponents of free
        # orbits, which make J(0) singular)
        sigma = 1e-3 * base + 1j * base * 0.5 * j / max(n_shifts - 1, 1)
        s, V = si.near(sigma, k)
        found_s.append(s)
        found_V.append(V)
    s, V = np.concatenate(found_s), np.hstack(found_V)
    cen = centroids(V)
    # follow only the copies that can decide stability: the FOLLOW rightmost (each follow costs a
    # factorisation and an Arnoldi run); the other copies are dropped
    copies = [i for i in np.argsort(-s.real) if round(float(cen[i])) != 0][:FOLLOW]
    central = [i for i in range(s.size) if round(float(cen[i])) == 0 and _has_copy(si, s[i], cen[i], base)]
    out_s, out_V = [s[i] for i in central], [V[:, i] for i in central]
    for i in copies:
        si_, vi = s[i], V[:, i]
        seen, lost = [si_], False
        for _ in range(4):
            m = round(float(centroids(vi[:, None])[0]))
            if m == 0:
                break
            s2, V2 = si.near(si_ + 1j * m * base, 2)
            j = int(np.argmin(np.abs(s2 - (si_ + 1j * m * base))))
            si_, vi = s2[j], V2[:, j]
            # back where it was: no copy lies a harmonic in, only another exponent (its conjugate):
            # a family of the truncation without a central member, left out by the dense selection's
            # count (FE cantilever of examples/cantilever_tip_stop.py, H = 10: Re s = 0.66, centroids
            # +-0.53, 1.59, ..., |mu| = 3.1 where the dense reductions converge to 1.00003)
            lost = any(abs(si_ - t) <= 1e-7 * base for t in seen)
            if lost:
                log.debug("hill_exponents: a family without a central member dropped (s = %s)", si_)
                break
            seen.append(si_)
        if not lost:
            out_s.append(si_)
            out_V.append(vi)
    s, V = np.asarray(out_s), np.column_stack(out_V)
    keep: list[int] = []  # the same exponent found twice counts once
    for i in np.argsort(np.abs(s)):
        if all(abs(s[i] - s[j]) > 1e-7 * base for j in keep):
            keep.append(int(i))
    return s[keep], V[:, keep]


def _has_copy(si: ShiftInvert, s: complex, c: float, base: float) -> bool:
    """Whether an exponent ``s`` of harmonic centroid ``c`` (``EDGE < |c| <= 1/2``; nearer the
    centre it is not tested) has its copy one harmonic across the centre, ``s + i m w/nu`` with
    ``m = sign(c)``, within :data:`COPY_TOL` of its multiplier (``exp((e - s - i m w/nu) T)`` for
    the exponent ``e`` found there, ``T = 2 pi / (w/nu)``).

    A genuine family has a copy at every harmonic shift the truncation resolves, and this one has
    its content as near the centre as the member's (centroid ``c - m``, ``|c - m| < 0.6``): it is
    resolved as well as the member itself, and gives the same multiplier. A family of the
    truncation without a central member has none: its members' real parts differ from one to the
    next, and the exponent nearest the target is the member's conjugate (FE cantilever of
    examples/cantilever_tip_stop.py, whole model, H = 10, at the peak of its backbone: ``Re s``
    = 0.41 w/nu, centroids +-0.48, ``|mu|`` = 13.5, the conjugate found 0.043 w/nu from the target,
    where the dense solves of 4 to 19 modes, which leave it out by their count, give 1.00003). A
    genuine period doubling passes: its conjugate is its copy, ``Im s = +-w/2nu``."""
    if abs(c) <= EDGE:
        return True
    m = 1.0 if c > 0 else -1.0
    target = complex(s) + 1j * m * base
    try:
        found, _ = si.near(target, 2)
    except (spla.ArpackError, RuntimeError) as exc:  # not tested: kept, as before the test existed
        log.debug("hill_exponents: the copy of s = %s not searched (%s)", s, exc)
        return True
    if found.size == 0:
        return False
    e = found[np.argmin(np.abs(found - target))]
    ok = abs(np.exp((e - target) * 2.0 * np.pi / base) - 1.0) <= COPY_TOL
    if not ok:
        log.info("hill_exponents: an exponent without its copy across the centre left out (s = %s, centroid %.2f, "
                 "|mu| = %.4g): a family of the truncation, not resolved by it", s, c, abs(np.exp(s * 2.0 * np.pi / base)))
    return bool(ok)
