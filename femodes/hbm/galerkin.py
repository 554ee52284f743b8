r"""Discretise layer: the Galerkin projection on a :class:`~femodes.hbm.Harmonics` (``h.galerkin``).

Coefficient ``a`` of the projection of :math:`f(\theta)` is ``norm_a * int f b_a`` with the basis
``b = [1, cos θ, sin θ, ...]`` and ``norm = [1/2π, 1/π, 1/π, ...]`` (:meth:`GalerkinProjection.projection_norms`);
period averages of products use the weights ``[1, 1/2, 1/2, ...]``
(:meth:`GalerkinProjection.norm_weights`); the projection of ``max(0, phi)`` is exact
(:mod:`femodes.hbm.positive_part`) or sampled (AFT, for comparison).
"""

from __future__ import annotations

import numpy as np

from . import positive_part as _pp
from .harmonic_layout import read_only

__all__ = ["GalerkinProjection"]


class GalerkinProjection:
    """Projections of functions of the signals on the harmonics of a
    :class:`~femodes.hbm.Harmonics` (``h.galerkin``): the normalisation and the period-average
    weights of the basis, and the exact (or sampled) projection of ``max(0, phi)``."""

    __slots__ = ("_h",)

    def __init__(self, harmonics):  # the Harmonics whose room this is
        self._h = harmonics

    def __repr__(self) -> str:
        return f"{self._h!r}.galerkin"

    def projection_norms(self) -> np.ndarray:
        r"""Normalisation of the projection: ``[1/2pi, 1/pi, 1/pi, ...]``.

        Coefficient ``a`` of the projection of ``f`` is
        ``norm[a] * int_0^{2pi} f(theta) b_a(theta) dtheta``.
        """
        k = self._h.layout.harmonic_of
        return self._h.memo("norms", lambda: read_only(np.where(k == 0, 1.0 / (2.0 * np.pi), 1.0 / np.pi)))

    def norm_weights(self) -> np.ndarray:
        r"""Weights ``w = [1, 1/2, 1/2, ...]`` of the period average of products.

        .. math::

            \frac{1}{T}\int_0^T u\,v\,dt = \sum_a w_a U_a V_a

        for series ``u, v`` with coefficients ``U, V`` (Parseval).
        """
        k = self._h.layout.harmonic_of
        return self._h.memo("weights", lambda: read_only(np.where(k == 0, 1.0, 0.5)))

    def positive_part(self, phi, *, roots=None):
        """Exact Galerkin projection of ``max(0, phi)`` for one signal ``phi`` of shape
        ``(n_coef,)``, and its Jacobian (:func:`femodes.hbm.positive_part.positive_part`; many
        signals at once: :class:`femodes.hbm.ExactProjection`)."""
        return _pp.positive_part(self._h, phi, roots=roots)

    def positive_intervals(self, phi, *, roots=None):
        """Phase intervals ``(k, 2)`` where ``phi > 0`` (:func:`femodes.hbm.positive_part.positive_intervals`)."""
        return _pp.positive_intervals(self._h, phi, roots=roots)

    def positive_part_sampled(self, phi, n_time: int | None = None):
        """AFT approximation of :meth:`positive_part` (:func:`femodes.hbm.positive_part.positive_part_sampled`)."""
        return _pp.positive_part_sampled(self._h, phi, n_time)
