"""Results layer: what a result knows of the contacts of its model (:class:`ContactInfo`), how a
model's contacts differ from them, and the contact quality (penetration, tension) of stored points."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..hbm.harmonics import Harmonics
from ..laws import PenaltyContact, UnilateralContact

__all__ = ["ContactInfo", "contact_differences", "contact_quality", "fine_points", "peak_amplitude"]

@dataclass(frozen=True, eq=False)
class ContactInfo:
    """What a result needs to know about the contacts of the model it was solved on."""

    kinds: tuple  # "complementarity" or "penalty" per model contact, in model.contacts order
    dofs: tuple
    gaps: tuple
    stiffness: tuple  # penalty stiffness (nan for complementarity)
    slots: tuple  # column in P for complementarity contacts (-1 for penalty)
    c: tuple  # complementarity parameter used (nan for penalty)

    @classmethod
    def from_system(cls, system) -> ContactInfo:
        kinds, dofs, gaps, stiff, slots, cs = [], [], [], [], [], []
        uc = {ct.dof: ct for ct in system.unilateral}
        for a in system.model.contacts:
            dofs.append(int(a.dof))
            gaps.append(float(a.item.gap))
            if a.dof in uc:
                kinds.append("complementarity")
                stiff.append(math.nan)
                slots.append(uc[a.dof].slot)
                cs.append(uc[a.dof].c)
            else:
                kinds.append("penalty")
                stiff.append(float(a.item.stiffness))
                slots.append(-1)
                cs.append(math.nan)
        return cls(tuple(kinds), tuple(dofs), tuple(gaps), tuple(stiff), tuple(slots), tuple(cs))

    def to_json(self) -> dict:
        return {k: list(getattr(self, k)) for k in ("kinds", "dofs", "gaps", "stiffness", "slots", "c")}

    @cached_property
    def laws(self) -> tuple:
        """The contact laws (``at`` = their DOF index), rebuilt from the stored parameters: results
        evaluate gaps and penalty forces with the formulas of :mod:`femodes.laws`."""
        return tuple(
            UnilateralContact(at=d, gap=g, c=c) if kind == "complementarity"
            else PenaltyContact(at=d, gap=g, stiffness=k)
            for kind, d, g, k, c in zip(self.kinds, self.dofs, self.gaps, self.stiffness, self.c)
        )

    @classmethod
    def from_json(cls, d: dict) -> ContactInfo:
        return cls(*(tuple(d[k]) for k in ("kinds", "dofs", "gaps", "stiffness", "slots", "c")))


def contact_differences(contacts: ContactInfo, model) -> list[str]:
    """How the contacts of ``model`` differ from those a result stores (DOF, law, gap, penalty
    stiffness), in words; empty if they agree."""
    ci = contacts
    if len(model.contacts) != len(ci.kinds):
        return [f"{len(ci.kinds)} contacts in the result, {len(model.contacts)} in this model"]
    out = []
    for j, (a, kind, dof, gap, k) in enumerate(zip(model.contacts, ci.kinds, ci.dofs, ci.gaps, ci.stiffness)):
        mkind = "penalty" if isinstance(a.item, PenaltyContact) else "complementarity"
        where = f"contact {j} (DOF {dof})"
        if int(a.dof) != int(dof):
            out.append(f"contact {j}: DOF {dof} in the result, {int(a.dof)} in this model")
        elif mkind != kind:
            out.append(f"{where}: {kind} in the result, {mkind} in this model")
        elif float(a.item.gap) != float(gap):
            out.append(f"{where}: gap {gap:g} in the result, {float(a.item.gap):g} in this model")
        elif kind == "penalty" and float(a.item.stiffness) != float(k):
            out.append(f"{where}: stiffness {k:g} in the result, {float(a.item.stiffness):g} in this model")
    return out


def fine_points(harmonics: Harmonics) -> int:
    """Samples per period of the fine grid on which contact quality is measured."""
    return max(2048, 64 * harmonics.n_coef)


def peak_amplitude(harmonics: Harmonics, C: np.ndarray, n: int | None = None) -> np.ndarray:
    """``max_t |q(t)|`` of the series with coefficients ``C`` (shape ``(m, n_coef)``, one DOF), one
    per row: the largest sample of an equidistant grid of ``n`` phases (default
    :func:`fine_points`), refined by parabolas through three points around it (spacings
    ``2 pi / n``, then 1/16, 1/256 and 1/4096 of it). The grid alone reads low by about
    ``(pi k / n)^2 / 2`` (2e-5 for a pure first harmonic on 512 points); the series at the last
    parabola's vertex is exact to round-off (a contact orbit's sharp peak needs the smaller
    spacings: two of them left 3e-11). Never below the grid's largest sample."""
    C = np.atleast_2d(np.asarray(C, dtype=float))
    if not len(C):
        return np.zeros(0)
    n = fine_points(harmonics) if n is None else int(n)
    grid = harmonics.grid
    theta = 2.0 * np.pi * np.arange(n) / n
    q = C @ grid.synthesis(theta).T                     # (m, n)
    k = np.argmax(np.abs(q), axis=1)
    best = np.abs(q[np.arange(len(C)), k])
    centre = theta[k]
    for step in 2.0 * np.pi / n / 16.0 ** np.arange(4):
        around = centre[:, None] + step * np.array([-1.0, 0.0, 1.0])[None, :]
        E = grid.synthesis(around.ravel()).reshape(len(C), 3, -1)
        f = np.abs(np.einsum("mpc,mc->mp", E, C))
        curv = f[:, 0] - 2.0 * f[:, 1] + f[:, 2]
        ok = curv < 0.0                                  # a maximum between the three
        shift = np.where(ok, 0.5 * (f[:, 0] - f[:, 2]) / np.where(ok, curv, -1.0), 0.0)
        centre = centre + np.clip(shift, -1.0, 1.0) * step
    # the series itself at the vertex (a parabola's value would overshoot by O(step^3))
    at = np.abs(np.einsum("mc,mc->m", grid.synthesis(centre).reshape(len(C), -1), C))
    return np.maximum(best, at)


def contact_quality(harmonics: Harmonics, contacts: ContactInfo, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Per point, over all contacts on a fine grid of ``fine_points`` equidistant phases over the
    period: penetration ``max(0, max_t -g_N)``, tension ``max(0, max_t -p)``, the largest ``|q|``
    of a contact DOF and the largest contact force ``max_t p`` (rows 0-3 of the ``(4, n_points)``
    result). The single definition behind the penetration and tension of
    :class:`PeriodicSolution` and :class:`Branch`.

    ``Q``, ``P`` of shapes ``(n_points, n_coef, n_dofs)`` and ``(n_points, n_coef, n_p)``: one
    synthesis matrix for all points, only the contact DOFs evaluated (the error estimate's
    contact quality of a 94-point branch took 1.2 s point by point, four syntheses each)."""
    m = Q.shape[0]
    out = np.zeros((4, m))
    if not contacts.kinds or not m:
        return out
    out[3] = -np.inf
    n = fine_points(harmonics)
    E = harmonics.grid.synthesis(2 * np.pi * np.arange(n) / n)
    for kind, law, dof, slot in zip(contacts.kinds, contacts.laws, contacts.dofs, contacts.slots):
        u = E @ Q[:, :, dof].T  # (n, m)
        f = E @ P[:, :, slot].T if kind == "complementarity" else law.force(u)[0]
        out[0] = np.maximum(out[0], np.max(-law.gap_function(u), axis=0))
        out[1] = np.maximum(out[1], np.max(-f, axis=0))
        out[2] = np.maximum(out[2], np.max(np.abs(u), axis=0))
        out[3] = np.maximum(out[3], np.max(f, axis=0))
    return out
