r"""Discretise layer: the dense Schur complement of the HBM Jacobian on its boundary unknowns.

The unknowns split into the *interior* ``I`` (coefficients of the linear DOFs) and the
*boundary* ``B`` (coefficients of the nonlinear DOFs, contact forces, modal coordinates of a
modal damping, border unknowns). Condensing onto ``B`` gives a dense Schur complement of size
``n_b (2H+1) + n_p + m`` whose linear part is the condensed dynamic stiffness
``Z_k[b,b] - Z_k[b,I] Z_k[I,I]^{-1} Z_k[I,b]`` of each harmonic (:mod:`.factors`), factorised by
dense LU with partial pivoting (the borders are inside it, so the solve stays accurate at folds,
where ``J`` without its border is singular). Layout of ``T``: ``[q_b | p | modal coordinates
(coefficient-major) | border]`` (:class:`SchurLayout`).
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from .blocks import StructureFailure, real_times_complex
from .factors import HarmonicFactors, LinearFactors
from .jacobian import HarmonicBlockJacobian
from .lowrank import ModalElimination

__all__ = ["SchurLayout", "SchurComplement"]


@dataclass(frozen=True)
class SchurLayout:
    """Positions of the boundary unknowns in ``J`` and in the Schur complement ``T``."""

    nc: int            # coefficient rows
    nb: int            # nonlinear (boundary) DOFs
    mr: int            # modal coordinates per coefficient row (rank of the modal damping)
    m: int             # border unknowns
    gq: np.ndarray     # global indices of the boundary displacement coefficients (coefficient-major)
    gB: np.ndarray     # gq and the contact-force unknowns
    off_y: int         # first modal coordinate in T
    off_m: int         # first border unknown in T
    nB: int            # size of T

    @classmethod
    def of(cls, J: HarmonicBlockJacobian, F: LinearFactors) -> SchurLayout:
        s, pat = J.system, F.pat
        nc, nb, m = s.h.n_coef, pat.bdofs.size, J.n_border
        gq = (np.arange(nc)[:, None] * s.n + pat.bdofs[None, :]).ravel()
        gB = np.concatenate([gq, s.nq + np.arange(s.np)])
        off_y = gB.size
        off_m = off_y + nc * F.rank
        return cls(nc, nb, F.rank, m, gq, gB, off_y, off_m, off_m + m)

    def qpos(self, row: int) -> np.ndarray:
        """Positions in ``T`` of the nonlinear DOFs at coefficient row ``row``."""
        return row * self.nb + np.arange(self.nb)

    def ypos(self, row: int) -> np.ndarray:
        """Positions of the modal coordinates (modal damping) at coefficient row ``row``."""
        return self.off_y + row * self.mr + np.arange(self.mr)

    def hpos(self, row: int) -> np.ndarray:
        """Positions of the condensed block of one coefficient row: nonlinear DOFs, then modal
        coordinates (the rows and columns of ``HarmonicFactors.Zc``)."""
        return _hpos(row, self.nb, self.mr, self.off_y)

    def block_rows(self, F: LinearFactors) -> tuple:
        """The coefficient rows ``(k, s)`` of each harmonic block of ``F`` (``s = -1`` for harmonic
        0), hashable: the key of the cached positions (:func:`_condensed_index`)."""
        return tuple((blk.k, -1 if blk.s is None else blk.s) for blk in F.blocks)


class SchurComplement:
    """``T = J[B, B] - J[B, I] J[I, I]^-1 J[I, B]``, assembled and factorised (dense LU).

    ``lean``: the border columns' interior solutions ``Zu = Z_II^-1 (u_c - i u_s)`` and rows
    ``vc`` are kept for the back substitution (and ``W = Z_II^-1 Z_Ib`` used where the factors
    keep it); otherwise the general path solves again (:mod:`.elimination`).
    """

    def __init__(self, J: HarmonicBlockJacobian, F: LinearFactors, layout: SchurLayout, lean: bool):
        self.J, self.F, self.L = J, F, layout
        # the lean path's interior solutions of the border columns and its border rows, per harmonic
        self.Zu: list | None = None
        self.vc: list | None = None
        T = self._boundary_block()
        self._add_condensed_stiffness(T)
        if layout.m and F.pat.perm.size:
            if lean:
                self._add_border_coupling_lean(T)
            else:
                self._add_border_coupling(T)
        if not np.all(np.isfinite(T)):
            raise StructureFailure("non-finite Schur complement")
        self.T = T
        self.ymodal = None
        if layout.mr:
            self.ymodal = ModalElimination.build(T, layout.block_rows(F), layout.mr, layout.off_y, layout.off_m)
        if self.ymodal is not None:
            self._factor(self.ymodal.Tr)
        elif layout.nB:
            self._factor(T)

    def _boundary_block(self) -> np.ndarray:
        """``J[B, B]`` without its linear part: the nonlinear part and the border entries."""
        J, L = self.J, self.L
        nG, om = L.gB.size, L.off_m
        T = np.zeros((L.nB, L.nB))
        # nonlinear part on the boundary (N is zero elsewhere by construction)
        NB = J.N[L.gB][:, L.gB]
        T[:nG, :nG] = J.scale * NB.toarray()
        # border entries on the boundary (the modal coordinates have none)
        if L.m:
            T[:nG, om:] = J.U[L.gB]
            T[om:, :nG] = J.V[:, L.gB]
            T[om:, om:] = J.D
        return T

    def _add_condensed_stiffness(self, T: np.ndarray) -> None:
        """Linear condensed stiffness per harmonic, real form ``[[X, Y], [-Y, X]]`` on ``(a, b)``:
        all harmonics in one scatter through the flat positions of :func:`_condensed_index`."""
        L, blocks = self.L, self.F.blocks
        single, paired = _condensed_index(L.nB, L.nb, L.mr, L.off_y, L.block_rows(self.F))
        sc = self.J.scale
        assert T.flags.c_contiguous  # (_boundary_block's array): the flat view writes into T
        flat = T.reshape(-1)  # ndarray.flat's fancy indexing is 5x slower
        ones = [blk.Zc for blk in blocks if blk.s is None]
        twos = [blk.Zc for blk in blocks if blk.s is not None]
        if ones:
            flat[single] += sc * np.concatenate([Z.real.ravel() for Z in ones])
        if twos:
            Z = np.stack(twos)
            p = Z.shape[1]
            R = np.empty((Z.shape[0], 2 * p, 2 * p))
            R[:, :p, :p] = R[:, p:, p:] = Z.real
            R[:, :p, p:] = Z.imag
            R[:, p:, :p] = -Z.imag
            flat[paired] += sc * R.ravel()

    def _border_solves(self, blk: HarmonicFactors, Ui: np.ndarray, Vi: np.ndarray):
        """Interior solves of one harmonic against the border columns ``Ui`` and rows ``Vi``."""
        R = self.F.pat.R
        # columns: z = Z^-1 (u_c - i u_s); interior solution (Re z, -Im z)
        rho = Ui[blk.k] - (1j * Ui[blk.s] if blk.s is not None else 0.0)
        assert blk.lu is not None  # called with interior DOFs only (F.pat.perm.size): each harmonic has its LU
        z = blk.lu.solve(rho)
        # rows: y = Z^-T (v_c + i v_s); v^T R^-1 = (Re, Im) of y^T
        mu = Vi[:, blk.k, :].T + (1j * Vi[:, blk.s, :].T if blk.s is not None else 0.0)
        y = blk.lu.solve(mu, trans=True)
        out = {}
        # T[q_b rows, border cols] -= real form of Z_bI z  (scale: s * (1/s))
        out["qb_m"] = blk.Zbi @ z[R]
        # T[border rows, q_b cols] -= (Re, Im) of y^T Z_Ib
        out["m_qb"] = (blk.Zib.T @ y[R]).T  # (m, nb)
        # T[border, border] -= v_I . (interior solution) / s
        vu = Vi[:, blk.k, :] @ z.real
        if blk.s is not None:
            vu = vu + Vi[:, blk.s, :] @ (-z.imag)
        out["m_m"] = vu
        if self.L.mr:
            lr = self.F.lowrank
            # modal rows: T[y, border] -= U_I^T z; modal columns: T[border, y] -= y^T (U_I diag(g))
            out["y_m"] = real_times_complex(lr.UI.T, z)
            out["m_y"] = real_times_complex(lr.UI.T, y).T * lr.Z.lowrank_gain(blk.f)
        return blk, out

    def _interior_borders(self):
        """The border columns ``U`` and rows ``V`` on the interior DOFs: ``(nc, nI, m)``, ``(m, nc, nI)``."""
        J, L = self.J, self.L
        s, I = J.system, self.F.pat.interior
        Ui = J.U[: s.nq].reshape(L.nc, s.n, L.m)[:, I, :]
        Vi = J.V[:, : s.nq].reshape(L.m, L.nc, s.n)[:, :, I]
        return Ui, Vi

    def _add_border_coupling(self, T: np.ndarray) -> None:
        """Border coupling through the interior: ``-J_BI J_II^-1 J_IB`` for the border rows/columns."""
        J, L = self.J, self.L
        qpos, m, off = L.qpos, L.m, L.off_m
        Ui, Vi = self._interior_borders()
        for blk, out in self.F.map(lambda blk: self._border_solves(blk, Ui, Vi)):
            Wz = out["qb_m"]
            T[np.ix_(qpos(blk.k), off + np.arange(m))] -= Wz.real
            if blk.s is not None:
                T[np.ix_(qpos(blk.s), off + np.arange(m))] -= -Wz.imag
            yZ = out["m_qb"]
            T[np.ix_(off + np.arange(m), qpos(blk.k))] -= yZ.real
            if blk.s is not None:
                T[np.ix_(off + np.arange(m), qpos(blk.s))] -= yZ.imag
            T[off:, off:] -= out["m_m"] / J.scale
            if L.mr:
                yk, ym = L.ypos(blk.k), off + np.arange(m)
                T[np.ix_(yk, ym)] -= out["y_m"].real
                T[np.ix_(ym, yk)] -= out["m_y"].real
                if blk.s is not None:
                    ys = L.ypos(blk.s)
                    T[np.ix_(ys, ym)] -= -out["y_m"].imag
                    T[np.ix_(ym, ys)] -= out["m_y"].imag

    def _add_border_coupling_lean(self, T: np.ndarray) -> None:
        """:meth:`_add_border_coupling` keeping the interior solutions ``Z_II^-1 (u_c - i u_s)``
        of the border columns for the back substitution and, where ``W = Z_II^-1 Z_Ib`` is kept,
        the border rows ``v^T Z_II^-1 Z_Ib = v^T W`` by a product instead of a transposed solve."""
        J, L, F = self.J, self.L, self.F
        m, nb, mr = L.m, L.nb, L.mr
        R = F.pat.R
        Ui, Vi = self._interior_borders()

        def one(blk: HarmonicFactors):
            rho = Ui[blk.k] - (1j * Ui[blk.s] if blk.s is not None else 0.0)
            assert blk.lu is not None  # called with interior DOFs only (F.pat.perm.size): each harmonic has its LU
            z = blk.lu.solve(rho)                                          # (nI, m)
            vc = Vi[:, blk.k, :] + (1j * Vi[:, blk.s, :] if blk.s is not None else 0.0)  # (m, nI)
            if not nb:
                yZ = np.zeros((m, 0))
            elif blk.W is not None:
                yZ = vc @ blk.W                                            # v^T Z^-1 Z_Ib
            else:
                y = blk.lu.solve(vc.T, trans=True)
                yZ = (blk.Zib.T @ y[R]).T
            if not mr:
                return z, vc, blk.Zbi @ z[R], yZ, (vc @ z).real, None, None
            # modal rows U_I^T z; modal columns v^T Z_II^-1 (U_I diag(g)) = (Z_II^-1 U_I)^T v ... by
            # the symmetry of Z (no sparse damping part, as in LowRankSplit._condense_modes)
            lr = F.lowrank
            ym = real_times_complex(lr.UI.T, z)
            my = lr.rows_x(blk, vc) * lr.Z.lowrank_gain(blk.f)
            return z, vc, blk.Zbi @ z[R], yZ, (vc @ z).real, ym, my

        out = F.map(one)
        self.Zu = [o[0] for o in out]
        self.vc = [o[1] for o in out]
        # the coefficient rows are consecutive in T (q_b coefficient-major from 0, the modal
        # coordinates from off_y): the border columns and rows of all harmonics go in by slices
        nc, off, oy = L.nc, L.off_m, L.off_y
        colq, rowq = np.zeros((nc, nb, m)), np.zeros((m, nc, nb))
        coly, rowy = (np.zeros((nc, mr, m)), np.zeros((m, nc, mr))) if mr else (None, None)
        for blk, (_, _, Wz, yZ, vu, ym, my) in zip(F.blocks, out):
            colq[blk.k], rowq[:, blk.k] = Wz.real, yZ.real
            if blk.s is not None:
                colq[blk.s], rowq[:, blk.s] = -Wz.imag, yZ.imag
            T[off:, off:] -= vu / J.scale
            if coly is not None and rowy is not None:  # as in _add_border_coupling
                coly[blk.k], rowy[:, blk.k] = ym.real, my.real
                if blk.s is not None:
                    coly[blk.s], rowy[:, blk.s] = -ym.imag, my.imag
        T[:nc * nb, off:] -= colq.reshape(nc * nb, m)
        T[off:, :nc * nb] -= rowq.reshape(m, nc * nb)
        if coly is not None and rowy is not None:
            T[oy:oy + nc * mr, off:] -= coly.reshape(nc * mr, m)
            T[off:, oy:oy + nc * mr] -= rowy.reshape(m, nc * mr)

    def _factor(self, T: np.ndarray) -> None:
        """Dense LU with partial pivoting of ``T`` (or of its part left by the modal elimination)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sla.LinAlgWarning)  # zero pivots are checked below
            lu, piv = sla.lu_factor(T, check_finite=False)
        d = np.abs(np.diag(lu))
        if np.any(d == 0.0):
            raise RuntimeError("singular Jacobian (zero pivot in the condensed system)")
        self.lu = (lu, piv)
        self.rcond_est = float(d.min() / max(d.max(), 1e-300))

    def solve(self, rhsB: np.ndarray) -> np.ndarray:
        """``T^-1 rhsB`` (with the modal coordinates eliminated first when they are)."""
        if self.ymodal is None:
            return sla.lu_solve(self.lu, rhsB, check_finite=False) if self.L.nB else rhsB
        return self.ymodal.solve(self.lu, rhsB)


@functools.lru_cache(maxsize=64)
def _condensed_index(nB: int, nb: int, mr: int, off_y: int, rows: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Flat positions in ``T`` (``nB x nB``) of the condensed blocks of the harmonics ``rows``
    (``(k, s)`` coefficient rows, ``s = -1`` for harmonic 0): those of the real blocks, then those of
    the ``[[X, Y], [-Y, X]]`` real forms, in the order of ``rows`` (positions as :meth:`SchurLayout.hpos`;
    cached: they depend on the layout's sizes only)."""
    def square(pos: np.ndarray) -> np.ndarray:
        return (pos[:, None] * nB + pos[None, :]).ravel()

    empty = np.zeros(0, dtype=np.intp)
    single = [square(_hpos(k, nb, mr, off_y)) for k, s in rows if s < 0]
    paired = [square(np.concatenate([_hpos(k, nb, mr, off_y), _hpos(s, nb, mr, off_y)])) for k, s in rows if s >= 0]
    return (np.concatenate(single) if single else empty, np.concatenate(paired) if paired else empty)


def _hpos(row: int, nb: int, mr: int, off_y: int) -> np.ndarray:
    """:meth:`SchurLayout.hpos` from the layout's sizes: the ``nb`` nonlinear DOFs of coefficient
    row ``row`` (coefficient-major from 0), then its ``mr`` modal coordinates (from ``off_y``)."""
    q = row * nb + np.arange(nb)
    return np.concatenate([q, off_y + row * mr + np.arange(mr)]) if mr else q
