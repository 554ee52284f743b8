"""The Moreau-Jean stepping loop: :func:`integrate` runs a :class:`Stepper` over ``n`` steps and records a :class:`Segment`.

The loop stores every ``store_every``-th step and the last (displacements, velocities, impulses,
energies, gaps) and the steps whose local problem was not solved; models up to
:data:`DENSE_LIMIT` DOFs step the state ``x = [q; v]`` with the dense propagators of the
stepper, larger ones with its sparse LU. The step itself (operators, local problem,
:data:`LOCAL_NEWTON`, :func:`solve_or_lstsq`) is :mod:`femodes.time.moreau_step`, re-exported here.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .moreau_step import DENSE_LIMIT, LOCAL_NEWTON, Stepper, solve_or_lstsq

__all__ = ["Stepper", "Segment", "LOCAL_NEWTON", "DENSE_LIMIT", "integrate", "solve_or_lstsq"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Segment:
    """Stored samples of :func:`integrate` and the steps whose local problem was not solved."""

    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    impulse: np.ndarray
    energy: np.ndarray
    gap: np.ndarray
    n_failed: int
    first_failure: tuple[float, str] | None  # (time, solver message)
    contact_work: float = 0.0  # net work of the unilateral contacts' impulses (:func:`integrate`)


class _Recorder:
    """Stored samples of a run (every ``store_every``-th step and the last) and its failed steps."""

    def __init__(self, st: Stepper, n_steps: int, store_every: int, q, v):
        idx = np.arange(0, n_steps + 1, store_every)
        if idx[-1] != n_steps:
            idx = np.append(idx, n_steps)
        self.idx = idx
        self.store = np.zeros(n_steps + 1, dtype=bool)
        self.store[idx] = True
        self.U = np.empty((idx.size, st.n))
        self.V = np.empty((idx.size, st.n))
        self.IMP = np.zeros((idx.size, st.n_contacts))
        self.U[0], self.V[0] = q, v
        self.k = 1
        self.n_failed = 0
        self.first_failure: tuple[float, str] | None = None
        self.work = 0.0  # net work of the unilateral contacts' impulses

    def failed(self, t: float, message: str) -> None:
        self.n_failed += 1
        if self.first_failure is None:
            self.first_failure = (t, message)
        log.debug("Moreau-Jean: local contact/nonlinear problem not solved at t = %.6g: %s", t, message)

    def sample(self, q, v, imp) -> None:
        self.U[self.k], self.V[self.k] = q, v
        self.IMP[self.k] = imp
        self.k += 1


def integrate(st: Stepper, t0: float, n_steps: int, q, v, store_every: int = 1) -> Segment:
    """Run ``n_steps`` steps from ``(q, v)`` at ``t0``; store every ``store_every`` step (and the last).

    ``Segment.contact_work`` sums the work of the unilateral contacts' impulses, ``-P_c`` times the
    velocity of the contact DOF that moves its position on the step (:func:`contact_work`): a
    rigid stop can only take energy out, so a positive sum is energy the steps put in."""
    rec = _Recorder(st, n_steps, store_every, q, v)
    tk = t0 + st.h * np.arange(n_steps + 1)
    fall = _forcing_samples(st, tk, n_steps) if st.fidx.size > 0 else None
    if st.dense:
        q, v = _DenseRun(st, rec, tk, fall).run(q, v, n_steps)
    else:
        q, v = _run_sparse(st, rec, tk, fall, q, v, n_steps)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
        raise FloatingPointError("Moreau-Jean integration diverged (non-finite state); reduce dt")
    return _segment(st, rec, tk)


def _forcing_samples(st: Stepper, tk: np.ndarray, n_steps: int) -> np.ndarray:
    """Forces on the forced DOFs at the step times ``tk`` (rows)."""
    if st.fk.size:
        assert st.omega is not None  # harmonic forcing requires omega (drivers._check_omega)
        return np.real(np.exp(1j * st.omega * np.outer(tk, st.fk)) @ st.Fk) + st.f0
    return np.tile(st.f0, (n_steps + 1, 1))


def _take(idx: np.ndarray):
    """DOF indices ``idx`` as a slice when they are ``i, i+1, ..., j``: ``x[idx]`` is then a view,
    cheaper than the copy of fancy indexing (the loops below only read it)."""
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


class _DenseRun:
    """The loop of small models: the state ``x = [q; v]`` stepped by the dense propagators, the
    contact impulses accumulated between stored samples.

    Per-step constants are set up here once. A model whose local DOFs are unilateral contacts on
    massive DOFs only (no smooth law) takes the free step without a local problem whenever no
    contact is predicted active (:meth:`ImpactLaw.free_flight`); one local DOF corrects the free
    state by its column of ``Psi`` (the product ``Psi @ lam`` with one term).
    """

    def __init__(self, st: Stepper, rec: _Recorder, tk: np.ndarray, fall: np.ndarray | None):
        self.st, self.rec, self.tk = st, rec, tk
        n = st.n
        self.fx = (st.thf * fall[1:] + (1.0 - st.thf) * fall[:-1]) @ st.Gam.T if fall is not None else None
        self.S, self.vS_idx = _take(st.S), _take(n + st.S)
        self.ucd, self.ucv = _take(st.uc_dof), _take(n + st.uc_dof)
        self.free_flight = (st.impact.free_flight if st.uc and not st.has_smooth and not st.impact.any_massless
                            else None)
        self.psi1 = st.Psi[:, 0].copy() if st.S.size == 1 else None
        self.uc_col = np.asarray(st.uc, dtype=int)  # impulse columns of the unilateral contacts
        self.acc = np.zeros(st.n_contacts)
        self.acc_used = False  # impulses accumulated since the last stored sample

    def run(self, q, v, n_steps: int):
        """Step ``n_steps`` times from ``(q, v)``; the final ``(q, v)``."""
        st, rec = self.st, self.rec
        n, nc, store = st.n, st.n_contacts, rec.store
        U, V, IMP = rec.U, rec.V, rec.IMP
        Phi, fx, free_flight, no_impulse = st.Phi, self.fx, self.free_flight, st.no_impulse
        local_step = self._local_step if st.S.size else None
        x = np.concatenate([q, v])
        j = rec.k
        for k in range(n_steps):
            xf = Phi @ x
            if fx is not None:
                xf += fx[k]
            if local_step is None:
                x = xf
            elif free_flight is not None and free_flight(x, n):  # no contact predicted: x = x_f
                st.P_prev = no_impulse
                x = xf
            else:
                x = local_step(k, x, xf)
            if store[k + 1]:  # rec.sample(x[:n], x[n:], acc), IMP is zero where nothing accumulated
                U[j] = x[:n]
                V[j] = x[n:]
                if self.acc_used:
                    IMP[j] = self.acc
                    self.acc = np.zeros(nc)
                    self.acc_used = False
                j += 1
        rec.k = j
        return x[:n], x[n:]

    def _local_step(self, k: int, x: np.ndarray, xf: np.ndarray) -> np.ndarray:
        """State after step ``k`` from ``x``, its free state ``xf`` corrected (in place) by the
        local problem."""
        st = self.st
        vS_idx = self.vS_idx
        q0S, v0S = x[self.S], x[vS_idx]
        if st.has_smooth:
            fs0, _ = st.smooth_force_fn(q0S)
            xf += st.Psi @ (st.free_fs * fs0)
        if st.uc:
            active, b = st.impact.rhs(x[self.ucd], x[self.ucv])
        else:
            active = b = st.no_contact
        lam, P, failure = st.local(q0S, v0S, xf[vS_idx] - v0S, active, b)
        if failure is not None:
            self.rec.failed(self.tk[k], failure)
        st.P_prev = P
        if self.psi1 is not None:
            xf += self.psi1 * lam.item(0)
        else:
            xf += st.Psi @ lam
        if st.n_contacts:
            if st.uc:
                self.acc[self.uc_col] += P
                self.rec.work += contact_work(P, st.work_w_uc, x[self.ucv], xf[self.ucv])
            if st.pc:
                self.acc += st.penalty_impulse(x[: st.n], xf[: st.n])
            self.acc_used = True
        return xf


def _run_sparse(st: Stepper, rec: _Recorder, tk: np.ndarray, fall: np.ndarray | None, q, v, n_steps: int):
    """The loop of large models (:meth:`Stepper.step`, sparse LU); the final ``(q, v)``."""
    nc, store = st.n_contacts, rec.store
    acc = np.zeros(nc)
    Kq = st.K @ q
    f0 = f1 = None
    uc = st.uc_dof
    for k in range(n_steps):
        if fall is not None:
            f0, f1 = fall[k], fall[k + 1]
        v0 = v
        q, v, Kq, imp, failure = st.step(q, v, Kq, f0, f1)
        if failure is not None:
            rec.failed(tk[k], failure)
        if nc:
            acc += imp
            if st.uc:
                # st.step keeps this step's impulses of the unilateral contacts in P_prev
                rec.work += contact_work(st.P_prev, st.work_w_uc, v0[uc], v[uc])
        if store[k + 1]:
            rec.sample(q, v, acc)
            acc = np.zeros(nc)
    return q, v


def _segment(st: Stepper, rec: _Recorder, tk: np.ndarray) -> Segment:
    """The stored samples as a :class:`Segment` (energies and gaps of the stored states)."""
    U, V = rec.U, rec.V
    G = (np.column_stack([law.gap_function(U[:, d]) for law, d in zip(st.c_law, st.c_dof)]) if st.n_contacts
         else np.zeros((U.shape[0], 0)))
    return Segment(t=tk[rec.idx], u=U, v=V, impulse=rec.IMP, energy=st.energies(U, V), gap=G,
                   n_failed=rec.n_failed, first_failure=rec.first_failure, contact_work=rec.work)


def contact_work(P: np.ndarray, w: np.ndarray, v0: np.ndarray, v1: np.ndarray) -> float:
    """Work of the impulses ``P >= 0`` of unilateral contacts on one step: each pushes its DOF
    back (``-P``), and an impulse works on the mean of the velocities before and after it, so the
    work is ``-sum P ((1 - w) v0 + w v1)`` with ``w = 1/2`` on a DOF with mass (``w = 1`` on a
    massless one, where the impulse is a force times the step's displacement ``h v1``). It is the
    impulses' exact term of the change of kinetic energy, ``(v1 - v0)^T M (v1 + v0) / 2``, for any
    theta; with theta = 1/2 also of the step's discrete energy balance (the other terms: the work
    of the forcing and of the damping). Under Newton's law ``v1 = -e v0`` it is
    ``-(1 - e^2) m v0^2 / 2 <= 0``. (The velocity that moves the position, ``theta v1 + (1 - theta)
    v0``, read ``+0.2 m v0^2`` per elastic impact at theta = 0.55: the scheme's numerical
    dissipation, ``(1/2 - theta) |v1 - v0|_M^2``, is where that goes.) Positive when an impulse
    stops a DOF that was moving away (the activation tests a gap predicted from inside the stop)."""
    return -float(P @ ((1.0 - w) * v0 + w * v1))
