"""Discretise layer: HBM problems exposing ``residual(x, p) -> (r, dr_dx, dr_dp)``.

* :class:`ForcedResponseProblem`: parameter ``p = w`` (forcing frequency, rad/s); unknowns
  ``x = [Q; P]``.
* :class:`NonlinearModeProblem`: the free system by the extended periodic motion concept (Krack
  2015, Comput. Struct. 154:59-71): an artificial damping term ``-xi M q'`` makes the
  degenerate family of conservative periodic orbits an isolated solution; ``xi`` is an unknown
  that comes out (near) zero for conservative systems. Unknowns ``x = [Q; P; w; xi]``, parameter
  ``p = log10(E)`` (period-averaged mechanical energy), extra equations: a phase condition (the
  first-harmonic sine component along the linear mode vanishes) and the energy condition.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..linear import linear_modes, rigid_body_message, rigid_body_modes
from ..model import StructuralModel
from .harmonics import Harmonics
from .system import HBMSystem

__all__ = ["ForcedResponseProblem", "NonlinearModeProblem", "PeriodDrivenModeProblem", "HBMUnknowns"]


@dataclass(frozen=True, eq=False)
class HBMUnknowns:
    """The unknowns of an HBM problem at one point, by name (callers never slice ``x``).

    Attributes
    ----------
    y : ndarray
        The harmonic balance unknowns ``[Q; P]`` of the system (:class:`~femodes.hbm.HBMSystem`
        layout).
    Q : ndarray (n_coef, n_dofs)
        Fourier coefficients of the displacements.
    P : ndarray (n_coef, n_unilateral)
        Fourier coefficients of the complementarity contact forces.
    omega : float
        Angular frequency (rad/s).
    xi : float
        Artificial damping of a nonlinear mode (0 for forced responses).
    """

    y: np.ndarray
    Q: np.ndarray
    P: np.ndarray
    omega: float
    xi: float


class ForcedResponseProblem:
    """Forced periodic response ``M q'' + C q' + K q + f_nl = f(t)``, parameter ``w``.

    Parameters
    ----------
    model : StructuralModel
        Must have forcing (:class:`~femodes.HarmonicForce`).
    harmonics : Harmonics
    projection, solver : keyword-only
        Strategies of the :class:`~femodes.hbm.HBMSystem`: how ``max(0, .)`` is projected
        (default :class:`~femodes.hbm.ExactProjection`) and how the Jacobian is factorised
        (default :class:`~femodes.hbm.BlockSolver`).
    """

    def __init__(self, model: StructuralModel, harmonics: Harmonics, *, projection=None, solver=None):
        self.system = HBMSystem(model, harmonics, projection=projection, solver=solver)
        if not model.forces:
            raise ValueError(
                "ForcedResponseProblem: the model has no forcing; add model.with_forcing(HarmonicForce(at=..., amplitude=...))"
            )
        F = self.system.linear.force()  # validates the harmonic count against the forcing
        # Equations are divided by the forcing amplitude so that Newton tolerances are relative.
        self.force_scale = float(np.max(np.abs(F))) or 1.0

    @property
    def size(self) -> int:
        return self.system.size

    def residual(self, x: np.ndarray, p: float):
        r, J, dr_dw, _ = self.system.residual(np.asarray(x, dtype=float), float(p))
        f = 1.0 / self.force_scale
        return r * f, J * f, dr_dw * f

    def initial_guess(self, p: float) -> np.ndarray:
        """Starting point for :func:`~femodes.continuation` at ``w = p``: the linear response."""
        return self.linear_guess(p)

    def linear_guess(self, omega: float) -> np.ndarray:
        """Linear response (contacts and nonlinear springs ignored) as a starting point."""
        s = self.system
        q = s.linear.solve(s.linear.force(), omega)
        return s.join(q.reshape(s.h.n_coef, s.n))

    def phase_shift(self, x: np.ndarray, tau: float) -> np.ndarray:
        """The unknowns of the response delayed by the phase ``tau`` (radians of ``w t / nu``).
        With :meth:`phase_generator`, what the continuation's ``predictors.Phase()`` uses."""
        return self.system.time_shift(np.asarray(x, dtype=float), float(tau))

    def phase_generator(self, x: np.ndarray) -> np.ndarray:
        """``d/dtau`` of :meth:`phase_shift` at ``tau = 0``."""
        return self.system.shift_generator(np.asarray(x, dtype=float))

    def forcing(self) -> np.ndarray:
        """The forcing's part of the residual (in the residual's scaling): ``r(x, w) = A(w) x + g(x) - forcing()``."""
        s = self.system
        return s.join(s.linear.force().reshape(s.h.n_coef, s.n)) / self.force_scale

    def unpack(self, x: np.ndarray, p: float) -> HBMUnknowns:
        x = np.asarray(x, dtype=float)
        Q, P = self.system.split(x)
        return HBMUnknowns(y=x, Q=Q, P=P, omega=float(p), xi=0.0)

    def pack(self, Q: np.ndarray, P: np.ndarray, omega: float, xi: float = 0.0) -> np.ndarray:
        """The unknowns ``x`` of a point from its parts (the inverse of :meth:`unpack`; ``omega``
        is the parameter, not an unknown)."""
        return self.system.join(Q, P)


class NonlinearModeProblem:
    """Nonlinear mode (EPMC) of the autonomous system; parameter ``p = log10(energy)``.

    Parameters
    ----------
    model : StructuralModel
        Forcing declarations are ignored (the free system). Damping is kept: for a damped model
        ``xi`` balances the dissipation (the EPMC backbone); for an undamped one it must vanish.
    harmonics : Harmonics
    mode : int
        Linear mode (1-based) the branch starts from; its shape defines the phase condition.
    reference_energy : float, keyword-only
        Energy of the motions traced: the equations are scaled by the force level of the linear
        mode at this energy, so that Newton tolerances are relative (``nonlinear_mode`` passes
        the geometric mean of its span).
    projection, solver : keyword-only
        Strategies of the :class:`~femodes.hbm.HBMSystem` (as for :class:`ForcedResponseProblem`).
    """

    def __init__(self, model: StructuralModel, harmonics: Harmonics, mode: int = 1, *, reference_energy: float = 1.0,
                 projection=None, solver=None):
        if isinstance(mode, bool) or not isinstance(mode, (int, np.integer)) or mode < 1:
            raise ValueError(f"NonlinearModeProblem: mode must be a positive integer (1 = first mode), got {mode!r}")
        if mode > model.n_dofs:
            raise ValueError(f"NonlinearModeProblem: mode={mode} but the model has {model.n_dofs} DOFs")
        if harmonics.n_harmonics < 1:
            raise ValueError("NonlinearModeProblem: needs n_harmonics >= 1")
        self.system = HBMSystem(model.without_forcing(), harmonics, projection=projection, solver=solver)
        modes = linear_modes(model, n=int(mode))
        self.mode = int(mode)
        self.omega0 = float(modes.omega[-1])
        rigid = rigid_body_modes(model, modes.omega)
        if self.omega0 <= 0 or rigid[-1]:
            raise ValueError("NonlinearModeProblem: " + rigid_body_message(int(rigid.sum()))
                             + f"; mode {mode} is one of them (w = {self.omega0:.3g} rad/s): its backbone is not a "
                             "vibration")
        if rigid.any():
            warnings.warn("nonlinear_mode: " + rigid_body_message(int(rigid.sum())) + f"; mode {mode} is counted "
                          "after them", UserWarning, stacklevel=3)
        self.shape = modes.shapes[:, -1]
        s = self.system
        self._phase_idx = s.h.layout.global_index(s.h.layout.sin_index(1), np.arange(s.n), s.n)
        self._Mphi = np.asarray(model.M @ self.shape).ravel()
        self.size = s.size + 2
        # Equations are divided by the elastic force of the unit-mass-normalised mode times the
        # amplitude of the linear mode at the reference energy, so that Newton tolerances are
        # relative to the force level of the motions traced (nonlinear_mode passes the geometric
        # mean of its energy span).
        energy = float(reference_energy)
        a = math.sqrt(2.0 * energy) / self.omega0 if energy > 0 else math.nan
        self.reference_energy = energy
        self.force_scale = (float(np.max(np.abs(model.K @ self.shape))) or 1.0) * a
        self.phase_scale = float(np.max(np.abs(self._Mphi))) * a or 1.0
        if not (math.isfinite(self.force_scale) and self.force_scale > 0 and math.isfinite(self.phase_scale)
                and 1.0 / self.force_scale < math.inf and 1.0 / self.phase_scale < math.inf):
            raise ValueError(f"NonlinearModeProblem: reference_energy={reference_energy!r} gives motions whose force "
                             "scale under- or overflows; rescale the units (mass, stiffness) or the energy span")

    def _parts(self, x: np.ndarray) -> tuple[np.ndarray, float, float]:
        """``x = [y; w; xi]``: the system unknowns, the frequency and the artificial damping."""
        n = self.system.size
        return x[:n], float(x[n]), float(x[n + 1])

    def arclength_scale(self, x0: np.ndarray) -> np.ndarray:
        """Scales of the unknowns for the continuation's arclength norm, from the start ``x0``:
        displacement coefficients by the starting amplitude, contact forces by the force that
        amplitude produces through the contact stiffness, ``w`` by ``w0``, ``xi`` by ``0.1 w0``."""
        s = self.system
        Q, _ = s.split(self._parts(np.asarray(x0, dtype=float))[0])
        aq = max(float(np.max(np.abs(Q))), 1e-300)
        cmax = max([ct.c for ct in s.unilateral] or [1.0])
        Qs = np.full((s.h.n_coef, s.n), aq)
        Ps = np.full((s.h.n_coef, s.n_uc), cmax * aq)
        return np.concatenate([s.join(Qs, Ps), [self.omega0, 0.1 * self.omega0]])

    def residual(self, x: np.ndarray, p: float):
        s = self.system
        y, omega, xi = self._parts(np.asarray(x, dtype=float))
        r0, J0, dr_dw, dr_dxi = s.residual(y, omega, xi=xi, forced=False)
        E, dE, dE_dw = s.energy(y, omega)
        E = max(E, 1e-300)
        fs = 1.0 / self.force_scale
        r0, J0, dr_dw, dr_dxi = r0 * fs, J0 * fs, dr_dw * fs, dr_dxi * fs
        # phase condition: first-harmonic sine part along the linear mode shape (M-orthogonal)
        gphase = np.zeros(s.size)
        gphase[self._phase_idx] = self._Mphi / self.phase_scale
        value, grad, d_w, d_p = self._parameter_row(E, dE, dE_dw, omega, p)
        r = np.concatenate([r0, [gphase @ y, value]])
        cols = np.column_stack([dr_dw, dr_dxi])
        rows = np.vstack([np.append(gphase, [0.0, 0.0]), np.append(grad, [d_w, 0.0])])
        J = J0.bordered(cols, rows[:, : s.size], rows[:, s.size:])  # the two extra unknowns: its border
        dr_dp = np.zeros(self.size)
        dr_dp[-1] = d_p
        return r, J, dr_dp

    def _parameter_row(self, E: float, dE: np.ndarray, dE_dw: float, omega: float, p: float):
        """The equation that fixes the parameter, ``log10(E) - p``, with its gradient in ``y`` and its
        ``w`` and ``p`` derivatives (:class:`PeriodDrivenModeProblem` fixes the frequency instead)."""
        ln10 = math.log(10.0)
        return math.log10(E) - p, dE / (E * ln10), dE_dw / (E * ln10), -1.0

    def initial_guess(self, p: float) -> np.ndarray:
        """Starting point for :func:`~femodes.continuation` at ``p = log10(E)``: the linear mode."""
        return self.linear_guess(10.0 ** p)

    def linear_guess(self, energy: float) -> np.ndarray:
        """The linear mode with energy ``E = a^2 w^2 / 2`` (mass-normalised shape)."""
        s = self.system
        a = math.sqrt(2.0 * energy) / self.omega0
        Q = np.zeros((s.h.n_coef, s.n))
        Q[s.h.layout.cos_index(1)] = a * self.shape
        return np.concatenate([s.join(Q), [self.omega0, 0.0]])

    def unpack(self, x: np.ndarray, p: float) -> HBMUnknowns:
        y, omega, xi = self._parts(np.asarray(x, dtype=float))
        Q, P = self.system.split(y)
        return HBMUnknowns(y=y, Q=Q, P=P, omega=omega, xi=xi)

    def pack(self, Q: np.ndarray, P: np.ndarray, omega: float, xi: float = 0.0) -> np.ndarray:
        """The unknowns ``x = [y; w; xi]`` of a point from its parts (the inverse of :meth:`unpack`)."""
        return np.concatenate([self.system.join(Q, P), [float(omega), float(xi)]])


class PeriodDrivenModeProblem(NonlinearModeProblem):
    """The periodic motions of :class:`NonlinearModeProblem` at a given frequency: parameter
    ``p = w`` (rad/s), energy free.

    The same unknowns ``x = [y; w; xi]`` and equations (harmonic balance with artificial damping
    ``xi``, phase condition) but the last one, ``(w - p) / w0 = 0``. Solved point by point at
    increasing ``w`` (the period-driven continuation of nonsmooth modes, Lu & Legrand's sweep of
    the period), it steps over the near-vertical internal-resonance tongues that a continuation in
    the energy climbs (:mod:`femodes.nonsmooth_modes`).
    """

    def _parameter_row(self, E: float, dE: np.ndarray, dE_dw: float, omega: float, p: float):
        return (omega - p) / self.omega0, np.zeros_like(dE), 1.0 / self.omega0, -1.0 / self.omega0
