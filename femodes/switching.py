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

import dataclasses
import logging
import math
import numpy as np
import scipy.linalg as sla

from .analyses import branch_from_continuation, frequency_response, frequency_response_options, nonlinear_mode_options
from .hbm.harmonics import Harmonics
from .hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from .results import Bifurcation, Branch
from .floquet import (StabilityOptions, annotate_branch, augmented_jacobian, branch_point_test, refine_branch_point, root_on_secant,
                      solve_on_secant)
from .solvers import (ContinuationOptions, ContinuationResult, ContinuationState, NewtonOptions, continuation,
                      semismooth_newton)
from .solvers.threads import limit_blas_threads

__all__ = ["switch_branch", "DENSE_LIMIT"]

log = logging.getLogger(__name__)

#: Largest matrix (unknowns) factorised densely: the odd block of a period doubling, the augmented
#: Jacobian ``[r_x, r_p]`` (``n + 1`` columns) of a branch point.
DENSE_LIMIT = 4000

#: A located branch point is genuine when the smallest singular value of ``[r_x, r_p]`` there is
#: below this fraction of its value at the ends of the bracketing segment (a simple branch point:
#: it vanishes linearly and the regula falsi takes it down by many orders; a sign change of the
#: test function by a tangent turning between far-apart points leaves it of the same order).
GENUINE = 1e-3

#: A reported segment without a sign change of the test function is sampled at this many
#: sub-segments (two branch points within one segment change the sign twice).
SUBDIVIDE = 16



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


@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
def _same_bifurcation(a: Bifurcation, b: Bifurcation) -> bool:
    """``b`` is ``a``, or a copy of it (the same bifurcation of a branch loaded again from its file)."""
    if a is b:
        return True
    return (a.kind == b.kind and a.index == b.index and a.omega_truncated == b.omega_truncated
            and np.shape(a.Q) == np.shape(b.Q)
            and np.array_equal(a.Q, b.Q) and np.shape(a.P) == np.shape(b.P) and np.array_equal(a.P, b.P))


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
        return _switch_at_branch_point(branch, bifurcation, (a_span, b_span), amplitude, options, stability,
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
class _Augmented:
    """The HBM problem a branch was traced with, its points ``z = [x; p]`` and ``A = [r_x, r_p]``."""

    def __init__(self, branch: Branch):
        model, h = branch.model, branch.harmonics
        self.forced = branch.kind == "forced"
        if self.forced:
            self.problem = ForcedResponseProblem(model, h)
        else:
            mode, span = branch.meta.get("mode"), branch.meta.get("energy_span")
            if mode is None or span is None:
                raise ValueError("switch_branch: the nonlinear-mode branch does not say its mode and energy span "
                                 "(branch.meta['mode'], ['energy_span']); pass a branch from fm.nonlinear_mode")
            ref = float(branch.meta.get("reference_energy", math.sqrt(float(span[0]) * float(span[1]))))
            self.problem = NonlinearModeProblem(model, h, int(mode), reference_energy=ref)
        self.n = self.problem.size
        if self.n + 1 > DENSE_LIMIT:
            raise NotImplementedError(
                f"switch_branch: locating a branch point factorises the {self.n} x {self.n + 1} Jacobian densely "
                f"(limit {DENSE_LIMIT} unknowns); reduce the model with craig_bampton or lower the harmonics")
        self.branch = branch

    def z(self, i: int) -> np.ndarray:
        b = self.branch
        return np.append(self.problem.pack(b.Q[i], b.P[i], b.omega_truncated[i], b.xi[i]), b.parameter[i])

    def unpack(self, z: np.ndarray):
        return self.problem.unpack(z[:-1], z[-1])

    def matrix(self, z: np.ndarray) -> np.ndarray:
        """``A = [r_x, r_p]`` at ``z`` (dense, ``n x (n + 1)``)."""
        return augmented_jacobian(self.problem, z)

    def scales(self, z: np.ndarray, options: ContinuationOptions) -> tuple[np.ndarray, float | None]:
        """The continuation's arclength scales ``(x_scale, p_scale)`` for the new branch, as its
        analysis sets them: the RMS of the orbit and the frequency span's width (forced), the
        nonlinear mode's own scales and one decade of energy (backbone); ``options`` may set them."""
        x = z[:-1]
        if options.x_scale is not None:
            xs = np.broadcast_to(np.asarray(options.x_scale, dtype=float), x.shape).copy()
        elif self.forced:
            xs = np.full(self.n, float(np.sqrt(np.mean(x ** 2))) or 1.0)
        else:
            xs = self.problem.arclength_scale(x)
        return xs, None if options.p_scale is None else float(options.p_scale)

    def test(self, z: np.ndarray, c: np.ndarray) -> tuple[float, float]:
        """``(sign, log|det|)`` of ``[A(z); c^T]`` (:func:`~femodes.floquet.branch_point_test`)."""
        return branch_point_test(self.problem, z, c)


def _smallest_sv(aug: _Augmented, z: np.ndarray, D: np.ndarray) -> float:
    return float(sla.svd(aug.matrix(z) * D[None, :], compute_uv=False)[-1])


def _sign_changes(aug: _Augmented, Z: dict, segments) -> list[int]:
    """The segments ``(i, i + 1)`` over which ``det [A; c^T]`` (``c`` their secant) changes sign."""
    out = []
    for i in segments:
        c = Z[i + 1] - Z[i]
        c = c / (np.linalg.norm(c) or 1.0)
        (s0, _), (s1, _) = aug.test(Z[i], c), aug.test(Z[i + 1], c)
        if s0 == 0 or s1 == 0 or s0 != s1:
            out.append(i)
    return out


def _refine(aug: _Augmented, za: np.ndarray, zb: np.ndarray, newton: NewtonOptions) -> np.ndarray:
    """The branch point between ``za`` and ``zb`` (:func:`~femodes.floquet.refine_branch_point`;
    the caller found the sign change)."""
    z = refine_branch_point(aug.problem, za, zb, newton)
    return za if z is None else z


def _locate_branch_point(aug: _Augmented, bif: Bifurcation, newton: NewtonOptions, window: int, D: np.ndarray):
    """The HBM branch's own branch point nearest to ``bif``: ``(z_bp, i, za, zb)`` with ``[za, zb]``
    the segment of the branch that brackets it.

    A reported point that is itself a branch point of the HBM problem (the start of a branch
    :func:`switch_branch` traced, where the test function is zero at a point of the branch) is
    taken as it is."""
    branch = aug.branch
    lo, hi = max(0, bif.index - window), min(len(branch) - 1, bif.index + 1 + window)
    Z = {i: aug.z(i) for i in range(lo, hi + 1)}
    changes = _sign_changes(aug, Z, range(lo, hi))
    if changes:
        i = min(changes, key=lambda j: abs(j - bif.index))
        return _refine(aug, Z[i], Z[i + 1], newton), i, Z[i], Z[i + 1]
    i = min(max(bif.index, lo), hi - 1)
    # two branch points within one segment (the narrow instability interval of a tongue between
    # them) change the sign twice: sample the reported segment finer
    S = {0: Z[i]}
    for k, theta in enumerate(np.linspace(0.0, 1.0, SUBDIVIDE + 1)[1:-1], start=1):
        z = solve_on_secant(aug.problem, Z[i], Z[i + 1], float(theta), newton)
        if z is None:
            break
        S[k] = z
    else:
        S[SUBDIVIDE] = Z[i + 1]
        sub = _sign_changes(aug, S, range(SUBDIVIDE))
        if sub:
            k = sub[0]
            return _refine(aug, S[k], S[k + 1], newton), i, S[k], S[k + 1]
    z_rep = np.append(aug.problem.pack(bif.Q, bif.P, bif.omega_truncated, bif.xi), bif.parameter)
    r = aug.problem.residual(z_rep[:-1], z_rep[-1])[0]
    if (float(np.max(np.abs(r))) <= 1e3 * newton.atol
            and _smallest_sv(aug, z_rep, D) <= GENUINE * max(_smallest_sv(aug, Z[i], D), _smallest_sv(aug, Z[i + 1], D))):
        return z_rep, i, Z[i], Z[i + 1]
    what = "backbone" if not aug.forced else "branch"
    raise RuntimeError(
        f"switch_branch: the HBM {what} has no branch point between w = {branch.omega_truncated[lo]:.6g} and "
        f"{branch.omega_truncated[hi]:.6g} (H = {branch.harmonics.n_harmonics}) near the reported one at "
        f"w = {bif.omega:.6g}: det [r_x, r_p; t^T] keeps its sign there, so the multiplier +1 is not a crossing of "
        "two branches but an imperfect (smooth) connection in the truncated HBM; the branch itself continues "
        "onto the other family: follow it with the continuation instead")


def _null_directions(aug: _Augmented, z_bp: np.ndarray, za: np.ndarray, zb: np.ndarray, D: np.ndarray):
    """Check the branch point is genuine; the new direction ``phi`` (the null vector of ``[r_x, r_p]``
    orthogonal to the branch in the metric ``sum (v_i / D_i)^2``, unit in it) and the singular
    values of the scaled matrix there."""
    ends = max(sla.svd(aug.matrix(z) * D[None, :], compute_uv=False)[-1] for z in (za, zb))
    _, s, Vt = sla.svd(aug.matrix(z_bp) * D[None, :])
    if not s[-1] <= GENUINE * ends:
        u = aug.unpack(z_bp)
        raise RuntimeError(
            f"switch_branch: the test function changes sign at w = {u.omega:.8g} but [r_x, r_p] keeps full rank there "
            f"(smallest singular value {s[-1]:.3g}, {ends:.3g} at the bracket's ends): not a genuine branch point of the "
            "HBM branch (an imperfect connection, or points too far apart: trace the branch with a smaller max_step)")
    N = Vt[-2:].T  # the two-dimensional null space, scaled unknowns
    a = N.T @ ((zb - za) / D)  # the old branch's direction in it
    coef = np.array([-a[1], a[0]]) / (np.linalg.norm(a) or 1.0)
    return D * (N @ coef), s


def _switch_at_branch_point(branch: Branch, bif: Bifurcation, span: tuple[float, float], amplitude, options,
                            stability, window: int) -> Branch:
    stab = StabilityOptions.parse(stability, "switch_branch")  # a bad value is refused before the work
    aug = _Augmented(branch)
    w_lo, w_hi = min(span), max(span)
    if not w_lo < bif.omega_truncated < w_hi:
        raise ValueError(f"switch_branch: omega = {span!r} must contain the branch point of the truncated series at w = {bif.omega_truncated:.6g}")
    z_rep = np.append(aug.problem.pack(bif.Q, bif.P, bif.omega_truncated, bif.xi), bif.parameter)
    if aug.forced:
        options = options or frequency_response_options()
    else:
        options = nonlinear_mode_options(aug.problem, z_rep[:-1], options)
    newton = options.newton
    xs, ps = aug.scales(z_rep, options)
    if ps is None:
        ps = w_hi - w_lo if aug.forced else 1.0  # frequency_response: the span; backbone: a decade
    # the continuation's norm (1/n) sum (dx_i / xs_i)^2 + (dp / ps)^2, written as sum (dz_i / D_i)^2
    D = np.append(math.sqrt(aug.n) * xs, ps)
    z_bp, i, za, zb = _locate_branch_point(aug, bif, newton, window, D)
    phi, svals = _null_directions(aug, z_bp, za, zb, D)
    u_bp = aug.unpack(z_bp)
    nq = float(np.linalg.norm(aug.unpack(phi).Q))
    if nq == 0.0:
        raise RuntimeError("switch_branch: the new direction at the branch point moves no displacement coefficient")
    a = 2e-2 * (float(np.max(np.abs(u_bp.Q))) or 1.0) if amplitude is None else float(amplitude)
    if not math.isfinite(a) or a == 0.0:
        raise ValueError(f"switch_branch: amplitude must be a non-zero finite number, got {amplitude!r}")
    step = a / nq
    if step < 0:
        phi, step = -phi, -step
    g = phi / D ** 2  # <phi, v> in the metric is g . v, and g . phi = 1
    z1 = _keller_point(aug.problem, z_bp, phi, g, step, newton)
    if z1 is None:
        raise RuntimeError(f"switch_branch: no point of the new branch found at amplitude {a:g} from the branch point "
                           f"at w = {u_bp.omega:.8g}; pass a smaller amplitude=")
    log.info("switch_branch: HBM branch point at w = %.8g (reported %.8g); new branch from w = %.8g",
             u_bp.omega, bif.omega, aug.unpack(z1).omega)
    if aug.forced:
        p_span = (w_lo, w_hi)
        meta = {"span": [w_lo, w_hi]}
    else:
        e0, e1 = (float(v) for v in branch.meta["energy_span"])
        p_span = (min(math.log10(e0) - 3.0, z1[-1] - 1.0), max(math.log10(e1) + 3.0, z1[-1] + 1.0))
        meta = {"mode": int(branch.meta["mode"]), "reference_energy": float(aug.problem.reference_energy)}
    res = _trace(aug, z_bp, z1, phi, D, xs, ps, p_span, (w_lo, w_hi), options)
    if not aug.forced:
        E = 10.0 ** np.asarray(res.p, dtype=float)
        meta["energy_span"] = [float(E.min()), float(E.max())]
    new = branch_from_continuation(aug.problem, res, kind=branch.kind, model=branch.model, meta=meta)
    if not new.success:
        log.warning("switch_branch: %s", new.message)
    if stab is not None:
        annotate_branch(new, aug.problem, branch.model, method=stab.method, tol=stab.tol, newton=newton,
                        locate=stab.locate)
        _add_branch_points(new, newton)
    new.meta["switched_from"] = {
        "kind": "branch_point", "reported_kind": bif.kind, "omega_hbm": float(u_bp.omega), "omega_reported": float(bif.omega), "index": int(i),
        "parameter_hbm": float(z_bp[-1]), "smallest_singular_value": float(svals[-1] / svals[0]),
        "second_singular_value": float(svals[-2] / svals[0])}
    return new


def _add_branch_points(new: Branch, newton: NewtonOptions) -> None:
    """Add the branch points of a switched branch to its bifurcations: the one it starts at (point
    0) and those the test function finds along it. Floquet multipliers miss them: along the side
    branch of a pitchfork the critical multiplier touches +1 without crossing."""
    aug = _Augmented(new)
    system = aug.problem.system

    def at(z: np.ndarray, index: int) -> Bifurcation:
        u = aug.unpack(z)
        return Bifurcation(kind="branch_point", index=index, omega=float(u.omega),
                           energy=float(system.energy(u.y, u.omega)[0]), parameter=float(z[-1]),
                           multiplier=complex(1.0), Q=np.array(u.Q), P=np.array(u.P), xi=float(u.xi))

    Z = {i: aug.z(i) for i in range(len(new))}
    found = [at(Z[0], 0)]
    for i in _sign_changes(aug, Z, range(1, len(new) - 1)):
        found.append(at(_refine(aug, Z[i], Z[i + 1], newton), i))
    mine = {b.index for b in found}
    others = [b for b in new.bifurcations
              if not (b.kind == "branch_point" and any(abs(b.index - j) <= 1 for j in mine))]
    bifs = sorted(found + others, key=lambda b: (b.index, b.parameter))
    new.set_stability(stable=new.stable, multipliers=new.multipliers, bifurcations=bifs,
                      methods=new.stability_method, tol=float(new.meta["stability_tol"]))


def _keller_point(problem, z_bp: np.ndarray, phi: np.ndarray, g: np.ndarray, step: float, newton: NewtonOptions):
    """``r(z) = 0`` with ``g . (z - z_bp) = step``, from ``z_bp + step phi`` (``g . phi = 1``)."""
    n = z_bp.size - 1

    def fun(z):
        r, J, dr_dp = problem.residual(z[:n], z[n])
        return (np.append(r, g @ (z - z_bp) - step),
                J.bordered(np.asarray(dr_dp)[:, None], g[None, :n], np.array([[g[n]]])))

    res = semismooth_newton(fun, z_bp + step * phi, options=newton)
    return res.x if res.success else None


def _trace(aug: _Augmented, z_bp: np.ndarray, z1: np.ndarray, phi: np.ndarray, D: np.ndarray, xs: np.ndarray,
           ps: float, p_span: tuple[float, float], w_span: tuple[float, float],
           options: ContinuationOptions) -> ContinuationResult:
    """The new branch: ``z_bp``, ``z1`` and its continuation away from the branch point, resumed
    from a state at ``z1`` whose tangent points along ``phi``, over the whole ``p_span``. It ends
    where it leaves ``p_span`` at either end, where its frequency leaves ``w_span`` (nonlinear
    modes, traced in energy), or where it comes back to ``z_bp`` (a closed branch, e.g. the
    isola of symmetry-breaking orbits of a pitchfork)."""
    n = aug.n
    A = aug.matrix(z1)
    # tangent at z1: [r_x, r_p] t = 0, oriented along phi (<t, phi> > 0 in the metric), unit in it
    t = np.linalg.solve(np.vstack([A, (phi / D ** 2)[None, :]]), np.append(np.zeros(n), 1.0))
    t = t / math.sqrt(float(np.sum((t / D) ** 2)))
    user = options.callback
    prev = [z1]

    def callback(point):
        if user is not None and user(point) is False:
            return False
        z = np.append(point.x, point.p)
        d, e = (z - prev[0]) / D, (z_bp - prev[0]) / D
        prev[0] = z
        lam = min(max(float(d @ e) / max(float(d @ d), 1e-300), 0.0), 1.0)
        if point.index >= 2 and np.linalg.norm(e - lam * d) <= 0.05 * np.linalg.norm(d):
            log.info("switch_branch: the new branch is closed (back at the branch point after %d points)", point.index)
            return False
        if not aug.forced and not w_span[0] <= aug.problem.unpack(point.x, point.p).omega <= w_span[1]:
            return False
        return None

    options = dataclasses.replace(options, callback=callback)
    state = ContinuationState(x=z1[:-1], p=float(z1[-1]), tangent=t, step=float(options.step), index=0, folds=(),
                              dp_sign=1.0 if t[-1] >= 0 else -1.0, x_scale=xs, p_scale=ps)
    res = continuation(aug.problem, p_span, options=options, start=state)
    # prepend the branch point and z1; the result counted z1 as point 0 already (folds, indices)
    rn = [float(np.max(np.abs(aug.problem.residual(z[:-1], z[-1])[0]))) for z in (z_bp, z1)]
    tangents = None if res.tangents is None else np.vstack([phi[None, :] / math.sqrt(float(np.sum((phi / D) ** 2))),
                                                            t[None, :], res.tangents])
    return dataclasses.replace(
        res, x=np.vstack([z_bp[None, :-1], z1[None, :-1], res.x]), p=np.concatenate([[z_bp[-1], z1[-1]], res.p]),
        nit=np.concatenate([[0, 0], res.nit]), residual_norm=np.concatenate([rn, res.residual_norm]),
        step=np.concatenate([[0.0, float(np.sqrt(np.sum(((z1 - z_bp) / D) ** 2)))], res.step]),
        folds=tuple(f + 1 for f in res.folds), tangents=tangents, first_index=0)


# ------------------------------------------------------------------------------------------------
# Period doubling: the first point
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
