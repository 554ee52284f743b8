"""Results layer: :class:`ErrorEstimate`, the estimated error of every point of a branch by source
(harmonic truncation, mesh), and what it covers."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

__all__ = ["ErrorEstimate", "ERROR_METHODS", "ERROR_SOURCES"]

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
        """The estimated relative error per point of what a branch shows: the larger of the error
        of its frequency (:attr:`frequency_error`, the best frequency, every source) and of its
        displacement (:attr:`amplitude`, the truncated series), NaN where it could not be
        estimated. :attr:`covers` says which sources."""
        mesh = None if self.mesh is None else np.asarray(self.mesh, float)
        if not self.harmonics_estimated:
            assert mesh is not None  # __post_init__: at least one source is estimated
            return mesh
        return np.fmax(self.frequency_error, np.asarray(self.amplitude, float))

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
        if self.harmonics_estimated and n:
            parts[0] += (f": frequency {largest(self.frequency_error)}, amplitude {largest(self.amplitude)} "
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
                **{k: np.asarray(getattr(self, k), float) for k in ("omega_limit", "omega_limit_error", "mesh")
                   if getattr(self, k) is not None},
                **({"finest": np.asarray(self.finest, int)} if self.finest is not None else {})}
