"""Results layer: :class:`PeriodicSolution`, one periodic solution stored by its Fourier
coefficients; time histories, contact forces, penetration and tension are evaluated from them."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..hbm.harmonics import Harmonics
from .contacts import ContactInfo, contact_quality, peak_amplitude

__all__ = ["PeriodicSolution"]


@dataclass(frozen=True, eq=False)
class PeriodicSolution:
    """One periodic solution ``q(t) = sum_k Q_k (cos, sin)(k w t / nu)``.

    Attributes
    ----------
    omega : float
        Frequency in rad/s (forcing frequency, or the nonlinear mode's frequency): the answer
        that meets ``rtol`` when the branch was error-controlled (the converged frequency of its
        error estimate, :attr:`Branch.omega`), else the harmonic balance's own.
    omega_truncated : float
        The frequency of the truncated Fourier series ``Q, P`` (the harmonic balance's solution;
        :attr:`period`, :meth:`displacement` and the other syntheses use it); equal to
        :attr:`omega` without an error estimate.
    Q, P, harmonics : ndarray (n_coef, n_dofs), ndarray (n_coef, n_contacts), Harmonics
        Displacement coefficients on the model it was solved on; contact force coefficients.
    energy : float
        Period-averaged mechanical energy.
    xi : float
        Artificial damping of the extended periodic motion concept (0 for forced responses).
    residual_norm : float
        Max-norm of the HBM residual at this point.
    model : StructuralModel or None
        The model (``None`` after loading from a file); needed for :meth:`full_displacement` and
        :func:`femodes.stability`.
    kind : str
        ``"forced"`` or ``"nonlinear mode"`` (the branch it belongs to).
    multipliers, stable : ndarray (complex) and bool, or None
        Floquet multipliers (largest modulus first) and stability, when the branch has them
        (``stability=True``); ``None`` otherwise.
    error_estimate : float or None
        Estimated relative error of frequency and amplitude (the larger) against the converged
        answer of the sources the branch's estimate covers (:attr:`ErrorEstimate.covers`); ``None``
        without one. ``harmonics`` is the point's own (error control may add harmonics).
    omega_error, amplitude_error : float or None
        The two parts of :attr:`error_estimate`: the relative error of :attr:`omega` (what
        ``rtol`` controls) and of :meth:`amplitude` (the exact orbit's where the estimate found
        it, else the truncated series', which ``rtol`` does not control).
    amplitude_limit : ndarray or None
        ``max_t |q_d(t)|`` per DOF of the point's exact orbit, where the branch's error estimate
        found it by shooting (``accuracy.amplitude_limit``); :meth:`amplitude` reads it.
    """

    omega: float
    Q: np.ndarray
    P: np.ndarray
    harmonics: Harmonics
    contacts: ContactInfo
    energy: float = math.nan
    xi: float = 0.0
    residual_norm: float = math.nan
    nit: int = 0
    model: Any = None
    kind: str = "forced"
    multipliers: np.ndarray | None = None
    stable: bool | None = None
    error_estimate: float | None = None
    # set by Branch.__getitem__ on an error-controlled branch; not constructor arguments, so that
    # dataclasses.replace(sol, omega=w, Q=...) gives a plain series at w, never a stale correction
    omega_truncated: float = field(init=False)
    omega_error: float | None = field(init=False, default=None)
    amplitude_error: float | None = field(init=False, default=None)
    amplitude_limit: np.ndarray | None = field(init=False, default=None)

    def __post_init__(self):
        object.__setattr__(self, "omega_truncated", float(self.omega))

    def _error_controlled(self, omega_truncated: float, omega_error: float, amplitude_error: float,
                          amplitude_limit: np.ndarray | None = None) -> PeriodicSolution:
        """This solution as the point of an error-controlled branch: ``omega`` is the converged
        frequency, the series ``Q, P`` is at ``omega_truncated`` (used by :meth:`Branch.__getitem__`)."""
        object.__setattr__(self, "omega_truncated", float(omega_truncated))
        object.__setattr__(self, "omega_error", float(omega_error))
        object.__setattr__(self, "amplitude_error", float(amplitude_error))
        object.__setattr__(self, "amplitude_limit", None if amplitude_limit is None else np.asarray(amplitude_limit, float))
        return self

    @property
    def period(self) -> float:
        """The period of the truncated series (``2 pi nu / omega_truncated``)."""
        return self.harmonics.grid.period(self.omega_truncated)

    @property
    def n_dofs(self) -> int:
        return self.Q.shape[1]

    def _t(self, t):
        return np.atleast_1d(np.asarray(t, dtype=float))

    def displacement(self, t) -> np.ndarray:
        """``q(t)``, shape ``(len(t), n_dofs)`` (DOFs of the model it was solved on)."""
        return self.harmonics.grid.evaluate(self.Q, self.omega_truncated, self._t(t))

    def velocity(self, t) -> np.ndarray:
        """``q'(t)``, shape ``(len(t), n_dofs)``."""
        D = self.harmonics.operators.derivative(self.omega_truncated)
        return self.harmonics.grid.evaluate(D @ self.Q, self.omega_truncated, self._t(t))

    def contact_force(self, t) -> np.ndarray:
        """Contact forces ``p(t) >= 0`` (compression positive), shape ``(len(t), n_contacts)``."""
        t = self._t(t)
        ci = self.contacts
        out = np.zeros((t.size, len(ci.kinds)))
        if not ci.kinds:
            return out
        u = None
        for j, kind in enumerate(ci.kinds):
            if kind == "complementarity":
                out[:, j] = self.harmonics.grid.evaluate(self.P[:, ci.slots[j]], self.omega_truncated, t)
            else:
                if u is None:
                    u = self.displacement(t)
                out[:, j] = ci.laws[j].force(u[:, ci.dofs[j]])[0]
        return out

    def gap(self, t) -> np.ndarray:
        """Normal gaps ``g_N(t) = gap - q_c(t)``, shape ``(len(t), n_contacts)``."""
        u = self.displacement(t)
        ci = self.contacts
        if not ci.kinds:
            return np.zeros((u.shape[0], 0))
        return np.column_stack([law.gap_function(u[:, dof]) for law, dof in zip(ci.laws, ci.dofs)])

    @property
    def penetration(self) -> float:
        """Max penetration ``max(0, max_t -g_N(t))`` over a fine time grid (0 without contacts)."""
        return float(contact_quality(self.harmonics, self.contacts, self.Q[None], self.P[None])[0, 0])

    @property
    def tension(self) -> float:
        """Max tension ``max(0, max_t -p(t))`` over a fine time grid (truncation artefact)."""
        return float(contact_quality(self.harmonics, self.contacts, self.Q[None], self.P[None])[1, 0])

    def amplitude(self, dof: int) -> float:
        """``max_t |q_dof(t)|``: that of the exact orbit where the branch's error estimate found
        it (:attr:`amplitude_limit`, as :meth:`Branch.amplitude`), else the series' peak
        (:func:`~femodes.results.contacts.peak_amplitude`)."""
        checked_dof(dof, self.Q.shape[-1], "PeriodicSolution.amplitude")
        if self.amplitude_limit is not None:
            return float(self.amplitude_limit[dof])
        return float(peak_amplitude(self.harmonics, self.Q[:, dof])[0])

    def full_displacement(self, t) -> np.ndarray:
        """Displacement expanded to the full model (Craig-Bampton parents) DOFs."""
        if self.model is None:
            raise ValueError("full_displacement needs the model: this solution was loaded from a file; use Branch.attach(model)")
        return self.model.mesh_map.to_owner(self.displacement(t))


def checked_dof(dof, n_dofs: int, where: str) -> int:
    """``dof`` as an index into ``n_dofs`` DOFs (negative from the end); a TypeError or IndexError
    that names ``where`` and the range otherwise."""
    if isinstance(dof, (bool, np.bool_)) or not isinstance(dof, (int, np.integer)):
        raise TypeError(f"{where}: dof must be an integer DOF index, got {dof!r} (a location name: "
                        "model.dof(name) gives its index)")
    if not -n_dofs <= dof < n_dofs:
        raise IndexError(f"{where}: dof={dof} is out of range for a branch of {n_dofs} DOFs "
                         f"(0 .. {n_dofs - 1}, or negative from the end)")
    return int(dof)
