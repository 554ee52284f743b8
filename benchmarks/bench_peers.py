"""Peer benchmark: femodes against pyHarm (PyPI ``pyharm-os``) on the same contact problems.

A plain script, not a pytest test.  pyHarm is an optional dependency (``pip install -e .[bench]``);
without it the script says so and exits with status 2.  Results and remarks: ``README_peers.md``.

Cases (unit mass / stiffness, w in rad/s):

* ``seed1`` -- seed forced contact case 1 (references.md, Shi & Legrand 2016):
  ``u'' + 0.1 u' + u = 0.2 cos(w t) - p``, obstacle at ``u = 1``, w 0.5 -> 2.0;
* ``seed2`` -- seed case 2: ``u'' + 0.2 u' + u = cos(w t) - p``, obstacle at ``u = 2.5``,
  w 0.5 -> 2.0;
* ``cant20`` / ``cant200`` -- Hermite cantilever (E = rho = A = I = L = 1), 10 / 100 elements
  (20 / 200 DOFs), rigid stop at the tip with gap 0.01, Rayleigh damping ``C = 0.02 M``, tip force
  0.004 cos(w t), w 3.0 -> 4.2 (around w1 = 3.516).

Contact laws, the same problem in both tools:

* ``penalty`` -- ``p = k max(0, u - gap)``: femodes ``PenaltyContact`` (exact Galerkin projection
  of ``max(0, .)``), pyHarm ``PenaltyUnilateralGap`` (alternating frequency/time on ``N_t``
  samples).  k = 100 (1-DOF cases), 300 = 100x the static tip stiffness 3EI/L^3 (cantilever).
* ``signorini`` -- rigid obstacle: femodes ``UnilateralContact`` (complementarity, semismooth
  Newton, exact projection), pyHarm ``DLFTUniGap`` (dynamic Lagrangian frequency-time method,
  penalty parameter eps = the static stiffness at the contact DOF).  pyHarm 1.2.2's
  ``DLFTUniGap.evalResidual`` unpacks two values from a function that returns one (a
  ``ValueError`` at the first residual); this script registers a subclass that only fixes that
  unpacking (``DLFTUniGapFixed``).  DLFT's admissible side is ``u_dir >= g``, so the pyHarm
  Signorini model is written in ``v = -u`` (force and gap negated) and mapped back.

Both tools get the same matrices: the femodes model (with its default contact mass treatment:
mass of the contact node redistributed for the Signorini cantilever, consistent for penalty) is
built first and its ``M``, ``K``, ``C`` are handed to pyHarm as a matrix substructure with one DOF
per "node".

Measured per run (each run is a fresh child process with OPENBLAS/OMP/MKL_NUM_THREADS=1; the
tools alternate; ``--repeat`` repeats, medians reported): wall time of model build + whole
continuation (imports excluded; pyHarm's numba functions are compiled once and cached on disk,
a warm-up child runs before timing), accepted points, time per point, the frequency of the main
fold, the turning point at the resonance peak (femodes: of ``branch.folds``, the one with the
largest tip amplitude; pyHarm: of the points where ``w`` stops increasing along its branch, the one
with the largest amplitude, refined by a parabola in arclength; the cantilever branches have
further folds at secondary resonances, so "the fold with the largest w" would change with H), its relative
error against a reference, and the penetration ``max over points of max_t (u_tip(t) - gap)`` on
4096 samples per period.

References (``REFERENCE``; recompute with ``--make-references``): femodes at large H
(``REFERENCE_H``), same model, same law.  Equal accuracy: the smallest H of the ladder with fold
error <= ``--tol`` (default 1 %) per tool.

Usage::

    python benchmarks/bench_peers.py                  # full run
    python benchmarks/bench_peers.py --quick          # 1 repeat, one pyHarm cant200 run capped to 2 solutions
    python benchmarks/bench_peers.py --json out/peers.json --timeout 1800
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "JAX_PLATFORMS": "cpu", "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
              "NUMBA_NUM_THREADS": "1"}
N_FINE = 4096
# pyHarm continuation settings: its defaults (tangent predictor, arc-length corrector, scipy 'hybr',
# step halved on failure and doubled after 5 accepted steps) with steps suited to these unit-scale
# problems (its default ds0 = ds_max = 1 jumps over the resonance: 3 points from 0.5 to 2.36), and a
# bound on the number of solutions (accepted + rejected): on the Signorini cases its fold detection
# (sign of det J) flips the direction at every step once the branch stalls, which never ends.
PYHARM_FRF = {"study": "frf", "ds0": 0.02, "ds_max": 0.05, "ds_min": 1e-6, "verbose": False,
              "stopper": "solnumber", "stopper_options": {"max_solutions": 600}}

CASES = {
    "seed1": dict(kind="oscillator", c=0.1, force=0.2, gap=1.0, span=(0.5, 2.0), k_pen=100.0, k_static=1.0),
    "seed2": dict(kind="oscillator", c=0.2, force=1.0, gap=2.5, span=(0.5, 2.0), k_pen=100.0, k_static=1.0),
    "cant20": dict(kind="cantilever", ne=10, alpha=0.02, force=0.004, gap=0.01, span=(3.0, 4.2), k_pen=300.0,
                   k_static=3.0),
    "cant200": dict(kind="cantilever", ne=100, alpha=0.02, force=0.004, gap=0.01, span=(3.0, 4.2), k_pen=300.0,
                    k_static=3.0),
}

# Main fold frequencies of femodes at REFERENCE_H (filled from --make-references, see README_peers.md).
REFERENCE_H = {"seed1": 60, "seed2": 60, "cant20": 30, "cant200": 20}
# --make-references on 2026-11-23 (femodes working tree of that day); the cantilever branches have
# several folds (secondary resonances), the main fold is the one at the largest tip amplitude.
REFERENCE = {
    ("seed1", "penalty"): 1.348299633810206,     # H = 60: 58 points, folds 1.34830, 1.08087
    ("seed1", "signorini"): 1.406666667724767,   # H = 60: 1158 points, folds 1.40667, 1.08085
    ("seed2", "penalty"): 1.353115949352832,     # H = 60: 54 points, folds 1.35312, 1.15195
    ("seed2", "signorini"): 1.4103913151627478,  # H = 60: 628 points, folds 1.41039, 1.15190
    ("cant20", "penalty"): 4.1842335569212885,   # H = 30: 344 points, 12 folds
    ("cant20", "signorini"): 3.7501500464192175,  # H = 30: 255 points, 13 folds
    ("cant200", "penalty"): 4.193881195197448,   # H = 20: 243 points, 8 folds
    ("cant200", "signorini"): 3.7203862450080107,  # H = 20: 233 points, 10 folds
}


# --------------------------------------------------------------------------------------- models
def femodes_model(case: str, law: str):
    import femodes as fm

    p = CASES[case]
    if law == "penalty":
        contact = fm.PenaltyContact(at=0 if p["kind"] == "oscillator" else "tip", gap=p["gap"], stiffness=p["k_pen"])
    else:
        contact = fm.UnilateralContact(at=0 if p["kind"] == "oscillator" else "tip", gap=p["gap"])
    if p["kind"] == "oscillator":
        return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[p["c"]]]).with_contact(contact)
                .with_forcing(fm.HarmonicForce(at=0, amplitude=p["force"]))), 0
    mesh = fm.line_mesh(length=1.0, n_elements=p["ne"], boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = (beam.with_contact(contact).with_damping(alpha=p["alpha"])
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=p["force"])))
    return model, model.dof("tip")


def tip_signal(Q_tip: np.ndarray, n: int = N_FINE) -> np.ndarray:
    """u_tip on n phases per period from coefficients [c0, c1, s1, c2, s2, ...] (rows: points)."""
    H = (Q_tip.shape[-1] - 1) // 2
    th = 2 * np.pi * np.arange(n) / n
    E = np.ones((n, 2 * H + 1))
    for h in range(1, H + 1):
        E[:, 2 * h - 1] = np.cos(h * th)
        E[:, 2 * h] = np.sin(h * th)
    return Q_tip @ E.T


def upper_fold(omega: np.ndarray, amp: np.ndarray) -> tuple[float, bool]:
    """The main fold: of the turning points where w stops increasing, the one with the largest
    amplitude (the resonance peak); parabola w(s) through the three points around it
    (s: arclength in (w, amp) scaled by their ranges).

    Also says whether the branch *retraced* itself after that turn (the amplitude after the turn
    equals the one before at the same w, within 1e-3 of its range, at the next 3 points): then the
    turn is a reversal of the continuation, not a fold of the solution curve."""
    omega, amp = np.asarray(omega), np.asarray(amp)
    turns = [i for i in range(1, len(omega) - 1) if omega[i] >= omega[i - 1] and omega[i] > omega[i + 1]]
    if not turns:
        return float("nan"), False
    i = max(turns, key=lambda j: amp[j])
    before_w, before_a = omega[:i + 1], amp[:i + 1]
    after = [j for j in range(i + 1, min(i + 4, len(omega))) if before_w.min() <= omega[j] <= before_w.max()]
    order = np.argsort(before_w)
    retraced = bool(after) and all(
        abs(np.interp(omega[j], before_w[order], before_a[order]) - amp[j]) <= 1e-3 * (np.ptp(amp) or 1.0)
        for j in after)
    dw, da = np.ptp(omega) or 1.0, np.ptp(amp) or 1.0
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(omega) / dw, np.diff(amp) / da))])
    c = np.polyfit(s[i - 1:i + 2] - s[i], omega[i - 1:i + 2], 2)
    w = float(omega[i]) if c[0] >= 0 else float(c[2] - c[1] ** 2 / (4 * c[0]))
    return w, retraced


# --------------------------------------------------------------------------------------- runners
def run_femodes(case: str, law: str, H: int, max_points: int | None = None) -> dict:
    import femodes as fm

    t0 = time.perf_counter()
    model, tip = femodes_model(case, law)
    opts = None
    if max_points:
        from femodes.analyses import frequency_response_options
        opts = frequency_response_options(max_points=max_points)
    br = fm.frequency_response(model, CASES[case]["span"], fm.Harmonics(H), options=opts)
    wall = time.perf_counter() - t0
    folds = [float(br.omega[i]) for i in br.folds]
    u = tip_signal(br.Q[:, :, tip])
    amp = np.abs(u).max(axis=1)
    main = max(br.folds, key=lambda i: amp[i]) if br.folds else None  # the fold at the resonance peak
    return dict(wall=wall, points=len(br), fold=float(br.omega[main]) if main is not None else float("nan"),
                folds=folds, fold_amp=float(amp[main]) if main is not None else float("nan"),
                penetration=float(max(0.0, (u.max(axis=1) - CASES[case]["gap"]).max())),
                w_end=float(br.omega[-1]), success=bool(br.success), nit_mean=float(np.mean(br.nit)))


def _dlft_fixed():
    from pyHarm.Elements.NodeToNodeElements.DLFTElements.DLFTUniGap import DLFTUniGap, DLFTUniGapResidual

    class DLFTUniGapFixed(DLFTUniGap):
        """pyHarm 1.2.2's DLFTUniGap with the tuple unpacking of its residual fixed (nothing else)."""
        factory_keyword = "DLFTUniGapFixed"

        def evalResidual(self, xg, om, Rglin=None):
            self.R = DLFTUniGapResidual(xg[self.indices], om, Rglin[self.indices], float(self.nbSub), self.Pdir,
                                        self.Pslave, self.Pmaster, self.g, self.eps, self.D["ft"], self.D["tf"],
                                        self.N0)
            return self.R

    return DLFTUniGapFixed


def pyharm_input(case: str, law: str, H: int, nti: int, max_solutions: int | None = None) -> tuple[dict, int, float]:
    p = CASES[case]
    model, tip = femodes_model(case, law)
    sign = -1.0 if law == "signorini" else 1.0  # DLFT: admissible side u_dir >= g -> write in v = -u
    inp = {
        "system": {"type": "Base", "nh": H, "nti": nti},
        "substructures": {"s": {"type": "substructure", "ndofs": 1,
                                "matrix": {"M": model.M.toarray(), "K": model.K.toarray(), "C": model.C.toarray()}}},
        "connectors": {"force": {"type": "CosinusForcing", "connect": {"s": [tip]}, "dirs": [0],
                                 "amp": sign * p["force"]}},
        "analysis": {"FRF": dict(PYHARM_FRF, puls_inf=p["span"][0], puls_sup=p["span"][1])},
    }
    if law == "penalty":
        inp["connectors"]["contact"] = {"type": "PenaltyUnilateralGap", "connect": {"s": [tip]}, "dirs": [0],
                                        "k": p["k_pen"], "g": p["gap"]}
    else:
        inp["plugin"] = [_dlft_fixed()]
        inp["connectors"]["contact"] = {"type": "DLFTUniGapFixed", "connect": {"s": [tip]}, "dirs": [0],
                                        "eps": p["k_static"], "g": -p["gap"], "N0": 0.0}
    if max_solutions:
        inp["analysis"]["FRF"]["stopper_options"] = {"max_solutions": max_solutions}
    return inp, tip, sign


def run_pyharm(case: str, law: str, H: int, nti: int, max_solutions: int | None = None) -> dict:
    import logging

    from pyHarm.Maestro import Maestro

    logging.disable(logging.INFO)
    t0 = time.perf_counter()
    inp, tip, sign = pyharm_input(case, law, H, nti, max_solutions)
    m = Maestro(inp)
    m.operate()
    wall = time.perf_counter() - t0
    sols = m.nls["FRF"].SolList
    acc = [s for s in sols if s.flag_accepted]
    edf = m.system.expl_dofs
    cols = [int(edf[(edf.node_num == tip) & (edf.harm == 0)].index[0])]
    for h in range(1, H + 1):
        for cs in "cs":
            cols.append(int(edf[(edf.node_num == tip) & (edf.harm == h) & (edf.cs == cs)].index[0]))
    X = np.array([s.x for s in acc])
    omega = X[:, -1]
    u = sign * tip_signal(X[:, cols])
    amp = np.abs(u).max(axis=1)
    inside = (omega >= CASES[case]["span"][0]) & (omega <= CASES[case]["span"][1])
    fold, retraced = upper_fold(omega, amp)
    return dict(wall=wall, points=len(acc), rejected=len(sols) - len(acc), fold=float("nan") if retraced else fold, turn=fold,
                retraced=retraced,
                penetration=float(max(0.0, (u[inside].max(axis=1) - CASES[case]["gap"]).max())),
                w_end=float(omega[-1]), success=bool(omega[-1] >= CASES[case]["span"][1]))


def child(spec: dict) -> dict:
    if spec["tool"] == "femodes":
        return run_femodes(spec["case"], spec["law"], spec["H"], spec.get("cap"))
    return run_pyharm(spec["case"], spec["law"], spec["H"], spec["nti"], spec.get("cap"))


_SCRATCH: list[str] = []


def _scratch() -> str:
    """One temporary working directory for the children of this run."""
    if not _SCRATCH:
        import tempfile
        _SCRATCH.append(tempfile.mkdtemp(prefix="bench_peers_"))
    return _SCRATCH[0]


def spawn(spec: dict, timeout: float) -> dict:
    env = dict(os.environ, **THREAD_ENV)
    t0 = time.perf_counter()
    try:
        # in a scratch directory: pyHarm writes its kernel registry (.pyHarm/) into the working directory
        cp = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", json.dumps(spec)], env=env,
                            capture_output=True, text=True, timeout=timeout, cwd=_scratch())
    except subprocess.TimeoutExpired:
        return dict(spec, status="timeout", wall=float(timeout), elapsed=time.perf_counter() - t0)
    for line in cp.stdout.splitlines()[::-1]:
        if line.startswith("@@RESULT "):
            return dict(spec, status="ok", **json.loads(line[9:]))
    tail = (cp.stderr or cp.stdout).strip().splitlines()[-3:]
    return dict(spec, status="failed", error=" | ".join(tail))


# --------------------------------------------------------------------------------------- plan
def nti_for(H: int) -> int:
    """pyHarm time samples: 256 up to H = 20 (as in the earlier measurements), then 2^k >= 12 H."""
    return 256 if H <= 20 else 1 << math.ceil(math.log2(12 * H))


def plan(args) -> list[dict]:
    ladders = {"seed1": [10, 20, 40], "seed2": [10, 20, 40], "cant20": [5, 10, 20], "cant200": [10]}
    if args.quick:
        ladders = {"seed1": [10, 20, 40], "seed2": [10, 20, 40], "cant20": [5, 10], "cant200": [10]}
    specs = []
    for case in args.cases:
        for law in args.laws:
            for H in ladders[case]:
                for tool in args.tools:
                    s = dict(case=case, law=law, H=H, tool=tool)
                    if tool == "pyharm":
                        s["nti"] = nti_for(H)
                        if case == "cant200" and args.quick:
                            if law != "penalty":
                                continue  # --quick: one capped pyHarm run at 200 DOFs (penalty)
                            s["cap"] = args.cap
                    specs.append(s)
            if case == "cant200" and "femodes" in args.tools:  # like-for-like with a capped pyHarm run
                specs.append(dict(case=case, law=law, H=ladders[case][0], tool="femodes", cap=args.cap))
    return specs


def key(s):
    return (s["case"], s["law"], s["H"], s["tool"], s.get("cap"))


def summarise(records: list[dict], tol: float) -> list[dict]:
    groups: dict = {}
    for r in records:
        groups.setdefault(key(r), []).append(r)
    rows = []
    for k, rs in groups.items():
        ok = [r for r in rs if r["status"] == "ok"]
        case, law, H, tool, cap = k
        row = dict(case=case, law=law, H=H, tool=tool, cap=cap, n=len(ok), status=rs[0]["status"] if not ok else "ok",
                   nti=rs[0].get("nti"))
        if ok:
            med = lambda f: statistics.median(r[f] for r in ok)  # noqa: E731
            row.update(wall=med("wall"), points=med("points"), fold=med("fold"), penetration=med("penetration"),
                       retraced=any(r.get("retraced") for r in ok), turn=med("turn") if "turn" in ok[0] else None,
                       w_end=med("w_end"), success=all(r["success"] for r in ok),
                       walls=[round(r["wall"], 3) for r in ok])
            ref = REFERENCE.get((case, law))
            row["fold_err"] = abs(row["fold"] - ref) / ref if ref and np.isfinite(row["fold"]) else float("nan")
        else:
            row.update(wall=rs[0].get("wall", float("nan")), error=rs[0].get("error", ""))
        rows.append(row)
    return rows


def fmt(x, spec=".3g"):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    return format(x, spec)


def fold_text(r) -> str:
    if r.get("retraced"):
        return f"none: reversed onto itself at w = {fmt(r['turn'], '.4f')}"
    return fmt(r["fold"], ".5f")


def report(rows: list[dict], tol: float, args) -> str:
    from _machine import cpu_model

    out = [f"# femodes vs pyHarm ({time.strftime('%Y-%m-%d %H:%M')})", "",
           f"machine: {cpu_model()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
           f"numpy {np.__version__}; pyHarm {pyharm_version()}; BLAS/OMP/numba threads 1; "
           f"medians of {args.repeat} run(s), tools alternated; fold tolerance {tol:.0%}", "",
           "## All runs", "",
           "| case | law | H | tool | N_t | wall [s] | points | ms/point | reaches end | upper fold w | fold err | "
           "penetration | runs [s] |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        label = r["tool"] + (f" (capped {r['cap']})" if r["cap"] else "")
        if r["status"] != "ok":
            out.append(f"| {r['case']} | {r['law']} | {r['H']} | {label} | {r['nti'] or '-'} | "
                       f"{r['status']} ({fmt(r['wall'], '.0f')} s) | | | | | | | {r.get('error', '')[:80]} |")
            continue
        out.append(f"| {r['case']} | {r['law']} | {r['H']} | {label} | {r['nti'] or 'exact'} | {fmt(r['wall'])} | "
                   f"{r['points']:.0f} | {fmt(1e3 * r['wall'] / max(r['points'], 1), '.0f')} | "
                   f"{'yes' if r['success'] else 'no (w=' + fmt(r['w_end'], '.3f') + ')'} | {fold_text(r)} | "
                   f"{fmt(r['fold_err'], '.1e')} | {fmt(r['penetration'], '.2e')} | {r['walls']} |")
    out += ["", "## Equal H (ratio = pyHarm wall / femodes wall)", "",
            "| case | law | H | femodes [s] | pyHarm [s] | ratio | ms/point femodes | ms/point pyHarm | ratio per point |",
            "|---|---|---|---|---|---|---|---|---|"]
    by = {(r["case"], r["law"], r["H"], r["tool"], r["cap"]): r for r in rows}
    for r in rows:
        if r["tool"] != "femodes" or r["cap"]:
            continue
        p = by.get((r["case"], r["law"], r["H"], "pyharm", None)) or by.get((r["case"], r["law"], r["H"], "pyharm", args.cap))
        if not p:
            continue
        if p["status"] != "ok":
            out.append(f"| {r['case']} | {r['law']} | {r['H']} | {fmt(r['wall'])} | {p['status']} "
                       f"(> {fmt(p['wall'], '.0f')}) | > {fmt(p['wall'] / r['wall'], '.0f')} | | | |")
            continue
        fc = by.get((r["case"], r["law"], r["H"], "femodes", p["cap"])) if p["cap"] else r
        mspf, msph = 1e3 * fc["wall"] / fc["points"], 1e3 * p["wall"] / p["points"]
        note = f" (pyHarm capped at {p['points']:.0f} pts vs femodes {fc['points']:.0f} pts)" if p["cap"] else ""
        out.append(f"| {r['case']} | {r['law']} | {r['H']} | {fmt(fc['wall'])} | {fmt(p['wall'])}{note} | "
                   f"{fmt(p['wall'] / fc['wall'], '.2g')} | {fmt(mspf, '.0f')} | {fmt(msph, '.0f')} | "
                   f"{fmt(msph / mspf, '.2g')} |")
    out += ["", f"## Equal accuracy (smallest H of the ladder with fold error <= {tol:.0%})", "",
            "| case | law | femodes H | femodes [s] | pyHarm H | pyHarm [s] | ratio |", "|---|---|---|---|---|---|---|"]
    for case in args.cases:
        for law in args.laws:
            pick = {}
            for tool in ("femodes", "pyharm"):
                cand = sorted((r for r in rows if r["case"] == case and r["law"] == law and r["tool"] == tool
                               and not r["cap"] and r["status"] == "ok" and r["success"]
                               and r.get("fold_err", np.nan) <= tol), key=lambda r: r["H"])
                pick[tool] = cand[0] if cand else None
            f, p = pick["femodes"], pick["pyharm"]
            tried = sorted({r["H"] for r in rows if r["case"] == case and r["law"] == law and r["tool"] == "pyharm"})
            ftxt = f"{f['H']} | {fmt(f['wall'])}" if f else "not reached | -"
            ptxt = f"{p['H']} | {fmt(p['wall'])}" if p else f"not reached for H in {tried} | -"
            ratio = fmt(p["wall"] / f["wall"], ".2g") if f and p else "-"
            out.append(f"| {case} | {law} | {ftxt} | {ptxt} | {ratio} |")
    refs = ", ".join(f"{c}/{law}: {v:.6f} (H = {REFERENCE_H[c]})" for (c, law), v in REFERENCE.items()
                     if c in args.cases)
    out += ["", f"Reference upper folds (femodes at large H): {refs}"]
    return "\n".join(out)


def pyharm_version() -> str:
    try:
        from importlib.metadata import version
        return version("pyharm-os")
    except Exception:  # noqa: BLE001
        return "?"


def make_references(cases, laws, timeout):
    for case in cases:
        for law in laws:
            r = spawn(dict(case=case, law=law, H=REFERENCE_H[case], tool="femodes"), timeout)
            print(f"    ({case!r}, {law!r}): {r.get('fold')!r},  # wall {r.get('wall', 0):.1f} s, {r.get('points')} pts, "
                  f"folds {r.get('folds')}, {r['status']}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--quick", action="store_true", help="1 repeat, pyHarm cant200 only for penalty and capped to --cap solutions")
    ap.add_argument("--repeat", type=int, default=None, help="repeats per run (default 3, --quick 1)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per child (default 900)")
    ap.add_argument("--cap", type=int, default=2, help="pyHarm solutions (accepted + rejected) for capped runs")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--laws", nargs="+", default=["penalty", "signorini"], choices=["penalty", "signorini"])
    ap.add_argument("--tools", nargs="+", default=["femodes", "pyharm"], choices=["femodes", "pyharm"])
    ap.add_argument("--tol", type=float, default=0.01, help="fold error for 'equal accuracy' (default 0.01)")
    ap.add_argument("--json", help="write all raw records here")
    ap.add_argument("--make-references", action="store_true", help="compute the femodes reference folds and exit")
    args = ap.parse_args(argv)
    if args.child:
        res = child(json.loads(args.child))
        print("@@RESULT " + json.dumps(res), flush=True)
        return 0
    import importlib.util
    if importlib.util.find_spec("pyHarm") is None:  # not imported here: it writes .pyHarm/ into the cwd
        print("bench_peers.py needs pyHarm (PyPI 'pyharm-os'): pip install -e .[bench]", file=sys.stderr)
        return 2
    if args.make_references:
        make_references(args.cases, args.laws, args.timeout)
        return 0
    args.repeat = args.repeat or (1 if args.quick else 3)
    specs = plan(args)
    t_start = time.perf_counter()
    # warm-up: fills pyHarm's numba on-disk cache (njit(cache=True) residuals) before timing
    if "pyharm" in args.tools:
        for law in args.laws:
            spawn(dict(case="seed1", law=law, H=3, tool="pyharm", nti=32), args.timeout)
    records = []
    for rep in range(args.repeat):
        for i, s in enumerate(specs):
            r = spawn(s, args.timeout)
            r["repeat"] = rep
            records.append(r)
            print(f"[{time.perf_counter() - t_start:7.1f} s] rep {rep} {s['case']:7s} {s['law']:9s} H={s['H']:<3d} "
                  f"{s['tool']:7s}{' cap ' + str(s['cap']) if s.get('cap') else ''}: {r['status']} "
                  f"wall {r.get('wall', float('nan')):.2f} s, {r.get('points', '-')} pts, fold {r.get('fold', '-')}",
                  file=sys.stderr, flush=True)
    rows = summarise(records, args.tol)
    print(report(rows, args.tol, args))
    print(f"\ntotal benchmark wall time: {time.perf_counter() - t_start:.0f} s")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(dict(records=records, rows=rows, references={
            f"{c}/{law}": v for (c, law), v in REFERENCE.items()}), indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
