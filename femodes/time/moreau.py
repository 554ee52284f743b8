r"""Moreau-Jean nonsmooth time-stepping of ``M q'' + C q' + K q + f_nl(q) = f(t) - sum_c e_c p_c``.

Scheme (Moreau 1988; Jean 1999; Acary & Brogliato 2008, section 10.1), on a step
``[t_k, t_{k+1}]`` of length ``h`` with row weights ``theta_i``:

.. math::

    M (v_{k+1} - v_k) = h\,\Theta\,F_{k+1} + h\,(I - \Theta)\,F_k - \sum_c e_c P_c, \qquad
    q_{k+1} = q_k + h\,\Theta\,v_{k+1} + h\,(I - \Theta)\,v_k,

with the smooth forces ``F = f(t) - C v - K q - f_s(q)`` (``f_s``: cubic springs and penalty
contacts, implicit by Newton on the step) and the contact impulses ``P_c = \int p_c dt``. For every
unilateral contact whose predicted gap ``g_N(q_k) - (h/2) v_{c,k}`` is non-positive, Newton's
impact law holds at the velocity level (``g_N >= 0`` up to ``O(h)``: Moreau's viability lemma):

.. math::

    0 \le U_{k+1} + e\,U_k \;\perp\; P_{k+1} \ge 0, \qquad U = \dot g_N = -v_c .

Massless DOFs (zero rows of ``M``) are algebraic: their rows use ``theta_i = 1``, and a contact
on one is the position-level Signorini condition ``0 <= g_N(q_{k+1}) \perp P_{k+1} >= 0``. Its
switches excite stiff modes that theta = 1/2 does not damp: :func:`simulate` and
:func:`steady_state` warn then (measurements: :doc:`/guide/performance`). The iteration matrix
``A = M + h Theta C + h^2 Theta K Theta`` is factorized once; the contact/nonlinear DOFs ``S`` are
coupled through the Delassus operator ``W = B_S^T A^{-1} B_S``, so each step is a small
complementarity problem on ``S``, solved by semismooth Newton on the Fischer-Burmeister function.
With ``theta = 1/2`` and ``e = 1`` the smooth part is the trapezoidal rule and impacts of massful
DOFs are conservative (``U_{k+1} = -U_k``).

This module re-exports the public names of :mod:`~femodes.time.results`,
:mod:`~femodes.time.stepper`, :mod:`~femodes.time.impact` and :mod:`~femodes.time.drivers`.

References
----------
J. J. Moreau, "Unilateral contact and dry friction in finite freedom dynamics", in *Nonsmooth
Mechanics and Applications*, CISM 302, Springer (1988) 1-82.
M. Jean, "The non-smooth contact dynamics method", Comput. Methods Appl. Mech. Engrg. 177 (1999)
235-257.
V. Acary and B. Brogliato, *Numerical Methods for Nonsmooth Dynamical Systems*, Springer (2008).
"""

from __future__ import annotations

from .drivers import simulate, steady_state
from .results import SteadyState, TimeHistory

__all__ = ["TimeHistory", "SteadyState", "simulate", "steady_state"]
