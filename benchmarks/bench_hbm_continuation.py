"""Full 3-D HBM on a real continuation: CPU per Newton iteration with the default block solver and
with ``BlockSolver(reuse=True)``, side by side in one run (issue 38, item 3).

``bench_hbm_iter.py`` times single Newton iterations at frequencies 1 % apart, so every harmonic
block is factorised again. A continuation's corrector moves the frequency far less between its
iterations (1e-5 to 1e-3 relative), which is where reused factors pay. Here the box3d model of
``bench_solids_scale.py`` (P2 tetrahedra, a contact per tip node, H = 5) is continued from
w = 1.5 for ``--points`` points with the options of ``fm.frequency_response``
(``fm.ForcedResponseProblem`` + ``fm.continuation``, the same machinery), in alternating child
processes, one BLAS thread. Recorded: CPU time of the continuation, Newton iterations
(``n_newton``), their ratio, the solver's counters, peak RSS, and the branch itself (both variants
must give the same points: the reused path solves to the exact path's backward error).
``--backends`` runs each variant on each named sparse back-end (``FEMODES_SPARSE_BACKEND`` of
the child; MKL's threads, for PARDISO, at ``--mkl-threads``, one by default as the BLAS).

    python benchmarks/bench_hbm_continuation.py --sizes 4,6 --points 6 --backends mumps,pardiso
"""

from __future__ import annotations

import argparse
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
RESULTS = HERE / "results_hbm_continuation.json"


def child(size: int, points: int, reuse: bool, cache: Path) -> dict:
    import numpy as np

    import femodes as fm
    from femodes.analyses import frequency_response_options
    from femodes.hbm.linsolve import BlockSolver

    with open(cache / f"box3d_{size}.pkl", "rb") as fh:
        _, model, built = pickle.load(fh)
    solver = BlockSolver(reuse=reuse)  # True / False forced, or the default "auto"
    c0, w0 = time.process_time(), time.perf_counter()
    pr = fm.ForcedResponseProblem(model, fm.Harmonics(5), solver=solver)
    res = fm.continuation(pr, (1.5, 2.5), options=frequency_response_options(max_points=points))
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    amp = [float(np.max(np.abs(pr.unpack(x, p).Q))) for x, p in zip(res.x, res.p)]
    return {"size": size, "N": built["N"], "n_contacts": built["n_contacts"], "unknowns": int(pr.size),
            "reuse": reuse, "cpu_s": cpu, "wall_s": wall, "n_newton": int(res.n_newton), "points": len(res.p),
            "cpu_per_iteration_s": cpu / max(int(res.n_newton), 1),
            "wall_per_iteration_s": wall / max(int(res.n_newton), 1), "status": int(res.status),
            "omega": [float(p) for p in res.p], "max_abs_Q": amp, "stats": dict(solver.stats),
            "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "backend": fm.sparse_backend_info().indefinite}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="4")
    ap.add_argument("--points", type=int, default=6)
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "femodes_hbm_iter_cache")
    ap.add_argument("--json", type=Path, default=RESULTS)
    ap.add_argument("--backends", default="", help="comma-separated FEMODES_SPARSE_BACKEND values (default: auto)")
    ap.add_argument("--mkl-threads", default="1", help="PARDISO's threads (MKL_NUM_THREADS of the child); '' to leave it unset")
    ap.add_argument("--reuse", default="0,1", help="the variants: 0 BlockSolver(reuse=False), 1 reuse=True, auto the default")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        size, points = int(args.child[0]), int(args.child[1])
        reuse = {"1": True, "0": False}.get(args.child[2], "auto")
        print(json.dumps(child(size, points, reuse, args.cache)))
        return
    sys.path.insert(0, str(HERE))
    from bench_hbm_iter import build_cache  # the same pickled box3d models as bench_hbm_iter.py

    recs = json.loads(args.json.read_text()) if args.json.is_file() else []
    for size in [int(s) for s in args.sizes.split(",")]:
        build_cache(size, args.cache)
        for backend, reuse in [(b, r) for b in (args.backends or "auto").split(",") for r in args.reuse.split(",")]:
            env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", FEMODES_SPARSE_BACKEND=backend)
            env.pop("MKL_NUM_THREADS", None)
            if args.mkl_threads:
                env["MKL_NUM_THREADS"] = args.mkl_threads
            load0 = os.getloadavg()
            p = subprocess.run([sys.executable, __file__, "--cache", str(args.cache), "--child", str(size),
                                str(args.points), reuse], env=env, capture_output=True, text=True)
            try:
                rec = json.loads(p.stdout.strip().splitlines()[-1])
            except (IndexError, json.JSONDecodeError):
                rec = {"size": size, "reuse": {"1": True, "0": False}.get(reuse, "auto"), "error": p.stderr[-3000:]}
            rec.update(load_before=list(load0), load_after=list(os.getloadavg()), requested_backend=backend,
                       mkl_threads=args.mkl_threads)
            recs.append(rec)
            print({k: rec.get(k) for k in ("N", "backend", "reuse", "cpu_s", "n_newton", "cpu_per_iteration_s",
                                           "wall_per_iteration_s", "points", "stats", "peak_mib", "error")}, flush=True)
            args.json.write_text(json.dumps(recs, indent=1))


if __name__ == "__main__":
    main()
