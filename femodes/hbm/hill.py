r"""Discretise layer: Floquet exponents of a harmonic balance solution by Hill's method.

A perturbation ``y(t) = e^{s t} p(t)`` of a periodic solution, ``p`` periodic with the solution's
period ``T = 2 pi nu / w``, solves the linearised equations of motion when ``s`` is a *Floquet
exponent*; the Floquet multipliers are ``mu = exp(s T)``. Expanding ``p`` on the same harmonics
as the solution, ``d/dt`` acts on the coefficients as ``w D1 + s``, so the harmonic balance
Jacobian ``J0`` of the solution becomes the quadratic matrix polynomial (Hill's problem; Lazarus
and Thomas, C. R. Mecanique 338 (2010) 510-517; Krack and Gross, *Harmonic Balance for
Nonlinear Vibration Problems*, 2019, sec. 3.6)

.. math::

    \bigl(J_0 + s\,J_1 + s^2 J_2\bigr)\,v = 0, \qquad
    J_1 = I \otimes (C - \xi M) + 2\omega\,D_1 \otimes M, \qquad J_2 = I \otimes M,

on the displacement unknowns (zero on the contact-force unknowns, whose equations are algebraic).
The contact and nonlinear terms enter through ``J0`` only: the generalized Jacobian of the
projected laws (for a complementarity contact, the linearised law holds the contact DOF on the
obstacle during the contact phases and frees its force elsewhere).

Selection of the meaningful exponents. The truncated Hill spectrum holds each exponent ``s``
together with copies ``s + i m w / nu`` whose eigenvectors are the same motion written with the
harmonics shifted by ``m``; all give the same multiplier, and the copies near the truncation edge
are inaccurate. Each eigenvector's *harmonic centroid* (the mass-weighted mean of the harmonic
index of its complex Fourier coefficients ``e^{i m w t / nu}``, ``m = -H .. H``) tells the copies
apart: the central copy has the centroid nearest to 0 (the symmetric-eigenvector criterion of
Guillot, Lazarus, Thomas, Vergez and Cochelin, J. Comput. Phys. 416 (2020) 109477, in a
weighted form). Exponents are taken in order of increasing ``|centroid|``, a copy of an exponent
already taken (``s`` differing by a nonzero multiple of ``i w / nu``, as the two members
``+- i w / 2 nu`` of a period-doubling family do) is skipped, until ``2 n_m`` exponents are held
(``n_m`` the DOFs with mass).

Solvers. Small problems (up to :data:`DENSE_LIMIT` unknowns) solve the linearised pencil densely
(one shift-and-invert of the whole spectrum). Larger ones use ARPACK in shift-invert mode with one
sparse LU of the complex Hill matrix ``J(sigma)`` per shift, the shifts placed along the
stability boundary (``Re s = 0``) in the central strip ``0 <= Im s <= w / 2 nu``, and every
exponent found is followed to the central member of its family: the exponents nearest the
boundary are found (not all ``2 n_m``: ``HillResult.complete`` is False); an exponent far to the
right of the boundary, farther than the spacing of the spectrum near it, can be missed.

Large models: Hill's problem on a Craig-Bampton reduction. The contact and nonlinear terms act
on a few DOFs only; the rest of the structure enters Hill's problem through its linear dynamics
at the frequencies ``Im s + m w / nu``, ``|m| <= H``. Above :data:`REDUCE_MIN_DOFS` DOFs (and
when the Hill problem exceeds :data:`DENSE_LIMIT` unknowns) the exponents are those of the
model's Craig-Bampton reduction that keeps the nonlinear and contact DOFs
(:func:`~femodes.craig_bampton`), with the fixed-interface modes up to a cut-off frequency
``omega_c = ALPHA (H + 1/2) w / nu``: the nonlinear part of ``J0`` is the same (it reads the
kept DOFs and the contact forces only), the interior is represented by its static response plus
the retained modes. The modal truncation error falls like ``omega_c^-3`` (measured on a bar with
a stop: the leading ``|mu|`` off by 4.4e-4, 5.6e-5, 7.5e-6, 9.6e-7, 1.2e-7 for ``omega_c`` =
1.6, 3.2, 6.3, 12.7, 25 times ``(H + 1/2) w``; 5 to 13 times smaller per doubling in the other
cases measured). It is estimated at every point from the exponents of the reduction with the
cut-off ``omega_c / r`` nearest to the leading ones, as ``|delta| / (r^2 - 1)`` (exact for a
rate of 2, conservative for the measured ones), and ``omega_c`` is raised until that estimate
is below :data:`REDUCTION_TOL` (``HillResult.reduction_error``) or the reduction would hold half
of the model's DOFs. The reduction is built once per system (one sparse factorisation of the
interior stiffness and one eigen-solve, grown when a larger cut-off needs more modes), and the
cut-off that sufficed is where the next point starts, so along a branch the
cost per point is that of a small Hill problem, independent of the model size.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import weakref
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..reduction import craig_bampton, kept_dofs
from ..sparse_direct import factorize
from .system import HBMSystem

__all__ = ["HillResult", "hill_matrices", "hill_exponents", "DENSE_LIMIT", "REDUCE_MIN_DOFS"]

log = logging.getLogger(__name__)

#: Sparse path: an eigenvector whose harmonic centroid is farther than this from 0 is a shifted
#: copy, not the central member of its family (the central one has ``|centroid| <= 1/2`` when
#: the Fourier series converges; the margin absorbs truncation).
CENTRAL = 0.75

#: Sparse path: shifted copies followed to their central member, rightmost first.
FOLLOW = 3

#: Hill problems up to this many unknowns (``(2H + 1) (n + n_contacts)``) are solved densely
#: (measured: the dense eigen-solve grows like unknowns^2.7, 0.19 s at 275 unknowns and 6.3 s at
#: 1100, where shift-invert took 0.2-0.7 s; benchmarks/README_stability.md).
DENSE_LIMIT = 400

#: Models with more DOFs than this (and Hill problems larger than DENSE_LIMIT) are solved on a
#: Craig-Bampton reduction (module docstring) when it keeps at most half of the DOFs.
REDUCE_MIN_DOFS = 200

#: Initial modal cut-off of the reduction, in units of the highest frequency ``(H + 1/2) w / nu``
#: of a central Hill eigenvector (doubled until the estimated truncation error is below the
#: tolerance).
ALPHA = 4.0

#: Target of the estimated truncation error of the reduction, on the multipliers' moduli (a
#: tenth of the default stability tolerance 1e-4 of :func:`femodes.stability`).
REDUCTION_TOL = 1e-5


@dataclass(frozen=True, eq=False)
class HillResult:
    """Floquet exponents and multipliers of one periodic solution by Hill's method.

    Attributes
    ----------
    exponents : ndarray (m,) complex
        Selected Floquet exponents ``s`` (1/s), ``-w/2nu < Im s <= w/2nu`` after folding.
    multipliers : ndarray (m,) complex
        ``exp(s T)``, sorted by decreasing modulus.
    centroids : ndarray (m,)
        Harmonic centroid of each selected eigenvector (``|c| < 1/2`` for a well-resolved one).
    vectors : ndarray (n_unknowns, m) complex
        Eigenvectors ``v`` (harmonic coefficients of ``p``, the HBM layout), in the same order.
    complete : bool
        True when all ``2 n_m`` exponents were found (dense solve); False for the sparse path,
        which returns those nearest to the stability boundary.
    period : float
    central : ndarray (m,) complex
        The same exponents before folding: the eigenvalues of the central members themselves
        (same order).
    n_modes : int or None
        Fixed-interface modes of the Craig-Bampton reduction Hill's problem was solved on (None:
        the model itself).
    reduction_error : float
        Estimated error of the multipliers' moduli from that reduction (0 without reduction).
    """

    exponents: np.ndarray
    multipliers: np.ndarray
    centroids: np.ndarray
    vectors: np.ndarray
    complete: bool
    period: float
    central: np.ndarray | None = None
    n_modes: int | None = None
    reduction_error: float = 0.0


def hill_matrices(system: HBMSystem, x: np.ndarray, omega: float, xi: float = 0.0):
    """``J0, J1, J2`` (sparse CSR, ``system.size`` square) of Hill's problem at solution ``x``
    (module docstring); ``J0`` is the harmonic balance Jacobian of ``system``."""
    _, J, _, _ = system.residual(np.asarray(x, dtype=float), float(omega), xi=float(xi), forced=False)
    J0 = J.tocsr()
    # the system's cached Kronecker operators (built once per system, not per point)
    J1q = system.IC + 2.0 * omega * system.AM
    if xi:
        J1q = J1q - xi * system.IM
    J2q = system.IM
    pad = system.size - system.nq

    def embed(A):
        return sp.block_diag([A, sp.csr_matrix((pad, pad))], format="csr") if pad else A.tocsr()

    return J0, embed(J1q), embed(J2q)


def _complex_harmonics(system: HBMSystem, V: np.ndarray) -> np.ndarray:
    """Mass-weighted power of each eigenvector at complex harmonics ``m = -H .. H``: shape
    ``(2H + 1, n_vectors)``. ``a cos + b sin = (a - ib)/2 e^{i.} + (a + ib)/2 e^{-i.}``."""
    h, n = system.h, system.n
    H = h.n_harmonics
    Q = V[: system.nq].reshape(h.n_coef, n, -1)
    Md = np.abs(system.M.diagonal())
    w = Md if np.any(Md > 0) else np.ones(n)  # massless DOFs (redistributed contact nodes) weigh 0
    power = np.zeros((2 * H + 1, V.shape[1]))
    power[H] = np.einsum("d,dv->v", w, np.abs(Q[0]) ** 2)
    k = np.arange(1, H + 1)
    a, b = Q[2 * k - 1], Q[2 * k]
    plus = np.einsum("d,kdv->kv", w, np.abs(a - 1j * b) ** 2) / 4.0
    minus = np.einsum("d,kdv->kv", w, np.abs(a + 1j * b) ** 2) / 4.0
    power[H + k] = plus
    power[H - k] = minus
    return power


def _centroids(system: HBMSystem, V: np.ndarray) -> np.ndarray:
    power = _complex_harmonics(system, V)
    H = system.h.n_harmonics
    m = np.arange(-H, H + 1)[:, None]
    total = power.sum(axis=0)
    total = np.where(total > 0, total, 1.0)
    return (m * power).sum(axis=0) / total


def _n_dynamic(system: HBMSystem) -> int:
    """DOFs with mass (each contributes two exponents)."""
    Md = system.M.diagonal()
    scale = float(np.max(np.abs(Md))) if Md.size else 0.0
    return int(np.count_nonzero(np.abs(Md) > 1e-14 * scale)) if scale > 0 else 0


def _select(system: HBMSystem, s: np.ndarray, V: np.ndarray, base: float, n_keep: int):
    """The central copy of each exponent family (module docstring), at most ``n_keep``."""
    cen = _centroids(system, V)
    order = np.lexsort((np.abs(s.imag), np.abs(cen)))
    taken: list[int] = []
    for i in order:
        if len(taken) >= n_keep:
            break
        dup = False
        for j in taken:
            d = s[i] - s[j]
            m = round(d.imag / base)
            # a copy shifted by m != 0 harmonics of the same exponent (relative tolerance: the
            # eigenvalues of the truncated problem agree to far better than 1e-6 of w for copies
            # that matter; distinct exponents this close would be a double multiplier anyway)
            if m != 0 and abs(d - 1j * m * base) <= 1e-6 * base:
                dup = True
                break
        if not dup:
            taken.append(int(i))
    return np.asarray(taken, dtype=int), cen


def _fold(s: np.ndarray, base: float) -> np.ndarray:
    """Exponents with ``Im s`` folded into ``(-base/2, base/2]`` (same multipliers)."""
    m = np.round(s.imag / base)
    return s - 1j * m * base


def hill_exponents(system: HBMSystem, x: np.ndarray, omega: float, xi: float = 0.0, *,
                   n_shifts: int = 2, k_per_shift: int | None = None, reduce: bool | None = None) -> HillResult:
    """Floquet exponents and multipliers of the HBM solution ``x`` at ``omega`` (module docstring).

    Parameters
    ----------
    system : HBMSystem
        The harmonic balance system the solution belongs to.
    x : ndarray
        Unknowns (displacement and contact-force coefficients), as returned by the problems.
    omega : float
        Frequency (rad/s); the period is ``2 pi nu / omega``.
    xi : float
        Artificial damping of a nonlinear mode (0 for forced responses).
    n_shifts, k_per_shift : int
        Sparse path only: number of shifts along ``Re s = 0`` and eigenvalues per shift
        (default ``max(6, 2 n_nl)`` with ``n_nl`` the nonlinear DOFs and contacts).
    reduce : bool, optional
        Solve on a Craig-Bampton reduction (module docstring): default when the model has more
        than :data:`REDUCE_MIN_DOFS` DOFs and Hill's problem more than :data:`DENSE_LIMIT`
        unknowns; False forces the model itself (shift-invert on the whole Hill matrix).

    Returns
    -------
    HillResult
    """
    omega = float(omega)
    if not (math.isfinite(omega) and omega > 0):
        raise ValueError(f"hill_exponents: omega must be a positive finite number, got {omega!r}")
    if reduce is None:
        reduce = system.n > REDUCE_MIN_DOFS and system.size > DENSE_LIMIT
    if reduce:
        res = _reduced(system, np.asarray(x, dtype=float), omega, xi, n_shifts=n_shifts, k_per_shift=k_per_shift)
        if res is not None:
            return res
    return _hill(system, x, omega, xi, n_shifts, k_per_shift)


def _hill(system: HBMSystem, x: np.ndarray, omega: float, xi: float, n_shifts: int,
          k_per_shift: int | None) -> HillResult:
    """Hill's problem of ``system`` itself (dense or shift-invert)."""
    base = omega / system.h.subharmonic          # spacing of the copies, w / nu
    T = system.h.period(omega)
    J0, J1, J2 = hill_matrices(system, x, omega, xi)
    N = system.size
    n_keep = 2 * _n_dynamic(system)
    if N <= DENSE_LIMIT:
        s, V = _dense(J0, J1, J2, base)
        complete = True
    else:
        k = k_per_shift or max(6, 2 * (system.nonlinear_dofs.size + system.n_uc))
        s, V = _sparse(system, J0, J1, J2, base, n_shifts, k)
        complete = False
    idx, cen = _select(system, s, V, base, n_keep)
    if not complete:  # central members only (_sparse followed the copies to them)
        idx = idx[np.abs(cen[idx]) <= CENTRAL]
    s_sel = _fold(s[idx], base)
    mu = np.exp(s_sel * T)
    order = np.argsort(-np.abs(mu), kind="stable")
    if complete and idx.size < n_keep:
        log.warning("hill_exponents: found %d of %d exponents (singular Hill pencil?)", idx.size, n_keep)
        complete = False
    return HillResult(exponents=s_sel[order], multipliers=mu[order], centroids=cen[idx][order],
                      vectors=V[:, idx][:, order], complete=complete, period=T, central=s[idx][order])


def _dense(J0, J1, J2, base):
    """All finite eigenvalues of the pencil ``[[0, I], [-J0, -J1]] - s [[I, 0], [0, J2]]``, by a
    shift-and-invert of the whole spectrum (standard dense eigenproblem instead of QZ; the
    infinite eigenvalues of the algebraic rows map to 0 and are dropped)."""
    N = J0.shape[0]
    sigma = 0.37 * base  # a real shift away from the spectrum near Re s = 0 (any non-eigenvalue works)
    A0, A1, A2 = J0.toarray(), J1.toarray(), J2.toarray()
    Js = A0 + sigma * A1 + sigma * sigma * A2
    try:
        lu = sla.lu_factor(Js, check_finite=False)
    except (sla.LinAlgError, ValueError):
        sigma = 0.53 * base
        lu = sla.lu_factor(A0 + sigma * A1 + sigma * sigma * A2, check_finite=False)
    # OP = (A - sigma B)^{-1} B on z = [v; w]:  (J(sigma)) z1 = -J2 y2 - (J1 + sigma J2) y1, z2 = y1 + sigma z1
    rhs1 = -(A1 + sigma * A2)
    rhs2 = -A2
    Z1 = sla.lu_solve(lu, np.hstack([rhs1, rhs2]), check_finite=False)
    OP = np.empty((2 * N, 2 * N))
    OP[:N] = Z1
    OP[N:] = sigma * Z1
    OP[N:, :N] += np.eye(N)
    theta, Zv = sla.eig(OP, check_finite=False)
    tol = 1e-10 * max(1.0, float(np.max(np.abs(theta))) if theta.size else 1.0)
    finite = np.abs(theta) > tol
    s = sigma + 1.0 / theta[finite]
    V = Zv[:N, finite]
    return s, V


class _ShiftInvert:
    """ARPACK shift-invert on the linearised Hill pencil, one sparse LU of ``J(sigma)`` per shift."""

    def __init__(self, J0, J1, J2):
        self.N = J0.shape[0]
        self.J0, self.J1, self.J2 = (A.astype(complex).tocsc() for A in (J0, J1, J2))

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
        theta, Z = spla.eigs(L, k=min(k, 2 * N - 2), which="LM", tol=1e-8)
        good = np.abs(theta) > 0
        return sigma + 1.0 / theta[good], Z[:N, good]


def _sparse(system, J0, J1, J2, base, n_shifts, k):
    """Exponents nearest to shifts along the stability boundary, each replaced by the central
    member of its family.

    A shift finds some families only through a shifted copy (an exponent with ``Im s`` beyond
    ``w/2nu`` is nearest the shifts as ``s - i w/nu``), whose real part carries the truncation
    error of the harmonic it lost (measured: 13 % on a bar with a penalty stop). Each copy is
    therefore followed to its central member by one more shift-invert at
    ``s + i round(c) w/nu`` (``c`` its harmonic centroid: the copy whose content sits at
    harmonic ``c`` becomes central when multiplied by ``e^{-i c w t / nu}``), until ``|c| <= 1/2``.
    """
    si = _ShiftInvert(J0, J1, J2)
    found_s, found_V = [], []
    for j in range(n_shifts):
        # slightly right of the boundary (the boundary itself holds the trivial exponents of free
        # orbits, which make J(0) singular)
        sigma = 1e-3 * base + 1j * base * 0.5 * j / max(n_shifts - 1, 1)
        s, V = si.near(sigma, k)
        found_s.append(s)
        found_V.append(V)
    s, V = np.concatenate(found_s), np.hstack(found_V)
    cen = _centroids(system, V)
    # follow only the copies that can decide stability: the FOLLOW rightmost (each follow costs a
    # factorisation and an Arnoldi run); the other copies are dropped
    copies = [i for i in np.argsort(-s.real) if round(float(cen[i])) != 0][:FOLLOW]
    central = [i for i in range(s.size) if round(float(cen[i])) == 0]
    out_s, out_V = [s[i] for i in central], [V[:, i] for i in central]
    for i in copies:
        si_, vi = s[i], V[:, i]
        for _ in range(4):
            c = float(_centroids(system, vi[:, None])[0])
            m = round(c)
            if m == 0:
                break
            s2, V2 = si.near(si_ + 1j * m * base, 2)
            j = int(np.argmin(np.abs(s2 - (si_ + 1j * m * base))))
            s2, V2 = s2[j:j + 1], V2[:, j:j + 1]
            si_, vi = s2[0], V2[:, 0]
        out_s.append(si_)
        out_V.append(vi)
    s, V = np.asarray(out_s), np.column_stack(out_V)
    keep: list[int] = []  # the same exponent found twice counts once
    for i in np.argsort(np.abs(s)):
        if all(abs(s[i] - s[j]) > 1e-7 * base for j in keep):
            keep.append(int(i))
    return s[keep], V[:, keep]


# ------------------------------------------------------------------------------------------------
# Craig-Bampton reduction of Hill's problem (module docstring)
# ------------------------------------------------------------------------------------------------
class _ModelCache:
    """The largest Craig-Bampton reduction built for a model, kept while the model lives (calls of
    :func:`femodes.stability` on points of one branch build a new system each time)."""

    def __init__(self):
        self._items: dict[int, tuple] = {}

    def get(self, model):
        item = self._items.get(id(model))
        return item[1] if item is not None and item[0]() is model else None

    def put(self, model, reduced) -> None:
        key = id(model)
        if key not in self._items:
            weakref.finalize(model, self._items.pop, key, None)
        self._items[key] = (weakref.ref(model), reduced)


_CB_CACHE = _ModelCache()


class _Reduction:
    """The Craig-Bampton reductions of one system's model, by number of modes (cached on it)."""

    def __init__(self, system: HBMSystem):
        self.system = system
        self.full = _CB_CACHE.get(system.model)  # the reduction with the most modes computed so far
        self.systems: dict = {}     # n_modes -> HBMSystem of the truncated reduction
        self.alpha = ALPHA          # cut-off (in (H + 1/2) w / nu) that sufficed at the last point
        model = system.model
        try:  # the DOFs craig_bampton keeps (ValueError: none declared, it cannot reduce either)
            self.n_kept = kept_dofs(model).size
        except ValueError:
            self.n_kept = 0
        self.n_interior = model.n_dofs - self.n_kept

    def modes_up_to(self, cutoff: float) -> int | None:
        """Number of fixed-interface modes at or below ``cutoff``; None when the reduction would
        not be much smaller than the model (or cannot be built)."""
        model = self.system.model
        n_kept, n_interior = self.n_kept, self.n_interior
        while True:
            if self.full is not None:
                w_i = np.asarray(self.full.interface_omega)
                if w_i.size and (w_i[-1] >= cutoff or self.full.n_modes >= n_interior):
                    return int(np.count_nonzero(w_i <= cutoff))
            if self.full is None:
                m = 16
            else:  # enough for the cut-off if the mode count grew linearly with frequency (1-D), with
                # a margin; at least twice as many
                m0 = self.full.n_modes
                m = max(2 * m0, math.ceil(1.3 * m0 * cutoff / max(float(w_i[-1]), 1e-300)))
            m = min(m, n_interior)
            if n_kept + m > model.n_dofs // 2:
                return None
            try:
                self.full = craig_bampton(model, m)
                _CB_CACHE.put(model, self.full)
            except ValueError as exc:  # free structure (singular interior stiffness)
                log.info("hill_exponents: no Craig-Bampton reduction (%s); Hill's problem of the whole model", exc)
                return None

    def system_with(self, n_modes: int) -> HBMSystem:
        if n_modes not in self.systems:
            s = self.system
            self.systems[n_modes] = HBMSystem(self.full.truncated(n_modes), s.h, projection=s.projection)
        return self.systems[n_modes]

    def state(self, x: np.ndarray, rs: HBMSystem) -> np.ndarray:
        """The solution's unknowns on a reduced system: kept DOFs' coefficients and the contact
        forces (all ``J0`` depends on); modal coordinates zero (they enter linearly)."""
        Q, P = self.system.split(x)
        Qr = np.zeros((Q.shape[0], rs.n))
        Qr[:, : self.full.n_kept] = Q[:, np.asarray(self.full.kept)]
        return rs.join(Qr, P)

    def expand(self, V: np.ndarray, rs: HBMSystem) -> np.ndarray:
        """Eigenvectors of a reduced problem in the layout of the model's own."""
        s = self.system
        nc, k = s.h.n_coef, V.shape[1]
        T = np.asarray(rs.model.basis)
        Qr = V[: rs.nq].reshape(nc, rs.n, k)
        Q = np.matmul(T[None], Qr).reshape(nc * s.n, k)  # T @ Qr[c] per coefficient row (BLAS)
        return np.vstack([Q, V[rs.nq:]])


def _reduced(system: HBMSystem, x: np.ndarray, omega: float, xi: float, **kw) -> HillResult | None:
    """Hill's exponents on a Craig-Bampton reduction whose estimated truncation error is below
    :data:`REDUCTION_TOL`; None when no useful reduction exists (then the model itself is used).

    The cut-off starts at the one that sufficed at the previous point of the same system (at
    least ``ALPHA (H + 1/2) w / nu``); when the estimate is too large it is raised by the factor
    the ``omega_c^-3`` rate asks for (with a margin), and the previous reduction becomes the
    coarse one of the next estimate.
    """
    red = system._cache.get("hill_reduction")
    if red is None:
        red = system._cache["hill_reduction"] = _Reduction(system)
    top = (system.h.n_harmonics + 0.5) * omega / system.h.subharmonic
    cutoff = max(ALPHA, red.alpha) * top
    m_coarse, ratio = red.modes_up_to(cutoff / 2.0), 2.0
    fine, used = None, cutoff
    for _ in range(8):
        m_next = None if m_coarse is None else red.modes_up_to(cutoff)
        if m_next is None:
            if fine is None:
                return None
            break  # the reduction cannot grow further (half the model): keep the last, with its estimate
        m, used = m_next, cutoff
        fine = _solve_reduced(red, m, x, omega, xi, kw)
        err = 0.0 if m_coarse == m else _error_near(red, m_coarse, fine, x, omega, xi, ratio)
        if err <= REDUCTION_TOL or m == red.full.n_modes and m >= red.n_interior:
            break
        log.debug("hill_exponents: %d modes (cut-off %.3g x (H + 1/2) w), error estimate %.2e", m, cutoff / top, err)
        # the cut-off the omega_c^-3 rate asks for, with a margin; at least doubled
        ratio = min(8.0, max(2.0, 1.25 * (err / REDUCTION_TOL) ** (1.0 / 3.0)))
        m_coarse, cutoff = m, cutoff * ratio
    if err > REDUCTION_TOL:
        log.info("hill_exponents: reduction error estimate %.1e above %.0e with %d modes", err, REDUCTION_TOL, m)
    red.alpha = used / top
    return dataclasses.replace(fine, vectors=red.expand(fine.vectors, red.system_with(m)),
                               reduction_error=err, complete=False)


#: Truncation error estimate: the change ``delta`` of the leading multipliers' moduli from a coarse
#: to a fine reduction (the coarse exponent nearest to each of the fine one's four leading ones),
#: cut-offs in the ratio ``r``, gives the fine one's error ``delta / (r^RATE - 1)`` if the error
#: falls like ``omega_c^-RATE``; RATE is set below the measured 3 (5 to 13 per doubling of the
#: cut-off) so that the estimate errs on the safe side (``|delta| / 3`` for ``r = 2``).
RATE = 2.0


def _error_near(red: _Reduction, m_coarse: int, fine: HillResult, x, omega, xi, ratio: float) -> float:
    """Error estimate of ``fine`` from the coarse reduction's exponents nearest to its leading
    exponents (one shift-invert each, not a whole Hill solve: the two solves need not return the
    same subset of the spectrum); ``ratio`` is the ratio of the cut-offs."""
    rs = red.system_with(m_coarse)
    si = _ShiftInvert(*hill_matrices(rs, red.state(x, rs), omega, xi))
    err = 0.0
    done: list[complex] = []
    for s in fine.central[:4]:
        if any(abs(s - d) <= 1e-9 * omega or abs(s - np.conj(d)) <= 1e-9 * omega for d in done):
            continue  # a conjugate partner changes by the same amount
        done.append(s)
        sc, _ = si.near(complex(s) + 1e-9j * omega, 2)
        if sc.size == 0:
            return math.inf
        c = sc[np.argmin(np.abs(sc - s))]
        err = max(err, abs(math.exp(c.real * fine.period) - math.exp(s.real * fine.period)))
    return err / (ratio ** RATE - 1.0)


def _solve_reduced(red: _Reduction, n_modes: int, x, omega, xi, kw) -> HillResult:
    rs = red.system_with(n_modes)
    r = _hill(rs, red.state(x, rs), omega, xi, kw["n_shifts"], kw["k_per_shift"])
    return dataclasses.replace(r, n_modes=n_modes)
