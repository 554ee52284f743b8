"""One full 3-D HBM Newton iteration, before / after, side by side in one run (issue 38, item 3).

The ``hbm_iter`` protocol of ``bench_solids_scale.py`` (box3d of P2 tetrahedra, a contact per tip
node, H = 5: one Newton step from the linear guess at w = 1.5, then ``--repeat`` iterations of
``residual`` + ``J.factorize().solve(r)`` at frequencies shifted by 1 % each), run for each size
in alternating child processes on

- ``before``: femodes at ``--before`` (a git revision, extracted with ``git archive``);
- ``after``: this tree, default solver (a fresh factorisation per iteration);
- ``after_reuse``: this tree, ``BlockSolver(reuse=True)`` (GMRES preconditioned by the factors of
  the last frequency, ``femodes/hbm/linsolve/krylov.py``).

CPU time (``time.process_time``) of each iteration with one BLAS thread; peak RSS of the child
(``ru_maxrss``); the models are built once per size and pickled (``--cache``). Results:
``results_hbm_iter.json``; table in ``README_solids_scale.md``.

    python benchmarks/bench_hbm_iter.py --sizes 4,5,6 --before 9916155
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import pickle
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results_hbm_iter.json"


def child(size: int, repeat: int, reuse: bool, cache: Path) -> dict:
    sys.path.insert(0, str(HERE))
    import bench_solids_scale as b

    import femodes

    path = cache / f"box3d_{size}.pkl"
    if path.is_file():
        with open(path, "rb") as fh:
            _, model, built = pickle.load(fh)
    else:
        built: dict = {}
        _, model = b._models("box3d", size, built)
    pkg = Path(femodes.__file__).parent  # the tree measured (before or after): SHA-1 prefixes of its solver files
    files = ["sparse_direct.py", "hbm/system.py"] + sorted(str(f.relative_to(pkg)) for f in (pkg / "hbm/linsolve").glob("*.py"))
    rec = {"size": size, "N": built["N"], "n_contacts": built["n_contacts"], "femodes": str(pkg),
           "code": {f: hashlib.sha1((pkg / f).read_bytes()).hexdigest()[:10] for f in files if (pkg / f).is_file()}}
    b._hbm_iter(model, rec, repeat, reuse=reuse)
    rec["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return rec


def build_cache(size: int, cache: Path) -> None:
    sys.path.insert(0, str(HERE))
    import bench_solids_scale as b

    path = cache / f"box3d_{size}.pkl"
    if path.is_file():
        return
    built: dict = {}
    plain, model = b._models("box3d", size, built)
    cache.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        pickle.dump((plain, model, built), fh, protocol=5)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="4,5")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--before", default="9916155", help="git revision of the 'before' code")
    ap.add_argument("--variants", default="before,after,after_reuse")
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "femodes_hbm_iter_cache")
    ap.add_argument("--json", type=Path, default=RESULTS)
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        size, repeat, reuse = int(args.child[0]), int(args.child[1]), args.child[2] == "1"
        print(json.dumps(child(size, repeat, reuse, args.cache)))
        return
    before = Path(tempfile.mkdtemp(prefix="femodes_before_"))
    subprocess.run(f"git -C {ROOT} archive {args.before} femodes | tar -x -C {before}", shell=True, check=True)
    trees = {"before": (before, False), "after": (ROOT, False), "after_reuse": (ROOT, True)}
    recs = json.loads(args.json.read_text()) if args.json.is_file() else []
    for size in [int(s) for s in args.sizes.split(",")]:
        build_cache(size, args.cache)
        for label in args.variants.split(","):
            tree, reuse = trees[label]
            env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
            load0 = os.getloadavg()
            t = time.perf_counter()
            p = subprocess.run([sys.executable, __file__, "--cache", str(args.cache), "--child", str(size),
                                str(args.repeat), "1" if reuse else "0"], env=env, capture_output=True, text=True)
            try:
                rec = json.loads(p.stdout.strip().splitlines()[-1])
            except (IndexError, json.JSONDecodeError):
                rec = {"size": size, "error": p.stderr[-3000:]}
            rec.update(variant=label, before_rev=args.before if label == "before" else None,
                       load_before=list(load0), load_after=list(os.getloadavg()), wall_s=time.perf_counter() - t)
            recs.append(rec)
            print(label, size, {k: rec.get(k) for k in ("N", "unknowns", "iteration_cpu_s", "cpu_s", "peak_mib",
                                                        "solver_stats", "step_norm", "error")}, flush=True)
            args.json.write_text(json.dumps(recs, indent=1))


if __name__ == "__main__":
    main()
