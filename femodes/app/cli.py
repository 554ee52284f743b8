"""Application layer: the ``femodes`` command line.

``femodes demo`` runs the flagship demonstration and writes its outputs to a folder it names.
``femodes run case.toml`` runs a case file (schema: :mod:`femodes.app.cases`, examples in
``examples/cases/``).
``femodes scaling case.toml`` times the case against N and H (:mod:`femodes.app.scaling`).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from .cases.schema import CHECKPOINT_NAME  # the checkpoint of `femodes run` in its output folder
from .progress import BranchProgress

log = logging.getLogger(__name__)

DESCRIPTION = """\
femodes: nonlinear vibration modes of finite-element structures with unilateral contact.

  femodes demo [--out DIR]   cantilever from meshes/cantilever.msh with a tip stop: linear modes,
                             Craig-Bampton reduction, nonlinear mode 1 (backbone) and a forced
                             response by harmonic balance; plots, summary.txt and the branches
                             (.npz, reload with femodes.load_branch) in DIR (default ./out/demo)
  femodes run CASE.toml [--out DIR] [--progress | --no-progress]
                             build the model described by a TOML case file ([mesh], [model],
                             [damping], [[contact]], [[force]], [[cubic]], [reduction], [analysis],
                             [outputs]), run the nonlinear-mode or frequency-response analysis and
                             write plot, branch (.npz), animation and summary.txt to DIR
                             (default ./out/<case name>). Ctrl-C (exit 130) keeps the points found
                             in DIR/checkpoint.npz.points/; the same command resumes from them. Commented examples:
                             examples/cases/cantilever_nnm.toml, examples/cases/oscillator_frc.toml;
                             full schema: python -c "import femodes.app.cases as c; help(c)"
                             or `femodes run --help`.
  femodes scaling CASE.toml [--elements 100,1000] [--harmonics 5,10] [--out DIR]
                             time per Newton iteration and per continuation point and peak
                             memory of the case against N (line meshes: [mesh] n_elements) and
                             H, one process per case; table, fitted exponents, scaling.csv,
                             scaling.json and a log-log plot scaling.png in DIR
                             (default ./out/<case name>_scaling). `femodes scaling --help`.
  femodes sweep CASE.toml --set PATH=V1,V2 [--set ...] [--workers 2 | --scheduler ADDRESS] [--out DIR]
                             run the case for every combination of parameter values
                             (contact.0.gap, force.0.amplitude, analysis.harmonics, ...) on
                             Dask workers; one study file DIR/study.npz. `femodes sweep --help`.

Mistakes in a case file are reported as `case.toml:LINE: [table] message` (exit code 2).
"""

RUN_HELP = """Run a TOML case file. Tables (see examples/cases/*.toml for commented examples):
  [mesh]        file = "x.msh" (relative to the case file)  or  length, n_elements, boundaries = {clamp = 0.0}
  [model]       kind = "beam" | "bar" | "discrete"; E, rho, area, inertia, clamped, pinned; discrete: M, K, C
  [damping]     alpha, beta (Rayleigh)  or  modal = 0.02
  [[contact]]   at = "tip" | ["tip", "w"] | 0, gap >= 0, law = "complementarity" (c) | "penalty" (stiffness)
  [[force]]     at, amplitude, harmonic = 1, phase = 0
  [[cubic]]     at, k3
  [reduction]   craig_bampton = 10
  [analysis]    type = "nonlinear_mode" (mode, energy = [a, b]) | "frequency_response" (omega = [a, b]);
                harmonics = 10, stability = true | "hill" | "shooting" (Floquet multipliers, bifurcations)
  [outputs]     plot = true, branch = "branch.npz", animation = true, gif = false, response_dof = "tip"
"""


def run_case_cli(path: Path, out: Path | None, progress: bool | None) -> int:
    """``femodes run``: returns the exit code (2 for mistakes in the case file or the output folder)."""
    from .cases import CaseError, analysis_span, command_out_folder, load_case, run_case

    try:
        case = load_case(path)
    except CaseError as exc:
        print(f"femodes run: {exc}", file=sys.stderr)
        return 2
    out = command_out_folder(out, Path("out") / path.stem, "run")
    if out is None:
        return 2
    other = _outputs_of_another_case(out, case.name)
    if other:  # its plots, animations and branch would stay beside this case's, under one summary
        print(f"femodes run: --out {str(out)!r} holds the outputs of case {other!r} (summary.txt); choose another "
              "--out, or delete that folder", file=sys.stderr)
        return 2
    show = sys.stderr.isatty() if progress is None else progress
    bar = None
    if show:
        label = "log10(energy)" if case.data["analysis"]["type"] == "nonlinear_mode" else "w"
        bar = BranchProgress(analysis_span(case), label)
    from ..store import Checkpoint, CheckpointInUse, CheckpointStore

    # the points are journalled as they are found: Ctrl-C keeps them, the same command resumes
    checkpoint = Checkpoint(out / CHECKPOINT_NAME, resume=True)
    store = CheckpointStore(checkpoint.path)
    ours = not (store.path.exists() or store.journal.exists())
    try:
        try:
            res = run_case(case, out, progress=bar.update if bar else False, checkpoint=checkpoint)
        except (KeyboardInterrupt, CheckpointInUse):
            raise
        except BaseException:
            if store.path.exists():  # the branch was computed: what failed came after it, keep it
                print(f"femodes run: the computed branch is kept in {str(store.path)!r}; the same command "
                      "reuses it once the cause below is fixed", file=sys.stderr)
            elif ours:  # a run that failed (not interrupted) leaves no journal to block the corrected case
                store.remove_journal()
            raise
    except CaseError as exc:  # an interrupted run of another case left its journal: say how to start over
        print(f"femodes run: {exc}".replace("or use another checkpoint file", f"or delete {str(store.journal)!r} to "
                                            "start this case over"), file=sys.stderr)
        return 2
    except CheckpointInUse as exc:  # another `femodes run` writes to this --out
        print(f"femodes run: {exc}".replace("or use another checkpoint file", "or choose another --out"),
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if bar:
            bar.close()
            bar = None
        if store.path.exists():  # after the continuation: its whole branch is kept (the journal is gone)
            print(f"femodes run: interrupted while writing the outputs; the computed branch is kept in "
                  f"{str(checkpoint.path)!r}; run the same command again to write them", file=sys.stderr)
            return 130
        n = len(store.indices()) if store.journal.is_dir() else 0
        print(f"femodes run: interrupted; {n} point{'s' * (n != 1)} kept in {str(checkpoint.path)!r} (journal "
              f"{checkpoint.path.name}.points/); run the same command again to resume", file=sys.stderr)
        return 130
    except MemoryError:
        print("femodes run: out of memory; use fewer harmonics ([analysis] harmonics), a coarser mesh or a "
              "Craig-Bampton reduction ([reduction] craig_bampton)", file=sys.stderr)
        return 1
    except OSError as exc:  # the folder became unwritable during the run, the disk is full...
        print(f"femodes run: cannot write the outputs to {str(out)!r}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    finally:
        if bar:
            bar.close()
    print("\n".join(res.lines))
    names = ", ".join(Path(f).name for f in res.files)
    print(f"outputs written to {out.resolve()} ({names})")
    return 0 if res.branch.success else 1


def _outputs_of_another_case(out: Path, name: str) -> str | None:
    """The case whose ``summary.txt`` is in ``out``, when it is not ``name`` (None otherwise)."""
    try:
        first = (out / "summary.txt").read_text(encoding="utf-8").splitlines()[0]
    except (OSError, IndexError, UnicodeDecodeError):
        return None
    other = first[len("case: "):] if first.startswith("case: ") else None
    # the same file run from another folder or by another path is the same case
    return other if other is not None and Path(other).name != Path(name).name else None


SWEEP_HELP = """Run a case file for many parameter values, as independent tasks on Dask workers.

  femodes sweep examples/cases/oscillator_frc.toml --set contact.0.gap=0.5,1.0,2.0 \\
      --set analysis.harmonics=5,10 --workers 2 --out out/gap_sweep

--set PATH=V1,V2,...   a case-file key by dotted path: table.key (analysis.harmonics,
                       mesh.n_elements, damping.alpha) or table.index.key for [[...]] tables
                       (contact.0.gap, force.0.amplitude); values are TOML values separated by
                       commas (pairs: analysis.omega=[0.5,2.0],[0.5,1.5]). Repeat --set for more
                       parameters: the sweep runs every combination.
Cases run on an embedded local Dask cluster of --workers single-threaded processes, or on the
running cluster at --scheduler ADDRESS (the output folder must then be shared with its workers).
Each case writes DIR/cases/<id>/ (case.toml, branch.npz, summary.txt); the study (parameters,
status, errors and summary numbers of every case) is DIR/study.npz (femodes.app.sweep.load_study).
A failed case is reported with its error and the others complete; exit code 1 if any case did not
finish, 2 for mistakes in the case file or in --set. The same sweep run again into the same --out
resumes it (finished cases are kept); a folder holding another sweep is refused (exit 2), never
overwritten.
"""


def run_sweep_cli(args) -> int:
    """``femodes sweep``: returns the exit code (2 for mistakes in the case file or in ``--set``)."""
    from ..store import FileInUse
    from .cases import CaseError, command_out_folder, load_case
    from .sweep import parse_set, run_sweep

    params: dict = {}
    try:
        for text in args.set or []:
            path, values = parse_set(text)
            if path in params:
                raise ValueError(f"--set: {path} is given twice; list all its values in one --set")
            params[path] = values
        if not params:
            raise ValueError("give at least one --set PATH=V1,V2,... (e.g. --set contact.0.gap=0.005,0.01)")
        case = load_case(args.case)
    except (ValueError, TypeError, CaseError) as exc:
        print(f"femodes sweep: {exc}", file=sys.stderr)
        return 2
    out = command_out_folder(args.out, Path("out") / f"{args.case.stem}_sweep", "sweep")
    if out is None:
        return 2
    show = sys.stderr.isatty() if args.progress is None else args.progress
    if not args.verbose:
        try:  # distributed logs its cluster's start and stop at INFO through our root handler
            import distributed  # noqa: F401

            logging.getLogger("distributed").setLevel(logging.WARNING)
        except ImportError:
            pass

    def report(rec, done, total):
        vals = " ".join(f"{k}={v}" for k, v in rec.parameters.items())
        extra = f": {rec.message}" if rec.status != "ok" else ""
        print(f"[{done}/{total}] {rec.id} {rec.status} ({rec.wall_time:.2f} s) {vals}{extra}", file=sys.stderr,
              flush=True)

    try:
        res = run_sweep(case, params, out=out, executor=args.scheduler, n_workers=args.workers,
                        progress=report if show else False)
    except KeyboardInterrupt:
        from .sweep import load_study

        study = out / "study.npz"
        try:
            kept = sum(r.status in ("ok", "incomplete") for r in load_study(study))
        except (OSError, ValueError):
            kept = 0
        print(f"femodes sweep: interrupted; {kept} finished case{'s' * (kept != 1)} kept in {str(study)!r}; run "
              "the same command again to resume", file=sys.stderr)
        return 130
    except MemoryError:
        print("femodes sweep: out of memory in this process; use fewer --workers or smaller cases", file=sys.stderr)
        return 1
    except FileInUse as exc:  # another sweep runs in this --out
        print(f"femodes sweep: {exc}", file=sys.stderr)
        return 2
    except (ValueError, TypeError) as exc:
        print(f"femodes sweep: {exc}", file=sys.stderr)
        return 2
    except (OSError, TimeoutError, ImportError) as exc:  # no scheduler at the address, no dask installed
        print(f"femodes sweep: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    print(res.table())
    n_ok = sum(r.ok for r in res)
    print(f"{n_ok} of {len(res)} cases ok in {res.elapsed:.1f} s; study written to {res.study} "
          f"(branches in {res.study.parent / 'cases'})")
    return 0 if res.success else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="femodes", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    demo = sub.add_parser("demo", help="run the flagship demonstration")
    demo.add_argument("--out", type=Path, default=Path("out") / "demo", help="output folder (default: out/demo)")
    run = sub.add_parser("run", help="run a TOML case file (examples/cases/*.toml)", description=RUN_HELP,
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("case", type=Path, help="the case file, e.g. examples/cases/cantilever_nnm.toml")
    run.add_argument("--out", type=Path, default=None, help="output folder (default: out/<case file name>)")
    run.add_argument("--progress", dest="progress", action="store_true", default=None,
                     help="show a progress bar on stderr (default: when stderr is a terminal)")
    run.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    from .scaling import add_scaling_parser

    add_scaling_parser(sub)
    sweep = sub.add_parser("sweep", help="run a case file over parameter values on Dask workers", description=SWEEP_HELP,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    sweep.add_argument("case", type=Path, help="the base case file, e.g. examples/cases/oscillator_frc.toml")
    sweep.add_argument("--set", action="append", metavar="PATH=V1,V2", help="parameter values (repeatable)")
    sweep.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="address of a running Dask scheduler, e.g. tcp://host:8786 (default: a local cluster)")
    sweep.add_argument("--workers", type=int, default=2, help="workers of the local cluster (default 2)")
    sweep.add_argument("--out", type=Path, default=None, help="output folder (default: out/<case name>_sweep)")
    sweep.add_argument("--progress", dest="progress", action="store_true", default=None,
                       help="one line per finished case on stderr (default: when stderr is a terminal)")
    sweep.add_argument("--no-progress", dest="progress", action="store_false", help="no progress lines")
    args = parser.parse_args(argv)
    try:
        return _command(parser, args)
    except KeyboardInterrupt:  # the commands that keep their work say so themselves; this is the rest
        print(f"femodes {args.command}: interrupted", file=sys.stderr)
        return 130


def _command(parser, args) -> int:
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    if args.command is None:
        parser.print_help()
        return 2
    if args.command == "demo":
        from .cases import command_out_folder
        from .demo import run_demo

        out = command_out_folder(args.out, Path("out") / "demo", "demo")
        if out is None:
            return 2
        res = run_demo(out)
        print("\n".join(res["lines"]))
        names = ", ".join(Path(f).name for f in res["files"])
        print(f"outputs written to {res['out'].resolve()} ({names})")
    elif args.command == "run":
        return run_case_cli(args.case, args.out, args.progress)
    elif args.command == "scaling":
        from .scaling import scaling_cli

        return scaling_cli(args)
    elif args.command == "sweep":
        return run_sweep_cli(args)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
