"""Analyses layer: running the continuation of an analysis, with progress and checkpoints.

:func:`run_continuation` is what :func:`~femodes.frequency_response` and
:func:`~femodes.nonlinear_mode` call: it chains the progress callback and the checkpoint journal in
front of the user's callback. With ``checkpoint=path`` (or ``checkpoint=femodes.Checkpoint(path)``,
:func:`checkpoint_spec`) it writes every converged point to a journal ``<path>.points/`` as it is
found (one small file per point, written atomically, see :class:`~femodes.store.CheckpointStore`)
and the finished branch to ``path``; ``checkpoint=femodes.Checkpoint(path, resume=True)``
continues a killed run from its last saved point (``continuation(start=...)``), so that the final
branch holds every point exactly once and equals the branch of an uninterrupted run. A checkpoint
is locked while a run uses it, and a run stops (keeping its points) before the points it holds
would outgrow the memory available at its start (:class:`_MemoryGuard`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
import logging
import os
import sys
import time
from typing import Any
from collections.abc import Callable, Iterator

import numpy as np

from .model import StructuralModel
from .results import Branch, load_branch
from .store import Checkpoint, CheckpointStore, model_fingerprint
from .solvers import ContinuationOptions, continuation
from .solvers.checks import InputTypeError, InputValueError, available_memory
from .solvers.continuation import ContinuationResult, ContinuationState

__all__ = ["run_continuation", "warn_short_of_span", "checkpoint_spec", "model_fingerprint", "shows_progress", "progress_shown"]

log = logging.getLogger(__name__)


class _MemoryGuard:
    """Stops a continuation before the points it keeps (unknowns, tangents, and the branch's copy
    of them: :data:`POINT_COPIES` arrays of ``problem.size`` floats per point) outgrow
    :data:`POINT_MEMORY_FRACTION` of the memory available when it started, so that a long run of
    a large model ends with its points and a message instead of a ``MemoryError``."""

    def __init__(self, size: int, label: str, n_saved: int = 0):
        avail = available_memory()
        self.per_point = POINT_COPIES * 8.0 * max(int(size), 1)
        self.limit = None if avail is None else int(POINT_MEMORY_FRACTION * avail // self.per_point)
        self.label, self.n_saved, self.message = label, n_saved, ""

    def __call__(self, point) -> bool:
        """False (stop) when one more point would pass the limit."""
        if self.limit is None or self.n_saved + point.index + 2 <= self.limit:
            return True
        self.message = (f"stopped at p = {point.p:.8g} after {point.index + 1} points: the branch's points "
                        f"({self.per_point / 2**20:.3g} MiB each) would outgrow the memory available "
                        f"({self.limit} points); the points so far are kept: use fewer harmonics, a Craig-Bampton "
                        "model, or a shorter span")
        log.warning("%s: %s", self.label, self.message)
        return False


#: Copies of the unknowns per continuation point held in memory (the point, its tangent, the
#: branch's Q and P), and the share of the memory available at the start they may take (the
#: factorisations and the analysis' other arrays need the rest).
POINT_COPIES = 3
POINT_MEMORY_FRACTION = 0.5


#: A frequency at or below this fraction of the branch's first is taken as zero (the guard's 6e-10
#: rad/s on a softening backbone that started at 1 rad/s: a period 1e9 times the linear one).
OMEGA_FLOOR = 1e-6


class _FrequencyGuard:
    """Stops a continuation whose frequency (an unknown of a nonlinear mode) falls to zero or below:
    the period of the orbits grows without bound there (a softening backbone at its separatrix),
    and past it the "orbits" have negative frequencies (a softening cubic spring's backbone went
    through w = 6e-10 to w = -0.999 with success True and three folds). :meth:`cut` drops that
    point and any after it."""

    def __init__(self, problem, label: str, describe: Callable[[float], str]):
        self.unpack = getattr(problem, "unpack", None)
        self.label, self.describe, self.message = label, describe, ""
        self.first: float | None = None

    def omega(self, x, p) -> float:
        return float(self.unpack(x, p).omega)

    def __call__(self, point) -> bool:
        """False (stop) at a point whose frequency is not positive (:data:`OMEGA_FLOOR`)."""
        if self.unpack is None:
            return True
        omega = self.omega(point.x, point.p)
        if self.first is None:
            self.first = abs(omega)
        return omega > OMEGA_FLOOR * self.first

    def cut(self, res: ContinuationResult) -> ContinuationResult:
        """``res`` up to its first point of non-positive frequency (unchanged if none)."""
        if self.unpack is None or not len(res.p):
            return res
        omega = np.array([self.omega(x, p) for x, p in zip(res.x, res.p)])
        bad = np.flatnonzero(~(omega > OMEGA_FLOOR * abs(omega[0])))
        if not bad.size:
            return res
        k = int(bad[0])
        last = (f"; the {k} point(s) before it are kept, the last at {self.describe(float(res.p[k - 1]))} (w = "
                f"{omega[k - 1]:.4g} rad/s)") if k else ""
        self.message = (f"stopped at {self.describe(float(res.p[k]))}: the frequency fell to {omega[k]:.3g} rad/s, "
                        "where the period of the orbits grows without bound (a softening nonlinearity's separatrix: "
                        f"no periodic motion of this family lies beyond){last}; orbits near w = 0 need many more "
                        "harmonics (check them with rtol=)")
        log.warning("%s: %s", self.label, self.message)
        cut = slice(0, k)
        return dataclasses.replace(
            res, x=res.x[cut], p=res.p[cut], nit=res.nit[cut], residual_norm=res.residual_norm[cut],
            step=res.step[cut], folds=tuple(int(i) for i in res.folds if i < k),
            tangents=None if res.tangents is None else res.tangents[cut], status=3, success=True,
            message=self.message)


def warn_short_of_span(branch: Branch, span, label: str, describe: Callable[[float], str],
                       options: ContinuationOptions) -> None:
    """A logged warning when a successful branch does not reach the end of its span: it turned back
    and left through the start (status 1), or stopped at ``max_points`` (status 2); in both the
    result said ``success=True`` and nothing else (a forced response asked for 0.5-2 rad/s covered
    0.5-0.599). A nonlinear mode whose contact-phase family replaced the energy continuation
    says so itself."""
    p = np.asarray(branch.parameter, dtype=float)
    if not branch.success or branch.status not in (1, 2) or not p.size or branch.meta.get("family") == "contact phase":
        return
    sign = 1.0 if span[1] >= span[0] else -1.0
    far = float(p[np.argmax(sign * (p - span[0]))])
    share = 100.0 * (far - span[0]) / (span[1] - span[0])
    if branch.status == 2:
        why = (f"it stopped at max_points = {options.max_points} at {describe(float(p[-1]))}; give "
               "ContinuationOptions(max_points=...) more points (or a larger max_step)")
    elif options.direction == -1 and p.size <= 2:
        why = ("it left the span at its start: ContinuationOptions(direction=-1) points out of the span; use "
               "direction=+1 (the default), or swap the span's ends to run the other way")
    else:
        why = (f"it turned back at {describe(far)} (a fold) and left the span through its start; the rest of the "
               "span lies on another branch: run again from the span's other end (the span's ends swapped)")
    log.warning("%s: the branch does not reach the end of its span (%s, %.0f %% of the way): %s", label,
                describe(float(span[1])), share, why)


def _run(problem, span, x0, options: ContinuationOptions, label: str, progress, *,
         start: ContinuationState | None = None, journal: Callable | None = None, guards: tuple = ()):
    """Continuation with the journal writer, the guards (memory, frequency) and the progress
    callback chained in front of the user's callback."""
    cb = _progress_callback(options.callback, span, label, progress)
    if journal is not None or guards:
        after = cb

        def cb(point):
            if journal is not None:
                journal(point)  # saved before the user's callback can stop the run
            if not all(g(point) for g in guards):
                return False
            return after(point) if after is not None else None

    if cb is not None:
        options = dataclasses.replace(options, callback=cb)
    return continuation(problem, span, x0=x0, options=options, start=start)


# ------------------------------------------------------------------------------------------------
# checkpoints: what a run is (to refuse resuming a different one) and what a point stores
# ------------------------------------------------------------------------------------------------
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


def _state_from_records(records: list[dict], ck: CheckpointStore) -> ContinuationState:
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
        tangents=None, first_index=0,
    )


def checkpoint_spec(checkpoint) -> Checkpoint | None:
    """The :class:`~femodes.store.Checkpoint` of an analysis' ``checkpoint=`` argument: ``None``,
    a path (a new run, ``Checkpoint(path)``) or a ``Checkpoint``."""
    if checkpoint is None or isinstance(checkpoint, Checkpoint):
        return checkpoint
    if not isinstance(checkpoint, (str, os.PathLike)):
        raise InputTypeError(f"checkpoint must be a file name (.npz or .h5) or a femodes.Checkpoint(path, "
                             f"resume=...), got {checkpoint!r}")
    try:
        return Checkpoint(checkpoint)
    except ValueError as exc:
        raise InputValueError(f"checkpoint {str(checkpoint)!r}: use a .npz or .h5 file name for the final "
                              "branch") from exc


def run_continuation(problem, span, options: ContinuationOptions, label: str, progress, *, x0: Callable,
                     wrap: Callable, model: StructuralModel, checkpoint: Checkpoint | None,
                     description: dict, describe: Callable[[float], str] | None = None) -> Branch:
    """Run (or resume, or return the finished) continuation of ``problem``; ``wrap(res, meta)`` -> Branch.

    Parameters
    ----------
    problem, span, options
        What :func:`~femodes.solvers.continuation` runs.
    label : str
        The analysis' name, for messages and log lines.
    progress : bool or callable
        ``True`` logs one INFO line per point; a callable receives every accepted point.
    x0 : callable
        ``x0(options)`` gives a new run's start point and its options (which may depend on the
        start, e.g. the arclength scale); a resumed run keeps the scales saved with its state.
    wrap : callable
        ``wrap(res, meta)`` makes the :class:`~femodes.results.Branch`; it warns (in the
        analysis' terms) when a run does not finish its span.
    model : StructuralModel
        Attached to a finished branch read back from its checkpoint.
    checkpoint : femodes.Checkpoint or None
        Where to journal the points (:func:`checkpoint_spec` turns an analysis' argument into
        one). ``resume=False``: a new run, an existing checkpoint is a ``FileExistsError``;
        ``resume=True``: continue the saved run, return its finished branch, or start a new one.
    description : dict
        JSON description of the run, saved in the journal and compared on resume.
    describe : callable, optional
        ``describe(p)`` names a parameter value in the analysis' terms (``"w = 1.2 rad/s"``, ``"the
        energy 0.03"``) for the messages; default ``"p = ..."``.
    """
    if not isinstance(progress, bool) and not callable(progress):
        raise TypeError(f"{label}: progress must be True, False or a callable(point), got {progress!r}")
    if checkpoint is not None and not isinstance(checkpoint, Checkpoint):
        raise TypeError(f"{label}: checkpoint must be a femodes.Checkpoint or None, got {checkpoint!r}")

    guard = _MemoryGuard(problem.size, label)
    frequency = _FrequencyGuard(problem, label, describe or (lambda p: f"p = {p:.8g}"))
    guards = (guard, frequency)

    def finish(res, meta) -> Branch:
        branch = wrap(frequency.cut(res), meta)
        if guard.message:
            branch.message = guard.message
        if not branch.success:
            log.warning("%s: %s", label, branch.message)
        return branch

    if checkpoint is None:
        start_x, start_options = x0(options)
        return finish(_run(problem, span, start_x, start_options, label, progress, guards=guards), {})
    ck = CheckpointStore(checkpoint.path)
    with ck.lock(label):  # a second run on the same checkpoint is refused, not raced
        return _run_checkpointed(problem, span, options, label, progress, x0, finish, model, checkpoint, ck,
                                 description, guards)


def _run_checkpointed(problem, span, options, label, progress, x0, finish, model, checkpoint, ck, description,
                      guards):
    """:func:`run_continuation` with a checkpoint, under its lock."""
    desc = json.loads(json.dumps(description))  # as it reads back from the JSON header
    if not checkpoint.resume and (ck.path.exists() or ck.journal.exists()):
        raise FileExistsError(f"{label}: checkpoint {str(ck.path)!r} (or its journal {ck.journal.name}/) exists; "
                              "pass checkpoint=femodes.Checkpoint(path, resume=True) to continue (or return) that "
                              "run, or delete it to start over")
    if ck.path.exists():
        return _finished_branch(ck, desc, label, model)
    records = _journal_records(ck, desc, label, problem.size)

    def journal(point):
        ck.write_point(point.index, _point_record(point))

    if records:
        start = _state_from_records(records, ck)
        log.info("%s: resuming %s from point %d at p = %.8g", label, ck.journal, start.index, start.p)
        res = _merge(records, _run(problem, span, None, options, label, progress, start=start, journal=journal,
                                   guards=guards))
    else:
        start_x, start_options = x0(options)
        res = _run(problem, span, start_x, start_options, label, progress, journal=journal, guards=guards)
    branch = finish(res, {"checkpoint": desc})
    ck.finish(branch)
    return branch


def _finished_branch(ck: CheckpointStore, desc: dict, label: str, model: StructuralModel) -> Branch:
    """The branch of a checkpointed run that finished (refused if it came from another run)."""
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


def _journal_records(ck: CheckpointStore, desc: dict, label: str, n: int) -> list[dict]:
    """The saved points of an interrupted run to continue from (a new journal if none)."""
    if not (ck.journal.exists() and (ck.header_path.exists() or ck.indices())):
        ck.create(desc)
        return []
    _check_same_run(ck.read_header(), desc, ck.journal, label)
    records = ck.read_points(required=_POINT_KEYS)
    for i, r in enumerate(records):
        if r["x"].shape != (n,) or (("tangent" in r) and r["tangent"].shape != (n + 1,)):
            raise ValueError(f"checkpoint: point file {str(ck.point_path(i))!r} holds {r['x'].shape} unknowns, "
                             f"this problem has {n}")
    # continue from the last point the run can continue from exactly; the points after it
    # (an inserted fold point, an end point) are computed again
    while records and "tangent" not in records[-1]:
        records.pop()
    ck.discard(after=len(records) - 1)
    return records


def _progress_callback(user_cb: Callable | None, span, label: str, progress: bool | Callable):
    if progress is False and user_cb is None:
        return None
    t0 = time.perf_counter()
    state = {"n": 0}

    def cb(point):
        state["n"] += 1
        if callable(progress):
            progress(point)
        elif progress:
            frac = (point.p - span[0]) / (span[1] - span[0])
            log.info("%s: point %d, p = %.6g (%.0f%% of span), %d Newton iterations, %.1f s",
                     label, state["n"], point.p, 100 * frac, point.nit, time.perf_counter() - t0)
        if user_cb is not None:
            return user_cb(point)
        return None

    return cb


@contextlib.contextmanager
def progress_shown(progress: bool | Callable) -> Iterator[None]:
    """With ``progress=True``, femodes' INFO records (the branch's points, the stability pass's size,
    time estimate and progress, the accuracy levels) reach the user for the block's duration even
    where logging is not configured: ``True`` is a request to see them, and Python's default shows
    warnings only (a user's ``progress=True`` printed nothing at all, its 70 s error estimate
    included). The ``femodes`` logger is set to INFO when it would drop them, and given a handler on
    stderr (message only) when no handler would receive them; both are undone on exit (process-wide
    while the call runs: calls in other threads show their INFO records too). A logging
    configuration that shows INFO already is left alone, and so is ``progress=False`` or a callable."""
    if progress is not True:
        yield
        return
    logger = logging.getLogger("femodes")
    level = logger.level
    handler = None
    if not logger.isEnabledFor(logging.INFO):
        logger.setLevel(logging.INFO)
    if not logger.hasHandlers():
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
    try:
        yield
    finally:
        if handler is not None:
            logger.removeHandler(handler)
        logger.setLevel(level)


def shows_progress(fn: Callable) -> Callable:
    """Decorator of an analysis with a keyword ``progress``: the whole call runs under
    :func:`progress_shown` (the continuation, its stability pass and ``rtol``'s levels)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with progress_shown(kwargs.get("progress", False)):
            return fn(*args, **kwargs)

    return wrapper
