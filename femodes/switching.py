r"""Analyses layer: switching from a branch onto the branch born at one of its bifurcations.

Period doubling (forced responses). A period-``T`` orbit ``x`` (harmonics of ``w / nu``) is also a
period-``2T`` orbit: written on the harmonics of ``w / 2 nu`` it has only even harmonics. At a
period-doubling point the harmonic balance Jacobian on that doubled basis, ``J2``, becomes
singular, and because multiplication by a period-``T`` function couples harmonics ``m`` and
``m +- 2k`` only, ``J2`` splits into an even block (the original Jacobian) and an *odd* block,
which holds the singularity and whose null vector ``phi`` (odd harmonics only) is the
period-doubled direction. The new branch is a pitchfork in the doubled space (``phi`` and
``-phi`` are the same orbit shifted by ``T``).

:func:`switch_branch` (1) locates the period doubling of the HBM orbit itself near the reported
bifurcation, by regula falsi on the sign of ``det`` of the odd block along the branch (the
reported point may come from shooting, which refines the orbit: the HBM's own period doubling
sits where its truncated series puts it); (2) takes ``phi`` from the smallest singular vector of
the odd block there; (3) solves ``r2(x, w) = 0`` with ``phi . (x - x_pd) = a`` for a point at
amplitude ``a`` on the new branch (Keller's method for a pitchfork); (4) continues it with
:func:`~femodes.frequency_response` on the doubled harmonics, away from the bifurcation.

Branch points (forced responses and backbones). A real Floquet multiplier crossing ``+1`` away
from a fold (:mod:`femodes.floquet`, kind ``"branch_point"``) is where another branch of orbits
of the *same* period crosses this one: the ``n x (n+1)`` Jacobian ``A = [r_x, r_p]`` of the HBM
problem ``r(x, p) = 0`` (parameter ``p = w`` for a forced response, ``log10 E`` for a nonlinear
mode) drops rank there and has a two-dimensional null space (Keller 1977; Allgower and Georg
2003, sec. 8.1). On a backbone this is how a k:1 internal-resonance tongue leaves it: a
nontrivial pair of multipliers ``exp(+-i 2 pi w_2 / w)`` reaches ``+1`` when ``w_2 = k w``, and
when a symmetry keeps the tongue's extra content out of the backbone orbits the tongue branches
off at a genuine (pitchfork) branch point. Without such a symmetry the truncated HBM usually
shows an *imperfect* connection instead (the backbone folds smoothly onto the tongue, no branch
point): :func:`switch_branch` then says so rather than pretend.

:func:`switch_branch` (1) locates the HBM branch's own branch point near the reported one by
regula falsi on the test function ``det [A(z); c^T]`` with ``c`` the secant of the bracketing
segment (``det [A; c^T] = c . a(z)`` with ``a`` the vector of signed maximal minors of ``A``,
which spans its null space on a regular branch, vanishes at a simple branch point and changes
sign there; at a fold ``A`` keeps full rank and the test function its sign), over solutions
corrected on the secant (:func:`~femodes.floquet.solve_on_secant`); (2) checks the located point
is genuine (the smallest singular value of ``A`` has dropped by orders of magnitude from the
bracket's ends) and takes the two-dimensional null space of ``A`` there (dense SVD, in the
scaled unknowns of the continuation); (3) takes the new direction ``phi`` as the null vector
orthogonal to the old branch's tangent and solves ``r(z) = 0`` with ``<phi, z - z_bp> = a``
(Keller's method: the old branch meets that hyperplane only at distance ``O(sqrt a)``);
(4) continues the new branch from that point away from the branch point: a continuation
(:func:`~femodes.solvers.continuation`) resumed from a state at that point whose tangent points
along ``phi``, in ``w`` over the whole requested span for a forced response, in ``log10 E`` for a
nonlinear mode, stopped when its frequency leaves the requested span. It also stops when the new
branch comes back to the branch point: the symmetry-breaking orbits of a pitchfork often form a
closed branch (an isola through the branch points of the symmetric branch, or a tongue that
leaves the backbone and returns to it). The new branch starts with the branch point itself
(point 0); with ``stability`` its bifurcations list that branch point first (index 0) and the
branch points the test function finds along it (along the side branch of a pitchfork the
critical multiplier only touches +1, so the Floquet multipliers do not show them):
``switch_branch`` on the new branch at one of them leads back, e.g. off the tongue onto the
backbone.

On a backbone the pair that collides at ``+1`` and leaves the unit circle is located by
:mod:`femodes.floquet` on the side where it is still complex (it classifies it as a branch point
by its distance to ``+1``, ``floquet.COLLISION``): the reported frequency is only bracketed by
that segment, and the HBM's own branch point is located here. Two branch points closer than one step of the branch (the two edges of a
narrow tongue) change the test function's sign twice: the reported segment is then sampled at
:data:`SUBDIVIDE` points. A third-order tongue (3:1 with the symmetry above) can be narrower
than any step: the multipliers then never leave the circle, nothing is reported and there is
nothing to switch at.
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
                  stability: bool | str | StabilityOptions = False, window: int = 10) -> Branch:
    """Continue the branch born at ``bifurcation`` of ``branch`` (module docstring).

    Parameters
    ----------
    branch : Branch
        A forced response (:func:`~femodes.frequency_response`) or a nonlinear mode
        (:func:`~femodes.nonlinear_mode`) with its model, traced with ``stability=True``.
    bifurcation : Bifurcation
        One of ``branch.bifurcations``: ``kind == "period_doubling"`` (forced responses) or
        ``"branch_point"`` (both). A fold is no branch point (the
        continuation passes it and no other branch is born there) and Neimark-Sacker or
        nonsmooth points are not supported: ``NotImplementedError`` for those.
    omega : (float, float)
        Frequency span (rad/s) of the new branch; a branch point must lie inside it. Period
        doubling: traced from the bifurcation towards the end of the span on the side where the
        new branch exists. Branch point, forced response: traced away from the branch point
        until it leaves the span at either end (or comes back to the branch point: a closed
        branch). Branch point, nonlinear mode (a backbone; still a *frequency* span): the new
        branch (e.g. an internal-resonance tongue) is continued in energy, upwards or downwards
        as it leaves the branch point, until its frequency leaves this span, it comes back to
        the branch point, or its energy leaves the backbone's energy span widened by three
        decades each way.
    amplitude : float, optional
        Size of the first step along the new direction, in displacement coefficients (the
        Euclidean norm of the step of ``Q``; default 1e-2 of the orbit's largest coefficient at
        a period doubling, 2e-2 at a branch point). At a branch point its sign picks the side of
        the new branch (the two sides of a symmetry-breaking pitchfork are mirror images).
    options : ContinuationOptions, optional
        Continuation of the new branch (default :func:`~femodes.frequency_response_options`,
        resp. :func:`~femodes.analyses.nonlinear_mode_options`); ``options.newton`` also
        corrects the located points and the first point.
    stability : bool, str or StabilityOptions
        Stability of the new branch, as in :func:`~femodes.frequency_response` (needed to switch
        again from the new branch, e.g. back off a tongue).
    window : int
        Points of ``branch`` on each side of the bifurcation searched for the HBM's own
        bifurcation.

    Returns
    -------
    Branch
        Period doubling: on the doubled harmonics ``Harmonics(2H, subharmonic=2 nu)``. Branch
        point: on the harmonics of ``branch``, of the same kind, starting at the branch point
        (point 0; with ``stability`` it is ``bifurcations[0]``, from which ``switch_branch``
        leads back onto ``branch``). ``meta["switched_from"]`` says where it starts (the HBM's
        own bifurcation ``omega_hbm``, the reported ``omega_reported``, the segment ``index`` of
        ``branch``, and the singular values of the (scaled) matrix that show the singularity:
        ``smallest_singular_value`` ~0, ``second_singular_value`` not, for a simple branch point).

    Raises
    ------
    NotImplementedError
        Another kind of bifurcation; a period doubling of a nonlinear mode; a problem too
        large for the dense factorisation (:data:`DENSE_LIMIT`: reduce the model with
        :func:`~femodes.craig_bampton` or lower the harmonics).
    RuntimeError
        The HBM branch has no such bifurcation near the reported one (for a branch point: the
        connection of the two families is imperfect in the truncated HBM, not a branch point),
        or no point of the new branch was found at ``amplitude``.
    """
    if not isinstance(branch, Branch):
        raise TypeError(f"switch_branch: branch must be a femodes Branch, got {type(branch).__name__}")
    if not isinstance(bifurcation, Bifurcation):
        raise TypeError(f"switch_branch: bifurcation must be one of branch.bifurcations, got {type(bifurcation).__name__}")
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
