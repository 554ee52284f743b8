r"""Damping of a model: Rayleigh ``C = alpha M + beta K`` (sparse) or modal damping kept as a
low-rank part ``U diag(d) U^T`` (:class:`LowRankDamping`), and its Woodbury solver;
:class:`Damping` (``model.damping``) is the damping of a model as one operator.

:func:`damped` is :meth:`~femodes.StructuralModel.with_damping`. The arguments are kept on the
model (``damping_spec``) with a fingerprint of the matrices they made, so that a later contact
that redistributes mass recomputes the damping from the new mass matrix
(:func:`redamped_after_contact`) unless the matrices were replaced since.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..solvers.checks import named_by, user_stacklevel
from ..eigen import normal_modes

__all__ = ["DENSE_DAMPING_MAX_DOFS", "Damping", "LowRankDamping", "low_rank_solver", "damped", "damping_fingerprint",
           "damping_spec_fresh", "fingerprinted", "redamped_after_contact"]

log = logging.getLogger(__name__)

#: Models above this many DOFs refuse to assemble a damping matrix that has a low-rank part
#: (:meth:`Damping.matrix`): its n^2 entries are what the low-rank form avoids.
DENSE_DAMPING_MAX_DOFS = 20000


@dataclass(frozen=True, eq=False)
class LowRankDamping:
    r"""The low-rank part ``U diag(d) U^T`` of a damping matrix (modal damping).

    Modal damping ``C = M Phi diag(2 zeta_j w_j) Phi^T M`` on ``m`` mass-normalised modes is
    kept as ``U = M Phi`` (``n x m``, dense) and ``d = 2 zeta w`` (``m``): ``2 n m`` numbers
    instead of ``n^2``, and ``C v`` costs ``4 n m`` flops. Every consumer uses it exactly: the
    harmonic balance residual and Jacobian, its block solver (the modal coordinates
    ``y = U^T q`` join the boundary of the Schur complement), linear responses and time stepping
    (Woodbury, :func:`low_rank_solver`), shooting and Hill's method (assembled, small models).

    Parameters
    ----------
    U : array_like, shape (n, m)
    d : array_like, shape (m,)
        Non-negative gains.
    modes, eigenvalues : ndarray, optional
        ``Phi`` and ``w_j^2`` when ``U = M Phi`` with ``K Phi = M Phi diag(w^2)`` (set by
        ``with_damping``): then ``(K - a M) Phi = U diag(w^2 - a)``, which gives the block solver
        ``Z^-1 U`` without solves. Only a hint: users of it check the relation on their matrices.
    """

    U: Any
    d: Any
    modes: Any = None
    eigenvalues: Any = None

    def __post_init__(self):
        U = np.array(self.U, dtype=float, order="C")
        d = np.array(self.d, dtype=float).ravel()
        if U.ndim != 2 or d.shape != (U.shape[1],):
            raise ValueError(f"LowRankDamping: U must be (n, m) and d (m,), got shapes {U.shape} and {d.shape}")
        if not (np.all(np.isfinite(U)) and np.all(np.isfinite(d))) or np.any(d < 0):
            raise ValueError("LowRankDamping: U and d must be finite and d non-negative")
        U.flags.writeable = d.flags.writeable = False
        object.__setattr__(self, "U", U)
        object.__setattr__(self, "d", d)

    @property
    def n(self) -> int:
        return self.U.shape[0]

    @property
    def rank(self) -> int:
        return self.U.shape[1]

    @property
    def nnz(self) -> int:
        """Stored numbers (``U`` and ``d``)."""
        return int(self.U.size + self.d.size)

    def matmul(self, X: np.ndarray) -> np.ndarray:
        """``U diag(d) U^T X`` for ``X`` of shape ``(n,)`` or ``(n, k)`` (real or complex)."""
        X = np.asarray(X)
        Y = self.U.T @ X
        Y = (self.d * Y.T).T if Y.ndim == 2 else self.d * Y
        return self.U @ Y

    def rmatmul_rows(self, Q: np.ndarray) -> np.ndarray:
        """``(C_lr Q^T)^T = Q U diag(d) U^T`` for ``Q`` of shape ``(k, n)`` (rows are vectors)."""
        return ((np.asarray(Q) @ self.U) * self.d) @ self.U.T

    def abs_bound_rows(self, Q: np.ndarray) -> np.ndarray:
        """An upper bound of ``|C_lr| |Q|`` on rows, like :meth:`rmatmul_rows`: ``|U| d |U|^T``."""
        aU = np.abs(self.U)
        return ((np.abs(np.asarray(Q)) @ aU) * self.d) @ aU.T

    def abs_row_sums(self) -> np.ndarray:
        """Upper bounds of the row sums of ``|U diag(d) U^T|``."""
        aU = np.abs(self.U)
        return aU @ (self.d * aU.sum(axis=0))

    def toarray(self) -> np.ndarray:
        """The assembled ``n x n`` matrix (symmetrized; small models and checks only)."""
        C = (self.U * self.d) @ self.U.T
        return 0.5 * (C + C.T)

    def restrict(self, rows) -> LowRankDamping:
        """The part on a subset (or slice) of the DOFs: ``U[rows] diag(d) U[rows]^T``."""
        return LowRankDamping(self.U[rows], self.d)

    def project(self, T: np.ndarray) -> LowRankDamping:
        """``T^T (U diag(d) U^T) T`` as a low-rank part: ``(T^T U, d)``."""
        return LowRankDamping(np.asarray(T).T @ self.U, self.d)


class Damping:
    """The damping matrix of a model as one operator, ``C + U diag(d) U^T`` (``model.damping``):
    its sparse part ``model.C`` and its low-rank part ``model.C_lowrank`` (modal damping)."""

    def __init__(self, C: Any, lowrank: LowRankDamping | None):
        self.C = C
        self.lowrank = lowrank

    @property
    def nonzero(self) -> bool:
        """True if the damping (sparse or low-rank part) is not zero (stored zeros do not count)."""
        return bool(self.C.count_nonzero()) or (self.lowrank is not None and bool(np.any(self.lowrank.d)))

    def apply(self, V: np.ndarray) -> np.ndarray:
        """The damping matrix times ``V`` (shape ``(n,)`` or ``(n, k)``): ``C V + U diag(d) U^T V``."""
        out = self.C @ V
        if self.lowrank is not None:
            out = out + self.lowrank.matmul(V)
        return out

    def matrix(self) -> sp.csr_matrix:
        """The assembled damping matrix ``C + U diag(d) U^T`` (``C`` itself without a low-rank part).

        With a low-rank part the matrix is dense: for small models and checks only; refused
        above :data:`DENSE_DAMPING_MAX_DOFS` DOFs.
        """
        lr, n = self.lowrank, self.C.shape[0]
        if lr is None:
            return self.C
        if n > DENSE_DAMPING_MAX_DOFS:
            raise ValueError(
                f"damping_matrix: the modal damping of this {n}-DOF model is kept as a low-rank part; "
                f"assembling it would store {n}^2 entries (use damping.apply, or C and C_lowrank)"
            )
        return sp.csr_matrix(self.C.toarray() + lr.toarray())

    def __repr__(self) -> str:
        low = "none" if self.lowrank is None else f"rank {self.lowrank.rank}"
        return f"Damping(sparse nnz={self.C.nnz}, low-rank part {low})"


def low_rank_solver(solve, L: np.ndarray, g: np.ndarray, R: np.ndarray, *, matvec=None, refine: int = 2,
                    AinvL: np.ndarray | None = None):
    r"""Solver of ``(A + L diag(g) R^T) x = b`` from a solver ``solve(b) = A^{-1} b`` (Woodbury).

    With ``X = A^{-1} L`` (``m`` solves, done here once; ``AinvL`` if the caller has it) and the
    ``m x m`` capacitance matrix ``S = I + diag(g) R^T X``: ``x0 = A^{-1} b``,
    ``y = S^{-1} diag(g) R^T x0``, ``x = x0 - X y`` (Hager 1989, "Updating the inverse of a
    matrix", SIAM Rev. 31:221). No ``g^{-1}`` is formed,
    so zero gains are fine. ``matvec(x) = A x``, if given, adds up to ``refine`` steps of
    iterative refinement against the full matrix (``A`` may be ill-conditioned: the undamped
    sparse part near a resonance that the low-rank part damps). ``b`` may be 1-D or 2-D.
    """
    import scipy.linalg as sla

    L = np.asarray(L)
    R = np.asarray(R)
    g = np.asarray(g)
    X = solve(L) if AinvL is None else np.asarray(AinvL)
    S = np.eye(g.size, dtype=np.result_type(X, g)) + g[:, None] * (R.T @ X)
    lu = sla.lu_factor(S, check_finite=False)

    def apply(x):
        Rx = R.T @ x
        return (L @ ((g * Rx.T).T if Rx.ndim == 2 else g * Rx))

    def once(b):
        x0 = solve(b)
        Rx = R.T @ x0
        y = sla.lu_solve(lu, (g * Rx.T).T if Rx.ndim == 2 else g * Rx, check_finite=False)
        return x0 - X @ y

    def run(b):
        b = np.asarray(b)
        x = once(b)
        if matvec is not None:
            scale = float(np.max(np.abs(b))) if b.size else 0.0
            for _ in range(refine):
                r = b - matvec(x) - apply(x)
                if not np.max(np.abs(r), initial=0.0) > 1e-14 * scale:
                    break
                x = x + once(r)
        return x

    return run

# -- with_damping and its spec ---------------------------------------------------------------
def _check_coefficients(alpha, beta) -> None:
    for name, v in (("alpha", alpha), ("beta", beta)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise TypeError(f"with_damping: {name} must be a finite non-negative number, got {v!r}")
        if not math.isfinite(v) or v < 0:
            raise ValueError(f"with_damping: {name} must be a finite non-negative number, got {v!r}")


def _modal_ratios(model, modal, n_modes) -> tuple[np.ndarray, int]:
    """The damping ratio of each of the first ``nm`` modes, and ``nm`` (checked against the
    model's modes)."""
    if isinstance(modal, (str, bytes, bool, np.bool_)):
        raise TypeError(f"with_damping: modal must be a damping ratio or a list of ratios, got {modal!r}")
    try:
        zeta = np.atleast_1d(np.asarray(modal, dtype=float))
    except (TypeError, ValueError) as exc:
        raise TypeError(f"with_damping: modal must be a damping ratio or a list of ratios, got {modal!r}") from exc
    if zeta.ndim != 1 or zeta.size == 0 or not np.all(np.isfinite(zeta)) or np.any(zeta < 0):
        raise ValueError(f"with_damping: modal must be non-negative finite damping ratios, got {modal!r}")
    if np.any(zeta > 1.0):  # legal (overdamped), but a percentage given as a ratio looks the same
        warnings.warn(f"with_damping: modal={modal!r} gives damping ratios above 1 (largest {zeta.max():g}): those modes "
                      f"are overdamped and do not vibrate; a ratio is a fraction of critical damping (1 % is 0.01, so "
                      f"{zeta.max():g} % is {zeta.max() / 100:g})", UserWarning, stacklevel=user_stacklevel())
    n = model.n_dofs
    if n_modes is not None:
        if isinstance(n_modes, (bool, np.bool_)) or not isinstance(n_modes, (int, np.integer)):
            raise TypeError(f"with_damping: n_modes must be an integer >= 1 or None, got {n_modes!r}")
        if not 1 <= n_modes <= n:
            raise ValueError(f"with_damping: n_modes must be in [1, {n}] (the model has {n} DOFs), got {n_modes!r}")
    # a DOF without mass (a contact node whose mass was redistributed) carries no mode
    n_inertial = int(np.count_nonzero(model.M.diagonal() > 0))
    if zeta.size > n_inertial or (n_modes is not None and n_modes > n_inertial):
        extra = f" ({n - n_inertial} of its {n} DOFs have no mass)" if n_inertial < n else ""
        raise ValueError(
            f"with_damping: modal gives {max(zeta.size, n_modes or 0)} modes' damping ratios (modal=, n_modes=) "
            f"but the model has only {n_inertial} modes{extra}; give at most {n_inertial}"
        )
    nm = int(n_modes) if n_modes is not None else (zeta.size if zeta.size > 1 else min(n_inertial, 20))
    if zeta.size == 1:
        zeta = np.full(nm, zeta[0])
    if zeta.size != nm:
        raise ValueError(f"with_damping: modal gives {zeta.size} ratios but n_modes={nm}")
    return zeta, nm


def damped(model, alpha: float = 0.0, beta: float = 0.0, modal: Any = None, n_modes: int | None = None):
    """``model`` with Rayleigh or modal damping (:meth:`~femodes.StructuralModel.with_damping`),
    its arguments and fingerprint in ``damping_spec``."""
    _check_coefficients(alpha, beta)
    if modal is None:
        with np.errstate(over="ignore"):
            C = alpha * model.M + beta * model.K
        if C.nnz and not np.all(np.isfinite(C.data)):
            raise ValueError(
                f"with_damping: alpha={alpha!r}, beta={beta!r} overflow: C = alpha M + beta K has infinite entries"
            )
        return fingerprinted(dataclasses.replace(model, C=C, C_lowrank=None,
                                                 damping_info=f"Rayleigh alpha={alpha:g}, beta={beta:g}",
                                                 damping_spec=(("alpha", alpha), ("beta", beta))))
    if alpha or beta:
        raise ValueError("with_damping: give either Rayleigh coefficients (alpha, beta) or modal=, not both")
    zeta, nm = _modal_ratios(model, modal, n_modes)
    with named_by("with_damping"):  # with_damping is not an entry point yet
        omega, phi = normal_modes(model.K, model.M, nm)
    lowrank = LowRankDamping(model.M @ phi, 2.0 * zeta * omega, modes=np.asarray(phi), eigenvalues=omega**2)
    ratios = f"{zeta[0]:g}" if np.all(zeta == zeta[0]) else f"{zeta.min():g}..{zeta.max():g}"
    spec = (("modal", tuple(float(z) for z in np.atleast_1d(np.asarray(modal, dtype=float)))), ("n_modes", n_modes))
    return fingerprinted(dataclasses.replace(model, C=sp.csr_matrix((model.n_dofs, model.n_dofs)), C_lowrank=lowrank,
                                             damping_info=f"modal zeta={ratios} on {nm} modes", damping_spec=spec))


def damping_fingerprint(model) -> tuple:
    """Sums that change when the damping matrices are replaced: ``sum |C|`` and the low-rank
    part's ``sum d`` and ``sum |U|``."""
    lr = model.C_lowrank
    return (float(abs(model.C).sum()), 0.0 if lr is None else float(np.sum(lr.d)),
            0.0 if lr is None else float(np.sum(np.abs(lr.U))))


def damping_spec_fresh(model) -> bool:
    """Whether ``damping_spec``'s fingerprint is that of the damping matrices (they were not
    replaced since ``with_damping``)."""
    return dict(model.damping_spec).get("fingerprint") == damping_fingerprint(model)


def fingerprinted(model):
    """This new model (just built by :func:`damped`, or rotated into nodal frames) with its damping
    matrices' fingerprint in ``damping_spec``: a later change of ``C`` by ``dataclasses.replace``
    makes the spec stale, and ``with_contact`` then keeps the matrices as they are."""
    spec = tuple(kv for kv in model.damping_spec if kv[0] != "fingerprint")
    object.__setattr__(model, "damping_spec", spec + (("fingerprint", damping_fingerprint(model)),))
    return model


def redamped_after_contact(before, out, mass_changed: bool):
    """The model ``out`` that ``with_contact`` built from ``before`` (``mass_changed``: the contact
    mass was redistributed), with the damping given before the contact recomputed
    for the redistributed mass (``C = alpha M + beta K``, or the new modes; the contact node's
    zero mass row then also zeroes ``C``); unless the matrices were replaced since
    ``with_damping`` (kept as they are, a warning)."""
    spec = dict(before.damping_spec)
    spec.pop("fingerprint", None)
    if not spec or not mass_changed:
        return out
    if not damping_spec_fresh(before):
        log.warning("with_contact: the damping matrices changed after with_damping(%s) (dataclasses.replace?): "
                    "kept as they are, not recomputed for the redistributed mass; call with_damping again",
                    ", ".join(f"{k}={v}" for k, v in spec.items()))
        return dataclasses.replace(out, damping_spec=())
    log.info("with_contact: damping (%s) recomputed for the redistributed mass", before.damping_info)
    if "modal" in spec:
        z = spec["modal"]
        spec["modal"] = z[0] if len(z) == 1 else list(z)
    return out.with_damping(**spec)
