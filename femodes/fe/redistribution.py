"""Models layer: mass redistribution at contact nodes of FE models (Khenous, Laborde & Renard 2008).

Works on the mass matrix and the FE description of a model (``model.fe``: kind, basis, free
DOFs); it does not know the model class, so :mod:`femodes.model` can call it.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

__all__ = ["redistribute_contact_mass", "RedistributeMass", "ConsistentMass"]

log = logging.getLogger(__name__)


def redistribute_contact_mass(fe, M: sp.spmatrix, dof: int) -> tuple[sp.csr_matrix, dict]:
    """Mass redistribution at a contact DOF (Khenous, Laborde & Renard 2008).

    The contact DOF gets zero mass (its row and column of ``M`` are removed), and the removed
    translational mass is added to the two nearest translational DOFs so that the total mass
    and the first moment (centre of mass) of a rigid translation are conserved:
    ``a + b = dm``, ``a x1 + b x2 = ds``. When that needs a negative nodal mass that would make
    ``M`` indefinite, the whole ``dm`` goes to the nearest DOF (mass conserved, centre of mass
    shifted by ``O(h)``; logged). A massless contact node makes the semi-discrete
    nonsmooth problem well posed (impacts of a point mass are what makes it ill-posed; Thorin &
    Legrand 2018).

    Returns the new mass matrix and a report ``{"mass_moved", "com_shift", "targets", ...}``.
    """
    M = M.tocsr()  # the model's mass, after earlier redistributions
    n = M.shape[0]
    pos = np.asarray(fe.basis.doflocs[0])[fe.free]
    if fe.kind == "beam":
        trans = np.zeros(n, dtype=bool)
        wdofs = fe.nodal[0]
        free_w = np.isin(fe.free, wdofs)
        trans[free_w] = True
        r = trans.astype(float)
        xvec = np.where(trans, pos, 1.0)  # the field w = x has rotations 1
    else:
        trans = np.ones(n, dtype=bool)
        r = np.ones(n)
        xvec = pos.copy()
    keep = np.ones(n)
    keep[dof] = 0.0
    Dk = sp.diags(keep)
    M2 = (Dk @ M @ Dk).tocsr()
    m_tot = r @ (M @ r)
    dm = m_tot - r @ (M2 @ r)
    ds = r @ (M @ xvec) - r @ (M2 @ xvec)
    cand = np.flatnonzero(trans)
    cand = cand[cand != dof]
    order = cand[np.argsort(np.abs(pos[cand] - pos[dof]), kind="stable")]
    report = {"mass_moved": float(dm), "total_mass": float(m_tot)}
    if order.size == 0 or dm <= 0:
        report.update(com_shift=0.0, targets=[])
        return M2.tocsr(), report
    i1 = order[0]
    applied = None
    if order.size >= 2:
        i2 = order[1]
        x1, x2 = pos[i1], pos[i2]
        if abs(x1 - x2) > 0:
            b = (ds - dm * x1) / (x2 - x1)
            a = dm - b
            trial = (M2 + sp.csr_matrix(([a, b], ([i1, i2], [i1, i2])), shape=M2.shape)).tocsr()
            if (a >= 0 and b >= 0) or _is_positive_definite(trial, dof):
                applied = trial
                report.update(com_shift=0.0, targets=[int(i1), int(i2)], added=[float(a), float(b)])
    if applied is None:
        applied = (M2 + sp.csr_matrix(([dm], ([i1], [i1])), shape=M2.shape)).tocsr()
        com_shift = (dm * pos[i1] - ds) / m_tot
        report.update(com_shift=float(com_shift), targets=[int(i1)], added=[float(dm)])
        log.warning("mass redistribution at DOF %d: centre of mass shifted by %.3g to keep M definite", dof, com_shift)
    return applied, report


def _is_positive_definite(M: sp.csr_matrix, massless: int) -> bool:
    """Cholesky test of M without the massless DOF (banded after reverse Cuthill-McKee)."""
    idx = np.setdiff1d(np.arange(M.shape[0]), [massless])
    A = M[idx][:, idx].tocsr()
    perm = reverse_cuthill_mckee(A, symmetric_mode=True)
    A = A[perm][:, perm].tocoo()
    bw = int(np.max(np.abs(A.row - A.col))) if A.nnz else 0
    ab = np.zeros((bw + 1, A.shape[0]))
    upper = A.col >= A.row
    ab[bw + A.row[upper] - A.col[upper], A.col[upper]] = A.data[upper]
    try:
        sla.cholesky_banded(ab, lower=False)
        return True
    except np.linalg.LinAlgError:
        return False


class RedistributeMass:
    """Contact-mass strategy: zero mass at each contact DOF, moved to its nearest translational
    neighbours (:func:`redistribute_contact_mass`). The default for complementarity contacts of
    FE models, whose nonsmooth modes are otherwise ill-posed under mesh refinement (Thorin &
    Legrand 2018)."""

    def apply(self, fe, M, dof: int):
        """``(M, report)`` after moving the mass of ``dof``; ``report`` is None if there was none."""
        if fe is None:
            raise ValueError("with_contact: RedistributeMass() needs an FE model (bar or beam), not a discrete one")
        if M[dof, dof] <= 0:
            return M, None
        M, report = redistribute_contact_mass(fe, M, dof)
        report["dof"] = dof
        return M, report

    def __repr__(self) -> str:
        return "RedistributeMass()"


class ConsistentMass:
    """Contact-mass strategy: keep the consistent mass at contact DOFs (the default for penalty
    contacts and discrete models)."""

    def apply(self, fe, M, dof: int):
        return M, None

    def __repr__(self) -> str:
        return "ConsistentMass()"

