"""Analyses layer: switching at a branch point (a multiplier +1 where two branches cross): the
test function ``det [r_x, r_p; t^T]`` along the branch, the point located where it changes sign and
checked by the smallest singular value of ``[r_x, r_p]``, the null directions, and the new branch
traced from a Keller point (:func:`switch_at_branch_point`, called by
:func:`femodes.switch_branch`, whose module docstring describes the method)."""

from __future__ import annotations

import dataclasses
import logging
import math
import numpy as np
import scipy.linalg as sla

from .analyses import branch_from_continuation, frequency_response_options, nonlinear_mode_options
from .hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from .results import Bifurcation, Branch
from .floquet import (StabilityOptions, annotate_branch, augmented_jacobian, branch_point_test, refine_branch_point, solve_on_secant)
from .solvers import (ContinuationOptions, ContinuationResult, ContinuationState, NewtonOptions, continuation,
                      semismooth_newton)

__all__ = ["switch_at_branch_point", "Augmented", "DENSE_LIMIT", "GENUINE", "SUBDIVIDE"]

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


class Augmented:
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


def _smallest_sv(aug: Augmented, z: np.ndarray, D: np.ndarray) -> float:
    return float(sla.svd(aug.matrix(z) * D[None, :], compute_uv=False)[-1])


def _sign_changes(aug: Augmented, Z: dict, segments) -> list[int]:
    """The segments ``(i, i + 1)`` over which ``det [A; c^T]`` (``c`` their secant) changes sign."""
    out = []
    for i in segments:
        c = Z[i + 1] - Z[i]
        c = c / (np.linalg.norm(c) or 1.0)
        (s0, _), (s1, _) = aug.test(Z[i], c), aug.test(Z[i + 1], c)
        if s0 == 0 or s1 == 0 or s0 != s1:
            out.append(i)
    return out


def _refine(aug: Augmented, za: np.ndarray, zb: np.ndarray, newton: NewtonOptions) -> np.ndarray:
    """The branch point between ``za`` and ``zb`` (:func:`~femodes.floquet.refine_branch_point`;
    the caller found the sign change)."""
    z = refine_branch_point(aug.problem, za, zb, newton)
    return za if z is None else z


def _locate_branch_point(aug: Augmented, bif: Bifurcation, newton: NewtonOptions, window: int, D: np.ndarray):
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


def _null_directions(aug: Augmented, z_bp: np.ndarray, za: np.ndarray, zb: np.ndarray, D: np.ndarray):
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


def switch_at_branch_point(branch: Branch, bif: Bifurcation, span: tuple[float, float], amplitude, options,
                            stability, window: int) -> Branch:
    stab = StabilityOptions.parse(stability)  # a bad value is refused before the work
    aug = Augmented(branch)
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
        new = annotate_branch(new, aug.problem, branch.model, method=stab.method, tol=stab.tol, newton=newton,
                              locate=stab.locate, check=stab.check)
        new = _with_branch_points(new, newton)
    new.meta["switched_from"] = {
        "kind": "branch_point", "reported_kind": bif.kind, "omega_hbm": float(u_bp.omega), "omega_reported": float(bif.omega), "index": int(i),
        "parameter_hbm": float(z_bp[-1]), "smallest_singular_value": float(svals[-1] / svals[0]),
        "second_singular_value": float(svals[-2] / svals[0])}
    return new


def _with_branch_points(new: Branch, newton: NewtonOptions) -> Branch:
    """A switched branch with its branch points added to its bifurcations: the one it starts at (point
    0) and those the test function finds along it. Floquet multipliers miss them: along the side
    branch of a pitchfork the critical multiplier touches +1 without crossing."""
    aug = Augmented(new)
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
    return new.with_stability(stable=new.stable, multipliers=new.multipliers, bifurcations=bifs,
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


def _trace(aug: Augmented, z_bp: np.ndarray, z1: np.ndarray, phi: np.ndarray, D: np.ndarray, xs: np.ndarray,
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
