r"""Application layer: one harmonic balance Newton step with its harmonic blocks on Dask workers
(a prototype of how a model that outgrows one machine runs; design in
``benchmarks/README_distributed.md``).

The Jacobian of a harmonic balance step with contacts is the block-diagonal linear dynamics plus a
dense coupling of all harmonics at the contact DOFs only:

.. math::

    J = \operatorname{blockdiag}(Z_0, Z_1, \dots, Z_H) + P^{\mathsf T} A P,\qquad
    Z_0 = K,\quad Z_k = \begin{bmatrix} K - k^2\omega^2 M & k\omega C \\ -k\omega C & K - k^2\omega^2 M
    \end{bmatrix}

in femodes' real layout ``[c0; c1, s1; ...]`` (``Z_k`` acts on the cosine and sine coefficients of
harmonic ``k``), ``P`` picks the contact DOFs' coefficients (``m = n_c (2H + 1)`` of them) and
``A`` (``m x m``) is the linearised contact law after the projection. By the Woodbury identity

.. math::

    x = Z^{-1} r - Z^{-1} P^{\mathsf T} y, \qquad (I + A\,P Z^{-1} P^{\mathsf T})\,y = A\,P Z^{-1} r,

so each worker holds one harmonic's block and its factorisation for the whole step (a Dask
actor: the factor never moves) and the client gathers only ``P Z_k^{-1} P^T`` (``2 n_c x 2 n_c``)
and ``P Z_k^{-1} r_k`` per harmonic, solves the small dense ``m x m`` system, and sends each
worker its ``y_k`` back; the workers return their ``x_k``. Data moved per step: the blocks' right
hand sides and solutions (``n (2H + 1)`` numbers) and ``O(n_c^2 H)`` for the coupling, against the
``O(n^{4/3})`` fill of each 3-D factorisation that stays where it was made.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..dynamic_stiffness import DynamicStiffness
from ..sparse_direct import factorize

__all__ = ["HarmonicBlock", "harmonic_block", "distributed_newton_step", "assembled_jacobian"]


def harmonic_block(K, M, C, omega: float, k: int) -> sp.csc_matrix:
    """``Z_k`` of the module docstring (``K`` for ``k = 0``; ``2n x 2n`` on ``[c_k; s_k]``):
    the real form of the dynamic stiffness at ``k w`` (:meth:`DynamicStiffness.real_block`)."""
    K, M, C = (sp.csr_matrix(A) for A in (K, M, C))
    if k == 0:
        return K.tocsc()
    return DynamicStiffness(K, M, C).real_block(k * omega)


class HarmonicBlock:
    """One harmonic's block on a worker (a Dask actor): it factorises ``Z_k`` once and answers
    the two requests of a Newton step."""

    def __init__(self, K, M, C, omega: float, k: int, contact_dofs):
        Z = harmonic_block(K, M, C, omega, k)
        self.n = K.shape[0]
        self.k = k
        self.lu = factorize(Z)  # the sparse direct back-end in use on this worker
        self.size = Z.shape[0]
        c = np.asarray(contact_dofs, dtype=int)
        self.rows = c if k == 0 else np.concatenate([c, c + self.n])  # P_k: the contact coefficients
        self.Zr = None

    def reduce(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(P Z^-1 P^T, P Z^-1 r)`` for the right-hand side ``r`` of this harmonic."""
        self.Zr = self.lu.solve(np.asarray(r, dtype=float))
        E = np.zeros((self.size, self.rows.size))
        E[self.rows, np.arange(self.rows.size)] = 1.0
        self.ZP = self.lu.solve(E)
        return self.ZP[self.rows], self.Zr[self.rows]

    def expand(self, y: np.ndarray) -> np.ndarray:
        """``x_k = Z^-1 r - Z^-1 P^T y_k``."""
        return self.Zr - self.ZP @ np.asarray(y, dtype=float)


def _layout(n: int, H: int, contact_dofs) -> tuple[list[slice], np.ndarray]:
    """Slices of each harmonic in the global unknowns and the global indices of ``P``."""
    sl, start = [], 0
    for k in range(H + 1):
        size = n if k == 0 else 2 * n
        sl.append(slice(start, start + size))
        start += size
    c = np.asarray(contact_dofs, dtype=int)
    P = np.concatenate([c] + [np.concatenate([c, c + n]) + sl[k].start for k in range(1, H + 1)])
    return sl, P


def assembled_jacobian(K, M, C, omega: float, H: int, contact_dofs, A) -> sp.csc_matrix:
    """The whole ``J`` of the module docstring (the serial reference)."""
    n = K.shape[0]
    sl, P = _layout(n, H, contact_dofs)
    J = sp.block_diag([harmonic_block(K, M, C, omega, k) for k in range(H + 1)], format="lil")
    A = np.asarray(A, dtype=float)
    for a, i in enumerate(P):
        for b, j in enumerate(P):
            if A[a, b]:
                J[i, j] += A[a, b]
    return J.tocsc()


def distributed_newton_step(client, K, M, C, omega: float, H: int, contact_dofs, A, r) -> np.ndarray:
    """Solve ``J x = r`` (module docstring) with one Dask actor per harmonic block.

    Parameters
    ----------
    client : distributed.Client
    K, M, C : sparse matrices (n x n)
    omega : float
    H : int
        Harmonics (blocks ``k = 0 .. H``: ``H + 1`` actors).
    contact_dofs : sequence of int
        The DOFs the contact law couples (``n_c``).
    A : ndarray (m, m)
        The linearised contact law on the contact coefficients, ``m = n_c (2H + 1)``, in the
        order ``[c0; c1, s1; ...]`` per harmonic.
    r : ndarray (n (2H + 1),)

    Returns
    -------
    ndarray
        ``x`` in femodes' layout.
    """
    n = K.shape[0]
    sl, P = _layout(n, H, contact_dofs)
    A = np.asarray(A, dtype=float)
    if A.shape != (P.size, P.size):
        raise ValueError(f"distributed_newton_step: A must be {P.size} x {P.size} (n_c (2H + 1)), got {A.shape}")
    r = np.asarray(r, dtype=float)
    if r.shape != (sl[-1].stop,):
        raise ValueError(f"distributed_newton_step: r must have {sl[-1].stop} entries (n (2H + 1)), got {r.shape}")
    # the matrices go to every worker once (not once per block), the blocks are made where they stay
    Kf, Mf, Cf = client.scatter([sp.csr_matrix(K), sp.csr_matrix(M), sp.csr_matrix(C)], broadcast=True)
    futures = [client.submit(HarmonicBlock, Kf, Mf, Cf, omega, k, contact_dofs, actor=True, pure=False)
               for k in range(H + 1)]
    actors = [f.result() for f in futures]
    parts = [a.reduce(r[sl[k]]) for k, a in enumerate(actors)]          # run on the workers
    parts = [p.result() for p in parts]
    # gather: block-diagonal P Z^-1 P^T and P Z^-1 r on the contact coefficients
    G = np.zeros((P.size, P.size))
    g = np.zeros(P.size)
    pos = 0
    bounds = []
    for ZPP, Zr in parts:
        m = Zr.size
        G[pos:pos + m, pos:pos + m] = ZPP
        g[pos:pos + m] = Zr
        bounds.append(slice(pos, pos + m))
        pos += m
    y = np.linalg.solve(np.eye(P.size) + A @ G, A @ g)
    xs = [a.expand(y[b]) for a, b in zip(actors, bounds)]               # scatter y_k, gather x_k
    return np.concatenate([x.result() for x in xs])
