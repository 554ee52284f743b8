#!/usr/bin/env python
"""Model build of meshed solids: ``fm.solid`` against a bare scikit-fem assembly of the same forms.

Run from the repository root::

    python benchmarks/bench_assembly.py                         # hex, tet4, tet6; 5 rounds (3 for tet6)
    python benchmarks/bench_assembly.py --cases hex tet4 --rounds 7
    python benchmarks/bench_assembly.py --before /tmp/oldtree   # also fm.solid of another source tree
    python benchmarks/bench_assembly.py --json out/assembly.json

This is a script, not a pytest test; results in ``benchmarks/README_assembly.md``. An old tree to
compare with is made by ``git archive <commit> | tar -x -C /tmp/oldtree``.

Cases (E = 210e9, rho = 7800, nu = 0.3; clamped on "left"; ``order=2``):

``hex``   Q2 hexahedral plate 150 x 40 x 4 mm, 15 x 2 x 2 hexahedra (``fm.box_mesh(hexahedra=True)``),
          like the tapered plate of the issue (60 hexahedra, 27-node Q2).
``tet4``  P2 tetrahedral box 1 x 0.1 x 0.1, 40 x 4 x 4 grid cells (``fm.box_mesh``), 19440 DOFs.
``tet6``  the same with 60 x 6 x 6 cells, 60840 DOFs (``benchmarks/bench_solids_scale.py`` box3d 4 and 6).

Variants, each measured in a fresh child process (``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=1``),
the mesh built before the timed region:

``femodes``  ``fm.solid(mesh, material, clamped="left", order=2)``: the whole model (bases, K, M,
             boundary groups and weights, supports, DOF map and labels, checks of the matrices).
``bare``     what a scikit-fem user writes for the same matrices: ``Basis`` of the same vector
             element with the same quadrature (``intorder`` of ``femodes.fe.quadrature``; K first,
             then the mass basis sharing the DOFs and the map of the stiffness basis, as
             ``fm.solid`` does), the same bilinear forms with constant coefficients, ``.assemble``
             to CSR. No supports, no DOF names, no boundary weights.
``before``   ``fm.solid`` of the tree given by ``--before`` (with ``PYTHONPATH``).

The variants alternate within each round (side by side, so that the load of the shared machine
hits all of them alike); the tables give the median over rounds of the wall time
(``time.perf_counter``) and of the CPU time of the child (``time.process_time``). One more child
per variant and case measures the peak of the Python-visible heap during the build with
``tracemalloc`` (numpy's buffers are traced; this run is not timed).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = {"hex": "Q2 hexahedral plate 150 x 40 x 4 mm, 15 x 2 x 2", "tet4": "P2 tetrahedra, box 40 x 4 x 4",
         "tet6": "P2 tetrahedra, box 60 x 6 x 6", "tet10": "P2 tetrahedra, box 100 x 10 x 10",
         "tet16": "P2 tetrahedra, box 160 x 16 x 16"}
DEFAULT_ROUNDS = {"hex": 5, "tet4": 5, "tet6": 3, "tet10": 3, "tet16": 2}
#: cases whose tracemalloc run is skipped (it doubles a minutes-long build): their peak is the RSS
NO_TRACE = ("tet10", "tet16")
#: resident memory (all processes of a child) above which a child is killed and recorded as such
MEM_LIMIT_GIB = 16.0
TIMEOUT_S = 1800.0


def build_mesh(case: str):
    import femodes as fm

    if case == "hex":
        return fm.box_mesh(0.150, 0.040, 0.004, 15, 2, 2, hexahedra=True)
    n = {"tet4": 4, "tet6": 6, "tet10": 10, "tet16": 16}[case]
    return fm.box_mesh(1.0, 0.1, 0.1, 10 * n, n, n)


def bare_build(mesh, material):
    """K and M by scikit-fem alone: the same element, quadrature and forms as femodes."""
    import skfem
    from skfem.helpers import ddot, div, dot, grad, transpose

    from femodes.fe.quadrature import orders

    scalar = skfem.ElementHex2() if isinstance(mesh, skfem.MeshHex1) else skfem.ElementTetP2()
    element = skfem.ElementVector(scalar)
    o = orders(mesh, element)
    lam, mu = material.lame

    @skfem.BilinearForm
    def stiffness(u, v, w):
        return lam * div(u) * div(v) + mu * ddot(grad(u), grad(v) + transpose(grad(v)))

    @skfem.BilinearForm
    def mass(u, v, w):
        return material.rho * dot(u, v)

    # as fm.solid: K first, its basis dropped before the mass basis (sharing its DOFs and map) is built
    same = o.stiffness == o.mass
    kbasis = skfem.Basis(mesh, element, intorder=o.stiffness, disable_doflocs=not same)
    K = stiffness.assemble(kbasis)
    mbasis = kbasis if same else skfem.Basis(mesh, element, intorder=o.mass, mapping=kbasis.mapping, dofs=kbasis.dofs)
    del kbasis
    return K, mass.assemble(mbasis)


def child(case: str, variant: str, trace: bool) -> dict:
    import time

    import femodes as fm

    material = fm.Material(E=210e9, rho=7800.0, nu=0.3)
    mesh = build_mesh(case)
    if variant == "bare":
        def run():
            K, M = bare_build(mesh, material)
            return K.shape[0]
    else:
        def run():
            return fm.solid(mesh, material, clamped="left", order=2).n_dofs
    if trace:
        import tracemalloc

        tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
        n = run()
        peak = tracemalloc.get_traced_memory()[1] - base
        tracemalloc.stop()
        return {"n": n, "peak_mib": peak / 2**20, "femodes": fm.__file__}
    import resource

    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    w0, c0 = time.perf_counter(), time.process_time()
    n = run()
    return {"n": n, "wall": time.perf_counter() - w0, "cpu": time.process_time() - c0, "femodes": fm.__file__,
            "rss_before_mib": rss0, "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def run_child(case: str, variant: str, before: str | None, trace: bool = False) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    tree = before if variant == "before" else str(ROOT)
    env["PYTHONPATH"] = str(Path(tree).resolve())
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", case, "bare" if variant == "bare" else "femodes"]
    if trace:
        cmd.append("--trace")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_solids_scale import RssWatchdog

    with RssWatchdog(MEM_LIMIT_GIB * 2**30) as dog:
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd="/")
        try:
            stdout, stderr = proc.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            return {"error": f"timed out after {TIMEOUT_S:g} s", "n": None}
    if dog.fired is not None:
        return {"error": f"RSS > {MEM_LIMIT_GIB:g} GiB ({dog.fired / 2**30:.1f} GiB; killed)", "n": None,
                "watchdog_peak_mib": dog.peak / 2**20}
    if proc.returncode:
        tail = [ln for ln in stderr.strip().splitlines() if ln.strip()]
        return {"error": f"failed (exit {proc.returncode}): {tail[-1] if tail else ''}", "n": None}
    out = json.loads(stdout.strip().splitlines()[-1])
    out["watchdog_peak_mib"] = dog.peak / 2**20
    expected = Path(tree).resolve() / "femodes" / "__init__.py"
    if Path(out["femodes"]).resolve() != expected:
        raise RuntimeError(f"{case}/{variant}: the child imported {out['femodes']}, not {expected}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", choices=sorted(CASES), default=["hex", "tet4", "tet6"])
    ap.add_argument("--rounds", type=int, default=None, help="alternating rounds per case (default 5, tet6 3)")
    ap.add_argument("--before", metavar="TREE", help="also time fm.solid of this source tree")
    ap.add_argument("--json", help="write the raw numbers here")
    ap.add_argument("--child", nargs=2, metavar=("CASE", "VARIANT"), help=argparse.SUPPRESS)
    ap.add_argument("--trace", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(*args.child, args.trace)))
        return
    variants = ["femodes", "bare"] + (["before"] if args.before else [])
    raw: dict = {}
    for case in args.cases:
        rounds = args.rounds or DEFAULT_ROUNDS[case]
        runs: dict = {v: [] for v in variants}
        for r in range(rounds):
            for v in variants[r % len(variants):] + variants[:r % len(variants)]:  # rotate the order
                runs[v].append(run_child(case, v, args.before))
                x = runs[v][-1]
                print(f"{case} round {r + 1}/{rounds} {v}: " + (x["error"] if "error" in x else
                      f"wall {x['wall']:.3f} s, cpu {x['cpu']:.3f} s, peak RSS {x['peak_rss_mib']:.0f} MiB"),
                      file=sys.stderr, flush=True)
        peaks = {v: None if case in NO_TRACE else run_child(case, v, args.before, trace=True).get("peak_mib")
                 for v in variants}
        raw[case] = {"runs": runs, "peak_mib": peaks, "load": os.getloadavg()}
    try:
        load = os.getloadavg()
    except OSError:  # pragma: no cover
        load = None
    print(f"\nmedians over rounds; load average at the end {load}\n")
    head = "| case | DOFs (free / full) | femodes wall [s] | femodes CPU [s] | bare scikit-fem wall [s] | bare CPU [s] " \
           "| ratio wall | ratio CPU | peak femodes / bare [MiB] | peak RSS femodes / bare [MiB] |"
    if args.before:
        head += " before wall [s] | before CPU [s] | peak before [MiB] |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for case, rec in raw.items():
        nan = float("nan")
        ok = {v: [x for x in rec["runs"][v] if "error" not in x] for v in variants}
        med = {v: {k: statistics.median(x[k] for x in ok[v]) if ok[v] else nan
                   for k in ("wall", "cpu", "peak_rss_mib")} for v in variants}
        pk = {v: nan if rec["peak_mib"][v] is None else rec["peak_mib"][v] for v in variants}
        n_of = {v: ok[v][0]["n"] if ok[v] else "-" for v in variants}
        row = (f"| {case}: {CASES[case]} | {n_of['femodes']} / {n_of['bare']} "
               f"| {med['femodes']['wall']:.3g} | {med['femodes']['cpu']:.3g} | {med['bare']['wall']:.3g} "
               f"| {med['bare']['cpu']:.3g} | {med['femodes']['wall'] / med['bare']['wall']:.2f} "
               f"| {med['femodes']['cpu'] / med['bare']['cpu']:.2f} "
               f"| {pk['femodes']:.0f} / {pk['bare']:.0f} "
               f"| {med['femodes']['peak_rss_mib']:.0f} / {med['bare']['peak_rss_mib']:.0f} |")
        if args.before:
            row += f" {med['before']['wall']:.3g} | {med['before']['cpu']:.3g} | {pk['before']:.0f} |"
        print(row)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        git = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout
        doc = {"load_end": load, "cases": raw, "git": git.strip(), "before": args.before,
               "machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]}}
        old = json.loads(Path(args.json).read_text()) if Path(args.json).is_file() else {}
        if "cases" in old:  # keep the cases not rerun
            doc["cases"] = {**old["cases"], **raw}
            doc["earlier"] = {k: v for k, v in old.items() if k != "cases"}
        Path(args.json).write_text(json.dumps(doc, indent=1))


if __name__ == "__main__":
    main()
