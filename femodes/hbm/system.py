"""Discretise layer: harmonic balance equations of a model, as sparse blocks.

Unknowns ``x = [Q.ravel(); P.ravel()]`` with ``Q`` of shape ``(n_coef, n_dofs)`` (displacement
Fourier coefficients, layout of :class:`~femodes.hbm.harmonics.Harmonics`) and ``P`` of shape
``(n_coef, n_uc)`` (Fourier coefficients of the contact forces of the ``n_uc`` complementarity
contacts). Equations (Galerkin projections on the same basis)::

    R_q = S(w) Q + F_nl(Q) + W P - F = 0          dynamic equilibrium
    R_p = P - proj[max(0, P + c U_c - c g0)] = 0    contact (Signorini by complementarity)

with the linear part ``S(w) = w^2 (D1^2 x M) + w (D1 x C) + (I x K)`` (``D1`` the derivative
operator at ``w = 1``, ``x`` the Kronecker product) block diagonal over harmonics (with modal
damping ``C = C_sparse + U diag(d) U^T``: the low-rank part is applied as such, never assembled
on the residual/Jacobian/solver paths; only the Kronecker operators ``A1``/``IC`` of the
assembled checks and Hill's method use the assembled matrix), and the
nonlinear terms living only on the rows/columns of the nonlinear DOFs
(:mod:`femodes.hbm.nonlinear_forces`). The positive part is
projected *exactly* (integration between the sign changes of the trigonometric polynomial,
``h.galerkin.positive_part``): sampling it makes the map piecewise linear with jumps and
semismooth Newton cycles (a sampled continuation of the 1-DOF contact case of Shi & Legrand
stalls near its resonance, where the exact one runs through both folds). Cubic springs use alias-free sampling
(``N >= 4H + 1``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from ..dynamic_stiffness import CoefficientStiffness, DynamicStiffness, mul_rows
from ..laws import CubicSpring, PenaltyContact, UnilateralContact
from ..model import StructuralModel
from ..sparse_direct import factorize
from .deprecated import moved_attribute
from .harmonics import Harmonics
from ..solvers.checks import check_memory
from .linsolve import DEFAULT_OPTIONS, BlockSolver, HarmonicBlockJacobian, solver_memory
from .linear_part import LinearPart
from .nonlinear_forces import ComplementarityContact, NonlinearForces, Triplets
from .positive_part import ExactProjection

__all__ = ["HBMSystem", "default_contact_parameter", "default_contact_parameters"]

log = logging.getLogger(__name__)

#: Systems with at most this many displacement coefficients (and no low-rank damping) take the
#: linear part of the residual from cached dense operators (the size up to which the block solver
#: factorises densely too, ``BlockSolverOptions.dense_max_size``).
DENSE_MAX_SIZE = DEFAULT_OPTIONS.dense_max_size

_mul = mul_rows

#: The methods that moved to the collaborators of an HBMSystem, by their old names (deprecated; found
#: by ``HBMSystem.__getattr__`` with a DeprecationWarning until the next release): the linear
#: structure's to ``linear`` (:class:`~femodes.hbm.linear_part.LinearPart`), the forwarders of the
#: dynamic stiffness to ``stiffness`` itself (:class:`~femodes.dynamic_stiffness.CoefficientStiffness`).
_MOVED = {
    "force": "linear.force", "apply_linear": "linear.apply", "solve_linear": "linear.solve",
    "block_pattern": "linear.block_pattern", "linear_factors": "linear.factors",
    "linear_operator": "stiffness.operator", "dense_linear_operator": "stiffness.dense_operator",
    "lowrank_border": "stiffness.lowrank_border", "lowrank_modes": "stiffness.Z.lowrank_modes",
    "abs_row_sums": "stiffness.abs_row_sums", "C_full": "stiffness.C_full",
    **{name: f'stiffness.term("{name}")' for name in ("A2", "A1", "A0", "AM", "IM", "IC")},
}


def default_contact_parameter(model: StructuralModel, dof: int) -> float:
    """Scale-aware complementarity constant: the static stiffness seen at the contact DOF.

    ``c = 1 / (K^-1)_dd`` (the force per unit displacement of the DOF with all others free),
    so ``p`` and ``c g_N`` have comparable magnitudes whatever the units. For a structure that is
    free (singular ``K``) the diagonal ``K_dd`` is used instead.
    """
    return float(default_contact_parameters(model, [dof])[0])


def default_contact_parameters(model: StructuralModel, dofs) -> np.ndarray:
    """:func:`default_contact_parameter` of every DOF of ``dofs`` with one factorisation of ``K``
    (a boundary of a meshed solid has hundreds of contact DOFs)."""
    dofs = np.asarray(dofs, dtype=int).reshape(-1)
    out = np.full(dofs.size, np.nan)
    if not dofs.size:
        return out
    K = model.K.tocsc()
    try:
        lu = factorize(K, positive_definite=True)
    except RuntimeError:  # singular K: a free structure
        lu = None
    if lu is not None:
        for start in range(0, dofs.size, 256):  # blocks of right-hand sides: bounded memory
            block = dofs[start:start + 256]
            E = np.zeros((model.n_dofs, block.size))
            E[block, np.arange(block.size)] = 1.0
            flex = lu.solve(E)[block, np.arange(block.size)]
            good = np.isfinite(flex) & (flex > 0)
            out[start:start + block.size][good] = 1.0 / flex[good]
    for k in np.flatnonzero(~np.isfinite(out)):
        kd = float(K[dofs[k], dofs[k]])
        out[k] = kd if kd > 0 else float(max(model.M.diagonal().max(), 1.0))
    return out


def _check_memory(harmonics: Harmonics, n_nonlinear: int, n_uc: int, n_aft: int, rank: int, block: bool) -> None:
    """Refuse, before anything large is allocated, a problem whose dense Schur complement and
    Fourier operators (:func:`~femodes.hbm.linsolve.solver_memory`) exceed the memory available:
    ``n_nonlinear`` nonlinear DOFs, ``n_uc`` complementarity contacts, ``n_aft`` signals sampled
    in time, a low-rank damping of rank ``rank``, the block solver if ``block``."""
    nc = harmonics.n_coef
    n_p = nc * n_uc
    need = solver_memory(nc, harmonics.n_time, n_nonlinear, n_p, rank, n_aft=n_aft, block=block)
    n_nl = n_nonlinear
    check_memory(need, f"harmonics: H = {harmonics.n_harmonics} with {n_nl} nonlinear DOF{'s' * (n_nl != 1)} "
                       f"({n_uc} complementarity contact{'s' * (n_uc != 1)}) gives a dense Schur "
                       f"complement of size {nc * (n_nl + rank) + n_p + 2} whose factorisation",
                 "use fewer harmonics (it grows as H^2) or fewer contact nodes (a coarser mesh along the contact "
                 "boundary)" + (", and Rayleigh instead of modal damping (its modes join the complement)" if rank
                                else ""))


class HBMSystem:
    """Harmonic balance residual and sparse Jacobian of a model (shared by all HBM problems).

    Parameters
    ----------
    model : StructuralModel (full or reduced)
    harmonics : Harmonics
    projection : ExactProjection or SampledProjection, optional
        How ``max(0, .)`` is projected on the harmonics: exactly (default,
        :class:`~femodes.hbm.ExactProjection`) or by sampling on the ``n_time`` grid (the naive
        AFT, :class:`~femodes.hbm.SampledProjection`, for comparison only).
    solver : BlockSolver or AssembledSolver, optional
        How the Jacobian (always a :class:`~femodes.hbm.linsolve.HarmonicBlockJacobian`) is
        factorised: per-harmonic factorisations and a Schur complement on the nonlinear DOFs
        (default, :class:`~femodes.hbm.BlockSolver`) or a sparse direct LU of the assembled matrix
        (:class:`~femodes.hbm.AssembledSolver`, for checks and comparisons).
    threads : int, optional
        Threads for the per-harmonic factorisations of large models (``0``: all CPUs; default
        one, which measured faster on 2 shared cores).
    """

    def __init__(self, model: StructuralModel, harmonics: Harmonics, *, projection=None, solver=None,
                 threads: int | None = None):
        if not isinstance(model, StructuralModel):
            raise TypeError(f"model must be a StructuralModel, got {type(model).__name__}")
        if not isinstance(harmonics, Harmonics):
            raise TypeError(f"harmonics must be a femodes.Harmonics, got {type(harmonics).__name__}")
        self.model = model
        self.h = harmonics
        self.projection = ExactProjection() if projection is None else projection
        if not callable(self.projection):
            raise TypeError(f"projection must be ExactProjection() or SampledProjection(), got {projection!r}")
        self.solver = BlockSolver() if solver is None else solver
        if not callable(getattr(self.solver, "factorize", None)):
            raise TypeError(f"solver must be BlockSolver() or AssembledSolver(), got {solver!r}")
        # the block solver's tuning also shapes the interior blocks and factors cached here
        self.solver_options = self.solver.options if isinstance(self.solver, BlockSolver) else DEFAULT_OPTIONS
        n, nc = model.n_dofs, harmonics.n_coef
        self.n = n
        self.unilateral: list[ComplementarityContact] = []
        self.penalty: list = []
        needs = [a.dof for a in model.contacts if isinstance(a.item, UnilateralContact) and a.item.c is None]
        defaults = dict(zip(needs, default_contact_parameters(model, needs)))
        for a in model.contacts:
            if isinstance(a.item, UnilateralContact):
                c = a.item.c if a.item.c is not None else float(defaults[a.dof])
                self.unilateral.append(ComplementarityContact(a.item, a.dof, c, len(self.unilateral)))
            elif isinstance(a.item, PenaltyContact):
                self.penalty.append((a.item, a.dof))
        self.cubic = [(a.item, a.dof) for a in model.nonlinearities if isinstance(a.item, CubicSpring)]
        self.n_uc = len(self.unilateral)
        self.nq = nc * n
        self.np = nc * self.n_uc
        self.size = self.nq + self.np
        lr = model.C_lowrank
        nonlinear = {ct.dof for ct in self.unilateral} | {d for _, d in self.penalty} | {d for _, d in self.cubic}
        _check_memory(harmonics, len(nonlinear), self.n_uc, 3 * self.n_uc + len(self.penalty) + len(self.cubic),
                      int(lr.rank) if lr is not None and lr.rank else 0, isinstance(self.solver, BlockSolver))
        self.D1 = sp.csr_matrix(np.asarray(harmonics.operators.derivative_domega()))
        self.M, self.K, self.C = model.M.tocsr(), model.K.tocsr(), model.C.tocsr()
        # modal damping: the low-rank part U diag(d) U^T of the damping, never assembled on the
        # fast paths (residual, Jacobian products, block solver); C above is the sparse part
        self.C_lr = lr if lr is not None and lr.rank else None
        #: the dynamic stiffness S(w) on the coefficients (femodes.dynamic_stiffness): every
        #: linear operator of the harmonic balance comes from it
        self.stiffness = CoefficientStiffness(DynamicStiffness(self.K, self.M, self.C, self.C_lr), self.D1,
                                              damping_matrix=model.damping_matrix)
        # period-average weights for energies: <u.v> = sum_a w_a U_a V_a
        self.w = np.asarray(harmonics.galerkin.norm_weights())
        self.E = np.asarray(harmonics.grid.synthesis())
        self.Pa = np.asarray(harmonics.grid.analysis())
        # DOFs where the contact and nonlinear terms act: they couple the harmonics; all other
        # DOFs see the block-diagonal linear operator only (see femodes.hbm.linsolve)
        self.nonlinear_dofs = np.unique(np.array(
            [ct.dof for ct in self.unilateral] + [d for _, d in self.penalty] + [d for _, d in self.cubic], dtype=int))
        #: the contact and nonlinear terms of the residual, the Jacobian and the energy
        self.nonlinear = NonlinearForces(harmonics, n, self.unilateral, self.penalty, self.cubic, self.projection,
                                         self.E, self.Pa)
        #: the linear structure: forcing, S(w) applied and solved, the block solver's pattern and factors
        self.linear = LinearPart(model, harmonics, self.stiffness, self.nonlinear_dofs,
                                 solver_options=self.solver_options, threads=threads)
        self._cache: dict = {}

    def __getattr__(self, name):
        # only for names an HBMSystem does not have: the methods that moved to its collaborators
        return moved_attribute(self, name, _MOVED)

    @property
    def threads(self) -> int | None:
        """Threads of the per-harmonic factorisations (the ``threads`` argument; settable)."""
        return self.linear.threads

    @threads.setter
    def threads(self, value: int | None) -> None:
        self.linear.threads = value

    # -- layout -----------------------------------------------------------------------------
    def q_index(self, dof: int) -> np.ndarray:
        """Global indices of the Fourier coefficients of model DOF ``dof``."""
        return self.h.layout.global_index(np.arange(self.h.n_coef), dof, self.n)

    def p_index(self, slot: int) -> np.ndarray:
        """Global indices of the contact-force coefficients of complementarity contact ``slot``."""
        return self.nq + self.h.layout.global_index(np.arange(self.h.n_coef), slot, self.n_uc)

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``x -> (Q, P)`` with shapes ``(n_coef, n_dofs)`` and ``(n_coef, n_uc)``."""
        Q = self.h.layout.reshape(x[: self.nq], self.n)
        P = x[self.nq : self.size].reshape(self.h.n_coef, self.n_uc)
        return Q, P

    def join(self, Q: np.ndarray, P: np.ndarray | None = None) -> np.ndarray:
        if P is None:
            P = np.zeros((self.h.n_coef, self.n_uc))
        return np.concatenate([np.asarray(Q, dtype=float).ravel(), np.asarray(P, dtype=float).ravel()])

    def time_shift(self, y: np.ndarray, tau: float) -> np.ndarray:
        """The unknowns ``[Q; P]`` of the motion delayed by the phase ``tau`` (every displacement
        and contact force ``f(theta) -> f(theta - tau)``, ``h.operators.time_shift``)."""
        Q, P = self.split(y)
        return self.join(self.h.operators.time_shift(Q, tau), self.h.operators.time_shift(P, tau))

    def shift_generator(self, y: np.ndarray) -> np.ndarray:
        """``d/dtau`` of :meth:`time_shift` at ``tau = 0``: ``-nu D1`` on every signal (the sparse
        derivative operator of the residual, ``h.operators.shift_generator``)."""
        Q, P = self.split(y)
        minus_nu = -float(self.h.subharmonic)
        return self.join(minus_nu * (self.D1 @ Q), minus_nu * (self.D1 @ P))

    def residual(self, x: np.ndarray, omega: float, *, xi: float = 0.0, forced: bool = True):
        """Residual, Jacobian, ``dr/dw`` and ``dr/dxi`` (artificial damping ``-xi M q'``).

        Returns
        -------
        r : ndarray (size,)
        J : HarmonicBlockJacobian (size, size); ``J.tocsr()`` assembles it
        dr_domega : ndarray (size,)
        dr_dxi : ndarray (size,)
        """
        Q = x[: self.nq].reshape(self.h.n_coef, self.n)
        r, dr_domega, dr_dxi = self._linear_residual(Q, omega, xi, forced)
        jac = Triplets()
        self.nonlinear.add(x, Q, r, jac)
        N = jac.matrix(self.size, self._cache)
        return r, HarmonicBlockJacobian(self, omega, xi, N), dr_domega, dr_dxi

    def _linear_residual(self, Q: np.ndarray, omega: float, xi: float, forced: bool):
        """Linear part ``S(w) q - xi w (D1 x M) q (- f)`` of the residual and its derivatives in
        ``w`` and ``xi`` (zero on the contact-force rows); small systems from the cached dense
        operators (four small dense products instead of a dozen sparse ones)."""
        nq = self.nq
        terms: Sequence[np.ndarray]  # (r, dr/dw, dr/dxi)
        if nq <= DENSE_MAX_SIZE and self.C_lr is None:
            terms = self.stiffness.dense_residual(Q.reshape(-1), omega, xi)
        else:
            terms = [t.ravel() for t in self.stiffness.residual(Q, omega, xi)]
        r, dr_domega, dr_dxi = np.zeros(self.size), np.zeros(self.size), np.zeros(self.size)
        r[:nq], dr_domega[:nq], dr_dxi[:nq] = terms
        if forced:
            r[:nq] -= self.linear.force()
        return r, dr_domega, dr_dxi

    # -- energy -----------------------------------------------------------------------------
    def energy(self, x: np.ndarray, omega: float) -> tuple[float, np.ndarray, float]:
        """Period-averaged mechanical energy and its derivatives ``(E, dE/dx, dE/dw)``.

        ``E = <1/2 q'.M q' + 1/2 q.K q + V_springs(q)>`` (period average); for a conservative
        motion this is the constant total energy. Complementarity contacts store no energy.
        """
        h, n, nq = self.h, self.n, self.nq
        q = x[:nq]
        Q = q.reshape(h.n_coef, n)
        w = self.w[:, None]
        V = self.D1 @ Q                                   # velocity coefficients at w = 1
        MV = _mul(self.M, V)
        KQ = _mul(self.K, Q)
        ke = 0.5 * omega * omega * float(np.sum(w * V * MV))
        pe = 0.5 * float(np.sum(w * Q * KQ))
        grad = np.zeros(self.size)
        grad[:nq] = ((omega * omega) * (self.D1.T @ (w * MV)) + w * KQ).ravel()
        pe = self.nonlinear.add_energy(Q, pe, grad)
        return float(ke + pe), grad, float(2.0 * ke / omega) if omega else 0.0
