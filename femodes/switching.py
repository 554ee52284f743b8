r"""Analyses layer: switching from a branch onto the branch born at one of its bifurcations.

:func:`switch_branch` continues, from a bifurcation of a branch traced with ``stability``:

- at a period doubling of a forced response, the period-doubled branch on the harmonics of
  ``w / 2 nu``: it locates the HBM's own period doubling by regula falsi on the sign of ``det`` of
  the odd block of the doubled Jacobian, takes its null vector ``phi`` and solves for a point at
  amplitude ``a`` along ``phi`` (Keller's method for a pitchfork);
- at a branch point (a real Floquet multiplier crossing ``+1`` away from a fold; on a backbone, a
  k:1 internal-resonance tongue), the other branch through it: it locates the HBM's own branch
  point by regula falsi on ``det [A; c^T]`` (``A = [r_x, r_p]``, ``c`` the secant), checks that
  ``A`` drops rank there, takes the null vector orthogonal to the old tangent and continues the
  new branch away from it (Keller 1977; Allgower and Georg 2003, sec. 8.1). An imperfect
  connection (the backbone folds smoothly onto the tongue) is refused, not pretended.

The method, step by step, and its limits (narrow tongues, closed branches):
:doc:`/guide/stability` (How switch_branch works).
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
from .floquet import (StabilityOptions, root_on_secant)
from .solvers import (ContinuationOptions, NewtonOptions, semismooth_newton)
from .solvers.checks import entry_point
from .solvers.threads import limit_blas_threads
from .stability_methods import StabilityMethod
from .branch_points import DENSE_LIMIT, switch_at_branch_point

__all__ = ["switch_branch", "DENSE_LIMIT"]

log = logging.getLogger(__name__)
def _doubled(h: Harmonics) -> Harmonics:
    return Harmonics(2 * h.n_harmonics, subharmonic=2 * h.subharmonic)


def _embed(C: np.ndarray, h: Harmonics, h2: Harmonics) -> np.ndarray:
    """Coefficients on ``h`` (rows) rewritten on the doubled harmonics ``h2``: harmonic ``k`` of
    ``w/nu`` is harmonic ``2k`` of ``w/2nu``."""
    out = np.zeros((h2.n_coef,) + C.shape[1:])
    out[0] = C[0]
    k = np.arange(1, h.n_harmonics + 1)
    out[h2.layout.cos_rows(2 * k)] = C[h.layout.cos_rows(k)]
    out[h2.layout.sin_rows(2 * k)] = C[h.layout.sin_rows(k)]
    return out


class _Doubled:
    """The forced problem on the doubled harmonics and its odd block."""

    def __init__(self, model, h: Harmonics):
        self.h, self.h2 = h, _doubled(h)
        self.problem = ForcedResponseProblem(model, self.h2)
        s = self.problem.system
        rows = np.flatnonzero(self.h2.layout.harmonic_of % 2 == 1)
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
    vals = {i: dbl.test(dbl.point(branch.Q[i], branch.P[i]), branch.omega_truncated[i]) for i in range(lo, hi + 1)}
    changes = [i for i in range(lo, hi) if vals[i] == 0.0 or (vals[i] > 0) != (vals[i + 1] > 0)]
    if not changes:
        raise RuntimeError(
            f"switch_branch: the HBM orbit shows no period doubling between w = {branch.omega_truncated[lo]:.6g} and "
            f"{branch.omega_truncated[hi]:.6g} (H = {branch.harmonics.n_harmonics}) near the reported one at w = {bif.omega:.6g}; "
            "raise the harmonics (contact orbits converge slowly) or widen the search")
    i = min(changes, key=lambda j: abs(j + 0.5 - (bif.index + 0.5)))
    za = np.append(p1.pack(branch.Q[i], branch.P[i], branch.omega_truncated[i]), branch.omega_truncated[i])
    zb = np.append(p1.pack(branch.Q[i + 1], branch.P[i + 1], branch.omega_truncated[i + 1]), branch.omega_truncated[i + 1])

    def test(z: np.ndarray) -> float:
        u = p1.unpack(z[:-1], z[-1])
        return dbl.test(dbl.point(u.Q, u.P), u.omega)

    best = root_on_secant(p1, za, zb, test, vals[i], vals[i + 1], newton, max_iter=60, ftol=1e-13, xtol=1e-12)
    return p1.unpack(best[:-1], best[-1]), i


def _same_bifurcation(a: Bifurcation, b: Bifurcation) -> bool:
    """``b`` is ``a``, or a copy of it (the same bifurcation of a branch loaded again from its file)."""
    if a is b:
        return True
    return (a.kind == b.kind and a.index == b.index and a.omega_truncated == b.omega_truncated
            and np.shape(a.Q) == np.shape(b.Q)
            and np.array_equal(a.Q, b.Q) and np.shape(a.P) == np.shape(b.P) and np.array_equal(a.P, b.P))


@entry_point("switch_branch")
@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
def switch_branch(branch: Branch, bifurcation: Bifurcation, omega: tuple[float, float], *,
                  amplitude: float | None = None, options: ContinuationOptions | None = None,
                  stability: bool | StabilityMethod | StabilityOptions = False, window: int = 10) -> Branch:
    """Continue the branch born at ``bifurcation`` of ``branch`` (module docstring).

    Parameters
    ----------
    branch : Branch
        A forced response (:func:`~femodes.frequency_response`) or a nonlinear mode
        (:func:`~femodes.nonlinear_mode`) with its model, traced with ``stability=True``.
    bifurcation : Bifurcation
        One of ``branch.bifurcations``: ``"period_doubling"`` (forced responses) or ``"branch_point"``
        (both). Folds, Neimark-Sacker and nonsmooth points: ``NotImplementedError``.
    omega : (float, float)
        Frequency span (rad/s) of the new branch, containing a branch point; traced away from the
        bifurcation until it leaves the span or returns to the branch point (from a backbone: in
        energy, within the backbone's energy span widened by three decades each way).
    amplitude : float, optional
        First step along the new direction (norm of the step of ``Q``; default 1e-2, resp. 2e-2 at a
        branch point, of the orbit's largest coefficient); at a branch point its sign picks the side.
    options : ContinuationOptions, optional
        Continuation of the new branch (default :func:`~femodes.frequency_response_options`, resp.
        :func:`~femodes.analyses.nonlinear_mode_options`); ``options.newton`` also corrects located points.
    stability : bool, StabilityMethod or StabilityOptions
        Stability of the new branch, as in :func:`~femodes.frequency_response` (needed to switch again).
    window : int
        Points of ``branch`` on each side of the bifurcation searched for the HBM's own bifurcation.

    Returns
    -------
    Branch
        On ``Harmonics(2H, subharmonic=2 nu)`` (period doubling) or the harmonics of ``branch``, from
        the branch point (point 0; with ``stability`` its ``bifurcations[0]``). ``meta["switched_from"]``:
        ``omega_hbm``, ``omega_reported``, ``index``, ``smallest_singular_value``, ``second_singular_value``.

    Raises
    ------
    NotImplementedError
        Another kind of bifurcation; a period doubling of a nonlinear mode; a problem larger than
        :data:`DENSE_LIMIT` (reduce with :func:`~femodes.craig_bampton` or lower the harmonics).
    RuntimeError
        No such bifurcation of the HBM near the reported one (imperfect connection), or no point at ``amplitude``.
    """
    if not isinstance(branch, Branch):
        raise TypeError(f"switch_branch: branch must be a femodes Branch, got {type(branch).__name__}")
    if not isinstance(bifurcation, Bifurcation):
        tongue = isinstance(bifurcation, dict) and "ratios" in bifurcation
        raise TypeError(f"switch_branch: bifurcation must be one of branch.bifurcations, got {type(bifurcation).__name__}"
                        + ("; a tongue of internal resonance (one of branch.internal_resonances) is not a bifurcation "
                           "of the traced family: its own branch is fm.tongue_branch(branch, k)" if tongue else ""))
    if branch.kind not in ("forced", "nonlinear mode"):
        raise ValueError(f"switch_branch: branch.kind must be 'forced' or 'nonlinear mode', got {branch.kind!r}")
    kind = bifurcation.kind
    if kind == "fold":
        raise NotImplementedError(
            f"switch_branch: bifurcation at w = {bifurcation.omega:.6g} is a fold, not a branch point: no other branch is "
            "born there (the continuation passes folds by itself); switch_branch takes a period doubling or a "
            "branch point")
    if kind not in ("period_doubling", "branch_point"):
        raise NotImplementedError(f"switch_branch: only period doubling and branch points are supported, got "
                                  f"kind={kind!r}")
    if kind == "period_doubling" and branch.kind != "forced":
        raise NotImplementedError("switch_branch: period doubling is supported on forced responses only (a nonlinear "
                                  "mode's period-doubled family is not traced); got a nonlinear-mode branch")
    if branch.model is None:
        raise ValueError("switch_branch: the branch has no model (loaded from a file?); attach it with branch.attach(model)")
    if not any(_same_bifurcation(b, bifurcation) for b in branch.bifurcations):
        found = ", ".join(f"{b.kind} at w = {b.omega:.6g}" for b in branch.bifurcations) or "none"
        raise ValueError(f"switch_branch: the {kind} at w = {bifurcation.omega:.6g} (index {bifurcation.index}) is not "
                         f"one of branch.bifurcations ({found}): it was found on another branch; pass a bifurcation "
                         "of the branch you switch from (computed with stability=True)")
    if not 0 <= bifurcation.index < len(branch):
        raise ValueError(f"switch_branch: bifurcation.index = {bifurcation.index} is not a point of the branch "
                         f"({len(branch)} points): pass one of branch.bifurcations")
    try:
        a_span, b_span = (float(v) for v in omega)
    except (TypeError, ValueError):
        raise TypeError(f"switch_branch: omega must be a pair (start, end) of frequencies, got {omega!r}") from None
    if not (math.isfinite(a_span) and math.isfinite(b_span) and a_span != b_span and min(a_span, b_span) > 0):
        raise ValueError(f"switch_branch: omega must be two distinct positive frequencies, got {omega!r}")
    if options is not None and not isinstance(options, ContinuationOptions):
        raise TypeError(f"switch_branch: options must be a femodes.ContinuationOptions or None, got {type(options).__name__}")
    if kind == "branch_point":
        return switch_at_branch_point(branch, bifurcation, (a_span, b_span), amplitude, options, stability,
                                       int(window))
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


# ------------------------------------------------------------------------------------------------
# Branch points
# ------------------------------------------------------------------------------------------------
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
