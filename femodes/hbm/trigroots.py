"""Discretise layer: sign changes of real trigonometric polynomials (for the exact positive part).

The real roots of ``phi(θ) = c0 + sum_k (c_k cos kθ + s_k sin kθ)`` are found as eigenvalues of
a colleague matrix (Chebyshev form of ``phi(α+θ) phi(α-θ)``; I. J. Good 1961) or of a companion
matrix (``z^H phi(z)``, ``z = exp(iθ)``; J. P. Boyd 2006), then bracketed by sign changes and
polished by safeguarded Newton iteration. Used by :mod:`femodes.hbm.positive_part`.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["DEGREE_TOL", "ColleagueRoots", "CompanionRoots", "GridRoots", "candidates", "sign_changes", "sign_changes_of", "trig_eval"]

_TWO_PI = 2.0 * np.pi
_EPS = np.finfo(float).eps

# Rotation of the phase used by the real (Chebyshev) root finder: roots are
# searched for phi(alpha + theta) * phi(alpha - theta), which is even in theta.
# A generic, irrational-looking alpha avoids the degenerate double roots that
# the choice alpha = 0 would produce for signals symmetric about theta = 0
# (e.g. cosine-only responses), and keeps roots away from x = cos(.) = +-1,
# where arccos is ill-conditioned.  (0.739085... is the fixed point of cos.)
_ALPHA = 0.7390851332151607

# A root of the polynomial is kept as a candidate sign change if it lies this
# close to the unit circle (companion) or to the real segment [-1, 1]
# (colleague).  Generous on purpose: spurious candidates only split an
# interval, a missing one loses a sign change.
_ROOT_ACCEPT = 1e-2

# Harmonic k is considered absent (effective degree < H) when
# max(|c_k|, |s_k|) <= DEGREE_TOL * max|coefficient|; such terms change phi by
# less than rounding of its evaluation.
DEGREE_TOL = 1e-16

_MAX_POLISH = 100

# Newton steps of _polish_in_cells before a root falls back to the safeguarded _polish.
_CELL_NEWTON = 6

# GridRoots.sign_changes leaves a signal to the general path when a sample lies within this many
# eps times sum|coefficients| of zero (the inverse FFT's rounding, with a margin, against the
# 8 eps bound of sign_changes).
_GRID_TOL = 64.0

# trig_eval sums the series directly (one complex exponential per point and harmonic, batched
# matrix products) when points x harmonics is at most this, by Horner's rule (a Python loop over
# the harmonics) above it. Measured (values and derivatives, microseconds, direct / Horner):
# 1 point at H = 20 21 / 117; 42 points at H = 20 45 / 92; 84 points at H = 40 116 / 198;
# 160 at H = 40 199 / 171; 320 at H = 20 202 / 119 (crossover near 3000-5000).
_DIRECT_EVAL_MAX = 4096


def _value_and_slope(coef, curvature=False):
    """``(p, H, 2)``: the complex coefficients ``a_k`` of ``phi`` and ``i k a_k`` of ``phi'``;
    with ``curvature``, ``(p, H, 3)``: also ``-k^2 a_k`` of ``phi''``."""
    ik = 1j * np.arange(1, coef.shape[1] + 1)
    return np.stack([coef, coef * ik, coef * (ik * ik)] if curvature else [coef, coef * ik], axis=2)


def trig_eval(A, x, derivative=False):
    """Values (and d/dθ) of the series with coefficient rows ``A`` (p, L) at ``x`` (p, q).

    ``phi = c0 + Re sum_k (c_k - i s_k) z^k``, ``phi' = Re sum_k i k (c_k - i s_k) z^k``,
    ``z = exp(iθ)``: summed directly for small sizes, by Horner's rule in ``z`` otherwise.
    """
    H = (A.shape[1] - 1) // 2
    if H == 0:
        f = np.broadcast_to(A[:, :1], x.shape).copy()
        return (f, np.zeros_like(x)) if derivative else f
    coef = A[:, 1::2] - 1j * A[:, 2::2]  # (p, H)
    if x.size * H <= _DIRECT_EVAL_MAX:
        k = np.arange(1, H + 1)
        Z = np.exp(1j * x[:, :, None] * k)  # (p, q, H)
        if not derivative:
            return A[:, :1] + np.matmul(Z, coef[:, :, None])[..., 0].real
        s = np.matmul(Z, _value_and_slope(coef))
        return A[:, :1] + s[..., 0].real, s[..., 1].real
    coef = coef[:, None, :]  # (p, 1, H)
    z = np.exp(1j * x)
    acc = np.broadcast_to(coef[..., H - 1], x.shape).copy()
    if derivative:
        dcoef = coef * np.arange(1, H + 1)
        dacc = np.broadcast_to(dcoef[..., H - 1], x.shape).copy()
    for k in range(H - 2, -1, -1):
        acc *= z
        acc += coef[..., k]
        if derivative:
            dacc *= z
            dacc += dcoef[..., k]
    f = A[:, :1] + (acc * z).real
    if not derivative:
        return f
    return f, -(dacc * z).imag


@functools.lru_cache(maxsize=128)
def _colleague_tables(h):
    """Constant data of the colleague root finder for effective degree ``h``.

    Returns the rotation factors ``exp(i k alpha)`` (k = -h..h), the matrix
    ``S`` mapping the flattened products ``Re(b_k b_j)`` to the Chebyshev
    coefficients ``[g_0, 2 g_1, ..., 2 g_2h]`` (``g_n = sum_{k-j=n} b_k b_j``),
    and the tridiagonal part of the transposed colleague matrix
    (``x T_0 = T_1``, ``x T_k = (T_{k-1} + T_{k+1})/2``; upper Hessenberg).
    """
    n = 2 * h
    kk = np.arange(-h, h + 1)
    rot = np.exp(1j * _ALPHA * kk)
    shift = (kk[:, None] - kk[None, :]).ravel()
    S = np.zeros((shift.size, n + 1))
    keep = shift >= 0
    S[np.nonzero(keep)[0], shift[keep]] = np.where(shift[keep] > 0, 2.0, 1.0)
    T = np.zeros((n, n))
    T[1, 0] = 1.0
    i = np.arange(1, n - 1)
    T[i - 1, i] = 0.5
    T[i + 1, i] = 0.5
    T[n - 2, n - 1] = 0.5
    return rot, S, T


class CompanionRoots:
    """Candidate sign changes from the complex companion matrix of ``z^h phi(z)``,
    ``z = exp(iθ)`` (J. P. Boyd, J. Eng. Math. 56 (2006) 203-219): the arguments of its
    eigenvalues near ``|z| = 1``."""

    #: candidate angles per unit of degree
    per_degree = 2

    def angles(self, a: np.ndarray, h: int) -> np.ndarray:
        """Candidate angles in ``[0, 2π)`` (``inf`` where rejected) of the signals whose complex
        coefficients ``a_k``, ``k = -h..h``, are the rows of ``a``; shape ``(rows, 2h)``."""
        n = 2 * h
        # companion (upper Hessenberg) of p(z) = z^h phi(z) = sum_j a_{j-h} z^j
        Cm = np.zeros((a.shape[0], n, n), dtype=complex)
        Cm[:, np.arange(1, n), np.arange(n - 1)] = 1.0
        Cm[:, :, -1] = -a[:, :n] / a[:, n:]
        z = np.linalg.eigvals(Cm)
        ok = np.abs(np.abs(z) - 1.0) <= _ROOT_ACCEPT
        return np.where(ok, np.mod(np.angle(z), _TWO_PI), np.inf)

    def __repr__(self) -> str:
        return "CompanionRoots()"


class ColleagueRoots:
    """Candidate sign changes from the real colleague matrix (I. J. Good, Quart. J. Math. 12
    (1961) 61-68) of the even polynomial ``g(θ) = phi(α+θ) phi(α-θ)`` in ``x = cos θ``; each
    eigenvalue ``x`` near ``[-1, 1]`` gives the candidates ``α ± arccos x``. The default: 2-3x
    cheaper than :class:`CompanionRoots` for ``H >= 20`` (real arithmetic)."""

    per_degree = 4

    def angles(self, a: np.ndarray, h: int) -> np.ndarray:
        """As :meth:`CompanionRoots.angles`; shape ``(rows, 4h)``."""
        n = 2 * h
        # g(θ) = sum_n g_n e^{inθ}, g_n = sum_k b_k b_{k-n}, b_k = a_k e^{ikα}; direct convolution
        # keeps the leading coefficient g_{2h} = |b_h|^2 relatively accurate.
        rot, S, template = _colleague_tables(int(h))
        b = a * rot
        prod = (b[:, :, None] * b[:, None, :]).real.reshape(a.shape[0], -1)
        cheb = prod @ S  # g(x) = sum_n cheb_n T_n(x), x = cos θ
        Cm = np.repeat(template[None], a.shape[0], axis=0)
        Cm[:, :, n - 1] -= cheb[:, :n] / (2.0 * cheb[:, n:])
        x = np.linalg.eigvals(Cm)
        ok = (np.abs(x.imag) <= _ROOT_ACCEPT) & (np.abs(x.real) <= 1.0 + _ROOT_ACCEPT)
        acos = np.arccos(np.clip(x.real, -1.0, 1.0))
        ang = np.concatenate([_ALPHA + acos, _ALPHA - acos], axis=1)
        return np.where(np.concatenate([ok, ok], axis=1), np.mod(ang, _TWO_PI), np.inf)

    def __repr__(self) -> str:
        return "ColleagueRoots()"


class GridRoots:
    """Candidate sign changes from samples: the signal and its derivative on ``per_harmonic``
    equidistant points per period of its highest harmonic (one real inverse FFT for both), giving

    * the linearly interpolated zero of every cell where the signal changes sign, and
    * the linearly interpolated zero of the derivative in every cell where *it* changes sign
      (an extremum), so that a pair of sign changes inside one cell (a dip across zero between
      two samples) is seen too: the polishing of :func:`sign_changes` brackets each change
      between the extremum and its neighbours.

    A trigonometric polynomial of degree ``h`` has at most ``2h`` zeros and ``2h`` extrema, so
    ``4h`` candidates suffice. What it can miss: a sign change pair whose extremum lies in a cell
    together with another extremum (two derivative sign changes in one cell cancel); the missed
    interval is then narrower than a cell (``2 pi / (per_harmonic h)``) and its contribution
    to ``max(0, .)`` below ``(cell / 2)^3 max|phi''| / 3``. Cost ``O(h log h)`` per signal
    against ``O(h^3)`` for the matrix eigenvalues (4-18 ms at h = 40-80, measured).
    """

    per_degree = 4

    def __init__(self, per_harmonic: int = 16):
        if isinstance(per_harmonic, bool) or not isinstance(per_harmonic, (int, np.integer)) or per_harmonic < 4:
            raise ValueError(f"GridRoots: per_harmonic must be an integer >= 4, got {per_harmonic!r}")
        self.per_harmonic = int(per_harmonic)

    def angles(self, a: np.ndarray, h: int) -> np.ndarray:
        """As :meth:`CompanionRoots.angles`; shape ``(rows, 4h)``."""
        rows, h = a.shape[0], int(h)
        N, vals = self._samples(a[:, h:])  # (2 rows, N)
        nxt = np.concatenate([vals[:, 1:], vals[:, :1]], axis=1)
        q, j = np.nonzero((np.sign(vals) != np.sign(nxt)) & (nxt != 0.0))
        v0, v1 = vals[q, j], nxt[q, j]
        x = (j + np.clip(v0 / (v0 - v1), 0.0, 1.0)) * (_TWO_PI / N)  # v0 != v1: opposite signs
        r = q % rows  # zeros of phi and of phi' of the same signal go to the same row
        order = np.argsort(r, kind="stable")
        r, x = r[order], x[order]
        slot = np.arange(r.size) - np.searchsorted(r, r)
        keep = slot < 4 * h
        out = np.full((rows, 4 * h), np.inf)
        out[r[keep], slot[keep]] = np.mod(x[keep], _TWO_PI)
        return out

    def _samples(self, half: np.ndarray) -> tuple[int, np.ndarray]:
        """The grid size ``N`` for the degree ``h`` of the half spectra ``half`` (rows of the
        complex coefficients ``a_k``, ``k = 0..h``) and the samples of ``phi`` (first rows) and
        ``phi'`` (last rows) on it: one real inverse FFT of both half spectra, stacked."""
        h = half.shape[1] - 1
        N = max(64, self.per_harmonic * h)
        return N, np.fft.irfft(np.concatenate([half, half * (1j * np.arange(h + 1))]), n=N, axis=1) * N

    def sign_changes(self, A: np.ndarray) -> tuple[tuple, np.ndarray]:
        """The sign changes of the series rows ``A`` (m, L) read off the grid directly, without the
        candidate sort and the test points of :func:`sign_changes`: every grid cell where ``phi``
        changes sign brackets one root, and a cell where ``phi'`` changes sign towards zero (a
        minimum of a positive stretch, a maximum of a negative one) is tested at the interpolated
        extremum. Returns the result of :func:`sign_changes` for the rows it decides and the mask
        of the rows it leaves to the general path (:func:`sign_changes_of`): a sample within
        :data:`_GRID_TOL` rounding bounds of zero, or a dip that reaches zero (to rounding) inside a
        cell (a pair of roots there, or a tangency). In a cell where ``phi`` and ``phi'`` both
        change sign the root is bracketed on its side of the extremum. The roots are started from
        the cubic Hermite interpolant of the cell's samples (value and slope at both ends) and
        polished by :func:`_polish_in_cells`. Same miss model as :meth:`angles` (one extremum per
        cell at most is seen)."""
        m, L = A.shape
        H = (L - 1) // 2
        half = np.empty((m, H + 1), dtype=complex)
        half[:, 0] = A[:, 0]
        half[:, 1:] = 0.5 * (A[:, 1::2] - 1j * A[:, 2::2])
        N, vals = self._samples(half)
        cell = _TWO_PI / N
        vals = np.concatenate([vals, vals[:, :1]], axis=1)  # sample N is sample 0: the cells' right ends
        f, d = vals[:m], vals[m:]
        tol = _GRID_TOL * _EPS * np.sum(np.abs(A), axis=1)
        undecided = np.any(np.abs(f) <= tol[:, None], axis=1)
        pos, up = f > 0, d > 0
        root_cell = pos[:, :-1] != pos[:, 1:]
        turn = up[:, :-1] != up[:, 1:]
        # phi at the interpolated extremum of the cells where phi' changes sign and phi either heads
        # towards zero (a dip: across zero?) or changes sign (which side of the extremum the root is)
        dip = turn & ~root_cell & (pos[:, :-1] == up[:, 1:])
        r, j = np.nonzero((dip | (turn & root_cell)) & ~undecided[:, None])
        split = None
        if r.size:
            d0, d1 = d[r, j], d[r, j + 1]
            xe = (j + d0 / (d0 - d1)) * cell  # d0, d1 of opposite signs (or d0 = 0)
            fe = trig_eval(A[r], xe[:, None])[:, 0]
            left = (fe > 0) != pos[r, j]  # a sign change between the cell's start and the extremum
            undecided[r[(np.abs(fe) <= tol[r]) | (dip[r, j] & left)]] = True
            split = np.zeros(root_cell.shape)  # +xe: the root is before it, -xe: after it
            split[r, j] = np.where(left, xe, -xe)
        r, j = np.nonzero(root_cell & ~undecided[:, None])
        sign_const = np.where(pos[:, 0], 1, -1)
        if not r.size:
            return (np.zeros(0, dtype=np.intp), np.zeros(0), np.zeros(0), np.zeros(m, dtype=bool), sign_const), undecided
        a, b, da, db = f[r, j], f[r, j + 1], d[r, j] * cell, d[r, j + 1] * cell
        u = a / (a - b)  # linear interpolation, then two Newton steps on the cubic Hermite interpolant
        c2, c3 = 3.0 * (b - a) - 2.0 * da - db, 2.0 * (a - b) + da + db
        for _ in range(2):
            dp = da + u * (2.0 * c2 + 3.0 * c3 * u)
            u = np.clip(u - (a + u * (da + u * (c2 + u * c3))) / np.where(dp == 0.0, 1.0, dp), 0.0, 1.0)
        lo = j * cell
        hi = lo + cell
        if split is not None:  # a cell with an extremum: the root's side of it
            sp = split[r, j]
            lo, hi = np.where(sp < 0, -sp, lo), np.where(sp > 0, sp, hi)
        positive = pos[r, j]
        rho = _polish_in_cells(A[r], np.clip(j * cell + u * cell, lo, hi), lo, hi, positive)
        w = np.where(positive, 1.0, -1.0)  # positive before the root: the end of a positive interval
        wrap = np.zeros(m, dtype=bool)
        wrap[r] = pos[r, 0]
        return (r, rho, w, wrap, sign_const), undecided

    def __repr__(self) -> str:
        return f"GridRoots(per_harmonic={self.per_harmonic})"


def sign_changes_of(A, heff, roots):
    """The result of :func:`sign_changes` for the rows ``A`` (m, L) with effective degrees
    ``heff`` and the root finder ``roots``: for :class:`GridRoots` read off its grid
    (:meth:`GridRoots.sign_changes`), the rows it leaves undecided (and every row for the
    matrix root finders) by :func:`candidates` and :func:`sign_changes`."""
    if not isinstance(roots, GridRoots) or A.shape[1] < 3:
        return sign_changes(A, candidates(A, heff, roots))
    out, undecided = roots.sign_changes(A)
    if not undecided.any():
        return out
    idx = np.flatnonzero(undecided)
    rows, rho, w, wrap, sign_const = sign_changes(A[idx], candidates(A[idx], heff[idx], roots))
    keep = ~undecided[out[0]]
    wrap_all, sign_all = out[3].copy(), out[4].copy()
    wrap_all[idx], sign_all[idx] = wrap, sign_const
    rows_all = np.concatenate([out[0][keep], idx[rows]])
    order = np.argsort(rows_all, kind="stable")  # rows ascending, each row's roots in order
    return (rows_all[order], np.concatenate([out[1][keep], rho])[order], np.concatenate([out[2][keep], w])[order],
            wrap_all, sign_all)


def candidates(A, heff, roots):
    """Sorted candidate sign-change angles in [0, 2π), padded with inf, shape (m, R), from the
    root finder ``roots`` (:class:`ColleagueRoots` or :class:`CompanionRoots`)."""
    m = A.shape[0]
    R = roots.per_degree * int(heff.max(initial=0))
    out = np.full((m, max(R, 1)), np.inf)
    for h in np.unique(heff):
        if h == 0:
            continue
        rows = np.nonzero(heff == h)[0]
        # complex coefficients a_k, k = -h..h, of phi(θ) = sum a_k e^{ikθ}
        c = A[rows, 1 : 2 * h : 2]
        s = A[rows, 2 : 2 * h + 1 : 2]
        a_pos = 0.5 * (c - 1j * s)  # k = 1..h
        a = np.concatenate([np.conj(a_pos[:, ::-1]), A[rows, :1].astype(complex), a_pos], axis=1)
        ang = roots.angles(a, int(h))
        out[rows, : ang.shape[1]] = ang
    out.sort(axis=1)
    return out


def sign_changes(A, cand):
    """Polished sign changes of the series ``A`` (m, L) from candidate angles (m, R).

    Returns ``rows, rho, w, wrap, sign_const`` (see ``Harmonics._positive_gram``);
    ``sign_const`` is the sign of each signal where it has no sign change.
    """
    m, R = cand.shape
    r = np.sum(np.isfinite(cand), axis=1)
    rmax = int(r.max(initial=0))
    sign_const = np.where(A[:, 0] > 0, 1, -1)  # mean has the sign of a one-signed phi
    empty = (np.zeros(0, dtype=np.intp), np.zeros(0), np.zeros(0), np.zeros(m, dtype=bool))
    if rmax == 0:
        return (*empty, sign_const)
    cand = cand[:, :rmax]
    j = np.arange(rmax)
    valid = j < r[:, None]
    c = np.where(valid, cand, 0.0)
    nxt = np.where(j + 1 < r[:, None], np.roll(c, -1, axis=1), c[:, :1] + _TWO_PI)
    mid = 0.5 * (c + nxt)
    # test points t = c_0, mid_0, c_1, mid_1, ... (cyclically increasing)
    t = np.stack([c, mid], axis=2).reshape(m, 2 * rmax)
    tvalid = np.repeat(valid, 2, axis=1)
    nt = 2 * r
    f = trig_eval(A, t)
    tol = 8.0 * _EPS * np.sum(np.abs(A), axis=1)
    s = np.where(np.abs(f) > tol[:, None], np.sign(f), 0.0)
    s[~tvalid] = 0.0
    # undetermined points inherit the sign of the previous determined point (cyclically)
    k = np.arange(2 * rmax)
    last = np.maximum.accumulate(np.where(s != 0, k, -1), axis=1)
    last_row = last[:, -1]
    fill = np.where(last >= 0, last, last_row[:, None])
    s = np.take_along_axis(s, np.maximum(fill, 0), axis=1)
    undetermined = last_row < 0
    s[undetermined] = np.where(sign_const[undetermined] > 0, 1.0, -1.0)[:, None]
    has_pts = r > 0
    sign_const = np.where(has_pts, np.where(s[:, 0] > 0, 1, -1), sign_const)

    prev = np.where(k == 0, nt[:, None] - 1, k - 1)
    prev = np.where(tvalid, prev, 0)
    s_prev = np.take_along_axis(s, prev, axis=1)
    change = tvalid & (s != s_prev)
    rows, kk = np.nonzero(change)
    if rows.size == 0:
        return (*empty, sign_const)
    hi = t[rows, kk]
    lo = np.where(kk == 0, t[rows, nt[rows] - 1] - _TWO_PI, t[rows, np.maximum(kk - 1, 0)])
    x0 = np.where(kk % 2 == 0, hi, lo)  # the candidate end of the bracket
    rho = _polish(A[rows], x0, lo, hi, s_prev[rows, kk])
    w = np.where(s[rows, kk] > 0, -1.0, 1.0)
    wrap = np.zeros(m, dtype=bool)
    wrap[has_pts] = s[has_pts, nt[has_pts] - 1] > 0
    return rows, rho, w, wrap, sign_const


def _polish(A, x, lo, hi, sign_lo):
    """Safeguarded Newton for one root of each series ``A[p]`` in ``[lo[p], hi[p]]``.

    ``sign_lo`` is the sign of the series on the ``lo`` side.  Newton steps
    leaving the (shrinking) bracket are replaced by bisection, so the
    iteration converges to a root inside the bracket.
    """
    x, lo, hi = x.copy(), lo.copy(), hi.copy()
    active = np.arange(x.size)
    tol_f = 8.0 * _EPS * np.sum(np.abs(A), axis=1)
    H = (A.shape[1] - 1) // 2
    if H == 0 or x.size * H > _DIRECT_EVAL_MAX:
        evaluate = lambda act, xa: trig_eval(A[act], xa[:, None], derivative=True)  # noqa: E731
    else:
        # direct sums, the complex coefficients formed once: phi = c0 + Re sum a_k z^k,
        # phi' = Re sum i k a_k z^k
        k = np.arange(1, H + 1)
        both = _value_and_slope(A[:, 1::2] - 1j * A[:, 2::2])

        def evaluate(act, xa):
            s = np.matmul(np.exp(1j * xa[:, None] * k)[:, None, :], both[act])[:, 0, :].real
            return s[:, :1] + A[act, :1], s[:, 1:]

    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(_MAX_POLISH):
            if active.size == 0:
                break
            xa = x[active]
            f, fp = evaluate(active, xa)
            f, fp = f[:, 0], fp[:, 0]
            root = np.abs(f) <= tol_f[active]
            same = np.sign(f) == sign_lo[active]
            lo[active] = np.where(same & ~root, xa, lo[active])
            hi[active] = np.where(~same & ~root, xa, hi[active])
            la, ha = lo[active], hi[active]
            xn = xa - f / fp
            bad = ~np.isfinite(xn) | (xn <= la) | (xn >= ha)
            xn = np.where(bad, 0.5 * (la + ha), xn)
            step = np.abs(xn - xa)
            small = 4.0 * _EPS * (1.0 + np.abs(xa))
            done = root | (step <= small) | (ha - la <= small)
            # at a rounding-level residual take one last Newton step (if it stays
            # in the bracket): it lands within ~eps |phi| / |phi'| of the root
            x[active] = np.where(root & bad, xa, xn)
            active = active[~done]
    return x


def _polish_in_cells(A, x, lo, hi, positive):
    """The root of each series ``A[p]`` in its grid cell ``[lo[p], hi[p]]``
    (:meth:`GridRoots.sign_changes`; ``positive``: the series is positive on the ``lo`` side),
    from a start accurate to the cell's cubic Hermite interpolant: plain Newton steps until the
    next one would be below rounding, ``|phi''| dx^2 / (2 |phi'|) <= 4 eps (1 + |x|)`` (quadratic
    convergence; ``phi''`` summed with the value and the slope) or the residual is at rounding
    level, at most :data:`_CELL_NEWTON` steps; a root that has not converged so or left its cell
    is polished again by the safeguarded :func:`_polish`. Fewer operations per iteration than
    :func:`_polish` for the few roots of a grid (2 steps per root on the seed's forced case)."""
    x0 = x
    H = (A.shape[1] - 1) // 2
    k = np.arange(1, H + 1)
    both = _value_and_slope(A[:, 1::2] - 1j * A[:, 2::2], curvature=True)  # phi, phi', phi''
    c0 = A[:, 0]
    tol_f = 8.0 * _EPS * np.sum(np.abs(A), axis=1)
    done = np.zeros(x.size, dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(_CELL_NEWTON):
            s = np.matmul(np.exp(1j * x[:, None] * k)[:, None, :], both)[:, 0, :].real
            f, fp = s[:, 0] + c0, s[:, 1]
            dx = np.where(done, 0.0, -f / fp)
            done |= (np.abs(f) <= tol_f) | (np.abs(s[:, 2]) * dx * dx <= 8.0 * _EPS * (1.0 + np.abs(x)) * np.abs(fp))
            x = x + dx
            if done.all():
                break
    bad = ~(done & (x >= lo) & (x <= hi))  # (non-finite x fails the comparisons)
    if bad.any():
        x[bad] = _polish(A[bad], x0[bad], lo[bad], hi[bad], np.where(positive[bad], 1.0, -1.0))
    return x
