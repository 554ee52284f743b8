r"""Truncated real Fourier series: layout, time grids, operators, exact positive part.

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

Exact positive part.  :meth:`Harmonics.positive_part` returns the Galerkin
coefficients of :math:`\max(0, \varphi(\theta))` for a trigonometric
polynomial :math:`\varphi`, computed in closed form from the sign changes of
:math:`\varphi` (no sampling), together with its Jacobian.  This makes the
projected contact law continuously differentiable wherever the roots of
:math:`\varphi` are simple, unlike alternating frequency/time (AFT) sampling
(:meth:`Harmonics.positive_part_sampled`), which is piecewise linear with
jumps in its Jacobian.
"""

from __future__ import annotations

import functools
import numbers

import numpy as np
from scipy.fft import next_fast_len

__all__ = ["Harmonics"]

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
# max(|c_k|, |s_k|) <= _DEGREE_TOL * max|coefficient|; such terms change phi by
# less than rounding of its evaluation.
_DEGREE_TOL = 1e-16

_MAX_POLISH = 100

# Largest dense operator (entries) a Harmonics may need: the (N, 2H+1) synthesis and analysis
# matrices are built on first use, so a huge H or N must fail here, naming the argument, and
# not later in numpy ("array is too big") or as a MemoryError. 2**28 float64 = 2 GiB.
_MAX_DENSE = 2**28


def _check_int(name, value, minimum):
    """Return ``int(value)`` after checking it is an integer ``>= minimum``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {value!r} ({type(value).__name__})")
    value = int(value)
    if value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return value


def _check_omega(omega):
    omega = float(omega)
    if not np.isfinite(omega) or omega <= 0.0:
        raise ValueError(f"omega must be a finite positive frequency, got {omega!r}")
    return omega


def _readonly(a):
    a.setflags(write=False)
    return a


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
        H = _check_int("n_harmonics", n_harmonics, 0)
        nu = _check_int("subharmonic", subharmonic, 1)
        if n_time is None:
            if (2 * H + 1) * (4 * H + 1) > _MAX_DENSE:  # before next_fast_len, which fails for huge H
                raise ValueError(
                    f"n_harmonics={H} needs dense ({4 * H + 1} x {2 * H + 1}) Fourier operators of more than "
                    f"{8 * _MAX_DENSE / 2**30:.0f} GiB; reduce n_harmonics"
                )
            N = int(next_fast_len(4 * H + 1, real=True))
        else:
            N = _check_int("n_time", n_time, 1)
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

    def _cached(self, key, build):
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
        return self.n_coef * _check_int("n", n, 0)

    # ----------------------------------------------------------------- layout
    def _check_harmonic(self, k, lowest):
        k_arr = np.asarray(k)
        if k_arr.dtype.kind not in "iu":
            raise TypeError(f"harmonic number must be an integer, got {k!r}")
        if np.any(k_arr < lowest) or np.any(k_arr > self._H):
            raise ValueError(f"harmonic number must lie in [{lowest}, {self._H}], got {k!r}")
        return k_arr

    def cos_index(self, k):
        """Row of ``c_k`` (``k = 0`` gives the mean ``c0`` at row 0): ``max(2k - 1, 0)``.

        Vectorised over integer arrays ``k`` in ``[0, H]``.
        """
        k_arr = self._check_harmonic(k, 0)
        out = np.maximum(2 * k_arr - 1, 0)
        return int(out) if out.ndim == 0 else out

    def sin_index(self, k):
        """Row ``2k`` of ``s_k``; ``k`` (integer or integer array) in ``[1, H]``."""
        k_arr = self._check_harmonic(k, 1)
        out = 2 * k_arr
        return int(out) if out.ndim == 0 else out

    @property
    def harmonic_of(self) -> np.ndarray:
        """Harmonic number of each coefficient row: ``[0, 1, 1, 2, 2, ..., H, H]``."""
        return self._cached(
            "harmonic_of", lambda: _readonly((np.arange(self.n_coef) + 1) // 2)
        )

    @property
    def is_sine(self) -> np.ndarray:
        """Boolean mask of the sine rows (even rows ``>= 2``)."""
        def build():
            rows = np.arange(self.n_coef)
            return _readonly((rows > 0) & (rows % 2 == 0))

        return self._cached("is_sine", build)

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
        n = _check_int("n", n, 1)
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
        n = _check_int("n", n, 1)
        if x.ndim != 1 or x.shape[0] != self.n_coef * n:
            raise ValueError(
                f"expected a vector of length n_coef*n = {self.n_coef * n}, got shape {x.shape}"
            )
        return x.reshape(self.n_coef, n)

    def flatten(self, Q) -> np.ndarray:
        """Global vector ``Q.ravel()`` of coefficients ``Q`` of shape ``(n_coef, n)``."""
        Q = np.asarray(Q)
        self._check_coef(Q, "Q")
        return np.ascontiguousarray(Q).reshape(-1)

    def _check_coef(self, Q, name, allow_1d=True):
        if Q.ndim not in ((1, 2) if allow_1d else (2,)) or Q.shape[0] != self.n_coef:
            raise ValueError(
                f"{name} must have shape (n_coef,) or (n_coef, n) with n_coef = {self.n_coef}, "
                f"got {Q.shape}"
            )

    # ------------------------------------------------------------ time grids
    def phases(self) -> np.ndarray:
        r"""Phase grid :math:`\theta_j = 2\pi j/N`, ``j = 0..N-1``."""
        return self._cached(
            "phases", lambda: _readonly(_TWO_PI * np.arange(self._N) / self._N)
        )

    def period(self, omega: float) -> float:
        r"""Period :math:`T = 2\pi\nu/\omega` of the response."""
        return _TWO_PI * self._nu / _check_omega(omega)

    def times(self, omega: float) -> np.ndarray:
        r"""Physical sample times :math:`t_j = 2\pi\nu j/(\omega N)`."""
        return self.period(omega) * np.arange(self._N) / self._N

    def frequencies(self, omega: float) -> np.ndarray:
        r"""Angular frequency :math:`k\omega/\nu` of each coefficient row (0 for ``c0``)."""
        return self.harmonic_of * (float(omega) / self._nu)

    # -------------------------------------------------------------- operators
    def _basis(self, theta):
        theta = np.asarray(theta, dtype=float)
        arg = theta[..., None] * self.harmonic_of
        return np.where(self.is_sine, np.sin(arg), np.cos(arg))

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
            return self._cached("E", lambda: _readonly(self._basis(self.phases())))
        theta = np.asarray(theta, dtype=float)
        if theta.ndim != 1:
            raise ValueError(f"theta must be 1-D, got shape {theta.shape}")
        return self._basis(theta)

    def _grid_analysis(self, N):
        """Discrete projection on ``N`` equidistant phases (``N >= 2H+1``)."""
        E = self._basis(_TWO_PI * np.arange(N) / N)
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
        return self._cached("P", lambda: _readonly(self._grid_analysis(self._N)[1]))

    def to_time(self, Q) -> np.ndarray:
        """Samples ``E @ Q`` on the phase grid: shape ``(N,)`` or ``(N, n)``."""
        Q = np.asarray(Q, dtype=float)
        self._check_coef(Q, "Q")
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
        self._check_coef(Q, "Q")
        t = np.asarray(t, dtype=float)
        theta = t * (float(omega) / self._nu)
        return self._basis(theta) @ Q

    def derivative(self, omega: float) -> np.ndarray:
        r"""Time-derivative operator ``D``: coefficients of ``du/dt`` are ``D @ Q``.

        With :math:`W = \omega/\nu`,
        :math:`\frac{d}{dt}(c\cos kWt + s\sin kWt) = kWs\cos kWt - kWc\sin kWt`,
        so ``D[2k-1, 2k] = kW`` and ``D[2k, 2k-1] = -kW`` (block diagonal,
        skew-symmetric).  Higher derivatives are powers, e.g. ``D @ D``.
        """
        return float(omega) * self.derivative_domega(omega)

    def derivative_domega(self, omega: float | None = None) -> np.ndarray:
        r"""``dD/domega``; ``D`` is linear in ``omega`` so this is ``D`` at ``omega = 1``.

        The argument is accepted for symmetry with :meth:`derivative` and ignored.
        """
        def build():
            D = np.zeros((self.n_coef, self.n_coef))
            k = np.arange(1, self._H + 1)
            D[2 * k - 1, 2 * k] = k / self._nu
            D[2 * k, 2 * k - 1] = -k / self._nu
            return _readonly(D)

        return self._cached("D1", build)

    def projection_norms(self) -> np.ndarray:
        r"""Normalisation of the projection: ``[1/2pi, 1/pi, 1/pi, ...]``.

        Coefficient ``a`` of the projection of ``f`` is
        ``norm[a] * int_0^{2pi} f(theta) b_a(theta) dtheta``.
        """
        return self._cached(
            "norms",
            lambda: _readonly(np.where(self.harmonic_of == 0, 1.0 / _TWO_PI, 1.0 / np.pi)),
        )

    def norm_weights(self) -> np.ndarray:
        r"""Weights ``w = [1, 1/2, 1/2, ...]`` of the period average of products.

        .. math::

            \frac{1}{T}\int_0^T u\,v\,dt = \sum_a w_a U_a V_a

        for series ``u, v`` with coefficients ``U, V`` (Parseval).
        """
        return self._cached(
            "weights", lambda: _readonly(np.where(self.harmonic_of == 0, 1.0, 0.5))
        )

    def mean_square_weights(self) -> np.ndarray:
        """Alias of :meth:`norm_weights`."""
        return self.norm_weights()

    # ----------------------------------------------------------- positive part
    def _check_phi(self, phi):
        phi = np.asarray(phi, dtype=float)
        self._check_coef(phi, "phi")
        if not np.all(np.isfinite(phi)):
            raise ValueError("phi must be finite")
        return phi

    def positive_part(self, phi, *, root_method: str = "colleague"):
        r"""Exact Galerkin projection of :math:`\max(0, \varphi(\theta))` and its Jacobian.

        .. math::

            G_{ab} = n_a \int_{\{\varphi > 0\}} b_a b_b \, d\theta, \qquad
            \mathrm{proj} = G\varphi, \qquad
            \frac{\partial\,\mathrm{proj}}{\partial\varphi} = G,

        with basis ``b = [1, cos θ, sin θ, ...]`` and ``n`` the
        :meth:`projection_norms`.  ``proj = G phi`` holds because
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
        phi = self._check_phi(phi)
        single = phi.ndim == 1
        Phi = phi[:, None] if single else phi
        G = self._positive_gram(Phi.T, root_method)[0]
        proj = np.einsum("sab,bs->as", G, Phi)
        if single:
            return proj[:, 0], G[0]
        return proj, G

    def positive_intervals(self, phi, *, root_method: str = "colleague"):
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
        phi = self._check_phi(phi)
        single = phi.ndim == 1
        Phi = phi[:, None] if single else phi
        _, info = self._positive_gram(Phi.T, root_method)
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

    def positive_part_sampled(self, phi, n_time: int | None = None):
        r"""AFT approximation of :meth:`positive_part` by sampling on a grid.

        .. math::

            \mathrm{proj} = P_N \max(0, E_N\varphi), \qquad
            G = P_N\,\mathrm{diag}(1\{E_N\varphi > 0\})\,E_N,

        with the grid operators of ``n_time`` samples (default
        :attr:`n_time`).  Piecewise linear in ``phi``; its Jacobian jumps
        whenever a sample changes sign.  For comparison only.
        """
        phi = self._check_phi(phi)
        N = self._N if n_time is None else _check_int("n_time", n_time, 2 * self._H + 1)
        E, P = self._cached(("grid", N), lambda: self._grid_analysis(N))
        single = phi.ndim == 1
        Phi = phi[:, None] if single else phi
        U = E @ Phi
        ind = (U > 0.0).astype(float)
        proj = P @ (U * ind)
        G = (P[None, :, :] * ind.T[:, None, :]) @ E
        if single:
            return proj[:, 0], G[0]
        return proj, G

    # ------------------------------------------------------ positive part core
    def _gram_tables(self):
        """Index/weight tables turning antiderivative sums into basis Gram matrices.

        With ``C(m) = int cos(m θ)`` and ``S(m) = int sin(m θ)`` over the
        positive set (``C`` even, ``S`` odd in ``m``), product-to-sum gives
        ``cos j cos k -> (C(j-k) + C(j+k))/2``,
        ``sin j sin k -> (C(j-k) - C(j+k))/2``,
        ``cos j sin k -> (S(k-j) + S(j+k))/2``,
        ``sin j cos k -> (S(j-k) + S(j+k))/2``.  ``V = [C(0..2H), S(0..2H)]``.
        """
        def build():
            L = 2 * self._H + 1
            k = self.harmonic_of
            sin = self.is_sine
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

        return self._cached("gram", build)

    def _positive_gram(self, Phi, root_method):
        """Core of :meth:`positive_part`; ``Phi`` has shape ``(m, n_coef)``.

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
        H = self._H
        L = 2 * H + 1
        m = Phi.shape[0]
        scale = np.max(np.abs(Phi), axis=1)
        nonzero = scale > 0.0
        A = Phi / np.where(nonzero, scale, 1.0)[:, None]

        # effective degree
        if H > 0:
            amp = np.maximum(np.abs(A[:, 1::2]), np.abs(A[:, 2::2]))
            present = amp > _DEGREE_TOL
            heff = np.where(present.any(axis=1), H - np.argmax(present[:, ::-1], axis=1), 0)
        else:
            heff = np.zeros(m, dtype=int)
        heff = np.where(nonzero, heff, 0)

        cand = _candidates(A, heff, root_method)  # (m, R) sorted, inf padded
        rows, rho, w, wrap, sign_const = _sign_changes(A, cand)

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
            idx1, w1, idx2, w2 = self._gram_tables()
            M = w1 * V[:, idx1] + w2 * V[:, idx2]
            G = self.projection_norms()[:, None] * M
            G[~changed] = 0.0
        G[full] = np.eye(L)
        return G, (rows, rho, w, wrap & changed, full)


# ---------------------------------------------------------------- root finding
def _trig_eval(A, x, derivative=False):
    """Values (and d/dθ) of the series with coefficient rows ``A`` (p, L) at ``x`` (p, q).

    Horner's rule in ``z = exp(iθ)``:
    ``phi = c0 + Re sum_k (c_k - i s_k) z^k``,
    ``phi' = Re sum_k i k (c_k - i s_k) z^k``.
    """
    H = (A.shape[1] - 1) // 2
    if H == 0:
        f = np.broadcast_to(A[:, :1], x.shape).copy()
        return (f, np.zeros_like(x)) if derivative else f
    coef = (A[:, 1::2] - 1j * A[:, 2::2])[:, None, :]  # (p, 1, H)
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


def _candidates(A, heff, method):
    """Sorted candidate sign-change angles in [0, 2π), padded with inf, shape (m, R)."""
    m = A.shape[0]
    R = 2 * int(heff.max(initial=0))
    if method == "colleague":
        R *= 2
    out = np.full((m, max(R, 1)), np.inf)
    for h in np.unique(heff):
        if h == 0:
            continue
        rows = np.nonzero(heff == h)[0]
        n = 2 * h
        # complex coefficients a_k, k = -h..h, of phi(θ) = sum a_k e^{ikθ}
        c = A[rows, 1 : 2 * h : 2]
        s = A[rows, 2 : 2 * h + 1 : 2]
        a_pos = 0.5 * (c - 1j * s)  # k = 1..h
        a = np.concatenate([np.conj(a_pos[:, ::-1]), A[rows, :1].astype(complex), a_pos], axis=1)
        if method == "companion":
            # companion (upper Hessenberg) of p(z) = z^h phi(z) = sum_j a_{j-h} z^j
            Cm = np.zeros((rows.size, n, n), dtype=complex)
            Cm[:, np.arange(1, n), np.arange(n - 1)] = 1.0
            Cm[:, :, -1] = -a[:, :n] / a[:, n:]
            z = np.linalg.eigvals(Cm)
            ok = np.abs(np.abs(z) - 1.0) <= _ROOT_ACCEPT
            ang = np.where(ok, np.mod(np.angle(z), _TWO_PI), np.inf)
        else:
            # g(θ) = phi(α+θ) phi(α-θ) = sum_n g_n e^{inθ}, g_n = sum_k b_k b_{k-n},
            # b_k = a_k e^{ikα}; direct convolution keeps the leading
            # coefficient g_{2h} = |b_h|^2 relatively accurate.
            rot, S, template = _colleague_tables(int(h))
            b = a * rot
            prod = (b[:, :, None] * b[:, None, :]).real.reshape(rows.size, -1)
            cheb = prod @ S  # g(x) = sum_n cheb_n T_n(x), x = cos θ
            Cm = np.repeat(template[None], rows.size, axis=0)
            Cm[:, :, n - 1] -= cheb[:, :n] / (2.0 * cheb[:, n:])
            x = np.linalg.eigvals(Cm)
            ok = (np.abs(x.imag) <= _ROOT_ACCEPT) & (np.abs(x.real) <= 1.0 + _ROOT_ACCEPT)
            acos = np.arccos(np.clip(x.real, -1.0, 1.0))
            ang = np.concatenate([_ALPHA + acos, _ALPHA - acos], axis=1)
            ang = np.where(np.concatenate([ok, ok], axis=1), np.mod(ang, _TWO_PI), np.inf)
        out[rows, : ang.shape[1]] = ang
    out.sort(axis=1)
    return out


def _sign_changes(A, cand):
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
    f = _trig_eval(A, t)
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
    for _ in range(_MAX_POLISH):
        if active.size == 0:
            break
        xa = x[active]
        f, fp = _trig_eval(A[active], xa[:, None], derivative=True)
        f, fp = f[:, 0], fp[:, 0]
        root = np.abs(f) <= tol_f[active]
        same = np.sign(f) == sign_lo[active]
        lo[active] = np.where(same & ~root, xa, lo[active])
        hi[active] = np.where(~same & ~root, xa, hi[active])
        la, ha = lo[active], hi[active]
        with np.errstate(divide="ignore", invalid="ignore"):
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
