#!/usr/bin/env python
"""Which factorisation for a mid-size HBM Jacobian (250 to ~4000 unknowns): the cost of one
factorisation and solve of a bordered Jacobian (a continuation corrector's linear system) by each
path of ``BlockSolver`` side by side, on line, 2-D and 3-D meshes with Rayleigh and modal damping,
a 1-DOF contact at many harmonics and a Craig-Bampton blade. Writes
``benchmarks/results_solver_paths.json``; discussion in ``benchmarks/README_solver_paths.md``.

    python benchmarks/bench_solver_paths.py            # ~6 min

Paths: ``dense`` (LAPACK on the assembled dense matrix, ``DenseFactorization``), ``assembled``
(SuperLU on the assembled sparse matrix; with modal damping its augmented form,
``AssembledFactorization``), ``structured`` (per-harmonic factors and a dense Schur complement on
the nonlinear DOFs and border, ``StructuredFactorization``), and ``default`` (what
``BlockSolver()`` picks). Each: median of 7 of ``factorize + solve`` (wall time, one BLAS
thread), at a random state of the unknowns (the cost does not depend on it), 10 % above the first
linear frequency, each factorisation at a frequency of its own (no cached factors). The paths run
interleaved, so that the machine's load falls on all alike. Then, for each case, the time of a
40-point frequency response with the block solver's defaults before and after the change
(:func:`branch_times`), the measure the defaults were chosen on.
"""
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "examples"))
import femodes as fm  # noqa: E402
from femodes.hbm.linsolve import (AssembledFactorization, BlockSolver, BlockSolverOptions,  # noqa: E402
                                  DEFAULT_OPTIONS, DenseFactorization)
import femodes.hbm.linsolve.solver as S  # noqa: E402 (the default options a BlockSolver() takes)
from _machine import cpu_model  # noqa: E402

#: the structured path at every size above ``dense_max_size``, otherwise the default tuning
STRUCTURED = dataclasses.replace(DEFAULT_OPTIONS, structured_min_size=0, structured_min_size_narrow=0)


def damped(model, damping):
    return model.with_damping(modal=0.01) if damping == "modal" else model.with_damping(beta=1e-3, alpha=1e-3)


def line(kind, n_el, damping):
    mesh = fm.line_mesh(1.0, n_el, boundaries={"clamp": 0.0, "tip": 1.0})
    if kind == "beam":
        m = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    else:
        m = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    return damped(m.with_contact(fm.UnilateralContact(at="tip", gap=0.01)), damping).with_forcing(
        fm.HarmonicForce(at="tip", amplitude=0.01))


def strip(nx, damping):
    m = fm.solid(fm.rectangle_mesh(1.0, 0.1, nx, 2, quadrilaterals=True), fm.Material(E=1.0, rho=1.0, nu=0.3),
                 clamped="left").with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0)))
    return damped(m, damping).with_forcing(fm.HarmonicForce(at=("right", "u_y"), amplitude=0.01))


def box(nx, damping):
    m = fm.solid(fm.box_mesh(1.0, 0.1, 0.1, nx, 1, 1, hexahedra=True), fm.Material(E=1.0, rho=1.0, nu=0.3),
                 clamped="left").with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0, 0.0)))
    return damped(m, damping).with_forcing(fm.HarmonicForce(at=("right", "u_y"), amplitude=0.01))


def one_dof():
    return (fm.StructuralModel(M=[[1.0]], K=[[1.0]], C=[[0.1]]).with_contact(fm.UnilateralContact(at=0, gap=1.0))
            .with_forcing(fm.HarmonicForce(at=0, amplitude=0.2)))


def blade_rom():
    import user_blade_3d as ub
    solid = fm.solid(fm.load_mesh(ub.MESHES[False]), ub.STEEL, clamped="root", order=2)
    return fm.craig_bampton(ub.with_stop(solid), 10)


def cases():
    for H in (60, 80, 120):
        yield f"1 DOF, H = {H}", one_dof(), H
    for damping in ("rayleigh", "modal"):
        for n_el, H in ((10, 10), (20, 10), (40, 10)):
            yield f"beam {n_el} el., {damping}, H = {H}", line("beam", n_el, damping), H
        for n_el, H in ((20, 10), (40, 10), (100, 10)):
            yield f"bar {n_el} el., {damping}, H = {H}", line("bar", n_el, damping), H
        for nx, H in ((4, 5), (8, 5), (8, 10), (16, 10)):
            yield f"2-D Q1 strip {nx} x 2, {damping}, H = {H}", strip(nx, damping), H
        for nx, H in ((2, 5), (4, 5), (4, 10), (8, 10)):
            yield f"3-D hex box {nx} x 1 x 1, {damping}, H = {H}", box(nx, damping), H
    rom = blade_rom()
    for H in (3, 5):
        yield f"user blade CB10 (37 DOFs, 27 contacts), H = {H}", rom, H


def measure(model, H, reps=7):
    p = fm.ForcedResponseProblem(model, fm.Harmonics(H))
    rng = np.random.default_rng(0)
    x = 0.01 * rng.standard_normal(p.size)
    w = 1.1 * float(fm.linear_modes(model, 1).omega[0])
    c = rng.standard_normal((1, p.size))
    b = rng.standard_normal(p.size + 1)
    paths = {"dense": lambda J: DenseFactorization(J, BlockSolverOptions()),
             "assembled": AssembledFactorization,
             "structured": lambda J: BlockSolver(options=STRUCTURED).factorize(J),
             "default": lambda J: BlockSolver().factorize(J)}
    if p.size > 3000:
        del paths["dense"]
    t = {k: [] for k in paths}
    chosen = None
    for rep in range(reps):
        for j, (k, make) in enumerate(paths.items()):
            # a frequency of its own for every factorisation, as in a corrector (omega is an
            # unknown there): the system's per-frequency factors are never reused
            _, J, drdp = p.residual(x, w * (1.0 + 1e-9 * (rep * len(paths) + j + 1)))
            Jb = J.bordered(drdp[:, None], c, np.array([[1.0]]))
            t0 = time.perf_counter()
            F = make(Jb)
            F.solve(b)
            t[k].append(time.perf_counter() - t0)
            if k == "default":
                chosen = type(F).__name__
    out = {k: 1e3 * statistics.median(v) for k, v in t.items()}
    out.update(n=int(p.size + 1), default_path=chosen, nonlinear_fill=float(J.N.nnz) / float(J.shape[0]) ** 2)
    return out


#: The rule before 2026-11-30: one threshold, 2000 unknowns, for every system.
PREVIOUS = dataclasses.replace(DEFAULT_OPTIONS, structured_min_size=2000)


def branch_times(model, H, points=40, reps=2):
    """CPU time of a frequency response over ``(0.8, 1.6) w1`` capped at ``points`` points, with the
    defaults before and after the change (the solver's options swapped in, alternating); the
    best of ``reps``. The measure that decides: a continuation's solves (corrector, tangent,
    refinement) and its states (contacts open and closed as the orbit has them), which the random
    state of :func:`measure` lacks."""
    w1 = float(fm.linear_modes(model, 1).omega[0])
    opts = fm.analyses.frequency_response_options(max_points=points)
    out = {"previous": [], "now": []}
    for _ in range(reps):
        for k, o in (("previous", PREVIOUS), ("now", DEFAULT_OPTIONS)):
            S.DEFAULT_OPTIONS = o
            try:
                c = time.process_time()
                b = fm.frequency_response(model, (0.8 * w1, 1.6 * w1), H, options=opts)
                out[k].append(time.process_time() - c)
            finally:
                S.DEFAULT_OPTIONS = DEFAULT_OPTIONS
    return {k: min(v) for k, v in out.items()} | {"points": len(b)}


def main():
    rows = {}
    with threadpool_limits(1):
        for name, model, H in cases():
            r = measure(model, H)
            r["branch"] = branch_times(model, H)
            rows[name] = r
            br = r["branch"]
            print(f"{name:48s} n = {r['n']:5d}  dense {r.get('dense', float('nan')):7.2f}  assembled "
                  f"{r['assembled']:7.2f}  structured {r['structured']:7.2f}  default {r['default']:7.2f} ms "
                  f"({r['default_path']});  branch {br['points']} pts: previous {br['previous']:6.3f} s, "
                  f"now {br['now']:6.3f} s", flush=True)
    meta = {"cpu": cpu_model(), "defaults": repr(BlockSolverOptions())}
    (HERE / "results_solver_paths.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
