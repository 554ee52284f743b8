"""Orbits of the exact flow with rigid stops (:class:`femodes.time.exact.LinearImpactFlow`, restitution
1: the limit of harmonic balance with complementarity contacts) on the hyperplanes of a branch's
points: Newton on the start state and the frequency, with the monodromy matrix, the hyperplane's
gradient and the frequency column exact from one variational run (:class:`Shooter`). Where Newton
from a point does not reach an orbit it starts from a neighbour's orbit, through intermediate
planes, from the linear orbit, or at the point's own frequency.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..time.exact import LinearImpactFlow, periodicity_residual
from .ladder import Ladder
from .options import AccuracyOptions
from .planes import FrequencyPlane, Plane

__all__ = ["Shooter"]

log = logging.getLogger(__name__)


class Shooter:
    """Orbits of the exact flow (:class:`femodes.time.exact.LinearImpactFlow`) on the hyperplanes
    of a branch's points: the ``H -> inf`` limit the levels extrapolate to, for rigid impacts
    with restitution 1 (the limit of harmonic balance with complementarity contacts: 4.4, 2.4,
    1.2, 0.67 % fold errors at H = 10-80 against the event-driven reference converge to it)."""

    def __init__(self, lad: Ladder, options: AccuracyOptions, flow=None):
        self.lad, self.options = lad, options
        self.branch = lad.branch
        self.H = lad.h0.n_harmonics
        self.flow = flow or LinearImpactFlow(lad.model, float(np.mean(self.branch.omega_truncated)))
        self.n = self.flow.n
        self.runs = 0

    def start(self, i: int) -> tuple[np.ndarray, float]:
        """State of point ``i`` at its most open phase (largest smallest gap) and that phase."""
        b, h = self.branch, self.lad.h0
        Q = b.Q[i]
        theta = h.grid.most_open_phase(Q, self.flow.dofs, self.flow.gaps)
        e = h.grid.synthesis(np.array([theta]))[0]
        return np.concatenate([e @ Q, e @ (h.operators.derivative(float(b.omega_truncated[i])) @ Q)]), theta

    def evaluate(self, x0: np.ndarray, omega: float, theta0: float, plane, jac: bool):
        """Periodicity residual, hyperplane value and (with ``jac``) their Jacobian in ``(x0, w)``,
        all from the variational run: the monodromy matrix, the end state's and the
        coefficients' change with ``w`` at the fixed start phase (:attr:`FlowRun.x_end_omega`,
        :meth:`FlowRun.coefficient_omega`) and the hyperplane's gradient."""
        F, dFdx, dFdw, run = periodicity_residual(self.flow, x0, omega, theta0 / omega, variational=jac)
        self.runs += 1
        h = plane.value(run, omega)
        if not jac:
            return F, h, None, run
        n2 = 2 * self.n
        J = np.zeros((n2 + 1, n2 + 1))
        J[:n2, :n2] = dFdx
        J[n2, :n2] = plane.gradient(run)
        J[:n2, n2] = dFdw
        J[n2, n2] = plane.omega_derivative(run)
        return F, h, J, run

    def plane(self, i: int, offset: float = 0.0) -> Plane:
        """The hyperplane of point ``i`` (shifted by ``offset``) as a function of a run."""
        return Plane(self.lad, self.H, i, offset)

    def glancing(self, i: int, r) -> float:
        """How obliquely the exact curve crosses point ``i``'s hyperplane compared with the
        branch: ``kappa = (dw*/ds) / (dw/ds)``, the change of the crossing frequency per unit
        offset of the plane on the exact curve over the same on the branch (its neighbours).
        About 1 where the two curves run alike (1.0-1.1 on seed case 1 from the rising side to
        the fold); large just above grazing, where a displacement's amplitude stays at the gap
        while the frequency moves and the plane is nearly tangent to the exact curve (18, 14, 10
        at the first three points with contact of seed case 1, whose crossings lie 12 %, 7 %
        and 1.2 % away), or negative (seed case 2, three points above grazing: the exact curve
        runs back through the plane): the crossing is then not the point's counterpart."""
        J = r[5]
        b = self.branch
        if J is None:  # the linear orbit: its curve is the branch's own
            return 1.0
        n2 = J.shape[0] - 1
        try:
            dws = float(np.linalg.solve(J, np.r_[np.zeros(n2), 1.0])[n2])
        except np.linalg.LinAlgError:
            return math.inf
        plane = self.plane(i)
        j0, j1 = max(i - 1, 0), min(i + 1, len(b) - 1)
        ds = plane.at(b.Q[j1], float(b.omega_truncated[j1])) - plane.at(b.Q[j0], float(b.omega_truncated[j0]))
        dw = float(b.omega_truncated[j1] - b.omega_truncated[j0])
        if dw == 0.0 or ds == 0.0:
            return math.inf
        return dws / (dw / ds)

    def crossing_cosine(self, i: int, r) -> float:
        """Cosine of the angle between the exact curve at its crossing of point ``i``'s
        hyperplane and the hyperplane's normal (the branch direction), in the branch's arclength
        weights on the displacements and the frequency: 1 for a crossing at right angles, near 0
        for a glancing one. The exact curve's direction ``d(x0, w)/ds`` is the Newton Jacobian's
        last column of its inverse; the coefficients follow exactly in ``x0`` and ``w`` (a
        variational run)."""
        x0, w, theta0, _, _, J = r[:6]
        if J is None:  # the linear orbit: the branch's own curve
            return 1.0
        n2 = J.shape[0] - 1
        try:
            d = np.linalg.solve(J, np.r_[np.zeros(n2), 1.0])
        except np.linalg.LinAlgError:
            return 0.0
        run = self.flow.at(w).run(x0, theta0 / w, variational=True)
        self.runs += 1
        dQ = (np.einsum("kdc,c->kd", run.coefficient_sensitivity(self.H), d[:n2])
              + run.coefficient_omega(self.H) * d[n2])
        lad = self.lad
        W = lad.weights(self.H)
        wQ, wp = lad.problem(self.H).unpack(W[:-1], W[-1]).Q, float(W[-1])
        t = lad.tangents[i]
        num = float(np.sum(wQ * t.Q * dQ)) + wp * t.omega * d[n2]
        den = math.sqrt(float(np.sum(wQ * t.Q ** 2)) + wp * t.omega ** 2) * math.sqrt(
            float(np.sum(wQ * dQ ** 2)) + wp * d[n2] ** 2)
        return abs(num) / den if den > 0.0 else 0.0

    def warm(self, i: int, prev) -> tuple:
        """A first guess for point ``i`` from the exact orbit ``prev = (x0, w, theta0, j)`` of a
        neighbour ``j``: moved by the branch's change from ``j`` to ``i`` at the same phase."""
        x0, omega, theta0, j = prev[:4]
        b, h = self.branch, self.lad.h0
        e = h.grid.synthesis(np.array([theta0]))[0]
        dQ = b.Q[i] - b.Q[j]
        D = h.operators.derivative
        dv = e @ (D(float(b.omega_truncated[i])) @ b.Q[i]) - e @ (D(float(b.omega_truncated[j])) @ b.Q[j])
        return x0 + np.concatenate([e @ dQ, dv]), omega + float(b.omega_truncated[i] - b.omega_truncated[j]), theta0

    def linear(self, i: int, offset: float = 0.0):
        """The orbit without impacts on the hyperplane of point ``i``, if that orbit stays off the
        obstacles (just above grazing the harmonic balance point touches, the exact orbit may
        not): the forced linear response, whose frequency on the hyperplane is found by the
        secant method. Same return as :meth:`solve`, or None."""
        plane = self.plane(i, offset)
        theta0 = self.start(i)[1]

        def value(omega):
            flow = self.flow.at(omega)
            t0 = theta0 / omega
            self.runs += 1
            run = flow.run(flow.particular(t0), t0)
            return plane.value(run, omega), run

        w0 = float(self.branch.omega_truncated[i])
        w1 = w0 * (1.0 + 1e-3)
        try:
            h0, _ = value(w0)
            for _ in range(30):
                h1, run = value(w1)
                if h1 == h0:
                    break
                w0, w1, h0 = w1, w1 - h1 * (w1 - w0) / (h1 - h0), h1
                if not w1 > 0.0:
                    return None
                if abs(w1 - w0) <= self.options.shooting_step * abs(w1) and abs(h1) <= self.options.shooting_tol:
                    h1, run = value(w1)
                    if run.touches:
                        return None  # the linear orbit there reaches an obstacle
                    return run.x_end, w1, theta0, run, abs(w1 - w0), None
        except ValueError:
            return None
        return None

    def at_frequency(self, i: int):
        """The exact orbit at point ``i``'s own frequency (:class:`~.planes.FrequencyPlane`), from the point
        itself, else from the linear orbit at that frequency and the point's start phase: just
        above grazing the exact orbit is near the linear one, while Newton from the point may
        stall (seed case 1 at H = 20, w = 0.906552, 6.3e-5 above the grazing: three steps cut below
        2^-8 from the point; 15 Newton iterations from the linear orbit). Same return as :meth:`solve`, or
        None."""
        omega = float(self.branch.omega_truncated[i])
        plane = FrequencyPlane(omega)
        r = self.solve(i, plane=plane)
        if r is None:
            theta0 = self.start(i)[1]
            x = self.flow.at(omega).particular(theta0 / omega)
            if self.flow.admissible(x):
                r = self.solve(i, guess=(x, omega, theta0), plane=plane)
        return r

    def solve_from(self, i: int, j: int, at_j, pieces: int = 8):
        """The orbit on point ``i``'s hyperplane by a continuation over the planes between a
        neighbour ``j``'s (solved: ``at_j``) and ``i``'s, in ``pieces`` steps: just above
        grazing, where the flow's derivative jumps with the impact, Newton from ``j``'s orbit
        in one step cycles between orbits with and without it (seed case 1: the first two
        points with contact)."""
        r = at_j
        for k in range(1, pieces + 1):
            plane = Plane(self.lad, self.H, j, toward=i, theta=k / pieces)
            r = self.solve(i, guess=r[:3], plane=plane)
            if r is None:
                return None
        return r

    def solve(self, i: int, guess=None, offset: float = 0.0, plane=None):
        """The exact orbit on the hyperplane of point ``i`` (shifted by ``offset``): ``(x0, w,
        theta0, run, dw)`` with the last Newton step ``dw``, or None. Newton with a backtracking
        search on the residual norm (near grazing the flow's derivative jumps where an impact
        appears, and full steps cycle between orbits with and without it)."""
        x_hbm, theta0 = self.start(i)
        if guess is None:
            x0, omega = x_hbm, float(self.branch.omega_truncated[i])
        else:
            x0, omega, theta0 = guess[0].copy(), guess[1], guess[2]
        plane = plane or self.plane(i, offset)
        opts = self.options
        n2 = 2 * self.n
        step = np.inf
        stalled = 0

        def converged(F, h, x, step, w):
            return (float(np.max(np.abs(F))) <= opts.shooting_tol * max(1.0, float(np.max(np.abs(x))))
                    and abs(h) <= opts.shooting_tol and step <= opts.shooting_step * w)

        def norm(F, h, x):
            return math.hypot(float(np.linalg.norm(F)) / max(1.0, float(np.max(np.abs(x)))), h)

        try:
            F, h, J, run = self.evaluate(x0, omega, theta0, plane, True)
        except ValueError as exc:  # a start state in the obstacle, an accumulation of impacts
            log.debug("accuracy: shooting at point %d: %s", i, exc)
            return None
        for _ in range(opts.shooting_max_iter):
            if converged(F, h, x0, step, omega):
                corr = float(np.max(np.abs(x0 - x_hbm))) / max(float(np.max(np.abs(x_hbm))), 1e-300)
                if guess is None and corr > opts.shooting_max_correction:
                    log.info("accuracy: shooting at point %d found another orbit (start state moved by %.0f %%)",
                             i, 100 * corr)
                    return None
                return x0, omega, theta0, run, step, J
            try:
                d = np.linalg.solve(J, -np.append(F, h))
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(d)):
                return None
            r0 = norm(F, h, x0)
            alpha = 1.0
            while alpha >= 2.0 ** -20:
                x1, w1 = x0 + alpha * d[:n2], omega + alpha * d[n2]
                if w1 > 0.0 and self.flow.admissible(x1):
                    try:
                        F1, h1, _, run1 = self.evaluate(x1, w1, theta0, plane, False)
                    except ValueError:
                        F1 = None
                    if F1 is not None and norm(F1, h1, x1) <= (1.0 - 1e-4 * alpha) * r0:
                        break
                alpha *= 0.5
            else:
                log.debug("accuracy: shooting at point %d: no step reduces the residual", i)
                return None
            step = abs(alpha * d[n2])
            stalled = stalled + 1 if alpha < opts.shooting_stall_alpha else 0
            if stalled >= opts.shooting_stall:
                log.debug("accuracy: shooting at point %d stalls (%d steps shorter than %g)", i, stalled,
                          opts.shooting_stall_alpha)
                return None
            x0, omega, F, h, run = x1, w1, F1, h1, run1
            if not converged(F, h, x0, step, omega):
                F, h, J, run = self.evaluate(x0, omega, theta0, plane, True)
        log.debug("accuracy: shooting at point %d did not converge", i)
        return None
