r"""Models layer: the dynamic stiffness, the one place where its formula is written.

For ``M q'' + C q' + K q = f`` with the damping ``C = C_s + U diag(d) U^T`` (a sparse part and
the low-rank part of modal damping, :class:`~femodes.model.LowRankDamping`) and the artificial
damping ``-xi M q'`` of the extended periodic motion concept (Krack 2015), a time derivative
``s`` gives the dynamic stiffness

.. math::

    Z(s) = K + s\,(C_s - \xi M) + s^2 M + s\,U \operatorname{diag}(d)\,U^T .

It is evaluated in two forms, each written once here:

* one harmonic ``e^{i f t}`` (``s = i f``): ``Z = K - f^2 M + i f (C_s - xi M) + i f U d U^T``
  (:class:`DynamicStiffness`: linear responses, the per-harmonic blocks of the HBM block solver);
* the coefficient rows ``Q`` (``n_coef x n``) of a Galerkin basis of periodic functions whose
  time derivative is ``w D`` (``D`` at unit frequency, e.g. ``h.operators.derivative_domega()``):
  ``S(w) = I x K + w D x (C - xi M) + w^2 D^2 x M`` (:class:`CoefficientStiffness`: the harmonic
  balance residual, Jacobian products, the assembled operators, Hill's matrices).

A new damping model is a change of this module. Each form keeps the order of its floating-point
operations (the results are the same to the last bit as where they were written before).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

__all__ = ["DynamicStiffness", "CoefficientStiffness", "mul_rows"]


def mul_rows(A, Q: np.ndarray) -> np.ndarray:
    """``(A @ Q.T).T`` for ``Q`` of shape (n_coef, n): the product on a contiguous copy (scipy
    would copy the strided view once per product anyway; this is ~2x faster at 1e5 DOFs)."""
    return np.ascontiguousarray((A @ np.ascontiguousarray(Q.T)).T)


@dataclass(frozen=True, eq=False)
class DynamicStiffness:
    """``Z(i f) = K - f^2 M + i f (C - xi M) + i f U diag(d) U^T`` of one harmonic (module docstring).

    ``K, M, C`` are any three arrays of one shape that support ``+``, ``-`` and scalar products:
    sparse matrices of a model, dense blocks of them, their values on a sparsity pattern, row
    sums. ``lowrank`` is the low-rank damping part (``U, d``), kept apart: it is applied, never
    assembled here.
    """

    K: Any
    M: Any
    C: Any
    lowrank: Any = None
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def of(cls, model) -> DynamicStiffness:
        """The dynamic stiffness of a :class:`~femodes.model.StructuralModel` (sparse CSR)."""
        lr = model.C_lowrank
        return cls(model.K.tocsr(), model.M.tocsr(), model.C.tocsr(), lr if lr is not None and lr.rank else None)

    def parts(self, f: float, xi: float = 0.0) -> tuple:
        """``(K - f^2 M, f (C - xi M))``: the real and imaginary parts of the sparse part of ``Z(i f)``."""
        C = self.C - xi * self.M if xi else self.C
        return self.K - (f * f) * self.M, f * C

    def harmonic(self, f: float, xi: float = 0.0):
        """The sparse part of ``Z(i f)``, complex (``K - f^2 M + i f (C - xi M)``)."""
        re, im = self.parts(f, xi)
        return re + 1j * im

    def real_block(self, f: float, xi: float = 0.0) -> sp.csc_matrix:
        """The sparse part of ``Z(i f)`` in real form on the coefficients ``[c; s]`` of
        ``c cos(f t) + s sin(f t)``: ``[[Re Z, Im Z], [-Im Z, Re Z]]`` (sparse matrices)."""
        re, im = self.parts(f, xi)
        return sp.bmat([[re, im], [-im, re]], format="csc")

    def lowrank_gain(self, f: float) -> np.ndarray:
        """``g = i f d``: the low-rank part of ``Z(i f)`` is ``U diag(g) U^T`` (zeros without one)."""
        if self.lowrank is None:
            return np.zeros(0, dtype=complex)
        return 1j * f * self.lowrank.d

    @staticmethod
    def mass_shift(f: float, xi: float = 0.0) -> complex:
        """``c = f^2 + i f xi``: ``Z(i f) = K - c M + i f C`` (the modal forms ``Z Phi = U diag(w^2 - c)``)."""
        return f * f + 1j * f * xi

    def abs_bound(self, f: float, xi: float = 0.0):
        """``|K| + f^2 |M| + f (|C| + |xi| |M|)`` for non-negative ``K, M, C`` (row sums of the
        absolute matrices): an upper bound of the row sums of ``|Z(i f)|``."""
        return self.K + f ** 2 * self.M + f * (self.C + abs(xi) * self.M)

    def lowrank_modes(self):
        """``(Phi, w^2, rows, E_rows)`` if the low-rank damping comes from modes of these matrices
        (``U = M_0 Phi``, ``K Phi = M_0 Phi diag(w^2)``) and there is no sparse damping part, else
        None. Then, with ``E = M Phi - U`` (zero but on the few ``rows`` where the mass changed
        after ``with_damping``: ``with_contact`` redistributes the contact node's mass),
        ``(K - c M) Phi = U diag(w^2 - c) - c E`` for ``c`` of :meth:`mass_shift` up to round-off
        (used by the block solver; cached).

        ``K Phi = U diag(w^2)`` is checked mode by mode (max norm) against the round-off of the
        products, ``1e3 eps max(|K| |phi_j| + w_j^2 |M| |phi_j|)``: that is the accuracy of any
        product with ``K`` (on a 1e5-DOF bar the first mode's relative residual is 3e-6, all of
        it round-off of ``K phi``; measured residuals are 1-8 eps of that bound at 1e3-1e5 DOFs),
        so the condensation is exact to the level the block solver's refinement test accepts.
        More than 64 changed rows of ``M``: None (the general path, ``m`` solves per harmonic)."""
        if "lr_modes" not in self._cache:
            lr, out = self.lowrank, None
            if lr is not None and lr.modes is not None and not self.C.nnz:
                Phi, lam = np.asarray(lr.modes), np.asarray(lr.eigenvalues)
                U = lr.U
                aPhi = np.abs(Phi)
                aUlam = np.abs(U) * lam
                tol = 1e3 * np.finfo(float).eps
                EK = self.K @ Phi - U * lam
                ok_k = bool(np.all(np.abs(EK).max(axis=0) <= tol * (abs(self.K) @ aPhi + aUlam).max(axis=0)))
                EM = self.M @ Phi - U
                bound = tol * (abs(self.M) @ aPhi + np.abs(U)).max(axis=0)
                rows = np.flatnonzero(np.any(np.abs(EM) > bound, axis=1))
                if ok_k and rows.size <= 64:
                    out = (Phi, lam, rows, EM[rows])
            self._cache["lr_modes"] = out
        return self._cache["lr_modes"]


def _combine(w: float, xi: float, A0, A1, A2, AM):
    """``w^2 A2 + w A1 + A0 - xi w AM``: ``S(w)`` from its terms ``I x K``, ``D x C``, ``D^2 x M``,
    ``D x M`` (operators, or their products with one vector)."""
    S = (w * w) * A2 + w * A1 + A0
    if xi:
        S = S - (xi * w) * AM
    return S


class CoefficientStiffness:
    r"""``S(w) = I x K + w D x (C - xi M) + w^2 D^2 x M (+ w D x U diag(d) U^T)``: the dynamic
    stiffness on coefficient rows (module docstring), applied without forming the Kronecker
    products; those are built on demand (cached) for the assembled operators.

    Parameters
    ----------
    Z : DynamicStiffness
        The model's sparse ``K, M, C`` and low-rank damping.
    D : sparse matrix (n_coef, n_coef)
        The time derivative on the coefficient index at unit frequency.
    damping_matrix : callable, optional
        The assembled damping ``C + U diag(d) U^T`` (``StructuralModel.damping_matrix``, which
        refuses large models); default: assembled here.
    """

    def __init__(self, Z: DynamicStiffness, D, *, damping_matrix: Callable | None = None):
        self.Z = Z
        self.D = sp.csr_matrix(D)
        self.n_coef = self.D.shape[0]
        self._damping_matrix = damping_matrix
        self._cache: dict = {}

    # -- Kronecker operators (n_coef n x n_coef n, cached) -------------------------------------
    @property
    def C_full(self):
        """The whole damping matrix, assembled (``C`` itself without a low-rank part; dense with
        one: only the assembled operators use it, for small systems and checks)."""
        if self.Z.lowrank is None:
            return self.Z.C
        if "C_full" not in self._cache:
            if self._damping_matrix is not None:
                C = self._damping_matrix()
            else:
                C = self.Z.C.toarray() + self.Z.lowrank.toarray()
            self._cache["C_full"] = sp.csr_matrix(C)
        return self._cache["C_full"]

    def term(self, name: str):
        """One Kronecker term (cached, built on first use): ``A2 = D^2 x M``, ``A1 = D x C``
        (whole damping), ``A1s = D x C_s`` (sparse part), ``A0 = I x K``, ``AM = D x M``,
        ``IM = I x M``, ``IC = I x C`` (whole damping)."""
        if name not in self._cache:
            Z, D = self.Z, self.D

            def eye():
                return sp.identity(self.n_coef, format="csr")

            left, A = {"A2": lambda: (D @ D, Z.M), "A1": lambda: (D, self.C_full), "A1s": lambda: (D, Z.C),
                       "A0": lambda: (eye(), Z.K), "AM": lambda: (D, Z.M), "IM": lambda: (eye(), Z.M),
                       "IC": lambda: (eye(), self.C_full)}[name]()
            self._cache[name] = sp.kron(left, A, format="csr")
        return self._cache[name]

    # -- assembled ------------------------------------------------------------------------------
    def operator(self, w: float, xi: float = 0.0, *, lowrank: bool = True) -> sp.csr_matrix:
        """``S(w)`` assembled (sparse; with ``lowrank`` and modal damping its blocks are dense:
        small systems and checks; ``lowrank=False``: the sparse part only, see :meth:`lowrank_border`)."""
        t = self.term
        return _combine(w, xi, t("A0"), t("A1") if lowrank else t("A1s"), t("A2"), t("AM"))

    def _dense(self) -> tuple:
        if "dense" not in self._cache:
            self._cache["dense"] = tuple(self.term(k).toarray() for k in ("A2", "A1", "A0", "AM"))
        return self._cache["dense"]

    def dense_operator(self, w: float, xi: float = 0.0) -> np.ndarray:
        """``S(w)`` as a dense array (small systems; the dense terms are cached on first use)."""
        A2, A1, A0, AM = self._dense()
        return _combine(w, xi, A0, A1, A2, AM)

    def dense_residual(self, q: np.ndarray, w: float, xi: float = 0.0) -> tuple:
        """``(S q, dS/dw q, dS/dxi q)`` from the cached dense terms (small systems: four small
        dense products instead of a dozen sparse ones; the 1-DOF seed case: 15 against 90 us)."""
        A2, A1, A0, AM = self._dense()
        y2, y1, ym = A2 @ q, A1 @ q, AM @ q
        Sq = _combine(w, xi, A0 @ q, y1, y2, ym)
        dS = (2.0 * w) * y2 + y1
        if xi:
            dS = dS - xi * ym
        return Sq, dS, -w * ym

    def lowrank_border(self, w: float):
        """The low-rank damping of ``S(w)`` as a border: ``S(w) = S_sparse(w) + B (I x U^T)`` with
        ``B = w (D x U diag(d))`` (``nq x n_coef m``, sparse) and the modal coordinates
        ``y = (I x U^T) q``; None without a low-rank part."""
        lr = self.Z.lowrank
        if lr is None:
            return None
        if "lr_rows" not in self._cache:
            self._cache["lr_rows"] = sp.kron(sp.identity(self.n_coef, format="csr"), sp.csr_matrix(lr.U.T), format="csr")
            self._cache["lr_cols"] = sp.kron(self.D, sp.csr_matrix(lr.U * lr.d), format="csr")
        return w * self._cache["lr_cols"], self._cache["lr_rows"]

    def exponent_terms(self, w: float, xi: float = 0.0, *, dense: bool = False) -> tuple:
        """``(J1, J2)`` with ``S(w)`` at ``d/dt + s`` equal to ``S(w) + s J1 + s^2 J2`` (Hill's
        method): ``J1 = I x (C - xi M) + 2 w D x M``, ``J2 = I x M``; dense arrays with
        ``dense`` (small systems: the dense terms are cached on first use)."""
        if dense:
            if "exponent_dense" not in self._cache:
                self._cache["exponent_dense"] = tuple(self.term(k).toarray() for k in ("IC", "AM", "IM"))
            IC, AM, IM = self._cache["exponent_dense"]
            J1 = IC + (2.0 * w) * AM
            return (J1 - xi * IM if xi else J1), IM
        J1 = self.term("IC") + 2.0 * w * self.term("AM")
        if xi:
            J1 = J1 - xi * self.term("IM")
        return J1, self.term("IM")

    # -- on coefficient rows ---------------------------------------------------------------------
    def _abs(self) -> tuple:
        """``|M|, |K|, |C|, |D|`` (cached: the Newton tolerance asks for them every iteration)."""
        if "abs" not in self._cache:
            Z = self.Z
            self._cache["abs"] = (abs(Z.M), abs(Z.K), abs(Z.C), abs(self.D))
        return self._cache["abs"]

    def _products(self, Q: np.ndarray, absolute: bool) -> tuple:
        """``K Q, M Q, C Q`` on rows (the whole damping) and ``D`` (``absolute``: of ``|K|, |M|,
        |C|``, ``|D|`` and a bound of the low-rank part)."""
        Z = self.Z
        M, K, C, D = (Z.M, Z.K, Z.C, self.D) if not absolute else self._abs()
        CQ = mul_rows(C, Q) if C.nnz else np.zeros_like(Q)
        if Z.lowrank is not None:
            CQ += Z.lowrank.abs_bound_rows(Q) if absolute else Z.lowrank.rmatmul_rows(Q)
        return mul_rows(K, Q), mul_rows(M, Q), CQ, D

    def apply(self, Q: np.ndarray, w: float, xi: float = 0.0, *, absolute: bool = False) -> np.ndarray:
        """``S(w) Q`` for coefficient rows ``Q`` (n_coef, n) (``absolute``: an upper bound of
        ``|S| |Q|``, for tolerances)."""
        KQ, MQ, CQ, D = self._products(Q, absolute)
        if absolute:
            w, xi = abs(w), -abs(xi)
        out = KQ
        out += (w * w) * (D @ (D @ MQ))
        if xi:
            CQ -= xi * MQ
        out += w * (D @ CQ)
        return out

    def residual(self, Q: np.ndarray, w: float, xi: float = 0.0) -> tuple:
        """``(S Q, dS/dw Q, dS/dxi Q)`` on coefficient rows (the linear part of the HBM residual;
        the terms grouped as :meth:`apply` does but for the ``xi`` term, kept apart for ``dS/dxi``)."""
        KQ, MQ, CQ, D = self._products(Q, False)
        DMQ = D @ MQ
        D2MQ, DCQ = D @ DMQ, D @ CQ
        SQ = KQ + (w * w) * D2MQ + w * DCQ
        dS = (2.0 * w) * D2MQ + DCQ
        if xi:
            SQ -= (xi * w) * DMQ
            dS -= xi * DMQ
        return SQ, dS, -w * DMQ

    def change(self, Q: np.ndarray, w0: float, w: float, xi: float = 0.0) -> np.ndarray:
        """``(S(w0) - S(w)) Q = (w0^2 - w^2) D^2 M Q + (w0 - w) D (C - xi M) Q`` for ``k`` sets of
        coefficient rows ``Q`` (n_coef, n, k), returned as ``(n_coef n, k)``: one GEMM with the
        dense ``D^T`` over the coefficient index (``K`` cancels). Without low-rank damping only."""
        if self.Z.lowrank is not None:
            raise ValueError("CoefficientStiffness.change: not with a low-rank damping part")
        nc, n, k = Q.shape
        if "dense_d" not in self._cache:
            D1 = self.D.toarray()
            self._cache["dense_d"] = (D1.T, (D1 @ D1).T)
        D1T, D2T = self._cache["dense_d"]
        QT = np.ascontiguousarray(Q.transpose(1, 0, 2)).reshape(n, nc * k)
        MQ = self.Z.M @ QT
        CQ = self.Z.C @ QT if self.Z.C.nnz else np.zeros_like(MQ)
        if xi:
            CQ -= xi * MQ

        def rows(A):  # (n, nc k) -> (n k, nc): one GEMM with D^T over the coefficient index
            return A.reshape(n, nc, k).transpose(0, 2, 1).reshape(n * k, nc)

        diff = rows(MQ) @ ((w0 * w0 - w * w) * D2T) + rows(CQ) @ ((w0 - w) * D1T)   # (n k, nc)
        return diff.reshape(n, k, nc).transpose(2, 0, 1).reshape(nc * n, k)

    def abs_row_sums(self) -> tuple[float, float, float]:
        """``max_i sum_j |A_ij|`` of ``K, M, C`` (the low-rank part included; for norm bounds)."""
        absM, absK, absC, _ = self._abs()
        rs = [float(A.sum(axis=1).max()) if A.nnz else 0.0 for A in (absK, absM, absC)]
        if self.Z.lowrank is not None:
            rowC = np.asarray(absC.sum(axis=1)).ravel() + self.Z.lowrank.abs_row_sums()
            rs[2] = float(rowC.max())
        return rs[0], rs[1], rs[2]
