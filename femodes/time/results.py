"""Results of the Moreau-Jean time integration: :class:`TimeHistory` and :class:`SteadyState`.

Both report like every solve of femodes (scipy's ``success``, ``status``, ``message``); status
codes (shared by both, :data:`STATUS`):

* 0 -- every step's local problem (contact impulses and smooth nonlinear forces on the local
  DOFs) was solved, and for :class:`SteadyState` a periodic state was found;
* 1 -- the local problem of at least one step was not solved to tolerance; the integration went
  on from the semismooth Newton iterate with the smallest residual, and the message names the
  number of such steps, the first time and the solver's reason;
* 2 -- :class:`SteadyState` only: no periodic state within ``n_periods_max`` (``converged`` is
  False); when local failures happened too, the status is 1 and the message says both.

Contact forces. An impact law yields impulses ``P_k = int p dt`` per step, not forces, so
``contact_force(t)`` returns the *average force over the stored interval that contains* ``t``,
``impulse_i / (t_i - t_{i-1})`` for ``t_{i-1} < t <= t_i`` (piecewise constant; with
``store_every=1`` the time step containing ``t``). The per-interval array itself is
``mean_contact_force`` (row ``i`` for the interval ending at ``t_i``, row 0 zero).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..solvers.checks import InputValueError, entry_point

__all__ = ["TimeHistory", "SteadyState", "STATUS"]

#: Meaning of the ``status`` codes of :class:`TimeHistory` and :class:`SteadyState`.
STATUS = {
    0: "success",
    1: "the local problem of at least one step was not solved to tolerance",
    2: "no periodic state within n_periods_max",
}


def _times(t) -> np.ndarray:
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise InputValueError(f"t must be a scalar or 1-D array of finite times, got shape {t.shape}")
    return t


def _interval_rows(samples: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Row ``i`` of the interval ``(samples[i-1], samples[i]]`` containing each ``t`` (``samples[0]``
    belongs to the first interval)."""
    return np.clip(np.searchsorted(samples, t, side="left"), 1, samples.size - 1)


@dataclass(frozen=True, eq=False)
class TimeHistory:
    """Samples of a Moreau-Jean time integration (:func:`femodes.simulate`).

    Attributes
    ----------
    t : ndarray (n_samples,)
        Sample times (the first is ``t0``).
    u, v : ndarray (n_samples, n_dofs)
        Displacements and velocities (velocities are right limits ``v(t^+)``).
    impulse : ndarray (n_samples, n_contacts)
        Contact impulses ``>= 0`` accumulated over the steps since the previous sample (row 0 is
        zero). For penalty contacts, the integrated penalty force ``h (theta p_{k+1} +
        (1 - theta) p_k)``.
    energy : ndarray (n_samples,)
        Mechanical energy ``1/2 v.M v + 1/2 u.K u`` plus the potentials of cubic springs and
        penalty contacts.
    gap : ndarray (n_samples, n_contacts)
        Normal gaps ``g_N = gap - u_c`` (negative = penetration).
    dt : float
        Time step actually used (adjusted so that an integer number of steps reaches ``t_end``).
    success : bool
        ``status == 0``.
    status : int
        0 every step's local problem solved; 1 some were not (see the module docstring).
    message : str
        What happened: on failure, how many steps failed, the first time and the solver's reason.
    contact_work : float
        Net work of the unilateral contacts' impulses over the run (J): ``<= 0`` for a rigid stop,
        which can only take energy out; a positive value is energy the steps put in
        (:func:`femodes.simulate` warns above :data:`~femodes.time.drivers.RUN_WORK_TOL` of the
        largest energy).
    """

    t: np.ndarray
    u: np.ndarray
    v: np.ndarray
    impulse: np.ndarray
    energy: np.ndarray
    gap: np.ndarray
    dt: float
    success: bool = True
    status: int = 0
    message: str = ""
    contact_work: float = 0.0

    @property
    def mean_contact_force(self) -> np.ndarray:
        """Average contact force over each stored interval, ``impulse_i / (t_i - t_{i-1})``.

        Shape ``(n_samples, n_contacts)``; row 0 (no interval ends at ``t0``) is zero.
        """
        out = np.zeros_like(self.impulse)
        if self.t.size > 1:
            out[1:] = self.impulse[1:] / np.diff(self.t)[:, None]
        return out

    @entry_point("TimeHistory.contact_force")
    def contact_force(self, t) -> np.ndarray:
        """Contact forces at times ``t`` (compression positive), shape ``(len(t), n_contacts)``.

        The average force over the stored interval ``(t_{i-1}, t_i]`` that contains ``t``
        (:attr:`mean_contact_force`, piecewise constant; ``t0`` belongs to the first interval):
        an impact law gives impulses per step, whose force is a measure, not a function.

        Raises
        ------
        ValueError
            If a time lies outside ``[t[0], t[-1]]`` or is not finite.
        """
        t = _times(t)
        t0, t1 = float(self.t[0]), float(self.t[-1])
        slack = 1e-12 * max(abs(t0), abs(t1), t1 - t0)
        if t.size and (t.min() < t0 - slack or t.max() > t1 + slack):
            raise ValueError(f"TimeHistory.contact_force: t must lie in [{t0:g}, {t1:g}] (the integrated span), "
                             f"got values in [{t.min():g}, {t.max():g}]")
        return self.mean_contact_force[_interval_rows(self.t, t)]


@dataclass(frozen=True, eq=False)
class SteadyState:
    """Last period of a forced time integration run until it repeats (:func:`femodes.steady_state`).

    Attributes
    ----------
    t, u, v, impulse, gap, energy : ndarray
        Samples over one (``nu``-fold) period, ``t`` from 0 to ``period`` inclusive (the forcing
        phase of ``t = 0``).
    period : float
        Period of the orbit, ``nu * 2 pi / omega``.
    nu : int
        Sub-harmonic order (1 = locked to the forcing; up to 4 is detected).
    amplitude : ndarray (n_dofs,)
        ``max_t |u|`` over the orbit.
    converged : bool
        Whether the state at period starts repeated to ``tol``.
    n_periods : int
        Forcing periods integrated (also :attr:`nit`, the iterations of the period map).
    change : float
        Last relative change of the period-start state (the convergence measure): over the orbit's
        ``nu`` periods when it converged, over one period when it did not.
    dt : float
        Time step used (``2 pi / (omega N)``).
    success : bool
        ``status == 0``: a periodic state was found and every local problem was solved.
    status : int
        0 success; 1 local problems not solved at some steps; 2 no periodic state within
        ``n_periods_max`` (see the module docstring).
    message : str
        What happened, in words.
    contact_work : float
        Net work of the unilateral contacts' impulses over all ``n_periods`` periods integrated
        (J), as in :attr:`TimeHistory.contact_work` (:func:`femodes.steady_state` warns when the
        mean per period exceeds :data:`~femodes.time.drivers.PERIOD_WORK_TOL` of the orbit's
        largest energy).
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
    success: bool = True
    status: int = 0
    message: str = ""
    contact_work: float = 0.0

    @property
    def nit(self) -> int:
        """Iterations of the period map (forcing periods integrated), scipy's name for ``n_periods``."""
        return self.n_periods

    @property
    def mean_contact_force(self) -> np.ndarray:
        """Average contact force over each step, ``impulse / dt`` (row 0 is zero)."""
        return self.impulse / self.dt

    @entry_point("SteadyState.contact_force")
    def contact_force(self, t) -> np.ndarray:
        """Contact forces at times ``t`` (compression positive), shape ``(len(t), n_contacts)``.

        The orbit is periodic: ``t`` is taken modulo :attr:`period` (any real time is accepted,
        like :meth:`femodes.PeriodicSolution.contact_force`), and the value is the average force
        over the step ``(t_{i-1}, t_i]`` containing it (:attr:`mean_contact_force`).
        """
        tau = np.mod(_times(t), self.period)
        i = np.searchsorted(self.t, tau, side="left")
        i[i == 0] = self.t.size - 1  # t = 0 is t = period: the last step of the orbit
        return self.mean_contact_force[np.minimum(i, self.t.size - 1)]
