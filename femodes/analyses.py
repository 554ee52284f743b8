"""Analyses layer: wire a model into an HBM problem, run the continuation, wrap the result.

The one module that sees both the problems (``femodes.hbm``) and the generic solvers
(``femodes.solvers``).

Long runs: ``checkpoint=path`` writes every converged point to a journal ``<path>.points/`` as it
is found (one small file per point, written atomically, see :class:`~femodes.results.Checkpoint`)
and the finished branch to ``path``; ``resume=True`` continues a killed run from its last saved
point (``continuation(start=...)``), so that the final branch holds every point exactly once and
equals the branch of an uninterrupted run.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
import time
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from .hbm.harmonics import Harmonics
from .hbm.problems import ForcedResponseProblem, NonlinearModeProblem
from .hbm.system import default_contact_parameter
from .laws import PenaltyContact, UnilateralContact
from .model import StructuralModel
from .results import Branch, Checkpoint, ContactInfo, load_branch
from .solvers import ContinuationOptions, NewtonOptions, continuation, semismooth_newton
from .solvers.continuation import ContinuationResult, ContinuationState

__all__ = ["frequency_response", "nonlinear_mode", "nonlinear_mode_options", "static_contact", "StaticContactResult",
           "branch_from_continuation", "model_fingerprint"]

log = logging.getLogger(__name__)


def _harmonics(h: Any, owner: str) -> Harmonics:
    if isinstance(h, Harmonics):
        return h
    if isinstance(h, (int, np.integer)) and not isinstance(h, bool):
        return Harmonics(int(h))
    raise TypeError(f"{owner}: harmonics must be a femodes.Harmonics (or an int number of harmonics), got {h!r}")


def _span(value: Any, name: str, owner: str, *, positive: bool) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{owner}: {name} must be a pair (start, end) of numbers, got {value!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)) or a == b or (positive and (a <= 0 or b <= 0)):
        raise ValueError(f"{owner}: {name} must be two distinct finite{' positive' if positive else ''} numbers, got {value!r}")
    if not math.isfinite((b - a) ** 2) or (b - a) ** 2 == 0.0 or (positive and not 1e-150 < min(a, b) <= max(a, b) < 1e150):
        raise ValueError(f"{owner}: {name} = {value!r} is out of the representable range (its width squared under- or "
                         "overflows); rescale the units")
    return a, b


def _options(options: Any, owner: str) -> ContinuationOptions | None:
    if options is not None and not isinstance(options, ContinuationOptions):
        raise TypeError(f"{owner}: options must be a femodes.ContinuationOptions or None, got {type(options).__name__}")
    return options


def _check_model(model: Any, owner: str) -> StructuralModel:
    if not isinstance(model, StructuralModel):
        raise TypeError(f"{owner}: model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
    return model


def branch_from_continuation(problem, result, *, kind: str, model: StructuralModel, meta: dict | None = None) -> Branch:
    """Wrap a :class:`~femodes.solvers.ContinuationResult` of an HBM problem into a Branch."""
    s = problem.system
    n_pts = result.x.shape[0]
    omega = np.empty(n_pts)
    Q = np.empty((n_pts, s.h.n_coef, s.n))
    P = np.empty((n_pts, s.h.n_coef, s.n_uc))
    energy = np.empty(n_pts)
    xi = np.empty(n_pts)
    for i in range(n_pts):
        d = problem.unpack(result.x[i], result.p[i])
        omega[i], Q[i], P[i], xi[i] = d["omega"], d["Q"], d["P"], d["xi"]
        energy[i] = s.energy(result.x[i][: s.size], omega[i])[0]
    return Branch(
        kind=kind, harmonics=s.h, contacts=ContactInfo.from_system(s), omega=omega, Q=Q, P=P, energy=energy, xi=xi,
        residual_norm=result.residual_norm, nit=result.nit, parameter=result.p, folds=result.folds,
        success=result.success, status=result.status, message=result.message, model=model, meta=meta,
    )


def _run(problem, span, x0, options: ContinuationOptions, label: str, progress: bool, *,
         start: ContinuationState | None = None, journal: Callable | None = None):
    """Continuation with the journal writer and the progress callback chained in front of the
    user's callback; warns on failure."""
    cb = _progress_callback(options.callback, span, label, progress)
    if journal is not None:
        after = cb

        def cb(point):
            journal(point)  # saved before the user's callback can stop the run
            return after(point) if after is not None else None

    if cb is not None:
        options = dataclasses.replace(options, callback=cb)
    res = continuation(problem, span, x0=x0, options=options, start=start)
    if not res.success:
        log.warning("%s: %s", label, res.message)
    return res


# ------------------------------------------------------------------------------------------------
# checkpoints: what a run is (to refuse resuming a different one) and what a point stores
# ------------------------------------------------------------------------------------------------
def _digest(*parts: bytes) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(len(part).to_bytes(8, "little"))
        h.update(part)
    return h.hexdigest()[:20]


def _matrix_bytes(A) -> list[bytes]:
    A = sp.csr_matrix(A, dtype=float, copy=True)
    A.sum_duplicates()
    A.sort_indices()
    return [np.asarray(A.shape, dtype=np.int64).tobytes(), A.indptr.astype(np.int64).tobytes(),
            A.indices.astype(np.int64).tobytes(), A.data.tobytes()]


def _declarations(items) -> bytes:
    """Canonical bytes of attached laws (type, DOF and parameters; ``at`` is the DOF)."""
    out = []
    for a in items:
        law = a.item
        params = {f.name: repr(getattr(law, f.name)) for f in dataclasses.fields(law) if f.name != "at"} \
            if dataclasses.is_dataclass(law) else {"repr": repr(law)}
        out.append([type(law).__name__, int(a.dof), params])
    return json.dumps(out, sort_keys=True).encode()


def model_fingerprint(model: StructuralModel) -> dict:
    """Short hashes of what defines a model's equations: matrices, forcing, contacts, nonlinearities.

    Stored in checkpoints (and their final branch files) so that resuming with another model is
    refused with a message saying which part differs.
    """
    forces = model.force_vectors()
    force_bytes = [np.int64(k).tobytes() + np.asarray(forces[k], dtype=complex).tobytes() for k in sorted(forces)]
    return {
        "n_dofs": int(model.n_dofs),
        "matrices": _digest(*_matrix_bytes(model.M), *_matrix_bytes(model.K), *_matrix_bytes(model.C)),
        "forcing": _digest(*force_bytes),
        "contacts": _digest(_declarations(model.contacts)),
        "nonlinearities": _digest(_declarations(model.nonlinearities)),
    }


def _differences(saved: Any, current: Any, prefix: str = "") -> list[str]:
    if isinstance(saved, dict) and isinstance(current, dict):
        out = []
        for key in sorted(set(saved) | set(current), key=str):
            out += _differences(saved.get(key, "<absent>"), current.get(key, "<absent>"), f"{prefix}{key}.")
        return out
    if saved != current:
        return [f"{prefix[:-1]}: {saved!r} in the checkpoint, {current!r} in this call"]
    return []


def _check_same_run(saved: dict, current: dict, where, label: str) -> None:
    diff = _differences(saved, current)
    if diff:
        raise ValueError(f"{label}: checkpoint {str(where)!r} was written by a different run ({'; '.join(diff)}); "
                         "resume it with the same arguments, or use another checkpoint file")


#: Members of every point file; resumable points (ContinuationPoint.state not None) add _STATE_KEYS.
_POINT_KEYS = ("x", "p", "nit", "residual_norm", "step", "is_fold")
_STATE_KEYS = ("tangent", "next_step", "folds", "dp_sign", "p_scale", "n_newton", "n_rejected")


def _point_record(point) -> dict:
    """What the journal stores per point: the unknowns, and the continuation state to resume from."""
    rec = {"x": point.x, "p": point.p, "nit": point.nit, "residual_norm": point.residual_norm,
           "step": point.step, "is_fold": point.is_fold}
    st = point.state
    if st is not None:
        rec.update(tangent=st.tangent, next_step=st.step, folds=np.asarray(st.folds, dtype=np.int64),
                   dp_sign=st.dp_sign, p_scale=st.p_scale, n_newton=st.n_newton, n_rejected=st.n_rejected)
        if st.index == 0:
            rec["x_scale"] = st.x_scale  # the scales are fixed for a run: stored once
    return rec


def _state_from_records(records: list[dict], ck: Checkpoint) -> ContinuationState:
    k = len(records) - 1
    r = records[k]
    try:
        if "x_scale" not in records[0]:
            raise ValueError("missing x_scale")
        return ContinuationState(
            x=r["x"], p=float(r["p"]), tangent=r["tangent"], step=float(r["next_step"]), index=k,
            folds=tuple(int(i) for i in np.atleast_1d(r["folds"])), dp_sign=float(r["dp_sign"]),
            x_scale=records[0]["x_scale"], p_scale=float(r["p_scale"]), n_newton=int(r["n_newton"]),
            n_rejected=int(r["n_rejected"]),
        )
    except (ValueError, TypeError) as exc:
        bad = ck.point_path(0 if "x_scale" in str(exc) else k)
        raise ValueError(f"checkpoint: point file {str(bad)!r} is damaged ({exc})") from exc


def _merge(records: list[dict], res: ContinuationResult) -> ContinuationResult:
    """Saved points followed by the points of the resumed run (whose folds cover the whole branch)."""
    def stack(key, new, dtype):
        old = np.array([r[key] for r in records], dtype=dtype)
        return np.concatenate([old.reshape((len(records),) + new.shape[1:]), new])

    return dataclasses.replace(
        res, x=stack("x", res.x, float), p=stack("p", res.p, float), nit=stack("nit", res.nit, int),
        residual_norm=stack("residual_norm", res.residual_norm, float), step=stack("step", res.step, float),
        converged=np.ones(len(records) + res.p.size, dtype=bool), tangents=None, first_index=0,
    )


def _checkpointed(problem, span, options: ContinuationOptions, label: str, progress: bool, *, x0: Callable,
                  wrap: Callable, model: StructuralModel, checkpoint, resume: bool, description: dict) -> Branch:
    """Run (or resume, or return the finished) continuation of ``problem``; ``wrap(res, meta)`` -> Branch."""
    if not isinstance(resume, bool):
        raise TypeError(f"{label}: resume must be True or False, got {resume!r}")
    if checkpoint is None:
        if resume:
            raise ValueError(f"{label}: resume=True needs checkpoint=<file> (the checkpoint of the run to resume)")
        return wrap(_run(problem, span, x0(), options, label, progress), {})
    if not isinstance(checkpoint, (str, os.PathLike)):
        raise TypeError(f"{label}: checkpoint must be a file name (.npz or .h5), got {checkpoint!r}")
    ck = Checkpoint(checkpoint)
    desc = json.loads(json.dumps(description))  # as it reads back from the JSON header
    if not resume and (ck.path.exists() or ck.journal.exists()):
        raise FileExistsError(f"{label}: checkpoint {str(ck.path)!r} (or its journal {ck.journal.name}/) exists; "
                              "pass resume=True to continue (or return) that run, or delete it to start over")
    if ck.path.exists():
        branch = load_branch(ck.path)
        saved = branch.meta.get("checkpoint")
        if not isinstance(saved, dict):
            raise ValueError(f"{label}: {str(ck.path)!r} is a branch file but not the result of a checkpointed run; "
                             "choose another checkpoint file name")
        _check_same_run(saved, desc, ck.path, label)
        branch.attach(model)
        ck.remove_journal()  # left over if the run was killed while removing it
        log.info("%s: the checkpointed run %s is finished; returning its branch", label, ck.path)
        return branch

    records: list[dict] = []
    if ck.journal.exists() and (ck.header_path.exists() or ck.indices()):
        _check_same_run(ck.read_header(), desc, ck.journal, label)
        records = ck.read_points(required=_POINT_KEYS)
        n = problem.size
        for i, r in enumerate(records):
            if r["x"].shape != (n,) or (("tangent" in r) and r["tangent"].shape != (n + 1,)):
                raise ValueError(f"checkpoint: point file {str(ck.point_path(i))!r} holds {r['x'].shape} unknowns, "
                                 f"this problem has {n}")
        # continue from the last point the run can continue from exactly; the points after it
        # (an inserted fold point, an end point) are computed again
        while records and "tangent" not in records[-1]:
            records.pop()
        ck.discard(after=len(records) - 1)
    else:
        ck.create(desc)

    def journal(point):
        ck.write_point(point.index, _point_record(point))

    if records:
        start = _state_from_records(records, ck)
        log.info("%s: resuming %s from point %d at p = %.8g", label, ck.journal, start.index, start.p)
        res = _merge(records, _run(problem, span, None, options, label, progress, start=start, journal=journal))
    else:
        res = _run(problem, span, x0(), options, label, progress, journal=journal)
    branch = wrap(res, {"checkpoint": desc})
    ck.finish(branch)
    return branch


def _progress_callback(user_cb: Callable | None, span, label: str, progress: bool):
    if not progress and user_cb is None:
        return None
    t0 = time.perf_counter()
    state = {"n": 0}

    def cb(point):
        state["n"] += 1
        if progress:
            frac = (point.p - span[0]) / (span[1] - span[0])
            log.info("%s: point %d, p = %.6g (%.0f%% of span), %d Newton iterations, %.1f s",
                     label, state["n"], point.p, 100 * frac, point.nit, time.perf_counter() - t0)
        if user_cb is not None:
            return user_cb(point)
        return None

    return cb


def frequency_response(
    model: StructuralModel,
    omega: tuple[float, float],
    harmonics: Harmonics | int,
    *,
    options: ContinuationOptions | None = None,
    x0: np.ndarray | None = None,
    exact_contact: bool = True,
    progress: bool = False,
    checkpoint: str | os.PathLike | None = None,
    resume: bool = False,
) -> Branch:
    """Forced frequency-response curve by HBM and pseudo-arclength continuation.

    ``M q'' + C q' + K q + f_nl(q) = f cos(w t) - w_c p`` for ``w`` from ``omega[0]`` to
    ``omega[1]`` (rad/s), through folds.

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        With forcing; contacts and nonlinear springs as declared.
    omega : (float, float)
        Start and end frequencies (rad/s); the branch may run downwards.
    harmonics : Harmonics or int
    options : ContinuationOptions, optional
        Step control, Newton options, callback.
    x0 : ndarray, optional
        Initial guess at ``omega[0]`` (default: the linear response).
    exact_contact : bool
        Exact Galerkin projection of the contact law (default; ``False`` only for comparison).
    progress : bool
        Log progress at INFO level (the command line shows it as a progress bar).
    checkpoint : str or PathLike, optional
        Final branch file (``.npz`` or ``.h5``).  Every converged point is written to the journal
        ``<checkpoint>.points/`` as it is found (one file per point, atomic, O(1) I/O per point);
        at the end the branch is saved to ``checkpoint`` and the journal removed.  Without
        ``resume`` an existing checkpoint is an error (``FileExistsError``), never overwritten.
    resume : bool
        With ``checkpoint``: continue the run from its last saved point, or return its branch if
        it finished (any status); start a new run if there is no checkpoint yet.  The final
        branch holds every point exactly once and equals that of an uninterrupted run.  The
        checkpoint must come from the same model, harmonics, span and ``exact_contact``
        (``ValueError`` saying what differs otherwise); ``options`` may change (step bounds,
        ``max_points``...), the arclength scaling of the run is kept.  Damaged files or another
        format version give a ``ValueError`` naming the file.

    Returns
    -------
    Branch
        ``success`` False (with ``message``) if the continuation could not finish the span.
    """
    model = _check_model(model, "frequency_response")
    h = _harmonics(harmonics, "frequency_response")
    _options(options, "frequency_response")
    span = _span(omega, "omega", "frequency_response", positive=True)
    problem = ForcedResponseProblem(model, h, exact_contact=exact_contact)
    opts = options or ContinuationOptions(step=0.05, max_step=0.5, newton=NewtonOptions(atol=1e-9, max_iter=20))

    def start() -> np.ndarray:
        if x0 is not None:
            return x0
        with np.errstate(all="ignore"):
            xs = _starting_point(problem, span[0], opts.newton)
        if not np.all(np.isfinite(xs)):
            raise ValueError(f"frequency_response: the response at omega = {span[0]:g} is not finite in floating point: "
                             "the forcing amplitude (HarmonicForce amplitude) is too large for these units; rescale them")
        return xs

    def wrap(res, meta) -> Branch:
        return branch_from_continuation(problem, res, kind="forced", model=model, meta={"span": list(span), **meta})

    description = {"analysis": "frequency_response", "omega": list(span), "harmonics": _harmonics_key(h),
                   "exact_contact": bool(exact_contact), "n_unknowns": int(problem.size),
                   "model": model_fingerprint(model)} if checkpoint is not None else {}
    return _checkpointed(problem, span, opts, "frequency_response", progress, x0=start, wrap=wrap, model=model,
                         checkpoint=checkpoint, resume=resume, description=description)


def _harmonics_key(h: Harmonics) -> list:
    return [int(h.n_harmonics), None if h.n_time is None else int(h.n_time), int(h.subharmonic)]


class _ForcingHomotopy:
    """``r(x; lam) = r(x, w0) + (1 - lam) F``: the forced problem with the forcing scaled by ``lam``."""

    def __init__(self, problem: ForcedResponseProblem, omega: float):
        self.problem, self.omega = problem, float(omega)
        s = problem.system
        self.f = np.zeros(s.size)
        self.f[: s.nq] = s.force() / problem.force_scale

    def residual(self, x, lam):
        r, J, _ = self.problem.residual(x, self.omega)
        return r + (1.0 - lam) * self.f, J, -self.f


def _starting_point(problem: ForcedResponseProblem, omega: float, newton: NewtonOptions) -> np.ndarray:
    """Converged start at ``omega``: Newton from the linear response, else a forcing homotopy.

    Near superharmonic resonances the linear guess can be outside Newton's basin (forced Duffing
    at w = 0.5, H = 5); growing the forcing from 1 % by continuation from the linear solution
    (nonlinear terms negligible at small amplitude) reaches the solution.
    """
    x0 = problem.linear_guess(omega)
    res = semismooth_newton(lambda x: problem.residual(x, omega)[:2], x0, options=newton)
    if res.success:
        return res.x
    log.info("frequency_response: Newton from the linear guess failed at w = %g (%s); forcing homotopy", omega, res.message)
    hom = _ForcingHomotopy(problem, omega)
    lam0 = 0.01
    linear = problem.linear_guess(omega)
    start = linear * lam0
    # arclength scale of the full-forcing response: with the default (the size of the 1 % start)
    # the unknowns grow 100x over the homotopy and the steps in lam shrink accordingly (measured:
    # 522 points and 44 s on a 1e4-DOF bar against a stop, 14 points and 4 s with this scale)
    scale = float(np.sqrt(np.mean(linear ** 2))) or 1.0
    out = continuation(hom, (lam0, 1.0), x0=start,
                       options=ContinuationOptions(step=0.05, max_step=0.2, newton=newton, x_scale=scale))
    if out.success and out.status == 0:
        return out.x[-1]
    log.warning("frequency_response: forcing homotopy at w = %g failed (%s)", omega, out.message)
    return x0


def nonlinear_mode_options(problem: NonlinearModeProblem, x0: np.ndarray,
                           options: ContinuationOptions | None = None) -> ContinuationOptions:
    """Continuation options for a nonlinear mode starting at ``x0`` (used by :func:`nonlinear_mode`).

    Arclength scaling: displacement coefficients by the starting amplitude, contact forces by the
    force that amplitude produces through the contact stiffness, ``w`` by ``w0``, ``xi`` by
    ``0.1 w0``, ``log10(E)`` by 1. With ``options`` given, the scaling is filled in only if the
    options do not set ``x_scale`` themselves.
    """
    s = problem.system
    aq = max(float(np.max(np.abs(x0[: s.nq]))), 1e-300)
    cmax = max([ct.c for ct in s.unilateral] or [1.0])
    scale = np.empty(problem.size)
    scale[: s.nq] = aq
    scale[s.nq : s.size] = cmax * aq
    scale[s.size] = problem.omega0
    scale[s.size + 1] = 0.1 * problem.omega0
    if options is None:
        return ContinuationOptions(step=0.05, max_step=0.25, x_scale=scale, p_scale=1.0,
                                   newton=NewtonOptions(atol=1e-9, max_iter=20))
    if options.x_scale is None:
        return dataclasses.replace(options, x_scale=scale, p_scale=options.p_scale or 1.0)
    return options


def nonlinear_mode(
    model: StructuralModel,
    mode: int = 1,
    energy: tuple[float, float] = (1e-3, 1.0),
    harmonics: Harmonics | int = 10,
    *,
    options: ContinuationOptions | None = None,
    exact_contact: bool = True,
    progress: bool = False,
    checkpoint: str | os.PathLike | None = None,
    resume: bool = False,
) -> Branch:
    """Nonlinear mode (frequency-energy backbone) by the extended periodic motion concept.

    Follows the periodic motions of the free system ``M q'' + K q + f_nl(q) = -w_c p`` that
    continue linear mode ``mode`` from energy ``energy[0]`` to ``energy[1]`` (continuation in
    ``log10`` of the period-averaged mechanical energy). ``branch.xi`` holds the artificial
    damping, which is ~0 for a conservative model (a check of the solution).

    ``checkpoint`` and ``resume`` write every converged point to a journal as it is found and
    continue a killed run from it, as for :func:`frequency_response`; the checkpoint must come
    from the same model, ``mode``, energy span, harmonics and ``exact_contact``.

    Returns
    -------
    Branch
        ``omega`` (rad/s) against ``energy``.
    """
    model = _check_model(model, "nonlinear_mode")
    h = _harmonics(harmonics, "nonlinear_mode")
    _options(options, "nonlinear_mode")
    e0, e1 = _span(energy, "energy", "nonlinear_mode", positive=True)
    problem = NonlinearModeProblem(model, h, mode, exact_contact=exact_contact)
    span = (math.log10(e0), math.log10(e1))
    problem.set_reference_energy(math.sqrt(e0 * e1))
    x0 = problem.linear_guess(e0)
    options = nonlinear_mode_options(problem, x0, options)

    def wrap(res, meta) -> Branch:
        return branch_from_continuation(problem, res, kind="nonlinear mode", model=model,
                                        meta={"mode": int(mode), "energy_span": [e0, e1], **meta})

    description = {"analysis": "nonlinear_mode", "mode": int(mode), "energy": [e0, e1], "harmonics": _harmonics_key(h),
                   "exact_contact": bool(exact_contact), "n_unknowns": int(problem.size),
                   "model": model_fingerprint(model)} if checkpoint is not None else {}
    return _checkpointed(problem, span, options, "nonlinear_mode", progress, x0=lambda: x0, wrap=wrap, model=model,
                         checkpoint=checkpoint, resume=resume, description=description)


@dataclasses.dataclass(frozen=True, eq=False)
class StaticContactResult:
    """Static contact solution: ``x`` displacements, ``contact_force`` per contact, scipy-style fields."""

    x: np.ndarray
    contact_force: np.ndarray
    success: bool
    status: int
    message: str
    nit: int
    residual_norm: float

    @property
    def gap(self) -> np.ndarray:
        return self._gaps

    @property
    def penetration(self) -> float:
        return float(max(0.0, np.max(-self._gaps))) if self._gaps.size else 0.0


def static_contact(model: StructuralModel, force: np.ndarray | None = None, *, x0: np.ndarray | None = None,
                   options: NewtonOptions | None = None) -> StaticContactResult:
    """Static equilibrium with contact: ``K q + f_nl(q) = f - W p``, ``p - max(0, p - c g_N) = 0``.

    Solved with the same semismooth Newton as the dynamic problems (no harmonics). ``force``
    defaults to the static part of the declared forcing plus the amplitudes of harmonic-1 forces
    (a quasi-static load).
    """
    model = _check_model(model, "static_contact")
    n = model.n_dofs
    if force is None:
        fv = model.force_vectors()
        f = sum((v.real for v in fv.values()), np.zeros(n))
    else:
        f = np.asarray(force, dtype=float)
        if f.shape != (n,) or not np.all(np.isfinite(f)):
            raise ValueError(f"static_contact: force must be a finite vector of length {n}, got shape {f.shape}")
    uc = [(a.item, a.dof) for a in model.contacts if isinstance(a.item, UnilateralContact)]
    cs = [law.c if law.c is not None else default_contact_parameter(model, dof) for law, dof in uc]
    m = len(uc)
    K = model.K.tocsr()

    def fun(x):
        q, p = x[:n], x[n:]
        r = np.empty(n + m)
        r[:n] = K @ q - f
        rows, cols, vals = [], [], []
        for a in model.contacts:
            if isinstance(a.item, PenaltyContact):
                pf, dp = a.item.force(q[a.dof])
                r[a.dof] += pf
                rows.append(a.dof); cols.append(a.dof); vals.append(float(dp))
        for a in model.nonlinearities:
            ff, df = a.item.force(q[a.dof])
            r[a.dof] += ff
            rows.append(a.dof); cols.append(a.dof); vals.append(float(df))
        for j, ((law, dof), c) in enumerate(zip(uc, cs)):
            r[dof] += p[j]
            rows.append(dof); cols.append(n + j); vals.append(1.0)
            rr, drp, dru = law.residual(p[j], q[dof], c)
            r[n + j] = rr
            rows += [n + j, n + j]; cols += [n + j, dof]; vals += [float(drp), float(dru)]
        J = sp.block_diag([K, sp.csr_matrix((m, m))], format="csr") + sp.csr_matrix((vals, (rows, cols)), shape=(n + m, n + m))
        return r, J

    x_init = np.zeros(n + m) if x0 is None else np.asarray(x0, dtype=float)
    res = semismooth_newton(fun, x_init, options=options or NewtonOptions(atol=1e-10, max_iter=50))
    q = res.x[:n]
    forces = np.zeros(len(model.contacts))
    gaps = np.zeros(len(model.contacts))
    j = 0
    for i, a in enumerate(model.contacts):
        gaps[i] = a.item.gap - q[a.dof]
        if isinstance(a.item, UnilateralContact):
            forces[i] = res.x[n + j]
            j += 1
        else:
            forces[i] = a.item.force(q[a.dof])[0]
    out = StaticContactResult(x=q, contact_force=forces, success=res.success, status=res.status, message=res.message,
                              nit=res.nit, residual_norm=res.residual_norm)
    object.__setattr__(out, "_gaps", gaps)
    return out
