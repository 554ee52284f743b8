"""Discretise layer: one pass of the block elimination of an HBM Newton system (no refinement).

Forward: the interior solves of each harmonic and their coupling into the boundary right-hand
side; the Schur complement solve (:mod:`.schur`); back substitution on the interior. The lean
pass (:meth:`BlockElimination.lean`) works harmonic by harmonic in complex form with one band solve
per harmonic where ``W = Z_II^-1 Z_Ib`` is kept (the back substitution is ``W x_b`` plus the
kept interior solutions of the border columns); the general pass (:meth:`BlockElimination.general`)
handles any damping (modal coordinates without the modes relation included) with two. Cost per
Newton iteration: ``O(N H bw^2)`` for the band LUs, ``O(N H (n_b + m))`` for the condensation
solves and ``O((n_b (2H+1))^3)`` for the dense LU.
"""

from __future__ import annotations

import numpy as np

from .blocks import real_times_complex
from .factors import HarmonicFactors, LinearFactors
from .jacobian import HarmonicBlockJacobian
from .schur import SchurComplement, SchurLayout

__all__ = ["BlockElimination"]


class BlockElimination:
    """``x = P^-1 B`` for the factors ``F`` of ``J`` (``P = J`` when ``F`` is at ``J``'s frequency)."""

    def __init__(self, J: HarmonicBlockJacobian, F: LinearFactors, layout: SchurLayout, schur: SchurComplement,
                 lean: bool):
        self.J, self.F, self.L, self.schur, self.is_lean = J, F, layout, schur, lean

    def __call__(self, B: np.ndarray) -> np.ndarray:
        return self.lean(B) if self.is_lean else self.general(B)

    def _boundary_rhs(self, B: np.ndarray) -> np.ndarray:
        """``(nB, k)``: ``q_b``, ``p``, modal coordinates (zero), border."""
        L, n0 = self.L, self.J.system.size
        return np.concatenate([B[L.gB], np.zeros((L.nc * L.mr, B.shape[1])), B[n0:]], axis=0)

    def lean(self, B: np.ndarray) -> np.ndarray:
        """One pass harmonic by harmonic in complex form (module docstring)."""
        J, L, F = self.J, self.L, self.F
        s, pat = J.system, F.pat
        nc, n, m, k = L.nc, s.n, L.m, B.shape[1]
        n0, nb, sc, mr = s.size, L.nb, J.scale, L.mr
        I, R = pat.interior, pat.R
        nI = I.size
        lr = F.lowrank
        x = np.zeros_like(B)
        rhsB = self._boundary_rhs(B)
        blocks = F.blocks
        if nI:
            bq = B[: s.nq].reshape(nc, n, k)
            inv_sc = 1.0 / sc
            vc = self.schur.vc

            def forward(i: int):
                blk = blocks[i]
                rho = bq[blk.k][I] if blk.s is None else bq[blk.k][I] - 1j * bq[blk.s][I]
                assert blk.lu is not None  # nI > 0: each harmonic has its interior LU
                z = blk.lu.solve(rho * inv_sc)
                w = (blk.Zbi @ z[R]) * sc if nb else None
                v = None
                if m:
                    assert vc is not None  # the lean Schur complement keeps its border rows
                    v = (vc[i] @ z).real
                return z, w, v

            fw = F.map_index(forward)
            # the modal rows U_I^T z of all harmonics in one product (it reads U_I once: at 1e5 DOFs
            # and 20 modes that is 16 MB per harmonic)
            yms: list = (np.split(real_times_complex(lr.UI.T, np.hstack([f[0] for f in fw]).astype(complex, copy=False))
                                  * sc, len(fw), axis=1) if mr else [None] * len(fw))
            for blk, (z, w, v), ym in zip(blocks, fw, yms):
                if ym is not None:  # modal rows y = U^T q (real form): rhs_y -= s U_I^T y_I
                    rhsB[L.ypos(blk.k)] -= ym.real
                    if blk.s is not None:
                        rhsB[L.ypos(blk.s)] += ym.imag
                if nb:
                    rhsB[blk.k * nb + np.arange(nb)] -= w.real
                    if blk.s is not None:
                        rhsB[blk.s * nb + np.arange(nb)] += w.imag
                if m:
                    rhsB[L.off_m:] -= v
        xB = self.schur.solve(rhsB)
        x[L.gB] = xB[: L.gB.size]
        x[n0:] = xB[L.off_m:]
        if nI:
            xq = xB[: L.gq.size].reshape(nc, nb, k)
            xm = xB[L.off_m:] * inv_sc if m else None
            xy = xB[L.off_y:L.off_m].reshape(nc, mr, k) if mr else None
            Zu = self.schur.Zu
            # Phi_I diag(1/mu) (diag(g) y) of every harmonic with modal coordinates in one product
            # (LowRankSplit.apply_x; Phi_I read once)
            modal = [i for i, blk in enumerate(blocks) if mr and blk.s is not None and blk.f != 0.0]
            gy: dict = {}
            PXs: dict = {}
            if modal:
                assert xy is not None  # set when mr
                for i in modal:
                    blk = blocks[i]
                    gy[i] = lr.Z.lowrank_gain(blk.f)[:, None] * (xy[blk.k] - 1j * xy[blk.s])
                PX = real_times_complex(lr.modes[0], np.hstack([lr.scaled(blocks[i], gy[i]) for i in modal]))
                PXs = dict(zip(modal, np.split(PX, len(modal), axis=1)))

            def back(i: int):
                blk = blocks[i]
                z = fw[i][0]
                if nb:
                    zc = xq[blk.k] if blk.s is None else xq[blk.k] - 1j * xq[blk.s]
                    if blk.W is not None:
                        z = z - blk.W @ zc
                    else:
                        full = np.zeros((nI, k), dtype=complex)
                        full[R] = blk.Zib @ zc
                        assert blk.lu is not None  # nI > 0: each harmonic has its interior LU
                        z = z - blk.lu.solve(full)
                if m:
                    assert Zu is not None  # the lean Schur complement keeps the border columns' solutions
                    z = z - Zu[i] @ xm
                if i in gy:
                    # Z_II^-1 (U_I diag(g) y) with y = y_c - i y_s, by products (LowRankSplit.apply_x)
                    z = z - lr.apply_x(blk, gy[i], PXs[i])
                return z

            bw = F.map_index(back)
            xq_all = x[: s.nq].reshape(nc, n, k)
            for blk, z in zip(blocks, bw):
                if np.iscomplexobj(z):
                    xq_all[blk.k, I] = z.real
                    if blk.s is not None:
                        xq_all[blk.s, I] = -z.imag
                else:
                    xq_all[blk.k, I] = z
        return x

    def _interior_solve(self, X: np.ndarray) -> np.ndarray:
        """``S_II^{-1}`` on real interior coefficient arrays ``X`` of shape (nc, nI, k)."""
        out = np.empty_like(X)

        def one(blk: HarmonicFactors):
            rho = X[blk.k] - (1j * X[blk.s] if blk.s is not None else 0.0)
            assert blk.lu is not None  # called with interior DOFs only: each harmonic has its LU
            z = blk.lu.solve(rho)
            return blk, z

        for blk, z in self.F.map(one):
            out[blk.k] = z.real
            if blk.s is not None:
                out[blk.s] = -z.imag
        return out

    def general(self, B: np.ndarray) -> np.ndarray:
        """One pass of the block elimination, any damping (modal coordinates included)."""
        J, L, F = self.J, self.L, self.F
        s, pat = J.system, F.pat
        nc, n, m, k = L.nc, s.n, L.m, B.shape[1]
        n0, sc, mr, nb = s.size, J.scale, L.mr, L.nb
        I = pat.interior
        nI = I.size
        lr = F.lowrank
        x = np.zeros_like(B)
        rhsB = self._boundary_rhs(B)
        if nI:
            bI = B[: s.nq].reshape(nc, n, k)[:, I, :] / sc
            yI = self._interior_solve(bI)
            if mr:  # modal rows (real form y_c = U^T q_c on every coefficient row): rhs_y -= s U_I^T y_I
                rhsB[L.off_y:L.off_m] -= sc * np.matmul(lr.UI.T, yI).reshape(nc * mr, k)
            # rhs_B -= J_BI y_I: q_b rows get s * S_bI y_I, border rows V_I y_I
            if nb:
                for blk in F.blocks:
                    yc = yI[blk.k] - (1j * yI[blk.s] if blk.s is not None else 0.0)
                    w = (blk.Zbi @ yc[pat.R]) * sc
                    rhsB[blk.k * nb + np.arange(nb)] -= w.real
                    if blk.s is not None:
                        rhsB[blk.s * nb + np.arange(nb)] -= -w.imag
            if m:
                Vi = J.V[:, : s.nq].reshape(m, nc, n)[:, :, I]
                rhsB[L.off_m:] -= np.einsum("mci,cik->mk", Vi, yI)
        xB = self.schur.solve(rhsB)
        x[L.gB] = xB[: L.gB.size]
        x[n0:] = xB[L.off_m:]
        if nI:
            # x_I = y_I - S_II^{-1} (S_Ib x_qb + U_I x_m / s)
            c = np.zeros((nc, nI, k))
            if nb:
                xq = xB[: L.gq.size].reshape(nc, nb, k)
                for blk in F.blocks:
                    zc = xq[blk.k] - (1j * xq[blk.s] if blk.s is not None else 0.0)
                    w = blk.Zib @ zc
                    c[blk.k, pat.R] += w.real
                    if blk.s is not None:
                        c[blk.s, pat.R] += -w.imag
            if mr:  # x_I -= Z_II^-1 (U_I diag(g) y), g = i f d: real form f U_I d y_s on cos rows,
                    # -f U_I d y_c on sin rows
                y = xB[L.off_y:L.off_m].reshape(nc, mr, k)
                for blk in F.blocks:
                    if blk.f == 0.0 or blk.s is None:
                        continue
                    gain = lr.Z.lowrank_gain(blk.f).imag[:, None]
                    c[blk.k] += lr.UI @ (gain * y[blk.s])
                    c[blk.s] -= lr.UI @ (gain * y[blk.k])
            if m:
                Ui = J.U[: s.nq].reshape(nc, n, m)[:, I, :]
                c += np.einsum("cim,mk->cik", Ui, xB[L.off_m:]) / sc
            xI = yI - self._interior_solve(c)
            xq_all = x[: s.nq].reshape(nc, n, k)
            xq_all[:, I, :] = xI
        return x
