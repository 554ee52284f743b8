"""Models layer: mass redistribution at contact nodes of FE models (Khenous, Laborde & Renard 2008).

Works on the mass matrix and the FE description of a model (``model.fe``: kind, basis, free
DOFs); it does not know the model class, so :mod:`femodes.model` can call it. Bars and beams
move the mass of one contact DOF at a time (:func:`redistribute_contact_mass`); solids move the
mass of all the contact DOFs of a boundary at once (:func:`redistribute_surface_mass`).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

__all__ = ["redistribute_contact_mass", "redistribute_surface_mass", "RedistributeMass", "ConsistentMass", "apply_each"]

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
    pos = np.asarray(fe.doflocs[0])[fe.free]
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
    report: dict[str, Any] = {"mass_moved": float(dm), "total_mass": float(m_tot)}
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


def redistribute_surface_mass(fe, M: sp.spmatrix, dofs) -> tuple[sp.csr_matrix, dict]:
    """Mass redistribution at the contact DOFs of a meshed solid (all at once).

    ``M_new = D M D + sum_k dm_k w_k w_k^T`` (``D`` zeroes the contact DOFs ``S``).

    The generalisation of Khenous, Laborde & Renard (2008) used here works for each displacement
    component ``c`` separately (the consistent mass of vector elasticity couples only equal
    components). Removing the rows and columns of ``S`` takes from the rigid translation
    ``r_c`` (ones on the ``c`` DOFs) the mass ``r^T M r - r^T D M D r`` and the first moments
    ``r^T M x - r^T D M D x`` (``x`` each coordinate of the nodes). Contact DOF ``i`` is
    attributed ``dm_i = 2 (M r)_i - (M_SS r_S)_i`` and ``ds_i = (M x)_i + x_i (M r)_i -
    (M_SS x_S)_i``, which sum exactly to those losses; a DOF with ``dm_i <= 0`` (vertices of P2
    simplices, whose consistent row sums are zero or negative) gives its ``dm_i`` and ``ds_i`` to
    its coupled contact neighbour of largest mass (split equally among neighbours whose masses
    tie to ``1e-9`` relative, all such DOFs at once: see :func:`_lumps`), repeatedly, so that
    every lump ``k`` has ``dm_k > 0``. The lumps, and so ``M_new``, depend neither on round-off
    nor on the numbering of the DOFs: a rotated or mirrored mesh gets the rotated or mirrored
    mass matrix.

    Each lump becomes a point mass ``dm_k`` at its centre ``ds_k / dm_k``, carried by the
    ``c`` DOFs of the surrounding non-contact nodes (the two rings of neighbours in ``M``: the
    adjacent interior layer and the next one, as the second neighbour in 1-D) through
    interpolation weights ``w_k`` that are exact for affine fields: ``sum_j w_j = 1`` and
    ``sum_j w_j x_j = ds_k / dm_k`` in every coordinate (the smallest such weights, mass-weighted
    least norm). Its kinetic energy is ``dm_k (w_k . q')^2 / 2``. Hence

    * the contact DOFs are exactly massless and ``M`` stays symmetric;
    * total mass and first moments (centre of mass) of every rigid translation are conserved:
      ``r^T (dm w w^T) r = dm`` and ``r^T (dm w w^T) x = ds``;
    * ``M_new`` is positive definite on the other DOFs without any check: ``D M D`` is (a
      principal submatrix of ``M``) and every added term is positive semidefinite.

    Cost and why not diagonal lumps: :doc:`/guide/solids` (Design notes).

    Returns the new mass matrix and a report ``{"dofs", "mass_moved", "total_mass",
    "com_shift", "lumps"}`` (``com_shift``: largest change of a centre of mass, relative to the
    mesh extent; zero to round-off unless the neighbours of a contact node all lie on a line).
    """
    M = sp.csr_matrix(M)
    n = M.shape[0]
    dofs = np.unique(np.asarray(dofs, dtype=int))
    diag = M.diagonal()
    dofs = dofs[diag[dofs] > 0]
    report = {"dofs": dofs.tolist(), "mass_moved": 0.0, "total_mass": 0.0, "com_shift": 0.0, "lumps": 0}
    if dofs.size == 0:
        return M, report
    pos, comp = _dof_positions(fe, n)
    keep = np.ones(n)
    keep[dofs] = 0.0
    Dk = sp.diags(keep)
    M2 = (Dk @ M @ Dk).tocsr()
    massless = np.zeros(n, dtype=bool)
    massless[dofs] = True
    massless |= diag <= 0
    diag2 = M2.diagonal()
    rows, cols, vals = [], [], []
    total = moved = 0.0
    n_lumps = 0
    for c in np.unique(comp[dofs]):
        r = (comp == c).astype(float)
        S = dofs[comp[dofs] == c]
        Mr = M @ r
        MX = (M @ (pos * r).T).T  # (dim, n): M times each coordinate field on the c DOFs
        MSS = M[S][:, S].tocsr()
        dm = 2.0 * Mr[S] - MSS @ np.ones(S.size)
        ds = MX[:, S] + pos[:, S] * Mr[S] - (MSS @ pos[:, S].T).T
        total += float(r @ Mr)
        moved += float(dm.sum())
        for members, m_k, s_k in _lumps(MSS, dm, ds):
            targets = _rings(M, S[members], comp, c, massless, 2)
            if targets.size == 0:
                raise ValueError(
                    f"with_contact: contact DOF {S[members[0]]} has no massive neighbour to take its mass; use "
                    "contact_mass=fm.ConsistentMass() or a finer mesh"
                )
            w = _affine_weights(diag2[targets], pos[:, targets], s_k / m_k)
            rows.append(np.repeat(targets, targets.size))
            cols.append(np.tile(targets, targets.size))
            vals.append(m_k * np.outer(w, w).ravel())
            n_lumps += 1
    added = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    new = (M2 + added).tocsr()
    new = (0.5 * (new + new.T)).tocsr()
    extent = float(np.ptp(pos, axis=1).max()) or 1.0
    shift = _com_shift(M, new, pos, comp, dofs) / extent
    report.update(mass_moved=moved, total_mass=total, com_shift=shift, lumps=n_lumps)
    if shift > 1e-9:
        log.warning("surface mass redistribution of %d contact DOFs: the neighbours of some contact node do not span "
                    "the coordinates; centre of mass shifted by %.3g of the mesh extent", dofs.size, shift)
    return new, report


def _lumps(MSS: sp.csr_matrix, dm: np.ndarray, ds: np.ndarray, rtol: float = 1e-9):
    """``[(member indices, mass, moments)]``: the contact DOFs grouped into lumps of positive mass.

    A lump with ``mass <= tiny`` (P2 vertices) gives its mass and moments to its coupled lumps
    of largest mass, repeatedly, until every lump has a positive mass. Two rules make the
    result independent of round-off and of the DOF numbering:

    * candidates within ``rtol`` (relative) of the largest mass are ties, and the mass and
      moments are split equally among them (each tied lump gets ``dm_i / t`` and
      ``ds_i / t`` and counts DOF ``i`` among its members, whose rings carry its mass). Picking
      one of them (the first index, or the one round-off makes largest) conserves mass and
      moments too, but breaks the symmetries of the mesh, and mirror-image or rotated meshes
      would then get different mass matrices; the equal split keeps them, and the shares still
      add up to ``dm_i`` and ``ds_i``, so the total mass and the centre of mass are conserved
      (exactly, up to round-off, as before).
    * all the lumps with too little mass move at once (Jacobi passes): the choices of a pass
      are made on the masses at its start, so no lump is served first. A lump whose coupled
      lumps all have too little mass waits for them to be absorbed; if none can move, each
      connected group of such lumps is merged into one.

    The old rule (one merge at a time in DOF order, the first of the round-off-largest
    neighbours) gave the same lumps where no choice met a tie or an earlier merge; elsewhere its
    result depended on the numbering. Cost: a pass costs its light lumps times their couplings
    (set operations, no scan of all DOFs); meshes need a few passes, so near-linear in the
    number of contact DOFs.
    """
    n = dm.size
    mass = np.asarray(dm, dtype=float).copy()
    mom = np.array(ds, dtype=float, copy=True)
    tiny = 1e-12 * max(float(np.abs(mass).max(initial=0.0)), 1e-300)
    MSS = sp.csr_matrix(MSS)
    members = [{i} for i in range(n)]
    adj = [set(MSS.indices[MSS.indptr[i]:MSS.indptr[i + 1]].tolist()) - {i} for i in range(n)]
    alive = np.ones(n, dtype=bool)
    bad = set(np.flatnonzero(mass <= tiny).tolist())
    while bad:
        moves = []
        for i in sorted(bad):
            if not adj[i]:
                continue
            cand = np.fromiter(sorted(adj[i]), dtype=int, count=len(adj[i]))
            best = float(mass[cand].max())
            if best <= tiny:  # only lumps with too little mass around: wait for them
                continue
            moves.append((i, cand[mass[cand] >= best - rtol * best]))
        if not moves:
            if not _merge_stuck(bad, adj, members, mass, mom, alive):
                break
            bad = {i for i in bad if alive[i] and mass[i] <= tiny}
            continue
        # the senders of a pass are not targets (targets have mass > tiny): their masses, moments,
        # members and couplings are the ones at the start of the pass, whatever the order below
        touched = set()
        for i, targets in moves:
            t_set = set(targets.tolist())
            share_m = mass[i] / targets.size
            share_s = mom[:, i] / targets.size
            for t in targets:
                mass[t] += share_m
                mom[:, t] += share_s
                members[t] |= members[i]
                adj[t] |= adj[i]
            for u in adj[i]:
                adj[u].discard(i)
                adj[u] |= t_set
                adj[u].discard(u)
            alive[i] = False
            mass[i] = 0.0
            mom[:, i] = 0.0
            adj[i] = set()
            members[i] = set()
            bad.discard(i)
            touched |= t_set
        bad |= {t for t in touched if alive[t] and mass[t] <= tiny}
    out = []
    for lump in np.flatnonzero(alive):
        if mass[lump] <= tiny:
            raise ValueError(
                "with_contact: the consistent mass of a contact patch is not positive: an isolated P2 vertex, or "
                "contacts on two faces too close for both (the mass moved off one face went onto the other with "
                "a negative weight); use contact_mass=fm.ConsistentMass(), more elements across the thickness, "
                "or order=1 for an isolated P2 vertex"
            )
        out.append((np.array(sorted(members[lump]), dtype=int), float(mass[lump]), mom[:, lump]))
    return out


def _merge_stuck(bad, adj, members, mass, mom, alive) -> bool:
    """Merge every connected group of lumps of ``bad`` (all of whose coupled lumps are in ``bad``)
    into its lowest index; False if there was nothing to merge."""
    merged = False
    seen = set()
    for i in sorted(bad):
        if i in seen or not adj[i]:
            continue
        group, stack = {i}, [i]
        while stack:
            for u in adj[stack.pop()]:
                if u not in group:
                    group.add(u)
                    stack.append(u)
        seen |= group
        root = min(group)
        rest = sorted(group - {root})
        for j in rest:
            mass[root] += mass[j]
            mom[:, root] += mom[:, j]
            members[root] |= members[j]
            alive[j] = False
            mass[j] = 0.0
            mom[:, j] = 0.0
            members[j] = set()
        outside = set().union(*(adj[j] for j in group)) - group
        for j in rest:
            adj[j] = set()
        adj[root] = outside
        for u in outside:
            adj[u] -= group
            adj[u].add(root)
        merged = True
    return merged


def _rings(M: sp.csr_matrix, start: np.ndarray, comp: np.ndarray, c: int, massless: np.ndarray, n_rings: int) -> np.ndarray:
    """DOFs of component ``c`` within ``n_rings`` couplings of ``start`` in ``M``, without massless
    (contact) DOFs; the first ring is found through the contact DOFs' own couplings."""
    seen = set(int(i) for i in start)
    ring = np.asarray(start, dtype=int)
    found = []
    for _ in range(n_rings):
        if ring.size == 0:
            break
        cols = np.unique(np.concatenate([M.indices[M.indptr[i]:M.indptr[i + 1]] for i in ring]))
        cols = cols[(comp[cols] == c) & ~massless[cols]]
        cols = np.array([j for j in cols if j not in seen], dtype=int)
        seen.update(int(j) for j in cols)
        found.append(cols)
        ring = cols
    return np.concatenate(found) if found else np.zeros(0, dtype=int)


def _affine_weights(mass: np.ndarray, x: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Weights ``w`` with ``sum w = 1`` and ``x w = centre``, minimising ``sum w_j^2 / mass_j``
    (least squares on the constraints if the targets do not span the coordinates)."""
    A = np.vstack([np.ones(mass.size), x])
    b = np.concatenate([[1.0], centre])
    m = np.maximum(mass, 1e-300)
    G = (A * m) @ A.T
    lam = np.linalg.lstsq(G, b, rcond=1e-12)[0]
    return m * (A.T @ lam)


def _dof_positions(fe, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates ``(dim, n)`` and component index of every model DOF of a solid."""
    nodal = np.asarray(fe.nodal)
    X = np.asarray(fe.node_coordinates, dtype=float)
    node_of_full = np.full(fe.n_full, -1)
    comp_of_full = np.full(fe.n_full, -1)
    for c in range(nodal.shape[0]):
        node_of_full[nodal[c]] = np.arange(nodal.shape[1])
        comp_of_full[nodal[c]] = c
    free = np.asarray(fe.free)[:n]
    return X[:, node_of_full[free]], comp_of_full[free]


def _com_shift(M: sp.csr_matrix, new: sp.csr_matrix, pos: np.ndarray, comp: np.ndarray, dofs: np.ndarray) -> float:
    """Largest change of the centre of mass over the components of the contact DOFs."""
    shift = 0.0
    for c in np.unique(comp[dofs]):
        r = (comp == c).astype(float)
        for X in pos * r:
            before = (r @ (M @ X)) / (r @ (M @ r))
            after = (r @ (new @ X)) / (r @ (new @ r))
            shift = max(shift, abs(after - before))
    return shift


def apply_each(strategy, fe, M, dofs) -> tuple:
    """``(M, reports)`` after ``strategy.apply(fe, M, dof)`` on each of ``dofs`` in turn (the
    reports that are not None): what a strategy without ``apply_all`` does to several DOFs."""
    reports = []
    for dof in dofs:
        M, rep = strategy.apply(fe, M, dof)
        if rep is not None:
            reports.append(rep)
    return M, reports


class RedistributeMass:
    """Contact-mass strategy: zero mass at each contact DOF, moved to its nearest translational
    neighbours (:func:`redistribute_contact_mass` for bars and beams; for solids, all contact
    DOFs at once to the interior rings of nodes, :func:`redistribute_surface_mass`). The default
    for complementarity contacts of FE models, whose nonsmooth modes are otherwise ill-posed
    under mesh refinement (Thorin & Legrand 2018)."""

    def apply(self, fe, M, dof: int):
        """``(M, report)`` after moving the mass of ``dof``; ``report`` is None if there was none."""
        if fe is None:
            raise ValueError("with_contact: RedistributeMass() needs an FE model (bar or beam), not a discrete one")
        if M[dof, dof] <= 0:
            return M, None
        M, report = redistribute_contact_mass(fe, M, dof)
        report["dof"] = dof
        return M, report

    def apply_all(self, fe, M, dofs):
        """``(M, reports)`` after moving the mass of all ``dofs``: one DOF at a time for bars and
        beams (:meth:`apply`), all at once for solids (:func:`redistribute_surface_mass`)."""
        if fe is None:
            raise ValueError("with_contact: RedistributeMass() needs an FE model (bar, beam or solid), not a discrete one")
        if fe.kind == "solid":
            M, report = redistribute_surface_mass(fe, M, dofs)
            return M, ([report] if report["dofs"] else [])
        return apply_each(self, fe, M, dofs)

    def __repr__(self) -> str:
        return "RedistributeMass()"


class ConsistentMass:
    """Contact-mass strategy: keep the consistent mass at contact DOFs (the default for penalty
    contacts and discrete models)."""

    def apply(self, fe, M, dof: int):
        return M, None

    def apply_all(self, fe, M, dofs):
        return M, []

    def __repr__(self) -> str:
        return "ConsistentMass()"

