"""Models layer: Craig-Bampton reduction keeping contact, forcing and nonlinear DOFs physical.

``q = T r`` with ``r = [q_B; eta]``: kept (boundary) DOFs ``q_B`` stay physical, interior DOFs
``q_I = Psi q_B + Phi eta`` with static constraint modes ``Psi = -K_II^-1 K_IB`` and the first
fixed-interface modes ``Phi`` of ``(K_II, M_II)`` (Craig & Bampton 1968). Reduced matrices are
``T^T M T``, ``T^T K T``, ``T^T C T``. Only sparse factorizations of ``K_II`` and sparse-times-
tall-dense products are formed, so 1e5-DOF models reduce without dense full-size matrices.
"""

from __future__ import annotations

import logging
import warnings
import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar
from collections.abc import Sequence

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from .eigen import IllConditionedWarning, check_conditioning, normal_modes
from .model import Attached, MeshMap, StructuralModel
from .sparse_direct import factorize
from .model.dofs import node_dof_list
from .solvers.checks import InputValueError, check_int, check_memory, entry_point, named_by

__all__ = ["ReducedModel", "ReducedMeshMap", "craig_bampton"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ReducedModel(StructuralModel):
    """A Craig-Bampton reduced model; it is a :class:`StructuralModel` (use it anywhere one is).

    The first ``n_kept`` DOFs are the kept physical DOFs (in ``kept`` order, names preserved),
    the last ``n_modes`` are fixed-interface modal coordinates.

    Attributes
    ----------
    parent : StructuralModel
        The full model.
    basis : ndarray (parent.n_dofs, n_dofs)
        Reduction basis ``T``: ``q_parent = T r``.
    kept : ndarray of int
        Parent DOF index of each kept DOF.
    interface_omega : ndarray
        Fixed-interface frequencies (rad/s) of the retained modes.
    """

    parent: Any = None
    basis: Any = None
    kept: Any = None
    interface_omega: Any = None

    is_reduced: ClassVar[bool] = True

    @property
    def n_kept(self) -> int:
        return int(np.asarray(self.kept).size)

    @property
    def n_modes(self) -> int:
        return self.n_dofs - self.n_kept

    @entry_point("ReducedModel.truncated")
    def truncated(self, n_modes: int) -> ReducedModel:
        """The same reduction with only its first ``n_modes`` fixed-interface modes: exactly
        ``craig_bampton(parent, n_modes)`` with the same kept DOFs (the modes are nested), without
        a new eigen-solve."""
        n_modes = check_int("n_modes", n_modes, 0)
        if n_modes > self.n_modes:
            raise InputValueError(f"n_modes={n_modes} exceeds the {self.n_modes} modes of this reduction")
        k = self.n_kept + n_modes
        dofmap = self.parent.dofmap.restrict(self.kept).extended([f"cb mode {j + 1}" for j in range(n_modes)])
        return dataclasses.replace(
            self, M=self.M[:k][:, :k], K=self.K[:k][:, :k], C=self.C[:k][:, :k], dofmap=dofmap,
            C_lowrank=None if self.C_lowrank is None else self.C_lowrank.restrict(slice(0, k)),
            basis=self.basis[:, :k], interface_omega=np.asarray(self.interface_omega)[:n_modes])

    def expand(self, q: np.ndarray) -> np.ndarray:
        """Reduced coordinates ``(..., n_dofs)`` -> parent DOFs ``(..., parent.n_dofs)``: ``T r``."""
        q = np.asarray(q)
        if q.shape[-1] != self.n_dofs:
            raise ValueError(f"expand: expected last axis of length {self.n_dofs} (reduced DOFs), got shape {q.shape}")
        return q @ self.basis.T

    @property
    def mesh_map(self) -> ReducedMeshMap:
        """The map to the parent's FE mesh, through the basis (:class:`ReducedMeshMap`)."""
        return ReducedMeshMap(self)

    def __repr__(self) -> str:
        return (
            f"ReducedModel(n_dofs={self.n_dofs} = {self.n_kept} kept + {self.n_modes} modes, "
            f"parent n_dofs={self.parent.n_dofs}, contacts={len(self.contacts)}, forces={len(self.forces)})"
        )


class ReducedMeshMap(MeshMap):
    """:class:`~femodes.model.MeshMap` of a reduced model: the parent's, through the basis
    ``q_parent = T r`` (every reduction level down to the model that owns the mesh)."""

    @property
    def owner(self) -> StructuralModel | None:
        return self.model.parent.mesh_map.owner

    def to_owner(self, q: np.ndarray) -> np.ndarray:
        return self.model.parent.mesh_map.to_owner(self.model.expand(q))

    def fe_dof(self, dof: int) -> int | None:
        if dof >= self.model.n_kept:
            return None  # a modal coordinate
        return self.model.parent.mesh_map.fe_dof(int(np.asarray(self.model.kept)[dof]))

    def full_field(self, q: np.ndarray) -> np.ndarray:
        """Reduced coordinates -> the parent's full FE field (constrained DOFs zero)."""
        return self.model.parent.mesh_map.full_field(self.model.expand(q))

    def weights(self, at, how: str = "mean") -> np.ndarray:
        """The parent's probe weights through the basis: any boundary or DOF of the full model,
        kept or not."""
        return self.model.parent.mesh_map.weights(at, how) @ self.model.basis


def _check_n_modes(n_modes, n_interior: int) -> int:
    n_modes = check_int("n_modes", n_modes, 0)
    if n_modes > n_interior:
        raise InputValueError(f"n_modes={n_modes} exceeds the {n_interior} interior DOFs")
    return int(n_modes)


@entry_point("craig_bampton")
def craig_bampton(model: StructuralModel, n_modes: int = 10, *, keep: Sequence | None = None) -> ReducedModel:
    """Craig-Bampton reduction of ``model``.

    Parameters
    ----------
    model : StructuralModel
        Full (or already reduced) model with its declarations.
    n_modes : int
        Number of fixed-interface modes (0 gives a Guyan/static condensation).
    keep : location or sequence of locations, optional
        Extra DOFs to keep physical: a named point keeps the whole node (every free component,
        e.g. ``w`` and ``theta`` of a beam node, as Craig-Bampton interfaces are usually kept); a
        ``(name, component)`` pair or a DOF index keeps that one DOF. Contact, forcing and
        nonlinear DOFs are always kept.

    Returns
    -------
    ReducedModel
        Declarations re-indexed to reduced DOFs; ``expand`` maps back to the parent's DOFs.

    Raises
    ------
    ValueError
        No DOF to keep, too many modes, or an interior stiffness that is singular (the structure
        is not restrained once the kept DOFs are fixed).
    """
    if not isinstance(model, StructuralModel):
        raise TypeError(f"craig_bampton: model must be a StructuralModel, got {type(model).__name__}")
    check_int("n_modes", n_modes, 0)  # its own error before the kept DOFs' (-1 read "no DOF to keep")
    kept = kept_dofs(model, keep)
    n = model.n_dofs
    interior = np.setdiff1d(np.arange(n), kept)
    n_modes = _check_n_modes(n_modes, interior.size)
    # the basis T (parent DOFs x kept + modes), the interior coupling K_IB and the constraint modes
    # are dense: three arrays of n_dofs x (kept + modes) floats, refused before they are allocated
    width = kept.size + n_modes
    check_memory(24.0 * model.n_dofs * width, f"the dense reduction basis of {model.n_dofs} DOFs x {kept.size} kept "
                 f"DOFs + {n_modes} modes", "keep fewer DOFs (contacts and forces on fewer nodes) or fewer modes")
    T, omega_i, cond = _reduction_basis(model.K.tocsr(), model.M.tocsr(), kept, interior, n_modes)
    reduced = _reduced_model(model, kept, T, omega_i, n_modes, schur=bool(cond * np.finfo(float).eps <= SCHUR_COND_EPS))
    log.info("craig_bampton: %d DOFs -> %d kept + %d modes", n, kept.size, n_modes)
    return reduced


def kept_dofs(model: StructuralModel, keep: Sequence | None = None) -> np.ndarray:
    """Sorted parent DOFs kept physical: contact, forcing and nonlinear DOFs plus those of ``keep``."""
    declared = [a.dof for a in model.contacts + model.forces + model.nonlinearities]
    extra = []
    if keep is not None:
        if isinstance(keep, (str, int, np.integer, tuple)) and not (
            isinstance(keep, tuple) and keep and isinstance(keep[0], (tuple, int, np.integer))
        ):
            keep = [keep]
        if isinstance(keep, (bool, np.bool_)) or not isinstance(keep, (list, tuple, np.ndarray)):
            raise TypeError(
                "craig_bampton: keep must be a location or a list of locations (names, (name, component) pairs "
                f"or DOF indices), got {keep!r}"
            )
        dm = model.dofmap
        assert dm is not None  # check_fields fills it on construction
        with named_by("craig_bampton: keep"):
            extra = [d for k in keep for d in node_dof_list(dm, k)]
    kept = np.array(sorted(set(declared) | set(extra)), dtype=int)
    if kept.size == 0:
        raise ValueError(
            "craig_bampton: no DOF to keep; declare contact/forcing first (with_contact, with_forcing) or pass keep=['tip']"
        )
    return kept


def _reduction_basis(K, M, kept: np.ndarray, interior: np.ndarray,
                     n_modes: int) -> tuple[np.ndarray, np.ndarray, float]:
    """``T = [[I, 0], [Psi, Phi]]`` (rows in parent order), the fixed-interface frequencies and the
    condition number estimate of ``K_II`` (0 without interior DOFs)."""
    nB, nI = kept.size, interior.size
    T = np.zeros((kept.size + nI, nB + n_modes))
    T[kept, np.arange(nB)] = 1.0
    omega_i = np.zeros(0)
    cond = 0.0
    if nI:
        KI = K[interior]  # the interior rows once, for K_II and K_IB
        KII = KI[:, interior].tocsc()
        KIB = KI[:, kept].tocsc()
        del KI
        MII = M[interior][:, interior]  # CSR: ARPACK multiplies by it (symmetric: the same matrix)
        lu, cond = _factor_interior(KII)
        # the constraint modes in blocks of columns (PSI_BLOCK_COLUMNS, PSI_BLOCK_BYTES): K_IB and
        # Psi are n_I x n_B dense, 1.4 GB each at 1e6 DOFs and 169 kept DOFs, held next to the factor
        step = max(16, min(PSI_BLOCK_COLUMNS, int(PSI_BLOCK_BYTES // (8 * nI))))
        for c0 in range(0, nB, step):
            cols = slice(c0, min(nB, c0 + step))
            # Fortran order: the column layout the back-ends solve in, so no copy is made for them
            T[interior, cols] = _constraint_modes(lu, KIB[:, cols].toarray(order="F"))
        del KIB
        if n_modes:
            T[interior, nB:], omega_i = _fixed_interface_modes(KII, MII, lu, n_modes)
    return T, omega_i, cond


#: Bytes of the block of constraint modes (and of the ``K_IB`` columns it solves for) formed at a
#: time; the back-ends' block solves read the factor once per block.
PSI_BLOCK_BYTES = 2**29

#: Columns of constraint modes solved for at a time (at most): the supernodal solves of CHOLMOD and
#: MUMPS run faster on blocks of about a hundred right-hand sides than on all of them at once (the
#: 637 columns of a 7.9e4-DOF blade: 5.3-7.3 s at once, 3.9-4.7 s in blocks of 106-320, the
#: dense blocks 600 MB smaller; ``benchmarks/README_backends.md``).
PSI_BLOCK_COLUMNS = 128


def _factor_interior(KII) -> tuple[Any, float]:
    """Factorisation of the interior stiffness (:func:`~femodes.sparse_direct.factorize`,
    positive definite: CHOLMOD where installed) and its condition number estimate; ValueError if
    singular, warning if ill-conditioned."""
    try:
        # symmetric: a StructuralModel's K is (checked at construction), so the exact test of
        # factorize (a transpose and a difference of K_II) is not needed
        lu = factorize(KII, positive_definite=True, symmetric=True)
    except RuntimeError as exc:
        raise ValueError(
            "craig_bampton: the interior stiffness K_II is singular: the structure is not restrained when the "
            "kept DOFs are fixed (keep more DOFs or add supports)"
        ) from exc
    cond = check_conditioning(KII, lu.solve, KII.shape[0], warn=False)
    if 1e-2 < cond * np.finfo(float).eps <= 10.0:
        warnings.warn(
            f"craig_bampton: the interior stiffness is ill-conditioned (cond_1 ~ {cond:.1e}); low frequencies lose "
            "digits. Euler-Bernoulli beams reach this near 1e4 DOFs; use bars for larger studies.",
            IllConditionedWarning,
            stacklevel=5,  # the caller of craig_bampton (via _reduction_basis and its entry_point wrapper)
        )
    elif cond * np.finfo(float).eps > 10.0:
        raise ValueError(
            f"craig_bampton: the interior stiffness K_II is numerically singular (cond_1 ~ {cond:.1e}): the "
            "structure is not restrained when the kept DOFs are fixed (keep more DOFs or add supports), or a "
            "beam mesh is far too fine for double precision (use bars beyond ~1e4 DOFs)"
        )
    return lu, float(cond)


def _constraint_modes(lu: Any, KIB: np.ndarray) -> np.ndarray:
    """Static constraint modes ``Psi = -K_II^-1 K_IB``."""
    psi = lu.solve(KIB)
    np.negative(psi, out=psi)
    if not np.all(np.isfinite(psi)):
        raise ValueError("craig_bampton: the interior stiffness K_II is singular (non-finite constraint modes)")
    return psi


def _fixed_interface_modes(KII, MII, lu: Any, n_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """The first ``n_modes`` mass-normalized modes of ``(K_II, M_II)`` and their frequencies.

    When the kept DOFs cut the interior into parts that do not touch (a bar or beam kept at a
    middle node), each part's modes are computed on that part alone: they are then exactly zero
    elsewhere, and so are their couplings to the other parts' modes. Modes of the whole interior
    leak onto the other parts at the eigen-solver's tolerance (1e-12), and which of those
    couplings the projection kept depended on the BLAS kernel. A Rayleigh-Ritz step on each
    part's modes makes them ``M``-orthonormal and ``K``-orthogonal to the round-off of the
    products (:func:`_project` tells the exact zeros from the rest by that round-off)."""
    n_parts, label = _parts(KII, MII)
    if n_parts == 1:
        # K_II is definite here (factorised above): shift-invert at 0 reuses its factor
        _, phi = normal_modes(KII, MII, n_modes, sigma=0.0, factor=lu, check=False)
        omega, phi = _rayleigh_ritz(KII, MII, phi)
        return phi, omega
    omegas, columns = [], []
    for part in range(n_parts):
        idx = np.flatnonzero(label == part)
        Kp, Mp = KII[idx][:, idx], MII[idx][:, idx]
        if not Mp.nnz:
            continue  # massless part: no dynamic mode
        n = min(n_modes, idx.size)
        _, phi = normal_modes(Kp.tocsc(), Mp.tocsc(), n, sigma=0.0, check=False)
        w, phi = _rayleigh_ritz(Kp, Mp, phi)
        for j in range(w.size):
            col = np.zeros(KII.shape[0])
            col[idx] = phi[:, j]
            omegas.append(w[j])
            columns.append(col)
    order = np.argsort(omegas, kind="stable")[:n_modes]
    if order.size < n_modes:
        raise ValueError(f"craig_bampton: n_modes={n_modes} exceeds the {order.size} fixed-interface modes of the "
                         "interior; ask for fewer modes")
    return np.column_stack([columns[i] for i in order]), np.asarray(omegas)[order]


def _parts(KII, MII) -> tuple[int, np.ndarray]:
    """The parts of the interior that no stiffness or mass entry couples (connected components of
    the pattern of ``|K_II| + |M_II|``). A breadth-first search over the pattern of ``K_II`` (its
    CSC arrays read as CSR, no copy) comes first: when it reaches every DOF the interior is one
    part, and neither the sum of the absolute values nor scipy's symmetrized graph is formed
    (0.013 s against 0.85 s on a 7.9e4-DOF blade). It can only miss DOFs, never join parts, so
    anything else takes the components of the whole pattern. The search counts every stored entry
    as an edge, so it is skipped when ``K_II`` stores explicit zeros (which do not couple)."""
    KII = sp.csc_matrix(KII)
    if KII.shape[0] and np.count_nonzero(KII.data) == KII.data.size:
        graph = sp.csr_matrix((KII.data, KII.indices, KII.indptr), shape=KII.shape)
        if breadth_first_order(graph, 0, directed=True, return_predecessors=False).size == KII.shape[0]:
            return 1, np.zeros(KII.shape[0], dtype=np.int32)
    return connected_components(abs(KII) + abs(MII), directed=False)


def _rayleigh_ritz(K, M, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and modes of ``(K, M)`` restricted to the span of ``phi`` (``phi^T M phi = I``
    and ``phi^T K phi = diag(omega^2)`` to the round-off of the products)."""
    Mr, Kr = phi.T @ (M @ phi), phi.T @ (K @ phi)
    lam, Q = scipy.linalg.eigh(0.5 * (Kr + Kr.T), 0.5 * (Mr + Mr.T))
    return np.sqrt(np.maximum(lam, 0.0)), phi @ Q


def _project(A, T: np.ndarray, n_kept: int, lowrank: Any = None, schur_rows: np.ndarray | None = None) -> sp.csr_matrix:
    """``T^T A T`` (plus ``T^T U diag(d) U^T T`` for a low-rank part ``lowrank``), symmetrized, as
    a sparse matrix without the round-off of its exact zeros. With ``schur_rows`` (the kept DOFs;
    ``A`` the stiffness the constraint modes solve), the kept-kept block is the Schur complement
    ``A_bb + A_bI Psi`` (:data:`SCHUR_COND_EPS`) and only the mode columns are multiplied.

    The fixed-interface modes are orthonormal (:func:`_rayleigh_ritz`), so the modal block of
    ``M`` and ``K`` (and of Rayleigh ``C``) is diagonal and only the kept DOFs' rows couple to the
    modes. Keeping the round-off there would make every reduced matrix dense (a Hill or harmonic
    balance problem on 100 modes: 30x the fill), and which round-off entries survive a threshold
    fixed relative to the diagonal depended on the BLAS kernel (the banded-or-SuperLU choice of the
    harmonic blocks followed it). The threshold comes from each entry's own round-off scale
    instead, the larger of

    - ``(|T|^T |A| |T|)_ij``: a computed product carries an error of a small multiple of eps times
      it (Higham, *Accuracy and Stability of Numerical Algorithms*, 2002, section 3.5); it grows
      with ``||A||``, hence with the conditioning of a fine mesh;
    - ``sqrt(|R_ii R_jj|)``: the basis vectors are themselves computed, orthogonal to a small
      multiple of eps in the norms they define (modes on parts of the interior that the kept DOFs
      separate do not overlap, and the first scale vanishes there).

    Entries below :data:`ZERO_ULPS` x eps x that scale are dropped, in the blocks where exact
    zeros are expected (mode-mode and kept-mode; the first ``n_kept`` columns of ``T`` are the
    constraint modes): the kept-kept block is a Schur complement whose genuine entries can be
    far below the first scale, so the first scale is formed for the mode columns only
    (``|A| |T_m|``: ``n_modes`` columns instead of all of them; ``|A|`` is symmetric, as the
    matrices of a :class:`StructuralModel` are, so ``S`` is too). The round-off measured on
    reduced beams and bars under OpenBLAS's Haswell, SkylakeX, Sandybridge and Prescott kernels stays below 16 of it, the smallest genuine
    coupling of those models above 1.8e4 of it (a Rayleigh damping's mass part on a fine beam).

    The products are summed over blocks of rows (:data:`PROJECT_BLOCK_BYTES`), so no
    ``n x width`` array besides ``T`` is held: at 1e6 DOFs and 300 kept DOFs each is 2.4 GB. The
    whole product is ``X + X^T`` with ``X = T^T H T`` and ``H`` the lower half of ``A``
    (:func:`_lower_half`); its round-off is bounded by the same first scale."""
    A = sp.csr_matrix(A)
    n, width = T.shape
    Tm = np.abs(T[:, n_kept:])
    Bm = _abs(A) @ Tm  # |A| |T_m|, n x n_modes
    UT = None
    if lowrank is not None:
        UT = lowrank.U.T @ T
        Bm += np.abs(lowrank.U) @ (np.abs(lowrank.d)[:, None] * np.abs(UT[:, n_kept:]))
    del Tm
    R = np.zeros((width, width))
    Sm = np.zeros((width, width - n_kept))
    step = max(256, int(PROJECT_BLOCK_BYTES // (8 * max(width, 1))))
    # contiguous: scipy would copy the strided mode columns (n x n_modes) at every block's product
    Tmodes = np.ascontiguousarray(T[:, n_kept:]) if schur_rows is not None else None
    # the whole product through the half H = tril(A, -1) + diag(A) / 2 of the symmetric A = H + H^T:
    # T^T A T = X + X^T with X = T^T H T; scipy's sparse-times-dense product is the costly half
    # (1.9 of 2.9 s for a 7.9e4-DOF blade's mass and 657 columns) and H has half of A's entries
    H = None if Tmodes is not None else _lower_half(A)
    for r0 in range(0, n, step):
        rows = slice(r0, min(n, r0 + step))
        Tr = T[rows]
        if H is None:  # the mode columns only
            R[:, n_kept:] += Tr.T @ (A[rows] @ Tmodes)
        else:
            R += Tr.T @ (H[rows] @ T)
        Sm += np.abs(Tr).T @ Bm[rows]
    if H is not None:
        R += R.T.copy()
    del Bm
    if schur_rows is not None:
        # A T_b = [A_bb + A_bI Psi; A_II Psi + A_Ib] and the second block is the residual r of the
        # constraint modes' solve: T_b^T A T_b = A_bb + A_bI Psi + Psi^T r, of which the last term
        # (the only n x n_b product) is dropped
        Ab = A[schur_rows].tocsc()
        cols = np.flatnonzero(np.diff(Ab.indptr))  # the DOFs coupled to the kept ones: a few rows of T
        S = np.asarray(Ab[:, cols] @ T[cols, :n_kept])
        R[:n_kept, :n_kept] = 0.5 * (S + S.T)
    if UT is not None:
        R += UT.T @ (lowrank.d[:, None] * UT)
    R = np.triu(R) + np.triu(R, 1).T
    Sm[n_kept:] = 0.5 * (Sm[n_kept:] + Sm[n_kept:].T)
    d = np.sqrt(np.abs(np.diag(R)))
    scale = np.maximum(Sm, np.outer(d, d[n_kept:]))
    Rm = R[:, n_kept:]
    zero = np.abs(Rm) <= ZERO_ULPS * np.finfo(float).eps * scale
    zero[n_kept + np.arange(width - n_kept), np.arange(width - n_kept)] = False  # the diagonal
    Rm[zero] = 0.0
    R[n_kept:, :] = Rm.T  # the same entries of the symmetric half
    return sp.csr_matrix(R)


#: The reduced stiffness's kept-kept block is the Schur complement ``K_bb + K_bI Psi`` (symmetrized)
#: instead of ``T_b^T K T_b`` when ``cond_1(K_II) eps`` is at most this. The two differ by
#: ``Psi^T r`` (``r`` the residual of the constraint modes' solve); with a backward stable solve
#: that is ``Psi^T E Psi`` for a perturbation ``|E| <~ eps |K_II|``, the order of the rounding of
#: the quadratic form's own products, and the quadratic form costs the ``n x n_b`` product
#: ``K T_b`` (3.1 s of 15.9 s on a 7.9e4-DOF blade with 637 kept DOFs). Measured against
#: ``3 EI / L^3`` on cantilevers of 50-800 elements (``cond eps`` 6.5e-9 to 4.1e-4) under SuperLU,
#: MUMPS and PARDISO: the Schur form's tip-stiffness error is 0.09-16 times the quadratic
#: form's (1e-10 to 5e-6), smaller in 11 of the 21 cases; on the blade (cond 7e6) both put the
#: smallest reduced stiffness eigenvalue 1.5e-10 from a reference with refined ``Psi``. Past
#: this bound (a 1000-element beam, ``cond eps`` 1e-3: 3.4e-5 against 3.2e-6) the quadratic form.
SCHUR_COND_EPS = 1e-4


#: Bytes of the ``rows x width`` block of ``A T`` that :func:`_project` forms at a time.
PROJECT_BLOCK_BYTES = 16 * 2**20


#: Multiple of eps times an entry's round-off scale (:func:`_project`) below which an entry of a
#: projected matrix is the round-off of an exact zero: the worst case of a length-n dot product is
#: n eps, the typical one sqrt(n) eps; 1e3 leaves nearly two decades above the largest round-off
#: measured (16) and one below the smallest genuine entry (1.8e4).
ZERO_ULPS = 1e3


def _project_damping(model: StructuralModel, T: np.ndarray, n_kept: int, Mr: sp.csr_matrix,
                     Kr: sp.csr_matrix) -> sp.csr_matrix | None:
    """``T^T C T`` of the whole damping. Rayleigh damping ``C = alpha M + beta K`` (as
    ``with_damping`` made it, checked entry by entry) is ``alpha Mr + beta Kr`` from the projected
    ``Mr, Kr``: no third projection (the projections are a third of the reduction of a
    7.9e4-DOF blade with 637 kept DOFs, ``benchmarks/README_backends.md``). A modal (low-rank) part
    ``U diag(d) U^T`` is projected through ``C T = C_sparse T + U diag(d) (U^T T)`` (no ``n x n``
    matrix); the reduced damping is small and generally dense (the fixed-interface modes are not
    the model's modes), so it is stored as an ordinary matrix with the clean-up of :func:`_project`."""
    lr = model.C_lowrank
    if lr is not None:
        return _project(model.C.tocsr(), T, n_kept, lr)
    if not model.C.nnz:
        return None
    ab = _rayleigh_coefficients(model)
    if ab is not None:
        return sp.csr_matrix(ab[0] * Mr + ab[1] * Kr)
    return _project(model.C.tocsr(), T, n_kept)


def _rayleigh_coefficients(model: StructuralModel) -> tuple[float, float] | None:
    """``(alpha, beta)`` if the model's sparse damping is ``alpha M + beta K`` of its current ``M``
    and ``K``, to the round-off of that sum (``4 eps`` of ``alpha |M| + beta |K|`` entry by entry),
    else None."""
    spec = dict(model.damping_spec)
    if "alpha" not in spec or model.C_lowrank is not None:
        return None
    alpha, beta = float(spec["alpha"]), float(spec.get("beta", 0.0))
    C, M, K = (sp.csr_matrix(A) for A in (model.C, model.M, model.K))
    # a probe instead of the entry-by-entry difference (four n x n sparse sums: 0.23 s against
    # 0.09 s at 7.9e4 DOFs): C x - (alpha M x + beta K x) for a fixed random x is round-off
    # unless C differs from alpha M + beta K, whose entries' own round-off (4 eps) is then
    # summed with the products' (one eps per term of a row) in the bound
    x = np.random.default_rng(0).standard_normal(C.shape[0])
    diff = np.abs(C @ x - (alpha * (M @ x) + beta * (K @ x)))
    ax = np.abs(x)
    row = int(max(np.diff(A.indptr).max(initial=0) for A in (C, M, K)))
    scale = abs(alpha) * (_abs(M) @ ax) + abs(beta) * (_abs(K) @ ax) + _abs(C) @ ax
    return (alpha, beta) if np.all(diff <= (4.0 + 2.0 * row) * np.finfo(float).eps * scale) else None


def _lower_half(A: sp.csr_matrix) -> sp.csr_matrix:
    """``tril(A, -1) + diag(A) / 2`` (CSR): ``A = H + H^T`` for a symmetric ``A``."""
    return sp.csr_matrix(sp.tril(A, -1, format="csr") + sp.diags(0.5 * A.diagonal(), format="csr"))


def _abs(A: sp.csr_matrix) -> sp.csr_matrix:
    """``|A|`` entry by entry (``A``'s index arrays shared, not copied)."""
    return sp.csr_matrix((np.abs(A.data), A.indices, A.indptr), shape=A.shape, copy=False)


def _reduced_model(model: StructuralModel, kept: np.ndarray, T: np.ndarray, omega_i: np.ndarray, n_modes: int,
                   schur: bool = False) -> ReducedModel:
    """The projected model, its declarations re-indexed to the reduced DOFs (``schur``: the
    stiffness's kept block as a Schur complement, :data:`SCHUR_COND_EPS`)."""
    pos = {int(d): i for i, d in enumerate(kept)}

    def reindex(items):
        return tuple(Attached(a.item, pos[a.dof]) for a in items)

    assert model.dofmap is not None  # check_fields fills it on construction
    dofmap = model.dofmap.restrict(kept).extended([f"cb mode {j + 1}" for j in range(n_modes)])
    Mr = _project(model.M.tocsr(), T, kept.size)
    Kr = _project(model.K.tocsr(), T, kept.size, schur_rows=kept if schur else None)
    return ReducedModel(
        M=Mr,
        K=Kr,
        C=_project_damping(model, T, kept.size, Mr, Kr),
        dofmap=dofmap,
        forces=reindex(model.forces),
        contacts=reindex(model.contacts),
        nonlinearities=reindex(model.nonlinearities),
        fe=None,
        damping_info=model.damping_info,
        parent=model,
        basis=T,
        kept=kept,
        interface_omega=omega_i,
    )
