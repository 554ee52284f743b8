"""Discretise layer: nonsmooth time integration of the same models (Moreau-Jean).

* :func:`simulate` -- Moreau-Jean time-stepping (theta-method on the smooth part, Newton's
  impact law at the velocity level for unilateral contacts; Moreau 1988, Jean 1999, Acary &
  Brogliato 2008) of a :class:`~femodes.StructuralModel` or :class:`~femodes.ReducedModel`,
  returning a :class:`TimeHistory`.
* :func:`steady_state` -- integrate a forced model period by period until the state at the
  period start repeats (period-``nu`` orbits for ``nu <= 4``), returning a :class:`SteadyState`.
* :func:`monodromy`, :func:`shoot`, :func:`trajectory` -- event-driven integration (DOP853 with
  impact and kink events, saltation matrices) of the state and variational equations: monodromy
  matrix and Floquet multipliers of a periodic orbit (:class:`Monodromy`), Newton shooting for
  the orbit (:class:`ShootingResult`); the time-domain reference for Hill's method (module
  ``shooting``).

* ``exact.LinearImpactFlow`` -- the closed-form flow of a linear model with rigid stops (modal
  exponentials between contact events; impacts at contacts on DOFs with mass, switches of
  condensed massless contact DOFs; events located to round-off by a certified search; exact
  Fourier coefficients): the shooting refinement of :func:`femodes.estimate_error`
  (``method=fm.error_methods.Shooting()``) and the exact branch :func:`femodes.exact_frequency_response` (an
  analysis: ``femodes.time.exact_frequency_response`` and ``femodes.time.ExactBranch`` still work,
  deprecated).

Modules: ``moreau`` (the scheme, described once, and the public names), ``results`` (the two
result classes), ``stepper`` (operators of a step, its local problem, the stepping loop),
``impact`` (the impact law and its complementarity problem), ``drivers`` (``simulate``,
``steady_state``), ``exact`` (the closed-form flow), ``exact_run`` (one run of it),
``exact_events`` (its certified event search), ``exact_fourier`` (its Fourier coefficients). The
local problems are solved by :func:`femodes.solvers.semismooth_newton`.

This layer imports the models, laws and solvers, never :mod:`femodes.hbm`: both are independent
discretisations of the same model and can be compared.
"""

from .drivers import TimeSteppingOptions
from .moreau import SteadyState, TimeHistory, simulate, steady_state
from .shooting import Monodromy, ShootingResult, monodromy, shoot, trajectory

__all__ = ["TimeHistory", "SteadyState", "simulate", "steady_state", "TimeSteppingOptions",
           "Monodromy", "ShootingResult", "monodromy", "shoot", "trajectory"]


def __getattr__(name: str):
    # the exact branch moved to the analyses and results layers (issue 39): deprecated here
    if name in ("ExactBranch", "exact_frequency_response"):
        from .exact import moved

        return moved(__name__, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
