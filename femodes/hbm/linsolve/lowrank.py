r"""Discretise layer: modal damping's low-rank part in the block solver.

Modal damping (``with_damping(modal=...)``) adds ``U diag(d) U^T`` (``U = M Phi``, ``n x m``) to
``C``: it couples all DOFs within each harmonic, so it is kept out of ``Z_k[I, I]`` (whose band LU
stays that of the sparse part) and handled through the Schur complement: the ``m`` modal
coordinates ``y_k = U^T z_k`` of each harmonic join the boundary, with the equations
``Z_k z + U diag(g) y = r`` (``g = i f d``, :meth:`DynamicStiffness.lowrank_gain`) and
``U^T z - y = 0``. The condensation needs ``Z_k[I, I]^{-1} U_I``; when ``Phi`` are modes of the
structure (``K Phi = M Phi diag(w^2)``, checked: :meth:`DynamicStiffness.lowrank_modes`),
``Z_k Phi = U diag(w^2 - c)`` (``c`` of :meth:`DynamicStiffness.mass_shift`) gives it from the
``n_b`` columns ``Z_k[I, I]^{-1} Z_k[I, b]`` already solved, so a Newton iteration costs about
what it costs with Rayleigh damping (``benchmarks/README.md``, "Modal damping"). The modal
coordinates couple only within their harmonic and to the borders, so they are eliminated
harmonic by harmonic (``m x m`` complex blocks, :class:`ModalElimination`) before the dense LU, which
keeps the size it has with Rayleigh damping. Woodbury on each block is the same algebra in
another order; the bordered form keeps the refinement and fallback paths unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ...dynamic_stiffness import DynamicStiffness
from .blocks import BlockPattern, real_times_complex

__all__ = ["LowRankSplit", "split_lowrank", "modal_shift", "ModalElimination"]


@dataclass
class LowRankSplit:
    """The low-rank damping ``U diag(d) U^T`` split on the interior and boundary DOFs of a pattern.

    ``modes`` (when ``U = M Phi`` with modes ``Phi`` of the structure): ``(Phi_I, Phi_b, w^2,
    U_I^T Phi_I, sI, E_S)`` with ``sI`` the interior positions of the rows where the mass changed
    after the modes were computed and ``E_S`` those rows of ``E = M Phi - U``.
    """

    Z: DynamicStiffness   # the model's: K, M, C and the low-rank part
    UI: np.ndarray
    Ub: np.ndarray
    modes: tuple | None = None

    @property
    def rank(self) -> int:
        return self.UI.shape[1]

    @property
    def d(self) -> np.ndarray:
        return self.Z.lowrank.d

    def condense(self, pat: BlockPattern, lu, Zbb, Zib, Zbi, f: float, xi: float, keep_w: bool):
        """Condensed block of one harmonic on ``[z_b; y]`` with modal coordinates ``y = U^T z``:

        ``[[Z_bb, U_b diag(g)], [U_b^T, -I]] - [[Z_bI], [U_I^T]] Z_II^-1 [Z_Ib, U_I diag(g)]``

        (``Z_II`` the sparse part, which keeps its band LU). One interior solve with ``n_b + m``
        columns and one real ``m x n_I`` product per harmonic; through the modes of the structure
        (:meth:`_condense_modes`) only the ``n_b`` columns are solved. Returns ``Zc``, or with
        ``keep_w`` on the modes path ``(Zc, W_b, pieces of Z_II^-1 U_I)`` (:meth:`apply_x`)."""
        if self.modes is not None and lu is not None:
            return self._condense_modes(pat, lu, Zbb, Zib, Zbi, f, xi, keep_w)
        m = self.rank
        nb = pat.bdofs.size
        gd = self.Z.lowrank_gain(f)
        top = np.hstack([Zbb, self.Ub * gd])
        bottom = np.hstack([self.Ub.T.astype(complex), -np.eye(m, dtype=complex)])
        Zc = np.vstack([top, bottom])
        if lu is None:
            return Zc
        nI = pat.perm.size
        full = np.zeros((nI, nb + m), dtype=complex)
        full[pat.R, :nb] = Zib
        full[:, nb:] = self.UI * gd
        W = np.ascontiguousarray(lu.solve_columns(full), dtype=complex)
        Zc[:nb] -= Zbi @ W[pat.R]
        # U_I^T W as one real product on the interleaved (re, im) view of W
        UW = (self.UI.T @ W.view(float).reshape(nI, 2 * (nb + m))).view(complex)
        Zc[nb:] -= UW
        return Zc

    def _condense_modes(self, pat: BlockPattern, lu, Zbb, Zib, Zbi, f: float, xi: float, keep_w: bool):
        """:meth:`condense` through the modes: ``Z_s Phi = U diag(mu)``, ``mu = w^2 - c``, gives
        ``Z_II^-1 U_I = (Phi_I + Z_II^-1 Z_Ib Phi_b + c Z_II^-1 E_I) diag(1/mu)`` from the ``n_b``
        columns already solved; only the modes with ``|mu|`` small (``k w`` at their frequency)
        are solved for."""
        m = self.rank
        nb, nI = pat.bdofs.size, pat.perm.size
        assert self.modes is not None  # condense takes this path with modes only
        PhiI, Phib, lam, G, sI, ES = self.modes
        c, mu_ok, bad = modal_shift(lam, f, xi)
        gd = self.Z.lowrank_gain(f)
        ns = sI.size
        full = np.zeros((nI, nb + ns + bad.size), dtype=complex)
        full[pat.R, :nb] = Zib
        full[sI, nb + np.arange(ns)] = 1.0   # unit columns on the changed mass rows
        full[:, nb + ns:] = self.UI[:, bad]
        W = lu.solve_columns(full) if full.shape[1] else full
        Wb = np.ascontiguousarray(W[:, :nb], dtype=complex)
        UWb = real_times_complex(self.UI.T, Wb) if nb else np.zeros((m, 0), complex)
        # X = Z_II^-1 U_I = (Phi_I + W_b Phi_b + c Z_II^-1 E_I) / mu with E = M Phi - U on the rows
        # sI (lowrank_modes): U_I^T X. The modes' residual K Phi - U diag(w^2) is round-off
        # (checked there); what it leaves is for the refinement.
        WS: np.ndarray | None
        Xbad: np.ndarray | None
        UX = G + UWb @ Phib
        if ns:
            WS = np.ascontiguousarray(W[:, nb:nb + ns], dtype=complex)
            UX = UX + c * (real_times_complex(self.UI.T, WS) @ ES)
        UX = UX / mu_ok
        if bad.size:
            Xbad = np.ascontiguousarray(W[:, nb + ns:], dtype=complex)
            UX[:, bad] = real_times_complex(self.UI.T, Xbad)
        # Z_bI X = Z_bI Z_II^-1 U_I = W_b^T U_I (Z is complex symmetric here: no sparse damping
        # part): exact, where (Phi_I + W_b Phi_b) / mu cancels near the held boundary DOFs (measured:
        # the first solve of a 1e5-DOF bar missed the refinement test by 30x that way)
        ZX = UWb.T
        Zc = np.empty((nb + m, nb + m), dtype=complex)
        Zc[:nb, :nb] = Zbb - Zbi @ Wb[pat.R] if nb else Zbb
        Zc[:nb, nb:] = (self.Ub - ZX) * gd
        Zc[nb:, :nb] = self.Ub.T - UWb
        Zc[nb:, nb:] = -np.eye(m) - UX * gd
        if not keep_w:
            return Zc
        inv_mu = 1.0 / mu_ok
        inv_mu[bad] = 0.0
        Xbad = np.ascontiguousarray(W[:, nb + ns:], dtype=complex) if bad.size else None
        WS = np.ascontiguousarray(W[:, nb:nb + ns], dtype=complex) if ns else None
        return Zc, Wb, (inv_mu, bad, Xbad, WS, c)

    def apply_x(self, blk, V: np.ndarray, PhiVm: np.ndarray | None = None) -> np.ndarray:
        """``Z_II^-1 U_I V`` (complex ``V``, ``m x k``) of one harmonic from the modes relation
        of :meth:`_condense_modes`, ``Z_II^-1 U_I = (Phi_I + W_b Phi_b + c Z_II^-1 E_I) diag(1/mu)``
        (the columns at ``k w`` near a mode's frequency solved directly): products, no solve.
        ``PhiVm``: ``Phi_I`` times :meth:`scaled` ``(blk, V)`` if the caller computed it (for all
        harmonics in one product, which reads ``Phi_I`` once); it is added to in place."""
        assert self.modes is not None  # blk.Xm is kept on the modes path only (_condense_modes)
        PhiI, Phib, _, _, _, ES = self.modes
        _, bad, Xbad, WS, c = blk.Xm
        Vm = self.scaled(blk, V)
        X = real_times_complex(PhiI, Vm) if PhiVm is None else PhiVm
        if blk.W is not None and blk.W.shape[1]:
            X += blk.W @ (Phib @ Vm)
        if WS is not None:
            X += WS @ (c * (ES @ Vm))
        if Xbad is not None:
            X += Xbad @ V[bad]
        return X

    @staticmethod
    def scaled(blk, V: np.ndarray) -> np.ndarray:
        """``diag(1/mu) V`` (zero on the modes solved directly), as :meth:`apply_x` uses it."""
        return np.ascontiguousarray(V * blk.Xm[0][:, None], dtype=complex)

    def rows_x(self, blk, L: np.ndarray) -> np.ndarray:
        """``L Z_II^-1 U_I`` (complex ``L``, ``r x n_I``) by the relation of :meth:`apply_x`."""
        assert self.modes is not None  # blk.Xm is kept on the modes path only (_condense_modes)
        PhiI, Phib, _, _, _, ES = self.modes
        inv_mu, bad, Xbad, WS, c = blk.Xm
        out = real_times_complex(PhiI.T, np.ascontiguousarray(L.T, dtype=complex)).T
        if blk.W is not None and blk.W.shape[1]:
            out = out + (L @ blk.W) @ Phib
        if WS is not None:
            out = out + c * ((L @ WS) @ ES)
        out = out * inv_mu
        if Xbad is not None:
            out[:, bad] = L @ Xbad
        return out


def modal_shift(lam: np.ndarray, f: float, xi: float = 0.0) -> tuple:
    """``(c, mu, bad)`` of the modes relation at the frequency ``f``: the mass shift ``c``
    (:meth:`DynamicStiffness.mass_shift`, real without ``xi``), the divisors ``mu = w^2 - c`` and
    the modes ``bad`` whose ``|mu|`` is within 1e-6 of the spectrum's scale of zero (``k w`` at
    their frequency: the relation cannot divide by ``mu``, their columns are solved directly; their
    ``mu`` is 1, so that dividing by all of ``mu`` is safe)."""
    c = DynamicStiffness.mass_shift(f, xi) if xi else f * f
    mu = lam - c
    bad = np.flatnonzero(np.abs(mu) <= 1e-6 * max(float(lam.max()), f * f, 1e-300))
    mu[bad] = 1.0
    return c, mu, bad


def split_lowrank(pat: BlockPattern, Z: DynamicStiffness) -> LowRankSplit | None:
    """The split of ``Z``'s low-rank damping on ``pat`` (None without one), with the modes relation
    of :meth:`DynamicStiffness.lowrank_modes` when it holds."""
    lr = Z.lowrank
    if lr is None or not lr.rank:
        return None
    UI = np.ascontiguousarray(lr.U[pat.interior])
    split = LowRankSplit(Z, UI, lr.U[pat.bdofs])
    em = Z.lowrank_modes()
    if em is not None:
        Phi, lam, rows, Erows = em
        PhiI = Phi[pat.interior]
        # the changed mass rows that are interior: their positions in the interior order
        pos = np.searchsorted(pat.interior, rows)
        inner = (pos < pat.interior.size) & (pat.interior[np.minimum(pos, pat.interior.size - 1)] == rows)
        split.modes = (PhiI, Phi[pat.bdofs], lam, UI.T @ PhiI, pos[inner], Erows[inner])
    return split


class ModalElimination:
    """The modal coordinates eliminated from the Schur complement ``T`` harmonic by harmonic: they
    couple only to the nonlinear DOFs of their harmonic and to the borders, so ``T_yy`` is block
    diagonal and the dense LU works on ``T_rr - T_ry T_yy^-1 T_yr``, the size it has with Rayleigh
    damping (at H = 10 the modal coordinates of 20 modes would make it 21x larger). The block of a
    harmonic pair is the real form ``[[X, Y], [-Y, X]]`` of the complex ``X + i Y`` (the condensed
    stiffness, :meth:`SchurComplement._add_condensed_stiffness`), so it is inverted as the ``m x m``
    complex matrix, all harmonics in one batched call. :meth:`build` returns None (the full ``T``
    is factorised, with its pivoting) if a block is ill-conditioned (condition number above 1e10).
    """

    def __init__(self, Tr, r, single, paired, Try, Y, oy: int, om: int):
        self.Tr, self.r, self.single, self.paired, self.Try, self.Y = Tr, r, single, paired, Try, Y
        self.oy, self.om = oy, om

    @staticmethod
    def _stacked(X: np.ndarray, single, paired, mr: int) -> tuple[np.ndarray, np.ndarray]:
        """``X`` (rows coefficient-major, ``(nc mr, k)``) as the stacks ``(n_0, mr, k)`` of the
        single rows and ``(n_p, 2 mr, k)`` of the pairs ``[cos; sin]``."""
        X4 = X.reshape(-1, mr, X.shape[1])
        return X4[single[0]], np.concatenate([X4[paired[0]], X4[paired[1]]], axis=1)

    @staticmethod
    def _unstack(out: np.ndarray, z0: np.ndarray, zp: np.ndarray, single, paired, mr: int) -> None:
        o4 = out.reshape(-1, mr, out.shape[1])
        o4[single[0]] = z0
        o4[paired[0]] = zp[:, :mr]
        o4[paired[1]] = zp[:, mr:]

    @classmethod
    def build(cls, T: np.ndarray, rows: tuple, mr: int, oy: int, om: int) -> ModalElimination | None:
        """``rows``: the coefficient rows ``(k, s)`` of each harmonic (``s = -1`` for harmonic 0),
        ``mr`` modal coordinates per row, ``T[oy:om]`` the modal rows (coefficient-major)."""
        nB = T.shape[0]
        nc = (om - oy) // mr
        r = np.r_[0:oy, om:nB]
        single = (np.array([k for k, s in rows if s < 0], dtype=int),)
        paired = (np.array([k for k, s in rows if s >= 0], dtype=int), np.array([s for k, s in rows if s >= 0], dtype=int))
        Tyy = T[oy:om, oy:om].reshape(nc, mr, nc, mr)
        A0 = Tyy[single[0], :, single[0], :]                               # (n_0, mr, mr)
        Zp = Tyy[paired[0], :, paired[0], :] + 1j * Tyy[paired[0], :, paired[1], :]   # (n_p, mr, mr)
        try:
            inv0, invp = np.linalg.inv(A0), np.linalg.inv(Zp)
        except np.linalg.LinAlgError:
            return None

        def rows_inf(B):  # infinity norms of the blocks (of the real forms for complex blocks)
            return (np.abs(B.real) + np.abs(B.imag)).sum(axis=2).max(axis=1)
        cond = np.concatenate([rows_inf(A0) * rows_inf(inv0), rows_inf(Zp) * rows_inf(invp)])
        if not (np.all(np.isfinite(inv0)) and np.all(np.isfinite(invp))) or np.any(cond > 1e10):
            return None
        realp = np.empty((invp.shape[0], 2 * mr, 2 * mr))                  # the real forms of the inverses
        realp[:, :mr, :mr] = realp[:, mr:, mr:] = invp.real
        realp[:, :mr, mr:] = invp.imag
        realp[:, mr:, :mr] = -invp.imag
        Tyr = T[oy:om][:, r]
        Y = np.empty((om - oy, r.size))
        t0, tp = cls._stacked(Tyr, single, paired, mr)
        cls._unstack(Y, inv0 @ t0, realp @ tp, single, paired, mr)
        Try = T[r][:, oy:om]
        Tr = T[np.ix_(r, r)] - Try @ Y
        return cls(Tr, r, (single[0], inv0), (paired, realp), Try, Y, oy, om)

    def solve(self, lu, rhsB: np.ndarray) -> np.ndarray:
        """``T^-1 rhsB`` from the LU of the reduced matrix ``Tr``."""
        oy, om, r = self.oy, self.om, self.r
        (k0, inv0), (paired, realp) = self.single, self.paired
        mr = inv0.shape[1] if inv0.size else realp.shape[1] // 2
        ry = rhsB[oy:om]
        zy = np.empty_like(ry)
        t0, tp = self._stacked(ry, (k0,), paired, mr)
        self._unstack(zy, inv0 @ t0, realp @ tp, (k0,), paired, mr)
        xr = sla.lu_solve(lu, rhsB[r] - self.Try @ zy, check_finite=False)
        x = np.empty_like(rhsB)
        x[r] = xr
        x[oy:om] = zy - self.Y @ xr
        return x
