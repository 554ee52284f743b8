r"""Semi-analytic event-driven reference for the forced 1-DOF impact oscillator.

.. math::

    u'' + c\,u' + u = F \cos(\omega t), \qquad u \le g, \qquad
    u = g:\ u'(t^+) = -u'(t^-) \quad (\text{Newton restitution } e = 1).

Plain numpy/scipy on purpose: nothing is imported from :mod:`femodes`, so this module is an
independent check of the product's shooting (:mod:`femodes.time.shooting`) and of harmonic
balance extrapolations, not a second copy of them.

Between impacts the motion is the linear damped forced oscillator, solved in closed form
(underdamped, ``0 <= c < 2``):

.. math::

    x(t) = x_p(t) + e^{A s}\,\big(x(t_i^+) - x_p(t_i)\big), \quad s = t - t_i, \quad
    A = \begin{bmatrix} 0 & 1 \\ -1 & -c \end{bmatrix},

with ``x = [u, u']``, the periodic particular solution ``u_p(t) = Re(P e^{i w t})``,
``P = F / (1 - w^2 + i c w)``, and

.. math::

    e^{A s} = e^{-c s/2}\Big(\cos(\Omega s)\,I + \frac{\sin(\Omega s)}{\Omega}\,(A + \tfrac{c}{2} I)\Big),
    \qquad \Omega = \sqrt{1 - c^2/4}.

*One impact per forcing period* ``T = 2 pi / w``: the orbit leaves the stop at the impact time
``t_i`` with ``x(t_i^+) = (g, -v)``, ``v > 0``, and must come back to ``(g, +v)`` at ``t_i + T``.
As ``x_p`` is T-periodic, this is the linear condition

.. math::

    (e^{A T} - I)\,d = (0, 2v)^T, \quad d = (g, -v)^T - x_p(t_i)
    \;\Longrightarrow\; x_p(t_i) = (g, -v)^T - 2 v\,h, \quad h = (e^{A T} - I)^{-1} e_2 .

With ``x_p(t_i) = (X cos psi, -w X sin psi)``, ``X = |P|``, ``psi = w t_i + arg P``, eliminating
the phase gives a *quadratic in v*:

.. math::

    a v^2 + b v + (g^2 - X^2) = 0, \qquad a = 4 h_1^2 + (1 + 2 h_2)^2 / w^2, \quad b = -4 g h_1 .

So the candidate orbits at a frequency are closed-form (the two roots), and the saddle-node of
the impacting branch is where the two roots merge: the zero of the discriminant
``D(w) = b^2 - 4 a (g^2 - X^2)``, a smooth function of ``w`` found by ``brentq``. A root is a
physical orbit when ``v > 0`` and the flight stays strictly below the stop, ``u(s) < g`` for
``0 < s < T`` (checked at every interior critical point of ``u``, located by sign changes of
``u'`` on a fine grid refined by ``brentq``; an orbit that would cross the stop has more than
one impact per period and is rejected).

Energies are exact: with ``u = sum_k Re(z_k e^{mu_k s})`` the period integral of products of
such terms is closed-form (:func:`_mean_square`).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq, minimize_scalar

__all__ = ["Orbit", "Fold", "propagator", "one_impact_orbits", "upper_fold", "peak_response", "grazing_frequencies",
           "free_frequency", "discriminant"]

#: Grid points per period on which ``u'`` is sampled to bracket the critical points of ``u``.
#: A flight lasts one period and ``u`` has at most a few extrema per free period, so this grid
#: separates them with a wide margin; ``brentq`` then locates each to machine precision.
GRID = 4000
#: Relative tolerance on ``u <= g`` at interior maxima: a flight touching the stop with zero
#: velocity (grazing) is accepted, one rising above it by more than round-off is not.
TOUCH = 1e-12


# --------------------------------------------------------------------------------------------
# The linear flow between impacts
# --------------------------------------------------------------------------------------------
def _check_damping(c: float) -> None:
    if not (0.0 <= c < 2.0):
        raise ValueError(f"damping c must be in [0, 2) (underdamped closed form), got {c!r}")


def _omega_d(c: float) -> float:
    """Damped natural frequency ``Omega = sqrt(1 - c^2 / 4)``."""
    return math.sqrt(1.0 - 0.25 * c * c)


def propagator(c: float, s: float) -> np.ndarray:
    """Matrix exponential ``exp(A s)`` of ``A = [[0, 1], [-1, -c]]`` in closed form.

    Parameters
    ----------
    c : float
        Damping, ``0 <= c < 2``.
    s : float
        Time.

    Returns
    -------
    ndarray (2, 2)
    """
    _check_damping(c)
    W = _omega_d(c)
    A = np.array([[0.0, 1.0], [-1.0, -c]])
    return math.exp(-0.5 * c * s) * (math.cos(W * s) * np.eye(2) + math.sin(W * s) / W * (A + 0.5 * c * np.eye(2)))


def _particular(c: float, F: float, w: float) -> complex:
    """Complex amplitude ``P`` of the periodic solution ``u_p = Re(P e^{i w t})``."""
    return F / complex(1.0 - w * w, c * w)


def _h(c: float, w: float) -> np.ndarray:
    """``h = (exp(A T) - I)^{-1} e_2``: the homogeneous part ``d = 2 v h`` of a one-impact orbit.

    ``exp(A T) - I`` is singular only for ``c = 0`` and ``T`` a multiple of ``2 pi`` (w = 1/k),
    where the free linear oscillator itself is T-periodic.
    """
    T = 2.0 * math.pi / w
    return np.linalg.solve(propagator(c, T) - np.eye(2), np.array([0.0, 1.0]))


def _quadratic(c: float, F: float, g: float, w: float):
    """Coefficients ``(a, b, c0)`` of ``a v^2 + b v + c0 = 0``, with ``h`` and ``P``."""
    h = _h(c, w)
    P = _particular(c, F, w)
    X2 = abs(P) ** 2
    a = 4.0 * h[0] ** 2 + (1.0 + 2.0 * h[1]) ** 2 / (w * w)
    b = -4.0 * g * h[0]
    return a, b, g * g - X2, h, P


def discriminant(c: float, F: float, g: float, w: float) -> float:
    """Discriminant ``b^2 - 4 a c0`` of the impact-velocity quadratic, scaled by ``1 / g^2``.

    Smooth in ``w``; its zeros are where two one-impact candidates merge (fold).
    """
    a, b, c0, _, _ = _quadratic(c, F, g, w)
    return (b * b - 4.0 * a * c0) / (g * g)


# --------------------------------------------------------------------------------------------
# Exact period averages
# --------------------------------------------------------------------------------------------
def _int_exp(mu: complex, T: float) -> complex:
    """``int_0^T e^{mu s} ds``, accurate also for ``mu T`` near 0 (series there)."""
    z = mu * T
    if abs(z) < 1e-4:
        # (e^z - 1) / z = 1 + z/2 + z^2/6 + z^3/24 + ...: four terms leave O(1e-20)
        return T * (1.0 + z / 2.0 + z * z / 6.0 + z ** 3 / 24.0)
    return (cmath.exp(z) - 1.0) / mu


def _mean_square(terms: list[tuple[complex, complex]], T: float) -> float:
    """Exact ``(1/T) int_0^T (sum_k Re(z_k e^{mu_k s}))^2 ds``.

    Uses ``Re(a) Re(b) = (Re(a b) + Re(a conj(b))) / 2`` term by term.
    """
    total = 0.0
    for zj, mj in terms:
        for zk, mk in terms:
            total += 0.5 * (zj * zk * _int_exp(mj + mk, T)
                            + zj * zk.conjugate() * _int_exp(mj + mk.conjugate(), T)).real
    return total / T


# --------------------------------------------------------------------------------------------
# Orbits
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Orbit:
    """A periodic orbit of period ``T = 2 pi / w`` (one impact per period, or none).

    Attributes
    ----------
    w : float
        Forcing frequency.
    phase : float
        Impact phase ``w t_i`` in ``[0, 2 pi)`` (``nan`` for the non-impacting linear orbit).
    velocity : float
        Impact velocity ``v > 0`` (``u' = +v`` just before, ``-v`` just after); 0 for the linear orbit.
    max_abs_u : float
        ``max |u(t)|`` over the period: ``max(g, -min u)`` for an impacting orbit (the positive
        side is capped by the stop), the amplitude ``|P|`` for the linear one.
    energy : float
        Period average of ``(u'^2 + u^2) / 2`` (exact).
    impacting : bool
        Whether the orbit hits the stop.
    c, F, g : float
        The system.
    """

    w: float
    phase: float
    velocity: float
    max_abs_u: float
    energy: float
    impacting: bool
    c: float
    F: float
    g: float
    _P: complex = field(repr=False, default=0j)
    _alpha: complex = field(repr=False, default=0j)

    @property
    def period(self) -> float:
        """``T = 2 pi / w``."""
        return 2.0 * math.pi / self.w

    @property
    def impact_time(self) -> float:
        """``t_i = phase / w`` in ``[0, T)`` (``nan`` for the linear orbit)."""
        return self.phase / self.w

    def _lam(self) -> complex:
        return complex(-0.5 * self.c, _omega_d(self.c))

    def state(self, t) -> tuple[np.ndarray, np.ndarray]:
        """``(u(t), u'(t))`` on the orbit, any real ``t`` (arrays accepted).

        At an impact time the state just *after* the impact (``u' = -v``) is returned.
        """
        t = np.asarray(t, dtype=float)
        wt = np.exp(1j * self.w * t)
        u = (self._P * wt).real
        du = (1j * self.w * self._P * wt).real
        if self.impacting:
            s = np.mod(t - self.impact_time, self.period)
            lam = self._lam()
            e = np.exp(lam * s)
            u = u + (self._alpha * e).real
            du = du + (self._alpha * lam * e).real
        return u, du

    def u(self, t) -> np.ndarray:
        """Displacement ``u(t)``."""
        return self.state(t)[0]

    def v(self, t) -> np.ndarray:
        """Velocity ``u'(t)`` (after the impact at an impact time)."""
        return self.state(t)[1]


def _critical_points(du, T: float) -> np.ndarray:
    """Zeros of ``du(s)`` in ``(0, T)``: sign changes on a grid, refined by ``brentq``."""
    s = np.linspace(0.0, T, GRID + 1)
    d = du(s)
    roots = []
    for k in np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0):
        roots.append(brentq(lambda x: float(du(x)), s[k], s[k + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps))
    roots.extend(s[1:-1][d[1:-1] == 0.0])  # exact grid hits (rare)
    return np.array(sorted(roots))


def _impacting_orbit(c: float, F: float, g: float, w: float, v: float, h: np.ndarray, P: complex):
    """The one-impact orbit with impact velocity ``v`` (a root of the quadratic), or ``None``
    when it is not physical (``v <= 0`` or the flight rises above the stop)."""
    if not v > 0.0:
        return None
    X = abs(P)
    # x_p(t_i) = (X cos psi, -w X sin psi) = (g - 2 v h1, -v - 2 v h2)
    psi = math.atan2(v * (1.0 + 2.0 * h[1]) / w, g - 2.0 * v * h[0])
    phase = (psi - cmath.phase(P)) % (2.0 * math.pi)
    T = 2.0 * math.pi / w
    # homogeneous part from the impact: d = 2 v h, written as Re(alpha e^{lambda s})
    d0, d1 = 2.0 * v * h[0], 2.0 * v * h[1]
    W = _omega_d(c)
    alpha = complex(d0, -(d1 + 0.5 * c * d0) / W)
    lam = complex(-0.5 * c, W)
    Q = P * cmath.exp(1j * phase)  # particular part in the flight time s = t - t_i

    def u(s):
        return (Q * np.exp(1j * w * s)).real + (alpha * np.exp(lam * s)).real

    def du(s):
        return (1j * w * Q * np.exp(1j * w * s)).real + (alpha * lam * np.exp(lam * s)).real

    crit = _critical_points(du, T)
    uc = u(crit) if crit.size else np.array([])
    scale = max(g, X, v)
    if uc.size and np.max(uc) > g + TOUCH * scale:
        return None  # the flight crosses the stop: more than one impact per period
    # both ends of the flight are at u = g; the largest |u| is g or the deepest minimum
    max_abs_u = max(g, float(-np.min(uc))) if uc.size else g
    ms_u = _mean_square([(Q, 1j * w), (alpha, lam)], T)
    ms_du = _mean_square([(1j * w * Q, 1j * w), (alpha * lam, lam)], T)
    return Orbit(w=w, phase=phase, velocity=v, max_abs_u=max_abs_u, energy=0.5 * (ms_u + ms_du), impacting=True,
                 c=c, F=F, g=g, _P=P, _alpha=alpha)


def _linear_orbit(c: float, F: float, g: float, w: float) -> Orbit:
    P = _particular(c, F, w)
    X = abs(P)
    return Orbit(w=w, phase=math.nan, velocity=0.0, max_abs_u=X, energy=0.25 * X * X * (1.0 + w * w), impacting=False,
                 c=c, F=F, g=g, _P=P)


def one_impact_orbits(c: float, F: float, g: float, w: float) -> list[Orbit]:
    """All T-periodic orbits with exactly one impact per period, plus the linear orbit if it fits.

    Parameters
    ----------
    c, F, g : float
        Damping ``0 <= c < 2``, forcing amplitude, gap ``g > 0``.
    w : float
        Forcing frequency (``> 0``; for ``c = 0`` not ``1/k``).

    Returns
    -------
    list of Orbit
        Impacting orbits by increasing impact velocity, then the non-impacting linear orbit
        when its amplitude ``F / sqrt((1 - w^2)^2 + (c w)^2) <= g``.
    """
    _check_damping(c)
    if not (g > 0 and w > 0):
        raise ValueError(f"need g > 0 and w > 0, got g={g!r}, w={w!r}")
    a, b, c0, h, P = _quadratic(c, F, g, w)
    D = b * b - 4.0 * a * c0
    out = []
    if D >= 0.0:
        r = math.sqrt(D)
        # numerically stable roots: q = -(b + sign(b) r) / 2, v = q / a and c0 / q
        q = -0.5 * (b + math.copysign(r, b))
        roots = sorted({q / a, c0 / q} if q != 0.0 else {0.0})
        for v in roots:
            orbit = _impacting_orbit(c, F, g, w, v, h, P)
            if orbit is not None:
                out.append(orbit)
    if abs(P) <= g:
        out.append(_linear_orbit(c, F, g, w))
    return out


# --------------------------------------------------------------------------------------------
# Fold, grazing, free backbone
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Fold:
    """Saddle-node of the impacting one-impact branch (:func:`upper_fold`).

    Attributes
    ----------
    w : float
        Fold frequency.
    orbit : Orbit
        The double orbit there.
    """

    w: float
    orbit: Orbit

    @property
    def max_abs_u(self) -> float:
        return self.orbit.max_abs_u

    @property
    def energy(self) -> float:
        return self.orbit.energy


def upper_fold(c: float, F: float, g: float, w_max: float = 4.0, n_scan: int = 4000) -> Fold:
    """Upper fold of the impacting branch: the largest ``w`` where two one-impact orbits merge.

    The discriminant ``D(w)`` of the impact-velocity quadratic is smooth; it is scanned on
    ``(w_graze, w_max]`` (``w_graze`` the upper grazing frequency, or 1 when there is none) and
    the last sign change from ``D >= 0`` to ``D < 0`` whose double root is a physical orbit is
    refined by ``brentq`` to machine precision. At the fold the double root is ``v = -b / (2a)``,
    smooth in ``w`` (unlike the two roots, which vary like ``sqrt(w_f - w)``), so the fold
    orbit, its ``max|u|`` and energy inherit the accuracy of ``w_f``.

    Parameters
    ----------
    c, F, g : float
        The system (``c > 0`` so the forced orbit is bounded).
    w_max, n_scan : float, int
        Upper end and points of the scan.

    Returns
    -------
    Fold
    """
    _check_damping(c)
    graze = grazing_frequencies(c, F, g)
    w_lo = graze[-1] if graze else 1.0
    ws = np.linspace(w_lo, w_max, n_scan + 1)[1:]
    D = np.array([discriminant(c, F, g, w) for w in ws])
    for k in np.flatnonzero((D[:-1] >= 0) & (D[1:] < 0))[::-1]:
        wf = brentq(lambda w: discriminant(c, F, g, w), ws[k], ws[k + 1], xtol=1e-15, rtol=4 * np.finfo(float).eps)
        a, b, _, h, P = _quadratic(c, F, g, wf)
        orbit = _impacting_orbit(c, F, g, wf, -b / (2.0 * a), h, P)
        if orbit is not None:
            return Fold(w=wf, orbit=orbit)
    raise ValueError(f"no fold of one-impact orbits found in ({w_lo}, {w_max}] for c={c}, F={F}, g={g}")


def peak_response(c: float, F: float, g: float, quantity: str = "max_abs_u", n_scan: int = 400) -> Orbit:
    """Orbit of largest ``max_abs_u`` (or ``energy``) on the resonant (larger-``v``) impacting branch.

    Not the fold: like the nose of a damped Duffing curve, the branch reaches its largest
    response slightly *below* the fold frequency and comes back down to the fold (where
    ``d w / d v = 0``, not ``d max|u| / d v = 0``). A continuation that reports the response at
    its turning point in ``w`` and one that reports the peak response differ by this much.

    The larger root is smooth in ``w`` inside ``(w_graze_low, w_f)``; the maximum is bracketed on
    a grid and refined by bounded Brent (the value is then exact to round-off, the location to
    about ``sqrt(eps)``).

    Parameters
    ----------
    c, F, g : float
        The system.
    quantity : {"max_abs_u", "energy"}
        What to maximise.
    n_scan : int
        Grid points between the lower grazing frequency and the fold.

    Returns
    -------
    Orbit
    """
    if quantity not in ("max_abs_u", "energy"):
        raise ValueError(f"quantity must be 'max_abs_u' or 'energy', got {quantity!r}")
    wf = upper_fold(c, F, g).w
    graze = grazing_frequencies(c, F, g)
    w_lo = graze[0] if graze else 1.0

    def upper(w):
        hits = [o for o in one_impact_orbits(c, F, g, w) if o.impacting]
        return max(hits, key=lambda o: o.velocity) if hits else None

    def value(w):
        o = upper(w)
        return -getattr(o, quantity) if o is not None else math.inf

    ws = np.linspace(w_lo, wf, n_scan + 1)[1:-1]
    vals = np.array([value(w) for w in ws])
    k = int(np.argmin(vals))
    lo, hi = ws[max(k - 1, 0)], (ws[k + 1] if k + 1 < ws.size else wf)
    res = minimize_scalar(value, bounds=(lo, hi), method="bounded", options={"xatol": 1e-13})
    return upper(res.x)


def grazing_frequencies(c: float, F: float, g: float) -> list[float]:
    """Frequencies where the linear orbit's amplitude ``F / sqrt((1 - w^2)^2 + (c w)^2)`` equals ``g``.

    ``z = w^2`` solves ``z^2 - (2 - c^2) z + 1 - (F/g)^2 = 0``.

    Returns
    -------
    list of float
        The positive solutions, increasing (0, 1 or 2 of them).
    """
    p = 2.0 - c * c
    q = 1.0 - (F / g) ** 2
    disc = p * p - 4.0 * q
    if disc < 0:
        return []
    r = math.sqrt(disc)
    zs = [0.5 * (p - r), 0.5 * (p + r)]
    return sorted(math.sqrt(z) for z in zs if z > 0)


def free_frequency(E: float, g: float) -> float:
    """Exact frequency of the free conservative impact oscillator ``u'' + u = 0``, ``u <= g``.

    ``w = pi / (pi - arccos(g / A))``, ``A = sqrt(2 E)`` (the orbit is a cosine of amplitude
    ``A`` cut at ``u = g``); 1 when ``A <= g`` (no impact).
    """
    A = math.sqrt(2.0 * E)
    if A <= g:
        return 1.0
    return math.pi / (math.pi - math.acos(g / A))
