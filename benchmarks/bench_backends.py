#!/usr/bin/env python
"""Sparse direct back-ends side by side (issue 38, item 1): CPU time of what femodes factorises,
on 3-D P2 tetrahedra (``fm.box_mesh`` 1 x 0.1 x 0.1, nx = 10 n, ny = nz = n, ``fm.solid(order=2)``,
clamped "left", a stop on "right": one contact per node, Rayleigh beta = 0.02).

Run from the repository root (the back-ends that are not installed are skipped)::

    python3 benchmarks/bench_backends.py                 # sizes n = 3, 4, 6 (8.8e3, 1.9e4, 6.1e4 DOFs)
    python3 benchmarks/bench_backends.py --sizes 4 --repeat 3
    python3 benchmarks/bench_backends.py --geometry strip2d --sizes 113,160 --ops spd,complex

``--geometry strip2d``: the issue's 2-D rows, a plane-stress strip 1 x 0.1 of Q1 quadrilaterals
(``fm.rectangle_mesh(nx=10 n, ny=n, quadrilaterals=True)``, ``fm.solid(plane="stress")``, clamped "left",
a stop on "right"): n = 113 / 160 give 2.6e5 / 5.2e5 DOFs. ``--geometry blade``: the gmsh blade
of ``examples/user_blade_3d.py`` (a structure none of this was tuned on), refined n times in plane.

Operations, each run for every back-end in one process, back-ends interleaved within each repeat
(the machine is shared: CPU time by ``time.process_time``, BLAS on one thread through
threadpoolctl, ``OMP_NUM_THREADS=1``; medians of the repeats):

spd       ``factorize(K_II, positive_definite=True)`` (interior = all DOFs but the contact DOFs),
          then one solve with the ``n_b`` columns of ``K_IB`` (the constraint modes).
complex   the harmonic block ``Z = K_II - w^2 M_II + i w C_II`` at ``w = 1.5`` (the blade: 1300
          rad/s; between eigenfrequencies), ``factorize(Z, symmetric=True)`` (SuperLU with the options of the
          HBM block solver, ``BlockSolverOptions().superlu_options``), then one solve with ``n_b`` columns.
cb        the whole ``fm.craig_bampton(model, n_modes=20)`` under ``FEMODES_SPARSE_BACKEND``.
cbquad    the same with the reduced stiffness's kept block by the quadratic form ``T_b^T K T_b``
          (``reduction.SCHUR_COND_EPS = -1``: the reduction before it took the Schur complement).
floor     what CHOLMOD or MUMPS itself costs for cb's work (``bench_solids_scale._cb_floor``: the
          factorisation of ``K_II``, its ``n_b`` solves, ARPACK shift-invert for 20 modes).
modes     ``fm.linear_modes(model, n=20)`` (shift-invert eigen-solve) likewise.

``--backends`` limits the back-ends (default: all installed); ``--ops`` the operations.

Results: ``benchmarks/results_backends.json``; summary: ``benchmarks/README_backends.md``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")  # PARDISO on one thread too (its calls set their own count)

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import femodes as fm  # noqa: E402
from femodes import sparse_direct as sd  # noqa: E402
from femodes.hbm.linsolve import BlockSolverOptions  # noqa: E402

SUPERLU_OPTIONS = BlockSolverOptions().superlu_options

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import cpu_model  # noqa: E402

OUT = Path(__file__).resolve().parent / "results_backends.json"


def model_of(n: int, geometry: str = "box3d"):
    if geometry == "strip2d":
        mesh = fm.rectangle_mesh(length=1.0, height=0.1, nx=10 * n, ny=n, quadrilaterals=True)
        model = fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left", plane="stress", thickness=1.0)
        direction: tuple = (1.0, 0.0)
    elif geometry == "box3d":
        mesh = fm.box_mesh(length=1.0, width=0.1, height=0.1, nx=10 * n, ny=n, nz=n)
        model = fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left", order=2)
        direction = (1.0, 0.0, 0.0)
    elif geometry == "blade":
        return blade_model(n)
    else:
        raise SystemExit(f"--geometry: unknown {geometry!r} (box3d, strip2d or blade)")
    return model.with_damping(beta=0.02).with_contact(
        fm.UnilateralContact(at="right", gap=0.01, direction=direction))


def blade_model(n: int):
    """The gmsh blade of ``examples/user_blade_3d.py`` refined n times in plane (15 n x 4 n x 1
    hexahedra of order 2, steel, SI units), the stop over its pad, Rayleigh ``beta`` for 1 %
    damping at its first mode (1109.8 rad/s)."""
    import tempfile

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
    from user_blade_3d import STEEL, with_stop, write_mesh

    with tempfile.TemporaryDirectory() as tmp:
        mesh = fm.load_mesh(write_mesh(Path(tmp) / "blade.msh", n_length=15 * n, n_chord=4 * n))
    solid = fm.solid(mesh, STEEL, clamped="root", order=2)
    return with_stop(solid, zeta=None, force=None).with_damping(beta=2 * 0.01 / 1109.8)


def cpu(f):
    t = time.process_time()
    out = f()
    return time.process_time() - t, out


def run(n: int, repeat: int, backends, ops=("spd", "complex", "cb", "modes"), geometry: str = "box3d") -> list[dict]:
    model = model_of(n, geometry)
    bd = np.array(sorted({c.dof for c in model.contacts}))
    mask = np.ones(model.n_dofs, bool)
    mask[bd] = False
    I = np.flatnonzero(mask)
    K, M, C = (A.tocsr() for A in (model.K, model.M, model.C))
    KII = K[I][:, I].tocsc()
    KIB = K[I][:, bd].toarray()
    w = 1300.0 if geometry == "blade" else 1.5   # between the first two eigenfrequencies
    Z = (K - w * w * M + 1j * w * C)[I][:, I].tocsc()
    ZIB = (K - w * w * M + 1j * w * C)[I][:, bd].toarray()
    recs = {(op, b): [] for op in ("spd", "complex", "cb", "cbquad", "modes", "floor") for b in backends}
    ref = {}
    for r in range(repeat):
        for b in backends:
            os.environ[sd.ENV_VAR] = b
            for op, A, B, kw in [o for o in (("spd", KII, KIB, dict(positive_definite=True)),
                                              ("complex", Z, ZIB, dict(symmetric=True, superlu_options=SUPERLU_OPTIONS)))
                                 if o[0] in ops and not (o[0] == "complex" and b == "cholmod")]:
                # (CHOLMOD takes positive definite matrices only: its "complex" row would time SuperLU)
                tf, f = cpu(lambda: sd.factorize(A, **kw))
                ts, X = cpu(lambda: f.solve(B))  # noqa: F821 (f is bound on the line above)
                res = float(np.abs(A @ X - B).max() / np.abs(B).max())
                key = (op, "x")
                ref.setdefault(key, X)
                diff = float(np.abs(X - ref[key]).max() / np.abs(ref[key]).max())
                recs[(op, b)].append(dict(factor_s=tf, solve_s=ts, total_s=tf + ts, residual=res,
                                          rel_diff_vs_first=diff, used=f.backend))
                del f
            tc = tm = float("nan")
            if "cb" in ops:
                tc, rom = cpu(lambda: fm.craig_bampton(model, n_modes=20))
                om = np.sort(fm.linear_modes(rom, n=10).omega) if r == 0 else None
                if om is not None:
                    ref.setdefault("omega", om)
                recs[("cb", b)].append(dict(total_s=tc, omega_rel_diff=(float(np.abs(om / ref["omega"] - 1).max())
                                                                         if om is not None else None)))
            if "cbquad" in ops:
                from femodes import reduction

                bound, reduction.SCHUR_COND_EPS = reduction.SCHUR_COND_EPS, -1.0
                try:
                    tq, romq = cpu(lambda: fm.craig_bampton(model, n_modes=20))
                finally:
                    reduction.SCHUR_COND_EPS = bound
                if r == 0:
                    oq = np.sort(fm.linear_modes(romq, n=10).omega)
                    ref.setdefault("omega", oq)
                recs[("cbquad", b)].append(dict(total_s=tq, omega_rel_diff=(float(np.abs(oq / ref["omega"] - 1).max())
                                                                             if r == 0 else None)))
            if "floor" in ops and b in ("cholmod", "mumps"):
                # what the library itself costs for cb's work (factor, n_b solves, 20 modes by
                # shift-invert with the factor), called directly: README_solids_scale.md's floor
                from bench_solids_scale import _cb_floor
                rec: dict = {}
                _cb_floor(model, b, rec, 1)
                recs[("floor", b)].append(dict(total_s=rec["cpu_s"], factor_s=rec["factor_cpu_s"],
                                               solve_s=rec["solve_nb_cpu_s"], eigen_s=rec["eigen_cpu_s"]))
            if "modes" in ops:
                tm, lm = cpu(lambda: fm.linear_modes(model, n=20))
                ref.setdefault("modes", lm.omega)
                recs[("modes", b)].append(dict(total_s=tm, omega_rel_diff=float(np.abs(lm.omega / ref["modes"] - 1).max())))
            last = {op: (recs[(op, b)][-1]["total_s"] if recs[(op, b)] else float("nan")) for op in ("spd", "complex")}
            print(f"n={n} N={model.n_dofs} repeat {r} {b}: spd {last['spd']:.2f} s, complex {last['complex']:.2f} s, "
                  f"cb {tc:.2f} s, modes {tm:.2f} s", flush=True)
    out = []
    for (op, b), rs in recs.items():
        if not rs:
            continue
        med = {k: statistics.median(x[k] for x in rs) for k in rs[0] if k.endswith("_s")}
        out.append(dict(geometry=geometry, size=n, n_dofs=int(model.n_dofs), n_interior=int(I.size), n_b=int(bd.size),
                        op=op, backend=b, repeats=rs, **{"median_" + k: v for k, v in med.items()}))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="3,4,6")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--backends", default="", help="comma-separated (default: every installed back-end)")
    ap.add_argument("--ops", default="spd,complex,cb,modes")
    ap.add_argument("--geometry", default="box3d",
                    help="box3d (P2 tetrahedra), strip2d (Q1 quadrilaterals) or blade (gmsh, Q2 hexahedra)")
    ap.add_argument("--json", type=Path, default=OUT)
    args = ap.parse_args(argv)
    backends = tuple(b for b in (args.backends.split(",") if args.backends else sd.available_backends())
                     if b in sd.available_backends())
    ops = tuple(args.ops.split(","))
    results = dict(cpu=cpu_model(), note="CPU time, BLAS 1 thread, machine shared with other sessions",
                   backends=list(backends), runs=[])
    with threadpool_limits(1):
        for n in (int(s) for s in args.sizes.split(",")):
            results["runs"] += run(n, args.repeat, backends, ops, args.geometry)
            args.json.write_text(json.dumps(results, indent=1))
    for r in results["runs"]:
        base = next((x for x in results["runs"] if x["size"] == r["size"] and x["op"] == r["op"]
                     and x["backend"] == backends[0]), r)
        print(f"{r['n_dofs']:7d} {r['op']:8s} {r['backend']:8s} {r['median_total_s']:8.2f} s "
              f"(x{base['median_total_s'] / r['median_total_s']:.1f} vs {backends[0]})")


if __name__ == "__main__":
    main()
