r"""Moreau-Jean nonsmooth time-stepping of ``M q'' + C q' + K q + f_nl(q) = f(t) - sum_c e_c p_c``.

Scheme (Moreau 1988; Jean 1999; Acary & Brogliato 2008, section 10.1), on a step
``[t_k, t_{k+1}]`` of length ``h`` with row weights ``theta_i``:

.. math::

    M (v_{k+1} - v_k) = h\,\Theta\,F_{k+1} + h\,(I - \Theta)\,F_k - \sum_c e_c P_c, \qquad
    q_{k+1} = q_k + h\,\Theta\,v_{k+1} + h\,(I - \Theta)\,v_k,

with the smooth forces ``F = f(t) - C v - K q - f_s(q)`` (``f_s``: cubic springs and penalty
contacts, treated implicitly by Newton iterations on the step) and the contact impulses
``P_c = \int p_c dt`` over the step. For every unilateral contact whose predicted gap
``g_N(q_k) - (h/2) v_{c,k}`` is non-positive, Newton's impact law at the velocity level holds
(Moreau's viability lemma makes it enforce ``g_N >= 0`` up to ``O(h)``)

.. math::

    0 \le U_{k+1} + e\,U_k \;\perp\; P_{k+1} \ge 0, \qquad U = \dot g_N = -v_c .

Massless DOFs (zero rows of ``M``, e.g. contact nodes after mass redistribution) are algebraic
(quasi-static): their rows use ``theta_i = 1`` (a trapezoidal rule on an algebraic equation
would carry undamped ``(-1)^k`` oscillations), and a contact on a massless DOF is the
position-level Signorini condition ``0 <= g_N(q_{k+1}) \perp P_{k+1} >= 0`` (no penetration
drift). Caveat, measured on a 40-element cantilever with a massless tip stop: every contact
switch excites stiff modes that the trapezoidal rule neither resolves nor damps, so the energy
jumps by O(dt^2) per switch (24 %, 7 %, 1.7 %, 0.6 % over five periods for dt = T/800 ... T/6400,
examples/validation_cantilever.py); use small steps (or theta > 1/2) on such FE models.
With these weights the iteration matrix is ``A = M + h Theta C + h^2 Theta K Theta``; it is
factorized once and the contact/nonlinear DOFs ``S`` are coupled through the local Delassus
operator ``W = B_S^T A^{-1} B_S`` (``|S|`` solves), so each step is a small complementarity
problem on ``S``, solved exactly by semismooth Newton on the Fischer-Burmeister function.

With ``theta = 1/2`` and ``e = 1`` the smooth part is the trapezoidal rule (energy conserving
for linear systems) and impacts of massful DOFs are conservative: ``U_{k+1} = -U_k`` (energy
drift 9e-12 over 100 impacts of the 1-DOF oscillator).

References
----------
J. J. Moreau, "Unilateral contact and dry friction in finite freedom dynamics", in *Nonsmooth
Mechanics and Applications*, CISM 302, Springer (1988) 1-82.
M. Jean, "The non-smooth contact dynamics method", Comput. Methods Appl. Mech. Engrg. 177 (1999)
235-257.
V. Acary and B. Brogliato, *Numerical Methods for Nonsmooth Dynamical Systems*, Lecture Notes in
Applied and Computational Mechanics 35, Springer (2008), chapter 10.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..laws import CubicSpring, PenaltyContact, UnilateralContact
from ..model import StructuralModel

__all__ = ["TimeHistory", "SteadyState", "simulate", "steady_state"]

log = logging.getLogger(__name__)

#: Models up to this size use dense inverses of the iteration matrix (faster per step).
_DENSE_LIMIT = 200
#: Newton tolerance of the local (contact + nonlinear DOFs) problem, relative.
_LOCAL_TOL = 1e-13
_LOCAL_MAXIT = 60
#: Bounds that turn an absurd dt (or t_end) into an error naming it instead of an overflow or a
#: failed allocation deep inside numpy: steps per run, and stored floats per history array
#: (2**28 float64 = 2 GiB).
_MAX_STEPS = 10**9
_MAX_STORED = 2**28


def _n_steps(span: float, dt: float, what: str, owner: str) -> int:
    """``ceil(span / dt)`` steps, or a ValueError naming ``dt`` when that is not a sane count."""
    ratio = span / dt
    if not math.isfinite(ratio) or ratio > _MAX_STEPS:
        raise ValueError(
            f"{owner}: dt={dt!r} gives {ratio:.3g} steps over {what} = {span:.6g} (more than {_MAX_STEPS:.0e}); "
            "increase dt"
        )
    return max(1, int(math.ceil(ratio - 1e-9)))


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class TimeHistory:
    """Samples of a Moreau-Jean time integration.

    Attributes
    ----------
    t : ndarray (n_steps,)
        Sample times (the first is ``t0``).
    u, v : ndarray (n_steps, n_dofs)
        Displacements and velocities (velocities are right limits ``v(t^+)``).
    impulse : ndarray (n_steps, n_contacts)
        Contact impulses ``>= 0`` accumulated over the steps since the previous sample (row 0 is
        zero). For penalty contacts, the integrated penalty force ``h (theta p_{k+1} +
        (1 - theta) p_k)``.
    energy : ndarray (n_steps,)
        Mechanical energy ``1/2 v.M v + 1/2 u.K u + sum k3 u^4/4 + sum k_p max(0, u - g)^2/2``.
    gap : ndarray (n_steps, n_contacts)
        Normal gaps ``g_N = gap - u_c`` (negative = penetration).
    dt : float
        Time step actually used (adjusted so that an integer number of steps reaches ``t_end``).
    """

    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    impulse: np.ndarray
    energy: np.ndarray
    gap: np.ndarray
    dt: float

    def contact_force(self) -> np.ndarray:
        """Average contact force over each sample interval, ``impulse / (t_i - t_{i-1})``.

        Row 0 is zero. Shape ``(n_steps, n_contacts)``.
        """
        out = np.zeros_like(self.impulse)
        if self.t.size > 1:
            out[1:] = self.impulse[1:] / np.diff(self.t)[:, None]
        return out


@dataclass(frozen=True, eq=False)
class SteadyState:
    """Last period of a forced time integration run until it repeats.

    Attributes
    ----------
    t, u, v, impulse, gap, energy : ndarray
        Samples over one (``nu``-fold) period, ``t`` from its start to its end inclusive.
    period : float
        Period of the orbit, ``nu * 2 pi / omega``.
    nu : int
        Sub-harmonic order (1 = locked to the forcing; up to 4 is detected).
    amplitude : ndarray (n_dofs,)
        ``max_t |u|`` over the orbit.
    converged : bool
        Whether the state at period starts repeated to ``tol``.
    n_periods : int
        Forcing periods integrated.
    change : float
        Last relative change of the period-start state (the convergence measure).
    dt : float
        Time step used (``2 pi / (omega N)``).
    """

    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    impulse: np.ndarray
    gap: np.ndarray
    energy: np.ndarray
    period: float
    nu: int
    amplitude: np.ndarray
    converged: bool
    n_periods: int
    change: float
    dt: float

    def contact_force(self) -> np.ndarray:
        """Average contact force per step, ``impulse / dt``."""
        return self.impulse / self.dt


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------
def _real(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def _state(x: Any, name: str, n: int) -> np.ndarray:
    if x is None:
        return np.zeros(n)
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a real array of shape ({n},), got {type(x).__name__}") from exc
    if arr.ndim == 0 and n == 1:
        arr = arr.reshape(1)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) (one value per model DOF), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr.copy()


def _check_model(model: Any, owner: str) -> StructuralModel:
    if not isinstance(model, StructuralModel):
        raise TypeError(f"{owner}: model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
    return model


def _check_omega(model: StructuralModel, omega: Any, owner: str) -> float | None:
    harmonic = any(a.item.harmonic >= 1 for a in model.forces)
    if omega is None:
        if harmonic:
            raise ValueError(f"{owner}: omega (forcing frequency, rad/s) is required: the model has harmonic forcing")
        return None
    w = _real(omega, "omega")
    if w <= 0:
        raise ValueError(f"{owner}: omega must be > 0, got {omega!r}")
    if not harmonic:
        raise ValueError(
            f"{owner}: omega={omega!r} given but the model has no harmonic forcing (add with_forcing or omit omega)"
        )
    return w


# --------------------------------------------------------------------------------------------
# The stepper
# --------------------------------------------------------------------------------------------
class _Stepper:
    """Precomputed operators of the Moreau-Jean step for a fixed ``h`` (see module docstring)."""

    def __init__(self, model: StructuralModel, h: float, theta: float, restitution: float, omega: float | None):
        n = model.n_dofs
        self.n, self.h, self.theta, self.e = n, h, theta, restitution
        M, K, C = model.M.tocsr(), model.K.tocsr(), model.C.tocsr()
        dM = M.diagonal()
        scale = float(np.max(np.abs(dM))) if dM.size else 1.0
        massless = dM <= 1e-14 * scale
        if np.any(massless):
            rows = abs(M)[massless].max() if M.nnz else 0.0
            if rows > 1e-12 * scale:
                raise ValueError("model: M has a zero diagonal entry on a DOF whose row is not zero (M is not PSD)")
            log.info("%d massless DOFs treated as quasi-static (theta = 1 on their rows)", int(massless.sum()))
        self.massless = massless
        th = np.where(massless, 1.0, theta)
        self.th = th
        Th = sp.diags(th)
        A = (M + h * (Th @ C) + h * h * (Th @ K @ Th)).tocsc()
        self.dense = n <= _DENSE_LIMIT
        if self.dense:
            self.M, self.K, self.C = M.toarray(), K.toarray(), C.toarray()
            Ad = A.toarray()
            try:
                self.Ainv = np.linalg.inv(Ad)
            except np.linalg.LinAlgError as exc:
                raise ValueError(
                    "model: the iteration matrix M + h theta C + h^2 theta^2 K is singular (a massless DOF without stiffness?)"
                ) from exc
            if not np.all(np.isfinite(self.Ainv)) or np.linalg.cond(Ad) > 1e15:
                raise ValueError("model: the iteration matrix M + h theta C + h^2 theta^2 K is singular")
            self.solve = lambda r: self.Ainv @ r
        else:
            self.M, self.K, self.C = M, K, C
            try:
                lu = spla.splu(A)
            except RuntimeError as exc:
                raise ValueError(
                    "model: the iteration matrix M + h theta C + h^2 theta^2 K is singular (a massless DOF without stiffness?)"
                ) from exc
            self.solve = lu.solve
        self.has_C = C.nnz > 0

        # forcing: only forced DOFs
        fv = model.force_vectors()
        self.omega = omega
        forced = sorted({a.dof for a in model.forces})
        self.fidx = np.asarray(forced, dtype=int)
        ks = sorted(k for k in fv if k >= 1)
        self.fk = np.asarray(ks, dtype=float)
        self.Fk = np.array([fv[k][self.fidx] for k in ks]).reshape(len(ks), self.fidx.size)
        self.f0 = np.real(fv[0][self.fidx]) if 0 in fv else np.zeros(self.fidx.size)
        self.thf = th[self.fidx]

        # local DOFs: contacts and smooth nonlinearities
        contacts = list(model.contacts)
        smooth = [(a.item, a.dof) for a in model.nonlinearities]
        smooth += [(a.item, a.dof) for a in contacts if isinstance(a.item, PenaltyContact)]
        S = sorted({d for _, d in smooth} | {a.dof for a in contacts if isinstance(a.item, UnilateralContact)})
        self.S = np.asarray(S, dtype=int)
        pos = {d: i for i, d in enumerate(S)}
        s = len(S)
        # smooth laws on local DOFs, each kind evaluated at once by its stacked law (femodes.laws):
        # (stacked law, local positions, whether a position repeats) per kind; the positions are a
        # slice when contiguous (a view: smooth_force runs in every local Newton iteration)
        cubic = sorted(((law, pos[d]) for law, d in smooth if isinstance(law, CubicSpring)), key=lambda ld: ld[1])
        penalty = [(law, pos[d]) for law, d in smooth if isinstance(law, PenaltyContact)]
        self.smooth_laws = []
        for kind, group in ((CubicSpring, cubic), (PenaltyContact, penalty)):
            if group:
                loc = np.asarray([i for _, i in group], dtype=int)
                if np.array_equal(loc, np.arange(loc[0], loc[0] + loc.size)):
                    loc = slice(int(loc[0]), int(loc[0]) + loc.size)
                repeats = not isinstance(loc, slice) and np.unique(loc).size < loc.size
                self.smooth_laws.append((kind.stack(law for law, _ in group), loc, repeats))
        self.has_smooth = bool(self.smooth_laws)
        self.smooth_everywhere = (len(self.smooth_laws) == 1 and isinstance(self.smooth_laws[0][1], slice)
                                  and self.smooth_laws[0][1] == slice(0, s))
        # unilateral contacts
        self.uc = [j for j, a in enumerate(contacts) if isinstance(a.item, UnilateralContact)]
        self.uc_loc = np.asarray([pos[contacts[j].dof] for j in self.uc], dtype=int)
        self.uc_dof = np.asarray([contacts[j].dof for j in self.uc], dtype=int)
        self.uc_law = UnilateralContact.stack(contacts[j].item for j in self.uc)
        self.uc_massless = massless[self.uc_dof] if self.uc else np.zeros(0, dtype=bool)
        self.pc = [j for j, a in enumerate(contacts) if isinstance(a.item, PenaltyContact)]
        self.pc_dof = np.asarray([contacts[j].dof for j in self.pc], dtype=int)
        self.pc_law = [contacts[j].item for j in self.pc]
        self.n_contacts = len(contacts)
        self.c_dof = np.asarray([a.dof for a in contacts], dtype=int)
        self.c_law = [a.item for a in contacts]
        self.thS = th[self.S]
        if s:
            B = np.zeros((n, s))
            B[self.S, np.arange(s)] = 1.0
            Z = self.solve(B) if self.dense else np.column_stack([self.solve(B[:, i]) for i in range(s)])
            self.Z = np.asarray(Z).reshape(n, s)
            self.W = self.Z[self.S, :]  # local Delassus operator B^T A^-1 B
        else:
            self.Z = np.zeros((n, 0))
            self.W = np.zeros((0, 0))
        self.Wuc = self.W[np.ix_(self.uc_loc, self.uc_loc)] if self.uc else np.zeros((0, 0))
        if self.uc and np.any(np.diag(self.Wuc) <= 0):
            raise ValueError("model: non-positive Delassus operator at a contact DOF")
        self.P_prev = np.zeros(len(self.uc))
        self.n_newton_fail = 0
        if self.dense:
            # state x = [q; v]: free step x_f = Phi x + Gam f_theta, correction Psi lam
            Ai, Kd, Cd = self.Ainv, self.K, self.C
            Dq = -h * (Ai @ Kd)
            Dv = -(Ai @ ((h * h) * th[:, None] * Kd + h * Cd))
            I = np.eye(n)
            self.Phi = np.block([[I + h * th[:, None] * Dq, h * I + h * th[:, None] * Dv], [Dq, I + Dv]])
            G = h * Ai[:, self.fidx]
            self.Gam = np.vstack([h * th[:, None] * G, G])
            self.Psi = np.vstack([h * th[:, None] * self.Z, self.Z])

    # -- pieces ----------------------------------------------------------------------------------
    def force(self, t: float) -> np.ndarray:
        """Forces at the forced DOFs at time ``t``."""
        f = self.f0.copy()
        if self.fk.size:
            f += np.real(np.exp(1j * self.omega * t * self.fk) @ self.Fk)
        return f

    def smooth_force(self, qS: np.ndarray):
        """Local smooth forces (cubic + penalty) and derivatives on the local DOFs."""
        if self.smooth_everywhere:  # one kind of law, one on every local DOF
            return self.smooth_laws[0][0].force(qS)
        f = np.zeros(qS.shape)
        df = np.zeros(qS.shape)
        for law, loc, repeats in self.smooth_laws:
            fl, dfl = law.force(qS[loc])
            if repeats:  # several laws on one DOF (cubic springs): accumulate
                np.add.at(f, loc, fl)
                np.add.at(df, loc, dfl)
            else:
                f[loc] += fl
                df[loc] += dfl
        return f, df

    def smooth_potential(self, qS: np.ndarray) -> np.ndarray:
        """Potential energy of the smooth laws, ``qS`` of shape ``(..., |S|)`` -> shape ``(...)``."""
        E = np.zeros(qS.shape[:-1])
        for law, loc, _ in self.smooth_laws:
            E += np.sum(law.potential(qS[..., loc]), axis=-1)
        return E

    def energy(self, q, v, Kq) -> float:
        E = 0.5 * float(v @ (self.M @ v)) + 0.5 * float(q @ Kq)
        if self.S.size:
            E += float(self.smooth_potential(q[self.S]))
        return E

    # -- the local problem ------------------------------------------------------------------------
    def _local(self, q0S, v0S, dvfS, active, b):
        """Solve for the local generalized impulses ``lam`` (on S) and contact impulses ``P``.

        ``lam + h theta f_s(q1_S) + E P = 0`` (with ``h (1-theta) f_s(q0)`` already in the free
        step), ``FB(P_c, y_c / W_cc) = 0`` for active contacts, ``P_c = 0`` otherwise, with
        ``y_c = b_c - v1_c``.
        """
        h, W, thS = self.h, self.W, self.thS
        s = self.S.size
        ia = np.flatnonzero(active)
        na = ia.size
        loc_a = self.uc_loc[ia]
        # Linear fast path: no smooth law -> lam = -E P, an LCP in P with Delassus Wa.
        if not self.has_smooth:
            P = np.zeros(len(self.uc))
            if na == 0:
                return np.zeros(s), P, True
            Wa = self.Wuc[np.ix_(ia, ia)]
            yfree = b[ia] - (v0S[loc_a] + dvfS[loc_a])
            if na == 1:
                P[ia] = max(0.0, -yfree[0] / Wa[0, 0])
                ok = True
            else:
                Pa, ok = _lcp(Wa, yfree, self.P_prev[ia])
                P[ia] = Pa
            lam = np.zeros(s)
            np.subtract.at(lam, loc_a, P[ia])
            return lam, P, ok
        # General semismooth Newton on z = [lam (s), P_a (na)].
        sig = np.diag(W)[loc_a] if na else np.zeros(0)
        z = np.zeros(s + na)
        if na:
            z[s:] = self.P_prev[ia]
            np.subtract.at(z[:s], loc_a, z[s:])
        base_q = q0S + h * v0S + h * thS * dvfS
        v1free = v0S + dvfS

        def F(z):
            lam, Pa = z[:s], z[s:]
            Wl = W @ lam
            q1 = base_q + h * thS * Wl
            fs, dfs = self.smooth_force(q1)
            r1 = lam + h * thS * fs
            if na:
                np.add.at(r1, loc_a, Pa)
            J = np.zeros((s + na, s + na))
            J[:s, :s] = np.eye(s) + (h * h * thS * thS * dfs)[:, None] * W
            if na == 0:
                return r1, J
            J[loc_a, s + np.arange(na)] += 1.0
            y = (b[ia] - (v1free[loc_a] + Wl[loc_a])) / sig
            r2, da, db = _fischer_burmeister(Pa, y)
            J[s:, :s] = -(db / sig)[:, None] * W[loc_a, :]
            J[s:, s:] = np.diag(da)
            return np.concatenate([r1, r2]), J

        r, J = F(z)
        nr = float(np.linalg.norm(r))
        scale = 1.0 + float(np.linalg.norm(z))
        ok = False
        for _ in range(_LOCAL_MAXIT):
            if nr <= _LOCAL_TOL * scale:
                ok = True
                break
            try:
                dz = np.linalg.solve(J, -r)
            except np.linalg.LinAlgError:
                dz = np.linalg.lstsq(J, -r, rcond=None)[0]
            alpha = 1.0
            while True:
                zt = z + alpha * dz
                rt, Jt = F(zt)
                nt = float(np.linalg.norm(rt))
                if nt <= (1.0 - 1e-4 * alpha) * nr or alpha < 1e-10:
                    break
                alpha *= 0.5
            z, r, J, nr = zt, rt, Jt, nt
            scale = 1.0 + float(np.linalg.norm(z))
            if np.linalg.norm(alpha * dz) <= 1e-15 * scale:
                ok = nr <= 1e-9 * scale
                break
        P = np.zeros(len(self.uc))
        P[ia] = np.maximum(z[s:], 0.0)
        return z[:s], P, ok

    # -- one step --------------------------------------------------------------------------------
    def step(self, t0, q0, v0, Kq0, f0, f1):
        """Advance ``(q0, v0)`` by one step; returns ``q1, v1, Kq1, contact impulses``."""
        h, th = self.h, self.th
        Kv0 = self.K @ v0
        r = -h * Kq0 - (h * h) * th * Kv0
        if self.has_C:
            r -= h * (self.C @ v0)
        if self.fidx.size:
            r[self.fidx] += h * (self.thf * f1 + (1.0 - self.thf) * f0)
        S = self.S
        imp = np.zeros(self.n_contacts)
        if S.size:
            q0S, v0S = q0[S], v0[S]
            if self.has_smooth:
                fs0, _ = self.smooth_force(q0S)
                r[S] -= h * (1.0 - self.thS) * fs0
            dvf = self.solve(r)
            dvfS = dvf[S]
            if self.uc:
                qc, vc = q0[self.uc_dof], v0[self.uc_dof]
                g0 = self.uc_law.gap_function(qc)
                # massless: position-level Signorini at t_{k+1} (always in the problem)
                # massive: Newton impact law, active if the predicted gap g0 - h/2 v0 <= 0
                active = self.uc_massless | (g0 - 0.5 * h * vc <= 0.0)
                b = np.where(self.uc_massless, g0 / h, -self.e * vc)
            else:
                active = np.zeros(0, dtype=bool)
                b = np.zeros(0)
            lam, P, ok = self._local(q0S, v0S, dvfS, active, b)
            if not ok:
                self.n_newton_fail += 1
                if self.n_newton_fail <= 5:
                    log.warning("Moreau-Jean: local contact/nonlinear problem not converged at t = %.6g", t0)
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
        return q1, v1, Kq1, imp

    def penalty_impulse(self, q0, q1) -> np.ndarray:
        """Impulses of the penalty contacts over a step, ``h (theta p(q1) + (1 - theta) p(q0))``."""
        imp = np.zeros(self.n_contacts)
        for j, law, d in zip(self.pc, self.pc_law, self.pc_dof):
            p0 = float(law.force(q0[d])[0])
            p1 = float(law.force(q1[d])[0])
            imp[j] = self.h * (self.th[d] * p1 + (1.0 - self.th[d]) * p0)
        return imp


def _fischer_burmeister(a: np.ndarray, b: np.ndarray):
    """``phi(a, b) = a + b - sqrt(a^2 + b^2)`` (zero iff ``0 <= a perp b >= 0``) and its partials.

    At ``a = b = 0`` the element ``(1 - 1/sqrt 2, 1 - 1/sqrt 2)`` of the generalized Jacobian is used.
    """
    rr = np.sqrt(a * a + b * b)
    safe = rr > 0
    da = np.where(safe, 1.0 - a / np.where(safe, rr, 1.0), 1.0 - 1.0 / math.sqrt(2.0))
    db = np.where(safe, 1.0 - b / np.where(safe, rr, 1.0), 1.0 - 1.0 / math.sqrt(2.0))
    return a + b - rr, da, db


def _lcp(W: np.ndarray, q: np.ndarray, x0: np.ndarray, tol: float = 1e-14, maxit: int = 100):
    """Solve ``0 <= x  perp  W x + q >= 0`` by semismooth Newton on Fischer-Burmeister (small W).

    Unknown scaled by ``diag(W)``; Armijo backtracking on ``1/2 |phi|^2``.
    """
    d = np.diag(W).copy()
    x = np.maximum(x0, 0.0)

    def phi(x):
        y = (W @ x + q) / d
        r, da, db = _fischer_burmeister(x, y)
        J = np.diag(da) + (db / d)[:, None] * W
        return r, J

    r, J = phi(x)
    nr = float(np.linalg.norm(r))
    xscale = 1.0 + float(np.max(np.abs(q / d)))
    for _ in range(maxit):
        if nr <= tol * xscale:
            return np.maximum(x, 0.0), True
        dx = np.linalg.solve(J, -r)
        a = 1.0
        while True:
            xt = x + a * dx
            rt, Jt = phi(xt)
            nt = float(np.linalg.norm(rt))
            if nt <= (1.0 - 1e-4 * a) * nr or a < 1e-12:
                break
            a *= 0.5
        x, r, J, nr = xt, rt, Jt, nt
    return np.maximum(x, 0.0), nr <= 1e-9 * xscale


# --------------------------------------------------------------------------------------------
# Drivers
# --------------------------------------------------------------------------------------------
def _check_common(model, dt, restitution, theta, owner):
    model = _check_model(model, owner)
    dt = _real(dt, "dt")
    if dt <= 0:
        raise ValueError(f"{owner}: dt must be > 0, got {dt!r}")
    e = _real(restitution, "restitution")
    if not 0.0 <= e <= 1.0:
        raise ValueError(f"{owner}: restitution must be in [0, 1], got {restitution!r}")
    th = _real(theta, "theta")
    if not 0.5 <= th <= 1.0:
        raise ValueError(f"{owner}: theta must be in [0.5, 1], got {theta!r}")
    return model, dt, e, th


def _energies(st: _Stepper, U: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Mechanical energy of stored samples (vectorised)."""
    MV = np.asarray(st.M @ V.T).T
    KU = np.asarray(st.K @ U.T).T
    E = 0.5 * np.einsum("ij,ij->i", V, MV) + 0.5 * np.einsum("ij,ij->i", U, KU)
    if st.S.size:
        E += st.smooth_potential(U[:, st.S])
    return E


def _integrate(st: _Stepper, t0: float, n_steps: int, q, v, store_every: int = 1):
    """Run ``n_steps`` steps from ``(q, v)`` at ``t0``; store every ``store_every`` step (and the last).

    Returns ``t, u, v, impulse, energy, gap`` arrays of the stored samples.
    """
    h = st.h
    idx = np.arange(0, n_steps + 1, store_every)
    if idx[-1] != n_steps:
        idx = np.append(idx, n_steps)
    ns = idx.size
    store = np.zeros(n_steps + 1, dtype=bool)
    store[idx] = True
    n, nc = st.n, st.n_contacts
    U = np.empty((ns, n))
    V = np.empty((ns, n))
    IMP = np.zeros((ns, nc))
    U[0], V[0] = q, v
    tk = t0 + h * np.arange(n_steps + 1)
    forced = st.fidx.size > 0
    if forced:
        if st.fk.size:
            fall = np.real(np.exp(1j * st.omega * np.outer(tk, st.fk)) @ st.Fk) + st.f0
        else:
            fall = np.tile(st.f0, (n_steps + 1, 1))
        fth = st.thf * fall[1:] + (1.0 - st.thf) * fall[:-1]
    k_store = 1
    acc = np.zeros(nc)
    S = st.S
    has_local = S.size > 0
    if st.dense:
        x = np.concatenate([q, v])
        Phi, Psi = st.Phi, st.Psi
        fx = fth @ st.Gam.T if forced else None
        uc = st.uc
        if uc:
            ucd, ucv = st.uc_dof, n + st.uc_dof
            gap_function, mless, e = st.uc_law.gap_function, st.uc_massless, st.e
            nless = not np.any(mless)
        vS_idx = n + S
        for k in range(n_steps):
            xf = Phi @ x
            if forced:
                xf += fx[k]
            if has_local:
                q0S, v0S = x[S], x[vS_idx]
                if st.has_smooth:
                    fs0, _ = st.smooth_force(q0S)
                    xf += Psi @ (-h * (1.0 - st.thS) * fs0)
                if uc:
                    qc, vc = x[ucd], x[ucv]
                    g0 = gap_function(qc)
                    if nless:
                        active = g0 - 0.5 * h * vc <= 0.0
                        if not st.has_smooth and not active.any():
                            x = xf
                            st.P_prev = np.zeros(len(uc))
                            if store[k + 1]:
                                U[k_store], V[k_store] = x[:n], x[n:]
                                IMP[k_store] = acc
                                acc = np.zeros(nc)
                                k_store += 1
                            continue
                        b = -e * vc
                    else:
                        active = mless | (g0 - 0.5 * h * vc <= 0.0)
                        b = np.where(mless, g0 / h, -e * vc)
                else:
                    active = np.zeros(0, dtype=bool)
                    b = active
                dvfS = xf[vS_idx] - v0S
                lam, P, ok = st._local(q0S, v0S, dvfS, active, b)
                if not ok:
                    st.n_newton_fail += 1
                    if st.n_newton_fail <= 5:
                        log.warning("Moreau-Jean: local contact/nonlinear problem not converged at t = %.6g", tk[k])
                st.P_prev = P
                x_new = xf + Psi @ lam
                if nc:
                    if uc:
                        acc[uc] += P
                    if st.pc:
                        acc += st.penalty_impulse(x[:n], x_new[:n])
                x = x_new
            else:
                x = xf
            if store[k + 1]:
                U[k_store], V[k_store] = x[:n], x[n:]
                IMP[k_store] = acc
                acc = np.zeros(nc)
                k_store += 1
        q, v = x[:n], x[n:]
    else:
        Kq = st.K @ q
        f0 = f1 = None
        for k in range(n_steps):
            if forced:
                f0, f1 = fall[k], fall[k + 1]
            q, v, Kq, imp = st.step(tk[k], q, v, Kq, f0, f1)
            if nc:
                acc += imp
            if store[k + 1]:
                U[k_store], V[k_store] = q, v
                IMP[k_store] = acc
                acc = np.zeros(nc)
                k_store += 1
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
        raise FloatingPointError("Moreau-Jean integration diverged (non-finite state); reduce dt")
    E = _energies(st, U, V)
    G = (np.column_stack([law.gap_function(U[:, d]) for law, d in zip(st.c_law, st.c_dof)]) if nc
         else np.zeros((ns, 0)))
    return tk[idx], U, V, IMP, E, G


def simulate(
    model: StructuralModel,
    t_end: float,
    dt: float,
    *,
    u0=None,
    v0=None,
    omega: float | None = None,
    restitution: float = 1.0,
    theta: float = 0.5,
    t0: float = 0.0,
    store_every: int = 1,
) -> TimeHistory:
    r"""Moreau-Jean time-stepping of a model with unilateral contact (Jean 1999; Moreau 1988).

    .. math::

        M \Delta v = h\,\Theta F_{k+1} + h (I - \Theta) F_k - \sum_c e_c P_c, \quad
        0 \le U_{c,k+1} + e\,U_{c,k} \perp P_c \ge 0 \ \text{(predicted gap} \le 0),

    see :mod:`femodes.time.moreau` and Acary & Brogliato (2008), chapter 10.

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        Linear structure with UnilateralContact / PenaltyContact / CubicSpring declarations and
        optional harmonic forcing ``Re sum_k F_k e^{i k omega t}``.
    t_end : float
        Final time (``> t0``).
    dt : float
        Time step (``0 < dt < t_end - t0``); reduced so that an integer number of steps fits.
    u0, v0 : array_like (n_dofs,), optional
        Initial displacement and velocity (zero by default).
    omega : float, optional
        Forcing frequency (rad/s): required if the model has harmonic forcing, refused otherwise.
    restitution : float
        Newton restitution coefficient ``e`` in ``[0, 1]`` (massive contact DOFs; a contact on a
        massless DOF is quasi-static and uses the position-level Signorini law).
    theta : float
        Theta-method parameter in ``[1/2, 1]`` (1/2: trapezoidal, energy conserving for linear
        parts; 1: backward Euler, dissipative).
    t0 : float
        Initial time.
    store_every : int
        Store every ``store_every``-th step (the last step is always stored).

    Returns
    -------
    TimeHistory

    Raises
    ------
    TypeError, ValueError
        Invalid arguments (the message names the argument).
    """
    model, dt, e, th = _check_common(model, dt, restitution, theta, "simulate")
    t0 = _real(t0, "t0")
    t_end = _real(t_end, "t_end")
    if t_end <= t0:
        raise ValueError(f"simulate: t_end must be > t0 = {t0}, got {t_end!r}")
    if not math.isfinite(t_end - t0):
        raise ValueError(f"simulate: t_end - t0 overflows: t_end={t_end!r}, t0={t0!r}")
    if dt >= t_end - t0:
        raise ValueError(f"simulate: dt must be smaller than t_end - t0 = {t_end - t0:g}, got {dt!r}")
    if isinstance(store_every, bool) or not isinstance(store_every, (int, np.integer)) or store_every < 1:
        raise ValueError(f"simulate: store_every must be an integer >= 1, got {store_every!r}")
    w = _check_omega(model, omega, "simulate")
    n = model.n_dofs
    q = _state(u0, "u0", n)
    v = _state(v0, "v0", n)
    n_steps = _n_steps(t_end - t0, dt, "t_end - t0", "simulate")
    n_stored = (n_steps // int(store_every) + 2) * max(n, 1)
    if n_stored > _MAX_STORED:
        raise ValueError(
            f"simulate: storing {n_steps} steps of {n} DOFs every store_every={store_every} step(s) needs "
            f"{n_stored:.3g} values per array (more than {_MAX_STORED:.3g}); increase store_every or dt"
        )
    h = (t_end - t0) / n_steps
    st = _Stepper(model, h, th, e, w)
    for j, a in enumerate(model.contacts):
        g = float(a.item.gap_function(q[a.dof]))
        if g < 0:
            log.warning("simulate: initial penetration %.3g at contact %d", g, j)
    T, U, V, IMP, E, G = _integrate(st, t0, n_steps, q, v, int(store_every))
    log.info("simulate: %d steps of %.4g, %d local Newton failures", n_steps, h, st.n_newton_fail)
    return TimeHistory(t=T, u=U, v=V, impulse=IMP, energy=E, gap=G, dt=h)


def steady_state(
    model: StructuralModel,
    omega: float,
    *,
    dt: float,
    n_periods_max: int = 2000,
    tol: float = 1e-8,
    u0=None,
    v0=None,
    periods_per_check: int = 1,
    restitution: float = 1.0,
    theta: float = 0.5,
) -> SteadyState:
    r"""Periodic steady state of a forced model by Moreau-Jean integration, period after period.

    The step is ``h = T / N`` with ``T = 2 pi / omega`` and ``N = ceil(T / dt)``, so the discrete
    map over one forcing period ``x_j -> x_{j+1}`` (``x = (q, v)`` at ``t = j T``) is iterated until
    ``|x_j - x_{j-nu}| <= tol |x_j|`` (displacements and velocities measured separately) for the
    smallest ``nu`` in 1..4. The last ``nu`` periods are returned.

    Parameters
    ----------
    model : StructuralModel or ReducedModel
        With harmonic forcing.
    omega : float
        Forcing frequency (rad/s).
    dt : float
        Largest time step.
    n_periods_max : int
        Bound on the forcing periods integrated (non-convergence is reported, never a hang).
    tol : float
        Relative tolerance of the period-start state.
    u0, v0 : array_like, optional
        Initial state at ``t = 0``.
    periods_per_check : int
        Check convergence every this many periods.
    restitution, theta : float
        As in :func:`simulate`.

    Returns
    -------
    SteadyState
    """
    model, dt, e, th = _check_common(model, dt, restitution, theta, "steady_state")
    w = _check_omega(model, omega, "steady_state")
    if w is None:
        raise ValueError("steady_state: omega is required")
    for name, val in (("n_periods_max", n_periods_max), ("periods_per_check", periods_per_check)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
            raise ValueError(f"steady_state: {name} must be an integer >= 1, got {val!r}")
    tol = _real(tol, "tol")
    if tol <= 0:
        raise ValueError(f"steady_state: tol must be > 0, got {tol!r}")
    T = 2.0 * math.pi / w
    if dt >= T:
        raise ValueError(f"steady_state: dt must be smaller than the forcing period {T:g}, got {dt!r}")
    n = model.n_dofs
    q = _state(u0, "u0", n)
    v = _state(v0, "v0", n)
    N = _n_steps(T, dt, "the forcing period 2 pi / omega", "steady_state")
    if N * max(n, 1) > _MAX_STORED:
        raise ValueError(
            f"steady_state: dt={dt!r} gives {N} steps per period for {n} DOFs (more than {_MAX_STORED:.3g} stored "
            "values); increase dt"
        )
    h = T / N
    st = _Stepper(model, h, th, e, w)
    starts = [np.concatenate([q, v])]
    history: list = []
    nu, converged, change = 1, False, math.inf
    j = 0
    while j < int(n_periods_max):
        # time restarts at 0 each period: the forcing is T-periodic
        out = _integrate(st, 0.0, N, q, v)
        j += 1
        q, v = out[1][-1].copy(), out[2][-1].copy()
        history.append(out)
        if len(history) > 4:
            history.pop(0)
        starts.append(np.concatenate([q, v]))
        if len(starts) > 6:
            starts.pop(0)
        if j % int(periods_per_check):
            continue
        x = starts[-1]
        sq = max(float(np.linalg.norm(x[:n])), 1e-300)
        sv = max(float(np.linalg.norm(x[n:])), 1e-300)

        def rel(a, b):
            return max(float(np.linalg.norm(a[:n] - b[:n])) / sq, float(np.linalg.norm(a[n:] - b[n:])) / sv)

        best = None
        for m in range(1, 5):
            if len(starts) > m + (1 if m > 1 else 0):
                c = rel(starts[-1], starts[-1 - m])
                if m == 1:
                    change = c
                ok = c <= tol
                if ok and m > 1:  # a genuine period-m orbit: also holds one period earlier
                    ok = rel(starts[-2], starts[-2 - m]) <= tol
                if ok:
                    best = m
                    break
        if best is not None:
            nu, converged = best, True
            break
    if not converged:
        log.warning("steady_state: no periodic state after %d periods (last relative change %.3g)", j, change)
    seg = history[-nu:]
    tt = np.concatenate([seg[0][0]] + [s[0][1:] + (i + 1) * T for i, s in enumerate(seg[1:])])
    cat = lambda k: np.concatenate([seg[0][k]] + [s[k][1:] for s in seg[1:]])  # noqa: E731
    U, V, IMP, E, G = (cat(k) for k in (1, 2, 3, 4, 5))
    amp = np.max(np.abs(U), axis=0)
    log.info("steady_state: w = %.6g, nu = %d, %d periods, change %.3g, converged %s", w, nu, j, change, converged)
    return SteadyState(t=tt, u=U, v=V, impulse=IMP, gap=G, energy=E, period=nu * T, nu=nu, amplitude=amp,
                       converged=converged, n_periods=j, change=change, dt=h)
