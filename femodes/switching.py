r"""Analyses layer: switching from a branch onto the branch born at one of its bifurcations.

Period doubling. A period-``T`` orbit ``x`` (harmonics of ``w / nu``) is also a period-``2T``
orbit: written on the harmonics of ``w / 2 nu`` it has only even harmonics. At a period-doubling
point the harmonic balance Jacobian on that doubled basis, ``J2``, becomes singular, and because
multiplication by a period-``T`` function couples harmonics ``m`` and ``m +- 2k`` only, ``J2``
splits into an even block (the original Jacobian) and an *odd* block, which holds the singularity
and whose null vector ``phi`` (odd harmonics only) is the period-doubled direction. The new branch
is a pitchfork in the doubled space (``phi`` and ``-phi`` are the same orbit shifted by ``T``).

:func:`switch_branch` (1) locates the period doubling of the HBM orbit itself near the reported
bifurcation, by regula falsi on the sign of ``det`` of the odd block along the branch (the
reported point may come from shooting, which refines the orbit: the HBM's own period doubling
sits where its truncated series puts it); (2) takes ``phi`` from the smallest singular vector of
the odd block there; (3) solves ``r2(x, w) = 0`` with ``phi . (x - x_pd) = a`` for a point at
amplitude ``a`` on the new branch (Keller's method for a pitchfork); (4) continues it with
:func:`~femodes.frequency_response` on the doubled harmonics, away from the bifurcation.
"""

from __future__ import annotations

import logging
import math
import numpy as np
import scipy.linalg as sla

from .analyses import frequency_response
from .hbm.harmonics import Harmonics
from .hbm.problems import ForcedResponseProblem
from .results import Bifurcation, Branch
from .floquet import solve_on_secant
from .solvers import ContinuationOptions, NewtonOptions, semismooth_newton
from .solvers.roots import illinois

__all__ = ["switch_branch", "DENSE_LIMIT"]

log = logging.getLogger(__name__)

#: Largest odd block (unknowns) factorised densely to locate a period doubling.
DENSE_LIMIT = 4000


def _doubled(h: Harmonics) -> Harmonics:
    return Harmonics(2 * h.n_harmonics, subharmonic=2 * h.subharmonic)


def _embed(C: np.ndarray, h: Harmonics, h2: Harmonics) -> np.ndarray:
    """Coefficients on ``h`` (rows) rewritten on the doubled harmonics ``h2``: harmonic ``k`` of
    ``w/nu`` is harmonic ``2k`` of ``w/2nu``."""
    out = np.zeros((h2.n_coef,) + C.shape[1:])
    out[0] = C[0]
    k = np.arange(1, h.n_harmonics + 1)
    out[h2.cos_rows(2 * k)] = C[h.cos_rows(k)]
    out[h2.sin_rows(2 * k)] = C[h.sin_rows(k)]
    return out


class _Doubled:
    """The forced problem on the doubled harmonics and its odd block."""

    def __init__(self, model, h: Harmonics):
        self.h, self.h2 = h, _doubled(h)
        self.problem = ForcedResponseProblem(model, self.h2)
        s = self.problem.system
        rows = np.flatnonzero(self.h2.harmonic_of % 2 == 1)
        # the odd-harmonic unknowns, by the system's own index maps (a symmetric permutation of
        # the block: its determinant's sign and its null vector are unaffected)
        self.odd = np.concatenate([s.q_index(d)[rows] for d in range(s.n)]
                                  + [s.p_index(k)[rows] for k in range(s.n_uc)])
        if self.odd.size > DENSE_LIMIT:
            raise NotImplementedError(
                f"switch_branch: the period-doubled problem has {self.odd.size} odd unknowns (dense limit "
                f"{DENSE_LIMIT}); reduce the model with craig_bampton or lower the harmonics")

    def point(self, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
        return self.problem.pack(_embed(Q, self.h, self.h2), _embed(P, self.h, self.h2), 0.0)

    def odd_block(self, x2: np.ndarray, omega: float) -> np.ndarray:
        _, J, _ = self.problem.residual(x2, omega)
        return J.tocsr()[self.odd][:, self.odd].toarray()

    def test(self, x2: np.ndarray, omega: float) -> float:
        """``sign(det A) |det A|^(1/m)`` of the odd block ``A``: continuous, zero at a period doubling."""
        A = self.odd_block(x2, omega)
        sign, logdet = np.linalg.slogdet(A)
        return float(sign * math.exp(logdet / A.shape[0])) if sign != 0 else 0.0


def _locate_hbm_doubling(branch: Branch, bif: Bifurcation, dbl: _Doubled, newton: NewtonOptions, window: int):
    """The HBM orbit's own period doubling nearest to ``bif``: ``(x1, omega)`` on the branch."""
    p1 = ForcedResponseProblem(branch.model, branch.harmonics)
    lo, hi = max(0, bif.index - window), min(len(branch) - 1, bif.index + 1 + window)
    vals = {i: dbl.test(dbl.point(branch.Q[i], branch.P[i]), branch.omega[i]) for i in range(lo, hi + 1)}
    changes = [i for i in range(lo, hi) if vals[i] == 0.0 or (vals[i] > 0) != (vals[i + 1] > 0)]
    if not changes:
        raise RuntimeError(
            f"switch_branch: the HBM orbit shows no period doubling between w = {branch.omega[lo]:.6g} and "
            f"{branch.omega[hi]:.6g} (H = {branch.harmonics.n_harmonics}) near the reported one at w = {bif.omega:.6g}; "
            "raise the harmonics (contact orbits converge slowly) or widen the search")
    i = min(changes, key=lambda j: abs(j + 0.5 - (bif.index + 0.5)))
    za = np.append(p1.pack(branch.Q[i], branch.P[i], branch.omega[i]), branch.omega[i])
    zb = np.append(p1.pack(branch.Q[i + 1], branch.P[i + 1], branch.omega[i + 1]), branch.omega[i + 1])
    points = {0.0: za, 1.0: zb}

    def test(theta: float) -> float | None:
        z = solve_on_secant(p1, za, zb, theta, newton)
        if z is None:
            return None
        points[theta] = z
        u = p1.unpack(z[:-1], z[-1])
        return dbl.test(dbl.point(u.Q, u.P), u.omega)

    br = illinois(test, 0.0, 1.0, vals[i], vals[i + 1], max_iter=60, ftol=1e-13, xtol=1e-12)
    best = points[br.lo if abs(br.f_lo) <= abs(br.f_hi) else br.hi]
    u = p1.unpack(best[:-1], best[-1])
    return u, i


def switch_branch(branch: Branch, bifurcation: Bifurcation, omega: tuple[float, float], *,
                  amplitude: float | None = None, options: ContinuationOptions | None = None,
                  stability: bool | str = False, window: int = 10) -> Branch:
    """Continue the branch born at ``bifurcation`` of ``branch`` (module docstring).

    Parameters
    ----------
    branch : Branch
        A forced response with its model (as returned by :func:`~femodes.frequency_response`
        with ``stability=True``).
    bifurcation : Bifurcation
        One of ``branch.bifurcations``; ``kind == "period_doubling"`` (other kinds:
        ``NotImplementedError``).
    omega : (float, float)
        Frequency span (rad/s) the new branch is traced in; it starts at the bifurcation and
        runs away from it towards the end of the span on the side where the new branch exists.
    amplitude : float, optional
        Size of the first step along the period-doubled direction (default 1e-2 of the
        orbit's largest coefficient).
    options : ContinuationOptions, optional
        Continuation of the new branch (default :func:`~femodes.frequency_response_options`).
    stability : bool or str
        Stability of the new branch, as in :func:`~femodes.frequency_response`.
    window : int
        Points of ``branch`` on each side of the bifurcation searched for the HBM's own period
        doubling.

    Returns
    -------
    Branch
        On the doubled harmonics ``Harmonics(2H, subharmonic=2 nu)``; ``meta["switched_from"]``
        says where it starts.
    """
    if not isinstance(branch, Branch):
        raise TypeError(f"switch_branch: branch must be a femodes Branch, got {type(branch).__name__}")
    if not isinstance(bifurcation, Bifurcation):
        raise TypeError(f"switch_branch: bifurcation must be one of branch.bifurcations, got {type(bifurcation).__name__}")
    if branch.kind != "forced":
        raise NotImplementedError("switch_branch: only forced responses so far (backbone tongues are not supported)")
    if bifurcation.kind != "period_doubling":
        raise NotImplementedError(f"switch_branch: only period doubling is supported, got kind={bifurcation.kind!r}")
    if branch.model is None:
        raise ValueError("switch_branch: the branch has no model (loaded from a file?); attach it with branch.attach(model)")
    try:
        a_span, b_span = (float(v) for v in omega)
    except (TypeError, ValueError):
        raise TypeError(f"switch_branch: omega must be a pair (start, end) of frequencies, got {omega!r}") from None
    model = branch.model
    newton = (options.newton if options is not None else NewtonOptions(atol=1e-9, max_iter=20))
    dbl = _Doubled(model, branch.harmonics)
    u, i = _locate_hbm_doubling(branch, bifurcation, dbl, newton, int(window))
    x_pd = dbl.point(u.Q, u.P)
    A = dbl.odd_block(x_pd, u.omega)
    _, svals, Vt = sla.svd(A)
    phi = np.zeros(dbl.problem.size)
    phi[dbl.odd] = Vt[-1]
    scale = float(np.max(np.abs(u.Q))) or 1.0
    a = 1e-2 * scale if amplitude is None else float(amplitude)
    first = _first_point(dbl.problem, x_pd, u.omega, phi, a, newton)
    if first is None:
        raise RuntimeError(f"switch_branch: no period-doubled orbit found at amplitude {a:g} from w = {u.omega:.8g}; "
                           "pass a smaller amplitude=")
    x1, w1 = first
    end = max(a_span, b_span) if w1 >= u.omega else min(a_span, b_span)
    log.info("switch_branch: HBM period doubling at w = %.8g (reported %.8g); new branch from w = %.8g towards %.6g",
             u.omega, bifurcation.omega, w1, end)
    new = frequency_response(model, (w1, end), dbl.h2, options=options, x0=x1, stability=stability)
    new.meta["switched_from"] = {"kind": bifurcation.kind, "omega_hbm": float(u.omega),
                                 "omega_reported": float(bifurcation.omega), "index": int(i),
                                 "smallest_singular_value": float(svals[-1] / svals[0])}
    return new


def _first_point(problem: ForcedResponseProblem, x_pd, w_pd, phi, a, newton):
    """``r2(x, w) = 0`` with ``phi . (x - x_pd) = a``, from ``x_pd + a phi`` at ``w_pd``."""
    n = x_pd.size

    def fun(z):
        r, J, dr_dw = problem.residual(z[:n], z[n])
        return (np.append(r, phi @ (z[:n] - x_pd) - a),
                J.bordered(dr_dw[:, None], phi[None, :], np.zeros((1, 1))))

    res = semismooth_newton(fun, np.append(x_pd + a * phi, w_pd), options=newton)
    if not res.success:
        return None
    return res.x[:n], float(res.x[n])
