r"""Discretise layer: the exact Galerkin projection of ``max(0, phi)`` for a truncated Fourier series.

:func:`positive_part` returns the Galerkin coefficients of :math:`\max(0, \varphi(\theta))` and its
Jacobian in closed form from the sign changes of :math:`\varphi` (no sampling,
:mod:`femodes.hbm.trigroots`); :func:`positive_part_sampled` is the alternating frequency/time
(AFT) approximation kept for comparison. The methods of the same names of ``h.galerkin``
(:class:`~femodes.hbm.galerkin.GalerkinProjection`) call these functions.
"""

from __future__ import annotations

import numpy as np

from ..solvers.checks import check_int, entry_point
from .trigroots import DEGREE_TOL, GridRoots, sign_changes_of

__all__ = ["positive_part", "positive_intervals", "positive_part_sampled", "ExactProjection", "SampledProjection"]

_TWO_PI = 2.0 * np.pi


def check_phi(h, phi, *, single: bool):
    """``phi`` as a finite float array of shape ``(n_coef,)`` (``single``) or ``(n_coef, m)``."""
    phi = np.asarray(phi, dtype=float)
    want = 1 if single else 2
    if phi.ndim != want or phi.shape[0] != h.n_coef:
        shape = "(n_coef,)" if single else "(n_coef, m)"
        hint = ("; for several signals at once use femodes.hbm.ExactProjection()(h, Phi)" if single
                else "; for one signal use h.galerkin.positive_part(phi)")
        raise ValueError(f"phi must have shape {shape} with n_coef = {h.n_coef}, got {phi.shape}{hint}")
    if not np.all(np.isfinite(phi)):
        raise ValueError("phi must be finite")
    return phi


def positive_part(h, phi, *, roots=None):
    r"""Exact Galerkin projection of :math:`\max(0, \varphi(\theta))` and its Jacobian.

    .. math::

        G_{ab} = n_a \int_{\{\varphi > 0\}} b_a b_b \, d\theta, \qquad
        \mathrm{proj} = G\varphi, \qquad
        \frac{\partial\,\mathrm{proj}}{\partial\varphi} = G,

    with basis ``b = [1, cos θ, sin θ, ...]`` and ``n`` the ``h.galerkin.projection_norms()``.
    ``proj = G phi`` holds because ``max(0, phi) = phi * 1{phi > 0}``; the derivative equals ``G``
    because ``phi`` vanishes at the ends of the positive intervals, so ``proj`` is continuously
    differentiable wherever the roots of ``phi`` are simple. No quadrature: candidate sign changes
    from ``roots``, test points between them (values below the rounding bound ``8 eps sum|phi_a|``
    take the previous sign), roots polished by safeguarded Newton, and closed-form integrals between
    them. ``phi`` positive everywhere gives ``G = I`` exactly, non-positive everywhere ``G = 0``. The
    algorithm step by step, with its measurements: :doc:`/guide/harmonic-balance`.

    Parameters
    ----------
    phi : array_like, shape ``(n_coef,)``
        Coefficients of one signal (many signals at once: :class:`ExactProjection`).
    roots : GridRoots, ColleagueRoots or CompanionRoots, optional
        Candidate root finder, default ``GridRoots()`` (FFT samples of ``phi`` and ``phi'``); the
        others use the colleague matrix (I. J. Good, Quart. J. Math. 12 (1961) 61-68) or the companion
        matrix (J. P. Boyd, J. Eng. Math. 56 (2006) 203-219).

    Returns
    -------
    proj : ndarray, shape ``(n_coef,)``
        Galerkin coefficients of ``max(0, phi)``.
    G : ndarray, shape ``(n_coef, n_coef)``
        Jacobian ``d proj / d phi``.  ``diag(1/norms) @ G`` is symmetric.

    Notes
    -----
    Accuracy: roots are accurate to ``~ eps |phi| / |phi'|``; ``proj`` and ``G`` to a few ``eps``
    relative to ``max|phi|`` for simple roots. Near a tangency (double root) of depth ``delta`` the
    interval length ``~ sqrt(delta)`` is resolved as long as ``delta`` exceeds the rounding bound.
    """
    phi = check_phi(h, phi, single=True)
    G = positive_gram(h, phi[None, :], roots)[0][0]
    return G @ phi, G


def positive_intervals(h, phi, *, roots=None):
    """Intervals ``[start, end]`` where ``phi(theta) > 0``.

    Parameters
    ----------
    phi : array_like, shape ``(n_coef,)``
    roots : GridRoots, ColleagueRoots or CompanionRoots, optional
        Root finder (default :class:`~femodes.hbm.trigroots.GridRoots`).

    Returns
    -------
    ndarray of shape ``(k, 2)``
        Phase intervals (radians), sorted by ``start``, with
        ``0 <= start < 2 pi`` and ``start < end < start + 2 pi`` (an
        interval crossing ``theta = 2 pi`` has ``end > 2 pi``).  ``[[0, 2 pi]]`` if ``phi > 0``
        everywhere, empty if nowhere.  The contact fraction is
        ``sum(end - start) / (2 pi)``.
    """
    phi = check_phi(h, phi, single=True)
    _, info = positive_gram(h, phi[None, :], roots)
    rows, rho, w, wrap, full = info
    if full[0]:
        return np.array([[0.0, _TWO_PI]])
    order = np.argsort(rho, kind="stable")
    r, ws = rho[order], w[order]
    starts = r[ws < 0]
    ends = r[ws > 0]
    if wrap[0]:
        ends = np.concatenate([ends[1:], ends[:1] + _TWO_PI])
    shift = np.floor(starts / _TWO_PI) * _TWO_PI
    iv = np.column_stack([starts - shift, ends - shift]).reshape(-1, 2)
    return iv[np.argsort(iv[:, 0], kind="stable")]

def positive_part_sampled(h, phi, n_time: int | None = None):
    r"""AFT approximation of :func:`positive_part` by sampling on a grid.

    .. math::

        \mathrm{proj} = P_N \max(0, E_N\varphi), \qquad
        G = P_N\,\mathrm{diag}(1\{E_N\varphi > 0\})\,E_N,

    with the grid operators of ``n_time`` samples (default
    :attr:`n_time`).  Piecewise linear in ``phi``; its Jacobian jumps
    whenever a sample changes sign.  For comparison only.
    """
    phi = check_phi(h, phi, single=True)
    proj, G = _sampled(h, phi[:, None], n_time)
    return proj[:, 0], G[0]


def _sampled(h, Phi, n_time):
    N = h.n_time if n_time is None else check_int("n_time", n_time, 2 * h.n_harmonics + 1)
    E, P = h.memo(("grid", N), lambda: h.grid.grid_operators(N))
    U = E @ Phi
    ind = (U > 0.0).astype(float)
    return P @ (U * ind), (P[None, :, :] * ind.T[:, None, :]) @ E


class ExactProjection:
    """Strategy of the harmonic balance for ``max(0, .)``: the exact Galerkin projection
    (:func:`positive_part`) of many signals at once. The default of :class:`~femodes.hbm.HBMSystem`.

    ``ExactProjection(roots=CompanionRoots())`` picks the root finder.
    ``projection(h, Phi)`` with ``Phi`` of shape ``(n_coef, m)`` returns ``proj`` of the same
    shape and the Jacobians ``G`` of shape ``(m, n_coef, n_coef)``.
    """

    def __init__(self, roots=None):
        self.roots = GridRoots() if roots is None else roots
        if not callable(getattr(self.roots, "angles", None)):
            raise TypeError(f"ExactProjection: roots must be GridRoots(), ColleagueRoots() or CompanionRoots(), got {roots!r}")

    def __call__(self, h, Phi):
        Phi = check_phi(h, Phi, single=False)
        G = positive_gram(h, Phi.T, self.roots)[0]
        return np.einsum("sab,bs->as", G, Phi), G

    def __repr__(self) -> str:
        return f"ExactProjection(roots={self.roots!r})"


class SampledProjection:
    """Strategy of the harmonic balance for ``max(0, .)``: alternating frequency/time sampling on
    ``n_time`` points (:func:`positive_part_sampled`); for comparison only (its Jacobian jumps and
    semismooth Newton cycles near contact onset). Same call as :class:`ExactProjection`."""

    @entry_point("SampledProjection")
    def __init__(self, n_time: int | None = None):
        self.n_time = None if n_time is None else check_int("n_time", n_time, 1)

    def __call__(self, h, Phi):
        return _sampled(h, check_phi(h, Phi, single=False), self.n_time)

    def __repr__(self) -> str:
        return f"SampledProjection(n_time={self.n_time})"


def gram_tables(h):
    """Index/weight tables turning antiderivative sums into basis Gram matrices.

    With ``C(m) = int cos(m θ)`` and ``S(m) = int sin(m θ)`` over the
    positive set (``C`` even, ``S`` odd in ``m``), product-to-sum gives
    ``cos j cos k -> (C(j-k) + C(j+k))/2``,
    ``sin j sin k -> (C(j-k) - C(j+k))/2``,
    ``cos j sin k -> (S(k-j) + S(j+k))/2``,
    ``sin j cos k -> (S(j-k) + S(j+k))/2``.  ``V = [C(0..2H), S(0..2H)]``.
    """
    def build():
        L = 2 * h.n_harmonics + 1
        k = h.layout.harmonic_of
        sin = h.layout.is_sine
        ka, kb = k[:, None], k[None, :]
        sa, sb = sin[:, None], sin[None, :]
        diff = np.where(sa == sb, ka - kb, np.where(sa, ka - kb, kb - ka))
        summ = ka + kb
        both_sin = sa & sb
        mixed = sa != sb
        idx1 = np.where(mixed, L + np.abs(diff), np.abs(diff))
        idx2 = np.where(mixed, L + summ, summ)
        w1 = np.where(mixed, 0.5 * np.sign(diff), 0.5)
        w2 = np.where(both_sin, -0.5, 0.5)
        return idx1, w1, idx2, w2

    return h.memo("gram", build)

def positive_gram(h, Phi, roots=None):
    """Core of :func:`positive_part`; ``Phi`` has shape ``(m, n_coef)``.

    Returns ``G`` of shape ``(m, n_coef, n_coef)`` and the root data
    ``(rows, rho, w, wrap, full)``: root ``rho`` of signal ``rows`` with
    ``w = +1`` at the end of a positive interval and ``-1`` at its start;
    ``wrap`` marks signals positive at the start of the sweep (the last
    interval crosses the cut), ``full`` those positive everywhere.
    """
    roots = GridRoots() if roots is None else roots
    H = h.n_harmonics
    L = 2 * H + 1
    m = Phi.shape[0]
    scale = np.max(np.abs(Phi), axis=1)
    nonzero = scale > 0.0
    A = Phi / np.where(nonzero, scale, 1.0)[:, None]

    # effective degree
    if H > 0:
        amp = np.maximum(np.abs(A[:, 1::2]), np.abs(A[:, 2::2]))
        present = amp > DEGREE_TOL
        heff = np.where(present.any(axis=1), H - np.argmax(present[:, ::-1], axis=1), 0)
    else:
        heff = np.zeros(m, dtype=int)
    heff = np.where(nonzero, heff, 0)

    rows, rho, w, wrap, sign_const = sign_changes_of(A, heff, roots)

    # signals without sign change: constant sign
    changed = np.zeros(m, dtype=bool)
    changed[rows] = True
    full = (~changed) & (sign_const > 0) & nonzero

    G = np.zeros((m, L, L))
    if rows.size:
        mm = np.arange(L)
        arg = rho[:, None] * mm
        inv = np.zeros(L)
        inv[1:] = 1.0 / mm[1:]
        Fc = np.sin(arg) * inv
        Fc[:, 0] = rho
        Fs = -np.cos(arg) * inv
        Wm = np.zeros((m, rho.size))
        Wm[rows, np.arange(rho.size)] = w
        V = np.concatenate([Wm @ Fc, Wm @ Fs], axis=1)
        V[:, 0] += np.where(wrap, _TWO_PI, 0.0)
        idx1, w1, idx2, w2 = gram_tables(h)
        M = w1 * V[:, idx1] + w2 * V[:, idx2]
        G = h.galerkin.projection_norms()[:, None] * M
        G[~changed] = 0.0
    G[full] = np.eye(L)
    return G, (rows, rho, w, wrap & changed, full)
