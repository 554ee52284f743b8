r"""Independent finite-difference check of the bar-on-a-stop nonsmooth mode
(``bar_stop_reference``).

Shares no code with :mod:`tests.bar_stop_reference` (nor with :mod:`femodes`): plain numpy.

Scheme
------

Grid ``x_j = j h``, ``h = 1 / n_cells``, time step ``dt = h`` (CFL = 1)::

    u_j^{n+1} = u_{j+1}^n + u_{j-1}^n - u_j^{n-1}        (1 <= j < N)
    u_0^{n+1} = 0                                          (clamp)
    u_N^{n+1} = min(2 u_{N-1}^n - u_N^{n-1}, g)            (free end by an even ghost, clipped)

At CFL = 1 the interior update is d'Alembert's identity ``u(x, t+h) + u(x, t-h) = u(x+h, t) +
u(x-h, t)``, exact for *any* solution, and the even ghost is exact for a free end, so without
contact the scheme reproduces the sampled exact solution to round-off. With contact:

* the hit is exact too (the clipped value ``g`` is the true tip value once contact started), and
  while in contact the free prediction exceeds ``g`` (compressive incoming wave), so the tip stays
  exact;
* the *release* is not: the ghost update over ``[t_{n-1}, t_{n+1}]`` still sees part of the contact
  phase, so the tip leaves the stop one step late (error ``<= 2 a h`` in the tip value), which
  leaves an O(h) error and excites the grid-scale mode ``(-1)^{n+j}``. That mode has zero value of
  the leapfrog energy ``sum (du/dt)^2/2 + (u_x^{n+1} u_x^n)/2`` (semi-definite at CFL = 1), so the
  leapfrog energy is not a useful invariant here; we monitor a *filtered* energy (central time
  difference for the velocity, ``(u^{n-1} + 2 u^n + u^{n+1})/4`` for the strain; both blind to the
  grid-scale mode), whose drift is O(h).

Hence: displacements, period and contact duration converge at first order in ``h``; nothing here
conserves the energy to round-off. The initial state is the one claimed to lie on the orbit: the
bar at rest with a uniform strain, ``u0 = -lam x``, ``lam = sqrt(2 E)``, ``E = rho E_g``,
``E_g = pi^2 g^2 / 16`` -- it needs no formula from the reference module.
"""

from __future__ import annotations

import numpy as np


def grazing_energy(gap: float = 0.01) -> float:
    return np.pi**2 * gap**2 / 16.0


def uniform_strain_start(energy_ratio: float, n_cells: int, gap: float = 0.01):
    """``(x, u0, v0)``: bar at rest with uniform strain of energy ``energy_ratio * E_g``."""
    x = np.linspace(0.0, 1.0, n_cells + 1)
    lam = np.sqrt(2.0 * energy_ratio * grazing_energy(gap))
    return x, -lam * x, np.zeros_like(x)


def leapfrog_signorini(u0, v0, gap: float, n_steps: int, record_steps=()):
    """Integrate ``n_steps`` steps of the clipped CFL = 1 leapfrog.

    Returns a dict: ``tip`` (``n_steps + 1`` values of ``u_N``), ``energy_filtered`` (at steps
    1 .. n_steps-1), ``energy_leapfrog`` (at half steps), ``states`` {step: (u, v)} for the steps
    in ``record_steps`` (``v`` by central difference; at step 0 the given ``v0``).
    """
    u0 = np.asarray(u0, float)
    v0 = np.asarray(v0, float)
    N = u0.size - 1
    h = 1.0 / N
    want = set(int(s) for s in record_steps)
    # first step: exact one-step d'Alembert with trapezoid for the velocity integral
    u1 = np.empty_like(u0)
    u1[1:N] = 0.5 * (u0[2:] + u0[:-2]) + 0.25 * h * (v0[:-2] + 2.0 * v0[1:N] + v0[2:])
    u1[0] = 0.0
    u1[N] = min(u0[N - 1] + 0.5 * h * (v0[N - 1] + v0[N]), gap)
    w = np.ones(N + 1)
    w[0] = 0.0
    w[N] = 0.5
    tip = np.empty(n_steps + 1)
    tip[0], tip[1] = u0[N], u1[N]
    ef = np.full(n_steps + 1, np.nan)
    el = np.full(n_steps, np.nan)
    states = {}
    if 0 in want:
        states[0] = (u0.copy(), v0.copy())
    prev, cur = u0, u1
    el[0] = (np.sum(w * (u1 - u0) ** 2) + np.sum(np.diff(u1) * np.diff(u0))) / (2 * h)
    for n in range(1, n_steps):
        nxt = np.empty_like(cur)
        nxt[1:N] = cur[2:] + cur[:-2] - prev[1:N]
        nxt[0] = 0.0
        nxt[N] = min(2.0 * cur[N - 1] - prev[N], gap)
        tip[n + 1] = nxt[N]
        el[n] = (np.sum(w * (nxt - cur) ** 2) + np.sum(np.diff(nxt) * np.diff(cur))) / (2 * h)
        v = (nxt - prev) / (2.0 * h)
        ub = 0.25 * (prev + 2.0 * cur + nxt)
        vm = 0.5 * (v[1:] + v[:-1])
        ef[n] = 0.5 * h * np.sum(vm**2 + (np.diff(ub) / h) ** 2)
        if n in want:
            states[n] = (cur.copy(), v)
        prev, cur = cur, nxt
    return {"tip": tip, "energy_filtered": ef, "energy_leapfrog": el, "states": states, "h": h}


def _line_cross(t, y, level):
    A = np.vstack([t, np.ones_like(t)]).T
    k, c = np.linalg.lstsq(A, y, rcond=None)[0]
    return (level - c) / k


def contact_events(tip, h, gap, fit_span=0.4, skip=3, merge_gap=0.05):
    """Hit and release times of the tip, each from a least-squares line through the time-averaged
    tip values ``(u^n + u^{n+1})/2`` (blind to the grid-scale mode) over ``fit_span`` time units of
    free flight next to the event (``skip`` steps next to it left out), crossed with ``g``. Contact
    runs separated by less than ``merge_gap`` (spurious one-step releases of the clipped scheme,
    seen after a few periods) count as one contact phase."""
    c = tip >= gap
    tb = 0.5 * (tip[:-1] + tip[1:])
    tt = (np.arange(tb.size) + 0.5) * h
    m = max(int(fit_span / h), 4)
    hits, rels = [], []
    starts = np.where(c[1:] & ~c[:-1])[0] + 1
    ends = np.where(~c[1:] & c[:-1])[0] + 1  # first free step after contact
    # merge contact runs split by short spurious releases (chatter of the clipped scheme)
    gap_steps = max(int(merge_gap / h), 1)
    if starts.size and ends.size:
        keep_s = np.r_[True, [not np.any((ends < st) & (ends >= st - gap_steps))
                              for st in starts[1:]]]
        keep_e = np.array([not np.any((starts > en) & (starts <= en + gap_steps)) for en in ends])
        starts, ends = starts[keep_s], ends[keep_e]
    for s in starts:
        i0, i1 = s - 1 - skip - m, s - 1 - skip
        if i0 >= 0 and not c[i0:i1 + skip].any():
            hits.append(_line_cross(tt[i0:i1], tb[i0:i1], gap))
    for e in ends:
        i0, i1 = e + skip, e + skip + m
        if i1 + 1 < c.size and not c[i0 - skip:i1 + 2].any():
            rels.append(_line_cross(tt[i0:i1], tb[i0:i1], gap))
    return np.array(hits), np.array(rels)


def fd_period_and_return_error(energy_ratio: float, n_cells: int, n_periods: int = 3,
                               gap: float = 0.01, period_guess: float = 4.0):
    """Integrate ``n_periods`` (+ a margin) from the uniform-strain state and measure.

    Returns a dict with ``period`` (mean of successive hit-time differences), ``period_spread``
    (max - min of them), ``contact_duration`` (mean release - hit), ``return_disp`` (max over the
    ``n_periods`` returns of ``max|u(kT) - u0| / max|u0|``, ``u(kT)`` at the nearest step),
    ``return_disp_l2`` (same, L2 norms), ``return_vel_l2`` (``||v(kT)||_L2 / lam``),
    ``energy_drift`` (max - min of the filtered energy / E), ``energy_mean`` (mean filtered
    energy / E), ``leapfrog_energy_change`` (last / first leapfrog energy - 1).
    Cost: ``~ n_periods * 3.6 * n_cells`` vector steps of size ``n_cells`` (N = 800: < 1 s).
    """
    _, u0, v0 = uniform_strain_start(energy_ratio, n_cells, gap)
    h = 1.0 / n_cells
    E = energy_ratio * grazing_energy(gap)
    lam = np.sqrt(2.0 * E)
    n_steps = int(np.ceil((n_periods + 0.6) * period_guess / h))
    first = leapfrog_signorini(u0, v0, gap, n_steps)
    hits, rels = contact_events(first["tip"], h, gap)
    if hits.size < 2:
        raise RuntimeError("fewer than two contact phases found")
    dT = np.diff(hits)
    T = float(np.mean(dT))
    dur = [r - hh for hh in hits for r in rels[(rels > hh) & (rels < hh + T)][:1]]
    k_steps = [int(round(k * T / h)) for k in range(1, n_periods + 1)]
    n_steps2 = max(k_steps) + 2
    run = leapfrog_signorini(u0, v0, gap, n_steps2, record_steps=k_steps)
    scale = np.max(np.abs(u0))

    def l2(f):  # trapezoid L2 norm (f[0] = 0 at the clamp)
        return np.sqrt(h * (np.sum(f**2) - 0.5 * f[-1] ** 2))

    rd = max(np.max(np.abs(run["states"][k][0] - u0)) / scale for k in k_steps)
    rd2 = max(l2(run["states"][k][0] - u0) / l2(u0) for k in k_steps)
    rv2 = max(l2(run["states"][k][1] - v0) / lam for k in k_steps)
    ef = first["energy_filtered"]
    ef = ef[np.isfinite(ef)]
    el = first["energy_leapfrog"]
    return {
        "period": T,
        "period_spread": float(np.ptp(dT)),
        "contact_duration": float(np.mean(dur)) if dur else float("nan"),
        "return_disp": float(rd),
        "return_disp_l2": float(rd2),
        "return_vel_l2": float(rv2),
        "energy_drift": float(np.ptp(ef) / E),
        "energy_mean": float(np.mean(ef) / E),
        "leapfrog_energy_change": float(el[-1] / el[0] - 1.0),
        "hits": hits,
        "releases": rels,
    }


def fd_max_displacement_error(energy_ratio: float, n_cells: int, exact, t_end: float,
                              gap: float = 0.01):
    """``max_n max_j |u_j^n - exact(x_j, t_n)| / max|u0|`` over ``[0, t_end]``; ``exact(x, t)``
    is a callable supplied by the caller (e.g. the closed form), so this module imports nothing."""
    x, u0, v0 = uniform_strain_start(energy_ratio, n_cells, gap)
    h = 1.0 / n_cells
    n_steps = int(np.ceil(t_end / h))
    step = max(1, n_steps // 400)
    rec = list(range(0, n_steps, step))
    run = leapfrog_signorini(u0, v0, gap, n_steps, record_steps=rec)
    scale = np.max(np.abs(u0))
    err = 0.0
    for n, (u, _) in run["states"].items():
        err = max(err, float(np.max(np.abs(u - exact(x, n * h)))))
    return err / scale
