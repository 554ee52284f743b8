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

import numpy as np
import scipy.sparse as sp

from ..model import StructuralModel
from .harmonics import Harmonics
from .system import HBMSystem

__all__ = ["ForcedResponseProblem", "NonlinearModeProblem"]


class ForcedResponseProblem:
    """Forced periodic response ``M q'' + C q' + K q + f_nl = f(t)``, parameter ``w``.

    Parameters
    ----------
    model : StructuralModel
        Must have forcing (:class:`~femodes.HarmonicForce`).
    harmonics : Harmonics
    exact_contact : bool, keyword-only
        Exact positive-part projection (default) or sampled (comparison only).
    structured : bool, keyword-only
        Jacobian kept in harmonic blocks and solved by per-harmonic factorisations + a Schur
        complement on the nonlinear DOFs (default); ``False``: one assembled sparse matrix.
    """

    def __init__(self, model: StructuralModel, harmonics: Harmonics, *, exact_contact: bool = True,
                 structured: bool = True):
        self.system = HBMSystem(model, harmonics, exact_contact=exact_contact, structured=structured)
        if not model.forces:
            raise ValueError(
                "ForcedResponseProblem: the model has no forcing; add model.with_forcing(HarmonicForce(at=..., amplitude=...))"
            )
        F = self.system.force()  # validates the harmonic count against the forcing
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
        q = s.solve_linear(s.force(), omega)
        return s.join(q.reshape(s.h.n_coef, s.n))

    def unpack(self, x: np.ndarray, p: float) -> dict:
        Q, P = self.system.split(np.asarray(x))
        return {"Q": Q, "P": P, "omega": float(p), "xi": 0.0}


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
    """

    def __init__(self, model: StructuralModel, harmonics: Harmonics, mode: int = 1, *, exact_contact: bool = True,
                 structured: bool = True):
        from ..linear import linear_modes

        if isinstance(mode, bool) or not isinstance(mode, (int, np.integer)) or mode < 1:
            raise ValueError(f"NonlinearModeProblem: mode must be a positive integer (1 = first mode), got {mode!r}")
        if mode > model.n_dofs:
            raise ValueError(f"NonlinearModeProblem: mode={mode} but the model has {model.n_dofs} DOFs")
        if harmonics.n_harmonics < 1:
            raise ValueError("NonlinearModeProblem: needs n_harmonics >= 1")
        self.system = HBMSystem(model.without_forcing(), harmonics, exact_contact=exact_contact, structured=structured)
        modes = linear_modes(model, n=int(mode))
        self.mode = int(mode)
        self.omega0 = float(modes.omega[-1])
        if self.omega0 <= 0:
            raise ValueError(f"NonlinearModeProblem: mode {mode} is a rigid-body mode (zero frequency)")
        self.shape = modes.shapes[:, -1]
        s = self.system
        self._phase_idx = s.h.global_index(s.h.sin_index(1), np.arange(s.n), s.n)
        self._Mphi = np.asarray(model.M @ self.shape).ravel()
        self.size = s.size + 2
        # Equations are divided by the elastic force of the unit-mass-normalised mode times the
        # amplitude of the linear mode at energy 1 (set by set_reference_energy), so tolerances
        # are relative to the force level of the motion.
        self._kphi = float(np.max(np.abs(model.K @ self.shape))) or 1.0
        self.set_reference_energy(1.0)

    def set_reference_energy(self, energy: float) -> None:
        """Scale the equations for motions of about this energy (keeps Newton tolerances relative)."""
        a = math.sqrt(2.0 * energy) / self.omega0
        self.force_scale = self._kphi * a
        self.phase_scale = float(np.max(np.abs(self._Mphi))) * a or 1.0
        if not (math.isfinite(self.force_scale) and self.force_scale > 0 and math.isfinite(self.phase_scale)
                and 1.0 / self.force_scale < math.inf and 1.0 / self.phase_scale < math.inf):
            raise ValueError(f"NonlinearModeProblem: energy {energy!r} gives motions whose force scale under- or "
                             "overflows; rescale the units (mass, stiffness) or the energy span")

    def residual(self, x: np.ndarray, p: float):
        s = self.system
        x = np.asarray(x, dtype=float)
        y, omega, xi = x[: s.size], float(x[s.size]), float(x[s.size + 1])
        r0, J0, dr_dw, dr_dxi = s.residual(y, omega, xi=xi, forced=False)
        E, dE, dE_dw = s.energy(y, omega)
        E = max(E, 1e-300)
        ln10 = math.log(10.0)
        fs = 1.0 / self.force_scale
        r0, J0, dr_dw, dr_dxi = r0 * fs, J0 * fs, dr_dw * fs, dr_dxi * fs
        r = np.empty(self.size)
        r[: s.size] = r0
        # phase condition: first-harmonic sine part along the linear mode shape (M-orthogonal)
        gphase = np.zeros(s.size)
        gphase[self._phase_idx] = self._Mphi / self.phase_scale
        r[s.size] = gphase @ y
        r[s.size + 1] = math.log10(E) - p
        gE = dE / (E * ln10)
        cols = np.column_stack([dr_dw, dr_dxi])
        rows = np.vstack([np.append(gphase, [0.0, 0.0]), np.append(gE, [dE_dw / (E * ln10), 0.0])])
        if sp.issparse(J0):
            J = sp.vstack([sp.hstack([J0, sp.csr_matrix(cols)]), sp.csr_matrix(rows)], format="csr")
        else:  # structured Jacobian: the two extra unknowns become its border
            J = J0.bordered(cols, rows[:, : s.size], rows[:, s.size:])
        dr_dp = np.zeros(self.size)
        dr_dp[-1] = -1.0
        return r, J, dr_dp

    def initial_guess(self, p: float) -> np.ndarray:
        """Starting point for :func:`~femodes.continuation` at ``p = log10(E)``: the linear mode."""
        return self.linear_guess(10.0 ** p)

    def linear_guess(self, energy: float) -> np.ndarray:
        """The linear mode with energy ``E = a^2 w^2 / 2`` (mass-normalised shape)."""
        s = self.system
        a = math.sqrt(2.0 * energy) / self.omega0
        Q = np.zeros((s.h.n_coef, s.n))
        Q[s.h.cos_index(1)] = a * self.shape
        return np.concatenate([s.join(Q), [self.omega0, 0.0]])

    def unpack(self, x: np.ndarray, p: float) -> dict:
        s = self.system
        Q, P = s.split(np.asarray(x)[: s.size])
        return {"Q": Q, "P": P, "omega": float(x[s.size]), "xi": float(x[s.size + 1])}
