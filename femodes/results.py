"""Results layer: ``Branch`` (a continued family of periodic solutions) and ``PeriodicSolution``.

A solution is stored by its Fourier coefficients; everything else (time histories, contact forces,
penetration, tension, energy) is evaluated from them. Branches save to ``.npz`` (always
available, never pickled) or ``.h5`` (with h5py) and load back with :func:`load_branch`.

Files are written by :mod:`femodes.store` (atomic writes; the checkpoint journal of long runs).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .hbm.harmonics import Harmonics
from .laws import PenaltyContact, UnilateralContact
from .store import RECORD_SUFFIXES, model_signature, read_record, signature_differences, write_record

__all__ = ["PeriodicSolution", "Branch", "Bifurcation", "ErrorEstimate", "ERROR_SOURCES", "load_branch", "contact_differences", "FORMAT_VERSION", "BIFURCATION_KINDS"]

FORMAT_VERSION = 1

#: The kinds of :class:`Bifurcation`: a fold (saddle-node; a multiplier crosses +1 where the
#: branch turns back), a branch point (a multiplier crosses +1 and another branch crosses this
#: one), period doubling (-1), Neimark-Sacker (a complex pair), and "nonsmooth": multipliers that
#: jump across the unit circle instead of crossing it (the contact pattern changes there: grazing).
BIFURCATION_KINDS = ("fold", "branch_point", "period_doubling", "neimark_sacker", "nonsmooth")


@dataclass(frozen=True, eq=False)
class Bifurcation:
    """A bifurcation located on a branch (``branch.bifurcations``).

    Attributes
    ----------
    kind : str
        One of :data:`BIFURCATION_KINDS`.
    index : int
        A fold: the index of the fold point of the branch; otherwise the point before the
        bifurcation (it lies between points ``index`` and ``index + 1``).
    omega, energy : float
        Where it is (rad/s; period-averaged energy).
    parameter : float
        The continuation parameter there (``omega``, or ``log10(energy)`` for nonlinear modes).
    multiplier : complex
        The Floquet multiplier that crosses the unit circle there (1 for a fold).
    Q, P : ndarray
        The periodic solution at the bifurcation (displacement and contact-force coefficients).
    xi : float
        Artificial damping (nonlinear modes).
    located : bool
        True when it was located between its two branch points (``omega``, ``Q``, ``P`` are
        there); False for a bracketed one (``StabilityOptions(locate=False)``), reported at the
        point of the bracket on its unstable side.
    bracket : (float, float)
        How well it is located: the frequencies (rad/s) of the two solutions between which the
        test function of :mod:`femodes.branch_stability` changes sign (the two branch points for a
        bracketed one; equal where the reported solution is the crossing itself, to the test's
        tolerance); NaN where not stated (folds, files written before it).
    """

    kind: str
    index: int
    omega: float
    energy: float
    parameter: float
    multiplier: complex
    Q: np.ndarray
    P: np.ndarray
    xi: float = 0.0
    located: bool = True
    bracket: tuple[float, float] = (math.nan, math.nan)

    def __post_init__(self):
        if self.kind not in BIFURCATION_KINDS:
            raise ValueError(f"Bifurcation: kind must be one of {BIFURCATION_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "bracket", (float(self.bracket[0]), float(self.bracket[1])))

    def __repr__(self) -> str:
        return (f"Bifurcation({self.kind!r}, index={self.index}, omega={self.omega:.8g}, "
                f"multiplier={complex(self.multiplier):.4g}{'' if self.located else ', located=False'})")


#: How the error of a point was estimated (:attr:`ErrorEstimate.method`): from the change between
#: levels of harmonics (``"doubling"``), from the exact orbit of the flow with rigid stops
#: (``"shooting"``, :func:`femodes.estimate_error` with ``method="shooting"``), or not at all
#: (``"failed"``: a level had no solution near the point, e.g. next to a fold that moves by more
#: than the branch's curvature allows); ``"truncation"``: a fold of the branch that the converged
#: answer does not have (no fold of the exact branch turns the same way near it: a loop of the
#: truncation), so no error can be stated for it as a fold (NaN, never met); ``"none"``: the
#: harmonic truncation was not estimated (an estimate that holds another source only, e.g. the
#: mesh's of :func:`femodes.estimate_mesh_error`).
ERROR_METHODS = ("doubling", "shooting", "failed", "truncation", "none")

#: The sources of error an :class:`ErrorEstimate` can cover, with the words its summary uses.
ERROR_SOURCES = {"harmonics": "harmonic truncation", "mesh": "mesh"}


@dataclass(frozen=True, eq=False)
class ErrorEstimate:
    """Estimated error of every point of a branch with respect to the converged answer, by source:
    the harmonic truncation (``H -> inf``, :mod:`femodes.accuracy`) and, when it was estimated,
    the mesh (``h -> 0``, :func:`femodes.estimate_mesh_error`). :attr:`sources` gives each
    source's frequency error per point, :attr:`covers` says in words which sources the numbers
    cover (``"harmonic truncation only; mesh not estimated"``), :meth:`summary` in one line.

    Attributes (arrays over the points)
    -----------------------------------
    omega : ndarray
        Relative error of the frequency from the harmonic truncation.
    amplitude : ndarray
        Relative error of the displacement from the harmonic truncation: ``|Q - Q_inf| / |Q|``
        over all Fourier coefficients (the RMS over the period and the DOFs).
    penetration, tension : ndarray
        Contact quality of the point as stored: max penetration over the largest contact-DOF
        displacement, max tension over the largest contact force (0 without contacts).
    harmonics : ndarray of int
        Harmonics of the point as stored.
    rate : ndarray
        Observed contraction of the error per doubling of H (``inf``: unchanged to round-off).
    method : ndarray of str
        One of :data:`ERROR_METHODS` per point (``"none"`` everywhere: the harmonic truncation
        was not estimated).
    rtol : float or None
        The requested tolerance (``None``: estimate only).
    omega_limit, omega_limit_error : ndarray or None
        Frequency extrapolated to ``H -> inf`` and the relative half-width of the interval that
        contains the limit, for branches with complementarity contacts (rigid impacts converge to
        first order in ``1/H``: :func:`femodes.estimate_error`); NaN where the levels do not
        bracket the limit (non-monotone changes, or an observed ratio outside ``(1, 2]``).
    finest : ndarray of int or None
        The largest number of harmonics whose solution entered the point's estimate (``2 H``, or
        more where ``rtol`` added levels; 0 where the exact orbit by shooting answered).
    mesh : ndarray or None
        Relative frequency error from the spatial discretisation (Richardson extrapolation over
        meshes, :func:`femodes.estimate_mesh_error`); NaN where the meshes do not give one;
        ``None``: the mesh was not estimated.
    mesh_method : str or None
        How :attr:`mesh` was estimated (meshes, matching, convergence order stated or measured).
    caveat : str or None
        Why the branch is not the converged answer of the problem whatever its error numbers say
        (e.g. ``"grazing family: ... does not predict the forced resonance"``): with a caveat no
        point is :attr:`met`.
    """

    omega: np.ndarray
    amplitude: np.ndarray
    penetration: np.ndarray
    tension: np.ndarray
    harmonics: np.ndarray
    rate: np.ndarray
    method: np.ndarray
    rtol: float | None = None
    omega_limit: np.ndarray | None = None
    omega_limit_error: np.ndarray | None = None
    finest: np.ndarray | None = None
    mesh: np.ndarray | None = None
    mesh_method: str | None = None
    caveat: str | None = None

    def __post_init__(self):
        n = np.asarray(self.omega).shape
        for name in ("omega_limit", "omega_limit_error", "finest", "mesh"):
            v = getattr(self, name)
            if v is not None and np.asarray(v).shape != n:
                raise ValueError(f"ErrorEstimate: {name} must have one value per point ({n}), "
                                 f"got shape {np.asarray(v).shape}")
        for name in ("omega", "amplitude", "penetration", "tension", "harmonics", "rate", "method"):
            if np.asarray(getattr(self, name)).shape != n:
                raise ValueError(f"ErrorEstimate: {name} must have one value per point ({n}), "
                                 f"got shape {np.asarray(getattr(self, name)).shape}")
        bad = set(np.asarray(self.method, dtype=str).tolist()) - set(ERROR_METHODS)
        if bad:
            raise ValueError(f"ErrorEstimate: method must be one of {ERROR_METHODS}, got {sorted(bad)}")
        if self.mesh is None and self.mesh_method is not None:
            raise ValueError("ErrorEstimate: mesh_method describes a mesh estimate, but mesh is None")
        if not self.harmonics_estimated and self.mesh is None:
            raise ValueError("ErrorEstimate: no source is estimated (method 'none' everywhere and no mesh)")

    @property
    def harmonics_estimated(self) -> bool:
        """Whether the harmonic truncation was estimated (a method other than ``"none"``)."""
        return bool(np.any(np.asarray(self.method, dtype=str) != "none")) or not np.asarray(self.method).size

    @property
    def harmonic_frequency_error(self) -> np.ndarray:
        """The relative error of the best frequency the harmonic estimate gives per point: the
        half-width of the extrapolation bracket where there is one (branches with complementarity
        contacts), else the estimated error of the branch's own frequency (NaN: unknown)."""
        plain = np.asarray(self.omega, float)
        if self.omega_limit_error is None:
            return plain
        lim = np.asarray(self.omega_limit_error, float)
        return np.where(np.isfinite(lim), lim, plain)

    @property
    def sources(self) -> dict[str, np.ndarray]:
        """The relative frequency error per point of each source estimated, by name (the keys of
        :data:`ERROR_SOURCES`): ``"harmonics"`` (:attr:`harmonic_frequency_error`) when the
        harmonic truncation was estimated, ``"mesh"`` when a mesh estimate is attached."""
        out = {}
        if self.harmonics_estimated:
            out["harmonics"] = self.harmonic_frequency_error
        if self.mesh is not None:
            out["mesh"] = np.asarray(self.mesh, float)
        return out

    @property
    def covers(self) -> str:
        """In words, which sources of error the numbers cover and which not: ``"harmonic
        truncation only; mesh not estimated"``, ``"harmonic truncation and mesh (...)"`` or
        ``"mesh only (...); harmonic truncation not estimated"``."""
        src = self.sources
        how = f" ({self.mesh_method})" if self.mesh_method else ""
        if "mesh" not in src:
            return "harmonic truncation only; mesh not estimated"
        if "harmonics" not in src:
            return f"mesh only{how}; harmonic truncation not estimated"
        return f"harmonic truncation and mesh{how}"

    @property
    def frequency_error(self) -> np.ndarray:
        """The relative error of the best frequency per point, all sources estimated together
        (their sum, a bound when the errors add up with the same sign; NaN where a source has no
        number): with the harmonic truncation alone, :attr:`harmonic_frequency_error`."""
        vals = list(self.sources.values())
        return vals[0] if len(vals) == 1 else np.sum(vals, axis=0)

    @property
    def value(self) -> np.ndarray:
        """The estimated relative error per point: the larger of frequency and amplitude from the
        harmonic truncation, the mesh's frequency error added to the frequency's when it was
        estimated (NaN where it could not be estimated). :attr:`covers` says which sources."""
        mesh = None if self.mesh is None else np.asarray(self.mesh, float)
        if not self.harmonics_estimated:
            assert mesh is not None  # __post_init__: at least one source is estimated
            return mesh
        freq = np.asarray(self.omega, float) + (0.0 if mesh is None else mesh)
        return np.fmax(freq, np.asarray(self.amplitude, float))

    @property
    def met(self) -> np.ndarray:
        """Per point: does :attr:`frequency_error` (every source estimated) meet ``rtol``? All
        False without ``rtol``, and all False with a :attr:`caveat` (a branch that is not the
        family the problem asks for is not converged, whatever its error)."""
        if self.rtol is None or self.caveat:
            return np.zeros(np.asarray(self.omega).shape, dtype=bool)
        err = self.frequency_error
        return np.isfinite(err) & (err <= self.rtol)

    def with_mesh(self, mesh, method: str) -> ErrorEstimate:
        """The same estimate with the mesh source ``mesh`` (relative frequency error per point)
        described by ``method`` (replacing an earlier mesh estimate)."""
        return dataclasses.replace(self, mesh=np.asarray(mesh, float), mesh_method=str(method))

    def summary(self) -> str:
        """One line: the largest error, per source, the points that meet ``rtol``, what the numbers
        cover, and the caveat if there is one."""
        n = np.asarray(self.omega).size

        def largest(v):
            v = np.asarray(v, float)
            return f"{np.nanmax(v):.3g}" if np.any(np.isfinite(v)) else "unknown"

        parts = [f"largest {largest(self.value) if n else 'unknown'}"]
        if len(self.sources) > 1:
            parts[0] += " (" + ", ".join(f"{ERROR_SOURCES[k]} {largest(v)}" for k, v in self.sources.items()) + ")"
        if self.rtol:
            parts.append(f"rtol = {self.rtol:g} met at {int(np.sum(self.met))} of {n} points")
        parts.append(f"covers {self.covers}")
        if self.caveat:
            parts.append(self.caveat)
        return "error estimate: " + "; ".join(parts)

    def __repr__(self) -> str:
        return f"ErrorEstimate({np.asarray(self.omega).size} points; {self.summary()[len('error estimate: '):]})"

    def arrays(self) -> dict:
        return {"omega": np.asarray(self.omega, float), "amplitude": np.asarray(self.amplitude, float),
                "penetration": np.asarray(self.penetration, float), "tension": np.asarray(self.tension, float),
                "harmonics": np.asarray(self.harmonics, int), "rate": np.asarray(self.rate, float),
                **{k: np.asarray(getattr(self, k), float) for k in ("omega_limit", "omega_limit_error", "mesh")
                   if getattr(self, k) is not None},
                **({"finest": np.asarray(self.finest, int)} if self.finest is not None else {})}


@dataclass(frozen=True, eq=False)
class ContactInfo:
    """What a result needs to know about the contacts of the model it was solved on."""

    kinds: tuple  # "complementarity" or "penalty" per model contact, in model.contacts order
    dofs: tuple
    gaps: tuple
    stiffness: tuple  # penalty stiffness (nan for complementarity)
    slots: tuple  # column in P for complementarity contacts (-1 for penalty)
    c: tuple  # complementarity parameter used (nan for penalty)

    @classmethod
    def from_system(cls, system) -> ContactInfo:
        kinds, dofs, gaps, stiff, slots, cs = [], [], [], [], [], []
        uc = {ct.dof: ct for ct in system.unilateral}
        for a in system.model.contacts:
            dofs.append(int(a.dof))
            gaps.append(float(a.item.gap))
            if a.dof in uc:
                kinds.append("complementarity")
                stiff.append(math.nan)
                slots.append(uc[a.dof].slot)
                cs.append(uc[a.dof].c)
            else:
                kinds.append("penalty")
                stiff.append(float(a.item.stiffness))
                slots.append(-1)
                cs.append(math.nan)
        return cls(tuple(kinds), tuple(dofs), tuple(gaps), tuple(stiff), tuple(slots), tuple(cs))

    def to_json(self) -> dict:
        return {k: list(getattr(self, k)) for k in ("kinds", "dofs", "gaps", "stiffness", "slots", "c")}

    @cached_property
    def laws(self) -> tuple:
        """The contact laws (``at`` = their DOF index), rebuilt from the stored parameters: results
        evaluate gaps and penalty forces with the formulas of :mod:`femodes.laws`."""
        return tuple(
            UnilateralContact(at=d, gap=g, c=c) if kind == "complementarity"
            else PenaltyContact(at=d, gap=g, stiffness=k)
            for kind, d, g, k, c in zip(self.kinds, self.dofs, self.gaps, self.stiffness, self.c)
        )

    @classmethod
    def from_json(cls, d: dict) -> ContactInfo:
        return cls(*(tuple(d[k]) for k in ("kinds", "dofs", "gaps", "stiffness", "slots", "c")))


def contact_differences(contacts: ContactInfo, model) -> list[str]:
    """How the contacts of ``model`` differ from those a result stores (DOF, law, gap, penalty
    stiffness), in words; empty if they agree."""
    ci = contacts
    if len(model.contacts) != len(ci.kinds):
        return [f"{len(ci.kinds)} contacts in the result, {len(model.contacts)} in this model"]
    out = []
    for j, (a, kind, dof, gap, k) in enumerate(zip(model.contacts, ci.kinds, ci.dofs, ci.gaps, ci.stiffness)):
        mkind = "penalty" if isinstance(a.item, PenaltyContact) else "complementarity"
        where = f"contact {j} (DOF {dof})"
        if int(a.dof) != int(dof):
            out.append(f"contact {j}: DOF {dof} in the result, {int(a.dof)} in this model")
        elif mkind != kind:
            out.append(f"{where}: {kind} in the result, {mkind} in this model")
        elif float(a.item.gap) != float(gap):
            out.append(f"{where}: gap {gap:g} in the result, {float(a.item.gap):g} in this model")
        elif kind == "penalty" and float(a.item.stiffness) != float(k):
            out.append(f"{where}: stiffness {k:g} in the result, {float(a.item.stiffness):g} in this model")
    return out


def _fine_points(harmonics: Harmonics) -> int:
    """Samples per period of the fine grid on which contact quality is measured."""
    return max(2048, 64 * harmonics.n_coef)


def _contact_quality(harmonics: Harmonics, contacts: ContactInfo, Q: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Per point, over all contacts on a fine grid of ``_fine_points`` equidistant phases over the
    period: penetration ``max(0, max_t -g_N)``, tension ``max(0, max_t -p)``, the largest ``|q|``
    of a contact DOF and the largest contact force ``max_t p`` (rows 0-3 of the ``(4, n_points)``
    result). The single definition behind the penetration and tension of
    :class:`PeriodicSolution` and :class:`Branch`.

    ``Q``, ``P`` of shapes ``(n_points, n_coef, n_dofs)`` and ``(n_points, n_coef, n_p)``: one
    synthesis matrix for all points, only the contact DOFs evaluated (the error estimate's
    contact quality of a 94-point branch took 1.2 s point by point, four syntheses each)."""
    m = Q.shape[0]
    out = np.zeros((4, m))
    if not contacts.kinds or not m:
        return out
    out[3] = -np.inf
    n = _fine_points(harmonics)
    E = harmonics.synthesis(2 * np.pi * np.arange(n) / n)
    for kind, law, dof, slot in zip(contacts.kinds, contacts.laws, contacts.dofs, contacts.slots):
        u = E @ Q[:, :, dof].T  # (n, m)
        f = E @ P[:, :, slot].T if kind == "complementarity" else law.force(u)[0]
        out[0] = np.maximum(out[0], np.max(-law.gap_function(u), axis=0))
        out[1] = np.maximum(out[1], np.max(-f, axis=0))
        out[2] = np.maximum(out[2], np.max(np.abs(u), axis=0))
        out[3] = np.maximum(out[3], np.max(f, axis=0))
    return out


@dataclass(frozen=True, eq=False)
class PeriodicSolution:
    """One periodic solution ``q(t) = sum_k Q_k (cos, sin)(k w t / nu)``.

    Attributes
    ----------
    omega : float
        Frequency in rad/s (forcing frequency, or the nonlinear mode's frequency).
    Q : ndarray (n_coef, n_dofs)
        Displacement coefficients on the model it was solved on.
    P : ndarray (n_coef, n_complementarity_contacts)
        Contact force coefficients.
    harmonics : Harmonics
    energy : float
        Period-averaged mechanical energy.
    xi : float
        Artificial damping of the extended periodic motion concept (0 for forced responses).
    residual_norm : float
        Max-norm of the HBM residual at this point.
    model : StructuralModel or None
        The model (``None`` after loading from a file); needed for :meth:`full_displacement` and
        :func:`femodes.stability`.
    kind : str
        ``"forced"`` or ``"nonlinear mode"`` (the branch it belongs to).
    multipliers, stable : ndarray (complex) and bool, or None
        Floquet multipliers (largest modulus first) and stability, when the branch has them
        (``stability=True``); ``None`` otherwise.
    error_estimate : float or None
        Estimated relative error of frequency and amplitude with respect to the converged
        answer of the sources the branch's estimate covers (``H -> inf``; and ``h -> 0`` if the
        mesh was estimated: :attr:`ErrorEstimate.covers`), when the branch has one (``rtol=`` of
        the analyses, :func:`femodes.estimate_error`, :func:`femodes.estimate_mesh_error`);
        ``None`` otherwise. ``harmonics`` is the point's own
        (error control may use more harmonics at some points than at others).
    """

    omega: float
    Q: np.ndarray
    P: np.ndarray
    harmonics: Harmonics
    contacts: ContactInfo
    energy: float = math.nan
    xi: float = 0.0
    residual_norm: float = math.nan
    nit: int = 0
    model: Any = None
    kind: str = "forced"
    multipliers: np.ndarray | None = None
    stable: bool | None = None
    error_estimate: float | None = None

    @property
    def period(self) -> float:
        return self.harmonics.period(self.omega)

    @property
    def n_dofs(self) -> int:
        return self.Q.shape[1]

    def _t(self, t):
        return np.atleast_1d(np.asarray(t, dtype=float))

    def displacement(self, t) -> np.ndarray:
        """``q(t)``, shape ``(len(t), n_dofs)`` (DOFs of the model it was solved on)."""
        return self.harmonics.evaluate(self.Q, self.omega, self._t(t))

    def velocity(self, t) -> np.ndarray:
        """``q'(t)``, shape ``(len(t), n_dofs)``."""
        D = self.harmonics.derivative(self.omega)
        return self.harmonics.evaluate(D @ self.Q, self.omega, self._t(t))

    def contact_force(self, t) -> np.ndarray:
        """Contact forces ``p(t) >= 0`` (compression positive), shape ``(len(t), n_contacts)``."""
        t = self._t(t)
        ci = self.contacts
        out = np.zeros((t.size, len(ci.kinds)))
        if not ci.kinds:
            return out
        u = None
        for j, kind in enumerate(ci.kinds):
            if kind == "complementarity":
                out[:, j] = self.harmonics.evaluate(self.P[:, ci.slots[j]], self.omega, t)
            else:
                if u is None:
                    u = self.displacement(t)
                out[:, j] = ci.laws[j].force(u[:, ci.dofs[j]])[0]
        return out

    def gap(self, t) -> np.ndarray:
        """Normal gaps ``g_N(t) = gap - q_c(t)``, shape ``(len(t), n_contacts)``."""
        u = self.displacement(t)
        ci = self.contacts
        if not ci.kinds:
            return np.zeros((u.shape[0], 0))
        return np.column_stack([law.gap_function(u[:, dof]) for law, dof in zip(ci.laws, ci.dofs)])

    def _fine_t(self) -> np.ndarray:
        n = _fine_points(self.harmonics)
        return np.arange(n) * (self.period / n)

    @property
    def penetration(self) -> float:
        """Max penetration ``max(0, max_t -g_N(t))`` over a fine time grid (0 without contacts)."""
        return float(_contact_quality(self.harmonics, self.contacts, self.Q[None], self.P[None])[0, 0])

    @property
    def tension(self) -> float:
        """Max tension ``max(0, max_t -p(t))`` over a fine time grid (truncation artefact)."""
        return float(_contact_quality(self.harmonics, self.contacts, self.Q[None], self.P[None])[1, 0])

    def amplitude(self, dof: int) -> float:
        """``max_t |q_dof(t)|`` over a fine grid."""
        return float(np.max(np.abs(self.displacement(self._fine_t())[:, dof])))

    def full_displacement(self, t) -> np.ndarray:
        """Displacement expanded to the full model (Craig-Bampton parents) DOFs."""
        if self.model is None:
            raise ValueError("full_displacement needs the model: this solution was loaded from a file; use Branch.attach(model)")
        return self.model.to_owner(self.displacement(t))


class Branch:
    """A branch of periodic solutions from continuation.

    Attributes (arrays over the points)
    -----------------------------------
    omega, energy, converged, nit, residual_norm, parameter, xi, penetration, tension;
    ``folds`` (indices), ``kind`` ("forced" or "nonlinear mode"), ``success``, ``message``.
    ``branch[i]`` is a :class:`PeriodicSolution`; ``len(branch)`` the number of points.

    With stability computed (``stability=True`` of the analyses, :mod:`femodes.floquet`):
    ``stable`` (bool per point), ``multipliers`` (complex, ``(n_points, m)``, largest modulus
    first, NaN-padded), ``stability_method`` (``"hill"`` or ``"shooting"`` per point) and
    ``bifurcations`` (:class:`Bifurcation` objects in branch order). Without it ``stable``,
    ``multipliers`` and ``stability_method`` are ``None`` and ``bifurcations`` is empty.
    """

    @property
    def internal_resonances(self) -> list[dict]:
        """Tongues of internal resonance that a period-driven nonlinear mode stepped over (frequencies,
        energies, the modes that took the energy and ``w_k / w``); empty otherwise."""
        return list(self.meta.get("internal_resonances", []))

    def __init__(self, *, kind: str, harmonics: Harmonics, contacts: ContactInfo, omega, Q, P, energy, xi,
                 residual_norm, nit, parameter, folds=(), success=True, status=0, message="", model=None,
                 meta: dict | None = None):
        self.kind = kind
        self.harmonics = harmonics
        self.contacts = contacts
        self.omega = np.asarray(omega, dtype=float)
        self.Q = np.asarray(Q, dtype=float)
        self.P = np.asarray(P, dtype=float)
        self.energy = np.asarray(energy, dtype=float)
        self.xi = np.asarray(xi, dtype=float)
        self.residual_norm = np.asarray(residual_norm, dtype=float)
        self.nit = np.asarray(nit, dtype=int)
        self.parameter = np.asarray(parameter, dtype=float)
        self.folds = tuple(int(i) for i in folds)
        self.success = bool(success)
        self.status = int(status)
        self.message = str(message)
        self.model = model
        self.meta = dict(meta or {})
        self.stable: np.ndarray | None = None
        self.multipliers: np.ndarray | None = None
        self.stability_method: np.ndarray | None = None
        self.bifurcations: tuple = ()
        self.accuracy: ErrorEstimate | None = None
        #: :func:`~femodes.store.model_signature` of the model the branch was solved on, as read
        #: from its file (None: not stored, a file of an older femodes; or computed from ``model``)
        self.model_signature: dict | None = None

    def set_accuracy(self, accuracy: ErrorEstimate) -> Branch:
        """Attach the error estimate of every point (used by :mod:`femodes.accuracy`)."""
        if not isinstance(accuracy, ErrorEstimate):
            raise TypeError(f"set_accuracy: expected an ErrorEstimate, got {type(accuracy).__name__}")
        if np.asarray(accuracy.omega).shape != (len(self),):
            raise ValueError(f"set_accuracy: one value per point ({len(self)}) expected")
        if np.any(np.asarray(accuracy.harmonics) > self.harmonics.n_harmonics):
            raise ValueError("set_accuracy: a point uses more harmonics than the branch stores")
        self.accuracy = accuracy
        return self

    @property
    def error_estimate(self) -> np.ndarray | None:
        """Estimated relative error (frequency and amplitude, the larger) of every point with
        respect to the converged answer of the sources estimated: the harmonic truncation
        (``H -> inf``; ``rtol=`` of the analyses, or :func:`femodes.estimate_error`) and the mesh
        if :func:`femodes.estimate_mesh_error` was run; ``None`` unless computed. Which sources
        the numbers cover: ``branch.accuracy.covers``; details: :attr:`accuracy`."""
        return None if self.accuracy is None else self.accuracy.value

    def point_harmonics(self, i: int) -> Harmonics:
        """The harmonics of point ``i`` (error control may refine some points more than others;
        the branch stores every point on its largest ``harmonics``, zero-padded)."""
        if self.accuracy is None:
            return self.harmonics
        H = int(self.accuracy.harmonics[i])
        if H == self.harmonics.n_harmonics:
            return self.harmonics
        return Harmonics(H, subharmonic=self.harmonics.subharmonic)

    def set_stability(self, *, stable, multipliers, bifurcations, methods, tol: float) -> Branch:
        """Attach the stability of every point (used by :mod:`femodes.floquet`)."""
        n = len(self)
        stable = np.asarray(stable, dtype=bool)
        multipliers = np.asarray(multipliers, dtype=complex).reshape(n, -1)
        methods = np.asarray(methods, dtype=str)
        if stable.shape != (n,) or methods.shape != (n,):
            raise ValueError(f"set_stability: one value per point ({n}) expected")
        for b in bifurcations:
            if not isinstance(b, Bifurcation):
                raise TypeError(f"set_stability: bifurcations must be Bifurcation objects, got {type(b).__name__}")
        self.stable, self.multipliers, self.stability_method = stable, multipliers, methods
        self.bifurcations = tuple(bifurcations)
        self.meta["stability_tol"] = float(tol)
        return self

    @property
    def converged(self) -> np.ndarray:
        """True for every stored point (only converged points are stored)."""
        return np.isfinite(self.residual_norm)

    def __len__(self) -> int:
        return self.omega.size

    def __getitem__(self, i: int) -> PeriodicSolution:
        if isinstance(i, slice) or not isinstance(i, (int, np.integer)):
            raise TypeError("Branch indices must be integers; use the array attributes for slices")
        try:
            i = range(len(self))[i]
        except IndexError:
            raise IndexError(f"branch index {i} is out of range for a branch of {len(self)} points "
                             f"(valid: 0 .. {len(self) - 1}, or negative from the end)") from None
        h = self.point_harmonics(i)
        Q, P = (self.Q[i], self.P[i]) if h is self.harmonics else (
            self.harmonics.convert(self.Q[i], h), self.harmonics.convert(self.P[i], h))
        return PeriodicSolution(
            omega=float(self.omega[i]), Q=Q, P=P, harmonics=h, contacts=self.contacts,
            energy=float(self.energy[i]), xi=float(self.xi[i]), residual_norm=float(self.residual_norm[i]),
            nit=int(self.nit[i]), model=self.model, kind=self.kind,
            multipliers=None if self.multipliers is None else self.multipliers[i][np.isfinite(self.multipliers[i])],
            stable=None if self.stable is None else bool(self.stable[i]),
            error_estimate=None if self.accuracy is None else float(self.accuracy.value[i]),
        )

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def amplitude(self, dof: int, Q: np.ndarray | None = None) -> np.ndarray:
        """``max_t |q_dof(t)|`` at every point (or of the coefficient stack ``Q`` of shape
        ``(m, n_coef, n_dofs)`` on this branch's harmonics, e.g. of its bifurcations)."""
        Q = self.Q if Q is None else np.asarray(Q, dtype=float)
        n = max(512, 16 * self.harmonics.n_coef)
        E = self.harmonics.synthesis(2 * np.pi * np.arange(n) / n)
        return np.max(np.abs(E @ Q[:, :, dof].T), axis=0)

    @property
    def penetration(self) -> np.ndarray:
        """:attr:`PeriodicSolution.penetration` at every point (one synthesis for the branch)."""
        if not len(self):
            return np.zeros(0)
        return _contact_quality(self.harmonics, self.contacts, self.Q, self.P)[0]

    @property
    def tension(self) -> np.ndarray:
        """:attr:`PeriodicSolution.tension` at every point (one synthesis for the branch)."""
        return _contact_quality(self.harmonics, self.contacts, self.Q, self.P)[1]

    def contact_quality(self) -> tuple[np.ndarray, np.ndarray]:
        """Relative contact quality at every point: penetration over the largest displacement of a
        contact DOF, tension over the largest contact force; zeros without contacts. A point
        whose largest contact force is at round-off level of the branch's (``1e-12`` of it: the
        complementarity forces of a point without contact) counts as without contact force (its
        tension over that force would be a ratio of round-offs, about 1). The measures of
        :attr:`ErrorEstimate.penetration` and :attr:`ErrorEstimate.tension`."""
        pen, ten, amp, fmax = _contact_quality(self.harmonics, self.contacts, self.Q, self.P)
        touching = (fmax > 0) & (fmax > 1e-12 * float(np.max(fmax, initial=0.0)))
        return pen / np.where(amp > 0, amp, 1.0), np.where(touching, ten / np.where(touching, fmax, 1.0), 0.0)

    def attach(self, model) -> Branch:
        """Attach the model (after :func:`load_branch`) so solutions can expand to the full field.

        The model must be the one the branch was solved on: its contacts (DOF, law, gap,
        stiffness) are compared with those the branch stores, and its matrices, damping, forcing
        and laws with the hashes the branch file stores (:func:`~femodes.store.model_signature`);
        a difference is a ValueError naming it. A file of an older femodes stores no hashes:
        only its contacts are checked, with a warning.
        """
        from .model import StructuralModel

        if not isinstance(model, StructuralModel):
            raise TypeError(f"attach: model must be the StructuralModel the branch was solved on, got {type(model).__name__}")
        if model.n_dofs != self.Q.shape[2]:
            raise ValueError(f"attach: model has {model.n_dofs} DOFs but the branch was solved on {self.Q.shape[2]}")
        if model is not self.model:
            diff = contact_differences(self.contacts, model)
            saved = self.model_signature if self.model_signature is not None else (
                model_signature(self.model) if self.model is not None else None)
            if saved is not None:
                diff += [d for d in signature_differences(saved, model_signature(model))
                         if not (d == "contact laws" and diff)]
            if diff:
                raise ValueError(f"attach: this model differs from the one the branch was solved on "
                                 f"({'; '.join(diff)}); attach the model the branch was solved on, or compute the "
                                 "branch again on this model")
            if saved is None:
                warnings.warn("attach: the branch file stores no fingerprint of its model (saved by an older "
                              "femodes), so the model's matrices, damping and forcing cannot be checked; only its "
                              "contacts were compared; save the branch again to store one", UserWarning, stacklevel=3)
        self.model = model
        return self

    def __repr__(self) -> str:
        return (f"Branch({self.kind}, {len(self)} points, omega in [{self.omega.min() if len(self) else np.nan:.6g}, "
                f"{self.omega.max() if len(self) else np.nan:.6g}], folds={list(self.folds)}, success={self.success})")

    # -- persistence -------------------------------------------------------------------------
    def _arrays(self) -> dict:
        out = {
            "omega": self.omega, "Q": self.Q, "P": self.P, "energy": self.energy, "xi": self.xi,
            "residual_norm": self.residual_norm, "nit": self.nit, "parameter": self.parameter,
            "folds": np.asarray(self.folds, dtype=int),
        }
        if self.accuracy is not None:
            out.update({f"accuracy_{k}": v for k, v in self.accuracy.arrays().items()})
        if self.stable is not None and self.multipliers is not None:  # set together (set_stability)
            bifs = self.bifurcations
            out.update({
                "stable": self.stable.astype(np.int8), "multipliers_re": self.multipliers.real,
                "multipliers_im": self.multipliers.imag,
                "bif_index": np.asarray([b.index for b in bifs], dtype=int),
                "bif_real": np.asarray([[b.omega, b.energy, b.parameter, b.multiplier.real, b.multiplier.imag, b.xi]
                                        for b in bifs], dtype=float).reshape(len(bifs), 6),
                "bif_Q": np.asarray([b.Q for b in bifs], dtype=float).reshape((len(bifs),) + self.Q.shape[1:]),
                "bif_P": np.asarray([b.P for b in bifs], dtype=float).reshape((len(bifs),) + self.P.shape[1:]),
                "bif_bracket": np.asarray([b.bracket for b in bifs], dtype=float).reshape(len(bifs), 2),
            })
        return out

    def _header(self) -> dict:
        return {
            "format": "femodes.Branch", "version": FORMAT_VERSION, "kind": self.kind,
            "harmonics": [self.harmonics.n_harmonics, self.harmonics.n_time, self.harmonics.subharmonic],
            "contacts": self.contacts.to_json(), "success": self.success, "status": self.status,
            "message": self.message, "meta": self.meta,
            "model": model_signature(self.model) if self.model is not None else self.model_signature,
            "accuracy": None if self.accuracy is None else {
                "method": [str(m) for m in self.accuracy.method], "rtol": self.accuracy.rtol,
                "mesh_method": self.accuracy.mesh_method, "caveat": self.accuracy.caveat},
            "stability": None if self.stable is None or self.stability_method is None else {
                "methods": [str(m) for m in self.stability_method], "kinds": [b.kind for b in self.bifurcations],
                "located": [bool(b.located) for b in self.bifurcations]},
        }

    def save(self, path) -> Path:
        """Write the branch atomically to ``.npz`` or ``.h5``/``.hdf5`` (needs h5py)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        suffix = path.suffix.lower()
        if suffix not in RECORD_SUFFIXES:
            raise ValueError(f"Branch.save: use a .npz or .h5 file name, got {str(path)!r}")
        write_record(path, self._header(), self._arrays())  # atomic: never a half-written file under `path`
        return path


#: What a branch file holds (:meth:`Branch._header`, :meth:`Branch._arrays`): header fields and
#: their types, and the arrays over the points with their number of dimensions.
_HEADER_FIELDS = {"kind": str, "harmonics": list, "contacts": dict, "success": bool, "status": int, "message": str}
_CONTACT_FIELDS = ("kinds", "dofs", "gaps", "stiffness", "slots", "c")
_POINT_ARRAYS = {"omega": 1, "Q": 3, "P": 3, "energy": 1, "xi": 1, "residual_norm": 1, "nit": 1, "parameter": 1}
_ACCURACY_ARRAYS = ("omega", "amplitude", "penetration", "tension", "harmonics", "rate")
_STABILITY_ARRAYS = ("stable", "multipliers_re", "multipliers_im", "bif_index", "bif_real", "bif_Q", "bif_P")


def _check_schema(header: dict, arrays: dict, path: Path) -> None:
    """One ValueError naming the first missing or malformed field of a branch file (a file that
    reads but lacks a field would otherwise fail later as a KeyError or AttributeError)."""
    def bad(what: str):
        raise ValueError(f"load_branch: {str(path)!r} is incomplete or damaged: {what}; it cannot be read as a "
                         "branch (save it again with Branch.save)")

    for key, typ in _HEADER_FIELDS.items():
        if key not in header:
            bad(f"its header has no {key!r}")
        if not isinstance(header[key], typ) or (typ is int and isinstance(header[key], bool)):
            bad(f"header field {key!r} is {header[key]!r}, not a {typ.__name__}")
    h = header["harmonics"]
    if len(h) != 3 or not all(isinstance(v, int) and not isinstance(v, bool) for v in h):
        bad(f"header field 'harmonics' is {h!r}, not [n_harmonics, n_time, subharmonic]")
    ct = header["contacts"]
    for key in _CONTACT_FIELDS:
        if not isinstance(ct.get(key), list):
            bad(f"header field 'contacts' has no list {key!r}")
    if len({len(ct[k]) for k in _CONTACT_FIELDS}) != 1:
        bad("the lists of header field 'contacts' differ in length")
    for key in ("meta", "accuracy", "stability", "model"):
        if header.get(key) is not None and not isinstance(header[key], dict):
            bad(f"header field {key!r} is {header[key]!r}, not a dict")
    for key, ndim in {**_POINT_ARRAYS, "folds": 1}.items():
        if key not in arrays:
            bad(f"it has no array {key!r}")
        if np.ndim(arrays[key]) != ndim:
            bad(f"array {key!r} has {np.ndim(arrays[key])} dimensions, not {ndim}")
    n = arrays["omega"].shape[0]
    for key in _POINT_ARRAYS:
        if arrays[key].shape[0] != n:
            bad(f"array {key!r} has {arrays[key].shape[0]} points, 'omega' {n}")
    try:
        nc = Harmonics(*h).n_coef
    except (TypeError, ValueError) as exc:
        bad(f"header field 'harmonics' is {h!r} ({exc})")
    n_uc = sum(k == "complementarity" for k in ct["kinds"])
    if arrays["Q"].shape[1] != nc or arrays["P"].shape[1] != nc or arrays["P"].shape[2] != n_uc:
        bad(f"arrays 'Q' {arrays['Q'].shape} and 'P' {arrays['P'].shape} do not fit {h[0]} harmonics "
            f"({nc} coefficients) and {n_uc} complementarity contacts")
    if any(not 0 <= d < arrays["Q"].shape[2] for d in ct["dofs"]):
        bad(f"a contact DOF of {ct['dofs']} is outside the {arrays['Q'].shape[2]} DOFs of 'Q'")
    acc = header.get("accuracy")
    if acc is not None:
        for key in ("method", "rtol"):
            if key not in acc:
                bad(f"header field 'accuracy' has no {key!r}")
        for key in _ACCURACY_ARRAYS:
            if f"accuracy_{key}" not in arrays:
                bad(f"it has an error estimate but no array 'accuracy_{key}'")
    stab = header.get("stability")
    if stab is not None:
        for key in ("methods", "kinds"):
            if not isinstance(stab.get(key), list):
                bad(f"header field 'stability' has no list {key!r}")
        for key in _STABILITY_ARRAYS:
            if key not in arrays:
                bad(f"it has stability but no array {key!r}")
        if len(stab["kinds"]) != len(arrays["bif_index"]) or arrays["bif_real"].shape[1:] != (6,):
            bad(f"its {len(stab['kinds'])} bifurcation kinds do not match arrays 'bif_index' and 'bif_real'")
        loc = stab.get("located")
        if loc is not None and (not isinstance(loc, list) or len(loc) != len(stab["kinds"])):
            bad(f"header field 'stability' has a 'located' that is not a list of {len(stab['kinds'])} flags")


def load_branch(path, model=None) -> Branch:
    """Read a branch written by :meth:`Branch.save`; ``model`` optionally re-attached."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"load_branch: no such file {str(path)!r}")
    try:
        header, arrays = read_record(path)
    except ValueError as exc:
        raise ValueError(f"load_branch: {str(path)!r} is not a readable femodes branch file ({exc})") from exc
    if not isinstance(header, dict) or header.get("format") != "femodes.Branch":
        raise ValueError(f"load_branch: {str(path)!r} is not a femodes branch file")
    if header.get("version") != FORMAT_VERSION:
        raise ValueError(
            f"load_branch: {str(path)!r} has format version {header.get('version')}, this femodes reads version {FORMAT_VERSION}"
        )
    _check_schema(header, arrays, path)
    H, N, nu = header["harmonics"]
    br = Branch(
        kind=header["kind"], harmonics=Harmonics(H, N, nu), contacts=ContactInfo.from_json(header["contacts"]),
        omega=arrays["omega"], Q=arrays["Q"], P=arrays["P"], energy=arrays["energy"], xi=arrays["xi"],
        residual_norm=arrays["residual_norm"], nit=arrays["nit"], parameter=arrays["parameter"],
        folds=arrays["folds"].tolist(), success=header["success"], status=header["status"], message=header["message"],
        meta=header.get("meta"),
    )
    sig = header.get("model")
    if not isinstance(sig, dict):  # older files: the finished branch of a checkpointed run has a fingerprint
        ck = (header.get("meta") or {}).get("checkpoint")
        sig = ck.get("model") if isinstance(ck, dict) and isinstance(ck.get("model"), dict) else None
    br.model_signature = sig
    acc = header.get("accuracy")
    if acc is not None:
        br.set_accuracy(ErrorEstimate(**{k: arrays[f"accuracy_{k}"] for k in ("omega", "amplitude", "penetration",
                                                                                "tension", "harmonics", "rate")},
                                      method=np.asarray(acc["method"], dtype=str), rtol=acc["rtol"],
                                      mesh_method=acc.get("mesh_method"), caveat=acc.get("caveat"),
                                      **{k: arrays[f"accuracy_{k}"] for k in ("omega_limit", "omega_limit_error",
                                                                              "finest", "mesh") if f"accuracy_{k}" in arrays}))
    stab = header.get("stability")
    if stab is not None:
        located = stab.get("located", [True] * len(stab["kinds"]))  # older files: every bifurcation located
        brackets = arrays.get("bif_bracket", np.full((len(stab["kinds"]), 2), np.nan))  # older files: not stated
        bifs = [Bifurcation(kind=k, index=int(i), omega=float(r[0]), energy=float(r[1]), parameter=float(r[2]),
                            multiplier=complex(r[3], r[4]), xi=float(r[5]), Q=q, P=p, located=bool(loc),
                            bracket=(float(w[0]), float(w[1])))
                for k, i, r, q, p, loc, w in zip(stab["kinds"], arrays["bif_index"], arrays["bif_real"],
                                                 arrays["bif_Q"], arrays["bif_P"], located, brackets)]
        br.set_stability(stable=arrays["stable"].astype(bool),
                         multipliers=arrays["multipliers_re"] + 1j * arrays["multipliers_im"], bifurcations=bifs,
                         methods=stab["methods"], tol=float(br.meta.get("stability_tol", 1e-4)))
    if model is not None:
        br.attach(model)
    return br
