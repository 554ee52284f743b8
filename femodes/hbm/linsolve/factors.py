"""Discretise layer: the per-harmonic interior factorisations and condensed stiffnesses at one ``(w, xi)``.

For each harmonic ``k`` (frequency ``f = k w / nu``) the interior block ``Z_k[I, I]`` is
factorised (:class:`~.blocks.BlockLU`) and the dynamic stiffness condensed onto the boundary,
``Z_k[b,b] - Z_k[b,I] Z_k[I,I]^{-1} Z_k[I,b]`` (with modal damping on the boundary and the modal
coordinates, :mod:`.lowrank`). The ``H + 1`` factorisations are independent and can run in
threads (``HBMSystem(threads=...)``; LAPACK and SuperLU release the GIL). Default one thread: on
the 2-core test machine two threads were slower (1e5-DOF bar, H = 20: 1283 ms vs 1118 ms per
Newton iteration, ``benchmarks/README.md``), the band solves being memory-bound. They depend only
on ``(w, xi)`` and are cached on the system: Newton at a fixed frequency reuses them at every
iteration; inside a continuation ``w`` changes at every iteration and they are rebuilt, all but
harmonic 0, whose block ``Z(0) = K`` does not depend on ``w`` (kept on the pattern); the sparse
factorisations of the other harmonics share one symbolic analysis
(:class:`~femodes.sparse_direct.PatternFactorizer`). The
columns ``W = Z_II^-1 Z_Ib`` of the condensation are kept (``keep_w_max_bytes``): the back
substitution is then a product instead of a band solve.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ...sparse_direct import sparse_backend_info
from .blocks import BlockLU

__all__ = ["HarmonicFactors", "LinearFactors"]


@dataclass
class HarmonicFactors:
    """The factors of one harmonic (its coefficient rows, frequency, interior LU, condensed block)."""

    k: int                 # coefficient row of the cosine (0 for the mean)
    s: int | None          # coefficient row of the sine (None for the mean)
    f: float               # k w / nu
    lu: BlockLU | None
    Zc: np.ndarray         # condensed dynamic stiffness on the boundary DOFs and modal coordinates
                           # (complex (n_b + m_lr) x (n_b + m_lr); n_b x n_b without modal damping)
    Zib: np.ndarray        # Z[I, b] on the coupled rows R (complex len(R) x n_b)
    Zbi: np.ndarray        # Z[b, I] on the coupled columns R (complex n_b x len(R))
    W: np.ndarray | None = None  # Z[I, I]^-1 Z[I, b], all interior rows (complex n_I x n_b), kept when
                                 # LinearFactors.keep_w (back substitution by a product, no solve)
    Xm: tuple | None = None      # modal damping through the modes: what Z[I, I]^-1 U_I is made of
                                 # (LowRankSplit.apply_x), kept with W


def _threads(n_tasks: int, threads: int | None, size: int, min_size: int) -> int:
    if threads is None or size < min_size:
        return 1
    if threads == 0:  # all CPUs
        threads = os.cpu_count() or 1
    return max(1, min(int(threads), n_tasks))


class LinearFactors:
    """Per-harmonic interior LUs and condensed stiffnesses at one ``(w, xi)`` (cached on the system).

    ``structure`` provides ``h`` (the harmonics), ``block_pattern()`` and ``solver_options``
    (:class:`~femodes.hbm.linear_part.LinearPart`, ``HBMSystem.linear``).
    """

    def __init__(self, structure, omega: float, xi: float, threads: int | None = None):
        t0 = time.process_time()
        self.omega, self.xi = float(omega), float(xi)
        h, opts = structure.h, structure.solver_options
        pat = structure.block_pattern()
        self.pat = pat
        nb = pat.bdofs.size
        # modal damping U diag(d) U^T: the modal coordinates y = U^T z join the boundary (.lowrank)
        self.lowrank = lr = pat.lowrank
        self.rank = 0 if lr is None else lr.rank
        self.modes = None if lr is None else lr.modes
        jobs: list[tuple[int, int | None, float]] = [(0, None, 0.0)]
        for k in range(1, h.n_harmonics + 1):
            f = k * self.omega / h.subharmonic
            jobs.append((int(h.layout.cos_index(k)), int(h.layout.sin_index(k)), f))
        # keep the condensation columns W = Z_II^-1 Z_Ib (computed anyway): the back substitution
        # and the border rows then cost a product instead of a band solve (keep_w_max_bytes).
        # With modal damping through the modes of the structure, W and the few columns that make
        # up Z_II^-1 U_I are kept too: the solve then takes the lean path (one band solve per
        # harmonic, issue 38 item 5)
        self.keep_w = bool((not self.rank or self.modes is not None) and nb and pat.perm.size
                           and 16 * pat.perm.size * nb * len(jobs)
                           <= (opts.keep_w_max_bytes if pat.banded else opts.keep_w_max_bytes_sparse))
        superlu = opts.superlu_options

        def one(job):
            row_c, row_s, f = job
            if f == 0.0:
                # harmonic 0: Z(0) = K whatever w and xi (f multiplies every term in them, modal
                # damping's gain i f d too), so its factors are kept on the pattern and shared by
                # every frequency (one factorisation of K_II and its n_b solves saved per Newton
                # iteration of a continuation); one entry per keep_w, not per xi (xi is an unknown
                # of the nonlinear-mode continuation)
                key = self.keep_w
                if pat.static is None:
                    pat.static = {}
                hit = pat.static.get(key)
                if hit is None:
                    hit = pat.static[key] = build(job)
                return hit
            return build(job)

        def build(job):
            row_c, row_s, f = job
            lu = BlockLU(pat, f, self.xi, superlu_options=superlu) if pat.perm.size else None
            Zbb, Zib, Zbi = (Z.harmonic(f, self.xi) for Z in (pat.bb, pat.Ib, pat.bI))
            W = Xm = None
            if self.rank:
                Zc = lr.condense(pat, lu, Zbb, Zib, Zbi, f, self.xi, self.keep_w)
                if isinstance(Zc, tuple):
                    Zc, W, Xm = Zc
            elif lu is not None and nb:
                W = lu.solve_rows(pat.R, Zib)  # Z_II^-1 Z_Ib: Z_Ib is nonzero on the rows R only
                Zc = Zbb - Zbi @ W[pat.R]
            else:
                Zc, W = Zbb, None
            keep = self.keep_w and W is not None
            return HarmonicFactors(row_c, row_s, f, lu, np.asarray(Zc, dtype=complex), Zib, Zbi,
                                   np.asarray(W, dtype=complex) if keep else None, Xm if keep else None)

        nt = _threads(len(jobs), threads, pat.perm.size, opts.thread_min_size)
        if nt > 1 and not pat.banded and sparse_backend_info().indefinite != "superlu":
            nt = 1  # MUMPS instances are not used from several Python threads (not tested for it)
        if nt > 1:
            with ThreadPoolExecutor(nt) as ex:
                self.blocks = list(ex.map(one, jobs))
        else:
            self.blocks = [one(j) for j in jobs]
        self.threads = nt
        #: CPU time of building these factors (the budget of a reused solve, .krylov)
        self.cpu_s = time.process_time() - t0

    def map(self, fun):
        """Apply ``fun(block)`` to all harmonics (threaded like the factorisation)."""
        if self.threads > 1:
            with ThreadPoolExecutor(self.threads) as ex:
                return list(ex.map(fun, self.blocks))
        return [fun(b) for b in self.blocks]

    def map_index(self, fun):
        """Apply ``fun(i)`` for the index ``i`` of every harmonic block (threaded like :meth:`map`)."""
        idx = range(len(self.blocks))
        if self.threads > 1:
            with ThreadPoolExecutor(self.threads) as ex:
                return list(ex.map(fun, idx))
        return [fun(i) for i in idx]
