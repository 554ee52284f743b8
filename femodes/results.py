"""Results layer: ``Branch`` (a continued family of periodic solutions) and ``PeriodicSolution``.

A solution is stored by its Fourier coefficients; everything else (time histories, contact forces,
penetration, tension, energy) is evaluated from them. Branches save to ``.npz`` (always
available, never pickled) or ``.h5`` (with h5py) and load back with :func:`load_branch`.

Long runs write a :class:`Checkpoint`: a journal directory ``<path>.points/`` holding a header
and one small file per converged point, each written to a temporary name and renamed into place
(``os.replace`` is atomic on POSIX and Windows), so that a killed run leaves only complete files;
the finished branch is then saved to ``path`` and the journal removed.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .hbm.harmonics import Harmonics

__all__ = ["PeriodicSolution", "Branch", "load_branch", "FORMAT_VERSION", "Checkpoint", "CHECKPOINT_VERSION"]

FORMAT_VERSION = 1
#: Version of the checkpoint journal layout (header and point files), checked on resume.
CHECKPOINT_VERSION = 1
_CHECKPOINT_FORMAT = "femodes.Checkpoint"
_BRANCH_SUFFIXES = (".npz", ".h5", ".hdf5")


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
    def from_system(cls, system) -> "ContactInfo":
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

    @classmethod
    def from_json(cls, d: dict) -> "ContactInfo":
        return cls(*(tuple(d[k]) for k in ("kinds", "dofs", "gaps", "stiffness", "slots", "c")))


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
        The model (``None`` after loading from a file); needed only for :meth:`full_displacement`.
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
                out[:, j] = ci.stiffness[j] * np.maximum(0.0, u[:, ci.dofs[j]] - ci.gaps[j])
        return out

    def gap(self, t) -> np.ndarray:
        """Normal gaps ``g_N(t) = gap - q_c(t)``, shape ``(len(t), n_contacts)``."""
        u = self.displacement(t)
        ci = self.contacts
        return np.asarray(ci.gaps)[None, :] - u[:, list(ci.dofs)]

    def _fine_t(self) -> np.ndarray:
        n = max(2048, 64 * self.harmonics.n_coef)
        return np.arange(n) * (self.period / n)

    @property
    def penetration(self) -> float:
        """Max penetration ``max(0, max_t -g_N(t))`` over a fine time grid (0 without contacts)."""
        if not self.contacts.kinds:
            return 0.0
        return float(max(0.0, np.max(-self.gap(self._fine_t()))))

    @property
    def tension(self) -> float:
        """Max tension ``max(0, max_t -p(t))`` over a fine time grid (truncation artefact)."""
        if not self.contacts.kinds:
            return 0.0
        return float(max(0.0, np.max(-self.contact_force(self._fine_t()))))

    def amplitude(self, dof: int) -> float:
        """``max_t |q_dof(t)|`` over a fine grid."""
        return float(np.max(np.abs(self.displacement(self._fine_t())[:, dof])))

    def full_displacement(self, t) -> np.ndarray:
        """Displacement expanded to the full model (Craig-Bampton parents) DOFs."""
        if self.model is None:
            raise ValueError("full_displacement needs the model: this solution was loaded from a file; use Branch.attach(model)")
        q = self.displacement(t)
        m = self.model
        while getattr(m, "is_reduced", False):
            q = m.expand(q)
            m = m.parent
        return q


class Branch:
    """A branch of periodic solutions from continuation.

    Attributes (arrays over the points)
    -----------------------------------
    omega, energy, converged, nit, residual_norm, parameter, xi, penetration, tension;
    ``folds`` (indices), ``kind`` ("forced" or "nonlinear mode"), ``success``, ``message``.
    ``branch[i]`` is a :class:`PeriodicSolution`; ``len(branch)`` the number of points.
    """

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

    @property
    def converged(self) -> np.ndarray:
        """True for every stored point (only converged points are stored)."""
        return np.isfinite(self.residual_norm)

    def __len__(self) -> int:
        return self.omega.size

    def __getitem__(self, i: int) -> PeriodicSolution:
        if isinstance(i, slice) or not isinstance(i, (int, np.integer)):
            raise TypeError("Branch indices must be integers; use the array attributes for slices")
        i = range(len(self))[i]
        return PeriodicSolution(
            omega=float(self.omega[i]), Q=self.Q[i], P=self.P[i], harmonics=self.harmonics, contacts=self.contacts,
            energy=float(self.energy[i]), xi=float(self.xi[i]), residual_norm=float(self.residual_norm[i]),
            nit=int(self.nit[i]), model=self.model,
        )

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def amplitude(self, dof: int) -> np.ndarray:
        """``max_t |q_dof(t)|`` at every point."""
        n = max(512, 16 * self.harmonics.n_coef)
        E = self.harmonics.synthesis(2 * np.pi * np.arange(n) / n)
        return np.max(np.abs(E @ self.Q[:, :, dof].T), axis=0)

    @property
    def penetration(self) -> np.ndarray:
        return np.array([s.penetration for s in self])

    @property
    def tension(self) -> np.ndarray:
        return np.array([s.tension for s in self])

    def attach(self, model) -> "Branch":
        """Attach the model (after :func:`load_branch`) so solutions can expand to the full field."""
        from .model import StructuralModel

        if not isinstance(model, StructuralModel):
            raise TypeError(f"attach: model must be the StructuralModel the branch was solved on, got {type(model).__name__}")
        if model.n_dofs != self.Q.shape[2]:
            raise ValueError(f"attach: model has {model.n_dofs} DOFs but the branch was solved on {self.Q.shape[2]}")
        self.model = model
        return self

    def __repr__(self) -> str:
        return (f"Branch({self.kind}, {len(self)} points, omega in [{self.omega.min() if len(self) else np.nan:.6g}, "
                f"{self.omega.max() if len(self) else np.nan:.6g}], folds={list(self.folds)}, success={self.success})")

    # -- persistence -------------------------------------------------------------------------
    def _arrays(self) -> dict:
        return {
            "omega": self.omega, "Q": self.Q, "P": self.P, "energy": self.energy, "xi": self.xi,
            "residual_norm": self.residual_norm, "nit": self.nit, "parameter": self.parameter,
            "folds": np.asarray(self.folds, dtype=int),
        }

    def _header(self) -> dict:
        return {
            "format": "femodes.Branch", "version": FORMAT_VERSION, "kind": self.kind,
            "harmonics": [self.harmonics.n_harmonics, self.harmonics.n_time, self.harmonics.subharmonic],
            "contacts": self.contacts.to_json(), "success": self.success, "status": self.status,
            "message": self.message, "meta": self.meta,
        }

    def save(self, path) -> Path:
        """Write the branch atomically to ``.npz`` or ``.h5``/``.hdf5`` (needs h5py)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        suffix = path.suffix.lower()
        if suffix not in _BRANCH_SUFFIXES:
            raise ValueError(f"Branch.save: use a .npz or .h5 file name, got {str(path)!r}")
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
        os.close(fd)
        try:
            header = json.dumps(self._header())
            if suffix == ".npz":
                with open(tmp, "wb") as f:
                    np.savez_compressed(f, header=np.array(header), **self._arrays())
            else:
                try:
                    import h5py
                except ImportError as exc:
                    raise ImportError("saving .h5 needs h5py (pip install 'femodes[store]'), or use a .npz file name") from exc
                with h5py.File(tmp, "w") as f:
                    f.attrs["header"] = header
                    for k, v in self._arrays().items():
                        # fletcher32 checksums: a damaged file is detected on load, not read silently
                        f.create_dataset(k, data=v, fletcher32=True, compression="gzip" if v.size > 1000 else None)
            os.replace(tmp, path)  # atomic: a crash never leaves a half-written file under `path`
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)
        return path


def load_branch(path, model=None) -> Branch:
    """Read a branch written by :meth:`Branch.save`; ``model`` optionally re-attached."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"load_branch: no such file {str(path)!r}")
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as f:
                header = json.loads(str(f["header"]))
                arrays = {k: f[k] for k in f.files if k != "header"}
        else:
            import h5py

            with h5py.File(path, "r") as f:
                header = json.loads(f.attrs["header"])
                arrays = {k: f[k][()] for k in f.keys()}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error, json.JSONDecodeError) as exc:
        raise ValueError(f"load_branch: {str(path)!r} is not a readable femodes branch file ({exc})") from exc
    if header.get("format") != "femodes.Branch":
        raise ValueError(f"load_branch: {str(path)!r} is not a femodes branch file")
    if header.get("version") != FORMAT_VERSION:
        raise ValueError(
            f"load_branch: {str(path)!r} has format version {header.get('version')}, this femodes reads version {FORMAT_VERSION}"
        )
    H, N, nu = header["harmonics"]
    br = Branch(
        kind=header["kind"], harmonics=Harmonics(H, N, nu), contacts=ContactInfo.from_json(header["contacts"]),
        omega=arrays["omega"], Q=arrays["Q"], P=arrays["P"], energy=arrays["energy"], xi=arrays["xi"],
        residual_norm=arrays["residual_norm"], nit=arrays["nit"], parameter=arrays["parameter"],
        folds=arrays["folds"].tolist(), success=header["success"], status=header["status"], message=header["message"],
        meta=header.get("meta"),
    )
    if model is not None:
        br.attach(model)
    return br


# ------------------------------------------------------------------------------------------------
# checkpoint journal of a running continuation
# ------------------------------------------------------------------------------------------------
_READ_ERRORS = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error, json.JSONDecodeError)


class Checkpoint:
    """Journal of a running continuation next to its final branch file ``path``.

    Layout: ``<path>.points/header.json`` (format, version and a JSON description of the run)
    and ``<path>.points/<index:08d>.npz``, one uncompressed ``.npz`` of named arrays per point.
    Every file is written to a unique ``*.tmp`` name, flushed to disk (``fsync``) and renamed
    into place, so a crash at any moment leaves complete files (plus perhaps a ``*.tmp`` that
    readers ignore); writing a point costs O(size of the point), independently of the branch
    length. The zip CRC-32 of every member is checked on reading, so a damaged point is
    reported, not read. When the run ends, :meth:`finish` saves the branch to ``path``
    (:meth:`Branch.save`, itself atomic) and only then removes the journal.

    The journal knows nothing about continuation: the caller decides what a point holds
    (:mod:`femodes.analyses` stores the unknowns and the continuation state).

    Parameters
    ----------
    path : str or PathLike
        Final branch file, ``.npz`` or ``.h5``/``.hdf5``.
    """

    def __init__(self, path):
        path = Path(path)
        if path.suffix.lower() not in _BRANCH_SUFFIXES:
            raise ValueError(f"checkpoint: use a .npz or .h5 file name for the final branch, got {str(path)!r}")
        self.path = path
        self.journal = path.with_name(path.name + ".points")

    def __repr__(self) -> str:
        return f"Checkpoint({str(self.path)!r})"

    @property
    def header_path(self) -> Path:
        return self.journal / "header.json"

    def point_path(self, index: int) -> Path:
        return self.journal / f"{int(index):08d}.npz"

    # -- writing -----------------------------------------------------------------------------
    def _write_atomic(self, target: Path, write) -> None:
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=target.name + ".", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                write(f)
                f.flush()
                os.fsync(f.fileno())  # the data is on disk before the rename makes it visible
            os.replace(tmp, target)
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)

    def create(self, description: dict) -> None:
        """Start a new journal (the directory must not hold one) with ``description`` in its header."""
        self.journal.mkdir(parents=True, exist_ok=True)
        if self.header_path.exists():
            raise FileExistsError(f"checkpoint: {str(self.journal)!r} already holds a journal")
        header = {"format": _CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "run": description}
        text = json.dumps(header, indent=1).encode()
        self._write_atomic(self.header_path, lambda f: f.write(text))

    def write_point(self, index: int, arrays: dict) -> Path:
        """Write point ``index`` (a dict of arrays; an ``index`` member is added) atomically."""
        target = self.point_path(index)
        arrays = dict(arrays, index=np.asarray(int(index)))
        self._write_atomic(target, lambda f: np.savez(f, **arrays))
        return target

    # -- reading -----------------------------------------------------------------------------
    def read_header(self) -> dict:
        """The description of the run; ``ValueError`` for a damaged header or another version."""
        where = str(self.header_path)
        try:
            header = json.loads(self.header_path.read_text())
        except FileNotFoundError:
            raise ValueError(f"checkpoint: {str(self.journal)!r} has no header.json (not a femodes checkpoint, "
                             "or damaged); delete the directory to start over") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"checkpoint: header {where!r} is damaged ({exc})") from exc
        if not isinstance(header, dict) or header.get("format") != _CHECKPOINT_FORMAT or not isinstance(
                header.get("run"), dict):
            raise ValueError(f"checkpoint: {where!r} is not a femodes checkpoint header")
        if header.get("version") != CHECKPOINT_VERSION:
            raise ValueError(f"checkpoint: {where!r} has checkpoint version {header.get('version')!r}, this femodes "
                             f"reads version {CHECKPOINT_VERSION}; finish that run with the femodes that started it, "
                             "or delete the directory to start over")
        return header["run"]

    def indices(self) -> list[int]:
        """Indices of the complete point files, ascending (``*.tmp`` leftovers are ignored)."""
        out = []
        for p in self.journal.glob("*.npz"):
            if p.stem.isdigit():
                out.append(int(p.stem))
        return sorted(out)

    def read_point(self, index: int, required: tuple = ()) -> dict:
        """Arrays of point ``index``; ``ValueError`` naming the file if it is damaged or incomplete."""
        path = self.point_path(index)
        try:
            with np.load(path, allow_pickle=False) as f:
                arrays = {k: f[k] for k in f.files}  # reads every member: the zip CRC-32 is checked
        except _READ_ERRORS as exc:
            raise ValueError(f"checkpoint: point file {str(path)!r} is damaged ({type(exc).__name__}: {exc}); "
                             "delete it and the points after it to resume from the point before") from exc
        missing = [k for k in ("index", *required) if k not in arrays]
        if missing:
            raise ValueError(f"checkpoint: point file {str(path)!r} is damaged (missing {', '.join(missing)})")
        if arrays["index"].shape != () or int(arrays["index"]) != index:
            raise ValueError(f"checkpoint: point file {str(path)!r} is damaged (it holds index {arrays['index']!r})")
        return arrays

    def read_points(self, required: tuple = ()) -> list[dict]:
        """All points ``0..k``; a missing index is reported as a ``ValueError``."""
        idx = self.indices()
        if idx != list(range(len(idx))):
            gap = next(i for i, j in enumerate(idx) if i != j)
            raise ValueError(f"checkpoint: {str(self.journal)!r} lacks point file {self.point_path(gap).name} "
                             f"(has {len(idx)} point files up to index {idx[-1]}); it is damaged")
        return [self.read_point(i, required) for i in idx]

    # -- maintenance -------------------------------------------------------------------------
    def discard(self, after: int) -> None:
        """Remove the point files with index > ``after`` and leftover temporary files."""
        for i in self.indices():
            if i > after:
                self.point_path(i).unlink()
        for p in self.journal.glob("*.tmp"):
            p.unlink(missing_ok=True)

    def finish(self, branch: "Branch") -> Path:
        """Save the final branch to ``path`` (atomically), then remove the journal."""
        branch.save(self.path)
        self.remove_journal()
        return self.path

    def remove_journal(self) -> None:
        if not self.journal.is_dir():
            return
        for p in self.journal.iterdir():
            if p.name == "header.json" or p.suffix in (".npz", ".tmp"):
                p.unlink(missing_ok=True)
        try:
            self.journal.rmdir()
        except OSError:  # a file we did not write: leave the directory to the user
            pass
