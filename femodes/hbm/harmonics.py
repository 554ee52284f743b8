r"""Truncated real Fourier series: layout, time grids, operators (and the exact positive part).

Conventions (owned by this module; nobody else computes offsets)
-----------------------------------------------------------------
Phase and time.  Every periodic signal is written in the phase
:math:`\theta = (\omega/\nu)\,t`, where :math:`\omega` is the excitation
frequency and :math:`\nu \ge 1` the subharmonic index, so the base
frequency is :math:`W = \omega/\nu` and the period is
:math:`T = 2\pi\nu/\omega`.

Series.  With :math:`H` harmonics

.. math::

    u(\theta) = c_0 + \sum_{k=1}^{H} \bigl(c_k \cos k\theta + s_k \sin k\theta\bigr).

Coefficient order of one signal: ``[c0, c1, s1, c2, s2, ..., cH, sH]``,
``n_coef = 2H + 1``; ``c_k`` sits at row ``2k - 1`` and ``s_k`` at row ``2k``.

Several signals (the ``n`` DOFs of a model, or ``m`` contact gaps) are stored
*harmonic-major* as an array ``Q`` of shape ``(n_coef, n)``; the global
unknown vector is ``Q.ravel()`` (C order), so coefficient row ``j`` of signal
``i`` is entry ``j*n + i``.  With this layout a linear operator acting on the
harmonic index (``A``, ``n_coef x n_coef``) and one acting on the DOF index
(``B``, ``n x n``) combine as ``np.kron(A, B) @ Q.ravel() == (A @ Q @ B.T).ravel()``.

Time grid.  ``N = n_time`` equidistant phases :math:`\theta_j = 2\pi j/N`,
physical times :math:`t_j = 2\pi\nu j/(\omega N)`.

Projection.  The Galerkin (Fourier) projection of a periodic function
:math:`f(\theta)` is

.. math::

    c_0 = \frac{1}{2\pi}\int_0^{2\pi} f\,d\theta,\qquad
    c_k = \frac{1}{\pi}\int_0^{2\pi} f\cos k\theta\,d\theta,\qquad
    s_k = \frac{1}{\pi}\int_0^{2\pi} f\sin k\theta\,d\theta,

i.e. coefficient ``a`` is ``norm_a * int f b_a`` with basis functions
``b = [1, cos θ, sin θ, ...]`` and ``norm = [1/2π, 1/π, 1/π, ...]``
(:meth:`Harmonics.projection_norms`).  Period averages of products use the
weights ``[1, 1/2, 1/2, ...]`` (:meth:`Harmonics.norm_weights`).

Exact positive part (:mod:`femodes.hbm.positive_part`).  :meth:`Harmonics.positive_part` returns the Galerkin
coefficients of :math:`\max(0, \varphi(\theta))` for a trigonometric
polynomial :math:`\varphi`, computed in closed form from the sign changes of
:math:`\varphi` (no sampling), together with its Jacobian.  This makes the
projected contact law continuously differentiable wherever the roots of
:math:`\varphi` are simple, unlike alternating frequency/time (AFT) sampling
(:meth:`Harmonics.positive_part_sampled`), which is piecewise linear with
jumps in its Jacobian.
"""

from __future__ import annotations

import numpy as np
from scipy.fft import next_fast_len

from ..solvers.checks import check_int
from . import positive_part as _pp

__all__ = ["Harmonics"]

_TWO_PI = 2.0 * np.pi
_EPS = np.finfo(float).eps

# Largest dense operator (entries) a Harmonics may need: the (N, 2H+1) synthesis and analysis
# matrices are built on first use, so a huge H or N must fail here, naming the argument, and
# not later in numpy ("array is too big") or as a MemoryError. 2**28 float64 = 2 GiB.
_MAX_DENSE = 2**28


def _check_omega(omega):
    omega = float(omega)
    if not np.isfinite(omega) or omega <= 0.0:
        raise ValueError(f"omega must be a finite positive frequency, got {omega!r}")
    return omega


def _readonly(a):
    a.setflags(write=False)
    return a


def _time_samples(H: int, n_time: int | None) -> int:
    """The number ``N`` of phase samples of a basis with ``H`` harmonics: ``n_time``, checked
    (``N >= 2H + 1``), or by default ``next_fast_len(4H + 1)``; ValueError if the dense
    ``(N, 2H + 1)`` Fourier operators would exceed :data:`_MAX_DENSE` entries."""
    if n_time is None:
        if (2 * H + 1) * (4 * H + 1) > _MAX_DENSE:  # before next_fast_len, which fails for huge H
            raise ValueError(
                f"n_harmonics={H} needs dense ({4 * H + 1} x {2 * H + 1}) Fourier operators of more than "
                f"{8 * _MAX_DENSE / 2**30:.0f} GiB; reduce n_harmonics"
            )
        N = int(next_fast_len(4 * H + 1, real=True))
    else:
        N = check_int("n_time", n_time, 1)
        if N < 2 * H + 1:
            raise ValueError(
                f"n_time must be >= 2*n_harmonics + 1 = {2 * H + 1}, got {n_time!r}"
            )
    if (2 * H + 1) * N > _MAX_DENSE:
        raise ValueError(
            f"n_harmonics={H} with n_time={N} needs dense ({N} x {2 * H + 1}) Fourier operators of "
            f"{8 * (2 * H + 1) * N / 2**30:.3g} GiB (more than {8 * _MAX_DENSE / 2**30:.0f} GiB); "
            "reduce n_harmonics or n_time"
        )
    return N


def _harmonic_numbers(k, lowest: int, H: int) -> np.ndarray:
    """``k`` as an integer array, checked to lie in ``[lowest, H]``."""
    k_arr = np.asarray(k)
    if k_arr.dtype.kind not in "iu":
        raise TypeError(f"harmonic number must be an integer, got {k!r}")
    if np.any(k_arr < lowest) or np.any(k_arr > H):
        raise ValueError(f"harmonic number must lie in [{lowest}, {H}], got {k!r}")
    return k_arr


def _basis(h: Harmonics, theta) -> np.ndarray:
    """Basis functions ``[1, cos theta, sin theta, ...]`` of ``h`` at the phases ``theta``, shape
    ``theta.shape + (n_coef,)``."""
    theta = np.asarray(theta, dtype=float)
    arg = theta[..., None] * h.harmonic_of
    return np.where(h.is_sine, np.sin(arg), np.cos(arg))


class Harmonics:
    r"""Truncated real Fourier basis with ``H`` harmonics of the base frequency ``omega/nu``.

    .. math::

        u(\theta) = c_0 + \sum_{k=1}^{H} c_k\cos k\theta + s_k\sin k\theta,
        \qquad \theta = \frac{\omega}{\nu} t.

    Immutable and hashable; dense operators are built lazily and cached
    (cached arrays are returned read-only).

    Parameters
    ----------
    n_harmonics : int
        Number of harmonics ``H >= 0`` (``H = 0``: constants only).
    n_time : int, optional
        Number ``N`` of equidistant phase samples per period.  Must satisfy
        ``N >= 2H + 1`` (the discrete projection reproduces every degree-``H``
        polynomial).  Default: ``scipy.fft.next_fast_len(4H + 1)``.  The rule
        ``N >= 4H + 1`` makes the Galerkin projection of a *cubic* nonlinearity
        alias-free: ``u^3 cos(k theta)`` has degree ``<= 4H`` and the discrete
        orthogonality ``sum_j cos(m theta_j) = 0`` is exact for
        ``0 < |m| < N``.  NLvib (companion code of Krack & Gross, *Harmonic
        Balance for Nonlinear Vibration Problems*, Springer 2019) examples use
        the same ``N = 4H + 1`` for cubic polynomials, citing App. A of
        Woiwode et al., Mech. Syst. Signal Process. 136 (2020) 106503,
        doi:10.1016/j.ymssp.2019.106503.  It is rounded up to a 5-smooth
        (fast FFT) size with :func:`scipy.fft.next_fast_len`.
        Non-polynomial laws are not alias-free for any finite ``N``; pass a
        larger ``n_time`` for them.
    subharmonic : int, optional
        Subharmonic index ``nu >= 1``; the period is ``2 pi nu / omega``.

    Raises
    ------
    TypeError
        If an argument is not an integer (``bool`` and ``float`` are rejected).
    ValueError
        If an argument is out of range.
    """

    __slots__ = ("_H", "_N", "_nu", "_cache")

    def __init__(self, n_harmonics: int, n_time: int | None = None, subharmonic: int = 1):
        H = check_int("n_harmonics", n_harmonics, 0)
        if H == 0:  # only the mean: no periodic motion can be represented
            raise ValueError("n_harmonics must be >= 1 (a periodic solution needs at least the fundamental), got 0; "
                             "for static equilibria with contact use femodes.static_contact")
        nu = check_int("subharmonic", subharmonic, 1)
        N = _time_samples(H, n_time)
        object.__setattr__(self, "_H", H)
        object.__setattr__(self, "_N", N)
        object.__setattr__(self, "_nu", nu)
        object.__setattr__(self, "_cache", {})

    def __setattr__(self, name, value):
        raise AttributeError(f"{type(self).__name__} is immutable")

    def __delattr__(self, name):
        raise AttributeError(f"{type(self).__name__} is immutable")

    def __repr__(self):
        return f"Harmonics(n_harmonics={self._H}, n_time={self._N}, subharmonic={self._nu})"

    def __eq__(self, other):
        if not isinstance(other, Harmonics):
            return NotImplemented
        return (self._H, self._N, self._nu) == (other._H, other._N, other._nu)

    def __hash__(self):
        return hash((Harmonics, self._H, self._N, self._nu))

    def __reduce__(self):
        return (Harmonics, (self._H, self._N, self._nu))

    def memo(self, key, build):
        try:
            return self._cache[key]
        except KeyError:
            value = build()
            self._cache[key] = value
            return value

    # ------------------------------------------------------------------ sizes
    @property
    def n_harmonics(self) -> int:
        """Number of harmonics ``H``."""
        return self._H

    @property
    def n_time(self) -> int:
        """Number ``N`` of phase samples per period."""
        return self._N

    @property
    def subharmonic(self) -> int:
        """Subharmonic index ``nu`` (base frequency ``omega/nu``)."""
        return self._nu

    @property
    def n_coef(self) -> int:
        """Number of real coefficients per signal, ``2H + 1``."""
        return 2 * self._H + 1

    def size(self, n: int) -> int:
        """Length ``n_coef * n`` of the global vector of an ``n``-signal model."""
        return self.n_coef * check_int("n", n, 0)

    # ----------------------------------------------------------------- layout
    def cos_index(self, k: int) -> int:
        """Row of ``c_k`` (``k = 0`` gives the mean ``c0`` at row 0): ``max(2k - 1, 0)``; one
        harmonic ``k`` in ``[0, H]`` (several: :meth:`cos_rows`)."""
        return int(self.cos_rows(check_int("k", k, 0))[()])

    def sin_index(self, k: int) -> int:
        """Row ``2k`` of ``s_k``; one harmonic ``k`` in ``[1, H]`` (several: :meth:`sin_rows`)."""
        return int(self.sin_rows(check_int("k", k, 1))[()])

    def cos_rows(self, ks) -> np.ndarray:
        """Rows of ``c_k`` for an integer array ``ks`` in ``[0, H]`` (an array of the same shape)."""
        return np.maximum(2 * _harmonic_numbers(ks, 0, self._H) - 1, 0)

    def sin_rows(self, ks) -> np.ndarray:
        """Rows of ``s_k`` for an integer array ``ks`` in ``[1, H]``."""
        return 2 * _harmonic_numbers(ks, 1, self._H)

    @property
    def harmonic_of(self) -> np.ndarray:
        """Harmonic number of each coefficient row: ``[0, 1, 1, 2, 2, ..., H, H]``."""
        return self.memo(
            "harmonic_of", lambda: _readonly((np.arange(self.n_coef) + 1) // 2)
        )

    @property
    def is_sine(self) -> np.ndarray:
        """Boolean mask of the sine rows (even rows ``>= 2``)."""
        def build():
            rows = np.arange(self.n_coef)
            return _readonly((rows > 0) & (rows % 2 == 0))

        return self.memo("is_sine", build)

    def global_index(self, j, dofs, n: int):
        """Position ``j*n + dof`` of coefficient row ``j`` of signal ``dof`` in ``Q.ravel()``.

        ``j`` and ``dofs`` broadcast against each other (numpy rules), e.g.
        ``global_index(np.arange(h.n_coef)[:, None], dofs, n)`` gives the
        ``(n_coef, len(dofs))`` array of all unknowns of ``dofs``.

        Raises
        ------
        ValueError
            If a row is outside ``[0, n_coef)`` or a DOF outside ``[0, n)``.
        """
        n = check_int("n", n, 1)
        j_arr = np.asarray(j)
        d_arr = np.asarray(dofs)
        for name, arr, upper in (("j", j_arr, self.n_coef), ("dofs", d_arr, n)):
            if arr.size and arr.dtype.kind not in "iu":
                raise TypeError(f"{name} must be integer, got dtype {arr.dtype}")
            if arr.size and (arr.min() < 0 or arr.max() >= upper):
                raise ValueError(f"{name} must lie in [0, {upper}), got {arr!r}")
        out = j_arr.astype(np.intp) * n + d_arr.astype(np.intp)
        return int(out) if out.ndim == 0 else out

    def reshape(self, x, n: int) -> np.ndarray:
        """View a global vector of length ``n_coef * n`` as ``Q`` of shape ``(n_coef, n)``."""
        x = np.asarray(x)
        n = check_int("n", n, 1)
        if x.ndim != 1 or x.shape[0] != self.n_coef * n:
            raise ValueError(
                f"expected a vector of length n_coef*n = {self.n_coef * n}, got shape {x.shape}"
            )
        return x.reshape(self.n_coef, n)

    def flatten(self, Q) -> np.ndarray:
        """Global vector ``Q.ravel()`` of coefficients ``Q`` of shape ``(n_coef, n)``."""
        Q = np.asarray(Q)
        self.check_coef(Q, "Q")
        return np.ascontiguousarray(Q).reshape(-1)

    def convert(self, Q, to: Harmonics) -> np.ndarray:
        """Coefficients ``Q`` (shape ``(n_coef, ...)``) of this basis on the basis ``to`` (same
        subharmonic index): harmonics up to ``min(H, H_to)`` copied, missing ones zero, the
        ones beyond ``H_to`` dropped (the L2-best truncation)."""
        if not isinstance(to, Harmonics) or to.subharmonic != self._nu:
            raise ValueError(f"convert: target must be a Harmonics with subharmonic={self._nu}, got {to!r}")
        Q = np.asarray(Q, dtype=float)
        self.check_coef(Q, "Q")
        out = np.zeros((to.n_coef,) + Q.shape[1:])
        m = 2 * min(self._H, to.n_harmonics) + 1  # rows [c0; c1; s1; ...; c_m; s_m] of both layouts
        out[:m] = Q[:m]
        return out

    def check_coef(self, Q, name, allow_1d=True):
        if Q.ndim not in ((1, 2) if allow_1d else (2,)) or Q.shape[0] != self.n_coef:
            raise ValueError(
                f"{name} must have shape (n_coef,) or (n_coef, n) with n_coef = {self.n_coef}, "
                f"got {Q.shape}"
            )

    # ------------------------------------------------------------ time grids
    def phases(self) -> np.ndarray:
        r"""Phase grid :math:`\theta_j = 2\pi j/N`, ``j = 0..N-1``."""
        return self.memo(
            "phases", lambda: _readonly(_TWO_PI * np.arange(self._N) / self._N)
        )

    def time_shift(self, Q, tau: float) -> np.ndarray:
        r"""Coefficients of the delayed signals :math:`q(\theta - \tau)` from ``Q`` (shape
        ``(n_coef, ...)``): harmonic ``k`` turned by the angle ``k tau``."""
        Q = np.asarray(Q, dtype=float)
        self.check_coef(Q, "Q")
        out = Q.copy()
        if self._H:
            kt = (np.arange(1, self._H + 1) * float(tau)).reshape((-1,) + (1,) * (Q.ndim - 1))
            co, si = np.cos(kt), np.sin(kt)
            c, s = Q[1::2], Q[2::2]
            out[1::2] = co * c - si * s
            out[2::2] = si * c + co * s
        return out

    def shift_generator(self, Q) -> np.ndarray:
        r"""``d/dtau`` of :meth:`time_shift` at ``tau = 0``, i.e. the coefficients of
        :math:`-\partial q / \partial\theta = -\nu D_1 Q` (:meth:`derivative_domega`):
        ``c_k -> -k s_k``, ``s_k -> k c_k``."""
        Q = np.asarray(Q, dtype=float)
        self.check_coef(Q, "Q")
        return -self._nu * (self.derivative_domega() @ Q)

    def period(self, omega: float) -> float:
        r"""Period :math:`T = 2\pi\nu/\omega` of the response."""
        return _TWO_PI * self._nu / _check_omega(omega)

    def times(self, omega: float) -> np.ndarray:
        r"""Physical sample times :math:`t_j = 2\pi\nu j/(\omega N)`."""
        return self.period(omega) * np.arange(self._N) / self._N

    def frequencies(self, omega: float) -> np.ndarray:
        r"""Angular frequency :math:`k\omega/\nu` of each coefficient row (0 for ``c0``)."""
        return self.harmonic_of * (float(omega) / self._nu)

    def most_open_phase(self, Q, dofs, gaps) -> float:
        r"""The phase :math:`\theta` at which the smallest of the gaps ``gaps - q_dofs(theta)`` is
        largest, on a grid of ``max(256, 8 n_coef)`` phases (0 without gaps): a start for a time
        integration away from the contact phases and slight penetrations of a harmonic balance
        solution ``Q`` (``fm.stability`` by shooting, the shooting refinement of
        :mod:`femodes.accuracy`)."""
        dofs = np.asarray(dofs, dtype=int)
        if not dofs.size:
            return 0.0
        n = max(256, 8 * self.n_coef)
        theta = _TWO_PI * np.arange(n) / n
        gaps = np.asarray(gaps, dtype=float) - self.synthesis(theta) @ np.asarray(Q)[:, dofs]
        return float(theta[int(np.argmax(gaps.min(axis=1)))])

    # -------------------------------------------------------------- operators
    def synthesis(self, theta=None) -> np.ndarray:
        r"""Synthesis matrix ``E`` with rows :math:`[1, \cos\theta_j, \sin\theta_j, \dots]`.

        Parameters
        ----------
        theta : array_like, optional
            Phases (1-D).  Default: the grid :meth:`phases`, in which case the
            cached ``(N, n_coef)`` matrix is returned.

        Returns
        -------
        ndarray, shape ``(len(theta), n_coef)``
        """
        if theta is None:
            return self.memo("E", lambda: _readonly(_basis(self, self.phases())))
        theta = np.asarray(theta, dtype=float)
        if theta.ndim != 1:
            raise ValueError(f"theta must be 1-D, got shape {theta.shape}")
        return _basis(self, theta)

    def grid_operators(self, N):
        """Discrete projection on ``N`` equidistant phases (``N >= 2H+1``)."""
        E = _basis(self, _TWO_PI * np.arange(N) / N)
        w = np.where(self.harmonic_of == 0, 1.0 / N, 2.0 / N)
        return E, w[:, None] * E.T

    def analysis(self) -> np.ndarray:
        r"""Discrete Galerkin projection ``P`` (``n_coef x N``) on the default grid.

        .. math::

            c_0 = \frac1N\sum_j u_j,\quad c_k = \frac2N\sum_j u_j\cos k\theta_j,\quad
            s_k = \frac2N\sum_j u_j\sin k\theta_j,

        the trapezoidal rule for the continuous projection, exact for
        integrands of degree ``< N``; hence ``P @ E = I``.
        """
        return self.memo("P", lambda: _readonly(self.grid_operators(self._N)[1]))

    def to_time(self, Q) -> np.ndarray:
        """Samples ``E @ Q`` on the phase grid: shape ``(N,)`` or ``(N, n)``."""
        Q = np.asarray(Q, dtype=float)
        self.check_coef(Q, "Q")
        return self.synthesis() @ Q

    def from_time(self, U) -> np.ndarray:
        """Coefficients ``P @ U`` of grid samples ``U`` of shape ``(N,)`` or ``(N, n)``."""
        U = np.asarray(U, dtype=float)
        if U.ndim not in (1, 2) or U.shape[0] != self._N:
            raise ValueError(f"U must have shape (N,) or (N, n) with N = {self._N}, got {U.shape}")
        return self.analysis() @ U

    def evaluate(self, Q, omega: float, t) -> np.ndarray:
        r"""Evaluate the series at physical times, :math:`\theta = \omega t/\nu`.

        Parameters
        ----------
        Q : array_like, shape ``(n_coef,)`` or ``(n_coef, n)``
        omega : float
            Excitation frequency.
        t : array_like
            Times (any shape).

        Returns
        -------
        ndarray, shape ``t.shape + Q.shape[1:]``
        """
        Q = np.asarray(Q, dtype=float)
        self.check_coef(Q, "Q")
        t = np.asarray(t, dtype=float)
        theta = t * (float(omega) / self._nu)
        return _basis(self, theta) @ Q

    def derivative(self, omega: float) -> np.ndarray:
        r"""Time-derivative operator ``D``: coefficients of ``du/dt`` are ``D @ Q``.

        With :math:`W = \omega/\nu`,
        :math:`\frac{d}{dt}(c\cos kWt + s\sin kWt) = kWs\cos kWt - kWc\sin kWt`,
        so ``D[2k-1, 2k] = kW`` and ``D[2k, 2k-1] = -kW`` (block diagonal,
        skew-symmetric).  Higher derivatives are powers, e.g. ``D @ D``.
        """
        return float(omega) * self.derivative_domega()

    def derivative_domega(self) -> np.ndarray:
        r"""``dD/domega``; ``D`` is linear in ``omega`` so this is ``D`` at ``omega = 1``."""
        def build():
            D = np.zeros((self.n_coef, self.n_coef))
            k = np.arange(1, self._H + 1)
            D[2 * k - 1, 2 * k] = k / self._nu
            D[2 * k, 2 * k - 1] = -k / self._nu
            return _readonly(D)

        return self.memo("D1", build)

    def projection_norms(self) -> np.ndarray:
        r"""Normalisation of the projection: ``[1/2pi, 1/pi, 1/pi, ...]``.

        Coefficient ``a`` of the projection of ``f`` is
        ``norm[a] * int_0^{2pi} f(theta) b_a(theta) dtheta``.
        """
        return self.memo(
            "norms",
            lambda: _readonly(np.where(self.harmonic_of == 0, 1.0 / _TWO_PI, 1.0 / np.pi)),
        )

    def norm_weights(self) -> np.ndarray:
        r"""Weights ``w = [1, 1/2, 1/2, ...]`` of the period average of products.

        .. math::

            \frac{1}{T}\int_0^T u\,v\,dt = \sum_a w_a U_a V_a

        for series ``u, v`` with coefficients ``U, V`` (Parseval).
        """
        return self.memo(
            "weights", lambda: _readonly(np.where(self.harmonic_of == 0, 1.0, 0.5))
        )

    # ----------------------------------------------------------- positive part
    def positive_part(self, phi, *, roots=None):
        """Exact Galerkin projection of ``max(0, phi)`` for one signal ``phi`` of shape
        ``(n_coef,)``, and its Jacobian (:func:`femodes.hbm.positive_part.positive_part`; many
        signals at once: :class:`femodes.hbm.ExactProjection`)."""
        return _pp.positive_part(self, phi, roots=roots)

    def positive_intervals(self, phi, *, roots=None):
        """Phase intervals ``(k, 2)`` where ``phi > 0`` (:func:`femodes.hbm.positive_part.positive_intervals`)."""
        return _pp.positive_intervals(self, phi, roots=roots)

    def positive_part_sampled(self, phi, n_time: int | None = None):
        """AFT approximation of :meth:`positive_part` (:func:`femodes.hbm.positive_part.positive_part_sampled`)."""
        return _pp.positive_part_sampled(self, phi, n_time)
