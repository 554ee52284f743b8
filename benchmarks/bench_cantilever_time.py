"""The FE cantilever's steady state in the time domain (issue 14 item 5; ``README_accuracy.md`` section 5).

A plain script, not a pytest test. The cantilever of ``bench_peers.py`` / ``bench_accuracy.py``
(``cant20``: 10 Hermite elements, E = rho = A = I = L = 1, tip stop at gap 0.01 on the tip's
massless DOF, tip force 0.004 cos(w t)) with its damping:

* ``alpha`` -- ``C = 0.02 M`` (the benchmark's case: every mode decays at the same rate 0.01/s,
  so the bending modes up to 5006 rad/s are hardly damped);
* ``modal`` -- 3 % modal damping on all 19 modes (``with_damping(modal=0.03)``).

Commands:

* ``settle`` -- from rest, ``--periods`` forcing periods at each ``--omega`` with the exact flow
  (``femodes.time.exact.LinearImpactFlow``: closed form between the contact's switches); prints
  every ``--every`` periods the largest tip displacement over the period, the switches and the
  relative change of the state over the period (round-off, ~1e-14, on a periodic orbit).
* ``sweep`` -- a quasi-static upward sweep with the exact flow: the state carries from one
  frequency to the next; ``--grid w0 w1 dw periods`` (repeatable) in order; reports each frequency
  and the jump down (the last frequency before the largest tip displacement halves).
* ``moreau`` -- the same as ``settle`` with femodes' Moreau-Jean time stepping
  (``fm.simulate``, ``--steps`` per period, ``--theta``): an integration independent of the flow.

Usage::

    python benchmarks/bench_cantilever_time.py settle --damping alpha --omega 3.6 3.75 --periods 1000
    python benchmarks/bench_cantilever_time.py moreau --damping alpha --omega 3.75 --periods 300 --steps 6400
    python benchmarks/bench_cantilever_time.py sweep --damping modal --grid 3.5 3.9 0.01 100 --grid 3.9 3.92 0.001 300
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import femodes as fm
from femodes.time.exact import LinearImpactFlow


def cantilever(damping: str):
    mesh = fm.line_mesh(length=1.0, n_elements=10, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = beam.with_contact(fm.UnilateralContact(at="tip", gap=0.01))
    model = model.with_damping(alpha=0.02) if damping == "alpha" else model.with_damping(modal=0.03)
    model = model.with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004))
    return model, model.dof("tip")


def period(flow: LinearImpactFlow, x: np.ndarray, dof: int):
    """One forcing period from ``x`` at ``t = 0``: end state, largest tip displacement, switches."""
    r = flow.run(x, 0.0)
    t = np.linspace(0.0, 2.0 * math.pi / flow.omega, 400)
    return r.x_end, float(np.max(np.abs(r.displacement(t)[:, dof]))), len(r.switches)


def change(x_new: np.ndarray, x_old: np.ndarray) -> float:
    return float(np.linalg.norm(x_new - x_old) / max(np.linalg.norm(x_new), 1e-300))


def settle(model, dof, omegas, periods: int, every: int) -> None:
    for w in omegas:
        flow = LinearImpactFlow(model, w)
        x = np.zeros(2 * model.n_dofs)
        start = time.process_time()
        amps = []
        for p in range(1, periods + 1):
            x_new, amp, sw = period(flow, x, dof)
            amps.append(amp)
            if p % every == 0:
                print(f"w = {w:g}  period {p:5d}: max |u_tip| {amp:.6f}, {sw:3d} switches, state change "
                      f"{change(x_new, x):.1e}  ({time.process_time() - start:.0f} s CPU)", flush=True)
            x = x_new
        last = amps[-periods // 2:]
        print(f"w = {w:g}: max |u_tip| per period over the last {len(last)} periods: {min(last):.6f} .. {max(last):.6f}")


def sweep(model, dof, grids) -> None:
    flow = LinearImpactFlow(model, grids[0][0])
    x = np.zeros(2 * model.n_dofs)
    rows = []
    first = True
    for w0, w1, dw, periods in grids:
        for w in np.arange(w0, w1 + 0.5 * dw, dw):
            f = flow.at(float(w))
            for _ in range(int(periods) * (3 if first else 1)):
                x_new, amp, sw = period(f, x, dof)
                x_old, x = x, x_new
            first = False
            rows.append((float(w), amp, sw, change(x, x_old)))
            print(f"w = {w:.4f}: max |u_tip| {amp:.6f}, {sw:2d} switches, state change over the last period "
                  f"{rows[-1][3]:.1e}", flush=True)
    for a, b in zip(rows, rows[1:]):
        if b[1] < 0.5 * a[1]:
            print(f"jump down between w = {a[0]:.4f} (max |u_tip| {a[1]:.6f}) and {b[0]:.4f} ({b[1]:.6f})")


def moreau(model, dof, omegas, periods: int, steps: int, theta: float) -> None:
    for w in omegas:
        T = 2.0 * math.pi / w
        start = time.process_time()
        h = fm.simulate(model, periods * T, T / steps, omega=w, options=fm.TimeSteppingOptions(theta=theta))
        u = np.abs(h.u[:, dof])
        k = np.minimum((h.t / T).astype(int), periods - 1)
        amps = np.zeros(periods)
        np.maximum.at(amps, k, u)
        print(f"w = {w:g}, theta {theta:g}, {steps} steps per period: {h.message} ({time.process_time() - start:.0f} s CPU)")
        for p in range(0, periods, max(1, periods // 20)):
            print(f"  period {p + 1:5d}: max |u_tip| {amps[p]:.6g}")
        last = amps[-periods // 2:]
        print(f"  last {len(last)} periods: {last.min():.6g} .. {last.max():.6g}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("command", choices=("settle", "sweep", "moreau"))
    ap.add_argument("--damping", choices=("alpha", "modal"), default="alpha")
    ap.add_argument("--omega", type=float, nargs="+", default=[3.75])
    ap.add_argument("--periods", type=int, default=300)
    ap.add_argument("--every", type=int, default=50)
    ap.add_argument("--grid", type=float, nargs=4, action="append", metavar=("W0", "W1", "DW", "PERIODS"))
    ap.add_argument("--steps", type=int, default=6400, help="Moreau-Jean steps per forcing period")
    ap.add_argument("--theta", type=float, default=0.5)
    args = ap.parse_args(argv)
    model, dof = cantilever(args.damping)
    print(f"cantilever, {model.damping_info}")
    if args.command == "settle":
        settle(model, dof, args.omega, args.periods, args.every)
    elif args.command == "sweep":
        if not args.grid:
            ap.error("sweep needs at least one --grid W0 W1 DW PERIODS")
        sweep(model, dof, args.grid)
    else:
        moreau(model, dof, args.omega, args.periods, args.steps, args.theta)


if __name__ == "__main__":
    main()
