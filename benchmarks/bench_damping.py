#!/usr/bin/env python
"""Modal damping vs Rayleigh damping: cost of a harmonic balance Newton iteration and point (issue 16).

Run from the repository root::

    python benchmarks/bench_damping.py                       # N = 1e3, 1e4, 1e5; H = 5, 10
    python benchmarks/bench_damping.py --N 1000 --H 5 --quick
    python benchmarks/bench_damping.py --base /tmp/damping_base   # + the old dense path at 1e3

This is a script, not a pytest test. Results: ``benchmarks/README.md``, section "Modal damping".

Model. Clamped axial P1 bar ``fm.bar(fm.line_mesh(1, N), E = rho = A = 1, clamped="clamp")``
(N DOFs, w1 = pi/2), tip force ``0.01 cos(w t)``, unilateral stop at the tip with gap 0.02
(femodes' defaults), damped either by Rayleigh ``alpha = 0.06, beta = 1e-4`` (about 2 % on mode
1) or by modal damping ``with_damping(modal=0.02, n_modes=20)``. Both are solved by the default
structured block solver (``BlockSolver``).

Measured, each (N, H) in a fresh child process with
``OPENBLAS_NUM_THREADS = OMP_NUM_THREADS = MKL_NUM_THREADS = 1`` that builds both models and
alternates them (Rayleigh, modal, Rayleigh, ...) so that the load of a shared machine hits both
alike:

``point``      ``fm.frequency_response`` from w = 1.40 (tip in contact) capped at ``--points``
               points: wall time / (points - 1), median of ``--rounds`` (3) continuations per
               damping, and Newton iterations per point;
``iteration``  one Newton iteration as the continuation does it: ``problem.residual(x, w)`` then
               ``J.factorize().solve(r)`` (refinement included), at the last (contact) state of the
               branch and a frequency that changes at every repetition (so no per-harmonic factor
               is reused), median of ``--repeat`` (7) after one warm-up;
``nnz(J)``     stored entries of the Jacobian (``J.nnz``: for modal damping its sparse part plus
               the low-rank factors ``U, d``; the old dense path stored the assembled matrix).

``--base DIR`` reruns the modal case at N = 1e3 with ``PYTHONPATH=DIR`` (a copy of the code
before the change, e.g. ``git archive HEAD femodes | tar -x -C DIR``): the dense ``C`` of the
old ``with_damping(modal=...)``, which refused N > 5000.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time

FORCE, GAP = 0.01, 0.02
ALPHA, BETA = 0.06, 1e-4
ZETA, N_MODES = 0.02, 20
W_START, W_END = 1.40, 1.60


def build_model(N: int, damping: str):
    """The bar; ``damping`` is ``"rayleigh"``, ``"modal"`` (declared after the contact) or
    ``"modal-first"`` (declared before it, as case files do: the contact then moves the tip mass,
    and the block solver corrects the modes' relation on those rows)."""
    import femodes as fm

    mesh = fm.line_mesh(length=1.0, n_elements=N, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=FORCE)))
    if damping == "modal-first":
        return model.with_damping(modal=ZETA, n_modes=N_MODES).with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    model = model.with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    if damping == "rayleigh":
        return model.with_damping(alpha=ALPHA, beta=BETA)
    return model.with_damping(modal=ZETA, n_modes=N_MODES)


def _nnz(J) -> int:
    nnz = getattr(type(J), "nnz", None)
    return int(J.nnz) if isinstance(nnz, property) else int(J.tocsr().nnz)


def case(N: int, H: int, dampings: list, repeat: int, points: int, rounds: int) -> dict:
    """Measure the dampings side by side in one process, alternating them (module docstring)."""
    import numpy as np

    import femodes as fm

    h = fm.Harmonics(H)
    opts = fm.ContinuationOptions(step=0.02, max_step=0.05, max_points=points,
                                  newton=fm.NewtonOptions(atol=1e-7, max_iter=20))
    recs, models = {}, {}
    for d in dampings:
        t0 = time.perf_counter()
        models[d] = build_model(N, d)
        recs[d] = {"N": N, "H": H, "damping": d, "t_model": time.perf_counter() - t0, "t_point_all": []}
    # per point: `rounds` continuations of each damping, alternated
    states = {}
    for _ in range(rounds):
        for d in dampings:
            t0 = time.perf_counter()
            br = fm.frequency_response(models[d], (W_START, W_END), h, options=opts)
            dt = time.perf_counter() - t0
            pts = len(br)
            recs[d]["t_point_all"].append(dt / max(pts - 1, 1))
            recs[d].update(points=pts, its_per_point=float(np.sum(br.nit[1:])) / max(pts - 1, 1),
                           success=bool(br.success), w_last=float(br.omega[-1]))
            states[d] = br
    # per Newton iteration at the last (contact) state: residual + structured solve, alternated,
    # a new frequency every time (no per-harmonic factor reused, as in a continuation)
    probs = {}
    for d in dampings:
        br = states[d]
        pr = fm.ForcedResponseProblem(models[d], h)
        x = pr.system.join(np.asarray(br.Q[-1]), np.asarray(br.P[-1]))
        w = float(br.omega[-1])
        probs[d] = (pr, x, w)
        sol = br[len(br) - 1]
        recs[d]["active"] = bool(np.max(sol.contact_force(np.linspace(0, 2 * np.pi / w, 64))) > 0)
        recs[d].update(unknowns=int(pr.size), t_res_all=[], t_solve_all=[], t_iter_all=[])
    for i in range(repeat + 1):
        for d in dampings:
            pr, x, w = probs[d]
            wi = w * (1.0 + 1e-6 * (i + 1))
            t0 = time.perf_counter()
            r, J, _ = pr.residual(x, wi)
            t1 = time.perf_counter()
            dx = J.factorize().solve(r)
            t2 = time.perf_counter()
            if i:  # the first round warms up (imports, caches of the system)
                recs[d]["t_res_all"].append(t1 - t0)
                recs[d]["t_solve_all"].append(t2 - t1)
                recs[d]["t_iter_all"].append(t2 - t0)
            recs[d]["relres"] = float(np.max(np.abs(J @ dx - r)) / max(np.max(np.abs(r)), 1e-300))
            recs[d]["nnz_J"] = _nnz(J)
            del J
    for d in dampings:
        rec = recs[d]
        rec.update(t_point=statistics.median(rec["t_point_all"]), t_iter=statistics.median(rec["t_iter_all"]),
                   t_res=statistics.median(rec["t_res_all"]), t_solve=statistics.median(rec["t_solve_all"]))
    return recs


def _child(args_list, pythonpath=None, timeout=3600) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    out = subprocess.run([sys.executable, __file__, "--case", *map(str, args_list)], env=env, capture_output=True,
                         text=True, timeout=timeout, cwd="/tmp" if pythonpath else None)
    for line in reversed(out.stdout.splitlines()):
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    return {"error": (out.stderr.strip().splitlines() or ["no output"])[-1]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--N", type=int, nargs="+", default=[1000, 10000, 100000])
    ap.add_argument("--H", type=int, nargs="+", default=[5, 10])
    ap.add_argument("--repeat", type=int, default=7, help="Newton iterations timed per damping (median)")
    ap.add_argument("--points", type=int, default=6)
    ap.add_argument("--dampings", default="rayleigh,modal",
                    help="compared to the first one (default rayleigh,modal; also modal-first)")
    ap.add_argument("--base", help="directory holding the old femodes package (before/after at N = 1e3)")
    ap.add_argument("--json", help="write the raw records here")
    ap.add_argument("--rounds", type=int, default=3, help="continuations per damping, alternated (median)")
    ap.add_argument("--case", nargs=6, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.case:
        N, H, dampings, repeat, points, rounds = a.case
        rec = case(int(N), int(H), dampings.split(","), int(repeat), int(points), int(rounds))
        print("RESULT " + json.dumps(rec))
        return
    print(f"# bench_damping: {platform.processor() or platform.machine()}, python {platform.python_version()}, "
          "OPENBLAS_NUM_THREADS=1, median of", a.repeat)
    recs = []
    head = ("| N | H | unknowns | damping | nnz(J) | iteration [ms] | residual [ms] | solve [ms] | point [ms] "
            "| it/point | modal/Rayleigh (iteration, point) |")
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for N in a.N:
        for H in a.H:
            names = a.dampings.split(",")
            pair = _child([N, H, a.dampings, a.repeat, a.points, a.rounds])
            if "error" in pair:
                pair = {d: {"N": N, "H": H, "damping": d, "error": pair["error"]} for d in names}
            for damping in names:
                pair[damping]["code"] = "new"
                recs.append(pair[damping])
                ref = {"rayleigh": pair[names[0]], "modal": pair[damping]} if damping != names[0] else None
                print(_row(pair[damping], ref), flush=True)
            if a.base and N <= 5000:
                old = _child([N, H, "modal", a.repeat, a.points, a.rounds], pythonpath=a.base)
                rec = old.get("modal", old)
                rec.update(N=N, H=H, damping="modal (old dense C)", code="old")
                recs.append(rec)
                print(_row(rec, {"rayleigh": pair[names[0]], "modal": rec}), flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(recs, f, indent=1)


def _row(r: dict, pair) -> str:
    if "error" in r:
        return f"| {r['N']} | {r['H']} | - | {r['damping']} | - | error: {r['error'][:80]} | | | | | |"
    ratio = "-"
    if pair and "t_iter" in pair.get("rayleigh", {}) and "t_iter" in pair["modal"]:
        ratio = (f"{pair['modal']['t_iter'] / pair['rayleigh']['t_iter']:.2f}, "
                 f"{pair['modal']['t_point'] / pair['rayleigh']['t_point']:.2f}")
    return (f"| {r['N']} | {r['H']} | {r['unknowns']} | {r['damping']} | {r['nnz_J']:.3g} | {1e3 * r['t_iter']:.3g} "
            f"| {1e3 * r['t_res']:.3g} | {1e3 * r['t_solve']:.3g} | {1e3 * r['t_point']:.3g} "
            f"| {r['its_per_point']:.2g} | {ratio} |")


if __name__ == "__main__":
    main()
