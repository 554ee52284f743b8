"""The exact branch over the branch's span (:func:`femodes.exact_frequency_response`,
continuation of exact orbits in the frequency), traced once when first needed
(:class:`ExactBranchCache`): its crossings of a point's hyperplane are starts for the points where
Newton from the branch found no orbit, and its folds are the folds the fold search did not locate
(:class:`ExactFolds`). A fold of the branch without a counterpart there is a fold of the
truncation (method ``"truncation"``: no estimate, never met). The cantilever with 3 % modal damping
of benchmarks/README_accuracy.md (section 5): its main fold at H = 20, 3.8431, gets the exact
3.9153002 (a time-domain sweep leaves the upper branch between 3.915 and 3.916), its loop of two
folds at 3.822 and 3.902 none. The seed cases and the FE bars never need the exact branch.
"""

from __future__ import annotations

import logging

import numpy as np

from ..hbm.harmonics import Harmonics
from ..exact_branch import fold_is_upper
from ..exact_response import exact_frequency_response
from ..time.exact import undamped
from .ladder import Ladder
from .options import AccuracyOptions
from .protocol import PointErrors, orbit_amplitudes

__all__ = ["ExactBranchCache", "ExactFolds"]

log = logging.getLogger(__name__)


class ExactBranchCache:
    """The exact branch over ``lad.branch``'s span, traced on the first call of :meth:`branch`
    (None for an undamped model, whose orbits are unbounded at resonances, or if it fails)."""

    def __init__(self, lad: Ladder):
        self.lad = lad
        self._eb = None
        self._Q = None
        self.traced = False

    def branch(self):
        if not self.traced:
            self.traced = True
            b = self.lad.branch
            span = (float(b.omega_truncated[0]), float(b.omega_truncated[-1]))
            if span[0] != span[1] and undamped(self.lad.model):
                log.info("accuracy: no exact branch of an undamped model (its orbits are unbounded at resonances)")
            elif span[0] != span[1]:
                eb = exact_frequency_response(self.lad.model, span)
                log.info("accuracy: exact branch over w %.6g -> %.6g: %d orbits, folds at %s, %d runs (%s)", *span,
                         len(eb), np.round(eb.fold_omega, 6).tolist(), eb.runs, eb.message)
                self._eb = eb if eb.success else None
        return self._eb

    def crossings(self, i: int, plane) -> list[int]:
        """The exact orbits (indices into :meth:`branch`) next to where the exact branch crosses
        point ``i``'s hyperplane ``plane``, the crossing nearest in frequency first (empty without
        an exact branch)."""
        eb = self.branch()
        if eb is None:
            return []
        H = self.lad.h0.n_harmonics
        if self._Q is None:  # the exact orbits' coefficients on the branch's harmonics, and their pieces
            self._Q = [eb.coefficients(j, H)[0] for j in range(len(eb))]
            self._piece = np.searchsorted(np.asarray(eb.pieces), np.arange(len(eb)), side="right")
        g = np.array([plane.at(Q, w) for Q, w in zip(self._Q, eb.omega)])
        piece = self._piece
        cross = [j for j in range(len(eb) - 1) if g[j] * g[j + 1] <= 0.0 and piece[j] == piece[j + 1]]
        w_i = float(self.lad.branch.omega_truncated[i])
        return [j if abs(g[j]) <= abs(g[j + 1]) else j + 1 for j in sorted(cross, key=lambda j: abs(eb.omega[j] - w_i))]


class ExactFolds:
    """The folds still to do, from the exact branch over the span (an :class:`~.protocol.Estimator`
    run after :class:`~.shooting.Shooting`, sharing its :class:`ExactBranchCache`): each is
    paired with the nearest exact fold that turns the same way (distance ``|dw| / w + |da| /
    a_max`` in frequency and the largest contact-DOF amplitude), one to one, nearest pairs first;
    exact folds that a located fold already has are not paired again. A fold left without a pair
    has no counterpart in the limit (a loop of the truncation): no estimate (method
    ``"truncation"``), and no levels either. Without an exact branch the folds stay for the
    levels."""

    def __init__(self, exact: ExactBranchCache, options: AccuracyOptions):
        self.exact, self.options = exact, options

    def estimate(self, lad: Ladder, errors: PointErrors, todo: np.ndarray) -> np.ndarray:
        branch = lad.branch
        todo = todo.copy()
        unresolved = [i for i in branch.folds if todo[i]]
        if not unresolved or self.exact.branch() is None:
            return todo
        eb = self.exact.branch()
        # the folds the fold search located: their exact frequencies (shooting's record, finest 0)
        resolved = [float(errors.omega_limit[i]) for i in branch.folds
                    if not todo[i] and errors.method[i] == "shooting" and errors.finest[i] == 0]
        dofs = sorted({int(d) for d in eb.flow.dofs})
        amp_h = np.max([branch.amplitude(d) for d in dofs], axis=0)
        scale = max(float(amp_h.max()), 1e-300)
        # exact folds (positions k in eb.folds) that a located fold already has are not paired again
        free = [k for k in range(len(eb.folds))
                if not any(abs(eb.fold_omega[k] - w) <= (eb.fold_error[k] + self.options.shooting_fold_slack) * abs(w)
                           for w in resolved)]
        # the same amplitude of the exact folds' orbits (max |q| over a fine grid)
        amp_e = dict(zip(free, eb.amplitude(dofs, samples=800, points=[eb.folds[k] for k in free])))
        pairs = sorted((abs(branch.omega_truncated[i] - eb.fold_omega[k]) / eb.fold_omega[k] + abs(amp_h[i] - amp_e[k]) / scale,
                        i, k) for i in unresolved for k in free if fold_is_upper(branch.omega_truncated, i) == eb.fold_upper[k])
        hk = Harmonics(8 * branch.harmonics.n_harmonics)  # the exact orbit to 8 H harmonics: the error has the tail
        taken_i, taken_j = set(), set()
        for _, i, j in pairs:  # j: a position in eb.folds
            if i in taken_i or j in taken_j:
                continue
            taken_i.add(i)
            taken_j.add(j)
            w, half = float(eb.fold_omega[j]), max(float(eb.fold_error[j]), self.options.shooting_floor)
            errors.record_exact(lad, i, w, half, eb.coefficients(eb.folds[j], hk.n_harmonics)[0], hk,
                                amplitudes=orbit_amplitudes(eb.orbit(eb.folds[j])))
            todo[i] = False
            log.info("accuracy: fold %d (w = %.7g) paired with the exact fold at w = %.7g", i, branch.omega_truncated[i], w)
        for i in unresolved:
            if i not in taken_i:
                todo[i] = False
                errors.finest[i] = 0
                errors.method[i] = "truncation"
                log.info("accuracy: fold %d (w = %.7g) has no counterpart on the exact branch (folds at %s): a fold of "
                         "the truncation, no estimate", i, branch.omega_truncated[i], np.round(eb.fold_omega, 6).tolist())
        return todo
