#!/usr/bin/env python
"""Per-iteration and per-point cost of the harmonic balance forced response of a FE beam with a stop.

Run from the repository root::

    python benchmarks/bench_hbm.py                 # N = 1e3, 1e4 DOFs; H = 10, 20; + profile (< 15 min)
    python benchmarks/bench_hbm.py --quick         # N = 1e3 only, no profile (< 2 min)
    python benchmarks/bench_hbm.py --ne 500 --H 10 --repeat 5 --no-profile
    python benchmarks/bench_hbm.py --json out/bench_hbm.json   # also dump the raw numbers

This is a script, not a pytest test. Results and their discussion: ``benchmarks/README_hbm.md``.

Model (unit properties, E = rho = A = I = L = 1): cantilever Hermite beam ``fm.beam`` on
``fm.line_mesh(1, ne)`` (N = 2 ne DOFs), Rayleigh damping ``alpha = 0.1, beta = 1e-4`` (about 1.4 %
on mode 1), tip force ``F cos(w t)`` with ``F = 0.01`` and a unilateral stop at the tip with gap
``g = 0.03`` (femodes' defaults: complementarity constant from the tip flexibility, mass of the
contact DOF redistributed). The first resonance is ``w1 = 3.516`` rad/s; the linear tip amplitude
there is several times g, so the tip hits the stop (from w ~ 3.35 on the rising side). The branch
is traced by ``fm.frequency_response(model, (3.2, 4.0), fm.Harmonics(H), options=...)`` from the
contact-free start at w = 3.2, capped at ``max_points = 30`` (``--max-points``): at N = 1e3 the 30
points cover the contact onset and the first part of the stiffened contact branch. The cap keeps the
cost per case bounded; the goal is the cost per point and per iteration, not a full curve.

Newton tolerance. ``frequency_response``'s default ``NewtonOptions(atol=1e-9)`` is absolute (on the
residual divided by the force amplitude); with this model the round-off floor of the residual lies
above it (1.7e-6 at N = 1e3, 1.7e-3 at N = 1e4), so the continuation fails at its very first
(linear) point. The benchmark therefore passes ``ContinuationOptions(step=0.05, max_step=0.5,
max_points=30, newton=NewtonOptions(atol=ATOL, max_iter=20))`` (``frequency_response``'s defaults
apart from atol and the cap) with ``ATOL = 10 * floor``: the floor is the largest residual
inf-norm met while refining the linear response at w = 3.2 by two plain Newton steps
(``_atol``; it follows whatever residual scaling ``ForcedResponseProblem`` applies).

For every (ne, H) the parent starts a fresh child process (same interpreter,
``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1``) that

1. runs the continuation once (wall time ``time.perf_counter``), counting through thin wrappers
   the residual evaluations, the bordered solves (``femodes.solvers.continuation.bordered_solver``)
   and the fixed-w solves (``default_linear_solver``), and the time spent in each;
2. at the branch point with the largest contact force (contact active), times R times each
   per-iteration piece (median reported):

   ``residual``   ``ForcedResponseProblem.residual(x, w)``: residual + sparse Jacobian + dr/dw;
   ``splu``       ``scipy.sparse.linalg.splu(J.tocsc())`` (what ``default_linear_solver`` does);
   ``solve``      one ``lu.solve(r)`` with that factorisation;
   ``bordered``   ``bordered_solver`` on the bordered matrix ``[[J, dr/dw], [c^T, 0]]`` that the
                  continuation corrector solves (assembled as ``_Branch.border`` does) -- this is the
                  linear solve of one corrector iteration (splu of J plus block elimination and up to
                  3 refinement steps);
   ``border``     the assembly of that bordered matrix from J;

3. reports ``ru_maxrss`` of the child (peak RSS of the whole case: model, problem, branch, LU).

Derived numbers: time per Newton iteration = continuation time / Newton iterations (all corrector
and fixed-w iterations, including rejected steps and fold localisation;
``ContinuationResult.n_newton``; reported n/a when Newton made fewer iterations than points, as at
N = 1e4 where the tolerance is above the predictor error), time per point = continuation time /
accepted points, ``res+border+bordered`` = the sum of the three per-iteration pieces (the cost of
one corrector iteration without line-search trials). Exponents: least-squares slope of log(time) against log N
(resp. log H) over the measured sizes.

``--profile`` (on by default unless ``--quick``): one more child runs the continuation at
ne = 5000, H = 10 under cProfile and prints the top entries by cumulative time.
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

from _machine import cpu_model  # noqa: E402 - benchmarks/ is on sys.path when run as a script

WINDOW = (3.2, 4.0)
FORCE = 0.01
GAP = 0.03
ALPHA, BETA = 0.1, 1e-4
ATOL_FACTOR = 10.0
MAX_POINTS = 30
ROW_ATOL = 1e-9 * GAP  # Newton atol on the row-scaled (displacement-like) residual
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


# ----------------------------------------------------------------------------------------------
# child side
# ----------------------------------------------------------------------------------------------
def _build(ne: int, H: int):
    import femodes as fm

    mesh = fm.line_mesh(1.0, ne, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (
        fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
        .with_damping(alpha=ALPHA, beta=BETA)
        .with_forcing(fm.HarmonicForce(at="tip", amplitude=FORCE))
        .with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    )
    return model, fm.Harmonics(H)


def _atol(pr, w0: float) -> tuple[float, float]:
    """Newton tolerance from the round-off floor of the residual; returns (atol, floor).

    At ``w0`` (below the window's contact onset, so the problem is linear) the linear response is
    refined by two plain Newton steps; the floor is the largest residual inf-norm met (it does not
    decrease further: it is round-off). ``atol = ATOL_FACTOR * floor``.
    """
    import numpy as np
    import scipy.sparse.linalg as spla

    x = pr.linear_guess(w0)
    r, J, _ = pr.residual(x, w0)
    norms = [float(np.max(np.abs(r)))]
    for _ in range(2):
        x = x - spla.splu(J.tocsc()).solve(r)
        r, J, _ = pr.residual(x, w0)
        norms.append(float(np.max(np.abs(r))))
    floor = max(norms)
    return ATOL_FACTOR * floor, floor


class RowScaled:
    """``ForcedResponseProblem`` with its equations multiplied by a fixed diagonal ``D``.

    ``D_i = 1 / sum_j |J_ij|`` from the Jacobian at the linear response at the start frequency,
    so each scaled residual entry is a displacement-like quantity whose round-off floor is
    ``~ eps * |x|`` whatever the mesh size. Same solutions, same Jacobian pattern; one extra
    sparse row scaling per evaluation.
    """

    def __init__(self, pr, w0: float):
        import numpy as np
        import scipy.sparse as sp

        self.pr = pr
        self.size = pr.size
        self.system = pr.system
        x = pr.linear_guess(w0)
        _, J, _ = pr.residual(x, w0)
        rs = np.asarray(abs(J).sum(axis=1)).ravel()
        self.d = 1.0 / np.where(rs > 0, rs, 1.0)
        self.D = sp.diags(self.d, format="csr")

    def residual(self, x, p):
        r, J, rp = self.pr.residual(x, p)
        return self.d * r, (self.D @ J).tocsr(), self.d * rp

    def linear_guess(self, w):
        return self.pr.linear_guess(w)

    def unpack(self, x, p):
        return self.pr.unpack(x, p)


def _timed(fn, repeat: int):
    out, times = None, []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, times


def child(ne: int, H: int, repeat: int, profile: bool, max_points: int = MAX_POINTS, scaling: str = "none") -> dict:
    import resource

    import numpy as np
    import scipy.sparse.linalg as spla

    import femodes as fm
    import femodes.analyses as fa
    import femodes.runs as fr
    import importlib

    # (femodes.solvers re-exports the *function* continuation, which shadows the submodule name)
    fc = importlib.import_module("femodes.solvers.continuation")
    fn = importlib.import_module("femodes.solvers.newton")

    rec: dict = {"ne": ne, "N": 2 * ne, "H": H, "max_points": max_points}
    t = time.perf_counter()
    model, h = _build(ne, H)
    rec["t_model"] = time.perf_counter() - t
    t = time.perf_counter()
    pr = fm.ForcedResponseProblem(model, h)
    rec["t_problem"] = time.perf_counter() - t
    rec["n_unknowns"] = int(pr.size)
    atol, r_lin = _atol(pr, WINDOW[0])
    rec["residual_floor"], rec["scaling"] = r_lin, scaling
    prs = None
    if scaling == "rows":
        t = time.perf_counter()
        prs = RowScaled(pr, WINDOW[0])
        rec["t_row_scaling_setup"] = time.perf_counter() - t
        atol = ROW_ATOL
    rec["atol"] = atol
    opts = fm.ContinuationOptions(step=0.05, max_step=0.5, max_points=max_points,
                                  newton=fm.NewtonOptions(atol=atol, max_iter=20))

    # ---- counting wrappers (a Python call each: negligible against the work they wrap) ----
    cnt = {"residual": 0, "t_residual": 0.0, "bordered": 0, "t_bordered": 0.0, "fixed": 0, "t_fixed": 0.0}
    orig_res = fm.ForcedResponseProblem.residual
    orig_bs, orig_dls = fc.bordered_solver, fn.default_linear_solver
    orig_cont = fr.continuation
    captured = {}

    def res_w(self, x, p):
        t0 = time.perf_counter()
        try:
            return orig_res(self, x, p)
        finally:
            cnt["residual"] += 1
            cnt["t_residual"] += time.perf_counter() - t0

    def bs_w(M, b):
        t0 = time.perf_counter()
        try:
            return orig_bs(M, b)
        finally:
            cnt["bordered"] += 1
            cnt["t_bordered"] += time.perf_counter() - t0

    def dls_w(A, b):
        t0 = time.perf_counter()
        try:
            return orig_dls(A, b)
        finally:
            cnt["fixed"] += 1
            cnt["t_fixed"] += time.perf_counter() - t0

    def cont_w(*a, **k):
        res = orig_cont(*a, **k)
        captured["res"] = res
        return res

    fm.ForcedResponseProblem.residual = res_w
    fc.bordered_solver = bs_w
    fn.default_linear_solver = dls_w
    fr.continuation = cont_w
    prof = None
    if profile:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    t = time.perf_counter()
    if prs is None:
        br = fm.frequency_response(model, WINDOW, h, options=opts)
    else:  # what frequency_response does, on the row-scaled equations
        res = fc.continuation(prs, WINDOW, x0=prs.linear_guess(WINDOW[0]), options=opts)
        captured["res"] = res
        br = fa.branch_from_continuation(pr, res, kind="forced", model=model, meta={"span": list(WINDOW)})
    rec["t_continuation"] = time.perf_counter() - t
    if prof is not None:
        prof.disable()
    fm.ForcedResponseProblem.residual = orig_res
    fc.bordered_solver, fn.default_linear_solver, fr.continuation = orig_bs, orig_dls, orig_cont

    cres = captured.get("res")
    rec.update(
        points=len(br), success=bool(br.success), message=str(br.message), folds=len(br.folds),
        nit_accepted=[int(v) for v in br.nit],
        n_newton=int(cres.n_newton) if cres is not None else int(np.sum(br.nit)),
        n_rejected=int(cres.n_rejected) if cres is not None else -1,
        calls=cnt,
        max_contact_force=float(np.max(np.abs(br.P[:, 0, 0]))) if len(br) else 0.0,
        omega_end=float(br.omega[-1]) if len(br) else float("nan"),
    )
    if prof is not None:
        import io
        import pstats

        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats("cumulative").print_stats(25)
        rec["profile"] = s.getvalue()
        st = pstats.Stats(prof)
        rec["profile_total"] = st.total_tt
        return rec

    # ---- per-iteration pieces at the point of largest contact force ----
    if len(br):
        i = int(np.argmax(np.abs(br.P[:, 0, 0])))
        from femodes.hbm.system import HBMSystem  # noqa: F401  (layout only)

        x = np.concatenate([br.Q[i].ravel(), br.P[i].ravel()])
        w = float(br.omega[i])
    else:
        x, w = pr.linear_guess(WINDOW[0]), WINDOW[0]
    (r, J, rp), t_res = _timed(lambda: pr.residual(x, w), repeat)
    rec["nnz_J"] = int(J.nnz)
    if prs is not None:
        (r, J, rp), t_res_s = _timed(lambda: prs.residual(x, w), repeat)
        rec["t_res_scaled"] = t_res_s
    Jc = J.tocsc()
    lu, t_lu = _timed(lambda: spla.splu(Jc), repeat)
    rec["nnz_LU"] = int(lu.L.nnz + lu.U.nnz)
    # the lambda runs inside _timed, before the del below (which is what F821 sees)
    _, t_sol = _timed(lambda: lu.solve(r), max(repeat, 5))  # noqa: F821
    del lu
    c = np.zeros(J.shape[0] + 1)
    c[-1] = 1.0
    c[:-1] = 1.0 / J.shape[0]
    from femodes.solvers.continuation import bordered_matrix

    Mb, t_border = _timed(lambda: bordered_matrix(J, rp, c), repeat)
    rhs = np.append(r, 0.0)
    _, t_bord = _timed(lambda: orig_bs(Mb, rhs), repeat)
    rec.update(t_res=t_res, t_splu=t_lu, t_solve=t_sol, t_border=t_border, t_bordered=t_bord)
    rec["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return rec


# ----------------------------------------------------------------------------------------------
# parent side
# ----------------------------------------------------------------------------------------------
def run_child(ne: int, H: int, repeat: int, profile: bool = False, max_points: int = MAX_POINTS,
              scaling: str = "none", timeout: float = 1800) -> dict:
    env = dict(os.environ)
    for v in THREAD_VARS:
        env[v] = "1"
    cmd = [sys.executable, os.path.abspath(__file__), "--child", str(ne), str(H), "--repeat", str(repeat),
           "--max-points", str(max_points), "--scaling", scaling]
    if profile:
        cmd.append("--child-profile")
    t = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise RuntimeError(f"child ne={ne} H={H} failed:\n{p.stderr[-4000:]}")
    rec = json.loads(p.stdout.strip().splitlines()[-1])
    rec["child_wall"] = wall
    return rec


def _med(v):
    return statistics.median(v)


def _per_it(r) -> str:
    """Continuation time / Newton iterations; n/a when Newton hardly iterated (< 1 per point)."""
    if r["n_newton"] < r["points"]:
        return f"n/a ({r['n_newton']} its)"
    return f"{r['t_continuation'] / r['n_newton'] * 1e3:.0f}"


def _fit(xs, ys):
    import numpy as np

    if len(xs) < 2:
        return float("nan")
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


def machine_info() -> dict:
    import numpy
    import scipy

    cpu = cpu_model("")
    try:
        from importlib.metadata import version

        skfem = version("scikit-fem")
    except Exception:  # pragma: no cover
        skfem = "?"
    import femodes

    return {
        "cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "numpy": numpy.__version__,
        "scipy": scipy.__version__, "scikit-fem": skfem, "femodes": getattr(femodes, "__version__", "?"),
        "threads": "OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1 (children)",
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="ne = 500 only (N = 1e3), no profile")
    ap.add_argument("--ne", type=int, nargs="+", help="numbers of elements (N = 2 ne), default 500 5000")
    ap.add_argument("--H", type=int, nargs="+", default=[10, 20], help="numbers of harmonics")
    ap.add_argument("--repeat", type=int, default=None, help="repeats of the per-iteration pieces")
    ap.add_argument("--max-points", type=int, default=MAX_POINTS,
                    help="cap of continuation points (ContinuationOptions.max_points)")
    ap.add_argument("--scaling", choices=["rows", "none"], default="none",
                    help="none (default): fm.frequency_response with atol = 10 x the round-off floor; "
                         "rows: experimental, continuation of the row-scaled equations with atol=1e-9*gap "
                         "(does not help at N=1e4, see README_hbm.md)")
    ap.add_argument("--no-profile", action="store_true")
    ap.add_argument("--profile-max-points", type=int, default=None, help="default: --max-points")
    ap.add_argument("--profile-ne", type=int, default=5000)
    ap.add_argument("--profile-H", type=int, default=10)
    ap.add_argument("--json", help="write the raw records to this file")
    ap.add_argument("--child", nargs=2, type=int, help=argparse.SUPPRESS)
    ap.add_argument("--child-profile", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)

    if a.child:
        rec = child(a.child[0], a.child[1], a.repeat or 3, a.child_profile, a.max_points, a.scaling)
        print(json.dumps(rec))
        return 0

    ne_list = a.ne or ([500] if a.quick else [500, 5000])
    profile = not (a.quick or a.no_profile)
    info = machine_info()
    print("machine:", json.dumps(info))
    print(f"model: cantilever beam, F={FORCE}, gap={GAP}, alpha={ALPHA}, beta={BETA}, window={WINDOW}")
    t_all = time.perf_counter()
    recs = []
    for ne in ne_list:
        for H in a.H:
            repeat = a.repeat or (5 if ne <= 1000 else 3)
            rec = run_child(ne, H, repeat, max_points=a.max_points, scaling=a.scaling)
            recs.append(rec)
            c = rec["calls"]
            print(
                f"ne={ne} N={rec['N']} H={H}: unknowns={rec['n_unknowns']} nnz(J)={rec.get('nnz_J')} "
                f"nnz(L+U)={rec.get('nnz_LU')} atol={rec['atol']:.2e} (floor {rec['residual_floor']:.1e}) | "
                f"continuation {rec['t_continuation']:.1f} s, {rec['points']} points, {rec['n_newton']} Newton its, "
                f"{rec['n_rejected']} rejected, {rec['folds']} folds, success={rec['success']} ({rec['message']}); "
                f"residual calls {c['residual']} ({c['t_residual']:.1f} s), bordered solves {c['bordered']} "
                f"({c['t_bordered']:.1f} s), fixed-w solves {c['fixed']} ({c['t_fixed']:.1f} s) | "
                f"residual {_med(rec['t_res'])*1e3:.1f} ms, splu {_med(rec['t_splu'])*1e3:.1f} ms, "
                f"solve {_med(rec['t_solve'])*1e3:.2f} ms, border {_med(rec['t_border'])*1e3:.1f} ms, "
                f"bordered_solver {_med(rec['t_bordered'])*1e3:.1f} ms | peak RSS {rec['peak_rss_mib']:.0f} MiB "
                f"| child wall {rec['child_wall']:.0f} s",
                flush=True,
            )

    # ---- table ----
    hdr = ("| N | H | unknowns | nnz(J) | residual+J [ms] | splu(J) [ms] | solve [ms] | bordered solve [ms] "
           "| res+border+bordered [ms] | per Newton it. [ms] | per point [s] | Newton its / point | residual calls / it. "
           "| points | peak RSS [MiB] |")
    print()
    print(hdr)
    print("|" + "|".join(["---"] * (hdr.count("|") - 1)) + "|")
    for r in recs:
        nit_pt = r["n_newton"] / max(r["points"], 1)
        print(
            f"| {r['N']} | {r['H']} | {r['n_unknowns']} | {r['nnz_J']} | {_med(r['t_res'])*1e3:.1f} | "
            f"{_med(r['t_splu'])*1e3:.1f} | {_med(r['t_solve'])*1e3:.2f} | {_med(r['t_bordered'])*1e3:.1f} | "
            f"{(_med(r['t_res']) + _med(r['t_border']) + _med(r['t_bordered'])) * 1e3:.0f} | "
            f"{_per_it(r)} | {r['t_continuation'] / max(r['points'], 1):.2f} | "
            f"{nit_pt:.1f} | {r['calls']['residual'] / max(r['n_newton'], 1):.1f} | {r['points']} | {r['peak_rss_mib']:.0f} |"
        )

    # ---- exponents ----
    keys = [("residual+J", lambda r: _med(r["t_res"])), ("splu", lambda r: _med(r["t_splu"])),
            ("solve", lambda r: _med(r["t_solve"])), ("bordered solve", lambda r: _med(r["t_bordered"])),
            ("res+border+bordered", lambda r: _med(r["t_res"]) + _med(r["t_border"]) + _med(r["t_bordered"])),
            ("per point", lambda r: r["t_continuation"] / max(r["points"], 1)),
            ("nnz(J)", lambda r: r["nnz_J"]), ("peak RSS", lambda r: r["peak_rss_mib"])]
    Hs = sorted({r["H"] for r in recs})
    Ns = sorted({r["N"] for r in recs})
    print()
    if len(Ns) > 1 or len(Hs) > 1:
        print("| quantity | " + " | ".join([f"exp. in N (H={H})" for H in Hs] if len(Ns) > 1 else [])
              + (" | " if len(Ns) > 1 and len(Hs) > 1 else "")
              + " | ".join([f"exp. in H (N={N})" for N in Ns] if len(Hs) > 1 else []) + " |")
        ncol = (len(Hs) if len(Ns) > 1 else 0) + (len(Ns) if len(Hs) > 1 else 0)
        print("|" + "|".join(["---"] * (ncol + 1)) + "|")
        for name, f in keys:
            cells = []
            if len(Ns) > 1:
                for H in Hs:
                    rr = sorted([r for r in recs if r["H"] == H], key=lambda r: r["N"])
                    cells.append(f"{_fit([r['N'] for r in rr], [f(r) for r in rr]):.2f}")
            if len(Hs) > 1:
                for N in Ns:
                    rr = sorted([r for r in recs if r["N"] == N], key=lambda r: r["H"])
                    cells.append(f"{_fit([r['H'] for r in rr], [f(r) for r in rr]):.2f}")
            print(f"| {name} | " + " | ".join(cells) + " |")

    prof = None
    if profile:
        print(f"\nprofile: continuation at ne={a.profile_ne}, H={a.profile_H} under cProfile ...", flush=True)
        prof = run_child(a.profile_ne, a.profile_H, 1, profile=True,
                         max_points=a.profile_max_points or a.max_points, scaling=a.scaling)
        print(f"(continuation {prof['t_continuation']:.1f} s under the profiler, {prof['points']} points, "
              f"{prof['n_newton']} Newton its)")
        print(prof["profile"])
    print(f"total benchmark wall time {time.perf_counter() - t_all:.0f} s")
    if a.json:
        os.makedirs(os.path.dirname(os.path.abspath(a.json)), exist_ok=True)
        with open(a.json, "w") as f:
            json.dump({"machine": info, "cases": recs, "profile": prof}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
