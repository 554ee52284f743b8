"""Results layer: :class:`ErrorEstimate`, the estimated error of every point of a branch by source
(harmonic truncation, mesh), and what it covers."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ErrorEstimate", "ERROR_METHODS", "ERROR_SOURCES", "AMPLITUDE_SAMPLES", "AMPLITUDE_SAMPLING", "largest_text"]

#: Samples per period on which the maximum of an exact orbit is taken, with its events
#: (:func:`femodes.accuracy.protocol.orbit_amplitudes`).
AMPLITUDE_SAMPLES = 4096
#: Relative error bound of that maximum: ``(w_max dt)^2 / 8`` for the harmonics up to the 8th.
AMPLITUDE_SAMPLING = (8 * 2 * math.pi / AMPLITUDE_SAMPLES) ** 2 / 8


def largest_text(v) -> str:
    """The largest finite value of ``v`` in three digits, or ``"unknown"`` (error summaries)."""
    v = np.asarray(v, float)
    return f"{np.nanmax(v):.3g}" if np.any(np.isfinite(v)) else "unknown"

#: levels of harmonics (``"doubling"``), from the exact orbit of the flow with rigid stops
#: (``"shooting"``, :func:`femodes.estimate_error` with ``method=fm.error_methods.Shooting()``), or not at all
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
    penetration, tension, harmonics : ndarray
        Contact quality of the point as stored (max penetration over the largest contact-DOF
        displacement, max tension over the largest contact force; 0 without contacts); its harmonics.
    rate, method : ndarray
        Observed contraction of the error per doubling of H (``inf``: unchanged to round-off); one of
        :data:`ERROR_METHODS` per point (``"none"``: not estimated). ``rtol``: the tolerance asked.
    omega_limit, omega_limit_error : ndarray or None
        Frequency extrapolated to ``H -> inf`` and the relative half-width of the interval that
        contains the limit, for branches with complementarity contacts (rigid impacts converge to
        first order in ``1/H``: :func:`femodes.estimate_error`); NaN where the levels do not
        bracket the limit (non-monotone changes, or an observed ratio outside ``(1, 2]``).
    finest : ndarray of int or None
        The largest number of harmonics whose solution entered the point's estimate (``2 H``, or
        more where ``rtol`` added levels; 0 where the exact orbit by shooting answered).
    mesh, mesh_method : ndarray or None, str or None
        Relative frequency error from the mesh (Richardson over meshes,
        :func:`femodes.estimate_mesh_error`; NaN where they give none; ``None``: not estimated), and how.
    caveat : str or None
        Why the branch is not the converged answer of the problem whatever its error numbers say
        (e.g. ``"grazing family: ... does not predict the forced resonance"``): with a caveat no
        point is :attr:`met`.
    amplitude_limit, amplitude_limit_error : ndarray or None
        ``max_t |q_d(t)|`` per DOF of each point's exact orbit, ``(n_points, n_dofs)`` (NaN rows: none;
        ``None``: shooting never answered), read by :meth:`femodes.Branch.amplitude`; and its relative
        error bar per point (the frequency half-width, its square root at a fold; at least
        :data:`AMPLITUDE_SAMPLING`).
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
    amplitude_limit: np.ndarray | None = None
    amplitude_limit_error: np.ndarray | None = None

    def __post_init__(self):
        n = np.asarray(self.omega).shape
        if self.amplitude_limit is not None and (np.ndim(self.amplitude_limit) != 2
                                                 or np.shape(self.amplitude_limit)[0] != n[0]):
            raise ValueError(f"ErrorEstimate: amplitude_limit must have one row per point ({n[0]}) and one column per "
                             f"DOF, got shape {np.shape(self.amplitude_limit)}")
        if (self.amplitude_limit is None) != (self.amplitude_limit_error is None):
            raise ValueError("ErrorEstimate: amplitude_limit and amplitude_limit_error go together")
        for name in ("omega_limit", "omega_limit_error", "finest", "mesh", "amplitude_limit_error"):
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
    def converged_amplitude(self) -> np.ndarray:
        """Per point: does :attr:`amplitude_limit` give the amplitudes of its exact orbit?"""
        n = np.asarray(self.omega).shape[0]
        if self.amplitude_limit is None:
            return np.zeros(n, dtype=bool)
        return np.all(np.isfinite(np.asarray(self.amplitude_limit, float)), axis=1)

    @property
    def amplitude_error(self) -> np.ndarray:
        """The relative error of the amplitudes a branch shows per point: those of the exact orbit
        (:attr:`amplitude_limit`) where there is one, with :attr:`amplitude_limit_error`; elsewhere
        the truncated series' own error, :attr:`amplitude`."""
        own = np.asarray(self.amplitude, float)
        if self.amplitude_limit is None or self.amplitude_limit_error is None:
            return own
        return np.where(self.converged_amplitude, np.asarray(self.amplitude_limit_error, float), own)

    @property
    def value(self) -> np.ndarray:
        """The estimated relative error per point of what a branch shows: the larger of the error
        of its frequency (:attr:`frequency_error`, the best frequency, every source) and of its
        amplitudes (:attr:`amplitude_error`: the exact orbit's where shooting gave one, else the
        truncated series'), NaN where it could not be estimated. :attr:`covers` says which
        sources."""
        mesh = None if self.mesh is None else np.asarray(self.mesh, float)
        if not self.harmonics_estimated:
            assert mesh is not None  # __post_init__: at least one source is estimated
            return mesh
        return np.fmax(self.frequency_error, self.amplitude_error)

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

        parts = [f"largest {largest_text(self.value) if n else 'unknown'}"]
        if len(self.sources) > 1:
            parts[0] += " (" + ", ".join(f"{ERROR_SOURCES[k]} {largest_text(v)}" for k, v in self.sources.items()) + ")"
        if self.harmonics_estimated and n:
            parts[0] += (f": frequency {largest_text(self.frequency_error)}, amplitude {largest_text(self.amplitude_error)} "
                         "(rtol controls the frequency)")
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
                **{k: np.asarray(getattr(self, k), float) for k in ("omega_limit", "omega_limit_error", "mesh",
                                                                     "amplitude_limit_error")
                   if getattr(self, k) is not None},
                **({"finest": np.asarray(self.finest, int)} if self.finest is not None else {}),
                **({"amplitude_limit": np.asarray(self.amplitude_limit, float)} if self.amplitude_limit is not None else {})}
