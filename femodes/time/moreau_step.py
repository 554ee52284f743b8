r"""The Moreau-Jean step: operators precomputed for a fixed ``h`` (:class:`Stepper`) and the local problem.

One step (see :mod:`femodes.time.moreau` for the scheme) is a *free* step of the linear part,
``A dv_f = r`` with the iteration matrix ``A = M + h Theta C + h^2 Theta K Theta`` factorized once,
plus a correction ``A^{-1} B_S lam`` by generalized impulses ``lam`` on the local DOFs ``S``
(contacts and smooth nonlinear springs). ``lam`` solves the *local problem* on ``S`` only, coupled
through the Delassus operator ``W = B_S^T A^{-1} B_S`` (``|S|`` solves):

.. math::

    \lambda + h\,\theta\,f_s(q_{k+1,S}) + E P = 0, \qquad
    \mathrm{FB}\bigl(P_c, (b_c - v_{c,k+1}) / W_{cc}\bigr) = 0 \ \text{(active contacts)},

with ``h (1 - theta) f_s(q_k)`` already in the free step and ``E`` the contact columns. It is
solved by :func:`femodes.solvers.semismooth_newton` (options :data:`LOCAL_NEWTON` unless given),
or, without smooth laws, as the linear complementarity problem of the impact law
(:mod:`femodes.time.impact`; one active contact in closed form). Each solve starts from the
previous step's impulses (``P`` of the contacts; ``lam`` of a step without active contact); a
step that leaves every penalty contact open (and meets no other law) needs no solve: ``lam = 0``.
Models up to :data:`DENSE_LIMIT` DOFs step the state ``x = [q; v]`` with dense propagators,
larger ones with a sparse LU of ``A``. The loop over the steps is :mod:`femodes.time.stepper`.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import scipy.sparse as sp

from ..laws import PenaltyContact, UnilateralContact
from ..model import StructuralModel, low_rank_solver
from ..sparse_direct import factorize
from ..solvers import NewtonOptions, semismooth_newton
from .impact import ImpactLaw, fischer_burmeister, solve_lcp
from .smooth_laws import SmoothLaws

__all__ = ["Stepper", "LOCAL_NEWTON", "DENSE_LIMIT", "solve_or_lstsq"]

log = logging.getLogger(__name__)

#: Models up to this size use dense inverses of the iteration matrix (faster per step).
DENSE_LIMIT = 200


def solve_or_lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A^{-1} b`` (LAPACK ``gesv``), or the least-squares solution when ``A`` is exactly singular
    (a kink of the Fischer-Burmeister function can make the generalized Jacobian singular; the
    minimum-norm step keeps the iteration going).

    A nonsingular ``1 x 1`` system (one local DOF, e.g. a Duffing oscillator: every step) is the
    quotient ``b / a``, what ``gesv`` computes there, without the LAPACK call (~5 us).
    """
    if type(A) is np.ndarray and A.shape == (1, 1):
        a = A.item()
        if a != 0.0:
            return b / a
    try:
        return np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(A, b, rcond=None)[0]


#: Semismooth Newton options of the local problem of a step (and of its complementarity problem):
#: converged at ``|r| <= max(1e-13, 1e-13 |z|)`` (inf-norms; a residual in impulse units, relative to
#: the impulses ``z``), monotone Armijo backtracking down to 1e-10 without watchdog (from the
#: previous step's impulses full steps converge; ``watchdog=0`` also selects the solver's plain
#: loop, cheaper per iteration), at most 60 iterations, and a residual within ``1e4`` times the
#: tolerance accepted when round-off stops the iteration first; singular Jacobians (a kink of the
#: Fischer-Burmeister function) take the least-squares step.
LOCAL_NEWTON = NewtonOptions(atol=1e-13, rtol=0.0, rtol_x=1e-13, xtol=1e-15, max_iter=60, min_alpha=1e-10, watchdog=0,
                             accept_factor=1e4, linear_solver=solve_or_lstsq)


def _massless_dofs(M: sp.csr_matrix) -> np.ndarray:
    """DOFs with a zero row of ``M`` (algebraic, quasi-static); ValueError if ``M`` is not PSD there."""
    dM = M.diagonal()
    scale = float(np.max(np.abs(dM))) if dM.size else 1.0
    massless = dM <= 1e-14 * scale
    if np.any(massless):
        rows = abs(M)[massless].max() if M.nnz else 0.0
        if rows > 1e-12 * scale:
            raise ValueError("model: M has a zero diagonal entry on a DOF whose row is not zero (M is not PSD)")
        log.info("%d massless DOFs treated as quasi-static (theta = 1 on their rows)", int(massless.sum()))
    return massless


_SINGULAR = "model: the iteration matrix M + h theta C + h^2 theta^2 K is singular"


def _iteration_solver(M, K, C, h: float, th: np.ndarray, C_lr, dense: bool):
    """The iteration matrix ``A = M + h Theta C + h^2 Theta K Theta``: ``(solve, Ainv)`` with
    ``solve(r) = A^{-1} r``, by the dense inverse ``Ainv`` (small models) or a sparse LU (``Ainv``
    None). A low-rank damping part ``C_lr`` adds ``(h Theta U) diag(d) U^T`` to the sparse ``A``:
    Woodbury (:func:`low_rank_solver`)."""
    Th = sp.diags(th)
    A = (M + h * (Th @ C) + h * h * (Th @ K @ Th)).tocsc()
    if dense:
        Ad = A.toarray()
        try:
            Ainv = np.linalg.inv(Ad)
        except np.linalg.LinAlgError as exc:
            raise ValueError(f"{_SINGULAR} (a massless DOF without stiffness?)") from exc
        if not np.all(np.isfinite(Ainv)) or np.linalg.cond(Ad) > 1e15:
            raise ValueError(_SINGULAR)
        return (lambda r: Ainv @ r), Ainv
    try:
        lu = factorize(A, positive_definite=True)
    except RuntimeError as exc:
        raise ValueError(f"{_SINGULAR} (a massless DOF without stiffness?)") from exc
    if C_lr is None:
        return lu.solve, None
    U = C_lr.U
    return low_rank_solver(lu.solve, h * th[:, None] * U, C_lr.d, U), None


def _propagators(h: float, th: np.ndarray, Ai: np.ndarray, Kd: np.ndarray, Cd: np.ndarray, fidx: np.ndarray,
                 Z: np.ndarray):
    """Dense propagators ``(Phi, Gam, Psi)`` of the state ``x = [q; v]``: free step
    ``x_f = Phi x + Gam f_theta``, correction ``Psi lam``."""
    n = th.size
    Dq = -h * (Ai @ Kd)
    Dv = -(Ai @ ((h * h) * th[:, None] * Kd + h * Cd))
    I = np.eye(n)
    Phi = np.block([[I + h * th[:, None] * Dq, h * I + h * th[:, None] * Dv], [Dq, I + Dv]])
    G = h * Ai[:, fidx]
    Gam = np.vstack([h * th[:, None] * G, G])
    Psi = np.vstack([h * th[:, None] * Z, Z])
    return Phi, Gam, Psi


class Stepper:
    """Precomputed operators of the Moreau-Jean step for a fixed ``h`` (module docstring).

    Parameters
    ----------
    model : StructuralModel
    h, theta, restitution : float
        Step, theta-method parameter, Newton's restitution coefficient.
    omega : float or None
        Forcing frequency (``None`` without harmonic forcing).
    newton : NewtonOptions, optional
        Options of the local problem's semismooth Newton solves (default :data:`LOCAL_NEWTON`).
    """

    def __init__(self, model: StructuralModel, h: float, theta: float, restitution: float, omega: float | None,
                 newton: NewtonOptions | None = None):
        self.n, self.h, self.theta, self.e = model.n_dofs, h, theta, restitution
        self.newton = LOCAL_NEWTON if newton is None else newton
        M, K, C = model.M.tocsr(), model.K.tocsr(), model.C.tocsr()
        # modal damping: the low-rank part U diag(d) U^T of the damping (StructuralModel); the
        # dense path of small models takes the assembled matrix, the sparse one Woodbury
        self.C_lr = model.C_lowrank
        if self.C_lr is not None and self.n <= DENSE_LIMIT:
            C, self.C_lr = model.damping_matrix().tocsr(), None
        self.massless = _massless_dofs(M)
        # massless rows are algebraic: theta = 1 there (the trapezoidal rule would carry (-1)^k)
        self.th = np.where(self.massless, 1.0, theta)
        self.dense = self.n <= DENSE_LIMIT
        self.has_C = C.nnz > 0 or self.C_lr is not None
        self.M, self.K, self.C = (M.toarray(), K.toarray(), C.toarray()) if self.dense else (M, K, C)
        self.solve, self.Ainv = _iteration_solver(M, K, C, h, self.th, self.C_lr, self.dense)
        self._forcing(model, omega)
        contacts = list(model.contacts)
        self._local_dofs(model, contacts)
        self._contacts(contacts)
        self._delassus()
        # read-only constants of the per-step path: no contact impulse, no unilateral contact
        self.no_impulse = np.zeros(len(self.impact))
        self.no_contact = np.zeros(0, dtype=bool)
        self.no_impulse.flags.writeable = self.no_contact.flags.writeable = False
        self.P_prev = self.no_impulse  # warm start of the next complementarity problem
        self.lam_prev = None  # warm start of the next smooth-only local problem (None: from lam = 0)
        if self.dense:
            self.Phi, self.Gam, self.Psi = _propagators(h, self.th, self.Ainv, self.K, self.C, self.fidx, self.Z)

    # -- construction, step by step ---------------------------------------------------------------
    def _forcing(self, model: StructuralModel, omega: float | None) -> None:
        """Harmonic forcing ``f0 + Re sum_k F_k e^{i k omega t}`` restricted to the forced DOFs."""
        fv = model.force_vectors()
        self.omega = omega
        self.fidx = np.asarray(sorted({a.dof for a in model.forces}), dtype=int)
        ks = sorted(k for k in fv if k >= 1)
        self.fk = np.asarray(ks, dtype=float)
        self.Fk = np.array([fv[k][self.fidx] for k in ks]).reshape(len(ks), self.fidx.size)
        self.f0 = np.real(fv[0][self.fidx]) if 0 in fv else np.zeros(self.fidx.size)
        self.thf = self.th[self.fidx]

    def _local_dofs(self, model: StructuralModel, contacts: list) -> None:
        """The local DOFs ``S`` (contacts and smooth laws) and the smooth laws on them
        (:class:`~femodes.time.smooth_laws.SmoothLaws`; ``smooth_laws`` is its list of stacked
        laws, local positions and whether a position repeats)."""
        smooth = [(a.item, a.dof) for a in model.nonlinearities]
        smooth += [(a.item, a.dof) for a in contacts if isinstance(a.item, PenaltyContact)]
        S = sorted({d for _, d in smooth} | {a.dof for a in contacts if isinstance(a.item, UnilateralContact)})
        self.S = np.asarray(S, dtype=int)
        self.thS = self.th[self.S]
        self.pos = {d: i for i, d in enumerate(S)}
        self.smooth = SmoothLaws(smooth, self.pos, len(S))
        self.smooth_laws = self.smooth.laws
        self.has_smooth = bool(self.smooth_laws)
        self.smooth_everywhere = self.smooth.everywhere
        # what smooth_force(qS) calls: the stacked law itself when it covers every local DOF
        self.smooth_force_fn = self.smooth.force_fn
        # penalty contacts only: an open contact exerts no force, so a step that leaves them all open
        # needs no local solve
        self.penalty_only = all(isinstance(law, PenaltyContact) for law, _ in smooth)
        # constants of the local problem (and of the explicit part h (1 - theta) f_s(q_k) of the free step)
        h, thS = self.h, self.thS
        self.hth, self.hhtt, self.eye_S = h * thS, h * h * thS * thS, np.eye(len(S))
        self.free_fs = -h * (1.0 - thS)

    def _contacts(self, contacts: list) -> None:
        """Unilateral contacts (the impact law), penalty contacts (their impulses), all contacts
        (gaps of the stored samples)."""
        self.uc = [j for j, a in enumerate(contacts) if isinstance(a.item, UnilateralContact)]
        self.uc_dof = np.asarray([contacts[j].dof for j in self.uc], dtype=int)
        self.uc_loc = np.asarray([self.pos[d] for d in self.uc_dof], dtype=int)
        # the weights of v_{k+1} in the velocity an impulse works on (stepper.contact_work): the mean
        # of the two velocities on a DOF with mass, the end one on a massless (algebraic) DOF
        self.work_w_uc = np.where(self.massless[self.uc_dof], 1.0, 0.5)
        self.impact = ImpactLaw([contacts[j].item for j in self.uc], self.uc_dof, self.massless[self.uc_dof],
                                self.e, self.h)
        self.pc = [j for j, a in enumerate(contacts) if isinstance(a.item, PenaltyContact)]
        self.pc_dof = np.asarray([contacts[j].dof for j in self.pc], dtype=int)
        self.pc_law = [contacts[j].item for j in self.pc]
        self.n_contacts = len(contacts)
        self.c_dof = np.asarray([a.dof for a in contacts], dtype=int)
        self.c_law = [a.item for a in contacts]

    def _delassus(self) -> None:
        """``Z = A^{-1} B_S`` and the local Delassus operator ``W = B_S^T A^{-1} B_S``."""
        n, s = self.n, self.S.size
        if s:
            B = np.zeros((n, s))
            B[self.S, np.arange(s)] = 1.0
            Z = self.solve(B) if self.dense else np.column_stack([self.solve(B[:, i]) for i in range(s)])
            self.Z = np.asarray(Z).reshape(n, s)
            self.W = self.Z[self.S, :]
        else:
            self.Z = np.zeros((n, 0))
            self.W = np.zeros((0, 0))
        self.Wuc = self.W[np.ix_(self.uc_loc, self.uc_loc)] if self.uc else np.zeros((0, 0))
        if self.uc and np.any(np.diag(self.Wuc) <= 0):
            raise ValueError("model: non-positive Delassus operator at a contact DOF")
        # one unilateral contact: its local position and Delassus entry (closed-form impulse)
        self.single_uc = len(self.uc) == 1
        self.uc_loc1 = int(self.uc_loc[0]) if self.single_uc else -1
        self.W1 = float(self.Wuc[0, 0]) if self.single_uc else math.nan

    # -- pieces ----------------------------------------------------------------------------------
    def smooth_force(self, qS: np.ndarray):
        """Local smooth forces (cubic + penalty) and derivatives on the local DOFs."""
        return self.smooth.force(qS)

    def smooth_potential(self, qS: np.ndarray) -> np.ndarray:
        """Potential energy of the smooth laws, ``qS`` of shape ``(..., |S|)`` -> shape ``(...)``."""
        return self.smooth.potential(qS)

    def penalty_impulse(self, q0, q1) -> np.ndarray:
        """Impulses of the penalty contacts over a step, ``h (theta p(q1) + (1 - theta) p(q0))``."""
        imp = np.zeros(self.n_contacts)
        for j, law, d in zip(self.pc, self.pc_law, self.pc_dof):
            p0 = float(law.force(q0[d])[0])
            p1 = float(law.force(q1[d])[0])
            imp[j] = self.h * (self.th[d] * p1 + (1.0 - self.th[d]) * p0)
        return imp

    def energies(self, U: np.ndarray, V: np.ndarray) -> np.ndarray:
        """Mechanical energy of stored samples (rows), vectorised."""
        MV = np.asarray(self.M @ V.T).T
        KU = np.asarray(self.K @ U.T).T
        E = 0.5 * np.einsum("ij,ij->i", V, MV) + 0.5 * np.einsum("ij,ij->i", U, KU)
        if self.S.size:
            E += self.smooth_potential(U[:, self.S])
        return E

    # -- the local problem ------------------------------------------------------------------------
    def local(self, q0S, v0S, dvfS, active, b):
        """Local generalized impulses ``lam`` (on S), contact impulses ``P`` and the solver's
        message if it failed (else ``None``).

        ``lam + h theta f_s(q1_S) + E P = 0`` (with ``h (1-theta) f_s(q0)`` already in the free
        step), ``FB(P_c, y_c / W_cc) = 0`` for active contacts, ``P_c = 0`` otherwise, with
        ``y_c = b_c - v1_c``.
        """
        if not self.has_smooth:
            return self._impacts_only(v0S, dvfS, active, b)
        h, W, hth, hhtt, eye = self.h, self.W, self.hth, self.hhtt, self.eye_S
        base_q = q0S + h * v0S + hth * dvfS
        if not self.uc or not active.any():
            return self._smooth_only(base_q)
        self.lam_prev = None
        s = self.S.size
        ia = np.flatnonzero(active)
        na = ia.size
        loc_a = self.uc_loc[ia]
        # semismooth Newton on z = [lam (s), P_a (na)], from the previous step's impulses
        sig = np.diag(W)[loc_a]
        z = np.zeros(s + na)
        z[s:] = self.P_prev[ia]
        np.subtract.at(z[:s], loc_a, z[s:])
        v1free = v0S + dvfS

        def F(z):
            lam, Pa = z[:s], z[s:]
            Wl = W @ lam
            fs, dfs = self.smooth.force(base_q + hth * Wl)
            r1 = lam + hth * fs
            np.add.at(r1, loc_a, Pa)
            J = np.zeros((s + na, s + na))
            J[:s, :s] = eye + (hhtt * dfs)[:, None] * W
            J[loc_a, s + np.arange(na)] += 1.0
            y = (b[ia] - (v1free[loc_a] + Wl[loc_a])) / sig
            r2, da, db = fischer_burmeister(Pa, y)
            J[s:, :s] = -(db / sig)[:, None] * W[loc_a, :]
            J[s:, s:] = np.diag(da)
            return np.concatenate([r1, r2]), J

        res = semismooth_newton(F, z, options=self.newton)
        P = np.zeros(len(self.impact))
        P[ia] = np.maximum(res.x[s:], 0.0)
        return res.x[:s], P, None if res.success else res.message

    def _smooth_only(self, base_q):
        """No active contact: ``lam + h theta f_s(base_q + h theta W lam) = 0``, from the previous
        step's ``lam`` (it changes by ``O(h^2)`` per step: measured 1.0 Newton iteration per step
        instead of 1.6 from ``lam = 0`` on a Duffing oscillator). Penalty contacts alone, all open
        at ``base_q``: ``lam = 0`` exactly, no solve."""
        smooth_force, no_impulse = self.smooth_force_fn, self.no_impulse
        if self.penalty_only and not smooth_force(base_q)[0].any():  # every contact open: lam = 0 exactly
            self.lam_prev = None
            return np.zeros(self.S.size), no_impulse, None
        W, hth, hhtt, eye = self.W, self.hth, self.hhtt, self.eye_S

        def F(lam):
            fs, dfs = smooth_force(base_q + hth * (W @ lam))
            return lam + hth * fs, eye + (hhtt * dfs)[:, None] * W

        res = semismooth_newton(F, np.zeros(self.S.size) if self.lam_prev is None else self.lam_prev,
                                options=self.newton)
        self.lam_prev = res.x
        return res.x, no_impulse, None if res.success else res.message

    def _impacts_only(self, v0S, dvfS, active, b):
        """No smooth law: ``lam = -E P`` and an LCP in ``P`` with Delassus ``W_a`` (closed form for
        one active contact)."""
        s = self.S.size
        if self.single_uc:  # one contact: the closed form in Python floats (s = 1)
            if not active.item(0):
                return np.zeros(s), self.no_impulse, None
            i = self.uc_loc1
            yfree = b.item(0) - (v0S.item(i) + dvfS.item(i))
            p = max(0.0, -yfree / self.W1)
            lam = np.zeros(s)
            lam[i] = 0.0 - p
            return lam, np.array([p]), None
        P = np.zeros(len(self.impact))
        ia = np.flatnonzero(active)
        if ia.size == 0:
            return np.zeros(s), P, None
        loc_a = self.uc_loc[ia]
        Wa = self.Wuc[np.ix_(ia, ia)]
        yfree = b[ia] - (v0S[loc_a] + dvfS[loc_a])
        failure = None
        if ia.size == 1:
            P[ia] = max(0.0, -yfree[0] / Wa[0, 0])
        else:
            P[ia], res = solve_lcp(Wa, yfree, self.P_prev[ia], self.newton)
            failure = None if res.success else res.message
        lam = np.zeros(s)
        np.subtract.at(lam, loc_a, P[ia])
        return lam, P, failure

    # -- one step (sparse models) ----------------------------------------------------------------
    def step(self, q0, v0, Kq0, f0, f1):
        """Advance ``(q0, v0)`` by one step; returns ``q1, v1, Kq1, contact impulses, failure``."""
        h, th = self.h, self.th
        Kv0 = self.K @ v0
        r = -h * Kq0 - (h * h) * th * Kv0
        if self.has_C:
            r -= h * (self.C @ v0)
            if self.C_lr is not None:
                r -= h * self.C_lr.matmul(v0)
        if self.fidx.size:
            r[self.fidx] += h * (self.thf * f1 + (1.0 - self.thf) * f0)
        S = self.S
        imp = np.zeros(self.n_contacts)
        failure = None
        if S.size:
            q0S, v0S = q0[S], v0[S]
            if self.has_smooth:
                fs0, _ = self.smooth_force_fn(q0S)
                r[S] -= h * (1.0 - self.thS) * fs0
            dvf = self.solve(r)
            if self.uc:
                active, b = self.impact.rhs(q0[self.uc_dof], v0[self.uc_dof])
            else:
                active = b = self.no_contact
            lam, P, failure = self.local(q0S, v0S, dvf[S], active, b)
            self.P_prev = P
            dv = dvf + self.Z @ lam
            if self.uc:
                imp[self.uc] = P
        else:
            dv = self.solve(r)
        v1 = v0 + dv
        q1 = q0 + h * v0 + h * th * dv
        Kq1 = self.K @ q1
        if self.pc:
            imp += self.penalty_impulse(q0, q1)
        return q1, v1, Kq1, imp, failure
