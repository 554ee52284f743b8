r"""Discretise layer: Floquet exponents of a harmonic balance solution by Hill's method.

A perturbation ``y(t) = e^{s t} p(t)`` of a periodic solution, ``p`` periodic with the solution's
period ``T = 2 pi nu / w``, solves the linearised equations of motion when ``s`` is a *Floquet
exponent*; the multipliers are ``mu = exp(s T)``. Expanding ``p`` on the solution's harmonics,
the harmonic balance Jacobian ``J0`` becomes the quadratic matrix polynomial (Hill's problem;
Lazarus and Thomas, C. R. Mecanique 338 (2010) 510-517; Krack and Gross, *Harmonic Balance for
Nonlinear Vibration Problems*, 2019, sec. 3.6)

.. math::

    \bigl(J_0 + s\,J_1 + s^2 J_2\bigr)\,v = 0, \qquad
    J_1 = I \otimes (C - \xi M) + 2\omega\,D_1 \otimes M, \qquad J_2 = I \otimes M,

on the displacement unknowns (zero on the contact-force unknowns, whose equations are algebraic).
The contact and nonlinear terms enter through ``J0`` only (the generalized Jacobian of the laws).

Selection: of each family of copies ``s + i m w / nu``, the exponent whose eigenvector has the
*harmonic centroid* (mass-weighted mean harmonic index) nearest 0 is kept (Guillot, Lazarus,
Thomas, Vergez and Cochelin, J. Comput. Phys. 416 (2020) 109477, in a weighted form), copies
already taken skipped, until ``2 n_m`` exponents are held (``n_m`` the DOFs with mass).

Solvers: up to :data:`DENSE_LIMIT` unknowns a dense solve of the whole spectrum; larger ones
ARPACK shift-invert with shifts along ``Re s = 0`` (:mod:`femodes.hbm.hill_sparse`; the exponents
nearest the boundary only, ``HillResult.complete`` False). With more than :data:`DENSE_LIMIT`
unknowns with mass or damping, the exponents are those of the model reduced to its
free-interface modes up to a cut-off ``omega_c = ALPHA (H + 1/2) w / nu`` plus the residual
flexibility of the DOFs the laws act on
(:mod:`femodes.hbm.hill_reduction`), whose unknowns are eliminated exactly (:mod:`femodes.hbm.hill_dense`);
``omega_c`` is raised until the estimated truncation error is below :data:`REDUCTION_TOL`
(``HillResult.reduction_error``) or the reduction would hold half of the model's DOFs. Accuracy,
cost and measurements: :doc:`/guide/stability` (Hill's method).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .harmonics import Harmonics
from .hill_dense import SMALL, Pencil, dense_pencil, dense_spectrum, pencil_on_dynamic
from .hill_elimination import algebraic_unknowns
from .hill_reduction import Estimate, FreeInterfaceReduction, decides_verdict
from .hill_sparse import ShiftInvert, sparse_exponents
from .hill_rest import XI_TOL, at_rest
from .system import HBMSystem

__all__ = ["HillResult", "hill_matrices", "hill_exponents", "coarse_multipliers", "COARSE", "DENSE_LIMIT", "REDUCE_MIN_DOFS"]

log = logging.getLogger(__name__)

#: Sparse path: an eigenvector whose harmonic centroid is farther than this from 0 is a shifted
#: copy, not the central member of its family (the central one has ``|centroid| <= 1/2`` when
#: the Fourier series converges; the margin absorbs truncation).
CENTRAL = 0.75

#: Hill problems up to this many unknowns (``(2H + 1) (n + n_contacts)``) are solved densely
#: (measured: the dense eigen-solve grows like unknowns^2.7, 0.19 s at 275 unknowns and 6.3 s at
#: 1100, where shift-invert took 0.2-0.7 s; benchmarks/README_stability.md).
DENSE_LIMIT = 400

#: Hill problems with more unknowns with mass or damping than this are solved on a free-interface
#: reduction (module docstring), whose dense eigen-solve has ``(2H + 1) m`` of them for ``m``
#: modes; below it the whole model's spectrum is cheap. The whole spectrum is not the better
#: answer on stiff reduced models: eliminating the force of a contact closed over most of the
#: period leaves a stiff constraint mode (``|s|`` 1e4-1e9 on the Craig-Bampton blade of
#: examples/blade_casing.py, 11 DOFs, H = 7), whose round-off real parts read as instabilities
#: (``|mu|`` up to 6 on its backbone, before they were set to 0 below their round-off bound) and
#: whose copies crowd the selection (on its forced curve the whole model's leading multipliers
#: were ~0 at 8 points where the reduction, confirmed by its neighbours, gives 0.96). Measured
#: there: 10-16 ms a point reduced against 43 ms whole.
REDUCE_MIN_UNKNOWNS = 100

#: Kept for scripts that read it: models are now reduced when their Hill problem has more than
#: DENSE_LIMIT unknowns with mass or damping, whatever their size (module docstring).
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
        Free-interface modes of the reduction Hill's problem was solved on (None:
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


def hill_matrices(system: HBMSystem, x: np.ndarray, omega: float, xi: float = 0.0, *, dense: bool = False):
    """``J0, J1, J2`` (sparse CSR, ``system.size`` square; dense arrays with ``dense``) of Hill's
    problem at solution ``x`` (module docstring); ``J0`` is the harmonic balance Jacobian of
    ``system``."""
    _, J, _, _ = system.residual(np.asarray(x, dtype=float), float(omega), xi=float(xi), forced=False)
    # the dynamic stiffness at d/dt + s (its cached Kronecker operators, built once per system)
    J1q, J2q = system.stiffness.exponent_terms(omega, xi, dense=dense)
    n, nq = system.size, system.nq
    if dense:  # small problems: no sparse matrix is built (scipy.sparse's per-call overhead)
        J0 = J.toarray() if hasattr(J, "toarray") else J.tocsr().toarray()
        J1, J2 = np.zeros((n, n)), np.zeros((n, n))
        J1[:nq, :nq], J2[:nq, :nq] = J1q, J2q
        return J0, J1, J2

    def embed(A):  # zero rows and columns of the contact forces appended (CSR index arithmetic)
        A = A.tocsr()
        return sp.csr_matrix((A.data, A.indices, np.concatenate([A.indptr, np.full(n - nq, A.indptr[-1])])),
                             shape=(n, n))

    return J.tocsr(), embed(J1q), embed(J2q)


def _complex_harmonics(system: HBMSystem | _Truncated, V: np.ndarray) -> np.ndarray:
    """Mass-weighted power of each eigenvector at complex harmonics ``m = -H .. H``: shape
    ``(2H + 1, n_vectors)``. ``a cos + b sin = (a - ib)/2 e^{i.} + (a + ib)/2 e^{-i.}``."""
    h, n = system.h, system.n
    H = h.n_harmonics
    Q = V[: system.nq].reshape(h.n_coef, n, -1)
    Md = np.abs(system.M.diagonal())
    w = Md if _weighs_mass(system) else np.ones(n)  # massless DOFs (redistributed contact nodes) weigh 0
    power = np.zeros((2 * H + 1, V.shape[1]))
    power[H] = np.einsum("d,dv->v", w, np.abs(Q[0]) ** 2)
    k = np.arange(1, H + 1)
    a, b = Q[2 * k - 1], Q[2 * k]
    plus = np.einsum("d,kdv->kv", w, np.abs(a - 1j * b) ** 2) / 4.0
    minus = np.einsum("d,kdv->kv", w, np.abs(a + 1j * b) ** 2) / 4.0
    power[H + k] = plus
    power[H - k] = minus
    return power


def _weighs_mass(system: HBMSystem | _Truncated) -> bool:
    """Whether the centroids weigh the DOFs by their mass (some DOF has mass), or all alike."""
    return bool(np.any(system.M.diagonal() != 0))


def _centroids(system: HBMSystem | _Truncated, V: np.ndarray) -> np.ndarray:
    power = _complex_harmonics(system, V)
    H = system.h.n_harmonics
    m = np.arange(-H, H + 1)[:, None]
    total = power.sum(axis=0)
    total = np.where(total > 0, total, 1.0)
    return (m * power).sum(axis=0) / total


def _n_dynamic(system: HBMSystem | _Truncated) -> int:
    """DOFs with mass (each contributes two exponents)."""
    Md = system.M.diagonal()
    scale = float(np.max(np.abs(Md))) if Md.size else 0.0
    return int(np.count_nonzero(np.abs(Md) > 1e-14 * scale)) if scale > 0 else 0


def _select(system: HBMSystem | _Truncated, s: np.ndarray, V: np.ndarray, base: float, n_keep: int):
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
        Solve on a free-interface reduction (module docstring): default when Hill's problem has
        more than :data:`DENSE_LIMIT` unknowns with mass or damping; False forces the model
        itself (dense after eliminating the algebraic unknowns, or shift-invert when larger).

    Returns
    -------
    HillResult
    """
    omega = float(omega)
    if not (math.isfinite(omega) and omega > 0):
        raise ValueError(f"hill_exponents: omega must be a positive finite number, got {omega!r}")
    kept = getattr(system, "_cache", None)  # an HBMSystem's cache (a test's stand-in may have none)
    cache: dict = kept if isinstance(kept, dict) else {}
    if reduce is None:
        # the dense solve holds the unknowns with mass or damping (the others are eliminated)
        if "hill_n_dynamic" not in cache:
            cache["hill_n_dynamic"] = _n_dynamic_unknowns(system)
        reduce = cache["hill_n_dynamic"] > REDUCE_MIN_UNKNOWNS
    # an orbit on which the nonlinear forces act as at rest (below the first contact) has the
    # linear system's exponents: those of the last such orbit, at this frequency (hill_rest)
    rest = isinstance(kept, dict) and at_rest(system, x)
    period = system.h.grid.period(omega)
    last = cache.get(("hill_at_rest", reduce)) if rest else None
    if last is not None and abs(xi - last[0]) * period <= XI_TOL and last[1].central is not None:
        # the same central exponents, folded and exponentiated with this period
        r = last[1]
        s = _fold(r.central, omega / system.h.subharmonic)
        mu = np.exp(s * period)
        order = np.argsort(-np.abs(mu), kind="stable")
        return dataclasses.replace(r, exponents=s[order], multipliers=mu[order], centroids=r.centroids[order],
                                   vectors=r.vectors[:, order], period=period, central=r.central[order])
    res = None
    if reduce:
        res = _reduced(system, np.asarray(x, dtype=float), omega, xi, n_shifts=n_shifts, k_per_shift=k_per_shift)
    if res is None:
        res = _hill(system, x, omega, xi, n_shifts, k_per_shift)
    if rest:
        cache[("hill_at_rest", reduce)] = (float(xi), res)
    return res


def _hill(system: HBMSystem, x: np.ndarray, omega: float, xi: float, n_shifts: int,
          k_per_shift: int | None) -> HillResult:
    """Hill's problem of ``system`` itself (dense or shift-invert)."""
    J0, J1, J2 = hill_matrices(system, x, omega, xi, dense=system.size <= SMALL)
    return _solve(system, J0, J1, J2, omega, n_shifts, k_per_shift)


def _solve(system: HBMSystem | _Truncated, J0, J1, J2, omega: float, n_shifts: int,
           k_per_shift: int | None, dense: bool | None = None) -> HillResult:
    """The selected exponents of the pencil ``J0 + s J1 + s^2 J2`` on the unknowns of ``system``;
    ``dense`` forces the path (default: dense up to :data:`DENSE_LIMIT` unknowns with mass or
    damping; the algebraic unknowns eliminated first, :mod:`femodes.hbm.hill_dense`)."""
    base = omega / system.h.subharmonic          # spacing of the copies, w / nu
    T = system.h.grid.period(omega)
    N = J0.shape[0]
    n_keep = 2 * _n_dynamic(system)
    algebraic = algebraic_unknowns(J1, J2)
    if dense is None:
        dense = N - np.count_nonzero(algebraic) <= DENSE_LIMIT
    if not dense:
        k = k_per_shift or max(6, 2 * (system.nonlinear_dofs.size + system.n_uc))
        s, V = sparse_exponents(J0, J1, J2, base, n_shifts, k, lambda V: _centroids(system, V))
        idx, cen = _select(system, s, V, base, n_keep)
        idx = idx[np.abs(cen[idx]) <= CENTRAL]  # central members only (_sparse followed the copies to them)
        return _result(s, V, idx, cen, base, T, False)
    p = pencil_on_dynamic(J0, J1, J2, algebraic)
    s, Vd = dense_pencil(p.A0, p.A1, p.A2, base)
    # the centroids weigh DOFs with mass only: not the algebraic unknowns (zero until filled)
    idx, cen = _select(system, s, _whole_vectors(system, p, Vd), base, n_keep)
    if idx.size < n_keep:
        log.warning("hill_exponents: found %d of %d exponents (singular Hill pencil?)", idx.size, n_keep)
    return _result(s, p.embed(Vd), idx, cen, base, T, idx.size == n_keep, p.fill)


def _result(s, V, idx, cen, base: float, T: float, complete: bool, fill=None) -> HillResult:
    """The selected exponents ``s[idx]``, folded, with their multipliers, largest first."""
    s_sel = _fold(s[idx], base)
    mu = np.exp(s_sel * T)
    order = np.argsort(-np.abs(mu), kind="stable")
    W = V[:, idx][:, order]
    return HillResult(exponents=s_sel[order], multipliers=mu[order], centroids=cen[idx][order],
                      vectors=W if fill is None else fill(W), complete=complete, period=T, central=s[idx][order])


def _whole_vectors(system: HBMSystem | _Truncated, p: Pencil, Vd: np.ndarray) -> np.ndarray:
    """Eigenvectors on the pencil's unknowns in the whole layout, for the centroids: eliminated rows
    zero, or filled in when no DOF has mass (the centroids then weigh all unknowns)."""
    V = p.embed(Vd)
    return V if _weighs_mass(system) else p.fill(V)


#: Hill's truncation check (:func:`coarse_multipliers`): the perturbation's harmonics cut to this
#: fraction of the orbit's.
COARSE = 0.75


def coarse_multipliers(system: HBMSystem, x: np.ndarray, omega: float, xi: float, n_modes: int | None) -> np.ndarray:
    """The multipliers of the same orbit with the perturbation truncated to ``Hc = floor(COARSE H)``
    harmonics, largest modulus first (empty when ``Hc < 1``): Hill's truncation check.

    Hill's problem truncates the perturbation ``p`` of the orbit to the orbit's ``H`` harmonics;
    its central exponents converge as that truncation grows, spectrally for smooth laws, slowly
    for complementarity contacts, whose Jacobian jumps at every contact event. The pencil of the
    coarser truncation is the block of the same pencil on the harmonics up to ``Hc`` (the orbit
    and its Jacobian unchanged; a prefix of the HBM layout), solved as :func:`hill_exponents`
    solved the whole one, on the same reduction (``n_modes`` free-interface modes, None: the model
    itself). A verdict that differs between the two truncations is not converged in the harmonics.
    """
    h = system.h
    Hc = int(COARSE * h.n_harmonics)
    if Hc < 1:
        return np.empty(0, dtype=complex)
    x = np.asarray(x, dtype=float)
    rs = system
    if n_modes is not None:
        red = system._cache["hill_reduction"]  # the reduction hill_exponents solved on
        rs = red.system_with(n_modes)
        x = red.state(x, rs)
    dense = rs.size <= SMALL
    J = hill_matrices(rs, x, omega, xi, dense=dense)
    keep = np.concatenate([np.arange((2 * Hc + 1) * rs.n), rs.nq + np.arange((2 * Hc + 1) * rs.n_uc)])
    sub = [A[np.ix_(keep, keep)] if dense else A[keep][:, keep] for A in J]
    J0, J1, J2 = sub
    # the path the whole problem took (a coarse block just under the dense limit would otherwise
    # cost a dense solve of up to DENSE_LIMIT unknowns where the whole one was a shift-invert)
    dense_whole = bool(rs.size - np.count_nonzero(algebraic_unknowns(J[1], J[2])) <= DENSE_LIMIT)
    return _solve(_Truncated(rs, Hc), J0, J1, J2, omega, 2, None, dense=dense_whole).multipliers


class _Truncated:
    """What :func:`_solve` reads of a system (its harmonics, mass, layout), with its harmonics cut
    to the first ``Hc``."""

    def __init__(self, system: HBMSystem, Hc: int):
        self.h = Harmonics(Hc, subharmonic=system.h.subharmonic)
        self.M, self.n, self.n_uc = system.M, system.n, system.n_uc
        self.nonlinear_dofs = system.nonlinear_dofs
        self.nq = self.h.n_coef * system.n


def _n_dynamic_unknowns(system: HBMSystem) -> int:
    """Unknowns of Hill's problem that carry mass or damping (the dense solve's size)."""
    # (IC holds the whole damping, a modal low-rank part included: stiffness.C_full)
    term = system.stiffness.term
    dyn = np.asarray(abs(term("IM")).sum(axis=1)).ravel() + np.asarray(abs(term("IC")).sum(axis=1)).ravel()
    return int(np.count_nonzero(dyn))


# ------------------------------------------------------------------------------------------------
# Hill's problem on a reduction (femodes.hbm.hill_reduction)
# ------------------------------------------------------------------------------------------------
def _reduced(system: HBMSystem, x: np.ndarray, omega: float, xi: float, **kw) -> HillResult | None:
    """Hill's exponents on a free-interface reduction whose estimated truncation error is below
    :data:`REDUCTION_TOL`; None when no useful reduction exists (then the model itself is used).

    The cut-off starts at the one that sufficed at the previous point of the same system (at
    least ``ALPHA (H + 1/2) w / nu``); when the estimate is too large it is raised by the factor
    the ``omega_c^-3`` rate asks for (with a margin), and the previous reduction becomes the
    coarse one of the next estimate.
    """
    red = system._cache.get("hill_reduction")
    if red is None:
        red = system._cache["hill_reduction"] = FreeInterfaceReduction(system, ALPHA)
    top = (system.h.n_harmonics + 0.5) * omega / system.h.subharmonic
    cutoff = max(ALPHA, red.alpha) * top
    m_coarse, ratio = red.modes_up_to(cutoff / 2.0), 2.0
    fine, used = None, cutoff
    for _ in range(8):
        # the first solve takes the largest reduction when the cut-off asks for more (a reduced
        # model's few modes); later ones stop growing there
        m_next = None if m_coarse is None else red.modes_up_to(cutoff, cap=fine is None)
        if m_next is None:
            if fine is None:
                return None
            break  # the reduction cannot grow further: keep the last, with its estimate
        m, used = m_next, cutoff
        fine = _solve_reduced(red, m, x, omega, xi, kw)
        if m_coarse == m and m >= 2:
            # no mode between the two cut-offs (or capped at the largest reduction): the same
            # reduction twice says nothing about the truncation, so the estimate compares with
            # half the modes (an estimate of 0 there read as exact: ALPHA = 2 on the forced
            # curve of examples/blade_casing.py gave 2 modes, "error 0", and stable verdicts at
            # three points where the whole model and 5 modes give |mu| = 1.0002-1.043)
            m_coarse, ratio = m // 2, 2.0
        last = red.last_estimate
        capped = m == red.max_modes
        if last is not None and last.modes == m and (capped or (abs(omega / last.omega - 1.0) <= REUSE_SPAN
                                                             and last.reuses < REUSE_POINTS
                                                             and (not last.decided
                                                                  or decides_verdict(fine.multipliers, last.error)))):
            # a neighbouring point of the branch with the same reduction: its estimate. Or the
            # largest reduction there is (max_modes: half the model's DOFs, 5 or 6 modes of the
            # 11-DOF blade of examples/blade_casing.py), wherever its last estimate was made: the
            # estimate chooses the cut-off, and this one cannot grow (a larger estimate could
            # only raise the starting cut-off of later points). It stays in reduction_error as an
            # indication. Computed at every point it cost 17 coarse solves on that blade's forced
            # curve, a fifth of its stability run; measured: the multipliers of the blade's forced
            # curve and backbone, and of the user blade's (examples/user_blade_3d.py), the same
            # to the last bit either way.
            # (an estimate kept only because it decided its point's verdict must decide this one's)
            err = last.error
            red.last_estimate = last._replace(reuses=last.reuses + 1)
            break
        assert m_coarse is not None  # m_next is None otherwise
        err = 0.0 if m_coarse == m else _error_near(red, m_coarse, fine, x, omega, xi, ratio)
        decided = err > REDUCTION_TOL and decides_verdict(fine.multipliers, err)
        red.last_estimate = Estimate(m, err, omega, 0, decided)
        if err <= REDUCTION_TOL or decided:
            break
        log.debug("hill_exponents: %d modes (cut-off %.3g x (H + 1/2) w), error estimate %.2e", m, cutoff / top, err)
        # the cut-off the omega_c^-3 rate asks for, with a margin; at least doubled
        ratio = min(8.0, max(2.0, 1.25 * (err / REDUCTION_TOL) ** (1.0 / 3.0)))
        m_coarse, cutoff = m, cutoff * ratio
    assert fine is not None  # the first pass solved (or returned None)
    if err > REDUCTION_TOL and not decides_verdict(fine.multipliers, err):  # a branch warns where it matters
        log.debug("hill_exponents: reduction error estimate %.1e above %.0e with %d modes", err, REDUCTION_TOL, m)
    red.alpha = used / top
    return dataclasses.replace(fine, vectors=red.expand(fine.vectors, m), reduction_error=err, complete=False)


#: Along a branch, a point whose reduction is that of the last estimated point, within this
#: relative distance in frequency, takes that point's truncation error estimate (up to
#: :data:`REUSE_POINTS` points in a row) instead of solving the coarse reduction again (an
#: estimate, used to choose the cut-off: it varies by orders of magnitude between neighbouring
#: points of a contact branch either way).
REUSE_SPAN = 0.02

#: Points in a row that reuse an estimate (:data:`REUSE_SPAN`).
REUSE_POINTS = 5


#: Truncation error estimate: the change ``delta`` of the leading multipliers' moduli from a coarse
#: to a fine reduction (the coarse exponent nearest to each of the fine one's four leading ones),
#: cut-offs in the ratio ``r``, gives the fine one's error ``delta / (r^RATE - 1)`` if the error
#: falls like ``omega_c^-RATE``; RATE is set below the measured 3 (5 to 13 per doubling of the
#: cut-off) so that the estimate errs on the safe side (``|delta| / 3`` for ``r = 2``).
RATE = 2.0


def _error_near(red: FreeInterfaceReduction, m_coarse: int, fine: HillResult, x, omega, xi, ratio: float) -> float:
    """Error estimate of ``fine`` from the coarse reduction's exponents nearest to its leading
    exponents (one shift-invert each, not a whole Hill solve: the two solves need not return the
    same subset of the spectrum); ``ratio`` is the ratio of the cut-offs."""
    rs = red.system_with(m_coarse)
    J0, J1, J2 = hill_matrices(rs, red.state(x, rs), omega, xi, dense=rs.size <= SMALL)
    algebraic = algebraic_unknowns(J1, J2)
    if J0.shape[0] - np.count_nonzero(algebraic) <= DENSE_LIMIT:
        s_all = dense_spectrum(J0, J1, J2, omega / rs.h.subharmonic, algebraic, vectors=False)[0]

        def near(s):
            return s_all
    else:
        si = ShiftInvert(J0, J1, J2)

        def near(s):
            return si.near(complex(s) + 1e-9j * omega, 2)[0]
    err = 0.0
    done: list[complex] = []
    assert fine.central is not None  # _hill sets it
    for s in fine.central[:4]:
        if any(abs(s - d) <= 1e-9 * omega or abs(s - np.conj(d)) <= 1e-9 * omega for d in done):
            continue  # a conjugate partner changes by the same amount
        done.append(s)
        sc = near(s)
        if sc.size == 0:
            return math.inf
        c = sc[np.argmin(np.abs(sc - s))]
        err = max(err, abs(math.exp(c.real * fine.period) - math.exp(s.real * fine.period)))
    return err / (ratio ** RATE - 1.0)


def _solve_reduced(red: FreeInterfaceReduction, n_modes: int, x, omega, xi, kw) -> HillResult:
    rs = red.system_with(n_modes)
    r = _hill(rs, red.state(x, rs), omega, xi, kw["n_shifts"], kw["k_per_shift"])
    return dataclasses.replace(r, n_modes=n_modes)
