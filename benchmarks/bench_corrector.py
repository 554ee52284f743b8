#!/usr/bin/env python
"""Cheap correctors at scale (issue 16, item 2): cost of a continuation point and of a corrector
iteration with and without the reuse of the per-harmonic factors across frequencies.

Run from the repository root::

    python benchmarks/bench_corrector.py --base /tmp/base          # 1e4 and 1e5 DOFs, 3 rounds (~40 min)
    python benchmarks/bench_corrector.py --base /tmp/base --quick  # 1e4 only, fewer points, 1 round (~2 min)
    python benchmarks/bench_corrector.py --N 10000 --cases tip --rounds 3 --points 12
    python benchmarks/bench_corrector.py --json out.json           # also dump the raw records
    python benchmarks/bench_corrector.py --micro --N 10000         # cost ratios, contraction (~1 min)
    PYTHONPATH=/tmp/base python benchmarks/bench_corrector.py --iter   # one iteration, fixed/moving w

``--base`` is a checkout of the tree to compare with (e.g. ``git worktree add --detach /tmp/base
HEAD`` before the change); without it only the two variants of this tree run. This is a script,
not a pytest test. Results and their discussion: ``benchmarks/README_corrector.md``.

Model (``bench_scale.py``'s): clamped-free axial P1 bar ``fm.bar(fm.line_mesh(1, N), E = rho =
A = 1, clamped="clamp")`` (N DOFs, w1 = pi/2), Rayleigh damping ``alpha = 0.2, beta = 1e-4``,
tip force ``0.01 cos(w t)``, unilateral contacts with gap 0.02: case ``tip`` one at the tip, case
``ten`` ten at x = 0.05, 0.15, ..., 0.95. H = 10 (``--H``).

Run. Newton at ``w = W_START`` from the linear response (fixed ``w``, outside the timer), then
``fm.continuation`` of the ``ForcedResponseProblem`` over ``(W_START, W_END)`` with
``frequency_response``'s options (step 0.05, max_step 0.5, Newton atol 1e-9, max_iter 20) and
its arclength scale, capped at ``--points`` points, timed (wall, ``time.perf_counter``). Every
variant runs in a fresh child process with ``OPENBLAS_NUM_THREADS = OMP_NUM_THREADS =
MKL_NUM_THREADS = 1``; the variants alternate within each round and the table gives medians over
the rounds:

``base``       the tree given by ``--base`` (``PYTHONPATH``), its default solver;
``exact``      this tree, ``BlockSolver()`` (the default: factors rebuilt at every new ``w``);
``reuse``      this tree, ``BlockSolver(reuse=True)`` (factors of a nearby frequency reused);
``assembled``  this tree, ``AssembledSolver()`` (SuperLU on the assembled Jacobian; not run by
               default: ``--variants``), a yardstick of how far two exact linear solvers move the
               branch.

Counted in the child (thin wrappers, same in both trees): ``LinearFactors`` built (the
per-harmonic factorisations), Jacobian factorisations requested (``HarmonicBlockJacobian.
factorize``: corrector iterations, tangents, line-search-free), Newton iterations
(``ContinuationResult.n_newton``), points. Per point = wall / (points - 1); per iteration = wall /
Newton iterations (everything of the run divided by the corrector iterations, tangents and
line-search residuals included); per solve = wall / factorisations requested.

Branch check: the branches of the variants must have the same points; the parent reports the
largest ``|w - w_base|`` and ``max |x - x_base| / max |x_base|`` over the points (against the first
variant of the list when ``base`` is not run), and the largest
residual ``max |r(x, w)|`` at the points of each variant (recomputed after the run, outside the
timer), against the Newton tolerance 1e-9.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from _machine import cpu_model  # noqa: E402 - benchmarks/ is on sys.path when run as a script

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

ALPHA, BETA = 0.2, 1e-4
FORCE = 0.01
GAP = 0.02
W_START, W_END = 1.5, 1.8
ATOL = 1e-9
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
TAG = "BENCH_CORRECTOR_RESULT "
CASES = ("tip", "ten")
VARIANTS = ("base", "exact", "reuse", "assembled")


# ================================================================================================
# child
# ================================================================================================
def build_model(N: int, case: str):
    import warnings

    import femodes as fm

    mesh = fm.line_mesh(length=1.0, n_elements=N, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_damping(alpha=ALPHA, beta=BETA)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=FORCE)))
    # DOF i of the clamped P1 bar sits at x = (i + 1) / N
    dofs = [N - 1] if case == "tip" else [int(round((j + 0.5) / 10 * N)) - 1 for j in range(10)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # mass redistribution notices
        return model.with_contact(*[fm.UnilateralContact(at=d, gap=GAP) for d in dofs])


def child(a) -> dict:
    import dataclasses

    import numpy as np

    import femodes as fm
    import femodes.hbm.linsolve as ls
    from femodes.analyses import _response_scale, frequency_response_options
    from femodes.hbm.problems import ForcedResponseProblem

    counts = {"linear_factors": 0, "factorize": 0}
    lf_init = ls.LinearFactors.__init__
    fz = ls.HarmonicBlockJacobian.factorize

    def counting_init(self, *args, **kw):
        counts["linear_factors"] += 1
        return lf_init(self, *args, **kw)

    def counting_factorize(self, *args, **kw):
        counts["factorize"] += 1
        return fz(self, *args, **kw)

    ls.LinearFactors.__init__ = counting_init
    ls.HarmonicBlockJacobian.factorize = counting_factorize

    model = build_model(a.N, a.case)
    if a.variant == "base":
        solver = None
    elif a.variant == "assembled":
        solver = ls.AssembledSolver()
    else:
        solver = ls.BlockSolver(reuse=(a.variant == "reuse"))
    pr = ForcedResponseProblem(model, fm.Harmonics(a.H), solver=solver)
    opts = frequency_response_options(max_points=a.points)
    res0 = fm.semismooth_newton(lambda x: pr.residual(x, W_START)[:2], pr.linear_guess(W_START),
                                options=dataclasses.replace(opts.newton, max_iter=40))
    if not res0.success:
        raise RuntimeError(f"start: {res0.message}")
    x0 = res0.x
    opts = dataclasses.replace(opts, x_scale=_response_scale(pr, (W_START, W_END), x0))
    if hasattr(solver, "reset_stats"):
        solver.reset_stats()
    for k in counts:
        counts[k] = 0
    t = time.perf_counter()
    res = fm.continuation(pr, (W_START, W_END), x0=x0, options=opts)
    wall = time.perf_counter() - t
    n = res.p.size
    resid = [float(np.max(np.abs(pr.residual(res.x[i], float(res.p[i]))[0]))) for i in range(n)]
    rec = {"N": a.N, "H": a.H, "case": a.case, "variant": a.variant, "wall": wall, "points": int(n),
           "n_newton": int(res.n_newton), "n_rejected": int(getattr(res, "n_rejected", -1)),
           "linear_factors": counts["linear_factors"], "factorize": counts["factorize"],
           "status": int(res.status), "message": str(res.message)[:160],
           "omega": [float(v) for v in res.p], "max_residual": max(resid),
           "stats": dict(solver.stats) if solver is not None and hasattr(solver, "stats") else None}
    if a.save_x:
        np.save(a.save_x, np.asarray(res.x))
    return rec


def iteration_costs(N: int, case: str, H: int, R: int = 7) -> None:
    """One bordered corrector iteration at the start point (``residual``, ``J.factorize()``,
    ``.solve``; public API only, so ``PYTHONPATH=<other tree>`` measures that tree): at a fixed
    ``w`` (the factors cached) and with ``w`` moved by 1e-4 relative each time (rebuilt)."""
    import numpy as np

    import femodes as fm
    from femodes.hbm.problems import ForcedResponseProblem
    from femodes.solvers.bordered import bordered_matrix

    pr = ForcedResponseProblem(build_model(N, case), fm.Harmonics(H))
    x = pr.linear_guess(W_START)
    c = np.random.default_rng(0).standard_normal(pr.size + 1)

    def it(w):
        t0 = time.perf_counter()
        r, J, rp = pr.residual(x, w)
        t1 = time.perf_counter()
        F = bordered_matrix(J, rp, c).factorize()
        t2 = time.perf_counter()
        F.solve(np.append(r, 0.0))
        return t1 - t0, t2 - t1, time.perf_counter() - t2

    for name, ws in (("fixed w", [W_START] * (R + 1)), ("moving w", [W_START * (1 + 1e-4 * i) for i in range(R + 1)])):
        T = np.array([it(w) for w in ws])[1:]
        m = 1e3 * np.median(T, axis=0)
        print(f"N={N} {case} {name}: residual {m[0]:.1f} ms, factorize {m[1]:.1f} ms, solve {m[2]:.1f} ms, "
              f"total {1e3 * np.median(T.sum(axis=1)):.1f} ms")


def micro(N: int, case: str, H: int, points: int) -> None:
    """Why the reuse does not pay here (README_corrector.md, "Why"): (a) the cost of refactorising
    one harmonic block against a single-column solve with its factors; (b) near the resonance,
    the contraction of ``x <- x + P^-1 (b - J x)`` with ``P`` the Jacobian whose linear part is at
    ``w0 = w (1 - dw)``: forward error after each pass, on a tangent-like system."""
    import dataclasses

    import numpy as np

    import femodes as fm
    import femodes.hbm.linsolve as ls
    from femodes.analyses import _response_scale, frequency_response_options
    from femodes.hbm.problems import ForcedResponseProblem
    from femodes.solvers.bordered import bordered_matrix

    def med(f, R=15):
        ts = []
        for _ in range(R):
            t = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t)
        return 1e3 * statistics.median(ts)

    pr = ForcedResponseProblem(build_model(N, case), fm.Harmonics(H), solver=ls.BlockSolver())
    s = pr.system
    pat = s.linear.block_pattern()
    f = H * 1.55
    lu = ls.BlockLU(pat, f)
    one = np.ones((pat.perm.size, 1), dtype=complex)
    many = np.ones((pat.perm.size, max(pat.bdofs.size, 1)), dtype=complex, order="F")
    t_lu = med(lambda: ls.BlockLU(pat, f))
    t_1 = med(lambda: lu.solve(one))
    t_nb = med(lambda: lu.solve(many))
    t_lf = med(lambda: ls.LinearFactors(s.linear, 1.55, 0.0), R=5)
    print(f"N={N} {case}: per harmonic block (n_I = {pat.perm.size}, band {pat.kl}): band LU with assembly "
          f"{t_lu:.2f} ms, one-column solve {t_1:.2f} ms ({t_lu / t_1:.1f} solves), {many.shape[1]} columns "
          f"{t_nb:.2f} ms; all {H + 1} harmonics with condensation (LinearFactors) {t_lf:.1f} ms")
    opts = frequency_response_options(max_points=points)
    x0 = fm.semismooth_newton(lambda x: pr.residual(x, W_START)[:2], pr.linear_guess(W_START),
                              options=dataclasses.replace(opts.newton, max_iter=40)).x
    opts = dataclasses.replace(opts, x_scale=_response_scale(pr, (W_START, W_END), x0))
    res = fm.continuation(pr, (W_START, W_END), x0=x0, options=opts)
    x, w = res.x[-1], float(res.p[-1])
    _, J, rp = pr.residual(x, w)
    e = np.zeros(pr.size + 1)
    e[-1] = 1.0
    Jb = bordered_matrix(J, rp, e)
    xe = ls.BlockSolver().factorize(Jb).solve(e)
    print(f"  contraction at the last of {points} points, w = {w:.5f}: forward error of pass 1, 2, ... "
          f"(relative to max |x|) and q = |d_j| / |d_(j-1)|")
    for dw in (1e-7, 1e-6, 1e-5, 1e-4, 1e-3):
        P = ls.StructuredFactorization(Jb, None, ls.LinearFactors(s.linear, w * (1 - dw), 0.0))
        xr = P._solve(e[:, None])[:, 0]
        errs, qs, d_prev = [float(np.max(np.abs(xr - xe)) / np.max(np.abs(xe)))], [], float(np.max(np.abs(xr)))
        for _ in range(7):
            d = P._solve((e - Jb.matvec(xr))[:, None])[:, 0]
            xr = xr + d
            dn = float(np.max(np.abs(d)))
            qs.append(dn / d_prev if d_prev else 0.0)
            d_prev = dn
            errs.append(float(np.max(np.abs(xr - xe)) / np.max(np.abs(xe))))
        print(f"    dw = {dw:.0e}: errors " + " ".join(f"{v:.0e}" for v in errs) + "; q(2), q(3) = "
              + ", ".join(f"{v:.1e}" for v in qs[:2]) + f"; q(2) / dw = {qs[0] / dw:.0f}")


# ================================================================================================
# parent
# ================================================================================================
def run_child(variant: str, case: str, N: int, H: int, points: int, base: str | None, xfile: str,
              timeout: float) -> dict:
    env = dict(os.environ)
    for v in THREAD_VARS:
        env[v] = "1"
    env["PYTHONPATH"] = (base if variant == "base" else ROOT) + os.pathsep + HERE
    cmd = [sys.executable, os.path.abspath(__file__), "--child", "--variant", variant, "--cases", case,
           "--N", str(N), "--H", str(H), "--points", str(points), "--save-x", xfile]
    t = time.perf_counter()
    print(f"  [{time.strftime('%H:%M:%S')}] {variant} {case} N={N} ...", end="", flush=True, file=sys.stderr)
    try:
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=HERE)
    except subprocess.TimeoutExpired:
        print(" timeout", file=sys.stderr)
        return {"variant": variant, "case": case, "N": N, "error": "timeout"}
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith(TAG)]
    if p.returncode != 0 or not lines:
        err = (p.stderr.strip().splitlines() or ["?"])[-1]
        print(f" FAILED ({err[:160]})", file=sys.stderr)
        return {"variant": variant, "case": case, "N": N, "error": err}
    rec = json.loads(lines[-1][len(TAG):])
    print(f" {time.perf_counter() - t:.1f} s (continuation {rec['wall']:.2f} s)", file=sys.stderr)
    return rec


def _med(v):
    v = [u for u in v if u is not None]
    return statistics.median(v) if v else float("nan")


def report(recs: list, variants: list) -> None:
    import numpy as np

    keys = sorted({(r["case"], r["N"]) for r in recs if "error" not in r}, key=lambda k: (k[1], k[0]))
    print("\n| N | case | variant | points | Newton it/point | factor sets/point | factorize calls/point "
          "| per point [ms] | per iteration [ms] | per factorize call [ms] | max residual "
          "| max dw vs base | max dx/x vs base |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for case, N in keys:
        ref = None
        for v in variants:
            rs = [r for r in recs if r.get("case") == case and r.get("N") == N and r.get("variant") == v
                  and "error" not in r]
            if not rs:
                continue
            pts = rs[0]["points"]
            npt = max(pts - 1, 1)
            wall = _med([r["wall"] for r in rs])
            its = rs[0]["n_newton"]
            same = all(r["points"] == pts and r["n_newton"] == its for r in rs)
            x = np.load(rs[0]["xfile"]) if os.path.exists(rs[0].get("xfile", "")) else None
            if ref is None:
                ref = (rs[0], x)
                dw = dx = "-"
            else:
                r0, x0 = ref
                if r0["points"] == pts:
                    dw = f"{max(abs(a - b) for a, b in zip(rs[0]['omega'], r0['omega'])):.1e}"
                    dx = (f"{float(np.max(np.abs(x - x0)) / np.max(np.abs(x0))):.1e}"
                          if x is not None and x0 is not None and x.shape == x0.shape else "n/a")
                else:
                    dw = dx = f"points differ ({pts} vs {r0['points']})"
            print(f"| {N} | {case} | {v} | {pts}{'' if same else ' (runs differ)'} | {its / npt:.2f} "
                  f"| {rs[0]['linear_factors'] / npt:.2f} | {rs[0]['factorize'] / npt:.2f} | {1e3 * wall / npt:.0f} "
                  f"| {1e3 * wall / max(its, 1):.0f} | {1e3 * wall / max(rs[0]['factorize'], 1):.1f} "
                  f"| {max(r['max_residual'] for r in rs):.1e} | {dw} | {dx} |")
    for r in recs:
        if r.get("stats") and r.get("round") == 0:
            print(f"stats {r['case']} N={r['N']} {r['variant']}: {r['stats']}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", help="checkout of the tree to compare with (variant 'base')")
    ap.add_argument("--quick", action="store_true", help="N = 1e4 only, 8 points, 1 round")
    ap.add_argument("--N", type=int, nargs="+", help="sizes (default 10000 100000)")
    ap.add_argument("--H", type=int, default=10)
    ap.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    ap.add_argument("--variants", nargs="+", choices=VARIANTS)
    ap.add_argument("--rounds", type=int, help="alternating rounds (default 3, quick 1)")
    ap.add_argument("--points", type=int, help="points per continuation (default 12 at 1e4, 8 at 1e5)")
    ap.add_argument("--json", help="write the raw records here")
    ap.add_argument("--timeout", type=float, default=3600)
    ap.add_argument("--iter", action="store_true", help="only the cost of one bordered iteration at fixed and "
                    "moving w (in this process; PYTHONPATH=<tree> selects the tree)")
    ap.add_argument("--micro", action="store_true", help="only the cost ratios and contraction measurements "
                    "(in this process, this tree; --N, --cases, --points)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--variant", choices=VARIANTS, help=argparse.SUPPRESS)
    ap.add_argument("--save-x", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        a.N, a.case = a.N[0], a.cases[0]
        print(TAG + json.dumps(child(a)), flush=True)
        return 0
    Ns = a.N or ([10000] if a.quick else [10000, 100000])
    if a.iter:
        for N in Ns:
            for case in a.cases:
                iteration_costs(N, case, a.H)
        return 0
    if a.micro:
        for N in Ns:
            for case in a.cases:
                micro(N, case, a.H, a.points or 8)
        return 0
    rounds = a.rounds or (1 if a.quick else 3)
    variants = a.variants or (["base", "exact", "reuse"] if a.base else ["exact", "reuse"])
    if "base" in variants and not a.base:
        ap.error("variant 'base' needs --base")
    import tempfile

    tmp = tempfile.mkdtemp(prefix="bench_corrector_")
    print(f"machine: {cpu_model()}, {os.cpu_count()} CPUs; load {os.getloadavg()[0]:.2f}; H = {a.H}; "
          f"rounds {rounds}; variants {variants}", flush=True)
    recs = []
    for rnd in range(rounds):
        for N in Ns:
            pts = a.points or (8 if a.quick or N >= 100000 else 12)
            for case in a.cases:
                order = variants if rnd % 2 == 0 else variants[::-1]
                for v in order:
                    xfile = os.path.join(tmp, f"x_{case}_{N}_{v}_{rnd}.npy")
                    rec = run_child(v, case, N, a.H, pts, a.base, xfile, a.timeout)
                    rec.update(round=rnd, xfile=xfile)
                    recs.append(rec)
    print(f"load at the end {os.getloadavg()[0]:.2f}")
    report(recs, variants)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(recs, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
