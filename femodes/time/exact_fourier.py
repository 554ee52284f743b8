"""Fourier coefficients of a run of the exact flow in closed form (:class:`RunSeries`).

On a segment the state is ``x(t) = x_p(t) + V e^{Lambda (t - t_a)} z_a``, so the coefficients
``(w / pi) int q(t) e^{-i k w t} dt`` are integrals of exponentials (:func:`exp_integrals`) and
of the particular solution's harmonics (:func:`harmonic_integrals`); the contact forces add the
impulses of the impacts and the closed-form forces of closed massless contacts. Their derivatives
with respect to the start state and the frequency follow from the variational run, the latter
with integrals of ``t`` times exponentials (:func:`t_integrals`). The conventions are those of
:mod:`femodes.hbm.harmonics` (``[c0, c1, s1, ...]`` in the phase ``theta = w t``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["RunSeries", "exp_integrals", "harmonic_integrals", "t_integrals", "real_coefficients"]


def exp_integrals(w: float, H: int, ta: float, tb: float, lam: np.ndarray) -> np.ndarray:
    """``int_ta^tb e^{lam_m (t - ta)} e^{-i k w t} dt`` for ``k = 0..H``, shape ``(len(lam), H + 1)``."""
    k = np.arange(H + 1)
    mu = np.subtract.outer(lam, 1j * k * w)
    dlt = tb - ta
    x = mu * dlt
    small = np.abs(x) < 1e-8
    phi1 = np.where(small, 1.0 + 0.5 * x, np.expm1(np.where(small, 1.0, x)) / np.where(small, 1.0, x))
    return dlt * phi1 * np.exp(-1j * k * w * ta)


def harmonic_integrals(w: float, H: int, ta: float, tb: float, d, Y: np.ndarray) -> np.ndarray:
    """``int_ta^tb Re(sum_k Y_k e^{i k w t}) e^{-i j w t} dt`` for ``j = 0..H``, shape
    ``(H + 1,) + Y.shape[1:]`` (``Y`` per harmonic ``d.ks`` of a mode's particular solution ``d``)."""
    j = np.arange(H + 1)

    def E(mu):  # int_ta^tb e^{i mu w t} dt
        mu = np.asarray(mu, dtype=float)
        safe = np.where(mu == 0.0, 1.0, mu)
        return np.where(mu == 0.0, tb - ta,
                        (np.exp(1j * safe * w * tb) - np.exp(1j * safe * w * ta)) / (1j * safe * w))

    k = d.ks[:, None]
    E1, E2 = E(k - j), E(-(k + j))  # (n_k, H + 1)
    Yf = Y.reshape(len(d.ks), -1)
    out = 0.5 * (E1.T @ Yf + E2.T @ np.conj(Yf))
    return out.reshape((H + 1,) + Y.shape[1:])


def t_integrals(ta: float, tb: float, mu: np.ndarray) -> np.ndarray:
    """``int_ta^tb t e^{mu (t - ta)} dt`` for every ``mu``: ``ta D phi1(mu D) + D^2
    psi(mu D)`` with ``D = tb - ta``, ``phi1(x) = (e^x - 1) / x`` and ``psi(x) = int_0^1 u
    e^{x u} du = (e^x (x - 1) + 1) / x^2`` (its series below ``|x| = 1/2``, where the closed
    form cancels)."""
    D = tb - ta
    x = np.asarray(mu, dtype=complex) * D
    small = np.abs(x) < 0.5
    xs = np.where(small, 1.0, x)
    tiny = np.abs(x) < 1e-8
    xt = np.where(tiny, 1.0, x)
    phi1 = np.where(tiny, 1.0 + 0.5 * x, np.expm1(xt) / xt)
    psi = (np.exp(xs) * (xs - 1.0) + 1.0) / (xs * xs)
    if small.any():  # sum_k x^k / (k! (k + 2)): 18 terms reach round-off for |x| < 1/2
        xx, term, ser = x[small], np.ones(int(small.sum()), dtype=complex), np.zeros(int(small.sum()), dtype=complex)
        for k in range(18):
            ser += term / (k + 2)
            term = term * xx / (k + 1)
        psi[small] = ser
    return ta * D * phi1 + D * D * psi


def real_coefficients(C: np.ndarray, H: int) -> np.ndarray:
    """Real coefficients ``[c0, c1, s1, ...]`` from ``(w / pi) int q e^{-ikwt} dt`` (rows k)."""
    out = np.zeros((2 * H + 1,) + C.shape[1:])
    out[0] = 0.5 * np.real(C[0])
    out[1::2] = np.real(C[1:])
    out[2::2] = -np.imag(C[1:])
    return out


class RunSeries:
    """The closed-form Fourier coefficients of one :class:`~femodes.time.exact_run.FlowRun` and
    their derivatives; the integrals of each segment are computed once per ``H``."""

    def __init__(self, run):
        self.run = run
        self._J: dict = {}  # (H, segment) -> its integrals

    def coefficients(self, H: int) -> tuple[np.ndarray, np.ndarray]:
        """Real Fourier coefficients ``[c0, c1, s1, ..., cH, sH]`` of the displacements (shape
        ``(2H + 1, n)``) and of the contact forces (``(2H + 1, n_contacts)``; impulses at the
        impacts, the closed-form forces of closed massless contacts) over the run, in the phase
        ``theta = w t`` (the conventions of :mod:`femodes.hbm.harmonics`). Exact when the run is
        one period of a periodic orbit."""
        f = self.run.flow
        w = f.omega
        k = np.arange(H + 1)
        Ic = np.zeros((H + 1, f.n), dtype=complex)  # int q(t) e^{-i k w t} dt
        Il = np.zeros((H + 1, len(f.dofs)), dtype=complex)  # the same for the massless contacts' forces
        for s, (ta, tb, z, closed) in enumerate(self.run.segments):
            m, d = f.mode(closed)
            J = self.segment_integrals(H, s)
            Ic += (J.T * z) @ m.Rq.T + harmonic_integrals(w, H, ta, tb, d, d.Yq)
            if closed:
                js = sorted(closed)
                Il[:, js] += (J.T * z) @ m.Re[js].T + harmonic_integrals(w, H, ta, tb, d, d.Ye[:, js])
        Q = real_coefficients(Ic * (w / math.pi), H)
        P = real_coefficients(Il * (w / math.pi), H)
        for t, c, imp in self.run.impacts:
            ph = w * t * k[1:]
            P[0, c] += imp * w / (2.0 * math.pi)
            P[1::2, c] += imp * w / math.pi * np.cos(ph)
            P[2::2, c] += imp * w / math.pi * np.sin(ph)
        return Q, P

    def coefficient_omega(self, H: int) -> np.ndarray:
        """``d Q / d w`` of :meth:`coefficients` (shape ``(2H + 1, n)``; a variational run) with
        the start and end phases held fixed, as :attr:`FlowRun.x_end_omega`. In the phase ``theta = w
        t``, ``Q = (1/pi) int q(theta / w; w) e^{-i k theta} d theta``, so ``dQ/dw = (w/pi) int
        (sigma_q(t) - (t/w) q'(t)) e^{-i k w t} dt`` with ``sigma_q`` the displacements' change
        at a fixed time. On a segment ``sigma = P(t) + V e^{Lambda (t - t_a)} V^-1 (sigma(t_a) -
        P(t_a))``, ``P = d x_p / d w`` (the particular solution's ``particular_omega``): the integrals of
        exponentials and of ``t`` times exponentials (:func:`t_integrals`), in closed form."""
        if self.run.Phi is None:
            raise ValueError("coefficient_omega needs a run with variational=True")
        f = self.run.flow
        w = f.omega
        dI = np.zeros((H + 1, f.n), dtype=complex)
        kk = np.arange(H + 1)
        for s, ((ta, tb, z, closed), sig) in enumerate(zip(self.run.segments, self.run.sigmas)):
            m, d = f.mode(closed)
            J0 = self.segment_integrals(H, s)  # (2nI, H + 1)
            J1 = np.exp(-1j * kk * w * ta)[None, :] * t_integrals(ta, tb, np.subtract.outer(m.lam, 1j * kk * w))
            zs = m.Vinv @ (sig - d.particular_omega(ta))
            # sigma_q's part t i k Yq_k e^{i k w t} (the phases' change at a fixed time) and the
            # forced part of (t/w) q' are the same: they cancel and are left out
            dI += (J0.T * zs) @ m.Rq.T + harmonic_integrals(w, H, ta, tb, d, d.dX @ m.Lq.T)
            dI -= ((J1.T * (m.lam * z)) @ m.Rq.T) / w
        return real_coefficients(dI * (w / math.pi), H)

    def segment_integrals(self, H: int, s: int) -> np.ndarray:
        """:func:`exp_integrals` of segment ``s`` in its mode, computed once per run and ``H``
        (:meth:`coefficients`, :meth:`coefficient_sensitivity` and :meth:`coefficient_omega` all
        need them)."""
        key = (H, s)
        J = self._J.get(key)
        if J is None:
            ta, tb, _, closed = self.run.segments[s]
            J = self._J[key] = exp_integrals(self.run.flow.omega, H, ta, tb, self.run.flow.mode(closed)[0].lam)
        return J

    def coefficient_sensitivity(self, H: int) -> np.ndarray:
        """``d Q / d x0`` of :meth:`coefficients`, shape ``(2H + 1, n, 2n)`` (a variational run):
        on each segment ``dq(t)/dx0 = L_q V e^{Lambda (t - t_a)} V^-1 Phi_a`` with ``Phi_a`` the
        sensitivity at its start (saltation included; q is continuous at the events, so a shift of
        an event time adds nothing else)."""
        if self.run.Phi is None:
            raise ValueError("coefficient_sensitivity needs a run with variational=True")
        f = self.run.flow
        w = f.omega
        Ic = np.zeros((H + 1, f.n, 2 * f.n), dtype=complex)
        for s, ((ta, tb, _, closed), Phi_a) in enumerate(zip(self.run.segments, self.run.sensitivities)):
            m, _ = f.mode(closed)
            J = self.segment_integrals(H, s)
            Zm = m.Vinv @ Phi_a  # (modes, 2n columns)
            Ic += (m.Rq[None, :, :] * J.T[:, None, :]) @ Zm  # sum over m of J[m, k] Rq[d, m] Zm[m, c]
        return real_coefficients(Ic * (w / math.pi), H)

