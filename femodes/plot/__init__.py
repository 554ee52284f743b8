"""Outputs layer: matplotlib figures of branches and periodic solutions.

Every function draws on the keyword ``ax=`` (a new figure if ``ax`` is None; passing it by
position is deprecated) and returns the Axes, except
:func:`contact_pressure`, which draws a map, a side panel and a colour bar and returns the Figure.
matplotlib is imported only when a function is called (``pip install 'femodes[plot]'``).

- :func:`frequency_energy`: backbones (nonlinear modes) and forced curves, frequency against
  energy (log axis).
- :func:`frequency_amplitude`: amplitude of one DOF against frequency, folds marked (was
  ``frequency_response``, the name of the analysis: a deprecated alias).
- :func:`time_history`: one DOF over time, contact forces on a twin axis.
- :func:`phase_portrait`: velocity against displacement of one DOF.
- :func:`mode_shape`: deflection snapshots along the mesh (reduced models expanded).
- :func:`contact_pressure`: space-time map of the contact pressure along a contact boundary
  of a meshed solid, with the total contact force over the period.
"""

from __future__ import annotations

from .branches import frequency_amplitude, frequency_energy, frequency_response
from .pressure import contact_pressure
from .solutions import mode_shape, phase_portrait, time_history

__all__ = ["frequency_energy", "frequency_amplitude", "time_history", "phase_portrait", "mode_shape",
           "contact_pressure", "frequency_response"]
