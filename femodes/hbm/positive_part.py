r"""Discretise layer: the exact Galerkin projection of ``max(0, phi)`` for a truncated Fourier series.

:func:`positive_part` returns the Galerkin coefficients of :math:`\max(0, \varphi(\theta))` and its
Jacobian in closed form from the sign changes of :math:`\varphi` (no sampling,
:mod:`femodes.hbm.trigroots`); :func:`positive_part_sampled` is the alternating frequency/time
(AFT) approximation kept for comparison. The :class:`~femodes.hbm.Harmonics` methods of the same
names call these functions.
"""

from __future__ import annotations

import numpy as np

from ..solvers.checks import check_int
from .trigroots import DEGREE_TOL, candidates, sign_changes

__all__ = ["positive_part", "positive_intervals", "positive_part_sampled"]

_TWO_PI = 2.0 * np.pi


def check_phi(h, phi):
    phi = np.asarray(phi, dtype=float)
    h.check_coef(phi, "phi")
    if not np.all(np.isfinite(phi)):
        raise ValueError("phi must be finite")
    return phi

def positive_part(h, phi, *, root_method: str = "colleague"):
    r"""Exact Galerkin projection of :math:`\max(0, \varphi(\theta))` and its Jacobian.

    .. math::

        G_{ab} = n_a \int_{\{\varphi > 0\}} b_a b_b \, d\theta, \qquad
        \mathrm{proj} = G\varphi, \qquad
        \frac{\partial\,\mathrm{proj}}{\partial\varphi} = G,

    with basis ``b = [1, cos θ, sin θ, ...]`` and ``n`` the
    :meth:`Harmonics.projection_norms`.  ``proj = G phi`` holds because
    ``max(0, phi) = phi * 1{phi > 0}``; the derivative equals ``G``
    because ``phi`` vanishes at the ends of the positive intervals, so the
    boundary terms of the Leibniz rule cancel.  ``proj`` is therefore
    continuously differentiable wherever the roots of ``phi`` are simple.

    Algorithm (no quadrature):

    1. Candidate sign changes: roots of a polynomial whose zeros contain
       the real zeros of ``phi``.  ``root_method="colleague"`` (default)
       takes the even trigonometric polynomial
       ``g(θ) = phi(α+θ) phi(α-θ)`` of degree ``2H``, whose cosine
       coefficients are the Chebyshev coefficients of ``g`` in
       ``x = cos θ``, and computes the eigenvalues of the (real) colleague
       matrix (I. J. Good, Quart. J. Math. 12 (1961) 61-68); each root
       ``x`` near ``[-1, 1]`` gives candidates ``α ± arccos x``.
       ``root_method="companion"`` uses the complex companion matrix of
       ``z^H phi(z)``, ``z = exp(iθ)``, with ``a_k = (c_k - i s_k)/2``
       (J. P. Boyd, J. Eng. Math. 56 (2006) 203-219), taking the
       arguments of the roots near ``|z| = 1``.  Both are batched over
       signals with :func:`numpy.linalg.eigvals` (LAPACK ``geev``, which
       balances the matrix); the real colleague matrix is 2-3x cheaper
       for ``H >= 20``.  Leading harmonics with
       ``max(|c_k|, |s_k|) <= 1e-16 max|phi|`` are dropped (effective
       degree).
    2. The candidates and the midpoints between them are sorted
       cyclically and ``phi`` is evaluated there.  Values below the
       rounding bound ``8 eps sum|phi_a|`` are "undetermined" and take the
       sign of the previous point, so a near-tangent sign change of depth
       at rounding level is ignored.  Spurious or duplicated candidates
       only split an interval; sampling at the candidates themselves also
       catches pairs of close roots whose eigenvalues came out as one
       complex pair.
    3. Every sign change between consecutive test points brackets a root,
       which is polished by safeguarded Newton iteration (bisection
       fallback) on the real trigonometric polynomial.
    4. The integrals of ``cos mθ`` and ``sin mθ`` (``m <= 2H``) over the
       positive set are differences of antiderivatives at the roots;
       products of basis functions follow by product-to-sum formulas.

    Special cases: ``phi`` positive everywhere gives ``G = I`` (exactly),
    non-positive everywhere (including ``phi == 0``) gives ``G = 0``.

    Parameters
    ----------
    phi : array_like, shape ``(n_coef,)`` or ``(n_coef, m)``
        Coefficients of one signal or of ``m`` independent signals.
    root_method : {"colleague", "companion"}, optional
        Candidate root finder (see above).

    Returns
    -------
    proj : ndarray, same shape as ``phi``
        Galerkin coefficients of ``max(0, phi)``.
    G : ndarray, shape ``(n_coef, n_coef)`` or ``(m, n_coef, n_coef)``
        Jacobian ``d proj / d phi`` (per signal).  ``diag(1/norms) @ G``
        is symmetric.

    Notes
    -----
    Accuracy: roots are accurate to ``~ eps |phi| / |phi'|``; ``proj`` and
    ``G`` to a few ``eps`` relative to ``max|phi|`` for simple roots.  Near
    a tangency (double root) of depth ``delta`` the interval length
    ``~ sqrt(delta)`` is resolved as long as ``delta`` exceeds the
    rounding bound above.
    """
    phi = check_phi(h, phi)
    single = phi.ndim == 1
    Phi = phi[:, None] if single else phi
    G = positive_gram(h, Phi.T, root_method)[0]
    proj = np.einsum("sab,bs->as", G, Phi)
    if single:
        return proj[:, 0], G[0]
    return proj, G

def positive_intervals(h, phi, *, root_method: str = "colleague"):
    """Intervals ``[start, end]`` where ``phi(theta) > 0``.

    Parameters
    ----------
    phi : array_like, shape ``(n_coef,)`` or ``(n_coef, m)``

    Returns
    -------
    ndarray of shape ``(k, 2)``, or a list of ``m`` such arrays
        Phase intervals (radians), sorted by ``start``, with
        ``0 <= start < 2 pi`` and ``start < end < start + 2 pi`` (an
        interval crossing ``theta = 2 pi`` has ``end > 2 pi``).  ``[[0, 2 pi]]`` if ``phi > 0``
        everywhere, empty if nowhere.  The contact fraction is
        ``sum(end - start) / (2 pi)``.
    """
    phi = check_phi(h, phi)
    single = phi.ndim == 1
    Phi = phi[:, None] if single else phi
    _, info = positive_gram(h, Phi.T, root_method)
    rows, rho, w, wrap, full = info
    out = []
    for s in range(Phi.shape[1]):
        if full[s]:
            out.append(np.array([[0.0, _TWO_PI]]))
            continue
        sel = rows == s
        r, ws = rho[sel], w[sel]
        order = np.argsort(r, kind="stable")
        r, ws = r[order], ws[order]
        starts = r[ws < 0]
        ends = r[ws > 0]
        if wrap[s]:
            ends = np.concatenate([ends[1:], ends[:1] + _TWO_PI])
        shift = np.floor(starts / _TWO_PI) * _TWO_PI
        iv = np.column_stack([starts - shift, ends - shift]).reshape(-1, 2)
        out.append(iv[np.argsort(iv[:, 0], kind="stable")])
    return out[0] if single else out

def positive_part_sampled(h, phi, n_time: int | None = None):
    r"""AFT approximation of :func:`positive_part` by sampling on a grid.

    .. math::

        \mathrm{proj} = P_N \max(0, E_N\varphi), \qquad
        G = P_N\,\mathrm{diag}(1\{E_N\varphi > 0\})\,E_N,

    with the grid operators of ``n_time`` samples (default
    :attr:`n_time`).  Piecewise linear in ``phi``; its Jacobian jumps
    whenever a sample changes sign.  For comparison only.
    """
    phi = check_phi(h, phi)
    N = h.n_time if n_time is None else check_int("n_time", n_time, 2 * h.n_harmonics + 1)
    E, P = h.memo(("grid", N), lambda: h.grid_operators(N))
    single = phi.ndim == 1
    Phi = phi[:, None] if single else phi
    U = E @ Phi
    ind = (U > 0.0).astype(float)
    proj = P @ (U * ind)
    G = (P[None, :, :] * ind.T[:, None, :]) @ E
    if single:
        return proj[:, 0], G[0]
    return proj, G

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
        k = h.harmonic_of
        sin = h.is_sine
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

def positive_gram(h, Phi, root_method):
    """Core of :func:`positive_part`; ``Phi`` has shape ``(m, n_coef)``.

    Returns ``G`` of shape ``(m, n_coef, n_coef)`` and the root data
    ``(rows, rho, w, wrap, full)``: root ``rho`` of signal ``rows`` with
    ``w = +1`` at the end of a positive interval and ``-1`` at its start;
    ``wrap`` marks signals positive at the start of the sweep (the last
    interval crosses the cut), ``full`` those positive everywhere.
    """
    if root_method not in ("colleague", "companion"):
        raise ValueError(
            f"root_method must be 'colleague' or 'companion', got {root_method!r}"
        )
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

    cand = candidates(A, heff, root_method)  # (m, R) sorted, inf padded
    rows, rho, w, wrap, sign_const = sign_changes(A, cand)

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
        G = h.projection_norms()[:, None] * M
        G[~changed] = 0.0
    G[full] = np.eye(L)
    return G, (rows, rho, w, wrap & changed, full)
