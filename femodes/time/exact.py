r"""The exact flow of a linear model with rigid stops: closed form between impacts.

Between impacts a model without smooth nonlinear laws is linear, ``x' = A x + b(t)`` with
``x = [q; v]``, ``A = [[0, I], [-M^-1 K, -M^-1 C]]`` and harmonic forcing
``b(t) = Re sum_k [0; M^-1 F_k] e^{i k w t}``. With ``A = V diag(lambda) V^-1`` (diagonalised
once per model; :meth:`LinearImpactFlow.at` changes the frequency) and the particular solution
``x_p(t) = Re sum_k X_k e^{i k w t}``,
``(i k w I - A) X_k = [0; M^-1 F_k]``, the flow is

.. math::

    x(t) = x_p(t) + V\,e^{\Lambda (t - t_a)}\,V^{-1}\bigl(x(t_a) - x_p(t_a)\bigr)

on a free-flight interval starting at ``t_a``. An impact is the first time the gap
``g_N = gap - q_c`` of a :class:`~femodes.laws.UnilateralContact` reaches 0 while approaching;
it is bracketed on a grid of :data:`SAMPLES` points per shortest period of the flow (grazing
minima between grid points are searched too) and located to round-off by Newton on the closed
form, kept in the bracket. Newton's impact law and the saltation matrix are those of
:mod:`femodes.time.shooting` (impulse along ``M^-1 e_c``). No step size, no integration error:
the orbit is exact to round-off and to the root tolerance of the impact times (4 eps).
Restitution below 1 is accepted, but an accumulation of impacts (chattering into sticking) is
refused after :data:`~femodes.time.shooting.MAX_IMPACTS` impacts.

The Fourier coefficients of the orbit follow in closed form as well (integrals of exponentials
over each free-flight interval; impulses for the contact forces), which is what
:mod:`femodes.accuracy` compares harmonic balance solutions with.

Used by :mod:`femodes.accuracy` (shooting refinement of error-controlled branches); the general
event-driven integration with smooth laws is :mod:`femodes.time.shooting`.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import scipy.linalg as sla
from scipy.optimize import minimize_scalar

from ..laws import UnilateralContact
from ..model import StructuralModel
from .shooting import MAX_DOFS, MAX_IMPACTS, unsupported

__all__ = ["LinearImpactFlow", "FlowRun", "exact_flow_unsupported", "SAMPLES", "CHUNK"]

#: Grid points per shortest period of the flow (fastest eigenvalue or forcing harmonic) on which
#: the impacts are bracketed.
SAMPLES = 24
#: Largest number of grid points of one impact search evaluated at once (memory CHUNK x 2n
#: complex numbers); longer searches go chunk by chunk and stop at the first impact.
CHUNK = 4096
#: Largest condition number of the eigenvector matrix (a nearly defective A, e.g. critical
#: damping, makes the modal flow inaccurate).
MAX_CONDITION = 1e8


def exact_flow_unsupported(model: StructuralModel) -> str:
    """Why :class:`LinearImpactFlow` cannot take ``model`` (``""`` if it can): smooth nonlinear
    laws (cubic springs, penalty contacts), no unilateral contact, or what the event-driven
    shooting refuses (:func:`femodes.time.shooting.unsupported`)."""
    if not isinstance(model, StructuralModel):
        return f"model must be a StructuralModel (or ReducedModel), got {type(model).__name__}"
    Md = model.M.diagonal()
    for j, a in enumerate(model.contacts):
        if isinstance(a.item, UnilateralContact) and not Md[a.dof] > 0.0:
            return (f"UnilateralContact {j} (at={a.item.at!r}) acts on DOF {model.dofmap.label(a.dof)!r}, which has "
                    "no mass (redistributed away from the contact): an impact law needs a mass there "
                    "(with_contact(..., contact_mass=fm.ConsistentMass()) keeps it)")
    why = unsupported(model)
    if why:
        return why
    if model.nonlinearities:
        return "the model has smooth nonlinear laws (cubic springs): the flow between impacts is not linear"
    laws = [a.item for a in model.contacts]
    if not laws:
        return "the model has no contact"
    if not all(isinstance(law, UnilateralContact) for law in laws):
        return "the model has penalty contacts: the flow between impacts is not linear"
    return ""


class LinearImpactFlow:
    """Closed-form flow of a linear model with rigid stops at forcing frequency ``omega``."""

    def __init__(self, model: StructuralModel, omega: float, restitution: float = 1.0):
        why = exact_flow_unsupported(model)
        if why:
            raise ValueError(f"LinearImpactFlow: {why}")
        omega = float(omega)
        if not (math.isfinite(omega) and omega > 0.0):
            raise ValueError(f"LinearImpactFlow: omega must be a finite positive frequency, got {omega!r}")
        if not 0.0 <= restitution <= 1.0:
            raise ValueError(f"LinearImpactFlow: restitution must lie in [0, 1], got {restitution!r}")
        n = model.n_dofs
        if n > MAX_DOFS:  # unsupported() has said so; kept for the dense eigenproblem below
            raise ValueError(f"LinearImpactFlow: at most {MAX_DOFS} DOFs")
        self.n, self.e = n, float(restitution)
        M = model.M.toarray()
        Minv = sla.cho_solve(sla.cho_factor(M), np.eye(n))
        self.Minv = 0.5 * (Minv + Minv.T)
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -self.Minv @ model.K.toarray()
        A[n:, n:] = -self.Minv @ model.damping_matrix().toarray()
        self.A = A
        lam, V = np.linalg.eig(A)
        cond = np.linalg.cond(V)
        if not cond < MAX_CONDITION:
            raise ValueError(f"LinearImpactFlow: the state matrix is nearly defective (eigenvector condition "
                             f"{cond:.3g}, e.g. a critically damped mode); its modal flow is not accurate")
        self.lam, self.V, self.Vinv = lam, V, np.linalg.inv(V)
        fv = model.force_vectors()
        self.k = np.array(sorted(fv), dtype=int)
        self.MinvF = [self.Minv @ np.asarray(fv[k]) for k in self.k]
        self.contacts = [(j, a.item, a.dof) for j, a in enumerate(model.contacts)]
        self.dofs = np.array([c for _, _, c in self.contacts], dtype=int)
        self.gaps = np.array([law.gap for _, law, _ in self.contacts], dtype=float)
        # impulse along M^-1 e_c, scaled so that the contact velocity alone is reversed
        self.impact_dir = np.array([self.Minv[:, c] / self.Minv[c, c] for c in self.dofs])
        self._set_omega(omega)

    def _set_omega(self, omega: float) -> None:
        """Particular solution, one complex amplitude per forcing harmonic ``k`` (0: static load),
        and the grid step of the impact search."""
        n, A = self.n, self.A
        X = []
        for k, f in zip(self.k, self.MinvF):
            rhs = np.concatenate([np.zeros(n), f]).astype(complex)
            try:
                X.append(np.linalg.solve(1j * k * omega * np.eye(2 * n) - A, rhs))
            except np.linalg.LinAlgError:
                raise ValueError(f"LinearImpactFlow: forcing harmonic {k} at omega = {omega:g} is at an undamped "
                                 "eigenfrequency (no periodic particular solution)") from None
        self.omega = omega
        self.X = np.array(X).reshape(len(self.k), 2 * n)
        fastest = max(float(np.max(np.abs(self.lam))), float(np.max(self.k, initial=1)) * omega)
        self.dt = 2.0 * math.pi / fastest / SAMPLES

    def at(self, omega: float) -> "LinearImpactFlow":
        """The same model at another forcing frequency (the eigenproblem is not solved again)."""
        omega = float(omega)
        if not (math.isfinite(omega) and omega > 0.0):
            raise ValueError(f"LinearImpactFlow.at: omega must be a finite positive frequency, got {omega!r}")
        new = copy.copy(self)
        new._set_omega(omega)
        return new

    # -- pieces -------------------------------------------------------------------------------
    def particular(self, t) -> np.ndarray:
        """``x_p(t)``, shape ``(len(t), 2n)`` (or ``(2n,)`` for a scalar ``t``)."""
        t = np.asarray(t, dtype=float)
        ph = np.exp(1j * self.omega * np.multiply.outer(t, self.k))
        return np.real(ph @ self.X)

    def field(self, t: float, x: np.ndarray) -> np.ndarray:
        """``x' = A x + b(t)`` (free flight)."""
        xp = self.particular(t)
        return self.A @ (x - xp) + np.real(1j * self.omega * (self.k * np.exp(1j * self.omega * self.k * t)) @ self.X)

    def propagator(self, tau: float) -> np.ndarray:
        """``exp(A tau)`` (real)."""
        return np.real((self.V * np.exp(self.lam * tau)) @ self.Vinv)

    def run(self, x0, t0: float, period: float | None = None, variational: bool = False) -> "FlowRun":
        """The orbit from ``x(t0) = x0`` over ``period`` (default one forcing period)."""
        T = 2.0 * math.pi / self.omega if period is None else float(period)
        return FlowRun(self, np.asarray(x0, dtype=float), float(t0), float(t0) + T, variational)


class FlowRun:
    """One run of :class:`LinearImpactFlow`: end state, monodromy, free-flight segments, impacts.

    Attributes
    ----------
    x_end : ndarray (2n,)
    Phi : ndarray (2n, 2n) or None
        ``d x_end / d x0`` (saltation matrices at the impacts) when ``variational``.
    segments : list of (t_a, t_b, z_a)
        Free-flight intervals with the modal coordinates ``z_a = V^-1 (x(t_a) - x_p(t_a))``.
    impacts : list of (t, contact index, impulse)
        Impulse ``(1 + e) v_c^- / (M^-1)_cc`` (compression positive).
    """

    def __init__(self, flow: LinearImpactFlow, x0: np.ndarray, t0: float, t1: float, variational: bool):
        self.flow, self.t0, self.t1 = flow, t0, t1
        n2 = 2 * flow.n
        if x0.shape != (n2,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"LinearImpactFlow.run: x0 must be {n2} finite numbers, got shape {x0.shape}")
        g0 = flow.gaps - x0[flow.dofs]
        scale = max(float(np.max(np.abs(flow.gaps))), float(np.max(np.abs(x0[:flow.n]))), 1e-300)
        if np.any(g0 < -1e-9 * scale):
            raise ValueError(f"LinearImpactFlow.run: the start state penetrates an obstacle (gap {float(g0.min()):.3g})")
        self.segments: list = []
        self.impacts: list = []
        self.Phi = np.eye(n2) if variational else None
        self.sensitivities: list = []
        t, x = t0, x0.copy()
        while True:
            z = flow.Vinv @ (x - flow.particular(t))
            hit = self._next_impact(t, z, t1)
            tb = t1 if hit is None else hit[0]
            self.segments.append((t, tb, z))
            if variational:
                self.sensitivities.append(self.Phi)  # d x(t_a+) / d x0 of the segment
            x = flow.particular(tb) + np.real(flow.V @ (np.exp(flow.lam * (tb - t)) * z))
            if variational:
                self.Phi = flow.propagator(tb - t) @ self.Phi
            if hit is None:
                break
            if len(self.impacts) >= MAX_IMPACTS:
                raise ValueError(f"LinearImpactFlow.run: more than {MAX_IMPACTS} impacts in one run (an "
                                 "accumulation of impacts)")
            x = self._impact(tb, x, hit[1], variational)
            t = tb
        self.x_end = x

    def _gap_and_rate(self, t: float, z: np.ndarray, tau: np.ndarray):
        """Gaps and their rates at ``t + tau`` (rows) for every contact (columns)."""
        f = self.flow
        E = np.exp(np.multiply.outer(tau, f.lam)) * z  # (m, 2n)
        ph = np.exp(1j * f.omega * np.multiply.outer(t + tau, f.k))  # (m, nk)
        n = f.n
        q = np.real(E @ f.V[f.dofs].T + ph @ f.X[:, f.dofs])
        v = np.real(E @ f.V[n + f.dofs].T + ph @ f.X[:, n + f.dofs])
        return f.gaps - q, -v

    def _next_impact(self, t: float, z: np.ndarray, t1: float, start: float = 0.0):
        """``(time, contact)`` of the first approach to zero gap in ``(t + start, t1]`` (``start``
        > 0: a later chunk of the search, whose first sample is an ordinary one), or None."""
        f = self.flow
        span = t1 - t
        if span <= start:
            return None
        if start > 0.0:
            m = max(2, int(math.ceil((span - start) / f.dt)))
            tau = np.linspace(start, span, m + 1)
            g, r = self._gap_and_rate(t, z, tau)
            return self._first_crossing(t, z, tau, g, r, m, after_impact=False)
        m = max(2, int(math.ceil(span / f.dt)))
        if m > CHUNK:  # a stiff model: search chunk by chunk (memory m x 2n), the first hit ends it
            edges = np.linspace(0.0, span, -(-m // CHUNK) + 1)
            for a, b in zip(edges[:-1], edges[1:]):
                hit = (self._next_impact(t, z, t + b, start=a) if a > 0.0 else self._next_impact(t, z, t + b))
                if hit is not None:
                    return hit
            return None
        tau = np.linspace(0.0, span, m + 1)
        g, r = self._gap_and_rate(t, z, tau)
        return self._first_crossing(t, z, tau, g, r, m, after_impact=True)

    def _first_crossing(self, t, z, tau, g, r, m, after_impact: bool):
        """The earliest crossing on the sampled gaps ``g`` (rates ``r``) at ``t + tau``."""
        best = None
        for c in range(g.shape[1]):
            gc, rc = g[:, c], r[:, c]
            gc0 = max(gc[0], 0.0) if after_impact else gc[0]  # on the stop after an impact (or round-off below)

            def gap(s, c=c):
                return self._scalar(t, z, c, s)[0]

            found = None
            for i in range(1, m + 1):
                a = gc0 if i == 1 else gc[i - 1]
                if gc[i] < 0.0:
                    lo = tau[i - 1]
                    if i == 1 and gc[0] <= 0.0 and after_impact:  # leaving the stop: where does it close?
                        lo = self._leave(gap, tau[0], tau[1])
                        if lo is None:
                            found = None
                            break
                    found = self._root(t, z, c, lo, tau[i])
                    break
                if a > 0.0 and rc[i - 1] < 0.0 < rc[i]:  # a minimum between two grid points: grazing?
                    s_min = self._root(t, z, c, tau[i - 1], tau[i], rate=True)
                    if self._scalar(t, z, c, s_min)[0] < 0.0:
                        found = self._root(t, z, c, tau[i - 1], s_min)
                        break
            if found is not None and (best is None or found < best[0]):
                best = (found, c)
        if best is None:
            return None
        return t + best[0], best[1]

    def _scalar(self, t: float, z: np.ndarray, c: int, s: float) -> tuple[float, float, float]:
        """Gap of contact ``c`` at ``t + s``, its rate and the rate's rate (one point, no arrays
        of times: the root searches call it a few times per impact)."""
        f = self.flow
        e = np.exp(f.lam * s) * z
        ph = np.exp(1j * f.omega * f.k * (t + s))
        row = f.V[f.dofs[c]]
        x = f.X[:, f.dofs[c]]
        q = (row @ e + x @ ph).real
        v = (row @ (f.lam * e) + x @ (1j * f.omega * f.k * ph)).real
        acc = (row @ (f.lam ** 2 * e) + x @ (-(f.omega * f.k) ** 2 * ph)).real
        return f.gaps[c] - q, -v, -acc

    def _root(self, t: float, z: np.ndarray, c: int, a: float, b: float, rate: bool = False) -> float:
        """The zero in ``[a, b]`` of the gap of contact ``c`` (positive at ``a``, negative at
        ``b``), or with ``rate`` of its rate (negative at ``a``, positive at ``b``: the gap's
        minimum): Newton on the closed form with its derivative, kept in the bracket (bisection
        when a step leaves it), to round-off in time."""
        tol = 4.0 * np.finfo(float).eps * max(1.0, abs(t) + abs(b))
        sign = -1.0 if rate else 1.0  # the function is positive at a
        x = 0.5 * (a + b)
        for _ in range(100):
            g, r, dr = self._scalar(t, z, c, x)
            val, der = (sign * r, sign * dr) if rate else (g, r)
            if val > 0.0:
                a = x
            elif val < 0.0:
                b = x
            else:
                return x
            x1 = x - val / der if der != 0.0 else 0.5 * (a + b)
            if not a < x1 < b:
                x1 = 0.5 * (a + b)
            if abs(x1 - x) <= tol or b - a <= tol:
                return x1
            x = x1
        return x

    @staticmethod
    def _leave(gap, a: float, b: float):
        """After an impact the gap starts at 0 and must open: the first sampled interval is
        negative only if the rebound is slower than the forcing pushes back (a re-impact within
        one grid step); the root sought is then the one after the gap's maximum."""
        res = minimize_scalar(lambda s: -gap(s), bounds=(a, b), method="bounded")
        if -res.fun <= 0.0:
            return None
        return res.x

    def _impact(self, t: float, x: np.ndarray, c: int, variational: bool) -> np.ndarray:
        f = self.flow
        n = f.n
        dof = f.dofs[c]
        vc = x[n + dof]
        if vc <= 0.0:  # touching without approach: nothing to reverse
            return x
        self.impacts.append((t, c, (1.0 + f.e) * vc / f.Minv[dof, dof]))
        xp = x.copy()
        xp[n:] -= (1.0 + f.e) * vc * f.impact_dir[c]
        if variational:
            R = np.eye(2 * n)
            R[n:, n + dof] -= (1.0 + f.e) * f.impact_dir[c]
            f_minus, f_plus = f.field(t, x), f.field(t, xp)
            nvec = np.zeros(2 * n)
            nvec[dof] = -1.0
            self.Phi = (R + np.outer(f_plus - R @ f_minus, nvec) / (nvec @ f_minus)) @ self.Phi
        return xp

    # -- Fourier coefficients ---------------------------------------------------------------------
    def _integrals(self, H: int):
        """Per free-flight segment ``int_ta^tb e^{lam_m (t - ta)} e^{-i k w t} dt``, shape
        ``(2n, H + 1)``."""
        f = self.flow
        w = f.omega
        k = np.arange(H + 1)
        mu = np.subtract.outer(f.lam, 1j * k * w)  # (2n, H+1)
        for ta, tb, _ in self.segments:
            d = tb - ta
            x = mu * d
            small = np.abs(x) < 1e-8
            phi1 = np.where(small, 1.0 + 0.5 * x, np.expm1(np.where(small, 1.0, x)) / np.where(small, 1.0, x))
            yield d * phi1 * np.exp(-1j * k * w * ta)

    @staticmethod
    def _real(C: np.ndarray, H: int) -> np.ndarray:
        """Real coefficients ``[c0, c1, s1, ...]`` from ``(w / pi) int q e^{-ikwt} dt`` (rows k)."""
        out = np.zeros((2 * H + 1,) + C.shape[1:])
        out[0] = 0.5 * np.real(C[0])
        out[1::2] = np.real(C[1:])
        out[2::2] = -np.imag(C[1:])
        return out

    def coefficients(self, H: int) -> tuple[np.ndarray, np.ndarray]:
        """Real Fourier coefficients ``[c0, c1, s1, ..., cH, sH]`` of the displacements (shape
        ``(2H + 1, n)``) and of the contact forces (``(2H + 1, n_contacts)``; impulses) over the
        run, in the phase ``theta = w t`` (the conventions of :mod:`femodes.hbm.harmonics`).
        Exact when the run is one period of a periodic orbit."""
        f = self.flow
        n, w = f.n, f.omega
        k = np.arange(H + 1)
        Ic = np.zeros((H + 1, n), dtype=complex)  # int q(t) e^{-i k w t} dt
        Vq = f.V[:n]
        for J, (_, _, z) in zip(self._integrals(H), self.segments):
            Ic += (J.T * z) @ Vq.T
        Q = self._real(Ic * (w / math.pi), H)  # (1/pi) int q e^{-ik theta} dtheta over one period
        # the particular solution is periodic: its coefficients exactly (times the whole period)
        scale = (self.t1 - self.t0) * w / (2.0 * math.pi)
        for kk, Xk in zip(f.k, f.X):
            if kk > H:
                continue
            if kk == 0:
                Q[0] += scale * np.real(Xk[:n])
            else:
                Q[2 * kk - 1] += scale * np.real(Xk[:n])
                Q[2 * kk] -= scale * np.imag(Xk[:n])
        P = np.zeros((2 * H + 1, len(f.dofs)))
        for t, c, imp in self.impacts:
            ph = w * t * k[1:]
            P[0, c] += imp * w / (2.0 * math.pi)
            P[1::2, c] += imp * w / math.pi * np.cos(ph)
            P[2::2, c] += imp * w / math.pi * np.sin(ph)
        return Q, P

    def coefficient_sensitivity(self, H: int) -> np.ndarray:
        """``d Q / d x0`` of :meth:`coefficients`, shape ``(2H + 1, n, 2n)`` (a variational run):
        on each segment ``dq(t)/dx0 = [I 0] V e^{Lambda (t - t_a)} V^-1 Phi_a`` with ``Phi_a``
        the sensitivity after the impact that starts it (saltation included; q is continuous at
        an impact, so a shift of the impact time adds nothing else)."""
        if self.Phi is None:
            raise ValueError("coefficient_sensitivity needs a run with variational=True")
        f = self.flow
        n, w = f.n, f.omega
        Vq = f.V[:n]
        Ic = np.zeros((H + 1, n, 2 * n), dtype=complex)
        for J, Phi_a in zip(self._integrals(H), self.sensitivities):
            Zm = f.Vinv @ Phi_a  # (2n modes, 2n columns)
            Ic += np.einsum("mk,dm,mc->kdc", J, Vq, Zm)
        return self._real(Ic * (w / math.pi), H)
