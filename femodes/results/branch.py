"""Results layer: :class:`Branch`, a continued family of periodic solutions, with its stability
and error estimate, and its file (:meth:`Branch.save`; :func:`~femodes.results.load_branch`)."""

from __future__ import annotations

import copy
import functools
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..hbm.harmonics import Harmonics
from ..store import RECORD_SUFFIXES, model_signature, signature_differences, write_record
from ..solvers.checks import user_stacklevel
from .branch_annotations import answer, checked_accuracy, checked_stability, point_harmonics
from .branch_record import FORMAT_VERSION, branch_arrays, branch_header
from .contacts import ContactInfo, contact_differences, contact_quality, peak_amplitude
from .error_estimate import ErrorEstimate
from .solution import PeriodicSolution, checked_dof

__all__ = ["Branch", "FORMAT_VERSION", "fill_in_place"]



class _Bifurcations:
    """``Branch.bifurcations``, read from the branch. Assigning it was the way to replace the
    bifurcations before branches became values (issue 39): for this release the assignment still
    replaces them, as it did (the file :meth:`Branch.save` writes included), with a
    DeprecationWarning; :meth:`Branch.with_stability` builds a branch with others."""

    def __get__(self, branch: Any, owner: Any = None) -> Any:
        return self if branch is None else vars(branch).get("bifurcations", ())

    def __set__(self, branch: Any, value: Any) -> None:
        warnings.warn("Branch.bifurcations: assigning the bifurcations is deprecated and will be removed in the "
                      "next release; use branch.with_stability(...), which returns a new branch",
                      DeprecationWarning, stacklevel=user_stacklevel())
        branch._bifurcations = tuple(b.series() for b in value)
        _settle(branch)

class Branch:
    """A branch of periodic solutions from continuation.

    Attributes (arrays over the points)
    -----------------------------------
    omega, energy, converged, nit, residual_norm, parameter, xi, penetration, tension;
    ``folds`` (indices), ``kind`` ("forced" or "nonlinear mode"), ``success``, ``message``.
    ``omega`` is the answer: with an error estimate (``rtol=``), the converged frequency, with
    its error bar ``omega_error``; ``omega_truncated`` is the frequency of the truncated series
    ``Q, P`` (the same array without an estimate); ``amplitude_error`` is the error of the
    series' displacement (docs/guide/accuracy.md, "What the branch shows").
    ``branch[i]`` is a :class:`PeriodicSolution`; ``len(branch)`` the number of points.

    With stability computed (``stability=True`` of the analyses, :mod:`femodes.floquet`):
    ``stable`` (bool per point), ``multipliers`` (complex, ``(n_points, m)``, largest modulus
    first, NaN-padded), ``stability_method`` (``"hill"`` or ``"shooting"`` per point) and
    ``bifurcations`` (:class:`Bifurcation` objects in branch order). Without it ``stable``,
    ``multipliers`` and ``stability_method`` are ``None`` and ``bifurcations`` is empty.

    A branch is a value: the analyses build it with its error estimate and stability
    (:meth:`with_accuracy` and :meth:`with_stability` return a new branch and leave this one as
    it is), and the answer they give (``omega``, ``omega_error``, ``amplitude_error``,
    ``error_estimate``, ``bifurcations``) is computed once, when it is built
    (:mod:`femodes.results.branch_annotations`). :meth:`attach` sets the model (of a loaded
    branch), which changes no number.
    """

    #: The frequency of every point: the answer. With an error estimate whose harmonic
    #: extrapolation or exact orbit gives a converged frequency (``rtol=`` of the analyses,
    #: :func:`femodes.estimate_error` on branches with complementarity contacts), that frequency
    #: (``accuracy.omega_limit``), with the relative error bar :attr:`omega_error`; elsewhere the
    #: harmonic balance's own, :attr:`omega_truncated`. The coefficients ``Q, P`` are the
    #: truncated series at :attr:`omega_truncated`.
    omega: np.ndarray
    #: Relative error bar of :attr:`omega` per point, every source estimated
    #: (:attr:`ErrorEstimate.frequency_error`; what ``rtol`` controls and :attr:`ErrorEstimate.met`
    #: judges); NaN: unknown; ``None`` without an error estimate.
    omega_error: np.ndarray | None
    #: Relative error bar of the amplitudes :meth:`amplitude` gives per point
    #: (:attr:`ErrorEstimate.amplitude_error`): the exact orbit's where shooting answered (its
    #: amplitudes are then those of the exact orbit), else the truncated series' (which ``rtol``
    #: does not control); ``None`` without an error estimate.
    amplitude_error: np.ndarray | None
    #: Estimated relative error of every point with respect to the converged answer of the sources
    #: estimated: the harmonic truncation (``H -> inf``; ``rtol=`` of the analyses, or
    #: :func:`femodes.estimate_error`) and the mesh if :func:`femodes.estimate_mesh_error` was run;
    #: the larger of :attr:`omega_error` and :attr:`amplitude_error`; ``None`` unless computed.
    #: Which sources the numbers cover: ``branch.accuracy.covers``; details: :attr:`accuracy`.
    error_estimate: np.ndarray | None
    #: The :class:`Bifurcation` objects in branch order, at the frequency the branch reports
    #: (:attr:`omega`): on an error-controlled branch each is moved by its points' correction
    #: ``omega - omega_truncated``, so that it sits on the converged curve; ``b.omega_truncated``,
    #: ``b.Q`` and ``b.P`` stay the truncated series'. (Assigning them is deprecated.)
    bifurcations: tuple = _Bifurcations()  # type: ignore[assignment]

    @property
    def stability_unconverged(self) -> list[int]:
        """Points whose stability verdict failed Hill's truncation check (it changes when the
        perturbation is cut to fewer harmonics: :func:`femodes.stability_methods.harmonic_check`);
        empty when none did or stability was not computed. ``meta["stability_unconverged"]`` holds
        each one's leading moduli at both truncations, ``meta["stability_checked"]`` how many
        points were checked."""
        return [int(d["index"]) for d in self.meta.get("stability_unconverged", [])]

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
        #: the frequencies of the truncated series ``Q, P`` (the harmonic balance's own solutions);
        #: :attr:`omega` is the answer, which differs from these where an error estimate converged it
        self.omega_truncated = np.asarray(omega, dtype=float)
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
        self._bifurcations: tuple = ()  # at the frequencies of their series (see bifurcations)
        self.accuracy: ErrorEstimate | None = None
        #: :func:`~femodes.store.model_signature` of the model the branch was solved on, as read
        #: from its file (None: not stored, a file of an older femodes; or computed from ``model``)
        self.model_signature: dict | None = None
        #: True for every stored point (only converged points are stored)
        self.converged = np.isfinite(self.residual_norm)
        _settle(self)

    def with_accuracy(self, accuracy: ErrorEstimate) -> Branch:
        """This branch with the error estimate of every point (built so by :mod:`femodes.accuracy`
        and :func:`femodes.estimate_mesh_error`): a new branch; this one is unchanged."""
        return _annotated(self, accuracy=checked_accuracy(accuracy, len(self), self.harmonics.n_harmonics,
                                                          "with_accuracy"))

    def with_stability(self, *, stable, multipliers, bifurcations, methods, tol: float, checked: int = 0,
                       unconverged: Sequence[dict] = ()) -> Branch:
        """This branch with the stability of every point (built so by :mod:`femodes.floquet`): the
        verdicts, the multipliers (``(n_points, m)``, NaN-padded), the method of each point and the
        :class:`Bifurcation` objects; a new branch, this one unchanged. ``checked`` points passed
        through Hill's truncation check and ``unconverged`` those that failed it (``index``,
        ``modulus``, ``coarse``: :attr:`stability_unconverged`), kept in ``meta`` when any was
        checked."""
        new = _with_stability(self, "with_stability", stable, multipliers, bifurcations, methods, tol)
        for key in ("stability_checked", "stability_unconverged"):  # not those of an earlier stability
            new.meta.pop(key, None)
        if checked:
            new.meta["stability_checked"] = int(checked)
            new.meta["stability_unconverged"] = [dict(d) for d in unconverged]
        return new

    def __len__(self) -> int:
        return self.omega_truncated.size

    def __getitem__(self, i: int) -> PeriodicSolution:
        if isinstance(i, slice) or not isinstance(i, (int, np.integer)):
            raise TypeError("Branch indices must be integers; use the array attributes for slices")
        try:
            i = range(len(self))[i]
        except IndexError:
            raise IndexError(f"branch index {i} is out of range for a branch of {len(self)} points "
                             f"(valid: 0 .. {len(self) - 1}, or negative from the end)") from None
        h = point_harmonics(self.harmonics, self.accuracy, i)
        Q, P = (self.Q[i], self.P[i]) if h is self.harmonics else (
            self.harmonics.layout.convert(self.Q[i], h), self.harmonics.layout.convert(self.P[i], h))
        acc = self.accuracy
        sol = PeriodicSolution(
            omega=float(self.omega[i]), Q=Q, P=P, harmonics=h, contacts=self.contacts,
            energy=float(self.energy[i]), xi=float(self.xi[i]), residual_norm=float(self.residual_norm[i]),
            nit=int(self.nit[i]), model=self.model, kind=self.kind,
            multipliers=None if self.multipliers is None else self.multipliers[i][np.isfinite(self.multipliers[i])],
            stable=None if self.stable is None else bool(self.stable[i]),
            error_estimate=None if acc is None else float(acc.value[i]),
        )
        if acc is None:
            return sol
        limit = acc.amplitude_limit[i] if acc.amplitude_limit is not None and acc.converged_amplitude[i] else None
        return sol._error_controlled(float(self.omega_truncated[i]), float(acc.frequency_error[i]),
                                     float(acc.amplitude_error[i]), limit)

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def amplitude(self, dof: int, Q: np.ndarray | None = None) -> np.ndarray:
        """``max_t |q_dof(t)|`` at every point: the answer, as :attr:`omega`. Where an error
        estimate found the exact orbit (shooting: ``accuracy.amplitude_limit``), its amplitude,
        with the error bar :attr:`amplitude_error`; elsewhere that of the truncated series.
        With ``Q`` (a coefficient stack of shape ``(m, n_coef, n_dofs)`` on this branch's
        harmonics, e.g. ``branch.Q`` itself or its bifurcations'), that series' amplitude."""
        series = self.Q if Q is None else np.asarray(Q, dtype=float)
        checked_dof(dof, series.shape[-1], "Branch.amplitude")
        amp = peak_amplitude(self.harmonics, series[:, :, dof], n=max(512, 16 * self.harmonics.n_coef))
        acc = self.accuracy
        if Q is not None or acc is None or acc.amplitude_limit is None:
            return amp
        return np.where(acc.converged_amplitude, np.asarray(acc.amplitude_limit, float)[:, dof], amp)

    @property
    def penetration(self) -> np.ndarray:
        """:attr:`PeriodicSolution.penetration` at every point (one synthesis for the branch)."""
        if not len(self):
            return np.zeros(0)
        return contact_quality(self.harmonics, self.contacts, self.Q, self.P)[0]

    @property
    def tension(self) -> np.ndarray:
        """:attr:`PeriodicSolution.tension` at every point (one synthesis for the branch)."""
        return contact_quality(self.harmonics, self.contacts, self.Q, self.P)[1]

    def contact_quality(self) -> tuple[np.ndarray, np.ndarray]:
        """Relative contact quality at every point: penetration over the largest displacement of a
        contact DOF, tension over the largest contact force; zeros without contacts. A point
        whose largest contact force is at round-off level of the branch's (``1e-12`` of it: the
        complementarity forces of a point without contact) counts as without contact force (its
        tension over that force would be a ratio of round-offs, about 1). The measures of
        :attr:`ErrorEstimate.penetration` and :attr:`ErrorEstimate.tension`."""
        pen, ten, amp, fmax = contact_quality(self.harmonics, self.contacts, self.Q, self.P)
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
        from ..model import StructuralModel

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

    if not TYPE_CHECKING:  # the type checker sees no moved name
        def __getattr__(self, name: str) -> Any:
            # names that moved (the table MOVED below): they still work, with a DeprecationWarning
            if name not in MOVED:
                raise AttributeError(f"'Branch' object has no attribute {name!r}")
            new, value = MOVED[name]
            warnings.warn(f"Branch.{name} is deprecated and will be removed; use {new}", DeprecationWarning,
                          stacklevel=user_stacklevel())
            return value(self)

    def __repr__(self) -> str:
        return (f"Branch({self.kind}, {len(self)} points, omega in [{self.omega.min() if len(self) else np.nan:.6g}, "
                f"{self.omega.max() if len(self) else np.nan:.6g}], folds={list(self.folds)}, success={self.success})")

    def save(self, path) -> Path:
        """Write the branch atomically to ``.npz`` or ``.h5``/``.hdf5`` (needs h5py)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        suffix = path.suffix.lower()
        if suffix not in RECORD_SUFFIXES:
            raise ValueError(f"Branch.save: use a .npz or .h5 file name, got {str(path)!r}")
        # atomic: never a half-written file under `path`; the bifurcations at their series' frequencies
        write_record(path, branch_header(self), branch_arrays(self, self._bifurcations))
        return path


def _settle(branch: Branch) -> None:
    """Compute the answer of ``branch`` from its series, error estimate and bifurcations."""
    a = answer(branch.omega_truncated, branch.accuracy, branch._bifurcations)
    branch.omega, branch.omega_error, branch.amplitude_error = a.omega, a.omega_error, a.amplitude_error
    branch.error_estimate = a.error_estimate
    vars(branch)["bifurcations"] = a.bifurcations  # past the deprecated assignment (_Bifurcations)


def _annotated(branch: Branch, **attributes: Any) -> Branch:
    """A copy of ``branch`` (arrays shared: nobody writes them; ``meta`` copied) with
    ``attributes`` replaced and its answer computed again."""
    new = copy.copy(branch)
    new.meta = dict(branch.meta)
    for name, value in attributes.items():
        setattr(new, name, value)
    _settle(new)
    return new


def _with_stability(branch: Branch, name: str, stable, multipliers, bifurcations, methods, tol: float) -> Branch:
    stable, multipliers, methods, series = checked_stability(len(branch), stable, multipliers, bifurcations, methods,
                                                             name)
    new = _annotated(branch, stable=stable, multipliers=multipliers, stability_method=methods, _bifurcations=series)
    new.meta["stability_tol"] = float(tol)
    return new


def fill_in_place(branch: Branch, new: Branch) -> Branch:
    """Legacy of this release: ``branch`` reads as ``new`` (its model, error estimate, stability,
    ``meta``), and is returned. :func:`femodes.estimate_error`, :func:`femodes.estimate_mesh_error`
    and :func:`femodes.floquet.annotate_branch` return a new branch and still fill the one they are
    given so, as they did; so do the deprecated ``set_accuracy``/``set_stability``. A later release
    leaves the given branch unchanged."""
    vars(branch).update(vars(new))
    branch.meta = dict(new.meta)
    return branch


def _set_accuracy(branch: Branch, accuracy: ErrorEstimate) -> Branch:
    checked_accuracy(accuracy, len(branch), branch.harmonics.n_harmonics, "set_accuracy")
    return fill_in_place(branch, _annotated(branch, accuracy=accuracy))


def _set_stability(branch: Branch, *, stable, multipliers, bifurcations, methods, tol: float) -> Branch:
    return fill_in_place(branch, _with_stability(branch, "set_stability", stable, multipliers, bifurcations, methods, tol))


#: Names of :class:`Branch` that moved (issue 39), read by its ``__getattr__``: old name -> (new
#: spelling, for the DeprecationWarning; what the old name gives on the branch). They are removed in
#: a later release.
MOVED: dict[str, tuple[str, Callable[[Branch], Any]]] = {
    "set_accuracy": ("branch.with_accuracy(estimate), which returns a new branch",
                     lambda b: functools.partial(_set_accuracy, b)),
    "set_stability": ("branch.with_stability(...), which returns a new branch",
                      lambda b: functools.partial(_set_stability, b)),
    "point_harmonics": ("branch[i].harmonics", lambda b: functools.partial(point_harmonics, b.harmonics, b.accuracy)),
}
