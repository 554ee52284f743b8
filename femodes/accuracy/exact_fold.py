"""The fold of the exact curve next to a fold of the branch: the extreme frequency of the exact
orbits on hyperplanes parallel to the fold's own (Brent's method in the offset; with massless
contacts a failed continuation step to a plane is halved). Where the impacting orbits end at a
grazing (the lower fold of a forced impact oscillator: the branch meets the linear response) the
fold is that grazing frequency, in closed form (:func:`grazing`). Seed cases from H = 20: upper
folds 1.4191583461 and 1.4227515912, equal to the event-driven references to 1e-16 and 9e-15;
lower folds at the grazings 1.0808687 and 1.1519492.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .options import AccuracyOptions
from .planes import Plane
from .points import without_contact
from .protocol import orbit_amplitudes
from .shooter import Shooter

__all__ = ["ShootingFailed", "exact_fold", "grazing"]

log = logging.getLogger(__name__)


class ShootingFailed(RuntimeError):
    """No exact orbit where the fold search needs one."""


def exact_fold(sh: Shooter, f: int, at_f, options: AccuracyOptions
               ) -> tuple[float, float, np.ndarray | None, float] | None:
    """The fold of the exact curve next to the branch's fold ``f``: the extreme frequency of
    the exact orbits on the hyperplanes parallel to ``f``'s (offset ``s``), found by Brent's
    method in ``s`` from ``at_f`` (the orbit at ``s = 0``). Returns the frequency, the relative
    half-width of its uncertainty (the change of the frequency over the final tolerance in
    ``s``, at least ``options.shooting_floor``), the fold orbit's amplitudes per DOF
    (:func:`~.protocol.orbit_amplitudes`) and their relative change over that tolerance (at a fold
    they move at first order where the frequency moves at second: their own error bar); or None.
    A fold that is the grazing of the linear response has no amplitudes (None) and no bar (NaN)."""
    from scipy.optimize import minimize_scalar

    b = sh.branch
    n = len(b)
    nb = [j for j in (f - 1, f + 1) if 0 <= j < n]
    upper = all(b.omega_truncated[j] <= b.omega_truncated[f] for j in nb)
    sign = -1.0 if upper else 1.0
    # the offset of the neighbours in the plane's units: the scale of the search
    plane = Plane(sh.lad, sh.H, f)
    d = max(abs(plane.at(b.Q[j], float(b.omega_truncated[j]))) for j in nb)
    if not d > 0.0:
        return None
    solved = {0.0: at_f}

    # with impacts the orbits with contact end at a grazing next to a lower fold (handled below),
    # with massless contacts they go on into the linear orbit, which a step may overshoot
    halvings = options.fold_step_halvings if sh.flow.massless.any() else 0
    scale = d  # of the bracket; the continuation's steps are half of it

    def reach(s: float, exact: bool = True) -> float:
        """Continuation from the nearest solved offset to ``s`` in steps of ``scale / 2``, a failed
        step halved (``halvings`` times in all); the offset reached (``s`` if ``exact``)."""
        near = min(solved, key=lambda t: abs(t - s))
        r, at, step = solved[near], near, math.copysign(0.5 * scale, s - near)
        fails = 0
        while at != s:
            sk = s if abs(s - at) <= abs(step) else at + step
            rk = sh.solve(f, guess=r[:3], offset=sk)
            if rk is None:
                fails += 1
                if fails > halvings:
                    if exact or at == near:
                        raise ShootingFailed(f"no exact orbit at offset {sk:g} from fold {f}")
                    return at
                step *= 0.5
                continue
            r, at = rk, sk
            solved[sk] = r
        return at

    def omega_at(s: float) -> float:
        return sign * solved[reach(s)][1]

    def side(s: float) -> tuple[float, float]:
        at = reach(s, exact=False)
        return at, sign * solved[at][1]

    def extreme(h: float) -> tuple[float, float]:
        """A bracket (sa, sb, sc) with the extreme inside, walking downhill by ``h``, then Brent."""
        nonlocal scale
        scale = h
        sb, fb = 0.0, sign * at_f[1]
        (sa, fa), (sc, fc) = side(-h), side(h)
        for _ in range(8):
            if fb <= min(fa, fc):
                break
            if fa < fc:
                sa, sb, sc, fc, fb = sa - h, sa, sb, fb, fa
                fa = omega_at(sa)
            else:
                sa, sb, sc, fa, fb = sb, sc, sc + h, fb, fc
                fc = omega_at(sc)
        else:
            raise ShootingFailed(f"no extreme frequency within {8 * h:g} of fold {f}")
        res = minimize_scalar(omega_at, bracket=(sa, sb, sc), method="brent", options={"xtol": 1e-4})
        return float(res.x), sign * float(res.fun)

    try:
        try:
            s, w = extreme(d)
        except ShootingFailed:
            if not halvings:
                raise
            # massless contacts: planes a neighbour's offset away may cross the exact curve past its
            # fold (2-DOF case of the tests, H = 10: an orbit below the fold's frequency at 0.87 d)
            s, w = extreme(0.25 * d)
        tol = 1e-4 * max(abs(s), d)
        spread = max(abs(sign * omega_at(s + tol) - w), abs(sign * omega_at(s - tol) - w))
        amp = orbit_amplitudes(solved[s][3])
        ref = float(np.max(amp)) or 1.0
        amp_spread = max(float(np.max(np.abs(orbit_amplitudes(solved[s + e][3]) - amp))) for e in (tol, -tol)) / ref
    except (ShootingFailed, ValueError, RuntimeError) as exc:
        # a lower fold that ends the contact within a few points: the impacting orbits end at a
        # grazing there (past it the exact curve has no impacting orbit on these planes)
        free = without_contact(b)
        ends_contact = bool(free[max(f - options.grazing_points, 0): f + options.grazing_points + 1].any())
        # (impacts only: a massless contact's orbits leave the linear one smoothly, its folds are ordinary)
        impacts = not sh.flow.massless.any()
        graze = grazing(sh.flow, float(b.omega_truncated[f])) if not upper and ends_contact and impacts else None
        if graze is None:
            log.info("accuracy: the exact fold next to point %d was not located (%s)", f, exc)
            return None
        log.info("accuracy: the fold next to point %d is the grazing of the linear response at w = %.9g", f,
                 graze)
        return graze, options.shooting_floor, None, math.nan
    return w, max(spread / abs(w), options.shooting_floor), amp, amp_spread


def grazing(flow, omega: float) -> float | None:
    """The frequency nearest ``omega`` (within 5 %) at which the linear response just touches
    an obstacle (``max_t q_c = gap``). With restitution 1 the branch of impacting orbits
    ends there on the linear one (a nonsmooth fold; harmonic balance smooths it into a fold:
    seed case 1, H = 20, 1.080770 against the grazing 1.080869). Forcing with one harmonic
    (and a static part) only: ``max_t q_c = Re X_0 + |X_1|`` in closed form."""
    from scipy.optimize import brentq

    if not set(flow.k.tolist()) <= {0, 1}:
        return None

    def margin(w):
        fl = flow.at(w)
        X = fl.free_harmonics()
        top = np.abs(X[1]) if 1 in X else 0.0
        return float(np.min(fl.gaps - np.real(X[0]) - top))

    ws = omega * (1.0 + np.linspace(-0.05, 0.05, 201))
    m = np.array([margin(w) for w in ws])
    roots = [brentq(margin, ws[j], ws[j + 1], xtol=1e-14 * omega) for j in np.flatnonzero(m[:-1] * m[1:] < 0.0)]
    return min(roots, key=lambda r: abs(r - omega)) if roots else None
