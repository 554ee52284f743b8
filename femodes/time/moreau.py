r"""Moreau-Jean nonsmooth time-stepping of ``M q'' + C q' + K q + f_nl(q) = f(t) - sum_c e_c p_c``.

Scheme (Moreau 1988; Jean 1999; Acary & Brogliato 2008, section 10.1), on a step
``[t_k, t_{k+1}]`` of length ``h`` with row weights ``theta_i``:

.. math::

    M (v_{k+1} - v_k) = h\,\Theta\,F_{k+1} + h\,(I - \Theta)\,F_k - \sum_c e_c P_c, \qquad
    q_{k+1} = q_k + h\,\Theta\,v_{k+1} + h\,(I - \Theta)\,v_k,

with the smooth forces ``F = f(t) - C v - K q - f_s(q)`` (``f_s``: cubic springs and penalty
contacts, treated implicitly by Newton iterations on the step) and the contact impulses
``P_c = \int p_c dt`` over the step. For every unilateral contact whose predicted gap
``g_N(q_k) - (h/2) v_{c,k}`` is non-positive, Newton's impact law at the velocity level holds
(Moreau's viability lemma makes it enforce ``g_N >= 0`` up to ``O(h)``)

.. math::

    0 \le U_{k+1} + e\,U_k \;\perp\; P_{k+1} \ge 0, \qquad U = \dot g_N = -v_c .

Massless DOFs (zero rows of ``M``, e.g. contact nodes after mass redistribution) are algebraic
(quasi-static): their rows use ``theta_i = 1`` (a trapezoidal rule on an algebraic equation
would carry undamped ``(-1)^k`` oscillations), and a contact on a massless DOF is the
position-level Signorini condition ``0 <= g_N(q_{k+1}) \perp P_{k+1} >= 0`` (no penetration
drift). Caveat, measured on a 40-element cantilever with a massless tip stop: every contact
switch excites stiff modes that the trapezoidal rule neither resolves nor damps, so the energy
jumps by O(dt^2) per switch (24 %, 7 %, 1.7 %, 0.6 % over five periods for dt = T/800 ... T/6400,
examples/validation_cantilever.py); use small steps (or theta > 1/2) on such FE models. Over
long runs the energy can grow without bound: the 10-element cantilever of
``benchmarks/bench_cantilever_time.py`` (``C = 0.02 M``) at dt = T/400 and theta = 1/2 reached
1e76 after 480 forcing periods, whereas theta = 0.55 settles to a periodic state and dt = T/6400
stays bounded (an irregular response, as the exact flow finds). :func:`simulate` and
:func:`steady_state` warn when theta = 1/2 meets a contact on a massless DOF.
With these weights the iteration matrix is ``A = M + h Theta C + h^2 Theta K Theta``; it is
factorized once and the contact/nonlinear DOFs ``S`` are coupled through the local Delassus
operator ``W = B_S^T A^{-1} B_S`` (``|S|`` solves), so each step is a small complementarity
problem on ``S``, solved exactly by semismooth Newton on the Fischer-Burmeister function.

Modules: :mod:`~femodes.time.results` (:class:`TimeHistory`, :class:`SteadyState`),
:mod:`~femodes.time.stepper` (the operators of a step, its local problem, the stepping loop),
:mod:`~femodes.time.impact` (the impact law and its complementarity problem),
:mod:`~femodes.time.drivers` (:func:`simulate`, :func:`steady_state`). This module holds the
scheme's description and re-exports the public names.

With ``theta = 1/2`` and ``e = 1`` the smooth part is the trapezoidal rule (energy conserving
for linear systems) and impacts of massful DOFs are conservative: ``U_{k+1} = -U_k`` (energy
drift 9e-12 over 100 impacts of the 1-DOF oscillator).

References
----------
J. J. Moreau, "Unilateral contact and dry friction in finite freedom dynamics", in *Nonsmooth
Mechanics and Applications*, CISM 302, Springer (1988) 1-82.
M. Jean, "The non-smooth contact dynamics method", Comput. Methods Appl. Mech. Engrg. 177 (1999)
235-257.
V. Acary and B. Brogliato, *Numerical Methods for Nonsmooth Dynamical Systems*, Lecture Notes in
Applied and Computational Mechanics 35, Springer (2008), chapter 10.
"""

from __future__ import annotations

from .drivers import simulate, steady_state
from .results import SteadyState, TimeHistory

__all__ = ["TimeHistory", "SteadyState", "simulate", "steady_state"]
