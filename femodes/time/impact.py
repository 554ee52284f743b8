r"""The impact law of a Moreau-Jean step and its complementarity problem.

For every unilateral contact whose predicted gap ``g_N(q_k) - (h/2) v_{c,k}`` is non-positive,
Newton's impact law at the velocity level holds on the step (Moreau 1988; Acary & Brogliato 2008,
section 10.1),

.. math::

    0 \le U_{k+1} + e\,U_k \;\perp\; P_{k+1} \ge 0, \qquad U = \dot g_N = -v_c,

and a contact on a massless DOF is quasi-static, the position-level Signorini condition
``0 <= g_N(q_{k+1}) perp P_{k+1} >= 0``, always in the problem. Both read ``0 <= y perp P >= 0``
with ``y = b - v_{c,k+1}`` (:meth:`ImpactLaw.rhs`). Without smooth laws on the local DOFs,
``v_{c,k+1}`` is affine in the impulses through the Delassus operator ``W``, so the step is the
linear complementarity problem ``0 <= P perp W P + q >= 0`` (:func:`solve_lcp`), solved by
semismooth Newton (:func:`femodes.solvers.semismooth_newton`) on the Fischer-Burmeister function.
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import UnilateralContact
from ..solvers import NewtonOptions, NewtonResult, semismooth_newton

__all__ = ["ImpactLaw", "fischer_burmeister", "solve_lcp"]

_FB_KINK = 1.0 - 1.0 / math.sqrt(2.0)

#: Up to this many contacts, :meth:`ImpactLaw.free_flight` tests them one by one in Python floats
#: (~0.2 us each, against ~4 us for the vectorised test of any number).
_FEW = 8


class ImpactLaw:
    """The unilateral contacts of a model on a step of length ``h``: which are active, and ``b``.

    Parameters
    ----------
    laws : list of UnilateralContact
        One per contact (evaluated at once by their stacked law, :meth:`UnilateralContact.stack`).
    dofs : ndarray of int
        Contact DOFs.
    massless : ndarray of bool
        Whether each contact DOF has no mass (quasi-static, position-level Signorini law).
    restitution : float
        Newton's coefficient ``e`` (massive contact DOFs).
    h : float
        Time step.
    """

    def __init__(self, laws, dofs: np.ndarray, massless: np.ndarray, restitution: float, h: float):
        self.law = UnilateralContact.stack(laws)
        self.dofs = np.asarray(dofs, dtype=int)
        self.massless = np.asarray(massless, dtype=bool)
        self.any_massless = bool(np.any(self.massless))
        self.all_massless = bool(self.massless.size) and bool(np.all(self.massless))
        self.e, self.h = float(restitution), float(h)
        # per-step constants: h/2 of the predicted gap, and every contact active (all massless)
        self.half_h = 0.5 * self.h
        self.all_active = np.ones(self.dofs.size, dtype=bool)
        self.all_active.flags.writeable = False
        # a few massive contacts (the common case): the free-flight test in Python floats, the
        # operations of predicted_active (g_N = gap - q, UnilateralContact.gap_function) per contact
        self._few = (tuple(zip(self.law.gap.tolist(), self.dofs.tolist()))
                     if self.dofs.size <= _FEW and not self.any_massless else None)

    def __len__(self) -> int:
        return self.dofs.size

    def predicted_active(self, qc: np.ndarray, vc: np.ndarray) -> np.ndarray:
        """Massive contacts whose gap predicted at mid-step, ``g_N(q_k) - (h/2) v_k``, is ``<= 0``
        (Moreau's viability lemma then enforces ``g_N >= 0`` up to ``O(h)``)."""
        return self.law.gap_function(qc) - self.half_h * vc <= 0.0

    def free_flight(self, x: np.ndarray, n: int) -> bool:
        """Whether the step from the state ``x = [q; v]`` of ``n`` DOFs is a free flight: no
        contact in the complementarity problem (no massless contact, and :meth:`predicted_active`
        False for every massive one). Called on every step of a contact-only model."""
        if self.any_massless:
            return False
        if self._few is not None:
            half_h = self.half_h
            for gap, d in self._few:
                if (gap - x.item(d)) - half_h * x.item(n + d) <= 0.0:
                    return False
            return True
        return not self.predicted_active(x[self.dofs], x[n + self.dofs]).any()

    def rhs(self, qc: np.ndarray, vc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(active, b)`` at the start state of a step: the contacts in the complementarity problem
        and the right-hand sides of ``y = b - v_{c,k+1}``: ``-e v_{c,k}`` (impact law) or
        ``g_N(q_k) / h`` (massless: ``g_N(q_{k+1}) = g_N(q_k) - h v_{c,k+1}`` with theta = 1).
        ``active`` may be a shared read-only array."""
        if not self.any_massless:
            return self.predicted_active(qc, vc), -self.e * vc
        g0 = self.law.gap_function(qc)
        if self.all_massless:  # every contact quasi-static: all in the problem
            return self.all_active, g0 / self.h
        active = self.massless | (g0 - self.half_h * vc <= 0.0)
        return active, np.where(self.massless, g0 / self.h, -self.e * vc)


def fischer_burmeister(a: np.ndarray, b: np.ndarray):
    """``phi(a, b) = a + b - sqrt(a^2 + b^2)`` (zero iff ``0 <= a perp b >= 0``) and its partials.

    At ``a = b = 0`` the element ``(1 - 1/sqrt 2, 1 - 1/sqrt 2)`` of the generalized Jacobian is used.
    """
    rr = np.sqrt(a * a + b * b)
    safe = rr > 0
    da = np.where(safe, 1.0 - a / np.where(safe, rr, 1.0), _FB_KINK)
    db = np.where(safe, 1.0 - b / np.where(safe, rr, 1.0), _FB_KINK)
    return a + b - rr, da, db


def solve_lcp(W: np.ndarray, q: np.ndarray, x0: np.ndarray, options: NewtonOptions) -> tuple[np.ndarray, NewtonResult]:
    """Solve ``0 <= x perp W x + q >= 0`` (small dense ``W`` with a positive diagonal).

    Semismooth Newton (:func:`femodes.solvers.semismooth_newton` with ``options``) on the
    Fischer-Burmeister function of ``(x, (W x + q) / diag(W))``, for the unknown scaled by
    ``s = 1 + max |q / diag(W)|`` (the largest impulse that a single contact could need), so that
    the solver's absolute tolerance is relative to the data. Returns ``(max(x, 0), result)``.
    """
    d = np.diag(W).copy()
    s = 1.0 + float(np.max(np.abs(q / d)))
    qs = q / s

    def phi(x):
        y = (W @ x + qs) / d
        r, da, db = fischer_burmeister(x, y)
        return r, np.diag(da) + (db / d)[:, None] * W

    res = semismooth_newton(phi, np.maximum(x0, 0.0) / s, options=options)
    return np.maximum(res.x, 0.0) * s, res
