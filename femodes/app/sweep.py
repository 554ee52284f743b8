"""Application layer: parameter sweeps of a case file over many independent continuations.

A sweep is a base case file (:mod:`femodes.app.cases`) plus parameter values. A parameter is a
dotted path into the case file: ``table.key`` for plain tables (``analysis.harmonics``,
``mesh.n_elements``, ``damping.alpha``) and ``table.index.key`` for ``[[...]]`` tables
(``contact.0.gap``, ``force.0.amplitude``). The cases are the Cartesian product of the value
lists, or an explicit list of ``{path: value}`` dicts. Every case is re-checked by the case-file
machinery (the overridden case is written as TOML and parsed by :func:`~femodes.app.cases.parse_case`),
so a sweep accepts exactly what ``femodes run`` accepts.

Each case runs as one task: a top-level function of plain data (case text, folder) that runs
:func:`~femodes.app.cases.run_case` and writes ``out/cases/<id>/`` (``case.toml``, the exact case
that ran; ``branch.npz``; ``summary.txt``) and returns a small summary. A task that raises is
reported with its error; the other cases complete. The summaries are gathered into one study
file, ``out/study.npz`` (or ``.h5``), written atomically and read back by :func:`load_study`.

Where the tasks run: an embedded :class:`distributed.LocalCluster` (``n_workers`` single-threaded
worker processes) by default, an existing Dask cluster (``scheduler="tcp://host:8786"``), a
:class:`distributed.Client`, or any :class:`concurrent.futures.Executor` (thread or process pool).
With a remote cluster, ``out`` must be on a file system the workers share.

Worker environment of the embedded cluster (:func:`local_cluster`), measured in
``benchmarks/README_sweep.md``:

* Dask's nanny exports ``MALLOC_TRIM_THRESHOLD_=65536`` to its workers (config
  ``distributed.nanny.pre-spawn-environ``) so that they hand freed memory back to the OS. Setting
  any glibc malloc threshold explicitly also switches off glibc's *dynamic* mmap threshold
  (mallopt(3), "M_MMAP_THRESHOLD"), so every numpy temporary above 128 KiB is mmap'ed, page-faulted
  and unmapped again. Harmonic balance of FE models allocates such temporaries at every Newton
  step: a 1000-DOF bar (H = 10) needed 1.9x the CPU time per task (1.4 million page faults instead
  of a few hundred per case); a 1-DOF oscillator, whose arrays are a few KiB, 1.15x. The sweep
  cluster leaves the variable unset.
* The start of an embedded cluster costs about 2 s (processes, imports, shutdown): for short or
  repeated sweeps, keep one (``with local_cluster() as c, Client(c) as client:``) and pass it.
* One BLAS thread per worker (``OMP/MKL/OPENBLAS_NUM_THREADS=1``): the workers already use the
  cores, a multithreaded BLAS in each would oversubscribe them.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import itertools
import json
import logging
import math
import os
import re
import socket
import tempfile
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .cases import ARRAY_TABLES, SCHEMA, Case, CaseError, load_case, parse_case

__all__ = ["run_sweep", "SweepResult", "CaseRecord", "load_study", "save_study", "local_cluster", "run_sweep_case",
           "sweep_cases", "apply_overrides", "parse_set", "to_toml", "WORKER_ENVIRON", "STUDY_VERSION"]

log = logging.getLogger(__name__)

STUDY_VERSION = 1

# Environment of the embedded cluster's worker processes, set before they start (see the module
# docstring). ``None`` removes a variable from Dask's default ``pre-spawn-environ``.
WORKER_ENVIRON: dict[str, str | None] = {
    "MALLOC_TRIM_THRESHOLD_": None,  # keep glibc's dynamic mmap threshold (1.9x faster FE HBM tasks)
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
}

# Outputs of every sweep case: the branch only (plots and animations of many cases would cost
# more than the analyses; rerun one case with ``femodes run out/cases/<id>/case.toml`` for them).
_CASE_OUTPUTS = {"plot": False, "branch": "branch.npz", "animation": False, "gif": False}


# ---------------------------------------------------------------------------------------------
# Records
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CaseRecord:
    """Summary of one sweep case.

    ``status`` is ``"ok"`` (branch complete), ``"incomplete"`` (branch saved, continuation stopped
    before the end of the span: see ``message``), ``"failed"`` (no branch; ``message`` is the
    error) or ``"pending"`` (not finished: the study file of an interrupted sweep). ``wall_time`` and ``cpu_time`` (of the thread that ran it, so robust to a loaded
    machine) are the task's, in seconds, measured in its worker (``worker`` = host:pid).
    ``branch`` is the branch file relative to the study file's folder ("" if none). The numbers
    summarise the branch: frequency and energy ranges, ``max_amplitude`` = max over the branch of
    ``max_t |q(t)|`` at ``amplitude_dof`` (``[outputs] response_dof``, else the first force, else
    the first contact DOF), ``max_penetration`` of the contacts; NaN when failed.
    """

    id: str
    parameters: dict
    status: str
    message: str = ""
    n_points: int = 0
    wall_time: float = math.nan
    cpu_time: float = math.nan
    branch: str = ""
    omega_min: float = math.nan
    omega_max: float = math.nan
    energy_min: float = math.nan
    energy_max: float = math.nan
    max_amplitude: float = math.nan
    amplitude_dof: str = ""
    n_folds: int = 0
    max_penetration: float = math.nan
    worker: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "ok"


_NUMERIC = ("n_points", "wall_time", "cpu_time", "omega_min", "omega_max", "energy_min", "energy_max",
            "max_amplitude", "n_folds", "max_penetration")
_TEXT = ("id", "status", "message", "branch", "amplitude_dof", "worker")


@dataclass(frozen=True)
class SweepResult:
    """All cases of a sweep, in case order, and where the study file is.

    ``result[i]`` / ``result["c003"]`` is a :class:`CaseRecord`; ``result.column("max_amplitude")``
    an array over the cases; ``result.load_branch(i)`` reads a case's branch; ``result.table()``
    a text table.
    """

    cases: tuple
    parameters: tuple
    study: Path
    case: str = ""
    elapsed: float = math.nan

    def __len__(self) -> int:
        return len(self.cases)

    def __iter__(self):
        return iter(self.cases)

    def __getitem__(self, key: int | str) -> CaseRecord:
        if isinstance(key, str):
            for r in self.cases:
                if r.id == key:
                    return r
            raise KeyError(f"SweepResult: no case with id {key!r}; ids are {[r.id for r in self.cases]}")
        return self.cases[key]

    @property
    def success(self) -> bool:
        """True if every case ran to the end of its span."""
        return all(r.ok for r in self.cases)

    @property
    def failed(self) -> tuple:
        """The records whose status is not ``"ok"``."""
        return tuple(r for r in self.cases if not r.ok)

    def column(self, name: str) -> np.ndarray:
        """A record field (or a parameter path) as an array over the cases."""
        if name in self.parameters:
            return np.array([r.parameters.get(name) for r in self.cases], dtype=object)
        names = [f.name for f in fields(CaseRecord) if f.name != "parameters"]
        if name not in names:
            raise KeyError(f"SweepResult.column: unknown column {name!r}; columns are {names} "
                           f"and the parameters {list(self.parameters)}")
        return np.array([getattr(r, name) for r in self.cases])

    def load_branch(self, key: int | str):
        """The saved :class:`femodes.Branch` of a case (by index or id)."""
        from ..results import load_branch

        rec = self[key]
        if not rec.branch:
            raise ValueError(f"SweepResult.load_branch: case {rec.id} has no branch ({rec.status}: {rec.message})")
        return load_branch(self.study.parent / rec.branch)

    def table(self, max_message: int = 60) -> str:
        """Text table: id, parameter values, status, points, frequency range, amplitude, time, message."""
        head = ["id", *self.parameters, "status", "points", "w range [rad/s]", "max amp", "time [s]", "message"]
        rows = []
        for r in self.cases:
            w = f"{r.omega_min:.4g}..{r.omega_max:.4g}" if r.n_points else "-"
            msg = r.message if len(r.message) <= max_message else r.message[: max_message - 3] + "..."
            rows.append([r.id, *(_fmt_value(r.parameters.get(p)) for p in self.parameters), r.status, str(r.n_points),
                         w, f"{r.max_amplitude:.6g}" if r.n_points else "-", f"{r.wall_time:.2f}", msg])
        widths = [max(len(h), *(len(row[j]) for row in rows)) if rows else len(h) for j, h in enumerate(head)]
        fmt = lambda row: "  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip()  # noqa: E731
        return "\n".join([fmt(head), fmt(["-" * w for w in widths]), *map(fmt, rows)])


def _fmt_value(v: Any) -> str:
    return "-" if v is None else json.dumps(v) if isinstance(v, (str, list, dict)) else str(v)


# ---------------------------------------------------------------------------------------------
# Parameters and overrides
# ---------------------------------------------------------------------------------------------
def _plain(v: Any, where: str) -> Any:
    """``v`` as a TOML-representable Python value (numpy scalars and arrays converted)."""
    if isinstance(v, np.ndarray):
        v = v.tolist()
    elif isinstance(v, np.generic):
        v = v.item()
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    if isinstance(v, (list, tuple)):
        return [_plain(x, where) for x in v]
    if isinstance(v, Mapping):
        return {str(k): _plain(x, where) for k, x in v.items()}
    raise TypeError(f"parameters: value {v!r} of {where!r} is not a number, string, boolean, list or table")


def _parse_path(path: Any) -> tuple[str, int | None, str]:
    """``"contact.0.gap"`` -> ``("contact", 0, "gap")``; ValueError naming the path otherwise."""
    if not isinstance(path, str):
        raise TypeError(f"parameters: a parameter path must be a string like 'contact.0.gap', got {path!r}")
    parts = path.split(".")
    tables = ", ".join(f"{t}.<index>" if t in ARRAY_TABLES else t for t in SCHEMA)
    if parts[0] not in SCHEMA:
        raise ValueError(f"parameters: unknown table {parts[0]!r} in path {path!r}; valid tables are {tables}")
    table = parts[0]
    keys = ", ".join(SCHEMA[table])
    if table in ARRAY_TABLES:
        if len(parts) != 3 or not re.fullmatch(r"\d+", parts[1]):
            raise ValueError(f"parameters: path {path!r} must look like '{table}.<index>.<key>' ([[{table}]] is a "
                             f"list of tables; index 0 is the first), with a key among {keys}")
        index, key = int(parts[1]), parts[2]
    else:
        if len(parts) != 2:
            raise ValueError(f"parameters: path {path!r} must look like '{table}.<key>' with a key among {keys}")
        index, key = None, parts[1]
    if key not in SCHEMA[table]:
        raise ValueError(f"parameters: unknown key {key!r} in path {path!r}; valid keys of [{table}] are {keys}")
    if table == "outputs" and key in _CASE_OUTPUTS:
        raise ValueError(f"parameters: path {path!r} is set by the sweep (each case saves its branch only)")
    return table, index, key


def apply_overrides(data: Mapping, overrides: Mapping[str, Any]) -> dict:
    """Copy of a parsed case dict with ``{path: value}`` overrides applied (``None`` removes a key).

    Raises ValueError naming the path if it does not address the case (unknown table or key, or a
    ``[[table]]`` index beyond the tables of the case).
    """
    new = json.loads(json.dumps(data))  # deep copy of plain TOML data
    for path, value in overrides.items():
        table, index, key = _parse_path(path)
        value = _plain(value, path)
        if index is None:
            tab = new.setdefault(table, {})
        else:
            tabs = new.get(table, [])
            if isinstance(tabs, dict):
                tabs = new[table] = [tabs]
            if index >= len(tabs):
                raise ValueError(f"parameters: path {path!r} addresses [[{table}]] number {index + 1} but the case has "
                                 f"{len(tabs)} [[{table}]] table{'s' if len(tabs) != 1 else ''} (indices start at 0)")
            tab = tabs[index]
        if value is None:
            tab.pop(key, None)
        else:
            tab[key] = value
    return new


def sweep_cases(parameters: Mapping[str, Sequence] | Sequence[Mapping[str, Any]]) -> list[dict]:
    """The list of ``{path: value}`` overrides of a sweep.

    ``parameters`` is either ``{path: [values, ...]}`` (the Cartesian product, first path varying
    slowest) or an explicit sequence of ``{path: value}`` dicts. Paths are checked for syntax here
    and against the case in :func:`apply_overrides`.
    """
    if isinstance(parameters, Mapping):
        if not parameters:
            raise ValueError("parameters: give at least one parameter path with a list of values")
        lists = []
        for path, values in parameters.items():
            _parse_path(path)
            if isinstance(values, (str, bytes, Mapping)) or not isinstance(values, (Sequence, np.ndarray)):
                raise TypeError(f"parameters: the values of {path!r} must be a list, got {values!r} (a pair like "
                                f"omega is one value: {{'analysis.omega': [[0.5, 2.0], [0.5, 1.5]]}})")
            if len(values) == 0:
                raise ValueError(f"parameters: {path!r} has an empty list of values")
            lists.append([_plain(v, path) for v in values])
        return [dict(zip(parameters, combo)) for combo in itertools.product(*lists)]
    if isinstance(parameters, (str, bytes)) or not isinstance(parameters, Sequence):
        raise TypeError(f"parameters: expected {{path: [values]}} or a list of {{path: value}} dicts, got "
                        f"{type(parameters).__name__}")
    if not parameters:
        raise ValueError("parameters: the list of cases is empty")
    out = []
    for i, p in enumerate(parameters):
        if not isinstance(p, Mapping):
            raise TypeError(f"parameters: case {i} must be a {{path: value}} dict, got {p!r}")
        for path in p:
            _parse_path(path)
        out.append({path: _plain(v, path) for path, v in p.items()})
    return out


def _split_top(text: str) -> list[str]:
    """Split at commas outside brackets, braces and quotes."""
    items, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append("".join(cur))
            cur = []
            continue
        cur.append(ch)
    items.append("".join(cur))
    return [i.strip() for i in items]


def parse_set(text: str) -> tuple[str, list]:
    """``"contact.0.gap=0.005,0.01"`` -> ``("contact.0.gap", [0.005, 0.01])`` (the ``--set`` syntax).

    Values are TOML values separated by commas outside brackets (``analysis.omega=[0.5,2],[1,2]``
    is two pairs); a bare word is a string (``force.0.at=tip``). Raises ValueError with a message
    for the command line.
    """
    import tomllib

    if not isinstance(text, str) or "=" not in text:
        raise ValueError(f"--set {text!r}: expected PATH=VALUE[,VALUE...], e.g. contact.0.gap=0.005,0.01")
    path, _, rhs = text.partition("=")
    path = path.strip()
    if not path or not rhs.strip():
        raise ValueError(f"--set {text!r}: expected PATH=VALUE[,VALUE...], e.g. contact.0.gap=0.005,0.01")
    _parse_path(path)
    values = []
    for item in _split_top(rhs):
        if not item:
            raise ValueError(f"--set {text!r}: empty value (two commas in a row, or a trailing comma?)")
        try:
            values.append(tomllib.loads(f"v = {item}")["v"])
        except tomllib.TOMLDecodeError:
            if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", item):
                raise ValueError(f"--set {text!r}: cannot read value {item!r} (numbers, true/false, \"text\", "
                                 f"[lists] or plain names)") from None
            values.append(item)
    return path, values


# ---------------------------------------------------------------------------------------------
# TOML writer (the subset that case files use; tomllib only reads)
# ---------------------------------------------------------------------------------------------
_BARE = re.compile(r"[A-Za-z0-9_\-]+")


def _toml_key(k: str) -> str:
    return k if _BARE.fullmatch(k) else json.dumps(k)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return repr(v)  # shortest round-trip repr; 'inf', '1e-05', '1e+16' are valid TOML floats
    if isinstance(v, str):
        return json.dumps(v)  # JSON string escapes are TOML basic-string escapes
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    raise TypeError(f"to_toml: cannot write {v!r} ({type(v).__name__})")


def to_toml(data: Mapping) -> str:
    """TOML text of a case dict (``tomllib.loads(to_toml(d)) == d`` for case-file data)."""
    lines = []
    for name, value in data.items():
        tabs = value if isinstance(value, list) else [value]
        for tab in tabs:
            if not isinstance(tab, Mapping):
                raise TypeError(f"to_toml: [{name}] must be a table, got {tab!r}")
            lines.append(f"[[{_toml_key(name)}]]" if isinstance(value, list) else f"[{_toml_key(name)}]")
            lines.extend(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in tab.items())
            lines.append("")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# The task (runs in a worker: plain data in, plain dict out)
# ---------------------------------------------------------------------------------------------
def _amplitude_dof(case: Case, model) -> int | None:
    rd = case.data.get("outputs", {}).get("response_dof")
    if rd is not None:
        return model.dof(tuple(rd) if isinstance(rd, list) else rd)
    if model.forces:
        return model.forces[0].dof
    if model.contacts:
        return model.contacts[0].dof
    return None


def _max_penetration(br) -> float:
    """``max(0, max_t -g_N(t))`` over all points and contacts, ``g_N = gap - q_c``.

    The definition of :attr:`femodes.PeriodicSolution.penetration` (same fine grid), evaluated for
    the whole branch with one synthesis matrix: point by point it cost 20 % of a 300-point case.
    """
    ci = br.contacts
    if not ci.kinds or not len(br):
        return 0.0
    n = max(2048, 64 * br.harmonics.n_coef)
    E = br.harmonics.synthesis(2 * np.pi * np.arange(n) / n)
    worst = max(float(np.max(E @ br.Q[:, :, dof].T)) - gap for dof, gap in zip(ci.dofs, ci.gaps))
    return max(0.0, worst)


def run_sweep_case(case_id: str, text: str, folder: str) -> dict:
    """Run one sweep case in the current process; never raises.

    Writes ``folder/case.toml`` (``text``), runs it with :func:`~femodes.app.cases.run_case`
    (outputs in ``folder``) and returns the :class:`CaseRecord` fields as a plain dict, without
    ``parameters``; on any exception ``status = "failed"`` and ``message`` is the error.
    """
    from .cases import run_case

    t0, c0 = time.perf_counter(), time.thread_time()
    rec: dict[str, Any] = {"id": case_id, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        folder_p = Path(folder)
        folder_p.mkdir(parents=True, exist_ok=True)
        path = folder_p / "case.toml"
        path.write_text(text, encoding="utf-8")
        case = parse_case(text, path)
        res = run_case(case, folder_p, progress=False)
        br = res.branch
        dof = _amplitude_dof(case, res.model)
        amp = br.amplitude(dof) if dof is not None else np.max([br.amplitude(i) for i in range(br.Q.shape[2])], axis=0)
        rec.update(
            status="ok" if br.success else "incomplete", message=br.message, n_points=len(br),
            branch=str(folder_p / _CASE_OUTPUTS["branch"]), omega_min=float(br.omega.min()),
            omega_max=float(br.omega.max()), energy_min=float(br.energy.min()), energy_max=float(br.energy.max()),
            max_amplitude=float(amp.max()), amplitude_dof="all" if dof is None else res.model.dofmap.label(dof),
            n_folds=len(br.folds), max_penetration=_max_penetration(br),
        )
    except CaseError as exc:
        rec.update(status="failed", message=exc.message)
    except Exception as exc:  # noqa: BLE001 - a failed case is reported, the sweep goes on
        rec.update(status="failed", message=f"{type(exc).__name__}: {exc}")
    rec["wall_time"] = time.perf_counter() - t0
    rec["cpu_time"] = time.thread_time() - c0
    return rec


# ---------------------------------------------------------------------------------------------
# Executors
# ---------------------------------------------------------------------------------------------
@contextlib.contextmanager
def _restored_environ():
    """Undo changes to ``os.environ``: the nanny exports its pre-spawn variables into the process
    that starts it (ours), where they would leak into every later subprocess of the user."""
    saved = dict(os.environ)
    try:
        yield
    finally:
        for k in [k for k in os.environ if k not in saved]:
            del os.environ[k]
        for k, v in saved.items():
            if os.environ.get(k) != v:
                os.environ[k] = v


def local_cluster(n_workers: int = 2, **kwargs):
    """A :class:`distributed.LocalCluster` for sweeps: ``n_workers`` single-threaded processes.

    The workers start with :data:`WORKER_ENVIRON` (no ``MALLOC_TRIM_THRESHOLD_``, one BLAS thread;
    see the module docstring), with the scheduler and its HTTP server on free local ports (no fixed
    port to collide with other clusters on the machine). ``kwargs`` go to ``LocalCluster`` and
    override these defaults. Close it (``with local_cluster() as cluster:``) when done.
    """
    import dask
    from distributed import LocalCluster

    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
        raise ValueError(f"local_cluster: n_workers must be an integer >= 1, got {n_workers!r}")
    # dashboard_address=None would still bind Dask's HTTP server to the fixed port 8787 (with a
    # warning when another cluster has it): a free local port instead.
    opts = dict(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0")
    opts.update(kwargs)
    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    env.update(WORKER_ENVIRON)
    with _restored_environ(), dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
        # A value already in os.environ wins over the config and is inherited by the spawned
        # workers (e.g. exported by an earlier default cluster's nanny): drop it while they start.
        for k, v in WORKER_ENVIRON.items():
            if v is None and k in os.environ:
                log.info("sweep workers start without %s=%s (slows numpy-heavy tasks)", k, os.environ[k])
                del os.environ[k]
        return LocalCluster(**opts)


def _is_client(obj) -> bool:
    try:
        from distributed import Client
    except ImportError:
        return False
    return isinstance(obj, Client)


def _check_where(executor, scheduler, n_workers) -> None:
    if executor is not None and scheduler is not None:
        raise ValueError("run_sweep: give either executor or scheduler, not both")
    if executor is not None and not (_is_client(executor) or isinstance(executor, cf.Executor)):
        raise TypeError(f"run_sweep: executor must be a concurrent.futures.Executor or a distributed.Client, "
                        f"got {type(executor).__name__}")
    if scheduler is not None and (not isinstance(scheduler, str) or not scheduler):
        raise TypeError(f"run_sweep: scheduler must be an address string like 'tcp://host:8786', got {scheduler!r}")
    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
        raise ValueError(f"run_sweep: n_workers must be an integer >= 1, got {n_workers!r}")


@contextlib.contextmanager
def _executor(executor, scheduler, n_workers):
    """The concurrent.futures.Executor to submit to; creates and closes what the sweep owns."""
    _check_where(executor, scheduler, n_workers)
    if executor is not None:
        if _is_client(executor):
            from distributed.cfexecutor import ClientExecutor

            yield ClientExecutor(executor, pure=False), f"Dask client of {executor.scheduler.address}"
        else:
            yield executor, type(executor).__name__
        return
    try:
        from distributed import Client
        from distributed.cfexecutor import ClientExecutor
    except ImportError as exc:
        raise ImportError("run_sweep needs dask.distributed for its default cluster (pip install 'femodes[sweep]'), "
                          "or pass executor=concurrent.futures.ProcessPoolExecutor()") from exc
    if scheduler is not None:
        with Client(scheduler) as client:
            yield ClientExecutor(client, pure=False), f"Dask scheduler {scheduler}"
        return
    with local_cluster(n_workers) as cluster, Client(cluster) as client:
        yield ClientExecutor(client, pure=False), f"local Dask cluster, {n_workers} workers"


# ---------------------------------------------------------------------------------------------
# Sweep
# ---------------------------------------------------------------------------------------------
def _base_case(case) -> Case:
    if isinstance(case, Case):
        return case
    if isinstance(case, (str, os.PathLike)):
        return load_case(case)
    raise TypeError(f"run_sweep: case must be a case file path or a Case (femodes.app.cases.load_case), "
                    f"got {type(case).__name__}")


def _case_text(base: Case, overrides: Mapping[str, Any]) -> str:
    data = apply_overrides(base.data, overrides)
    mesh = data.get("mesh")
    if isinstance(mesh, dict) and isinstance(mesh.get("file"), str) and not Path(mesh["file"]).is_absolute():
        # the case runs from out/cases/<id>/: resolve the mesh against the base case's folder
        mesh["file"] = str((base.path.parent / mesh["file"]).resolve())
    outputs = {k: v for k, v in data.get("outputs", {}).items() if k not in _CASE_OUTPUTS}
    data["outputs"] = {**outputs, **_CASE_OUTPUTS}
    return to_toml(data)


def run_sweep(case, parameters, *, out, executor=None, scheduler: str | None = None, n_workers: int = 2,
              study: str = "study.npz", progress: bool = False,
              callback: Callable[[CaseRecord, int, int], None] | None = None) -> SweepResult:
    """Run a case file for many parameter values as independent tasks; gather one study file.

    Every case ``i`` is the base case with its overrides applied; it runs
    :func:`~femodes.app.cases.run_case` in a task and saves ``out/cases/c<i>/branch.npz``. A case
    the case-file checks reject, or whose task raises, gets ``status = "failed"`` with the error;
    the other cases complete.

    Parameters
    ----------
    case : str, Path or Case
        The base case file (or a parsed :class:`~femodes.app.cases.Case`).
    parameters : dict or list of dict
        ``{path: [values]}`` (Cartesian product) or ``[{path: value}, ...]``; paths like
        ``"contact.0.gap"``, ``"analysis.harmonics"`` (see the module docstring).
    out : str or Path
        Output folder: ``cases/<id>/`` per case and the study file.
    executor : concurrent.futures.Executor or distributed.Client, optional
        Where the tasks run; not shut down by the sweep. Worker environments are the caller's.
    scheduler : str, optional
        Address of a running Dask scheduler (``"tcp://host:8786"``); ``out`` must be shared.
    n_workers : int
        Workers of the embedded :func:`local_cluster` used when neither of the above is given.
    study : str
        Study file name in ``out``: ``*.npz`` or ``*.h5`` (needs h5py).
    progress : bool
        Log one INFO line per finished case (logger ``femodes.app.sweep``).
    callback : callable, optional
        ``callback(record, n_done, n_total)`` after each finished case, in the calling process.

    Returns
    -------
    SweepResult
        Records in case order; ``result.study`` is the study file (read with :func:`load_study`).
    """
    t_start = time.perf_counter()
    if out is None or not isinstance(out, (str, os.PathLike)):
        raise TypeError(f"run_sweep: out must be a folder path, got {out!r}")
    if (not isinstance(study, str) or Path(study).suffix.lower() not in (".npz", ".h5", ".hdf5")
            or Path(study).name != study):
        raise ValueError(f"run_sweep: study must be a file name ending in .npz or .h5, got {study!r}")
    if callback is not None and not callable(callback):
        raise TypeError(f"run_sweep: callback must be callable(record, n_done, n_total), got {callback!r}")
    _check_where(executor, scheduler, n_workers)
    base = _base_case(case)
    combos = sweep_cases(parameters)
    paths = tuple(dict.fromkeys(p for c in combos for p in c))
    width = max(3, len(str(len(combos) - 1)))
    ids = [f"c{i:0{width}d}" for i in range(len(combos))]
    texts = [_case_text(base, ov) for ov in combos]  # a path that does not fit the case: ValueError, nothing run
    out = Path(out).resolve()
    (out / "cases").mkdir(parents=True, exist_ok=True)
    records: dict[str, CaseRecord] = {}
    n = len(combos)
    pending = {cid: CaseRecord(id=cid, parameters=ov, status="pending", message="not finished")
               for cid, ov in zip(ids, combos)}

    def snapshot() -> SweepResult:
        return SweepResult(cases=tuple(records.get(i, pending[i]) for i in ids), parameters=paths,
                           study=out / study, case=base.name, elapsed=time.perf_counter() - t_start)

    def done(rec: CaseRecord) -> None:
        records[rec.id] = rec
        # the study file follows every finished case (small, atomic): an interrupted sweep keeps
        # its finished cases, the others are marked "pending"
        save_study(snapshot(), text=base.text)
        if progress:
            log.info("case %s (%d/%d) %s in %.2f s: %s %s", rec.id, len(records), n, rec.status, rec.wall_time,
                     ", ".join(f"{k}={_fmt_value(v)}" for k, v in rec.parameters.items()), rec.message)
        if callback is not None:
            callback(rec, len(records), n)

    jobs = []
    for cid, ov, text in zip(ids, combos, texts):
        try:  # the case-file checks in this process: a rejected value costs no task
            parse_case(text, out / "cases" / cid / "case.toml")
        except CaseError as exc:
            done(CaseRecord(id=cid, parameters=ov, status="failed", message=exc.message, wall_time=0.0))
            continue
        jobs.append((cid, ov, text))
    if jobs:
        with _executor(executor, scheduler, n_workers) as (ex, where):
            log.info("sweep of %s: %d cases (%d to run) on %s", base.name, n, len(jobs), where)
            futures = {ex.submit(run_sweep_case, cid, text, str(out / "cases" / cid)): (cid, ov)
                       for cid, ov, text in jobs}
            for fut in cf.as_completed(futures):
                cid, ov = futures[fut]
                try:
                    raw = fut.result()
                except Exception as exc:  # noqa: BLE001 - the task itself could not run (worker lost, ...)
                    raw = {"id": cid, "status": "failed", "message": f"{type(exc).__name__}: {exc}"}
                done(_record(raw, ov, out))
    res = snapshot()
    save_study(res, text=base.text)
    return res


def _record(raw: Mapping, overrides: Mapping, out: Path) -> CaseRecord:
    kw = {k: raw[k] for k in raw if k in {f.name for f in fields(CaseRecord)}}
    if kw.get("branch"):
        try:
            kw["branch"] = Path(kw["branch"]).resolve().relative_to(out).as_posix()
        except ValueError:
            kw["branch"] = str(kw["branch"])
    return CaseRecord(**{**kw, "parameters": dict(overrides)})


# ---------------------------------------------------------------------------------------------
# Study file
# ---------------------------------------------------------------------------------------------
def save_study(result: SweepResult, *, text: str = "") -> Path:
    """Write ``result.study`` atomically (temporary file + ``os.replace``).

    Layout (``.npz`` arrays or ``.h5`` datasets): ``header`` (JSON: format, version, base case name
    and text, parameter paths, every record), plus one array per record field over the cases
    (``status``, ``message``, ``branch``, ``max_amplitude``, ...) and ``param:<path>`` per
    parameter (JSON text of each value) for readers without femodes.
    """
    path = Path(result.study)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = {"format": "femodes.Study", "version": STUDY_VERSION, "case": result.case, "case_text": text,
              "parameters": list(result.parameters), "elapsed": result.elapsed,
              "records": [asdict(r) for r in result.cases]}
    arrays = {k: np.array([getattr(r, k) for r in result.cases], dtype=int if k in ("n_points", "n_folds") else float)
              for k in _NUMERIC}
    arrays.update({k: np.array([getattr(r, k) for r in result.cases], dtype=str) for k in _TEXT})
    arrays.update({f"param:{p}": np.array([json.dumps(r.parameters.get(p)) for r in result.cases], dtype=str)
                   for p in result.parameters})
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    os.close(fd)
    try:
        if path.suffix.lower() == ".npz":
            with open(tmp, "wb") as f:
                np.savez_compressed(f, header=np.array(json.dumps(header)), **arrays)
        else:
            try:
                import h5py
            except ImportError as exc:
                raise ImportError("a .h5 study file needs h5py (pip install 'femodes[store]'); use study.npz") from exc
            with h5py.File(tmp, "w") as f:
                f.attrs["header"] = json.dumps(header)
                for k, v in arrays.items():
                    f.create_dataset(k.replace("/", "|"), data=v.astype(object) if v.dtype.kind == "U" else v,
                                     dtype=h5py.string_dtype() if v.dtype.kind == "U" else v.dtype)
        os.replace(tmp, path)  # atomic: readers never see a half-written study
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def load_study(path) -> SweepResult:
    """Read a study file written by :func:`run_sweep`; branches via ``result.load_branch(i)``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"load_study: no such file {str(path)!r}")
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as f:
                header = json.loads(str(f["header"]))
        else:
            import h5py

            with h5py.File(path, "r") as f:
                header = json.loads(f.attrs["header"])
    except Exception as exc:  # noqa: BLE001 - any unreadable file gets the same message
        raise ValueError(f"load_study: {str(path)!r} is not a readable femodes study file ({exc})") from exc
    if not isinstance(header, dict) or header.get("format") != "femodes.Study":
        raise ValueError(f"load_study: {str(path)!r} is not a femodes study file")
    if header.get("version") != STUDY_VERSION:
        raise ValueError(f"load_study: {str(path)!r} has study version {header.get('version')}, this femodes reads "
                         f"version {STUDY_VERSION}")
    recs = tuple(CaseRecord(**r) for r in header["records"])
    return SweepResult(cases=recs, parameters=tuple(header["parameters"]), study=path, case=header.get("case", ""),
                       elapsed=header.get("elapsed", math.nan))
