"""Discretise layer: ``BlockSolver``, the default linear solver strategy of the harmonic balance.

It picks the factorisation of each Jacobian from its size and fill (``BlockSolverOptions``):
LAPACK on the dense matrix for small or half-full systems (:mod:`.assembled`), SuperLU on the
assembled matrix for mid-size ones, and from ``structured_min_size`` unknowns (systems SuperLU
factorises with little fill: ``structured_min_size_narrow``) the structured factorisation
(:mod:`.factorization`), optionally reusing the factors of a nearby frequency (:mod:`.reuse`); a
structure that does not apply (an interior resonance) falls back to SuperLU.
"""

from __future__ import annotations

import logging
import math
import weakref

import numpy as np

from .assembled import AssembledFactorization, DenseFactorization
from .blocks import StructureFailure
from .factorization import StructuredFactorization
from .jacobian import HarmonicBlockJacobian
from .options import DEFAULT_OPTIONS, BlockSolverOptions
from .krylov import KrylovReusedFactorization
from .reuse import ReusedFactorization, ReuseState, budget_from_factors

__all__ = ["BlockSolver", "STAT_KEYS"]

log = logging.getLogger(__name__)

#: Counters of :attr:`BlockSolver.stats`.
STAT_KEYS = ("factorizations", "reused", "solves_reused", "passes", "refactorized")


class BlockSolver:
    """Linear solver strategy of the harmonic balance (the default): per-harmonic band LU of the
    linear DOFs and a dense Schur complement on the nonlinear DOFs and borders
    (:mod:`femodes.hbm.linsolve`); systems up to ``options.dense_max_size`` unknowns (or below
    ``options.structured_min_size`` and at least ``options.dense_fill`` full) are assembled
    densely for LAPACK, larger ones below ``structured_min_size`` and blocks that cannot be
    factorised (an interior resonance) go to a sparse direct LU of the assembled matrix.

    Parameters
    ----------
    reuse : bool or "auto", default "auto"
        Reuse the per-harmonic factors of a nearby frequency (:mod:`femodes.hbm.linsolve.reuse`):
        a Jacobian at ``w`` within ``reuse_window`` (relative) of the frequency ``w0`` of the
        factors this solver used last for the same system (and at the same ``xi``) is solved
        with them as a preconditioner, refined against the true Jacobian to the backward-error
        test of a fresh factorisation (and a forward one), and factorised at ``w`` when the
        refinement would need more passes than a factorisation costs. Band-LU blocks (line
        meshes) iterate ``x <- x + P^-1 (b - J x)`` (:mod:`~femodes.hbm.linsolve.reuse`);
        sparse-direct blocks (2-D/3-D meshes) run GMRES with ``P^-1`` as preconditioner, its
        budget the measured cost of the factors (:mod:`~femodes.hbm.linsolve.krylov`). ``"auto"``:
        on sparse-direct blocks of at least ``options.reuse_auto_min_rows`` rows only
        (:doc:`/guide/performance`, Why these defaults).
    reuse_window : float, default 0.05
        Largest ``|w - w0| / |w0|`` tried.
    max_passes : int, optional
        Passes (solves with the reused factors) allowed per solve; default from the cost model
        of :meth:`passes_budget`.
    options : BlockSolverOptions, optional
        The tuning (thresholds of the paths, memory kept, cost model); default the measured one.

    Attributes
    ----------
    stats : dict
        Counters since construction (or :meth:`reset_stats`): ``factorizations`` (per-harmonic
        factor sets built through this solver), ``reused`` (factorisations served by factors of
        another frequency), ``solves_reused`` and ``passes`` (solves with them and their passes),
        ``refactorized`` (solves whose refinement did not contract fast enough: factorised
        afresh).
    """

    def __init__(self, *, reuse: bool | str = "auto", reuse_window: float = 0.05, max_passes: int | None = None,
                 options: BlockSolverOptions | None = None):
        if not (isinstance(reuse, (bool, np.bool_)) or reuse == "auto"):
            raise TypeError(f"reuse must be True, False or 'auto', got {reuse!r}")
        if not (isinstance(reuse_window, (int, float)) and 0.0 <= float(reuse_window) < 1.0):
            raise ValueError(f"reuse_window must be in [0, 1), got {reuse_window!r}")
        if max_passes is not None and (not isinstance(max_passes, (int, np.integer)) or max_passes < 1):
            raise ValueError(f"max_passes must be a positive integer or None, got {max_passes!r}")
        if options is not None and not isinstance(options, BlockSolverOptions):
            raise TypeError(f"options must be a BlockSolverOptions, got {options!r}")
        self.reuse: bool | str = reuse if reuse == "auto" else bool(reuse)
        self.reuse_window = float(reuse_window)
        self.max_passes = None if max_passes is None else int(max_passes)
        self.options = DEFAULT_OPTIONS if options is None else options
        self._states: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self.stats = dict.fromkeys(STAT_KEYS, 0)

    def reset_stats(self) -> None:
        self.stats = dict.fromkeys(STAT_KEYS, 0)

    def __getstate__(self):
        d = dict(self.__dict__)
        d["_states"] = None  # factors are not pickled
        return d

    def __setstate__(self, d):
        d.setdefault("options", DEFAULT_OPTIONS)  # pickled before the options existed
        self.__dict__.update(d)
        self._states = weakref.WeakKeyDictionary()

    def factorize(self, J: HarmonicBlockJacobian, *, threads: int | None = None):
        n, o = J.shape[0], self.options
        limit = self.structured_from(J)
        if n <= o.dense_max_size or (n < limit and J.N.nnz >= o.dense_fill * n * n):
            return DenseFactorization(J, o)
        if n < limit:
            return AssembledFactorization(J)
        try:
            state = self._state(J.system)
            F = self._reusable(J, state)
            if F is not None:
                assert state is not None  # _reusable finds factors in a state only
                try:
                    # sparse-direct blocks (2-D/3-D meshes): GMRES, where a factorisation costs
                    # tens to hundreds of solves (.krylov); band LU: the stationary iteration
                    reused = ReusedFactorization if F.pat.banded else KrylovReusedFactorization
                    fac = (StructuredFactorization(J, threads, F) if F.omega == J.omega
                           else reused(J, threads, F, self, state))
                except (StructureFailure, RuntimeError) as exc:  # P singular where J need not be
                    log.debug("reused factors not applicable (%s); factorising at w", exc)
                else:
                    if not fac.exact:
                        self.stats["reused"] += 1
                    return fac
            return self.fresh_factorization(J, threads, state)
        except StructureFailure as exc:
            log.debug("structured HBM factorisation not applicable (%s); the assembled matrix", exc)
            return AssembledFactorization(J)

    def structured_from(self, J: HarmonicBlockJacobian) -> int:
        """The size from which ``J`` takes the structured factorisation: ``structured_min_size``, or
        ``structured_min_size_narrow`` for systems SuperLU factorises with little fill, without
        modal damping: narrow band blocks (bars, beams: a bandwidth of at most ``narrow_band_kl``),
        no interior DOF, or mostly nonlinear DOFs (more than ``narrow_boundary_share`` of them: a
        reduced model with many contacts, whose structured path is a large dense Schur complement)
        (``BlockSolverOptions``)."""
        o = self.options
        n = J.shape[0]
        if n < o.structured_min_size or n >= o.structured_min_size_narrow:
            return o.structured_min_size  # the answer does not depend on the blocks
        system = J.system
        if system.stiffness.Z.lowrank is not None:
            return o.structured_min_size
        try:
            pat = system.linear.block_pattern()
        except StructureFailure:
            return o.structured_min_size  # the structured path reports its own failure
        narrow = (pat.interior.size == 0 or (pat.banded and pat.kl <= o.narrow_band_kl)
                  or pat.bdofs.size > o.narrow_boundary_share * (pat.bdofs.size + pat.interior.size))
        return o.structured_min_size_narrow if narrow else o.structured_min_size

    # -- reuse ------------------------------------------------------------------------------
    def reuses(self, J: HarmonicBlockJacobian) -> bool:
        """Whether factors of a nearby frequency may serve ``J`` (``reuse``; ``"auto"``: sparse-direct
        blocks of at least ``options.reuse_auto_min_rows`` interior rows)."""
        if self.reuse != "auto":
            return bool(self.reuse)
        pat = J.system.linear.block_pattern()
        return not pat.banded and pat.perm.size >= self.options.reuse_auto_min_rows

    def _state(self, system) -> ReuseState | None:
        try:
            st = self._states.get(system)
            if st is None:
                st = self._states[system] = ReuseState()
            return st
        except TypeError:  # not weak-referenceable / hashable: no reuse
            return None

    def fresh_factorization(self, J: HarmonicBlockJacobian, threads: int | None,
                            state: ReuseState | None) -> StructuredFactorization:
        """The exact factorisation at ``(J.omega, J.xi)`` (the system's cached factors if they are
        at that frequency); they become the base of later reuse. Without reuse the last factors are
        let go first: a Newton iteration at a new frequency then holds one set of factors, not two
        (and their MUMPS instances are refactorised, ``sparse_direct.PatternFactorizer``)."""
        if (state is not None and state.F is not None and not self.reuses(J)
                and (state.F.omega, state.F.xi) != (float(J.omega), float(J.xi))):
            state.F = None
        F = J.system.linear.factors(J.omega, J.xi, threads)
        if state is not None and F is not state.F:
            self.stats["factorizations"] += 1
            state.F = F
        return StructuredFactorization(J, threads, F)

    def _reusable(self, J: HarmonicBlockJacobian, state: ReuseState | None):
        """The factors to solve ``J`` with if they are at another, close frequency and the last
        measured contraction predicts a refinement within budget; else None."""
        if state is None or state.F is None or not self.reuses(J):
            return None
        F0 = state.F
        if F0.xi != J.xi or F0.pat is not J.system.linear.block_pattern():
            return None
        if F0.omega == J.omega:
            return F0
        if F0.omega == 0.0:
            return None
        dw = abs(J.omega - F0.omega) / abs(F0.omega)
        if not dw <= self.reuse_window:
            return None
        if state.rate is not None:  # passes predicted from the last measured contraction
            q = state.rate * dw
            budget = self.max_passes if self.max_passes is not None else budget_from_factors(F0, self.options)
            if q >= 0.5 or max(2, math.ceil(math.log(self.options.reuse_forward_tol) / math.log(q))) > budget:
                return None
        return F0

    def passes_budget(self, fac: StructuredFactorization) -> int:
        """Passes a reused solve may take before it refactorises: ``max_passes``, or the cost
        model of :func:`~femodes.hbm.linsolve.reuse.budget_from_factors`."""
        if self.max_passes is not None:
            return self.max_passes
        return budget_from_factors(fac.F, self.options)

    def record_reuse(self, state: ReuseState, fac: StructuredFactorization, passes: int, worst: float,
                     ok: bool) -> None:
        """Count a reused solve and remember its contraction per unit relative offset."""
        self.stats["solves_reused"] += 1
        self.stats["passes"] += passes
        dw = abs(fac.J.omega - fac.F.omega) / abs(fac.F.omega)
        if dw > 0 and worst > 0:
            state.rate = worst / dw  # contraction per unit relative offset, for the next prediction
        if not ok:
            self.stats["refactorized"] += 1

    def __repr__(self) -> str:
        args = []
        if self.reuse != "auto":
            args.append(f"reuse={self.reuse!r}")
        if self.reuse_window != 0.05:
            args.append(f"reuse_window={self.reuse_window!r}")
        if self.max_passes is not None:
            args.append(f"max_passes={self.max_passes!r}")
        if self.options != DEFAULT_OPTIONS:
            args.append(f"options={self.options!r}")
        return f"BlockSolver({', '.join(args)})"
