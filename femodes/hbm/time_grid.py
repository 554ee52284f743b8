r"""Discretise layer: a :class:`~femodes.hbm.Harmonics` in time (``h.grid``): the phase grid
:math:`\theta_j = 2\pi j/N`, physical times :math:`t_j = 2\pi\nu j/(\omega N)`, synthesis
(coefficients to samples) and the discrete Galerkin analysis back (conventions:
:mod:`femodes.hbm.harmonics`).
"""

from __future__ import annotations

import numpy as np

from .harmonic_layout import read_only

__all__ = ["TimeGrid"]

_TWO_PI = 2.0 * np.pi


def _check_omega(omega):
    omega = float(omega)
    if not np.isfinite(omega) or omega <= 0.0:
        raise ValueError(f"omega must be a finite positive frequency, got {omega!r}")
    return omega


def _basis(h, theta) -> np.ndarray:
    """Basis functions ``[1, cos theta, sin theta, ...]`` of ``h`` at the phases ``theta``, shape
    ``theta.shape + (n_coef,)``."""
    theta = np.asarray(theta, dtype=float)
    lay = h.layout
    arg = theta[..., None] * lay.harmonic_of
    return np.where(lay.is_sine, np.sin(arg), np.cos(arg))


class TimeGrid:
    r"""The series of a :class:`~femodes.hbm.Harmonics` in time (``h.grid``): ``N = n_time``
    phases per period, the synthesis ``E`` (samples ``= E @ Q``) and analysis ``P`` (``P @ E =
    I``) on them, evaluation at any time, period and sample times at a frequency ``omega``."""

    __slots__ = ("_h",)

    def __init__(self, harmonics):  # the Harmonics whose room this is
        self._h = harmonics

    def __repr__(self) -> str:
        return f"{self._h!r}.grid"

    def phases(self) -> np.ndarray:
        r"""Phase grid :math:`\theta_j = 2\pi j/N`, ``j = 0..N-1``."""
        N = self._h.n_time
        return self._h.memo("phases", lambda: read_only(_TWO_PI * np.arange(N) / N))

    def period(self, omega: float) -> float:
        r"""Period :math:`T = 2\pi\nu/\omega` of the response."""
        return _TWO_PI * self._h.subharmonic / _check_omega(omega)

    def times(self, omega: float) -> np.ndarray:
        r"""Physical sample times :math:`t_j = 2\pi\nu j/(\omega N)`."""
        N = self._h.n_time
        return self.period(omega) * np.arange(N) / N

    def frequencies(self, omega: float) -> np.ndarray:
        r"""Angular frequency :math:`k\omega/\nu` of each coefficient row (0 for ``c0``)."""
        return self._h.layout.harmonic_of * (float(omega) / self._h.subharmonic)

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
        h = self._h
        if theta is None:
            return h.memo("E", lambda: read_only(_basis(h, self.phases())))
        theta = np.asarray(theta, dtype=float)
        if theta.ndim != 1:
            raise ValueError(f"theta must be 1-D, got shape {theta.shape}")
        return _basis(h, theta)

    def grid_operators(self, N):
        """Synthesis and discrete projection ``(E, P)`` on ``N`` equidistant phases (``N >= 2H+1``)."""
        h = self._h
        E = _basis(h, _TWO_PI * np.arange(N) / N)
        w = np.where(h.layout.harmonic_of == 0, 1.0 / N, 2.0 / N)
        return E, w[:, None] * E.T

    def analysis(self) -> np.ndarray:
        r"""Discrete Galerkin projection ``P`` (``n_coef x N``) on the default grid.

        .. math::

            c_0 = \frac1N\sum_j u_j,\quad c_k = \frac2N\sum_j u_j\cos k\theta_j,\quad
            s_k = \frac2N\sum_j u_j\sin k\theta_j,

        the trapezoidal rule for the continuous projection, exact for
        integrands of degree ``< N``; hence ``P @ E = I``.
        """
        return self._h.memo("P", lambda: read_only(self.grid_operators(self._h.n_time)[1]))

    def to_time(self, Q) -> np.ndarray:
        """Samples ``E @ Q`` on the phase grid: shape ``(N,)`` or ``(N, n)``."""
        Q = np.asarray(Q, dtype=float)
        self._h.layout.check_coef(Q, "Q")
        return self.synthesis() @ Q

    def from_time(self, U) -> np.ndarray:
        """Coefficients ``P @ U`` of grid samples ``U`` of shape ``(N,)`` or ``(N, n)``."""
        U = np.asarray(U, dtype=float)
        N = self._h.n_time
        if U.ndim not in (1, 2) or U.shape[0] != N:
            raise ValueError(f"U must have shape (N,) or (N, n) with N = {N}, got {U.shape}")
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
        self._h.layout.check_coef(Q, "Q")
        t = np.asarray(t, dtype=float)
        theta = t * (float(omega) / self._h.subharmonic)
        return _basis(self._h, theta) @ Q

    def most_open_phase(self, Q, dofs, gaps) -> float:
        r"""The phase :math:`\theta` at which the smallest of the gaps ``gaps - q_dofs(theta)`` is
        largest, on a grid of ``max(256, 8 n_coef)`` phases (0 without gaps): a start for a time
        integration away from the contact phases and slight penetrations of a harmonic balance
        solution ``Q`` (``fm.stability`` by shooting, the shooting refinement of
        :mod:`femodes.accuracy`)."""
        dofs = np.asarray(dofs, dtype=int)
        if not dofs.size:
            return 0.0
        n = max(256, 8 * self._h.n_coef)
        theta = _TWO_PI * np.arange(n) / n
        gaps = np.asarray(gaps, dtype=float) - self.synthesis(theta) @ np.asarray(Q)[:, dofs]
        return float(theta[int(np.argmax(gaps.min(axis=1)))])
