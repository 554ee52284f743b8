"""Analyses layer: static equilibrium with contact (:func:`static_contact`), with the same
semismooth Newton and contact laws as the dynamic problems."""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from .analysis_inputs import check_model, start_vector
from .hbm.system import default_contact_parameters
from .laws import PenaltyContact, UnilateralContact
from .model import StructuralModel
from .solvers import NewtonOptions, semismooth_newton
from .solvers.checks import entry_point
from .solvers.threads import limit_blas_threads

__all__ = ["static_contact", "StaticContactResult"]


@dataclasses.dataclass(frozen=True, eq=False)
class StaticContactResult:
    """Static contact solution: ``x`` displacements, ``contact_force`` and ``gap`` per contact (in
    ``model.contacts`` order), scipy-style fields."""

    x: np.ndarray
    contact_force: np.ndarray
    gap: np.ndarray
    success: bool
    status: int
    message: str
    nit: int
    residual_norm: float

    @property
    def penetration(self) -> float:
        """``max(-gap)`` over the contacts (0 if none penetrates)."""
        return float(max(0.0, np.max(-self.gap))) if self.gap.size else 0.0


@entry_point("static_contact")
@limit_blas_threads()  # one BLAS thread unless FEMODES_BLAS_THREADS says otherwise
def static_contact(model: StructuralModel, force: np.ndarray | None = None, *, x0: np.ndarray | None = None,
                   options: NewtonOptions | None = None) -> StaticContactResult:
    """Static equilibrium with contact: ``K q + f_nl(q) = f - W p``, ``p - max(0, p - c g_N) = 0``.

    Solved with the same semismooth Newton as the dynamic problems (no harmonics). ``force``
    defaults to the static part of the declared forcing plus the amplitudes of harmonic-1 forces
    (a quasi-static load).
    """
    model = check_model(model)
    n = model.n_dofs
    if force is None:
        fv = model.force_vectors()
        f = sum((v.real for v in fv.values()), np.zeros(n))
    else:
        f = np.asarray(force, dtype=float)
        if f.shape != (n,) or not np.all(np.isfinite(f)):
            raise ValueError(f"static_contact: force must be a finite vector of length {n}, got shape {f.shape}")
    uc = [(a.item, a.dof) for a in model.contacts if isinstance(a.item, UnilateralContact)]
    defaults = default_contact_parameters(model, [dof for law, dof in uc if law.c is None])
    it = iter(defaults)
    cs = [law.c if law.c is not None else float(next(it)) for law, dof in uc]
    m = len(uc)
    K = model.K.tocsr()

    def fun(x):
        q, p = x[:n], x[n:]
        r = np.empty(n + m)
        r[:n] = K @ q - f
        rows, cols, vals = [], [], []
        for a in model.contacts:
            if isinstance(a.item, PenaltyContact):
                pf, dp = a.item.force(q[a.dof])
                r[a.dof] += pf
                rows.append(a.dof); cols.append(a.dof); vals.append(float(dp))
        for a in model.nonlinearities:
            ff, df = a.item.force(q[a.dof])
            r[a.dof] += ff
            rows.append(a.dof); cols.append(a.dof); vals.append(float(df))
        for j, ((law, dof), c) in enumerate(zip(uc, cs)):
            r[dof] += p[j]
            rows.append(dof); cols.append(n + j); vals.append(1.0)
            rr, drp, dru = law.residual(p[j], q[dof], c)
            r[n + j] = rr
            rows += [n + j, n + j]; cols += [n + j, dof]; vals += [float(drp), float(dru)]
        J = sp.block_diag([K, sp.csr_matrix((m, m))], format="csr") + sp.csr_matrix((vals, (rows, cols)), shape=(n + m, n + m))
        return r, J

    x_init = np.zeros(n + m) if x0 is None else start_vector(x0, n + m, f"{n} DOFs + {m} contact forces")
    res = semismooth_newton(fun, x_init, options=options or NewtonOptions(atol=1e-10, max_iter=50))
    q = res.x[:n]
    forces = np.zeros(len(model.contacts))
    gaps = np.zeros(len(model.contacts))
    j = 0
    for i, a in enumerate(model.contacts):
        gaps[i] = a.item.gap_function(q[a.dof])
        if isinstance(a.item, UnilateralContact):
            forces[i] = res.x[n + j]
            j += 1
        else:
            forces[i] = a.item.force(q[a.dof])[0]
    return StaticContactResult(x=q, contact_force=forces, gap=gaps, success=res.success, status=res.status,
                               message=res.message, nit=res.nit, residual_norm=res.residual_norm)
