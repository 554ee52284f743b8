r"""Discretise layer: the reduced model Hill's problem is solved on (free-interface modes with the
residual flexibility of the nonlinear DOFs).

Hill's problem of a model with many contacts is large even when the model is small: a
Craig-Bampton model of a blade with 27 contact DOFs and 10 modes has ``(2H + 1)(37 + 27)`` = 704
unknowns at H = 5, of which 407 carry mass. Its dense solve takes 2 s a point and its sparse one
did not converge (ARPACK, 108 exponents per shift). The perturbations that decide stability are
the slow ones, though: the exponents of vibration families up to a few times the orbit's highest
harmonic. They are described by the model's own (free-interface) modes up to a cut-off
``omega_c``, plus the *residual flexibility* of the DOFs the laws act on (MacNeal 1971; Rubin
1975; Craig and Kurdila, *Fundamentals of Structural Dynamics*, 2006, sec. 18.4):

.. math::

    q = \Phi\,\eta + A\,(q_k - \Phi_k \eta), \qquad
    G = E_k^T K^{-1} E_k - \Phi_k \Lambda^{-1} \Phi_k^T, \qquad
    A = (K^{-1} E_k - \Phi \Lambda^{-1} \Phi_k^T)\,G^{-1},

with ``Phi`` the ``m`` mass-normalised modes below ``omega_c`` (eigenvalues ``Lambda``),
``E_k`` the kept DOFs (contacts, nonlinear springs) and ``Phi_k = E_k^T Phi``. In the
coordinates ``[eta; q_k]``

.. math::

    K_r = \begin{bmatrix} \Lambda + \Phi_k^T G^{-1} \Phi_k & -\Phi_k^T G^{-1} \\
                          -G^{-1} \Phi_k & G^{-1} \end{bmatrix}, \qquad
    M_r = \begin{bmatrix} I & 0 \\ 0 & 0 \end{bmatrix}, \qquad
    C_r = \begin{bmatrix} \Phi^T C \Phi & 0 \\ 0 & 0 \end{bmatrix}:

statically exact (``K_r`` is the exact condensation of ``K`` on ``q_k`` when ``eta`` is free), the
modes below the cut-off exact, the inertia of the modes above it neglected (MacNeal's residual
flexibility without residual mass). The kept DOFs carry no mass, so in Hill's problem their
unknowns, like the contact forces', are algebraic and are eliminated
(:func:`femodes.hbm.hill.hill_exponents`): the eigenproblem has ``(2H + 1) m`` unknowns, whatever
the number of contacts. The laws read the kept DOFs only, so the orbit enters through its
kept-DOF coefficients and contact forces, exactly.
"""

from __future__ import annotations

import logging
import math
import weakref
from typing import NamedTuple

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..solvers.checks import named_by
from ..eigen import normal_modes
from ..model import Attached, StructuralModel
from ..sparse_direct import factorize
from .system import HBMSystem

__all__ = ["FreeInterfaceReduction", "Estimate", "decides_verdict", "VERDICT_MARGIN", "VERDICT_MAX_ERROR"]

log = logging.getLogger(__name__)

#: Fewest modes computed at once (they are computed again, more of them, when a larger cut-off
#: needs it).
FIRST_MODES = 16


class _ModelCache:
    """Per model, what the reduction computed (modes, the static solves), kept while the model
    lives: :func:`femodes.stability` builds a new system for every point of a branch."""

    def __init__(self):
        self._items: dict[int, tuple] = {}

    def get(self, model):
        item = self._items.get(id(model))
        return item[1] if item is not None and item[0]() is model else None

    def put(self, model, value) -> None:
        key = id(model)
        if key not in self._items:
            weakref.finalize(model, self._items.pop, key, None)
        self._items[key] = (weakref.ref(model), value)


_CACHE = _ModelCache()


class _Basis:
    """A model's free-interface modes and static solves at its kept DOFs (shared by the systems
    of one model)."""

    def __init__(self, model: StructuralModel, kept: np.ndarray):
        self.model, self.kept = model, kept
        self.omega = np.zeros(0)
        self.Phi = np.zeros((model.n_dofs, 0))
        self.F: np.ndarray | None = None       # K^-1 E_k (n x n_kept)
        self.failed = False

    def static(self) -> np.ndarray | None:
        """``K^-1 E_k``; None when ``K`` is singular (a free structure has no residual flexibility)."""
        if self.F is None and not self.failed:
            K = self.model.K.tocsc()
            n = K.shape[0]
            E = np.zeros((n, self.kept.size))
            E[self.kept, np.arange(self.kept.size)] = 1.0
            try:
                F = factorize(K, positive_definite=True).solve(E)
            except RuntimeError:  # singular (SingularMatrixError is one)
                F = None
            if F is not None:
                # a numerically singular K (rigid-body motion left once the supports are counted)
                # passes the factorisation with a tiny pivot: the residual K F - E tells
                res = np.abs(K @ F - E).max()
                if not np.all(np.isfinite(F)) or res > 1e-6:
                    F = None
            if F is None:
                self.failed = True
                log.info("hill_exponents: K is singular (a free structure): no residual flexibility reduction")
            self.F = F
        return self.F

    def modes(self, n: int) -> bool:
        """Make at least ``n`` modes available (False when the model has no more)."""
        n_max = self.model.n_dofs - 1
        if self.Phi.shape[1] >= n:
            return True
        if n > n_max:
            return False
        m = min(n_max, max(n, FIRST_MODES, 2 * self.Phi.shape[1]))
        try:
            with named_by("hill_exponents"):  # hill_exponents is not an entry point yet
                w, Phi = normal_modes(self.model.K, self.model.M, m, check=False)
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as exc:
            log.info("hill_exponents: free-interface modes failed (%s)", exc)
            return False
        keep = np.isfinite(w)
        self.omega, self.Phi = w[keep], Phi[:, keep]
        return self.Phi.shape[1] >= n


#: Smallest eigenvalue of the residual flexibility, relative to its largest, below which the
#: reduction with that many modes is refused (round-off of a cancellation of ``K^-1`` by modes).
RESIDUAL_RCOND = 1e-9


class _NoReduction(ValueError):
    pass


class Estimate(NamedTuple):
    """The truncation error estimate of the last point that computed one
    (:attr:`FreeInterfaceReduction.last_estimate`; the cut-off loop of
    :func:`femodes.hbm.hill.hill_exponents`)."""

    modes: int
    error: float
    omega: float
    #: points since that took it instead of computing their own
    reuses: int
    #: kept above the target only because it decided that point's verdict (:func:`decides_verdict`)
    decided: bool


#: A reduction whose estimated error is above the target (``hill.REDUCTION_TOL``) is kept when
#: every multiplier lies farther than this many times the estimate from the unit circle
#: (:func:`decides_verdict`): its verdict cannot change as the reduction grows. The margin covers
#: an estimate that is optimistic by up to 10x: it assumes an error falling like ``omega_c^-2`` at
#: least, and a stiffness-proportional damping converges like ``omega_c^-1`` (the kept DOFs carry
#: no damping, ``C_r`` in the module docstring: a clamped bar of 1000 P1 elements, penalty stop,
#: beta = 0.01, H = 5, w = 1.633: true error 1.15e-3 at 11 modes where the estimate read 3.7e-4,
#: and 2.7e-5 at 394 modes, 12-19 s a solve, where it read 1.0e-5).
VERDICT_MARGIN = 10.0

#: ... and when the estimate is at most this (a coarser one is not trusted).
VERDICT_MAX_ERROR = 1e-2


def decides_verdict(multipliers: np.ndarray, err: float) -> bool:
    """Whether the verdict on ``multipliers`` holds whatever the reduction's error ``err`` (its
    estimate): every one at least :data:`VERDICT_MARGIN` times ``err`` away from the unit circle. A
    free orbit's trivial multipliers (+1) never are: backbones keep the target."""
    mu = np.abs(multipliers)
    return bool(err <= VERDICT_MAX_ERROR and mu.size and np.all(np.abs(mu - 1.0) > VERDICT_MARGIN * err))


class FreeInterfaceReduction:
    """The reductions of one system's model by number of modes (module docstring); cached on the
    system (``system._cache["hill_reduction"]``), its modes and static solves on the model.

    Attributes
    ----------
    alpha : float
        Cut-off (in units of ``(H + 1/2) w / nu``) that sufficed at the last point.
    n_kept : int
        DOFs the laws act on.
    """

    def __init__(self, system: HBMSystem, alpha: float):
        self.system = system
        model = system.model
        self.kept = np.array(sorted({a.dof for a in model.contacts + model.nonlinearities}), dtype=int)
        self.n_kept = self.kept.size
        basis = _CACHE.get(model)
        if basis is None or not np.array_equal(basis.kept, self.kept):
            basis = _Basis(model, self.kept)
            _CACHE.put(model, basis)
        self.basis = basis
        self.alpha = alpha
        # of the last point whose estimate was computed
        self.last_estimate: Estimate | None = None
        self.systems: dict[int, tuple[HBMSystem, np.ndarray]] = {}
        # the reduced problem must be much smaller than the whole (at most half its DOFs), and the
        # modes must leave the kept DOFs a residual flexibility of full rank (n - m >= n_kept)
        self.max_modes = max(0, min(model.n_dofs // 2, model.n_dofs - self.n_kept))

    @property
    def usable(self) -> bool:
        return self.n_kept > 0 and self.basis.static() is not None

    def modes_up_to(self, cutoff: float, cap: bool = False) -> int | None:
        """Number of free-interface modes at or below ``cutoff`` (at least 1); None when more
        than the largest reduction that can be built (``max_modes``, and a residual flexibility
        of full rank) would be needed, or, with ``cap``, that largest one."""
        if not self.usable:
            return None
        b = self.basis
        while True:
            w = b.omega
            if not (w.size and (w[-1] >= cutoff or w.size >= min(self.model_dofs - 1, self.max_modes))):
                want = w.size + 1 if not w.size else math.ceil(1.3 * w.size * cutoff / max(float(w[-1]), 1e-300))
                if b.modes(min(max(want, 2 * w.size), self.max_modes + 1)):
                    continue
                if b.omega.size == w.size:  # no more modes to be had: the largest reduction there is
                    if not w.size:
                        return None
                else:
                    continue
            w = b.omega
            want = max(1, int(np.count_nonzero(w <= cutoff)))
            if not cap and (want > self.max_modes or (w[-1] < cutoff and w.size >= self.max_modes)):
                return None
            m = min(want, self.max_modes, w.size)
            while m >= 1:
                try:
                    self.system_with(m)
                    return m
                except _NoReduction as exc:
                    log.debug("hill_exponents: no reduction with %d modes (%s)", m, exc)
                    if not cap:
                        return None
                    m -= 1
            return None

    @property
    def model_dofs(self) -> int:
        return self.system.model.n_dofs

    def system_with(self, n_modes: int) -> HBMSystem:
        if n_modes not in self.systems:
            self.systems[n_modes] = self._build(n_modes)
        return self.systems[n_modes][0]

    def _build(self, m: int) -> tuple[HBMSystem, np.ndarray]:
        model, b, k = self.system.model, self.basis, self.kept
        Phi, lam = b.Phi[:, :m], b.omega[:m] ** 2
        if np.any(lam <= 0):
            raise ValueError("hill_exponents: a rigid-body mode in a supported structure")
        Pk = Phi[k]                                     # n_kept x m
        F = b.static()
        G = F[k] - (Pk / lam) @ Pk.T                    # residual flexibility at the kept DOFs
        G = 0.5 * (G + G.T)
        g = np.linalg.eigvalsh(G)
        if g[0] <= RESIDUAL_RCOND * g[-1]:
            # the modes explain (nearly) all of the kept DOFs' flexibility: their residual is
            # round-off, and its inverse meaningless
            raise _NoReduction(f"residual flexibility of rank < {k.size} with {m} modes")
        Gi = sla.inv(G)
        Gi = 0.5 * (Gi + Gi.T)
        A = (F - (Phi / lam) @ Pk.T) @ Gi               # n x n_kept
        T = np.hstack([Phi - A @ Pk, A])                # q = T [eta; q_k]
        Kr = np.block([[np.diag(lam) + Pk.T @ Gi @ Pk, -Pk.T @ Gi], [-Gi @ Pk, Gi]])
        Kr = 0.5 * (Kr + Kr.T)
        nk = k.size
        Mr = sp.block_diag([sp.identity(m), sp.csr_matrix((nk, nk))], format="csr")
        CPhi = model.C @ Phi
        if model.C_lowrank is not None:
            lr = model.C_lowrank
            CPhi = CPhi + lr.U @ (lr.d[:, None] * (lr.U.T @ Phi))
        Cm = Phi.T @ CPhi
        Cm = 0.5 * (Cm + Cm.T)
        Cr = sp.block_diag([sp.csr_matrix(Cm), sp.csr_matrix((nk, nk))], format="csr")
        pos = {int(d): m + i for i, d in enumerate(k)}
        reduced = StructuralModel(
            M=Mr, K=sp.csr_matrix(Kr), C=Cr,
            contacts=tuple(Attached(a.item, pos[a.dof]) for a in model.contacts),
            nonlinearities=tuple(Attached(a.item, pos[a.dof]) for a in model.nonlinearities))
        s = self.system
        return HBMSystem(reduced, s.h, projection=s.projection), T

    def state(self, x: np.ndarray, rs: HBMSystem) -> np.ndarray:
        """The orbit's unknowns on a reduced system: kept-DOF coefficients and contact forces
        (all ``J0`` depends on); modal coordinates zero (they enter linearly)."""
        Q, P = self.system.split(x)
        Qr = np.zeros((Q.shape[0], rs.n))
        Qr[:, rs.n - self.n_kept:] = Q[:, self.kept]
        return rs.join(Qr, P)

    def expand(self, V: np.ndarray, n_modes: int) -> np.ndarray:
        """Eigenvectors of the reduced problem in the layout of the model's own."""
        rs, T = self.systems[n_modes]
        s = self.system
        nc, k = s.h.n_coef, V.shape[1]
        Qr = V[: rs.nq].reshape(nc, rs.n, k)
        Q = np.matmul(T[None], Qr).reshape(nc * s.n, k)
        return np.vstack([Q, V[rs.nq:]])
