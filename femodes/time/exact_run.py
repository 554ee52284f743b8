"""One run of the exact flow (:class:`FlowRun`): from a start state over a time span, segment by
segment between contact events (located by :class:`~femodes.time.exact_events.EventSearch`),
with impacts (Newton's law and its saltation matrix) and switches of massless contacts, the end
state, and with ``variational`` its derivatives with respect to the start state (monodromy) and
the frequency. Its displacements and Fourier coefficients (:mod:`.exact_fourier`) are in closed
form.
"""

from __future__ import annotations

import copy

import numpy as np

from .exact_events import EventSearch
from .exact_fourier import RunSeries
from .shooting import MAX_IMPACTS

__all__ = ["FlowRun"]


class FlowRun:
    """One run of :class:`~femodes.time.exact.LinearImpactFlow`: end state, monodromy, segments,
    impacts, switches.

    Attributes
    ----------
    x_end : ndarray (2n,)
    Phi : ndarray (2n, 2n) or None
        ``d x_end / d x0`` (saltation matrices at the impacts) when ``variational``; zero columns
        for the massless DOFs' entries.
    x_end_omega : ndarray (2n,) or None
        ``d x_end / d w`` when ``variational``, with the start and end phases ``w t0`` and
        ``w t1`` held fixed (a run of one forcing period from a given phase, as shooting and
        :func:`exact_frequency_response` use it): the particular solution's change carried
        through the segments, the saltation matrices at the impacts (the impact surfaces depend
        on the state alone), unchanged through switches (the same vector field on both sides),
        and the moves ``-t0 / w`` and ``-t1 / w`` of the start and end times.
    segments : list of (t_a, t_b, z_a, closed)
        Intervals between events with the modal coordinates ``z_a = V^-1 (x(t_a) - x_p(t_a))`` of
        the mode ``closed`` (the massless contacts closed there).
    impacts : list of (t, contact index, impulse)
        Impulse ``(1 + e) v_c^- / (M^-1)_cc`` (compression positive).
    switches : list of (t, contact index, "close" | "open")
    samples : int
        Event function evaluations of the searches (the cost of a stiff model).
    sensitivities, sigmas : list of ndarray
        Per segment (a variational run), ``d x(t_a+) / d x0`` and ``d x(t_a+) / d w`` at the fixed
        time ``t_a`` of its start (inertial state).
    """

    def __init__(self, flow, x0: np.ndarray, t0: float, t1: float, variational: bool):
        self.flow, self.t0, self.t1 = flow, t0, t1
        n2 = 2 * flow.n
        if x0.shape != (n2,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"LinearImpactFlow.run: x0 must be {n2} finite numbers, got shape {x0.shape}")
        inertial = ~flow.massless
        g0 = flow.gaps[inertial] - x0[flow.dofs[inertial]]
        scale = max(float(np.max(np.abs(flow.gaps))), float(np.max(np.abs(x0[:flow.n]))), 1e-300)
        if g0.size and np.any(g0 < -1e-9 * scale):
            raise ValueError(f"LinearImpactFlow.run: the start state penetrates an obstacle (gap {float(g0.min()):.3g})")
        self.segments: list = []
        self.impacts: list = []
        self.switches: list = []
        self.samples = 0
        x = x0[flow.state_index].copy()
        self._Phi = np.eye(n2)[flow.state_index] if variational else None
        self._sigma = None  # d x(t) / d w at a fixed time t, the start time's move included
        self.sensitivities: list = []
        self.sigmas: list = []
        self._series: RunSeries | None = None  # the Fourier coefficients (RunSeries), when first asked for
        closed = flow.start_mode(x, t0)
        t = t0
        while True:
            m, d = flow.mode(closed)
            self._m, self._d = m, d
            if variational and self._sigma is None:  # x(t0) = x0 with t0 = theta0 / w: dt0/dw = -t0 / w
                self._sigma = self._field(t0, x) * (t0 / flow.omega)
            z = m.Vinv @ (x - d.particular(t))
            search = EventSearch(m, d)
            hit = search.first(t, z, t1)
            self.samples += search.samples
            tb = t1 if hit is None else hit[0]
            self.segments.append((t, tb, z, closed))
            if variational:
                self.sensitivities.append(self._Phi)  # d x(t_a+) / d x0 of the segment
                self.sigmas.append(self._sigma)  # and d x(t_a+) / d w at the fixed time t_a
            e = np.exp(m.lam * (tb - t))
            x = d.particular(tb) + np.real(m.V @ (e * z))
            if variational:
                Pm = np.real((m.V * e) @ m.Vinv)
                self._Phi = Pm @ self._Phi
                self._sigma = d.particular_omega(tb) + Pm @ (self._sigma - d.particular_omega(t))
            if hit is None:
                break
            if len(self.impacts) + len(self.switches) >= MAX_IMPACTS:
                raise ValueError(f"LinearImpactFlow.run: more than {MAX_IMPACTS} contact events in one run (an "
                                 "accumulation of impacts or switches)")
            j = hit[1]
            if flow.massless[j]:
                closed = closed ^ {j}
                self.switches.append((tb, j, "close" if j in closed else "open"))
            else:
                x = self._impact(tb, x, j, variational)
            t = tb
        m, d = flow.mode(closed)
        tail = d.phases(t1)
        self.x_end = np.concatenate([m.Lq @ x + np.real(tail @ d.G), m.Lv @ x + np.real((tail * d.iw) @ d.G)])
        self.Phi = np.vstack([m.Lq, m.Lv]) @ self._Phi if variational else None
        self.x_end_omega = None
        if variational:
            dx = self._sigma - self._field(t1, x) * (t1 / flow.omega)  # dt1/dw = -t1 / w
            # the forcing part of the massless DOFs at the fixed end phase: only the velocity's i k w
            self.x_end_omega = np.concatenate([m.Lq @ dx, m.Lv @ dx + np.real((tail * (1j * d.ks)) @ d.G)])

    def plain(self) -> FlowRun:
        """This run without its variational part (monodromy, segment sensitivities): what
        :meth:`displacement` and :meth:`coefficients` need, kept small."""
        out = copy.copy(self)
        out._Phi, out.Phi, out.x_end_omega, out._sigma = None, None, None, None
        out.sensitivities, out.sigmas, out._series = [], [], None
        return out

    @property
    def touches(self) -> bool:
        """Whether the orbit touches an obstacle (an impact or a closed massless contact)."""
        return bool(self.impacts or self.switches or any(s[3] for s in self.segments))

    def _field(self, t: float, x: np.ndarray) -> np.ndarray:
        """``x' = A x + b(t)`` of the current mode (inertial state)."""
        m, d = self._m, self._d
        ph = d.phases(t)
        return m.A @ (x - np.real(ph @ d.X)) + np.real((ph * d.iw) @ d.X)

    def _impact(self, t: float, x: np.ndarray, j: int, variational: bool) -> np.ndarray:
        f = self.flow
        nI = f.I.size
        i = f.pos[f.dofs[j]]
        vc = x[nI + i]
        if vc <= 0.0:  # touching without approach: nothing to reverse
            return x
        self.impacts.append((t, j, (1.0 + f.e) * vc / f.MinvII[i, i]))
        xp = x.copy()
        dirI = f.impact_dir[j, f.I]
        xp[nI:] -= (1.0 + f.e) * vc * dirI
        if variational:
            R = np.eye(2 * nI)
            R[nI:, nI + i] -= (1.0 + f.e) * dirI
            f_minus, f_plus = self._field(t, x), self._field(t, xp)
            nvec = np.zeros(2 * nI)
            nvec[i] = -1.0
            salt = R + np.outer(f_plus - R @ f_minus, nvec) / (nvec @ f_minus)
            self._Phi = salt @ self._Phi
            self._sigma = salt @ self._sigma
        return xp

    # -- closed form over the run ---------------------------------------------------------------
    def displacement(self, t) -> np.ndarray:
        """Displacements of all DOFs at times ``t`` in ``[t0, t1]``, shape ``(len(t), n)``."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty((t.size, self.flow.n))
        for k, (ta, tb, z, closed) in enumerate(self.segments):
            last = k == len(self.segments) - 1
            sel = (t >= ta) & ((t <= tb) if last else (t < tb))
            if sel.any():
                m, d = self.flow.mode(closed)
                E = np.exp(np.multiply.outer(t[sel] - ta, m.lam)) * z
                out[sel] = np.real(E @ m.Rq.T + d.phases(t[sel]) @ d.Yq)
        return out

    # -- Fourier coefficients in closed form (RunSeries) ----------------------------------------
    def _fourier(self) -> RunSeries:
        series = self._series
        if series is None:
            series = self._series = RunSeries(self)
        return series

    def coefficients(self, H: int) -> tuple[np.ndarray, np.ndarray]:
        """Real Fourier coefficients ``[c0, c1, s1, ..., cH, sH]`` of the displacements (shape
        ``(2H + 1, n)``) and of the contact forces (``(2H + 1, n_contacts)``) over the run
        (:meth:`RunSeries.coefficients <femodes.time.exact_fourier.RunSeries.coefficients>`).
        Exact when the run is one period of a periodic orbit."""
        return self._fourier().coefficients(H)

    def coefficient_omega(self, H: int) -> np.ndarray:
        """``d Q / d w`` of :meth:`coefficients` (a variational run) with the start and end phases
        held fixed, as :attr:`x_end_omega`."""
        return self._fourier().coefficient_omega(H)

    def coefficient_sensitivity(self, H: int) -> np.ndarray:
        """``d Q / d x0`` of :meth:`coefficients`, shape ``(2H + 1, n, 2n)`` (a variational run)."""
        return self._fourier().coefficient_sensitivity(H)
