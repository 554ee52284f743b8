r"""Event-driven reference for a linear structure with a *massless* unilateral contact DOF.

.. math::

    M q'' + C q' + K q = \mathrm{Re}\Big(\sum_k F_k e^{i k \omega t}\Big) - \lambda(t)\, e_c,
    \qquad q_c \le g, \quad \lambda \ge 0, \quad \lambda\,(q_c - g) = 0 .

Row and column ``c`` of ``M`` and ``C`` are zero; the other DOFs (set ``I``) carry a symmetric
positive definite ``M_II``. Plain numpy/scipy on purpose: nothing is imported from
:mod:`femodes`, so this module checks the closed-form flow of :mod:`femodes.time.exact`
independently instead of repeating it.

Row ``c`` has no inertia, so ``q_c`` is algebraic and the motion is piecewise linear in the
inertial state ``y = [q_I, v_I]``:

* *open* (``lambda = 0``): ``q_c = (F_c(t) - K_cI q_I) / K_cc``, and
  ``M_II q_I'' + C_II v_I + (K_II - K_Ic K_cI / K_cc) q_I = F_I - K_Ic F_c / K_cc``;
* *closed* (``q_c = g``): ``lambda = F_c(t) - K_cI q_I - K_cc g``, and
  ``M_II q_I'' + C_II v_I + K_II q_I = F_I - K_Ic g``.

It closes when the open ``q_c`` reaches ``g`` from below and opens when ``lambda`` reaches 0
from above. At both switches ``q_c`` is continuous (open ``q_c = g`` exactly where
``lambda = 0``), hence so is the force on the inertial DOFs: ``q_I`` is C^2 across a switch
(no impact, no velocity jump), whereas ``q_c`` and ``lambda`` are only C^0 (``v_c`` jumps).

Each mode is integrated by ``solve_ivp`` (DOP853, ``rtol = 1e-12``, ``atol = 1e-14`` times a
response scale) with a terminal, directional event for its switch, restarting in the other
mode from the located state. Grazing switches (event tangent to zero) get no special care.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import cho_factor, cho_solve

__all__ = ["MasslessContactReference", "FlowResult"]

#: ``atol = ATOL * scale``, scale = max(|start state|, static response * max(1, omega)).
RTOL, ATOL = 1e-12, 1e-14
#: Newton on the period map stops at ``max|residual| <= NEWTON_TOL * scale``.
NEWTON_TOL = 1e-10
#: Bound on switches in one run (a Zeno accumulation would otherwise loop forever).
MAX_SWITCHES = 100_000


@dataclass
class FlowResult:
    """Outcome of :meth:`MasslessContactReference.run` over ``[t0, t1]``.

    ``x_end`` (2n,): full state ``[q; v]`` at ``t1``, ``q_c, v_c`` from the mode active there;
    ``switches``: list of ``(time, "close" | "open")`` in time order; ``t0, t1``: the interval.
    """

    x_end: np.ndarray
    switches: list
    t0: float
    t1: float
    _segments: list = field(repr=False, default_factory=list)   # (ta, tb, mode, dense, y(tb))
    _ref: MasslessContactReference = field(repr=False, default=None)

    def _eval(self, t, what):
        t = np.asarray(t, dtype=float)
        ts = np.atleast_1d(t).ravel()
        starts = np.array([s[0] for s in self._segments])
        idx = np.clip(np.searchsorted(starts, ts, side="right") - 1, 0, len(starts) - 1)
        out = np.empty((ts.size, self._ref.n)) if what == "q" else np.empty(ts.size)
        for j in np.unique(idx):
            sel = idx == j
            _, _, mode, sol, y_end = self._segments[j]
            tt = ts[sel]
            y = sol(tt) if sol is not None else np.repeat(y_end[:, None], tt.size, axis=1)
            x = self._ref._full(tt, y, mode)
            out[sel] = x[:self._ref.n].T if what == "q" else self._ref._lam(tt, y, mode)
        return out.reshape(t.shape + out.shape[1:])

    def q(self, t):
        """Full displacement at ``t`` in ``[t0, t1]``: scalar -> (n,), shape S -> S + (n,)."""
        return self._eval(t, "q")

    def lam(self, t):
        """Contact force ``lambda(t) >= 0`` (0 while open), same shape as ``t``."""
        return self._eval(t, "lam")


class MasslessContactReference:
    """Piecewise-linear flow with a massless contact DOF ``dof`` against a stop at ``gap``.

    ``M, K, C`` (n, n): symmetric, row and column ``dof`` of ``M`` and ``C`` zero (else
    ``ValueError``), ``M_II`` positive definite, ``K_cc > 0``. ``forces``: ``{k >= 0: complex
    (n,)}``, load ``Re(sum_k F_k e^{i k omega t})``. ``omega``: fundamental frequency (period
    ``T = 2 pi / omega``). ``dof``: contact DOF ``c``; ``gap``: stop ``g`` (``q_c <= g``).
    """

    def __init__(self, M, K, C, forces, omega, dof, gap):
        M, K, C = (np.array(A, dtype=float) for A in (M, K, C))
        n = K.shape[0]
        if any(A.shape != (n, n) for A in (M, K, C)):
            raise ValueError("M, K and C must be square and of the same size")
        if not (n >= 2 and 0 <= dof < n):
            raise ValueError(f"need n >= 2 and 0 <= dof < n, got n={n}, dof={dof}")
        if np.any(M[dof]) or np.any(M[:, dof]) or np.any(C[dof]) or np.any(C[:, dof]):
            raise ValueError(f"row and column {dof} of M and C must be zero (massless contact DOF)")
        if not K[dof, dof] > 0:
            raise ValueError("K_cc must be positive")
        if not (omega > 0 and math.isfinite(gap)):
            raise ValueError("need omega > 0 and a finite gap")
        self.n, self.c, self.omega, self.gap = n, dof, float(omega), float(gap)
        self.period = 2.0 * math.pi / self.omega
        self.I = I = np.array([j for j in range(n) if j != dof], dtype=int)
        try:
            chol = cho_factor(M[np.ix_(I, I)])
        except np.linalg.LinAlgError as exc:
            raise ValueError("M_II must be symmetric positive definite") from exc
        self.ks = np.array(sorted(forces), dtype=float)
        if np.any(self.ks < 0):
            raise ValueError("harmonic indices must be >= 0")
        self.F = F = np.array([np.asarray(forces[k], dtype=complex) for k in sorted(forces)]).reshape(-1, n)
        Kcc, KcI, KIc = K[dof, dof], K[dof, I], K[I, dof]
        self.Kcc, self.KcI = Kcc, KcI
        m = I.size
        Minv = lambda B: cho_solve(chol, B)
        Kopen = K[np.ix_(I, I)] - np.outer(KIc, KcI) / Kcc
        # first-order systems y' = A y + Re(G^T e^{i k w t}) + b for each mode
        self._sys = {}
        for mode, Keff, G, b in (("open", Kopen, (F[:, I] - np.outer(F[:, dof], KIc) / Kcc), np.zeros(m)),
                                 ("closed", K[np.ix_(I, I)], F[:, I], -KIc * self.gap)):
            A = np.zeros((2 * m, 2 * m))
            A[:m, m:] = np.eye(m)
            A[m:, :m] = -Minv(Keff)
            A[m:, m:] = -Minv(C[np.ix_(I, I)])
            GI = np.zeros((F.shape[0], 2 * m), dtype=complex)
            GI[:, m:] = Minv(G.T).T if F.size else 0.0
            bb = np.concatenate([np.zeros(m), Minv(b)])
            self._sys[mode] = (A, GI, bb)
        # displacement scale for atol/Newton: static response to the load magnitudes
        self._uref = float(np.sum(np.abs(F).max(axis=1))) / np.linalg.norm(K, 2) if F.size else 0.0

    # ---- load and algebraic relations ---------------------------------------------------
    def _phase(self, t):
        return np.exp(1j * self.omega * np.multiply.outer(np.atleast_1d(t), self.ks))   # (nt, nk)

    def load(self, t, order=0):
        """``F(t)`` (order 0) or ``F'(t)`` (order 1), shape ``(nt, n)`` for ``t`` of size nt."""
        e = self._phase(t) * (1j * self.omega * self.ks) ** order
        return (e @ self.F).real

    def _qc_open(self, t, y):
        m = self.I.size
        return (self.load(t)[:, self.c] - self.KcI @ y[:m]) / self.Kcc

    def _lam(self, t, y, mode):
        if mode == "open":
            return np.zeros(np.atleast_1d(t).size)
        return self.Kcc * (self._qc_open(t, y) - self.gap)

    def _full(self, t, y, mode):
        """Full state(s) ``[q; v]`` (columns) from inertial state(s) ``y`` (columns)."""
        y = np.asarray(y, dtype=float).reshape(2 * self.I.size, -1)
        m, n = self.I.size, self.n
        x = np.zeros((2 * n, y.shape[1]))
        x[self.I], x[n + self.I] = y[:m], y[m:]
        if mode == "open":
            x[self.c] = self._qc_open(t, y)
            x[n + self.c] = (self.load(t, 1)[:, self.c] - self.KcI @ y[m:]) / self.Kcc
        else:
            x[self.c] = self.gap
        return x

    def _mode_at(self, t, y):
        """Open if the open ``q_c <= g``; else closed, where ``lambda = K_cc (q_c^open - g) > 0``."""
        return "open" if self._qc_open(t, y)[0] <= self.gap else "closed"

    def _inertial(self, x0):
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (2 * self.n,):
            raise ValueError(f"x0 must have shape ({2 * self.n},)")
        return np.concatenate([x0[self.I], x0[self.n + self.I]])

    def _scale(self, y):
        return max(float(np.max(np.abs(y), initial=0.0)), self._uref * max(1.0, self.omega), 1e-300)

    # ---- flow ---------------------------------------------------------------------------
    def _event(self, mode):
        """Terminal switch event: open ``q_c - g`` rising through 0, or ``lambda`` falling through 0."""
        if mode == "open":
            ev = lambda s, z: self._qc_open(s, z)[0] - self.gap
        else:
            ev = lambda s, z: self._lam(s, z, "closed")[0]
        ev.terminal, ev.direction = True, (1.0 if mode == "open" else -1.0)
        return ev

    def run(self, x0, t0, t1) -> FlowResult:
        """Integrate from the full state ``x0`` at ``t0`` to ``t1 >= t0`` (``x0[c], x0[n+c]`` ignored)."""
        if t1 < t0:
            raise ValueError("need t1 >= t0")
        y = self._inertial(x0)
        atol = ATOL * self._scale(y)
        t, mode, segments, switches = float(t0), self._mode_at(t0, y), [], []
        while t < t1:
            A, G, b = self._sys[mode]
            rhs = lambda s, z, A=A, G=G, b=b: A @ z + (self._phase(s)[0] @ G).real + b
            sol = solve_ivp(rhs, (t, t1), y, method="DOP853", rtol=RTOL, atol=atol, events=self._event(mode),
                            dense_output=True)
            if sol.status < 0:
                raise RuntimeError(sol.message)
            segments.append((t, sol.t[-1], mode, sol.sol, sol.y[:, -1]))
            if sol.status != 1:
                y = sol.y[:, -1]
                break
            t, y = float(sol.t_events[0][0]), sol.y_events[0][0]
            mode = "closed" if mode == "open" else "open"
            switches.append((t, "close" if mode == "closed" else "open"))
            if len(switches) > MAX_SWITCHES:
                raise RuntimeError("too many switches (Zeno behaviour?)")
        if not segments or segments[-1][2] != mode:         # t0 == t1, or a switch exactly at t1
            segments.append((t, t, mode, None, y))
        x_end = self._full(t1, y, mode)[:, 0]
        return FlowResult(x_end=x_end, switches=switches, t0=float(t0), t1=float(t1), _segments=segments, _ref=self)

    def coefficients(self, x0, t0, H, samples=2 ** 14):
        """Real Fourier coefficients ``(Q (2H+1, n), L (2H+1,))`` of ``q`` and ``lambda`` on ``[t0, t0 + T]``.

        Order ``[c0, c1, s1, ..., cH, sH]``: ``c0`` the mean, ``ck = (w/pi) int q cos(k w t) dt``,
        ``sk = (w/pi) int q sin(k w t) dt`` (absolute time ``t``). Composite trapezoid rule on
        ``samples`` intervals of the dense output, both ends included (a non-periodic history is
        integrated as it is). ``q_c`` and ``lambda`` have kinks at the switches, where the rule is
        of order 2 only (error ``O(h^2)``); ``q_I`` is C^2 there (``O(h^4)``).
        """
        T = self.period
        res = self.run(x0, t0, t0 + T)
        t = t0 + T * np.arange(samples + 1) / samples
        w = np.full(samples + 1, 1.0 / samples)
        w[[0, -1]] *= 0.5                                   # trapezoid weights of (1/T) int
        basis = [np.ones_like(t)]
        for k in range(1, H + 1):
            basis += [2.0 * np.cos(k * self.omega * t), 2.0 * np.sin(k * self.omega * t)]
        B = np.array(basis) * w                             # (2H+1, samples+1); (w/pi) = 2/T
        return B @ res.q(t), B @ res.lam(t)

    def periodic_orbit(self, x0_guess, t0, max_iter=30):
        """T-periodic orbit by Newton on ``y(t0 + T) - y(t0)`` (inertial part, central
        finite-difference Jacobian, step ``1e-6`` times the scale); stops when the residual is
        below ``1e-10`` times the scale. Returns the full start state ``[q; v]`` at ``t0``."""
        y, T = self._inertial(x0_guess), self.period
        m2 = y.size
        residual = lambda z: self._inertial(self.run(self._full(t0, z, "closed")[:, 0], t0, t0 + T).x_end) - z

        r = residual(y)
        for _ in range(max_iter):
            scale = self._scale(y)
            if np.max(np.abs(r)) <= NEWTON_TOL * scale:
                return self._full(t0, y, self._mode_at(t0, y))[:, 0]
            h = 1e-6 * scale
            J = np.array([residual(y + e) - residual(y - e) for e in h * np.eye(m2)]).T / (2.0 * h)
            step = np.linalg.solve(J, -r)
            alpha = 1.0
            while True:                                     # backtracking on the max norm
                y_new = y + alpha * step
                r_new = residual(y_new)
                if np.max(np.abs(r_new)) < np.max(np.abs(r)) or alpha < 1e-3:
                    break
                alpha *= 0.5
            y, r = y_new, r_new
        raise RuntimeError(f"Newton did not converge in {max_iter} iterations (|r| = {np.max(np.abs(r)):.3e})")
