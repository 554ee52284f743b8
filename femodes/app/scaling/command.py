"""Application layer: the ``femodes scaling`` subcommand (its parser and what it runs).

:func:`add_scaling_parser` adds the subcommand to the ``femodes`` command line (``cli.py``),
:func:`scaling_cli` runs it: the study, its table and fitted exponents on stdout, and an exit
code (0 all measured, 1 some cases failed, 2 bad input, 130 Ctrl-C).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..cases import CaseError, command_out_folder
from .records import ScalingResult
from .study import positive_float_list, positive_int_list, scaling_study

__all__ = ["SCALING_HELP", "add_scaling_parser", "scaling_cli"]

SCALING_HELP = """Scaling study of a TOML case file: for every N x H pair, in a fresh process,
  per iteration   median (and min) over --repeat of problem.residual(x, p) + default_linear_solver(J, r)
                  at a state with active contacts when possible, each repeat at a frequency shifted by
                  1e-9 (relative) so that the per-harmonic factorisations are recomputed, as in a
                  continuation corrector,
  per point       wall time of the case's analysis capped at --points points / points,
  peak MiB        ru_maxrss of the case's process.
N is varied through [mesh] n_elements of a line mesh (--elements), or by refining the case's own
generated mesh (--refine: a factor on n_elements of a line mesh, on nx, ny and nz of a solid's
rectangle or box, which keeps the aspect of its elements); not for mesh files or discrete models.
H is varied through [analysis] harmonics. Writes scaling.csv (after every case: Ctrl-C keeps what
was measured), scaling.json (with the fitted log-log exponents) and scaling.png to --out.
Examples: femodes scaling case.toml --elements 100,1000,10000 --harmonics 5,10,20
          femodes scaling examples/cases/strip2d_contact.toml --refine 1,2,4 --harmonics 5
"""


def add_scaling_parser(sub) -> None:
    """The ``femodes scaling`` subcommand on the command line's subparsers."""
    sc = sub.add_parser("scaling", help="time and memory of a case file against N and H", description=SCALING_HELP,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    sc.add_argument("case", type=Path, help="the case file (a generated mesh to vary N)")
    size = sc.add_mutually_exclusive_group()
    size.add_argument("--elements", type=positive_int_list, default=None, metavar="NE,NE,...",
                      help="values of [mesh] n_elements of a line mesh, e.g. 100,1000,10000 (default: the case's mesh)")
    size.add_argument("--refine", type=positive_float_list, default=None, metavar="F,F,...",
                      help="refinement factors of the case's mesh, e.g. 1,2,4: n_elements, or nx, ny, nz of a solid, "
                           "times F (default: the case's mesh)")
    sc.add_argument("--harmonics", type=positive_int_list, default=None, metavar="H,H,...",
                    help="values of [analysis] harmonics, e.g. 5,10,20 (default: the case's)")
    sc.add_argument("--repeat", type=_positive_int, default=3, help="repetitions of the timed Newton iteration (3)")
    sc.add_argument("--points", type=_points, default=5,
                    help="continuation points of the timed analysis (5; 0 skips it)")
    sc.add_argument("--timeout", type=_positive_float, default=None, metavar="SECONDS",
                    help="stop a case after this long and record it as failed")
    sc.add_argument("--out", type=Path, default=None, help="output folder (default: out/<case file name>_scaling)")
    sc.add_argument("--progress", dest="progress", action="store_true", default=None,
                    help="show a progress bar over the cases on stderr (default: when stderr is a terminal)")
    sc.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")


def _positive_int(text: str) -> int:
    v = positive_int_list(text)
    if len(v) != 1:
        raise argparse.ArgumentTypeError(f"expected one positive integer, got {text!r}")
    return v[0]


def _points(text: str) -> int:
    if text.strip() == "0":
        return 0
    v = _positive_int(text)
    if v < 2:
        raise argparse.ArgumentTypeError(f"expected 0 (skip the continuation) or an integer >= 2, got {text!r}")
    return v


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return v


def scaling_cli(args) -> int:
    """``femodes scaling``: 0 if every case was measured, 1 if some failed, 2 for bad input, 130 on Ctrl-C."""
    path = Path(args.case)
    out = command_out_folder(args.out, Path("out") / f"{path.stem}_scaling", "scaling")
    if out is None:
        return 2
    show = sys.stderr.isatty() if args.progress is None else args.progress
    try:
        res = scaling_study(path, elements=args.elements, refine=args.refine, harmonics=args.harmonics,
                            repeat=args.repeat, points=args.points, out=out, timeout=args.timeout, progress=show)
    except CaseError as exc:
        print(f"femodes scaling: {exc}", file=sys.stderr)
        return 2
    except (ValueError, TypeError) as exc:
        print(f"femodes scaling: {str(exc).removeprefix('scaling_study: ')}", file=sys.stderr)
        return 2
    print(res.table())
    print()
    _print_fits(res)
    print(f"outputs written to {Path(out).resolve()} ({', '.join(p.name for p in res.files)})")
    if res.interrupted:
        print(f"interrupted: {len(res.records)} case(s) measured", file=sys.stderr)
        return 130
    return 0 if res.success else 1


def _print_fits(res: ScalingResult) -> None:
    if res.fits:
        print("fitted exponents (least squares on log-log):")
        for line in res.fit_lines():
            print(f"  {line}")
    else:
        print("no exponent fitted (needs >= 2 measured sizes of N or H)")
