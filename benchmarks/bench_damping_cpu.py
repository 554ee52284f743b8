#!/usr/bin/env python
"""Modal vs Rayleigh damping per continuation point in CPU time (issue 38, item 5).

The model and continuation of ``bench_damping.py`` (P1 bar with a stop, H = 5, 6 points from
w = 1.40); both dampings in one process, alternated over ``ROUNDS`` rounds (15 up to 1e4 DOFs, where a
continuation takes 0.1-0.7 s and single rounds scatter by 10 %; 5 above), ``time.process_time`` (the
machine is shared), BLAS on one thread; prints the medians and their ratio. Before/after: run it
with ``PYTHONPATH`` pointing at another tree (``git archive REV femodes | tar -x -C DIR``)::

    python3 benchmarks/bench_damping_cpu.py 1000 10000 100000
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_damping import W_END, W_START, build_model  # noqa: E402


def main(sizes):
    import femodes as fm

    h = fm.Harmonics(5)
    opts = fm.ContinuationOptions(step=0.02, max_step=0.05, max_points=6,
                                  newton=fm.NewtonOptions(atol=1e-7, max_iter=20))
    print(f"femodes from {fm.__file__}")
    with threadpool_limits(1):
        for N in sizes:
            models = {d: build_model(N, d) for d in ("rayleigh", "modal")}
            per = {d: [] for d in models}
            its = {}
            for _ in range(15 if N <= 10000 else 5):
                for d, m in models.items():
                    t = time.process_time()
                    br = fm.frequency_response(m, (W_START, W_END), h, options=opts)
                    per[d].append((time.process_time() - t) / (len(br) - 1))
                    its[d] = float(np.sum(br.nit[1:])) / (len(br) - 1)
            r, mo = statistics.median(per["rayleigh"]), statistics.median(per["modal"])
            print(f"N={N}: Rayleigh {1e3 * r:.1f} ms, modal {1e3 * mo:.1f} ms per point "
                  f"(Newton it/point {its['rayleigh']:.1f}, {its['modal']:.1f}); modal/Rayleigh {mo / r:.2f}", flush=True)


if __name__ == "__main__":
    main([int(float(a)) for a in sys.argv[1:]] or [1000, 10000, 100000])
