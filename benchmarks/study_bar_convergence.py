"""The clamped bar with a stop: its first nonsmooth mode under mesh and harmonic refinement against
the continuum (issue 35 item 2). README_bar_convergence.md reads the results.

Two studies, both against the d'Alembert reference (tests/bar_stop_reference.py: ``w / w1 = 4 / T``,
``T = 3 + 2 sqrt(2) / (pi sqrt(E / E_g))``), energies in the continuum's ``E_g = pi^2 g^2 / 16``:

``sweep`` (default): ``fm.nonlinear_mode(..., energy=(0.5, 25) E_g, harmonics=H)`` as a user runs it
  (the period-driven contact-phase family past grazing). Each run stores its frequency at 2, 5
  and 20 E_g, where it stopped, and every kept orbit ``(w, E)`` above grazing, so that errors over
  the whole family can be formed afterwards (:func:`family_errors`).
``fixed``: the error at fixed frequencies, nested. The 13 frequencies of the reference at
  ``E = 2 ... 20 E_g`` (geometric), the first level's orbits interpolated from its sweep, each
  next level (finer mesh: nodal values interpolated; more harmonics: zero coefficients appended)
  solved by Newton from the previous level's orbit at the same frequency
  (:class:`femodes.hbm.PeriodDrivenModeProblem`). An orbit whose traced mode holds less than 25 %
  of the energy (the rule of ``fm.PeriodDriven``), below ``E_g`` (Newton fell onto the trivial
  orbit), or whose Newton solve fails, is not counted.

Results are appended to benchmarks/results_bar_convergence.json run by run (an interrupted study
keeps what it computed); CPU time is ``time.process_time`` with one BLAS thread.

    OPENBLAS_NUM_THREADS=1 python benchmarks/study_bar_convergence.py sweep --runs 20:10,40:20 [--consistent]
    OPENBLAS_NUM_THREADS=1 python benchmarks/study_bar_convergence.py fixed --levels 20:10,40:10,80:10 [--consistent]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

import femodes as fm
from femodes.hbm import NonlinearModeProblem, PeriodDrivenModeProblem
from femodes.nonsmooth_modes import modal_energy_fractions
from femodes.solvers import NewtonOptions, semismooth_newton

HERE = Path(__file__).resolve().parent
OUT = HERE / "results_bar_convergence.json"
GAP = 0.01
W1 = math.pi / 2
EG = math.pi ** 2 * GAP ** 2 / 16  # the continuum's grazing energy: every mesh compared at the same energies
FACTORS = (2.0, 5.0, 20.0)
A_CONTINUUM = 2.0 * math.sqrt(2.0) / math.pi
MIN_SHARE = 0.25  # fm.PeriodDriven().min_fraction


def continuum_omega(r):
    """The reference's frequency at ``E = r E_g``."""
    return 4.0 * W1 / (3.0 + A_CONTINUUM / np.sqrt(r))


def bar_model(n: int, redistribute: bool = True):
    mesh = fm.line_mesh(1.0, n, boundaries={"clamp": 0.0, "tip": 1.0})
    model = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    return model.with_contact(fm.UnilateralContact(at="tip", gap=GAP),
                              contact_mass=fm.RedistributeMass() if redistribute else fm.ConsistentMass())


def family_errors(omega, energy_ratio, span=(2.0, 20.0)):
    """Errors over the family's orbits with ``E / E_g`` in ``span``: the pointwise relative errors
    ``w / w_ref(E) - 1``, and the least-squares ``a`` of ``T = 3 + a / sqrt(E / E_g)`` (``T = 4 w1 / w``)
    with its relative error against the continuum's ``2 sqrt(2) / pi``."""
    w, r = np.asarray(omega, float), np.asarray(energy_ratio, float)
    m = (r >= span[0]) & (r <= span[1])
    e = w[m] / continuum_omega(r[m]) - 1.0
    x, y = 1.0 / np.sqrt(r[m]), 4.0 * W1 / w[m] - 3.0
    a = float(x @ y / (x @ x)) if m.any() else math.nan
    return {"n_orbits": int(m.sum()), "rms": float(np.sqrt(np.mean(e ** 2))) if m.any() else math.nan,
            "median_abs": float(np.median(np.abs(e))) if m.any() else math.nan,
            "mean": float(np.mean(e)) if m.any() else math.nan, "a": a, "a_error": a / A_CONTINUUM - 1.0}


def sweep(n: int, H: int, redistribute: bool) -> dict:
    model = bar_model(n, redistribute)
    eg = fm.grazing_energy(model)
    t = time.process_time()
    br = fm.nonlinear_mode(model, 1, energy=(0.5 * eg, 25 * eg), harmonics=H)
    cpu = time.process_time() - t
    o = np.argsort(br.energy)
    w = [float(np.interp(math.log(f * EG), np.log(br.energy[o]), br.omega[o], left=np.nan, right=np.nan))
         for f in FACTORS]
    ref = [float(continuum_omega(f)) for f in FACTORS]
    above = br.energy > eg
    return {"study": "sweep", "elements": n, "H": H, "mass": "redistributed" if redistribute else "consistent",
            "omega": w, "reference": ref, "error": [wi / ri - 1 for wi, ri in zip(w, ref)],
            "reached_E_over_Eg": float(br.energy.max() / EG), "points": len(br), "cpu_s": cpu,
            "family": br.meta.get("family"), "message": br.message,
            "tongues": len(br.meta.get("internal_resonances", [])),
            "orbits": {"omega": br.omega[above].tolist(), "E_over_Eg": (br.energy[above] / EG).tolist()},
            "family_errors": family_errors(br.omega[above], br.energy[above] / EG)}


def _prolong(Q: np.ndarray, n_dofs: int) -> np.ndarray:
    """Nodal coefficients of a uniform clamped P1 bar on the mesh twice as fine (linear interpolation,
    DOFs ordered from the clamp), repeated up to ``n_dofs``."""
    while Q.shape[1] < n_dofs:
        fine = np.zeros((Q.shape[0], 2 * Q.shape[1]))
        fine[:, 1::2] = Q
        left = np.concatenate([np.zeros((Q.shape[0], 1)), Q[:, :-1]], axis=1)
        fine[:, 0::2] = 0.5 * (left + Q)
        Q = fine
    return Q


def _pad(A: np.ndarray, n_coef: int) -> np.ndarray:
    out = np.zeros((n_coef, A.shape[1]))
    out[: min(n_coef, A.shape[0])] = A[:n_coef]
    return out


def fixed_frequency(levels: list[tuple[int, int]], redistribute: bool, n_freq: int = 13):
    """The nested fixed-frequency study (module docstring); yields one record per level."""
    rhos = np.geomspace(2.0, 20.0, n_freq)
    ws = continuum_omega(rhos)
    newton = NewtonOptions(atol=1e-9, max_iter=40)
    n0, H0 = levels[0]
    m0 = bar_model(n0, redistribute)
    eg0 = fm.grazing_energy(m0)
    br = fm.nonlinear_mode(m0, 1, energy=(0.5 * eg0, 25 * eg0), harmonics=H0)
    o = np.argsort(br.omega)

    def interp(A, w):
        flat = A[o].reshape(len(o), -1)
        return np.array([np.interp(w, br.omega[o], flat[:, k]) for k in range(flat.shape[1])]).reshape(A.shape[1:])

    states = [(interp(br.Q, w), interp(br.P, w)) for w in ws]
    for n, H in levels:
        model = bar_model(n, redistribute)
        h = fm.Harmonics(n_harmonics=H)
        base = NonlinearModeProblem(model, h, 1, reference_energy=EG)
        pd = PeriodDrivenModeProblem(model, h, 1, reference_energy=EG)
        lm = fm.linear_modes(model, n=12)
        t = time.process_time()
        rows, new = [], []
        for (Q, P), w in zip(states, ws):
            x0 = pd.pack(_pad(_prolong(Q, model.n_dofs), h.n_coef), _pad(P, h.n_coef), w)
            res = semismooth_newton(lambda z, w=w: pd.residual(z, w)[:2], x0, options=newton)
            ok = bool(res.success)
            E = float(pd.system.energy(res.x[: pd.system.size], w)[0]) if ok else math.nan
            share = float(modal_energy_fractions(base, res.x, lm.omega, lm.shapes)[0]) if ok else math.nan
            u = pd.unpack(res.x, 0.0)
            new.append((u.Q, u.P) if ok else (_pad(_prolong(Q, model.n_dofs), h.n_coef), _pad(P, h.n_coef)))
            kept = ok and share >= MIN_SHARE and E > EG  # on the family: above grazing, mode 1 not given away
            err = float(w / continuum_omega(E / EG) - 1.0) if kept else math.nan
            rows.append({"omega": float(w), "E_over_Eg": E / EG, "share": share, "error": err, "kept": kept,
                         "nit": int(res.nit)})
        states = new
        yield {"study": "fixed", "levels": [list(lv) for lv in levels], "elements": n, "H": H,
               "mass": "redistributed" if redistribute else "consistent", "cpu_s": time.process_time() - t,
               "reference_E_over_Eg": rhos.tolist(), "rows": rows}


def log_slope(x, y, sigma=None) -> tuple[float, float]:
    """Least-squares slope of ``log y`` against ``log x`` (weights ``1 / sigma``, ``sigma`` the standard
    errors of ``log y``) and its standard error: from the weights, scaled up by the residuals'
    reduced chi-square when that exceeds 1 (without weights: from the residuals)."""
    lx, ly = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
    wts = np.ones_like(lx) if sigma is None else 1.0 / np.asarray(sigma, float)
    A = np.column_stack([lx, np.ones_like(lx)]) * wts[:, None]
    coef, *_ = np.linalg.lstsq(A, ly * wts, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    res = (ly - coef[0] * lx - coef[1]) * wts
    scale = float(res @ res) / max(lx.size - 2, 1)
    if sigma is not None:
        scale = max(scale, 1.0)
    return float(coef[0]), float(math.sqrt(cov[0, 0] * scale))


def family_mean(record: dict, span=(2.0, 8.0)) -> tuple[float, float, int]:
    """Mean relative error of a sweep's orbits with ``E / E_g`` in ``span``, its standard error and
    the number of orbits (the tongues' pull scatters single orbits both ways; their mean keeps the
    bias of the truncation)."""
    w, r = np.array(record["orbits"]["omega"]), np.array(record["orbits"]["E_over_Eg"])
    m = (r >= span[0]) & (r <= span[1])
    e = w[m] / continuum_omega(r[m]) - 1.0
    if e.size < 2:
        return math.nan, math.nan, int(e.size)
    return float(e.mean()), float(e.std(ddof=1) / math.sqrt(e.size)), int(e.size)


def harmonic_rate(records, elements: int, harmonics=(10, 15, 20, 30, 40), span=(2.0, 8.0)):
    """``q`` of ``|family mean| ~ H^-q`` on one mesh (redistributed mass), with its standard error."""
    pts = []
    for r in records:
        if (r.get("study") == "sweep" and r["elements"] == elements and r["H"] in harmonics
                and r["mass"] == "redistributed" and r.get("family") == "contact phase"):
            m, se, k = family_mean(r, span)
            if k >= 2:
                pts.append((r["H"], abs(m), se / abs(m)))
    pts.sort()
    if len(pts) < 3:
        return math.nan, math.nan, []
    H, m, s = (np.array(v) for v in zip(*pts))
    slope, err = log_slope(H, m, s)
    return -slope, err, [int(h) for h in H]


def mesh_rate(records, mass: str):
    """``p`` of the fixed-frequency study's median change ``|error(2N) - error(N)| ~ N^-p`` (H = 10,
    frequencies kept on every mesh), with its standard error, and the changes."""
    levels = sorted((r for r in records if r.get("study") == "fixed" and r["mass"] == mass and r["H"] == 10
                     and all(lv[1] == 10 for lv in r["levels"])), key=lambda r: r["elements"])
    if len(levels) < 3:
        return math.nan, math.nan, [], []
    E = np.array([[row["error"] if row["kept"] else np.nan for row in r["rows"]] for r in levels])
    ok = np.all(np.isfinite(E), axis=0)
    change = np.median(np.abs(np.diff(E[:, ok], axis=0)), axis=1)
    N = [r["elements"] for r in levels[:-1]]
    slope, err = log_slope(N, change)
    return -slope, err, N, change.tolist()


def report(records) -> str:
    """The README's tables from the results."""
    ref = continuum_omega(np.array(FACTORS))
    out = ["| elements | H | mass | w at 2 E_g (error) | w at 5 E_g (error) | w at 20 E_g (error) | reached | "
           "mean error 2-8 E_g (orbits) | CPU |", "|---|---|---|---|---|---|---|---|---|",
           "| continuum | | | " + " | ".join(f"{w:.5f}" for w in ref) + " | | | |"]
    sweeps = sorted((r for r in records if r.get("study") == "sweep"), key=lambda r: (r["mass"] != "redistributed",
                                                                                     r["H"], r["elements"]))
    for r in sweeps:
        cells = [f"{w:.5f} ({e:+.2%})" if math.isfinite(w) else "-" for w, e in zip(r["omega"], r["error"])]
        if r.get("family") != "contact phase":
            cells = ["grazing family"] * 3
        m, se, k = family_mean(r) if r.get("family") == "contact phase" else (math.nan, math.nan, 0)
        mean = f"{m:+.2%} +- {se:.2%} ({k})" if math.isfinite(m) else f"- ({k})"
        out.append(f"| {r['elements']} | {r['H']} | {r['mass'][:5]}. | " + " | ".join(cells)
                   + f" | {r['reached_E_over_Eg']:.1f} E_g | {mean} | {r['cpu_s']:.0f} s |")
    out.append("")
    for n in (80, 160, 320):
        q, dq, Hs = harmonic_rate(records, n)
        if Hs:
            out.append(f"- harmonic rate on {n} elements (H = {', '.join(map(str, Hs))}): q = {q:.2f} +- {dq:.2f}")
    for mass in ("redistributed", "consistent"):
        p, dp, N, change = mesh_rate(records, mass)
        if N:
            out.append(f"- mesh rate, {mass} mass (H = 10, fixed frequencies): p = {p:.2f} +- {dp:.2f}; median changes "
                       + ", ".join(f"{n}->{2 * n}: {c:.3%}" for n, c in zip(N, change)))
    others = [r for r in records if r.get("study") == "fixed" and not all(lv[1] == 10 for lv in r["levels"])]
    for r in others:  # the harmonic series on one mesh, and the diagonal
        e = np.array([row["error"] for row in r["rows"] if row["kept"]])
        path = " -> ".join(f"{n}/{H}" for n, H in r["levels"])
        out.append(f"- fixed frequencies ({path}), {r['elements']} elements, H = {r['H']}: {e.size} of {len(r['rows'])} orbits on "
                   f"the family, median |error| {np.median(np.abs(e)):.2%}, largest {np.max(np.abs(e)):.2%}")
    return "\n".join(out)


def _save(record: dict) -> None:
    done = json.loads(OUT.read_text()) if OUT.exists() else []
    done.append(record)
    OUT.write_text(json.dumps(done, indent=1))


def _have(study, **key) -> bool:
    done = json.loads(OUT.read_text()) if OUT.exists() else []
    return any(r.get("study", "sweep") == study and all(r.get(k) == v for k, v in key.items()) for r in done)


def main() -> None:
    global OUT
    ap = argparse.ArgumentParser()
    ap.add_argument("study", nargs="?", default="sweep", choices=("sweep", "fixed", "report"))
    ap.add_argument("--runs", default="20:10,40:10,80:10,160:10,320:10,40:20,80:20,160:20,320:20,80:40,160:40,320:40,"
                                      "160:80,320:80")
    ap.add_argument("--levels", default="20:10,40:10,80:10,160:10,320:10")
    ap.add_argument("--consistent", action="store_true")
    ap.add_argument("--out", default=str(HERE / "results_bar_convergence.json"), help="results file (one per concurrent process)")
    a = ap.parse_args()
    OUT = Path(a.out)
    mass = "consistent" if a.consistent else "redistributed"
    if a.study == "report":
        print(report(json.loads(OUT.read_text())))
    elif a.study == "sweep":
        for item in a.runs.split(","):
            n, H = (int(v) for v in item.split(":"))
            if _have("sweep", elements=n, H=H, mass=mass):
                continue
            r = sweep(n, H, not a.consistent)
            _save(r)
            fe = r["family_errors"]
            print(f"{n:4d} el H = {H:3d} {mass:13s}: errors at 2/5/20 E_g "
                  + " ".join(f"{e:+.3%}" for e in r["error"]) + f"  reached {r['reached_E_over_Eg']:.1f} E_g, "
                  f"{fe['n_orbits']} orbits in [2, 20] E_g: rms {fe['rms']:.3%}, a error {fe['a_error']:+.3%}, "
                  f"{r['cpu_s']:.0f} s", flush=True)
    else:
        levels = [tuple(int(v) for v in item.split(":")) for item in a.levels.split(",")]
        for r in fixed_frequency(levels, not a.consistent):
            _save(r)
            e = np.array([row["error"] for row in r["rows"]])
            print(f"{r['elements']:4d} el H = {r['H']:3d} {mass}: fixed-frequency errors "
                  + " ".join(f"{v:+.3%}" for v in e) + f"  ({r['cpu_s']:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
