"""Models layer (leaf): the generalized symmetric eigenproblem ``K phi = lam M phi``.

Shared by linear modes (:mod:`femodes.linear`), modal damping (:mod:`femodes.model`) and the
fixed-interface modes of Craig-Bampton (:mod:`femodes.reduction`); imports only the other leaf,
:mod:`femodes.sparse_direct`, whose back-end factorises the shift-invert operator.
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .solvers.checks import entry_name
from .sparse_direct import factorize

__all__ = ["DENSE_LIMIT", "krylov_start", "IllConditionedWarning", "check_conditioning", "eigenvalue_floor", "mass_normalize", "generalized_eigh",
           "normal_modes"]

log = logging.getLogger(__name__)

#: Below this size a dense symmetric eigensolver is used (exact, all modes, no shift needed).
DENSE_LIMIT = 600


class IllConditionedWarning(UserWarning):
    """Stiffness matrix so ill-conditioned that low eigenvalues lose most of their digits."""


#: Seed of the Krylov start vectors (:func:`krylov_start`).
KRYLOV_SEED = 20260101


def krylov_start(n: int, complex_: bool = False) -> np.ndarray:
    """The start vector of an Arnoldi or Lanczos eigen-solve with ``n`` unknowns: pseudo-random
    (no structure it could be orthogonal to) but the same in every run. scipy draws ARPACK's start
    from fresh OS entropy unless given one (1.15+), so the same model gave eigenvectors that
    differed at round-off from run to run, and a conservative backbone's bifurcation list with
    them (7 or 9 on the user blade at H = 10)."""
    rng = np.random.default_rng(KRYLOV_SEED)
    v = rng.uniform(-1.0, 1.0, n)
    return v + 1j * rng.uniform(-1.0, 1.0, n) if complex_ else v


#: A negative eigenvalue below ``-NEGATIVE_FLOORS * eigenvalue_floor`` (about -2e-8 of the stiffest
#: DOF's K_ii / M_ii) is no round-off of a rigid-body mode: K or M is indefinite.
NEGATIVE_FLOORS = 1e5


def eigenvalue_floor(K, M) -> float:
    """Round-off floor of the eigenvalues of ``(K, M)``: ``1e3 eps max(K_ii / M_ii)`` over the DOFs
    with mass (``max |K_ii|`` if none has any). The largest diagonal ratio bounds the largest
    eigenvalue from below (Rayleigh quotients of unit vectors), so an eigenvalue under this floor
    carries no digits: a rigid-body mode, or a singular ``K`` passing a factorisation by round-off.
    ``K``, ``M``: sparse or dense."""
    Kd, Md = np.asarray(K.diagonal(), dtype=float), np.asarray(M.diagonal(), dtype=float)
    heavy = Md > 0
    scale = float(np.max(Kd[heavy] / Md[heavy])) if heavy.any() else float(np.max(np.abs(Kd), initial=0.0))
    return 1e3 * np.finfo(float).eps * scale


def check_conditioning(K: sp.spmatrix, solve, n: int, *, warn: bool = True) -> float:
    """Estimate cond_1(K) = ||K||_1 ||K^-1||_1 (Hager/Higham estimator) and warn if hopeless.

    ``solve`` applies ``K^-1`` (from an existing factorization). Low eigenvalues computed in
    double precision carry a relative error of about ``cond * eps``; we warn when that exceeds
    1e-2 (cond > 4.5e13; the estimate is pessimistic: at cond ~ 2e12 a 1e3-DOF beam still has
    w1 to 5e-7), which for Euler-Bernoulli beams (cond ~ (N/2)^4) happens near 1e4 DOFs, where
    about 3 digits are lost, and makes 1e5-DOF beams meaningless (benchmarks/README.md).
    """
    try:
        # the estimator applies K^-1 to blocks of t = 2 columns: one block solve (BLAS 3 in the
        # supernodal back-ends) instead of one solve per column
        Kinv = spla.LinearOperator((n, n), matvec=solve, rmatvec=solve, matmat=solve, rmatmat=solve, dtype=float)
        est = spla.onenormest(Kinv) * _one_norm(K)
    except Exception as exc:  # pragma: no cover - the estimate is advisory only
        log.debug("condition estimate failed: %s", exc)
        return float("nan")
    if warn and est * np.finfo(float).eps > 1e-2:
        warnings.warn(
            f"{entry_name()}: the stiffness matrix is ill-conditioned (cond_1(K) ~ {est:.1e}, so low frequencies "
            f"carry relative errors up to ~{est * np.finfo(float).eps:.0e}). Euler-Bernoulli beams reach this "
            "near 1e4-1e5 DOFs; use a coarser mesh, Craig-Bampton on a coarser model, or bars for scaling studies.",
            IllConditionedWarning,
            stacklevel=3,
        )
    return float(est)


def _one_norm(A) -> float:
    """``||A||_1`` (largest column sum of ``|A|``) from the stored entries, without the copy of
    ``|A|`` and the product that ``scipy.sparse.linalg.norm`` forms (0.37 of 0.57 s of the
    condition estimate of a 7.9e4-DOF blade's ``K_II``)."""
    if not sp.issparse(A) or A.format not in ("csr", "csc"):
        return float(spla.norm(sp.csc_matrix(A), 1))
    a = np.abs(A.data)
    sums: np.ndarray
    if A.format == "csr":
        sums = np.bincount(A.indices, weights=a, minlength=A.shape[1])
    else:  # the columns are the compressed axis: sums over each column's slice
        # reduceat at each column's start (clipped for empty trailing columns, whose sums are
        # then zeroed): no padded copy of the entries
        if not a.size:
            return 0.0
        sums = np.add.reduceat(a, np.minimum(A.indptr[:-1], a.size - 1))
        sums[np.diff(A.indptr) == 0] = 0.0
    return float(sums.max(initial=0.0))


def mass_normalize(shapes: np.ndarray, M) -> np.ndarray:
    """Columns scaled to ``phi^T M phi = 1``, sign fixed so that the largest entry is positive."""
    mm = np.einsum("ij,ij->j", shapes, M @ shapes)
    shapes = shapes / np.sqrt(mm)
    idx = np.argmax(np.abs(shapes), axis=0)
    signs = np.sign(shapes[idx, np.arange(shapes.shape[1])])
    signs[signs == 0] = 1.0
    return shapes * signs


def generalized_eigh(K: sp.spmatrix, M: sp.spmatrix, n: int, *, sigma: float | None = None,
                     factor=None, check: bool = True):
    """Lowest ``n`` eigenpairs of ``K phi = lam M phi`` (symmetric, M semidefinite), ascending.

    Dense LAPACK below :data:`DENSE_LIMIT` DOFs; otherwise ARPACK in shift-invert mode around
    ``sigma`` (default: 0, or a small negative shift if ``K`` is singular, so that rigid-body
    modes of free structures are found). ``factor``: an existing factorisation of
    ``K - sigma M`` (an object with ``solve``) to reuse. ``check`` estimates cond(K) and warns
    (:class:`IllConditionedWarning`) when the low eigenvalues lose most of their digits.
    Warnings, log lines and errors start with the public function running
    (:func:`~femodes.solvers.checks.entry_name`).
    """
    N = K.shape[0]
    if N <= DENSE_LIMIT or n >= N - 1:
        Kd, Md = K.toarray(), M.toarray()
        if np.any(np.diag(Md) <= 0):
            # Singular mass (e.g. redistributed contact mass): eliminate massless DOFs statically.
            lam, vec = sla.eig(Kd, Md)
            ok = np.isfinite(lam)
            lam, vec = lam[ok].real, vec[:, ok].real
            order = np.argsort(lam)[:n]
            lam, vec = lam[order], vec[:, order]
        else:
            try:
                # Inverse problem M phi = mu K phi (mu = 1/lambda) when K is definite: the wanted low
                # modes are then the dominant ones and get relative accuracy ~eps instead of
                # ~eps * lambda_max / lambda_1 (1e-7..1e-6 for fine Hermite beams).
                mu, vec = sla.eigh(Md, Kd, subset_by_index=[N - n, N - 1])
                # A singular K (free structure) may pass Cholesky by round-off (tiny positive
                # pivots; whether it does flips with the assembly's rounding): then 1/mu_max sits at
                # the round-off floor of K's eigenvalues, eps * lambda_max, and the other mu carry
                # absolute errors ~eps * mu_max, i.e. no digits. max K_ii / M_ii <= lambda_max
                # (Rayleigh quotients of unit vectors), so this floor test errs towards the inverse
                # problem only for cond(K) > 1 / (1e3 eps) = 4.5e12.
                if np.all(mu > 0) and 1.0 / mu[-1] > eigenvalue_floor(Kd, Md):
                    return 1.0 / mu[::-1], vec[:, ::-1]
            except (np.linalg.LinAlgError, ValueError):
                pass  # K singular (free structure): direct problem below
            lam, vec = sla.eigh(Kd, Md, subset_by_index=[0, n - 1])
        return lam, vec
    lu = factor
    if sigma is None and lu is None:
        # Shift-invert at 0 suits supported structures (near-rigid modes of free ones become the
        # largest Ritz values and converge first). Only if K is exactly singular do we shift below 0.
        sigma = 0.0
        try:
            lu = factorize(K, positive_definite=True)
        except RuntimeError:
            d = K.diagonal() / np.maximum(M.diagonal(), 1e-300)
            d = d[np.isfinite(d) & (d > 0)]
            sigma = -1e-3 * float(d.min()) if d.size else -1.0
            log.info("%s: K is singular, shift-invert with sigma=%g", entry_name(), sigma)
    if sigma is None:
        sigma = 0.0
    if lu is None:
        # K - sigma M is positive definite for sigma <= 0 (CHOLMOD where installed), indefinite above
        lu = factorize(K - sigma * M, positive_definite=sigma <= 0)
    if check and sigma <= 0:
        check_conditioning(K, lu.solve, N)
    op = spla.LinearOperator(K.shape, matvec=lu.solve, dtype=float)
    try:
        lam, vec = spla.eigsh(K, k=n, M=M, sigma=sigma, which="LM", OPinv=op, tol=1e-12, maxiter=max(500, 50 * n),
                              v0=krylov_start(N))
    except spla.ArpackNoConvergence as exc:
        raise RuntimeError(
            f"{entry_name()}: the Lanczos eigensolver did not converge for {n} modes of a {N}-DOF model "
            "(ill-conditioned K, or pass sigma= close to the frequencies of interest squared)"
        ) from exc
    order = np.argsort(lam)
    return lam[order], vec[:, order]


def normal_modes(K: sp.spmatrix, M: sp.spmatrix, n: int, *, sigma: float | None = None, factor=None,
                 check: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Lowest ``n`` angular frequencies (rad/s) and mass-normalised shapes of ``(K, M)``
    (:func:`generalized_eigh`, whose arguments these are).

    Rigid-body eigenvalues come out as +-(round-off): negative ones are clipped to zero frequency,
    small positive ones are kept (a scale-based threshold would also zero genuine low
    frequencies of fine meshes, whose lambda_max grows like h^-4).
    """
    lam, vec = generalized_eigh(K, M, n, sigma=sigma, factor=factor, check=check)
    floor = eigenvalue_floor(K, M)
    if np.any(lam < -NEGATIVE_FLOORS * floor):
        # no round-off: K or M is indefinite (a raw model's are checked fully up to 400 DOFs only)
        raise ValueError(f"{entry_name() or 'linear_modes'}: the model has {int(np.sum(lam < -NEGATIVE_FLOORS * floor))} "
                         f"eigenvalue(s) w^2 < 0, the lowest {lam.min():.6g} (its stiffest DOF: K_ii / M_ii = "
                         f"{floor / (1e3 * np.finfo(float).eps):.3g}): K is not positive semidefinite, or M not positive "
                         "definite on the DOFs with mass; check how K and M were built (signs, a material, a spring)")
    mm = np.einsum("ij,ij->j", vec, M @ vec)
    if np.any(mm <= 0):
        raise ValueError(f"{entry_name() or 'linear_modes'}: a mode has zero or negative modal mass (phi^T M phi = "
                         f"{mm.min():.6g}): M is not positive semidefinite; check how it was built")
    if np.any(lam < 0):
        log.info("%s: eigenvalues %s < 0 (round-off of rigid-body modes) set to zero frequency", entry_name(),
                 lam[lam < 0])
    return np.sqrt(np.maximum(lam, 0.0)), mass_normalize(vec, M)

