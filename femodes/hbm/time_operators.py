r"""Discretise layer: time acting on the coefficients of a :class:`~femodes.hbm.Harmonics`
(``h.operators``): the derivative ``d/dt`` (a block-diagonal, skew-symmetric matrix linear in
``omega``) and the delay :math:`q(\theta) \to q(\theta - \tau)` with its generator
(conventions: :mod:`femodes.hbm.harmonics`).
"""

from __future__ import annotations

import numpy as np

from .harmonic_layout import read_only

__all__ = ["TimeOperators"]


class TimeOperators:
    r"""Derivative and delay operators on the coefficients of a :class:`~femodes.hbm.Harmonics`
    (``h.operators``)."""

    __slots__ = ("_h",)

    def __init__(self, harmonics):  # the Harmonics whose room this is
        self._h = harmonics

    def __repr__(self) -> str:
        return f"{self._h!r}.operators"

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
        h = self._h

        def build():
            D = np.zeros((h.n_coef, h.n_coef))
            k = np.arange(1, h.n_harmonics + 1)
            D[2 * k - 1, 2 * k] = k / h.subharmonic
            D[2 * k, 2 * k - 1] = -k / h.subharmonic
            return read_only(D)

        return h.memo("D1", build)

    def time_shift(self, Q, tau: float) -> np.ndarray:
        r"""Coefficients of the delayed signals :math:`q(\theta - \tau)` from ``Q`` (shape
        ``(n_coef, ...)``): harmonic ``k`` turned by the angle ``k tau``."""
        Q = np.asarray(Q, dtype=float)
        self._h.layout.check_coef(Q, "Q")
        out = Q.copy()
        H = self._h.n_harmonics
        if H:
            kt = (np.arange(1, H + 1) * float(tau)).reshape((-1,) + (1,) * (Q.ndim - 1))
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
        self._h.layout.check_coef(Q, "Q")
        return -self._h.subharmonic * (self.derivative_domega() @ Q)
