r"""Closed-form reference: first nonsmooth mode of a clamped elastic bar against a rigid stop.

Plain numpy on purpose: nothing is imported from :mod:`femodes` (no harmonic balance, no finite
elements), so this module is an independent reference for the product's backbone of the bar
with a unilateral stop. The finite-difference confirmation lives in ``bar_stop_fd_check.py``
and shares no code with this module.

Problem (dimensionless, ``E = rho = A = L = 1``, wave speed ``c = 1``)
----------------------------------------------------------------------

.. math::

    u_{tt} = u_{xx} \ (0 < x < 1), \qquad u(0, t) = 0, \qquad
    u(1, t) \le g, \quad p = -u_x(1, t) \ge 0, \quad p\,(g - u(1, t)) = 0 .

Linear first mode ``sin(pi x / 2)``, ``w1 = pi / 2`` (period 4). Energy
``E = int_0^1 (u_t^2 + u_x^2) / 2 dx``. Grazing energy of the *sinusoidal* linear mode with tip
amplitude ``g``: ``E_g = pi^2 g^2 / 16``. Energy ratios below are ``rho = E / E_g``.

Derivation (d'Alembert / characteristics)
-----------------------------------------

1. The clamp gives ``u(x, t) = int_{t-x}^{t+x} phi(s) ds`` for one function ``phi`` on the real
   line, so ``u_t = phi(t+x) - phi(t-x)``, ``u_x = phi(t+x) + phi(t-x)`` and
   ``E(t) = int_{t-1}^{t+1} phi(s)^2 ds``. The tip displacement is
   ``U(t) = u(1, t) = int_{t-1}^{t+1} phi``.
2. At ``x = 1`` the outgoing value ``phi(t+1)`` is fixed by the incoming one ``phi(t-1)``:
   free end (``u_x = 0``): ``phi(t+1) = -phi(t-1)``; at the stop (``u_t(1) = 0``):
   ``phi(t+1) = +phi(t-1)``, admissible only while the force ``p = -2 phi(t-1) >= 0``. Both
   cases are the single law ``phi(t+1) = -|phi(t-1)|`` while ``U(t) = g`` (stick when the
   incoming wave compresses, release otherwise) and ``phi(t+1) = -phi(t-1)`` while
   ``U(t) < g``. Since ``phi(t+1)^2 = phi(t-1)^2`` the energy is conserved exactly.
3. Write ``phi(s) = sigma(s) phi(s - 2)`` with ``sigma = +1`` on the contact set (shifted by 1)
   and ``-1`` elsewhere. A ``T``-periodic motion with ``2 < T < 4`` gives, with
   ``r = T - 2``, the *cocycle* ``phi(s + r) = sigma(s) phi(s)``. If ``r / T`` is irrational the
   rotation by ``r`` is ergodic, so ``|phi|`` is constant: ``phi = a eps(s)``, ``eps = +-1``,
   i.e. the displacement is *piecewise linear* (as in Yoong, Thorin & Legrand 2018).
4. With two sign switches per period (the simplest, and the only family born at period 4):
   ``eps = +1`` on ``[0, r)``, ``-1`` on ``[r, T)`` (``T``-periodic). Then ``sigma = +1`` exactly
   on ``[r, T - r)``: one contact phase of length ``4 - T`` per period; the incoming wave there
   is ``-a`` (compressive, force ``p = 2a``), and the tip displacement during contact is
   ``U = a (3r - T) = 2 a (T - 3)``, the maximum of ``U`` over the period. Setting it to ``g``:

   .. math::

       a = \frac{g}{2 (T - 3)}, \qquad E = 2 a^2 = \frac{g^2}{2 (T - 3)^2}
       \;\Longrightarrow\;
       T = 3 + \frac{g}{\sqrt{2 E}} = 3 + \frac{2\sqrt 2}{\pi\sqrt{\rho}}, \qquad
       \frac{\omega}{\omega_1} = \frac{4}{T}, \qquad
       \frac{\tau_c}{T} = \frac{4 - T}{T} = \frac{\omega}{\omega_1} - 1 .

   ``T`` decreases from 4 (``w = w1``) to 3 (``w = 4 w1 / 3``, the bilinear limit: half a
   free-clamped period 2 plus half a clamped-clamped period 1) as ``E`` goes from ``g^2/2`` to
   infinity. The result is independent of ``g`` in the ratio ``E / E_g`` (homogeneity).

The motion (time origin at mid free flight)
-------------------------------------------

``u(x, t) = a [Psi(t - 1 + x) - Psi(t - 1 - x)]`` with ``Psi`` the antiderivative of ``eps``.

* ``t = 0``: the bar is at rest with a *uniform strain*: ``u(x, 0) = -2 a x``, ``u_t = 0``
  (tip at its minimum ``-2a = -g / (T - 3)``); ``2a = sqrt(2 E)``.
* ``0 < t < T - 2``: unloading waves; the tip moves towards the stop at constant speed ``2a``.
* ``T - 2 <= t <= 2``: contact phase, ``u(1, t) = g``, constant force ``p = 2a``; at mid
  contact ``t = T/2`` the bar is again at rest with the tent profile ``u = 2 a x`` for
  ``x <= r/2``, ``2 a (r - x)`` for ``x >= r/2``.
* ``2 < t < T``: release, the tip leaves at speed ``2a``; back to the initial state at ``t = T``.

Which family "continues the first linear mode"
----------------------------------------------

This family is born at ``T = 4`` from the grazing motion ``u(x, 0) = -g x``, ``u_t = 0``: the
*minimum-energy* 4-periodic linear motion whose tip reaches ``g`` (``E >= U_max^2 / 2`` by
Cauchy-Schwarz, equality iff ``|phi|`` is constant). Its energy is ``g^2 / 2 = (8/pi^2) E_g =
0.8106 E_g`` and it is 81 % mode 1 (the rest in modes 3, 5, ... -- the bar's spectrum is
commensurate, every 4-periodic mix of odd modes is a linear periodic motion). The sinusoidal
mode itself does **not** continue into periodic motions with a finite contact phase: no
``T``-periodic nonsmooth motion with ``T -> 4`` tends to it (``|phi|`` is ``T/q``-periodic on a
rotation orbit, and ``T = 4`` admits no contact at all). Hence at ``E = E_g`` the family is
already at ``w = 1.0256 w1`` (contact fraction 2.6 %); a discretised / truncated-harmonic
backbone that starts exactly at ``(E_g, w1)`` can only agree with this reference up to that
kind of offset near grazing.

Non-uniqueness (checked numerically when this file was written): at every
period with ``(T - 2) / T = p / q`` rational the cocycle allows ``|phi|`` to be any positive
``T/q``-periodic function, giving a *vertical ray* of periodic motions with the same period,
contact set and tip law and energies from the value above up to infinity (the constant-``|phi|``
member is the minimum-energy one). Other constant-``|phi|`` solutions with one finite contact
phase per period and more sign switches of ``phi`` (switch points ``p, p - r, ..., p - (2m-1) r``)
exist too, e.g. ``m = 4`` on ``3.0 < T < 3.2`` (same ``E(T)`` as here, smaller contact fraction),
``m = 6`` on ``10/3 < T < 3.43`` (``7.3 <= rho <= 39``), ``m = 8`` on ``3.5 < T < 3.56``, and
``m = 2, 3, ...`` at ``w > 1.5 w1``; but every one of them also *touches* the stop (``U = g``
at isolated instants) during its free flight, so they are non-generic (the leapfrog turns the
touches into short contacts) and none of them starts at ``w1``. The ``m = 1`` family here has
no such touch: ``U < g`` on the whole free flight.

Sources (facts only, no code copied): C. Yoong, A. Thorin, M. Legrand, "Nonsmooth modal analysis
of an elastic bar subject to a unilateral contact constraint", Nonlinear Dynamics 91 (2018),
doi:10.1007/s11071-017-4025-9 (d'Alembert construction with piecewise-linear initial data,
frequency rising with energy); A. Thorin, M. Legrand, "Nonsmooth modal analysis: from the
discrete to the continuous settings", hal-01771849 (2018). The formula above was derived
independently here and cross-checked with the CFL = 1 leapfrog of ``bar_stop_fd_check.py``.
"""

from __future__ import annotations

import numpy as np

OMEGA_1 = np.pi / 2.0
#: Energy ratio E / E_g at which the family is born (minimum-energy grazing motion, T = 4).
RHO_BIRTH = 8.0 / np.pi**2


def grazing_energy(gap: float = 0.01) -> float:
    """Energy of the sinusoidal linear mode 1 with tip amplitude ``gap``: ``pi^2 g^2 / 16``."""
    return np.pi**2 * gap**2 / 16.0


def period(energy_ratio):
    """Minimal period ``T = 3 + 2 sqrt(2) / (pi sqrt(rho))``; NaN below ``RHO_BIRTH``."""
    rho = np.asarray(energy_ratio, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        T = 3.0 + 2.0 * np.sqrt(2.0) / (np.pi * np.sqrt(rho))
    return np.where(rho >= RHO_BIRTH * (1 - 1e-14), T, np.nan)


def first_nonsmooth_mode(energy_ratio, gap: float = 0.01):
    """``(omega, contact_fraction)`` of the first nonsmooth mode at ``E = energy_ratio * E_g``.

    ``omega = 2 pi / T`` (rad per unit time, ``w1 = pi/2``); ``contact_fraction`` is the contact
    duration per period over ``T``, ``(4 - T) / T = omega / w1 - 1``. Vectorised; NaN for
    ``energy_ratio < 8 / pi^2`` (below the birth of the family). ``gap`` does not enter the
    ratios (the problem is homogeneous in ``(u, g)``); it is accepted for symmetry with
    :func:`initial_profiles`.
    """
    T = period(energy_ratio)
    omega = 2.0 * np.pi / T
    frac = (4.0 - T) / T
    if np.ndim(omega) == 0:
        return float(omega), float(frac)
    return omega, frac


def wave_amplitude(energy_ratio, gap: float = 0.01):
    """``a = |phi| = sqrt(E / 2) = g / (2 (T - 3))``; ``2a`` is the strain/velocity jump."""
    return np.sqrt(np.asarray(energy_ratio, float) * grazing_energy(gap) / 2.0)


def _Psi(s, T):
    """Antiderivative of the T-periodic sign function eps = +1 on [0, T-2), -1 on [T-2, T)."""
    r = T - 2.0
    q = np.floor(s / T)
    z = s - q * T
    return q * (2.0 * r - T) + np.where(z < r, z, 2.0 * r - z)


def _eps(s, T):
    z = np.mod(s, T)
    return np.where(z < T - 2.0, 1.0, -1.0)


def exact_state(x, t, energy_ratio, gap: float = 0.01):
    """Exact ``(u, u_t)`` at positions ``x`` (array in [0, 1]) and time ``t`` (scalar).

    Time origin at mid free flight (``u(x, 0) = -2 a x``, ``u_t = 0``); contact for
    ``t in [T - 2, 2] (mod T)``. At a velocity jump (a front) the mean of both sides is returned.
    """
    rho = float(energy_ratio)
    T = float(period(rho))
    if not np.isfinite(T):
        raise ValueError(f"energy_ratio {rho} below the birth of the family ({RHO_BIRTH:.6f})")
    a = float(wave_amplitude(rho, gap))
    x = np.asarray(x, dtype=float)
    sp, sm = t - 1.0 + x, t - 1.0 - x
    u = a * (_Psi(sp, T) - _Psi(sm, T))
    # velocity phi(t-1+x) - phi(t-1-x), averaged left/right at jumps
    d = 1e-12
    ep = 0.5 * (_eps(sp - d, T) + _eps(sp + d, T))
    em = 0.5 * (_eps(sm - d, T) + _eps(sm + d, T))
    return u, a * (ep - em)


def initial_profiles(x, energy_ratio, gap: float = 0.01, t: float = 0.0):
    """Displacement and velocity on the orbit at time ``t`` (default: mid free flight, at rest,
    ``u0 = -2 a x``, ``v0 = 0``; ``t = T/2``: mid contact, at rest, tent profile)."""
    return exact_state(x, t, energy_ratio, gap)


def tip_extremes(energy_ratio, gap: float = 0.01):
    """``(u_min, u_max) = (-g / (T - 3), g)`` of the tip over a period."""
    T = period(energy_ratio)
    return -gap / (T - 3.0), gap + 0.0 * T


# Values at a few energy ratios (g = 0.01) from the closed form (literal numbers, so a test can
# also check the functions above), with the agreement measured by the independent CFL = 1
# leapfrog of bar_stop_fd_check.fd_period_and_return_error (start: uniform strain at rest,
# 3 periods). 'fd': n_cells -> (period_fd / T - 1, contact_duration_fd / (4 - T) - 1,
# max displacement return error over the 3 returns / max|u0|, filtered-energy drift / E).
# All four are O(h): the clipped scheme releases the tip one step late and loses about
# h * E per contact phase. 'fd_period_richardson_rel_err' is (2 T_1600 - T_800) / T - 1.
# Direct comparison FD vs exact_state over 3 periods: max|u_fd - u| / max|u0| = 2.2e-2, 2.5e-2,
# 1.5e-2 (N = 200) and 5.2e-3, 6.3e-3, 2.6e-3 (N = 800) for rho = 2, 5, 20; FD runs started at
# mid contact (t = T/2) or at t = 0.37 T from initial_profiles give the same period to <= 4.6e-4
# (N = 800).
REFERENCE = {
    2: dict(
        period=3.6366197723675815, omega=1.727754260954531, omega_ratio=1.0999225243159925,
        contact_fraction=0.09992252431599243, contact_duration=0.3633802276324185,
        wave_amplitude=0.007853981633974483,
        tip_min=-0.015707963267948963,
        fd={
            200: (1.44e-03, -6.05e-03, 1.34e-02, 2.38e-02),
            400: (7.34e-04, -2.79e-03, 6.90e-03, 1.16e-02),
            800: (3.54e-04, -1.20e-03, 3.38e-03, 5.72e-03),
            1600: (1.90e-04, -6.64e-04, 1.90e-03, 2.99e-03),
        },
        fd_period_richardson_rel_err=2.6e-05,
    ),
    5: dict(
        period=3.4026336968358963, omega=1.8465652982342209, omega_ratio=1.1755599798237446,
        contact_fraction=0.17555997982374466, contact_duration=0.5973663031641037,
        wave_amplitude=0.012418235332245127,
        tip_min=-0.02483647066449025,
        fd={
            200: (1.36e-03, -1.27e-03, 1.68e-02, 1.94e-02),
            400: (4.65e-04, -9.63e-04, 3.44e-03, 6.41e-03),
            800: (2.44e-04, -3.89e-04, 2.90e-03, 5.65e-03),
            1600: (1.35e-04, -1.07e-04, 1.65e-03, 2.91e-03),
        },
        fd_period_richardson_rel_err=2.5e-05,
    ),
    20: dict(
        period=3.201316848417948, omega=1.9626877327949153, omega_ratio=1.2494858176805432,
        contact_fraction=0.24948581768054334, contact_duration=0.7986831515820518,
        wave_amplitude=0.024836470664490254,
        tip_min=-0.0496729413289805,
        fd={
            200: (5.04e-04, 1.36e-03, 1.13e-02, 2.57e-02),
            400: (2.06e-04, 6.69e-04, 6.05e-03, 1.49e-02),
            800: (6.94e-05, 2.38e-04, 1.45e-03, 4.04e-03),
            1600: (4.25e-05, 1.54e-04, 1.45e-03, 2.90e-03),
        },
        fd_period_richardson_rel_err=1.6e-05,
    ),
}
