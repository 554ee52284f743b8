"""Models layer: linear modes ``(K - w^2 M) phi = 0`` and linear forced response.

Frequencies are angular (rad/s) everywhere. Shapes are mass-normalised: ``Phi^T M Phi = I``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .dynamic_stiffness import DynamicStiffness
from .eigen import IllConditionedWarning, eigenvalue_floor, normal_modes
from .model import StructuralModel, low_rank_solver
from .sparse_direct import factorize
from .solvers.checks import InputTypeError, InputValueError, check_int, entry_point

__all__ = ["LinearModes", "LinearResponse", "linear_modes", "linear_response", "grazing_energy", "IllConditionedWarning"]

log = logging.getLogger(__name__)


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


def _check_n(n, n_max: int) -> int:
    n = check_int("n", n, 1)
    if n > n_max:
        raise InputValueError(f"n={n} modes requested but the model has only {n_max} DOFs")
    return int(n)




@entry_point("grazing_energy")
def grazing_energy(model: StructuralModel, mode: int = 1, *, modes: LinearModes | None = None) -> float:
    """Energy at which linear mode ``mode`` first touches a contact: ``E_g = w^2 a_g^2 / 2``.

    With the mass-normalised shape ``phi``, the modal amplitude ``a`` moves contact ``c`` (gap
    ``g_c`` along its DOF) by ``a |phi_c|``; the first contact reached sets
    ``a_g = min_c g_c / |phi_c|``. Backbones of a structure with contacts are naturally given in
    multiples of it: ``nonlinear_mode(model, energy=(0.5 * E_g, 25 * E_g), harmonics=H)``. For a clamped bar
    with a stop at the tip (``E = rho = A = L = 1``) it tends to ``pi^2 g^2 / 16``. ``modes``: the
    model's linear modes if already computed (at least ``mode`` of them).
    """
    if not isinstance(model, StructuralModel):
        raise InputTypeError(f"model must be a StructuralModel (or ReducedModel), got {type(model).__name__}")
    mode = check_int("mode", mode, 1)
    gapped = [(c.dof, float(c.item.gap)) for c in model.contacts
              if isinstance(getattr(c.item, "gap", None), (int, float, np.floating)) and float(c.item.gap) > 0.0]
    if not gapped:
        raise InputValueError("the model has no contact with a positive gap; declare one with "
                         "model.with_contact(fm.UnilateralContact(at=..., gap=...))")
    if modes is None or modes.omega.size < mode:
        modes = linear_modes(model, n=mode)
    w, phi = float(modes.omega[mode - 1]), modes.shapes[:, mode - 1]
    amp = [g / abs(phi[d]) for d, g in gapped if _moves(phi, d)]
    if not amp:
        more = modes if modes.omega.size >= min(mode + 5, model.n_dofs) else linear_modes(model, n=min(mode + 5, model.n_dofs))
        loading = [k + 1 for k in range(more.omega.size) if any(_moves(more.shapes[:, k], d) for d, _ in gapped)]
        hint = f" (of the first {more.omega.size}, modes {loading} move it)" if loading else ""
        raise InputValueError(f"linear mode {mode} does not move any contact DOF (a node of the mode shape sits on "
                              f"every contact, e.g. an antisymmetric mode of a symmetric structure): it never "
                              f"touches the stop; choose another mode{hint}")
    return 0.5 * w * w * min(amp) ** 2


#: A mode shape moves a DOF when its component there exceeds this fraction of its largest: below,
#: the component is the eigen-solver's round-off (measured 2.7e-9 and 1.1e-11 at the crown of a
#: symmetric arch in its antisymmetric mode, P1 and P2 quadrilaterals), and its grazing energy
#: (1e23 J against 15 J for the next mode) no amplitude a backbone could reach.
MOVES = float(np.sqrt(np.finfo(float).eps))


def _moves(phi: np.ndarray, dof: int) -> bool:
    return bool(abs(phi[dof]) > MOVES * float(np.max(np.abs(phi))))


def rigid_body_modes(model: StructuralModel, omega: np.ndarray) -> np.ndarray:
    """Which of the frequencies ``omega`` (rad/s) of ``model`` are rigid-body modes: ``w^2`` at the
    round-off floor of ``K``'s eigenvalues (:func:`femodes.eigen.eigenvalue_floor`). A model
    without supports, or with a mesh part that is not connected to them (unmerged duplicate
    nodes), has such modes."""
    return np.asarray(omega, dtype=float) ** 2 <= eigenvalue_floor(model.K, model.M)


def rigid_body_message(count: int) -> str:
    """What is wrong with a model that has ``count`` rigid-body modes, and the fix (no name: the
    caller puts its own in front)."""
    return (f"the model has {count} rigid-body mode(s) (zero frequency): it is not supported, or a part "
            "of its mesh is not connected to the supports; give supports (clamped=... in fm.solid, fm.bar, "
            "fm.beam) or merge the mesh's duplicate nodes")




@entry_point("linear_modes")
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
        raise InputTypeError(f"model must be a StructuralModel, got {type(model).__name__}")
    n = _check_n(n, model.n_dofs)
    if sigma is not None:
        if isinstance(sigma, (bool, np.bool_)) or not isinstance(sigma, (int, float, np.integer, np.floating)):
            raise InputTypeError(f"sigma must be a real shift (in w^2 units) or None, got {sigma!r}")
        if not np.isfinite(sigma):
            raise InputValueError(f"sigma must be finite, got {sigma!r}")
        sigma = float(sigma)
    omega, shapes = normal_modes(model.K, model.M, n, sigma=sigma)
    if omega.size < n:  # massless DOFs have no natural frequency: fewer modes than asked, said
        log.warning("linear_modes: %d modes asked, the model has %d: %d of its %d DOFs are massless (no inertia, no "
                    "natural frequency)", n, omega.size, model.n_dofs - omega.size, model.n_dofs)
    return LinearModes(omega=omega, shapes=shapes)


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


def _solve_lowrank(Z, lr, g: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(Z + U diag(g) U^T) q = F`` (``g = i w d``) by Woodbury on the LU of the sparse part ``Z``;
    if ``Z`` alone is singular (an undamped resonance of the sparse part that the modal damping
    damps), the sparse augmented system ``[[Z, U diag(g)], [U^T, -I]] [q; y] = [F; 0]``."""
    try:
        lu = factorize(Z)
    except RuntimeError:
        m = lr.rank
        A = sp.bmat([[Z, sp.csr_matrix(lr.U * g)], [sp.csr_matrix(lr.U.T), -sp.identity(m)]], format="csc")
        return factorize(A, symmetric=False).solve(
            np.concatenate([np.asarray(F, dtype=complex), np.zeros(m, dtype=complex)]))[: Z.shape[0]]
    return low_rank_solver(lu.solve, lr.U, g, lr.U, matvec=lambda x: Z @ x)(F)


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
    lr = model.C_lowrank  # modal damping U diag(d) U^T: Woodbury on the sparse part (StructuralModel)
    stiffness = DynamicStiffness(model.K.tocsc(), model.M.tocsc(), model.C.tocsc(), lr)
    for i, wi in enumerate(w):
        Z = stiffness.harmonic(wi).tocsc()
        try:
            if lr is None:
                out[i] = factorize(Z).solve(F)
            else:
                out[i] = _solve_lowrank(Z, lr, stiffness.lowrank_gain(wi), F)
        except RuntimeError as exc:
            raise ValueError(
                f"linear_response: the dynamic stiffness is singular at omega={wi:g} (undamped resonance); "
                "add damping or avoid that frequency"
            ) from exc
    return LinearResponse(omega=w, amplitude=out)
