"""femodes.app.distributed on this machine: one harmonic balance Newton step of a 3-D solid
(P2 tetrahedra, fm.box_mesh), its H + 1 harmonic blocks factorised serially in one process and on
2 Dask worker processes (actors), side by side; wall time (the point of workers) and the client's
gathered data. Writes benchmarks/results_distributed.json.

    python benchmarks/bench_distributed.py [--n 8] [--H 4] [--contacts 20]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import femodes as fm
from femodes.app.distributed import HarmonicBlock, distributed_newton_step

HERE = Path(__file__).resolve().parent


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--H", type=int, default=4)
    ap.add_argument("--contacts", type=int, default=20)
    a = ap.parse_args()
    mesh = fm.box_mesh(1.0, 0.2, 0.2, a.n * 5, a.n, a.n)
    model = fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left", order=2)
    K, M = model.K, model.M
    C = 1e-3 * K
    n, H = model.n_dofs, a.H
    contact = np.linspace(0, n - 1, a.contacts).astype(int)
    w1 = float(fm.linear_modes(model, 1).omega[0])
    omega = 1.1 * w1
    rng = np.random.default_rng(0)
    m = contact.size * (2 * H + 1)
    A = 1e-2 * rng.standard_normal((m, m))
    r = rng.standard_normal(n * (2 * H + 1))
    # serial: the same blocks in one process
    t = time.perf_counter()
    blocks = [HarmonicBlock(K, M, C, omega, k, contact) for k in range(H + 1)]
    for k, b in enumerate(blocks):
        b.reduce(r[:n] if k == 0 else r[n + 2 * n * (k - 1): n + 2 * n * k])
    serial = time.perf_counter() - t
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c, Client(c) as cl:
        distributed_newton_step(cl, K, M, C, omega, 1, contact, A[: contact.size * 3, : contact.size * 3],
                                r[: 3 * n])  # warm-up (imports on the workers)
        t = time.perf_counter()
        distributed_newton_step(cl, K, M, C, omega, H, contact, A, r)
        dist = time.perf_counter() - t
    row = {"dofs": n, "H": H, "contacts": int(contact.size), "serial_factor_and_reduce_s": serial,
           "two_workers_whole_step_s": dist, "gathered_numbers": int(m * m + m + n * (2 * H + 1))}
    print(json.dumps(row, indent=1))
    out = HERE / "results_distributed.json"
    rows = json.loads(out.read_text()) if out.exists() else []
    out.write_text(json.dumps(rows + [row], indent=1))


if __name__ == "__main__":
    main()
