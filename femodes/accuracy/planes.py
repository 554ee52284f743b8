"""The hyperplanes on which the exact orbits are solved (:mod:`.shooter`), as functions of a run of
the exact flow: a branch point's hyperplane (:class:`Plane`: the levels' hyperplane without its
contact-force part, since the exact contact forces are impulses whose coefficients the truncated
forces do not resemble) and a point's own frequency (:class:`FrequencyPlane`).
"""

from __future__ import annotations

import numpy as np

from .ladder import Ladder
from .points import anchor, blend

__all__ = ["FrequencyPlane", "Plane"]


class Plane:
    """The hyperplane of a branch point for orbits of the exact flow: ``(c_Q . (Q - Q_a) +
    c_w (w - w_a) - offset) / (|c| |a|)`` with ``Q`` the orbit's displacement coefficients on the
    branch's harmonics, ``c`` the point's normal in the branch's arclength weights (the levels'
    hyperplane without its contact-force part: the exact contact forces are impulses, whose
    coefficients the branch's truncated forces do not resemble) and ``a`` the point."""

    def __init__(self, lad: Ladder, H: int, i: int, offset: float = 0.0, toward: int | None = None,
                 theta: float = 0.0):
        b = lad.branch
        a_st, n_st = anchor(b, i), lad.tangents[i]
        if toward is not None:  # the plane a fraction theta of the way to point `toward`'s
            a_st = blend(a_st, anchor(b, toward), theta)
            n_st = blend(n_st, lad.tangents[toward], theta)
        a = lad.vector(H, a_st.Q, a_st.P, a_st.omega, a_st.xi, a_st.p)
        c = lad.weights(H) * lad.vector(H, n_st.Q, 0.0 * n_st.P, n_st.omega, n_st.xi, n_st.p)
        self.H = H
        self.scale = (float(np.linalg.norm(c)) or 1.0) * (float(np.linalg.norm(a)) or 1.0)
        self.cQ = lad.problem(H).unpack(c[:-1], c[-1]).Q
        self.cw = float(c[-1])
        self.Qa, self.wa = a_st.Q, a_st.omega
        self.offset = offset

    def at(self, Q: np.ndarray, omega: float) -> float:
        return (float(np.sum(self.cQ * (Q - self.Qa))) + self.cw * (omega - self.wa) - self.offset) / self.scale

    def value(self, run, omega: float) -> float:
        return self.at(run.coefficients(self.H)[0], omega)

    def gradient(self, run) -> np.ndarray:
        """``d value / d x0`` (a variational run)."""
        return np.einsum("kd,kdc->c", self.cQ, run.coefficient_sensitivity(self.H)) / self.scale

    def omega_derivative(self, run) -> float:
        """``d value / d w`` at the run's start phase (a variational run)."""
        return (float(np.sum(self.cQ * run.coefficient_omega(self.H))) + self.cw) / self.scale


class FrequencyPlane:
    """The plane ``w = w_a`` for :meth:`~.shooter.Shooter.solve`: the exact orbit at a point's own
    frequency, the counterpart of a point where the exact curve crosses the branch's hyperplane
    obliquely (just above grazing)."""

    def __init__(self, omega: float):
        self.wa = float(omega)

    def at(self, Q: np.ndarray, omega: float) -> float:
        return (omega - self.wa) / self.wa

    def value(self, run, omega: float) -> float:
        return self.at(None, omega)

    def gradient(self, run) -> np.ndarray:
        return np.zeros(2 * run.flow.n)

    def omega_derivative(self, run) -> float:
        return 1.0 / self.wa
