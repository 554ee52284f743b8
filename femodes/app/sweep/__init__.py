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
worker processes) by default, an existing Dask cluster (``executor="tcp://host:8786"``, the
scheduler's address), a :class:`distributed.Client`, or any :class:`concurrent.futures.Executor`
(thread or process pool).
With a remote cluster, ``out`` must be on a file system the workers share.

Modules: :mod:`.records` (:class:`CaseRecord`, :class:`SweepResult`), :mod:`.overrides`
(parameter paths, the case text of each case, ``--set`` and the TOML writer), :mod:`.task` (the
task run in a worker, :func:`run_sweep_case`), :mod:`.executors` (where the tasks run: the
embedded cluster, its worker environment and the main-script guard), :mod:`.study` (the study
file), :mod:`.run` (:func:`run_sweep`).
"""

from .executors import WORKER_ENVIRON, local_cluster
from .overrides import apply_overrides, parse_set, sweep_cases, to_toml
from .records import CaseRecord, SweepResult
from .run import run_sweep
from .study import STUDY_VERSION, load_study, save_study
from .task import max_penetration, run_sweep_case

__all__ = ["run_sweep", "SweepResult", "CaseRecord", "load_study", "save_study", "local_cluster", "run_sweep_case",
           "max_penetration",
           "sweep_cases", "apply_overrides", "parse_set", "to_toml", "WORKER_ENVIRON", "STUDY_VERSION"]
