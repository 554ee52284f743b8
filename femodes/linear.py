"""Models layer: linear modes ``(K - w^2 M) phi = 0`` and linear forced response.

Frequencies are angular (rad/s) everywhere. Shapes are mass-normalised: ``Phi^T M Phi = I``.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .model import StructuralModel

__all__ = ["LinearModes", "LinearResponse", "linear_modes", "linear_response", "IllConditionedWarning", "check_conditioning"]

log = logging.getLogger(__name__)

#: Below this size a dense symmetric eigensolver is used (exact, all modes, no shift needed).
DENSE_LIMIT = 600


class IllConditionedWarning(UserWarning):
    """Stiffness matrix so ill-conditioned that low eigenvalues lose most of their digits."""


@dataclass(frozen=True, eq=False)
class LinearModes:
    """Linear normal modes.

    Attributes
    ----------
    omega : ndarray (n,)
        Angular frequencies in rad/s, ascending.
    shapes : ndarray (n_dofs, n)
        Mass-normalised mode shapes (columns), sign fixed so that the largest entry is positive.
    """

    omega: np.ndarray
    shapes: np.ndarray

    @property
    def frequency_hz(self) -> np.ndarray:
        return self.omega / (2 * np.pi)

    def __len__(self) -> int:
        return self.omega.size


def _check_n(n, n_max: int, owner: str) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"{owner}: n must be a positive integer, got {n!r}")
    if n > n_max:
        raise ValueError(f"{owner}: n={n} modes requested but the model has only {n_max} DOFs")
    return int(n)


def check_conditioning(K: sp.spmatrix, solve, n: int, owner: str, *, warn: bool = True) -> float:
    """Estimate cond_1(K) = ||K||_1 ||K^-1||_1 (Hager/Higham estimator) and warn if hopeless.

    ``solve`` applies ``K^-1`` (from an existing factorization). Low eigenvalues computed in
    double precision carry a relative error of about ``cond * eps``; we warn when that exceeds
    1e-2 (cond > 4.5e13; the estimate is pessimistic: at cond ~ 2e12 a 1e3-DOF beam still has
    w1 to 5e-7), which for Euler-Bernoulli beams (cond ~ (N/2)^4) happens near 1e4 DOFs, where
    about 3 digits are lost, and makes 1e5-DOF beams meaningless (benchmarks/README.md).
    """
    try:
        Kinv = spla.LinearOperator((n, n), matvec=solve, rmatvec=solve, dtype=float)
        est = spla.onenormest(Kinv) * spla.norm(K, 1)
    except Exception as exc:  # pragma: no cover - the estimate is advisory only
        log.debug("condition estimate failed: %s", exc)
        return float("nan")
    if warn and est * np.finfo(float).eps > 1e-2:
        warnings.warn(
            f"{owner}: the stiffness matrix is ill-conditioned (cond_1(K) ~ {est:.1e}, so low frequencies "
            f"carry relative errors up to ~{est * np.finfo(float).eps:.0e}). Euler-Bernoulli beams reach this "
            "near 1e4-1e5 DOFs; use a coarser mesh, Craig-Bampton on a coarser model, or bars for scaling studies.",
            IllConditionedWarning,
            stacklevel=3,
        )
    return float(est)


def _normalize(shapes: np.ndarray, M) -> np.ndarray:
    mm = np.einsum("ij,ij->j", shapes, M @ shapes)
    shapes = shapes / np.sqrt(mm)
    idx = np.argmax(np.abs(shapes), axis=0)
    signs = np.sign(shapes[idx, np.arange(shapes.shape[1])])
    signs[signs == 0] = 1.0
    return shapes * signs


def generalized_eigh(K: sp.spmatrix, M: sp.spmatrix, n: int, owner: str, *, sigma: float | None = None, check: bool = True):
    """Lowest ``n`` eigenpairs of ``K phi = lam M phi`` (symmetric, M semidefinite).

    Dense LAPACK below :data:`DENSE_LIMIT` DOFs; otherwise ARPACK in shift-invert mode around
    ``sigma`` (default: a small negative shift so that rigid-body modes of free structures are
    found and K need not be invertible).
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
                if np.all(mu > 0):
                    return 1.0 / mu[::-1], vec[:, ::-1]
            except (np.linalg.LinAlgError, ValueError):
                pass  # K singular (free structure): direct problem below
            lam, vec = sla.eigh(Kd, Md, subset_by_index=[0, n - 1])
        return lam, vec
    lu = None
    if sigma is None:
        # Shift-invert at 0 suits supported structures (near-rigid modes of free ones become the
        # largest Ritz values and converge first). Only if K is exactly singular do we shift below 0.
        sigma = 0.0
        try:
            lu = spla.splu(K.tocsc())
        except RuntimeError:
            d = K.diagonal() / np.maximum(M.diagonal(), 1e-300)
            d = d[np.isfinite(d) & (d > 0)]
            sigma = -1e-3 * float(d.min()) if d.size else -1.0
            log.info("%s: K is singular, shift-invert with sigma=%g", owner, sigma)
    if lu is None:
        lu = spla.splu((K - sigma * M).tocsc())
    if check and sigma <= 0:
        check_conditioning(K, lu.solve, N, owner)
    op = spla.LinearOperator(K.shape, matvec=lu.solve, dtype=float)
    try:
        lam, vec = spla.eigsh(K, k=n, M=M, sigma=sigma, which="LM", OPinv=op, tol=1e-12, maxiter=max(500, 50 * n))
    except spla.ArpackNoConvergence as exc:
        raise RuntimeError(
            f"{owner}: the Lanczos eigensolver did not converge for {n} modes of a {N}-DOF model "
            "(ill-conditioned K, or pass sigma= close to the frequencies of interest squared)"
        ) from exc
    order = np.argsort(lam)
    return lam[order], vec[:, order]


def linear_modes(model: StructuralModel, n: int = 6, *, sigma: float | None = None) -> LinearModes:
    """Lowest ``n`` linear modes of ``model``: ``(K - w^2 M) phi = 0``.

    Parameters
    ----------
    model : StructuralModel or ReducedModel
    n : int
        Number of modes.
    sigma : float, optional
        Shift (in ``w^2`` units) for the shift-invert Lanczos solver of large models.

    Returns
    -------
    LinearModes
        ``omega`` in rad/s (rigid-body modes give 0) and mass-normalised ``shapes``.

    Warns
    -----
    IllConditionedWarning
        If cond(K) makes the low frequencies unreliable (very fine beam meshes).
    """
    if not isinstance(model, StructuralModel):
        raise TypeError(f"linear_modes: model must be a StructuralModel, got {type(model).__name__}")
    n = _check_n(n, model.n_dofs, "linear_modes")
    if sigma is not None:
        if isinstance(sigma, (bool, np.bool_)) or not isinstance(sigma, (int, float, np.integer, np.floating)):
            raise TypeError(f"linear_modes: sigma must be a real shift (in w^2 units) or None, got {sigma!r}")
        if not np.isfinite(sigma):
            raise ValueError(f"linear_modes: sigma must be finite, got {sigma!r}")
        sigma = float(sigma)
    lam, vec = generalized_eigh(model.K, model.M, n, "linear_modes", sigma=sigma)
    # Rigid-body eigenvalues come out as +-(round-off); negative ones are clipped to zero, small
    # positive ones are kept (a scale-based threshold would also zero genuine low frequencies of
    # fine meshes, whose lambda_max grows like h^-4).
    if np.any(lam < 0):
        log.info("linear_modes: eigenvalues %s < 0 (round-off of rigid-body modes) set to zero frequency", lam[lam < 0])
    omega = np.sqrt(np.maximum(lam, 0.0))
    return LinearModes(omega=omega, shapes=_normalize(vec, model.M))


@dataclass(frozen=True, eq=False)
class LinearResponse:
    """Linear steady-state response ``q(t) = Re(Q e^{i w t})`` to the model's forcing.

    Attributes
    ----------
    omega : ndarray (n_omega,)
    amplitude : ndarray complex (n_omega, n_dofs)
        Complex amplitudes ``Q = (K - w^2 M + i w C)^-1 F`` (primary harmonic forcing).
    """

    omega: np.ndarray
    amplitude: np.ndarray

    def magnitude(self, dof: int | None = None) -> np.ndarray:
        """``|Q|`` (all DOFs, or one)."""
        a = np.abs(self.amplitude)
        return a if dof is None else a[:, dof]


def linear_response(model: StructuralModel, omega, *, force=None) -> LinearResponse:
    """Linear forced response ``(K - w^2 M + i w C) Q = F`` at the frequencies ``omega``.

    Parameters
    ----------
    model : StructuralModel
        Its :class:`HarmonicForce` declarations with ``harmonic=1`` give ``F`` unless ``force``
        is passed.
    omega : float or array_like
        Forcing frequencies in rad/s (finite, >= 0).
    force : array_like, optional
        Complex or real force amplitude vector (n_dofs,), overrides the declarations.
    """
    if not isinstance(model, StructuralModel):
        raise TypeError(f"linear_response: model must be a StructuralModel, got {type(model).__name__}")
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    if w.ndim != 1 or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"linear_response: omega must be finite non-negative frequencies (rad/s), got {omega!r}")
    if force is None:
        fv = model.force_vectors()
        if 1 not in fv:
            raise ValueError("linear_response: the model has no forcing at harmonic 1; use model.with_forcing(HarmonicForce(...)) or pass force=")
        F = fv[1]
    else:
        F = np.asarray(force, dtype=complex)
        if F.shape != (model.n_dofs,) or not np.all(np.isfinite(F)):
            raise ValueError(f"linear_response: force must be a finite vector of length {model.n_dofs}, got shape {F.shape}")
    out = np.empty((w.size, model.n_dofs), dtype=complex)
    K, M, C = model.K.tocsc(), model.M.tocsc(), model.C.tocsc()
    for i, wi in enumerate(w):
        Z = (K - wi**2 * M + 1j * wi * C).tocsc()
        try:
            out[i] = spla.splu(Z).solve(F)
        except RuntimeError as exc:
            raise ValueError(
                f"linear_response: the dynamic stiffness is singular at omega={wi:g} (undamped resonance); "
                "add damping or avoid that frequency"
            ) from exc
    return LinearResponse(omega=w, amplitude=out)
