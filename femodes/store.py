"""Results layer: persistence of results (files written safely, checkpoint journals).

Every file femodes saves (branches, checkpoint journals, sweep studies, ParaView collections)
goes through :func:`atomic_write`: the data is written to a temporary file in the target's folder
and renamed over the target, so a crash or a full disk never leaves a half-written file under the
target's name, and readers see either the old or the new file. :func:`write_record` and
:func:`read_record` store a JSON header with named arrays (``.npz`` or ``.h5``). :class:`Checkpoint`
is what a user passes to ``checkpoint=`` of the long analyses (a file name, and whether to resume);
:class:`CheckpointStore` is the journal of a running continuation next to that file, locked while
a run uses it (:func:`file_lock`: a second run is refused, not raced). :func:`model_fingerprint`
and :func:`model_signature` hash what defines a model's equations, so that a checkpoint or a saved
branch is only ever resumed or reattached with the model that produced it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import tempfile
import zipfile
import zlib
from pathlib import Path
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

__all__ = ["atomic_write", "write_record", "read_record", "Checkpoint", "CheckpointStore", "CheckpointInUse",
           "FileInUse", "file_lock", "CHECKPOINT_VERSION", "RECORD_SUFFIXES", "model_fingerprint", "model_signature",
           "signature_differences"]

#: Version of the checkpoint journal layout (header.json + one .npz per point).
CHECKPOINT_VERSION = 1
_CHECKPOINT_FORMAT = "femodes.Checkpoint"
#: What reading a damaged or foreign file raises.
READ_ERRORS = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error, json.JSONDecodeError)
#: File names a record (and so a branch) can be saved under.
RECORD_SUFFIXES = (".npz", ".h5", ".hdf5")


def _file_mode() -> int:
    """Permissions of a newly created file under the process' umask (as ``open`` would give).

    ``tempfile.mkstemp`` creates its file with mode 0600; without this the saved results would be
    private while every other output (plots, VTK frames) is readable under the usual umask.
    """
    try:  # Linux: read the umask without changing it (os.umask flips it process-wide, a race for
        # other threads creating files meanwhile, e.g. a sweep on a thread pool)
        with open("/proc/self/status", encoding="ascii") as f:
            mask = next(int(line.split()[1], 8) for line in f if line.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        mask = os.umask(0o022)
        os.umask(mask)
    return 0o666 & ~mask


def atomic_write(target, write: Callable[[str], object], *, durable: bool = False) -> Path:
    """Write ``target`` through ``write(tmp_name)`` and rename the result over ``target``.

    ``write`` receives the name of a new empty file in ``target``'s folder (libraries such as
    h5py open files by name). With ``durable`` the data is flushed to disk (``fsync``) before the
    rename, so that after a power loss the target is either the old or the complete new file.
    The target gets the permissions a plain ``open`` would give it (``0666 & ~umask``).
    """
    target = Path(target)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=target.name + ".", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        if durable:
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
        os.chmod(tmp, _file_mode())
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return target


def write_record(path, header: dict, arrays: dict) -> Path:
    """Write a JSON ``header`` and named arrays atomically to ``.npz`` (compressed) or
    ``.h5``/``.hdf5`` (needs h5py; Fletcher-32 checksums, so a damaged file is detected on
    reading, not read silently)."""
    path = Path(path)
    text = json.dumps(header)

    def write(tmp: str) -> None:
        if path.suffix.lower() == ".npz":
            with open(tmp, "wb") as f:
                np.savez_compressed(f, header=np.array(text), **arrays)
            return
        try:
            import h5py
        except ImportError as exc:
            raise ImportError(f"saving {path.name} needs h5py (pip install 'femodes[store]'), or use a .npz file "
                              "name") from exc
        with h5py.File(tmp, "w") as f:
            f.attrs["header"] = text
            for k, v in arrays.items():
                f.create_dataset(k, data=v, fletcher32=True, compression="gzip" if v.size > 1000 else None)

    return atomic_write(path, write)


def read_record(path) -> tuple[dict, dict]:
    """``(header, arrays)`` of a file written by :func:`write_record`; ValueError if it cannot be
    read (damaged, truncated, not such a file)."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as f:
                return json.loads(str(f["header"])), {k: f[k] for k in f.files if k != "header"}
        import h5py

        with h5py.File(path, "r") as f:
            return json.loads(f.attrs["header"]), {k: f[k][()] for k in f.keys()}
    except READ_ERRORS as exc:
        raise ValueError(str(exc)) from exc


# ------------------------------------------------------------------------------------------------
# what a saved result is tied to: hashes of the model it was solved on
# ------------------------------------------------------------------------------------------------
def _digest(*parts: bytes) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(len(part).to_bytes(8, "little"))
        h.update(part)
    return h.hexdigest()[:20]


def _matrix_bytes(A) -> list[bytes]:
    A = sp.csr_matrix(A, dtype=float, copy=True)
    A.sum_duplicates()
    A.sort_indices()
    return [np.asarray(A.shape, dtype=np.int64).tobytes(), A.indptr.astype(np.int64).tobytes(),
            A.indices.astype(np.int64).tobytes(), A.data.tobytes()]


def _declarations(items) -> bytes:
    """Canonical bytes of attached laws (type, DOF and parameters; ``at`` is the DOF)."""
    out = []
    for a in items:
        law = a.item
        params = {f.name: repr(getattr(law, f.name)) for f in dataclasses.fields(law) if f.name != "at"} \
            if dataclasses.is_dataclass(law) else {"repr": repr(law)}
        out.append([type(law).__name__, int(a.dof), params])
    return json.dumps(out, sort_keys=True).encode()


def model_fingerprint(model) -> dict:
    """Short hashes of what defines a model's equations: matrices, forcing, contacts, nonlinearities.

    Stored in checkpoints (and their final branch files) so that resuming with another model is
    refused with a message saying which part differs. ``model`` is a
    :class:`~femodes.StructuralModel` (or a reduced model): only its matrices, force vectors and
    attached laws are read.
    """
    forces = model.force_vectors()
    lr_bytes = _lowrank_bytes(model)
    force_bytes = [np.int64(k).tobytes() + np.asarray(forces[k], dtype=complex).tobytes() for k in sorted(forces)]
    return {
        "n_dofs": int(model.n_dofs),
        "matrices": _digest(*_matrix_bytes(model.M), *_matrix_bytes(model.K), *_matrix_bytes(model.C), *lr_bytes),
        "forcing": _digest(*force_bytes),
        "contacts": _digest(_declarations(model.contacts)),
        "nonlinearities": _digest(_declarations(model.nonlinearities)),
    }

#: The parts of :func:`model_signature` in the words of the messages that name a difference.
_SIGNATURE_PARTS = {"n_dofs": "number of DOFs", "mass": "mass matrix M", "stiffness": "stiffness matrix K",
                    "damping": "damping (C, Rayleigh or modal)", "forcing": "forcing",
                    "contacts": "contact laws", "nonlinearities": "nonlinear laws (springs)"}


def model_signature(model) -> dict:
    """:func:`model_fingerprint` plus one hash per matrix (``mass``, ``stiffness``, ``damping``):
    what a saved branch stores of the model it was solved on, so that attaching another model
    is refused naming the part that differs (:meth:`femodes.Branch.attach`)."""
    return dict(model_fingerprint(model), mass=_digest(*_matrix_bytes(model.M)),
                stiffness=_digest(*_matrix_bytes(model.K)),
                damping=_digest(*_matrix_bytes(model.C), *_lowrank_bytes(model)))


def _lowrank_bytes(model) -> list[bytes]:
    """The bytes of modal damping's low-rank part (none when absent: older digests hold)."""
    lr = model.C_lowrank
    return [] if lr is None else [np.asarray(lr.U.shape, dtype=np.int64).tobytes(), lr.U.tobytes(), lr.d.tobytes()]


def signature_differences(saved: dict, current: dict) -> list[str]:
    """The parts (in words) in which two :func:`model_signature` dicts differ; parts that one of
    them lacks are not compared (``matrices`` only when neither names its matrices)."""
    keys = [k for k in _SIGNATURE_PARTS if k in saved and k in current]
    out = [_SIGNATURE_PARTS[k] for k in keys if saved[k] != current[k]]
    if not any(k in keys for k in ("mass", "stiffness", "damping")) and "matrices" in saved and "matrices" in current \
            and saved["matrices"] != current["matrices"]:
        out.append("matrices (M, K or C)")
    return out


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """Where a long continuation saves its points, and whether to continue an earlier run.

    Pass it as ``checkpoint=`` to :func:`~femodes.frequency_response` or
    :func:`~femodes.nonlinear_mode`; a plain path there means ``Checkpoint(path)``. Checked at
    construction: a bad value raises here, before anything runs.

    Parameters
    ----------
    path : str or PathLike
        Final branch file, ``.npz`` or ``.h5`` (``.hdf5``); the points go to the journal
        ``<path>.points/`` while the run goes on. Stored as a :class:`pathlib.Path`.
    resume : bool, keyword-only
        ``False`` (default): a new run; an existing checkpoint (final file or journal) is a
        ``FileExistsError``, never overwritten. ``True``: continue the run from its last saved
        point, or return its branch if it finished; start a new run if nothing is saved yet.

    Examples
    --------
    >>> ck = Checkpoint("out/frc.npz", resume=True)
    >>> ck.path.name, ck.resume
    ('frc.npz', True)
    """

    path: str | os.PathLike  # stored as a pathlib.Path
    resume: bool = dataclasses.field(default=False, kw_only=True)

    def __post_init__(self):
        if not isinstance(self.path, (str, os.PathLike)):
            raise TypeError(f"Checkpoint: path must be a file name (.npz or .h5), got {self.path!r}")
        path = Path(self.path)
        if path.suffix.lower() not in RECORD_SUFFIXES:
            raise ValueError(f"Checkpoint: path must be a .npz or .h5 file name (the final branch), got {str(path)!r}")
        if not isinstance(self.resume, bool):
            raise TypeError(f"Checkpoint: resume must be True or False, got {self.resume!r}")
        object.__setattr__(self, "path", path)


class FileInUse(RuntimeError):
    """Another process holds the lock (:func:`file_lock`) of what this one was to write."""


class CheckpointInUse(FileInUse):
    """Another process runs the checkpoint (it holds the lock :meth:`CheckpointStore.lock`)."""


@contextlib.contextmanager
def file_lock(path, refuse: Callable[[str], Exception]):
    """Hold an exclusive lock (``fcntl.flock``, POSIX; a no-op elsewhere) on the file ``path``,
    which holds the holder's process id and is removed on release; if another process holds it,
    raise ``refuse(holder_pid)`` at once (never wait: a second run on the same files is a mistake
    to report, not to queue)."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock (atomic writes still hold)
        yield
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        f = open(path, "a+")
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            holder = f.read().strip() or "?"
            f.close()
            raise refuse(holder) from None
        try:  # the holder before us may have removed the file after we opened it: lock the current one
            same = os.stat(path).st_ino == os.fstat(f.fileno()).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        f.close()
    try:
        f.seek(0)
        f.truncate()
        f.write(str(os.getpid()))
        f.flush()
        yield
    finally:
        with contextlib.suppress(OSError):
            os.remove(path)  # while still locked: an opener of the old file sees another inode and retries
        f.close()


def _write_durable(target: Path, write) -> None:
    """Write a journal file through ``write(binary file)`` durably (fsync before the rename): the
    journal is what survives a crash."""

    def to_file(tmp: str) -> None:
        with open(tmp, "wb") as f:
            write(f)

    atomic_write(target, to_file, durable=True)


class CheckpointStore:
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
    (:mod:`femodes.runs` stores the unknowns and the continuation state). Users do not make one:
    they pass a :class:`Checkpoint` (or a path) to the analyses.

    Parameters
    ----------
    path : str or PathLike
        Final branch file, ``.npz`` or ``.h5``/``.hdf5``.
    """

    def __init__(self, path):
        path = Path(path)
        if path.suffix.lower() not in RECORD_SUFFIXES:
            raise ValueError(f"checkpoint: use a .npz or .h5 file name for the final branch, got {str(path)!r}")
        self.path = path
        self.journal = path.with_name(path.name + ".points")

    def __repr__(self) -> str:
        return f"CheckpointStore({str(self.path)!r})"

    @property
    def lock_path(self) -> Path:
        return self.path.with_name(self.path.name + ".lock")

    def lock(self, label: str = "checkpoint"):
        """Hold an exclusive lock on the checkpoint for a run (:func:`file_lock` on ``<path>.lock``):
        a second run on the same checkpoint raises :class:`CheckpointInUse` at once instead of
        reading a journal the first one removes."""
        return file_lock(self.lock_path, lambda holder: CheckpointInUse(
            f"{label}: checkpoint {str(self.path)!r} is in use by another run (process {holder}); wait for that run "
            "to finish, or use another checkpoint file"))

    @property
    def header_path(self) -> Path:
        return self.journal / "header.json"

    def point_path(self, index: int) -> Path:
        return self.journal / f"{int(index):08d}.npz"

    # -- writing -----------------------------------------------------------------------------
    def create(self, description: dict) -> None:
        """Start a new journal (the directory must not hold one) with ``description`` in its header."""
        self.journal.mkdir(parents=True, exist_ok=True)
        if self.header_path.exists():
            raise FileExistsError(f"checkpoint: {str(self.journal)!r} already holds a journal")
        header = {"format": _CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "run": description}
        text = json.dumps(header, indent=1).encode()
        _write_durable(self.header_path, lambda f: f.write(text))

    def write_point(self, index: int, arrays: dict) -> Path:
        """Write point ``index`` (a dict of arrays; an ``index`` member is added) atomically."""
        target = self.point_path(index)
        arrays = dict(arrays, index=np.asarray(int(index)))
        _write_durable(target, lambda f: np.savez(f, **arrays))
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
        except READ_ERRORS as exc:
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

    def finish(self, branch) -> Path:
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
