#!/usr/bin/env python
"""HBM scaling (issue 6, part 2): time and memory per Newton iteration and per continuation point
against N and H, full and Craig-Bampton, against a raw-LAPACK floor, a dense-Jacobian HBM and time
integration.

Run from the repository root::

    python3 benchmarks/bench_scale.py               # everything (15 min at load 1-3 on 2 cores)
    python3 benchmarks/bench_scale.py --quick       # N <= 1e4, H in {5, 10}, fewer repeats (~1.5 min)
    python3 benchmarks/bench_scale.py --only floor  # one part: floor|newton|points|cb|dense|time
    python3 benchmarks/bench_scale.py --json out.json   # default: benchmarks/results_scale.json
    python3 benchmarks/bench_scale.py --report benchmarks/results_scale.json   # tables of a saved run
    python3 benchmarks/bench_scale.py --only newton --N 100000 --H 40 \
        --env MALLOC_MMAP_THRESHOLD_=1073741824 --env MALLOC_TRIM_THRESHOLD_=4294967296

This is a script, not a pytest test. Results and their discussion: ``benchmarks/README.md``,
section "HBM scaling (issue 6)".

Model. Clamped axial P1 bar ``fm.bar(fm.line_mesh(1, N), E = rho = A = 1, clamped="clamp")``
(N DOFs, w1 = pi/2), Rayleigh damping ``alpha = 0.2, beta = 1e-4`` (6.4 % on mode 1), tip force
``0.01 cos(w t)`` and ``n_c = 10`` unilateral contacts ``fm.UnilateralContact(at=dof, gap=0.02)``
at x = 0.05, 0.15, ..., 0.95 (femodes' defaults: complementarity constant from the local
flexibility, mass of the contact DOFs redistributed). A bar, not a beam: a 1e5-DOF Hermite beam is
too ill-conditioned to mean anything (``README.md``, first section).

State. One child ("ref") traces ``fm.frequency_response`` at N = 1000, H = 10 from w = 1.0
(no contact) until w >= 1.55 (near the first resonance; 6 contacts are active there) and takes
its last point w_s; the other H are reached at N = 1000 and that fixed w_s by Newton from the
neighbouring H (harmonics padded with zeros or truncated: 10 -> 20 -> 40, 10 -> 5; a direct
10 -> 40 Newton fails). Each (N, H) interpolates that reference (piecewise linear in x) and
corrects it by ``fm.semismooth_newton`` at w_s (structured solver); the converged state
``(x_s, w_s)`` is cached in a temporary directory and reused by the other parts. The number of active contacts (contact force > 1e-6 x its largest value somewhere in
the period, sampled on the Harmonics time grid) is reported per case.

Every case runs in a fresh child process (this file re-invoked with ``--case ...``) with
``OPENBLAS_NUM_THREADS = OMP_NUM_THREADS = MKL_NUM_THREADS = 1`` (femodes' own per-harmonic
thread pool is left at its default unless said otherwise) and an address-space limit of
16 GiB (``RLIMIT_AS``) so that a case that does not fit fails instead of swapping the machine.
Memory: ``rss_model`` = resident set (VmRSS) after building the model, ``peak`` =
``ru_maxrss`` at the end of the case; ``peak - rss_model`` is the HBM's share.

Parts (see ``README.md`` for the full protocol):

newton  per Newton iteration at the state, R repeats at R different w (w_s (1 + 1e-4 i), so the
        factor cache misses): ``ForcedResponseProblem.residual`` (residual + Jacobian) and
        ``J.factorize()`` + ``.solve(r)`` (what ``default_linear_solver`` does); then R repeats at
        one w (cache hit); structured (default) and assembled (``J.tocsr()`` in the residual time, then
        ``splu(J.tocsc()).solve(r)``) in separate children.
floor   N = 1e5, H = 20: femodes' iteration against a minimal raw scipy/LAPACK implementation of the
        same algorithm (``floor_solve`` below), same right-hand side, solutions compared.
points  ``fm.frequency_response(model, (w_s, 1.8), H, x0=x_s, options=...max_points=K)``: wall
        time / point, Newton iterations / point.
cb      ``fm.craig_bampton(model, n_modes=20)`` (time, memory), then the same on the reduced model.
dense   N = 100, 200, 500 at H = 10: ``numpy.linalg.solve(J.toarray(), r)`` against the
        structured solve (and SuperLU) of the same system.
time    N = 1000 and 1e4: ``fm.steady_state`` (theta = 1, 400 steps per period, tol 1e-5, from rest at
        the first frequency, then warm-started from the previous one) at the frequencies of a
        5-point HBM continuation (H = 20): time per frequency point and the relative difference
        of the amplitudes; at N = 1000 also theta = 0.5 (femodes' default) at the first frequency.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from _machine import cpu_model  # noqa: E402 - benchmarks/ is on sys.path when run as a script

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

ALPHA, BETA = 0.2, 1e-4
FORCE = 0.01
GAP = 0.02
N_CONTACTS = 10
X_CONTACTS = [(j + 0.5) / N_CONTACTS for j in range(N_CONTACTS)]
N_REF, H_REF = 1000, 10
W_START, W_STATE, W_END = 1.0, 1.55, 1.8
NEWTON_ATOL = 1e-9          # frequency_response's default (on the residual / force amplitude)
REL_DW = 1e-4               # relative frequency shift between timed repeats (cache misses)
CB_MODES = 20
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
MEM_LIMIT = 16 * 2 ** 30    # RLIMIT_AS of a child
GIB = 2 ** 30


# ================================================================================================
# child helpers
# ================================================================================================
def _rss_mib() -> float:
    """Current resident set size (VmRSS) in MiB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _contact_dofs(N: int) -> list[int]:
    # DOF i of the clamped P1 bar sits at x = (i + 1) / N
    return [int(round(x * N)) - 1 for x in X_CONTACTS]


def build_model(N: int):
    import femodes as fm

    mesh = fm.line_mesh(length=1.0, n_elements=N, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_damping(alpha=ALPHA, beta=BETA)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=FORCE)))
    return model.with_contact(*[fm.UnilateralContact(at=d, gap=GAP) for d in _contact_dofs(N)])


def _cont_options(max_points: int, callback=None):
    import femodes as fm

    # frequency_response's defaults, with a cap on the points
    return fm.ContinuationOptions(step=0.05, max_step=0.5, max_points=max_points, callback=callback,
                                  newton=fm.NewtonOptions(atol=NEWTON_ATOL, max_iter=20))


def _active(system, x) -> dict:
    """Active contacts of a state: contact force > 1e-6 max somewhere on the time grid."""
    import numpy as np

    _, P = system.split(x)
    E = np.asarray(system.h.grid.synthesis())
    f = E @ P  # (n_time, n_contacts)
    fmax = float(np.max(f)) if f.size else 0.0
    act = int(np.sum(np.max(f, axis=0) > 1e-6 * max(fmax, 1e-300))) if fmax > 0 else 0
    return {"active_contacts": act, "max_contact_force": fmax, "mean_force_positive": int(np.sum(P[0] > 0))}


def _med(v):
    return statistics.median(v) if v else float("nan")


def _guess_from_ref(system, ref) -> np.ndarray:  # noqa: F821 (numpy is imported inside)
    """Interpolate the reference state (N_REF, H_REF) to this system's N and H."""
    import numpy as np

    h, n = system.h, system.n
    Qr, Pr = ref["Q"], ref["P"]
    Hr = (Qr.shape[0] - 1) // 2
    nr = Qr.shape[1]
    xr = np.concatenate([[0.0], (np.arange(nr) + 1) / nr])
    xn = (np.arange(n) + 1) / n
    Q = np.zeros((h.n_coef, n))
    P = np.zeros((h.n_coef, system.n_uc))
    Q[0] = np.interp(xn, xr, np.concatenate([[0.0], Qr[0]]))
    P[0] = Pr[0]
    for k in range(1, min(Hr, h.n_harmonics) + 1):
        for dst, src in ((h.layout.cos_index(k), 2 * k - 1), (h.layout.sin_index(k), 2 * k)):
            Q[dst] = np.interp(xn, xr, np.concatenate([[0.0], Qr[src]]))
            P[dst] = Pr[src]
    return system.join(Q, P)


def _ref_layout_check():
    """The reference file stores rows in the order [c0, c1, s1, c2, s2, ...] (checked here)."""
    import femodes as fm

    h = fm.Harmonics(3)
    assert [h.layout.cos_index(k) for k in (1, 2, 3)] == [1, 3, 5] and [h.layout.sin_index(k) for k in (1, 2, 3)] == [2, 4, 6]


def get_state(pr, N: int, H: int, workdir: str) -> tuple:
    """Converged state (x, w, info) of this (N, H), cached in workdir."""
    import numpy as np

    import femodes as fm

    path = os.path.join(workdir, f"state_{N}_{H}.npz")
    info = {}
    if os.path.exists(path):
        d = np.load(path)
        x, w = d["x"], float(d["w"])
        info["state_from"] = "cache"
    else:
        ref = np.load(os.path.join(workdir, f"ref_{H}.npz"))
        w = float(ref["w"])
        s = pr.system
        x0 = _guess_from_ref(s, ref)
        t = time.perf_counter()  # the state is always found with the structured (default) solver
        res = fm.semismooth_newton(lambda x: pr.residual(x, w)[:2], x0,
                                   options=fm.NewtonOptions(atol=NEWTON_ATOL, max_iter=40))
        info["t_state_newton"] = time.perf_counter() - t
        s.linear._cache.pop("factors", None)
        info.update(state_nit=int(res.nit), state_success=bool(res.success), state_message=str(res.message)[:200])
        x = res.x
        if not res.success:
            raise RuntimeError(f"Newton at the state failed for N={N} H={H}: {res.message}")
        np.savez(path, x=x, w=w)
        info["state_from"] = "newton"
    info.update(_active(pr.system, x))
    info["w_state"] = w
    return x, w, info


# ================================================================================================
# the floor: a minimal raw scipy/LAPACK implementation of the same algorithm
# ================================================================================================
class FloorData:
    """Setup of the floor (outside its timer, like femodes' cached pattern): the interior
    tridiagonals of K, M, C, the interior-boundary couplings, the harmonic layout.

    Bar P1 matrices are tridiagonal in the natural order; removing the contact DOFs keeps the
    interior tridiagonal (couplings across a removed DOF are zero), so kl = ku = 1.
    """

    def __init__(self, K, M, C, bdofs, h_rows_c, h_rows_s, n_p: int):
        import numpy as np

        n = K.shape[0]
        self.n = n
        self.bdofs = np.asarray(bdofs)
        mask = np.ones(n, bool)
        mask[self.bdofs] = False
        I = np.flatnonzero(mask)
        self.I = I
        nI = I.size

        def tri(A):
            A = A.tocsr()
            d0 = A.diagonal()[I]
            up = np.zeros(nI)
            lo = np.zeros(nI)
            nxt = I[1:] == I[:-1] + 1  # consecutive interior DOFs: coupled
            up[1:][nxt] = A.diagonal(1)[I[:-1][nxt]]   # A[i, i+1] stored at column i+1
            lo[:-1][nxt] = A.diagonal(-1)[I[:-1][nxt]]  # A[i+1, i] stored at column i
            return d0, up, lo

        self.Kt, self.Mt, self.Ct = tri(K), tri(M), tri(C)
        # interior-boundary couplings Z_Ib: union COO pattern with aligned K, M, C values
        # (2 nonzeros per column for a bar), scattered into the dense right-hand side block
        KIb, MIb, CIb = (A.tocsc()[I][:, self.bdofs] for A in (K, M, C))
        U = (abs(KIb) + abs(MIb) + abs(CIb)).tocoo()
        self.ib_rows, self.ib_cols = U.row, U.col
        self.ib_k, self.ib_m, self.ib_c = (np.asarray(A.tocsr()[U.row, U.col]).ravel() for A in (KIb, MIb, CIb))
        self.KbI, self.MbI, self.CbI = (A[self.bdofs][:, I].tocsr() for A in (K, M, C))
        self.Kbb, self.Mbb, self.Cbb = (A[self.bdofs][:, self.bdofs].toarray() for A in (K, M, C))
        self.rc, self.rs = list(h_rows_c), list(h_rows_s)  # rows of cos / sin coefficients, k = 0..H
        self.n_coef = 2 * (len(self.rc) - 1) + 1
        self.n_p = n_p


def floor_solve(fd: FloorData, omega: float, scale: float, NBB, r):
    """Solve ``J dx = r`` for ``J = scale (S(w) + N)`` (N on the boundary unknowns only).

    Per harmonic k: band LU of ``Z_k[I, I] = K - (kw)^2 M + i kw C`` (``dgbtrf`` at k = 0,
    ``zgbtrf`` otherwise), one ``?gbtrs`` with ``n_b + 1`` right-hand sides (the coupling columns
    and the interior right-hand side), the condensed ``Z_k[b,b] - Z_k[b,I] Z_k[I,I]^-1 Z_k[I,b]``;
    then the dense real Schur system on the ``n_b (2H+1)`` boundary displacement coefficients and
    the ``n_p`` contact-force coefficients, LU with partial pivoting (``getrf``/``getrs``), one
    right-hand side; back substitution ``x_I = y - W x_b`` with the stored ``W = Z_II^-1 Z_Ib``.
    """
    import numpy as np
    from scipy.linalg import lapack

    n, I, nb = fd.n, fd.I, fd.bdofs.size
    nI = I.size
    nc = fd.n_coef
    nq = nc * n
    R = r[:nq].reshape(nc, n)
    nB = nb * nc + fd.n_p
    T = np.zeros((nB, nB))
    rhsB = np.empty(nB)
    rhsB[: nb * nc] = R[:, fd.bdofs].ravel() / scale
    rhsB[nb * nc:] = r[nq:] / scale
    T[:, :] = NBB  # nonlinear part on (q_b, p), unscaled
    Ws, Ys = [], []
    H = len(fd.rc) - 1
    for k in range(H + 1):
        f = k * omega
        a = f * f
        ic = fd.rc[k] * nb + np.arange(nb)
        # band storage of Z_II (LAPACK gbtrf layout: kl extra rows on top for the fill)
        if k == 0:
            ab = np.empty((4, nI))
            ab[0] = 0.0
            ab[1] = fd.Kt[1]
            ab[2] = fd.Kt[0]
            ab[3] = fd.Kt[2]
            lu, piv, info = lapack.dgbtrf(ab, 1, 1, overwrite_ab=True)
            rhs = np.zeros((nI, nb + 1), order="F")
            rhs[fd.ib_rows, fd.ib_cols] = fd.ib_k
            rhs[:, nb] = R[fd.rc[0], I] / scale
            X, info2 = lapack.dgbtrs(lu, 1, 1, rhs, piv, overwrite_b=True)
            Zbb = fd.Kbb
            ZbI = fd.KbI
        else:
            ab = np.empty((4, nI), dtype=complex)
            ab[0] = 0.0
            for row, j in ((1, 1), (2, 0), (3, 2)):
                ab[row] = (fd.Kt[j] - a * fd.Mt[j]) + 1j * f * fd.Ct[j]
            lu, piv, info = lapack.zgbtrf(ab, 1, 1, overwrite_ab=True)
            rhs = np.zeros((nI, nb + 1), dtype=complex, order="F")
            rhs[fd.ib_rows, fd.ib_cols] = (fd.ib_k - a * fd.ib_m) + 1j * f * fd.ib_c
            rhs[:, nb] = (R[fd.rc[k], I] - 1j * R[fd.rs[k], I]) / scale
            X, info2 = lapack.zgbtrs(lu, 1, 1, rhs, piv, overwrite_b=True)
            Zbb = (fd.Kbb - a * fd.Mbb) + 1j * f * fd.Cbb
            ZbI = (fd.KbI - a * fd.MbI) + 1j * f * fd.CbI
        if info or info2:
            raise RuntimeError(f"floor: gbtrf/gbtrs info {info}/{info2} at k={k}")
        W, y = X[:, :nb], X[:, nb]
        ZW = ZbI @ X  # (nb, nb + 1)
        Zc = Zbb - ZW[:, :nb]
        g = ZW[:, nb]  # Z_bI y
        Ws.append(W)
        Ys.append(y)
        if k == 0:
            T[np.ix_(ic, ic)] += Zc.real
            rhsB[ic] -= g.real
        else:
            is_ = fd.rs[k] * nb + np.arange(nb)
            T[np.ix_(ic, ic)] += Zc.real
            T[np.ix_(ic, is_)] += Zc.imag
            T[np.ix_(is_, ic)] -= Zc.imag
            T[np.ix_(is_, is_)] += Zc.real
            rhsB[ic] -= g.real
            rhsB[is_] += g.imag
    lu, piv, info = lapack.dgetrf(T, overwrite_a=True)
    if info:
        raise RuntimeError(f"floor: dgetrf info {info}")
    xB, info = lapack.dgetrs(lu, piv, rhsB)
    x = np.empty_like(r)
    X = x[:nq].reshape(nc, n)
    xb = xB[: nb * nc].reshape(nc, nb)
    X[:, fd.bdofs] = xb
    x[nq:] = xB[nb * nc:]
    for k in range(H + 1):
        if k == 0:
            X[fd.rc[0], I] = Ys[0] - Ws[0] @ xb[fd.rc[0]]
        else:
            z = Ys[k] - Ws[k] @ (xb[fd.rc[k]] - 1j * xb[fd.rs[k]])
            X[fd.rc[k], I] = z.real
            X[fd.rs[k], I] = -z.imag
    return x


def floor_linear_residual(K, M, C, D1, Q, omega: float):
    """The O(N H) part of a residual evaluation: ``S(w) Q`` by three sparse products."""
    import numpy as np

    Qt = np.ascontiguousarray(Q.T)
    KQ = (K @ Qt).T
    MQ = (M @ Qt).T
    CQ = (C @ Qt).T
    return KQ + (omega * omega) * (D1 @ (D1 @ MQ)) + omega * (D1 @ CQ)


# ================================================================================================
# child cases
# ================================================================================================
def chain_states(model, Q, P, w: float, Hs) -> tuple[dict, list]:
    """States of ``model`` at the fixed frequency ``w`` for every H in ``Hs``, from the state
    ``(Q, P)`` at ``H_REF``: Newton at ``w`` for each H from the previous one (harmonics padded
    or truncated), H_REF -> 20 -> 40 and H_REF -> 5. A Newton that fails falls back to this H's
    own continuation from ``W_START`` (then Newton at ``w`` from its last point)."""
    import numpy as np

    import femodes as fm

    states = {H_REF: {"Q": Q, "P": P, "w": w}}
    log = []
    up = sorted(H for H in Hs if H > H_REF)
    down = sorted((H for H in Hs if H < H_REF), reverse=True)
    stop = lambda pt: False if pt.p >= W_STATE else None  # noqa: E731
    for chain in (up, down):
        prev = H_REF
        for H in chain:
            pr = fm.ForcedResponseProblem(model, fm.Harmonics(H))
            x0 = _guess_from_ref(pr.system, states[prev])
            t = time.perf_counter()
            res = fm.semismooth_newton(lambda x: pr.residual(x, w)[:2], x0,
                                       options=fm.NewtonOptions(atol=NEWTON_ATOL, max_iter=40))
            how = "newton"
            if not res.success:
                br = fm.frequency_response(model, (W_START, W_END), H, options=_cont_options(400, stop))
                j = len(br) - 1
                xj = np.concatenate([br.Q[j].ravel(), br.P[j].ravel()])
                res = fm.semismooth_newton(lambda x: pr.residual(x, w)[:2], xj,
                                           options=fm.NewtonOptions(atol=NEWTON_ATOL, max_iter=40))
                how = "continuation+newton"
                if not res.success:
                    raise RuntimeError(f"state at H={H} failed: {res.message}")
            Qh, Ph = pr.system.split(res.x)
            states[H] = {"Q": Qh, "P": Ph, "w": w}
            log.append({"H": H, "from": prev, "how": how, "nit": int(res.nit), "t": time.perf_counter() - t,
                        **_active(pr.system, res.x)})
            prev = H
    return states, log


def case_ref(args) -> dict:
    """Reference states at N_REF: continuation at H_REF from W_START until w >= W_STATE, then
    :func:`chain_states` for the other H. Saved as ref_<H>.npz."""
    import numpy as np

    import femodes as fm

    _ref_layout_check()
    model = build_model(N_REF)
    stop = lambda pt: False if pt.p >= W_STATE else None  # noqa: E731
    t = time.perf_counter()
    br = fm.frequency_response(model, (W_START, W_END), H_REF, options=_cont_options(400, stop))
    dt = time.perf_counter() - t
    i = len(br) - 1
    w = float(br.omega[i])
    pr = fm.ForcedResponseProblem(model, fm.Harmonics(H_REF))
    x = np.concatenate([br.Q[i].ravel(), br.P[i].ravel()])
    rec = {"part": "ref", "N": N_REF, "H": H_REF, "points": len(br), "t": dt, "w": w,
           "success": bool(br.success), "message": str(br.message)[:200]}
    rec.update(_active(pr.system, x))
    states, rec["chain"] = chain_states(model, br.Q[i], br.P[i], w, args.Hs or [])
    for H, st in states.items():
        np.savez(os.path.join(args.workdir, f"ref_{H}.npz"), **st)
    return rec


def _full_state(rec: dict, N: int, H: int, workdir) -> tuple:
    """Full model, its forced-response problem and the benchmark state; RSS and state info into ``rec``."""
    import femodes as fm

    model = build_model(N)
    rec["rss_model"] = _rss_mib()
    pr = fm.ForcedResponseProblem(model, fm.Harmonics(H))
    x, w, info = get_state(pr, N, H, workdir)
    rec.update(info)
    return model, pr, x, w


def case_newton(args) -> dict:
    import numpy as np
    import scipy.sparse.linalg as spla

    import femodes as fm

    N, H, R = args.N, args.H, args.repeat
    structured = args.method == "structured"
    rec = {"part": "newton", "N": N, "H": H, "method": args.method, "repeat": R,
           "rss_start": _rss_mib()}
    t = time.perf_counter()
    model = build_model(N)
    rec["t_model"] = time.perf_counter() - t
    rec["rss_model"] = _rss_mib()
    pr = fm.ForcedResponseProblem(model, fm.Harmonics(H))
    if args.threads:
        pr.system.threads = args.threads
    rec["unknowns"] = int(pr.size)
    x, w, info = get_state(pr, N, H, args.workdir)
    rec.update(info)
    rec["rss_state"] = _rss_mib()
    rec["peak_state"] = _peak_mib()

    def ws(i):
        return w * (1.0 + REL_DW * (i + 1))

    if structured:
        def fact_solve(J, r):
            t0 = time.perf_counter()
            F = J.factorize()
            t1 = time.perf_counter()
            dx = F.solve(r)
            t2 = time.perf_counter()
            rec["factorization"] = type(F).__name__  # _Factorization (structured) or _Generic (SuperLU)
            return dx, t1 - t0, t2 - t1
    else:
        def fact_solve(J, r):
            t0 = time.perf_counter()
            lu = spla.splu(J.tocsc())
            t1 = time.perf_counter()
            dx = lu.solve(r)
            t2 = time.perf_counter()
            rec["nnz_LU"] = int(lu.L.nnz + lu.U.nnz)
            rec["nnz_J"] = int(J.nnz)
            return dx, t1 - t0, t2 - t1

    def run(wfun, R):
        t_res, t_fac, t_sol, t_tot, relres = [], [], [], [], []
        for i in range(R):
            t0 = time.perf_counter()
            r, J, _ = pr.residual(x, wfun(i))
            if not structured:  # the assembled method: assembling belongs to "res+J" as before
                J = J.tocsr()
            t1 = time.perf_counter()
            dx, tf, ts = fact_solve(J, r)
            t2 = time.perf_counter()
            t_res.append(t1 - t0)
            t_fac.append(tf)
            t_sol.append(ts)
            t_tot.append(t2 - t0)
            Jx = J @ dx
            relres.append(float(np.max(np.abs(Jx - r)) / max(np.max(np.abs(r)), 1e-300)))
            del J
        return t_res, t_fac, t_sol, t_tot, relres

    try:
        t_res, t_fac, t_sol, t_tot, relres = run(ws, R)
        rec.update(t_res=t_res, t_fac=t_fac, t_sol=t_sol, t_tot=t_tot, relres_max=max(relres))
        rec["peak_fresh"] = _peak_mib()
        if structured:
            # same w every time: the per-harmonic factors are cached on the system (the first of
            # the R + 1 calls fills the cache and is dropped)
            wc = ws(R)
            c_res, c_fac, c_sol, c_tot, _ = run(lambda i: wc, R + 1)
            rec.update(tc_res=c_res[1:], tc_fac=c_fac[1:], tc_sol=c_sol[1:], tc_tot=c_tot[1:])
            # check that default_linear_solver is what was timed
            from femodes.solvers.newton import default_linear_solver

            r, J, _ = pr.residual(x, ws(0))
            dx1 = default_linear_solver(J, r)
            dx2 = J.factorize().solve(r)
            rec["dls_same"] = bool(np.allclose(dx1, dx2, rtol=1e-10, atol=1e-14 * np.max(np.abs(dx2))))
            Jn = J.N
            rec["nnz_N"] = int(Jn.nnz)
    except MemoryError as exc:
        rec["error"] = f"MemoryError {exc}"
    rec["peak"] = _peak_mib()
    return rec


def case_floor(args) -> dict:
    import numpy as np
    import scipy.sparse as sp

    N, H, R = args.N, args.H, args.repeat
    rec = {"part": "floor", "N": N, "H": H, "repeat": R}
    model, pr, x, w = _full_state(rec, N, H, args.workdir)
    s = pr.system
    h = s.h
    rc = [0] + [int(h.layout.cos_index(k)) for k in range(1, H + 1)]
    rsn = [None] + [int(h.layout.sin_index(k)) for k in range(1, H + 1)]
    t = time.perf_counter()
    bd = s.nonlinear_dofs
    fd = FloorData(s.K, s.M, s.C, bd, rc, rsn, s.np)
    rec["t_floor_setup"] = time.perf_counter() - t
    # boundary unknowns in the floor's order: q of the boundary DOFs (coefficient-major), then p
    gB = np.concatenate([(np.arange(h.n_coef)[:, None] * s.n + bd[None, :]).ravel(), s.nq + np.arange(s.np)])
    D1 = sp.csr_matrix(np.asarray(h.operators.derivative_domega()))
    Qs = x[: s.nq].reshape(h.n_coef, s.n)

    def ws(i):
        return w * (1.0 + REL_DW * (i + 1))

    out = {k: [] for k in ("fm_res", "fm_fac", "fm_sol", "fm_res_1t", "fm_fac_1t", "fm_sol_1t", "fl_res", "fl_sol",
                           "diff", "relres_floor")}
    def femodes_it(wi, tag, threads):
        s.threads = threads
        s.linear._cache.pop("factors", None)
        t0 = time.perf_counter()
        r, J, _ = pr.residual(x, wi)
        t1 = time.perf_counter()
        F = J.factorize()
        t2 = time.perf_counter()
        dx = F.solve(r)
        t3 = time.perf_counter()
        out["fm_res" + tag].append(t1 - t0)
        out["fm_fac" + tag].append(t2 - t1)
        out["fm_sol" + tag].append(t3 - t2)
        return r, J, dx

    def floor_it(wi, r, J):
        NBB = J.N[gB][:, gB].toarray()  # the contact Jacobian is input data of the floor
        t0 = time.perf_counter()
        Sq = floor_linear_residual(s.K, s.M, s.C, D1, Qs, wi)
        t1 = time.perf_counter()
        dxf = floor_solve(fd, wi, J.scale, NBB, r)
        t2 = time.perf_counter()
        out["fl_res"].append(t1 - t0)
        out["fl_sol"].append(t2 - t1)
        return Sq, dxf

    # the three variants in rotating order, so that the load of the machine and cache effects
    # hit all three alike
    for i in range(R):
        wi = ws(i)
        r, J, _ = pr.residual(x, wi)  # the right-hand side and contact Jacobian of the floor
        order = [0, 1, 2][i % 3:] + [0, 1, 2][: i % 3]
        for v in order:
            if v == 0:
                _, _, dx = femodes_it(wi, "", None)
            elif v == 1:
                femodes_it(wi, "_1t", 1)
            else:
                Sq, dxf = floor_it(wi, r, J)
        out["diff"].append(float(np.max(np.abs(dxf - dx)) / np.max(np.abs(dx))))
        out["relres_floor"].append(float(np.max(np.abs(J @ dxf - r)) / np.max(np.abs(r))))
        # sanity: the floor's linear residual equals femodes' (without forcing and contact)
        if i == 0:
            lin = s.linear.apply(x[: s.nq], wi)
            rec["floor_residual_check"] = float(np.max(np.abs(Sq.ravel() - lin)) / np.max(np.abs(lin)))
        del J
    rec.update(out)
    rec["n_boundary"] = int(gB.size)
    rec["peak"] = _peak_mib()
    return rec


def _capture_continuation():
    """Wrap the continuation the analyses run (femodes.runs) to get the ContinuationResult (n_newton, n_rejected)."""
    import femodes.runs as fr

    orig = fr.continuation
    box = {}

    def wrap(*a, **k):
        res = orig(*a, **k)
        box["res"] = res
        return res

    fr.continuation = wrap
    return box, lambda: setattr(fr, "continuation", orig)


def _points(model, H, x0, w0, K) -> dict:
    import numpy as np

    import femodes as fm

    box, restore = _capture_continuation()
    t = time.perf_counter()
    br = fm.frequency_response(model, (w0, W_END), H, x0=x0, options=_cont_options(K))
    dt = time.perf_counter() - t
    restore()
    res = box.get("res")
    pts = len(br)
    nn = int(res.n_newton) if res is not None else int(np.sum(br.nit))
    out = {"t_cont": dt, "points": pts, "n_newton": nn, "n_rejected": int(res.n_rejected) if res is not None else -1,
           "success": bool(br.success), "message": str(br.message)[:160], "w_last": float(br.omega[-1]),
           "folds": len(br.folds), "t_per_point": dt / max(pts - 1, 1), "its_per_point": nn / max(pts - 1, 1)}
    return out, br


def case_points(args) -> dict:

    N, H = args.N, args.H
    rec = {"part": "points", "N": N, "H": H}
    model, pr, x, w = _full_state(rec, N, H, args.workdir)
    del pr
    out, br = _points(model, H, x, w, args.max_points)
    rec.update(out)
    rec["peak"] = _peak_mib()
    return rec


def case_cb(args) -> dict:
    import numpy as np

    import femodes as fm

    N, H, R = args.N, args.H, args.repeat
    rec = {"part": "cb", "N": N, "H": H, "repeat": R}
    model = build_model(N)
    rec["rss_model"] = _rss_mib()
    t = time.perf_counter()
    rom = fm.craig_bampton(model, n_modes=CB_MODES)
    rec["t_cb"] = time.perf_counter() - t
    rec["rss_cb"] = _rss_mib()
    rec["peak_cb"] = _peak_mib()
    rec["n_rom"] = int(rom.n_dofs)
    # the state on the ROM: its own continuation at H_REF from the contact-free start until
    # w >= W_STATE, then chain_states to this H (like the full model's reference)
    stop = lambda pt: False if pt.p >= W_STATE else None  # noqa: E731
    t = time.perf_counter()
    br = fm.frequency_response(rom, (W_START, W_END), H_REF, options=_cont_options(400, stop))
    i = len(br) - 1
    w = float(br.omega[i])
    path = sorted({h for h in (20, 40) if H_REF < h <= H} | {H})  # 10 -> 20 -> 40 as for the full model
    states, chain = chain_states(rom, br.Q[i], br.P[i], w, path)
    rec["t_rom_state"] = time.perf_counter() - t
    rec["rom_state_points"] = len(br)
    rec["rom_chain"] = chain
    x = np.concatenate([states[H]["Q"].ravel(), states[H]["P"].ravel()])
    pr = fm.ForcedResponseProblem(rom, fm.Harmonics(H))
    rec["unknowns"] = int(pr.size)
    rec.update(_active(pr.system, x))
    rec["w_state"] = w
    t_res, t_fs = [], []
    for i in range(R):
        wi = w * (1.0 + REL_DW * (i + 1))
        t0 = time.perf_counter()
        r, J, _ = pr.residual(x, wi)
        t1 = time.perf_counter()
        F = J.factorize()
        F.solve(r)
        t2 = time.perf_counter()
        t_res.append(t1 - t0)
        t_fs.append(t2 - t1)
        rec["factorization"] = type(F).__name__  # femodes uses SuperLU below 2000 unknowns
    rec.update(t_res=t_res, t_fs=t_fs, t_tot=[a + b for a, b in zip(t_res, t_fs)])
    out, _ = _points(rom, H, x, w, args.max_points)
    rec.update(out)
    rec["peak"] = _peak_mib()
    return rec


def case_dense(args) -> dict:
    import numpy as np
    import scipy.sparse.linalg as spla

    N, H, R, Rd = args.N, args.H, args.repeat, args.dense_repeat
    rec = {"part": "dense", "N": N, "H": H, "repeat": R, "dense_repeat": Rd}
    model, pr, x, w = _full_state(rec, N, H, args.workdir)
    rec["unknowns"] = int(pr.size)

    def ws(i):
        return w * (1.0 + REL_DW * (i + 1))

    t_res, t_st, t_lu = [], [], []
    for i in range(R):
        t0 = time.perf_counter()
        r, J, _ = pr.residual(x, ws(i))
        t1 = time.perf_counter()
        dx = J.factorize().solve(r)
        t2 = time.perf_counter()
        t_res.append(t1 - t0)
        t_st.append(t2 - t1)
        t2 = time.perf_counter()
        spla.splu(J.tocsc()).solve(r)
        t_lu.append(time.perf_counter() - t2)
    rec.update(t_res=t_res, t_struct=t_st, t_splu=t_lu)
    rec["peak_sparse"] = _peak_mib()
    t_arr, t_dense, diff = [], [], []
    for i in range(Rd):
        r, J, _ = pr.residual(x, ws(i))
        dx = J.factorize().solve(r)
        t0 = time.perf_counter()
        A = J.toarray()
        t1 = time.perf_counter()
        dxd = np.linalg.solve(A, r)
        t2 = time.perf_counter()
        t_arr.append(t1 - t0)
        t_dense.append(t2 - t1)
        diff.append(float(np.max(np.abs(dxd - dx)) / np.max(np.abs(dx))))
        del A
    rec.update(t_toarray=t_arr, t_dense=t_dense, dense_vs_struct=diff)
    rec["peak"] = _peak_mib()
    return rec


def case_time(args) -> dict:
    import numpy as np

    import femodes as fm

    N, H, K = args.N, args.H, args.max_points
    rec = {"part": "time", "N": N, "H": H}
    model, pr, x, w = _full_state(rec, N, H, args.workdir)
    out, br = _points(model, H, x, w, K)
    rec["hbm"] = out
    tip = model.dof("tip")
    cdofs = _contact_dofs(N)
    pts = []
    u0 = v0 = None
    for i in range(len(br)):
        sol = br[i]
        wi = float(br.omega[i])
        T = 2 * np.pi / wi
        tt = np.linspace(0.0, T, 2001)
        U = sol.displacement(tt)
        a_hbm = np.max(np.abs(U), axis=0)
        t0 = time.perf_counter()
        ss = fm.steady_state(model, wi, dt=T / args.steps, u0=u0, v0=v0,
                             options=fm.TimeSteppingOptions(tol=args.tol, n_periods_max=args.max_periods, theta=args.theta))
        dt = time.perf_counter() - t0
        # warm start from the previous frequency (a sweep), like the continuation does
        u0, v0 = ss.u[-1], ss.v[-1]
        a_ti = ss.amplitude
        pts.append({
            "omega": wi, "t_ti": dt, "periods": int(ss.n_periods), "converged": bool(ss.converged), "nu": int(ss.nu),
            "change": float(ss.change), "amp_tip_hbm": float(a_hbm[tip]), "amp_tip_ti": float(a_ti[tip]),
            "rel_tip": float(abs(a_ti[tip] - a_hbm[tip]) / a_hbm[tip]),
            "rel_max_contact_dofs": float(np.max(np.abs(a_ti[cdofs] - a_hbm[cdofs]) / a_hbm[cdofs])),
            "rel_all": float(np.max(np.abs(a_ti - a_hbm)) / np.max(a_hbm)),
            "hbm_penetration": float(sol.penetration),
        })
    rec["points"] = pts
    # the trapezoidal variant (theta = 0.5, femodes' default) at the first frequency, from rest:
    # without numerical dissipation the bar keeps rattling between its 10 stops
    if args.check_theta05:
        wi = float(br.omega[0])
        T = 2 * np.pi / wi
        t0 = time.perf_counter()
        ss = fm.steady_state(model, wi, dt=T / args.steps,
                             options=fm.TimeSteppingOptions(tol=args.tol, n_periods_max=args.check_theta05, theta=0.5))
        a_hbm = np.max(np.abs(br[0].displacement(np.linspace(0.0, T, 2001))), axis=0)
        rec["theta05"] = {"omega": wi, "t_ti": time.perf_counter() - t0, "periods": int(ss.n_periods),
                          "converged": bool(ss.converged), "nu": int(ss.nu), "change": float(ss.change),
                          "amp_tip_ti": float(ss.amplitude[tip]),
                          "rel_tip": float(abs(ss.amplitude[tip] - a_hbm[tip]) / a_hbm[tip])}
    rec["theta"] = args.theta
    rec["steps_per_period"] = args.steps
    rec["tol"] = args.tol
    rec["peak"] = _peak_mib()
    return rec


CASES = {"ref": case_ref, "newton": case_newton, "floor": case_floor, "points": case_points, "cb": case_cb,
         "dense": case_dense, "time": case_time}


def child_main(args) -> int:
    resource.setrlimit(resource.RLIMIT_AS, (MEM_LIMIT, MEM_LIMIT))
    rec = CASES[args.case](args)
    print("BENCH_SCALE_RESULT " + json.dumps(rec))
    return 0


# ================================================================================================
# parent side
# ================================================================================================
CHILD_ENV: dict = {}  # extra environment of the children (--env KEY=VALUE)


def run_child(case: str, workdir: str, timeout: float, **kw) -> dict:
    env = dict(os.environ)
    for v in THREAD_VARS:
        env[v] = "1"
    env.update(CHILD_ENV)
    cmd = [sys.executable, os.path.abspath(__file__), "--case", case, "--workdir", workdir]
    for k, v in kw.items():
        if v is None:
            continue
        cmd += [f"--{k.replace('_', '-')}"] + ([str(u) for u in v] if isinstance(v, (list, tuple)) else [str(v)])
    t = time.perf_counter()
    label = f"{case} " + " ".join(f"{k}={v}" for k, v in kw.items() if v is not None)
    print(f"  [{time.strftime('%H:%M:%S')}] {label} ...", end="", flush=True, file=sys.stderr)
    try:
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        print(f" timeout after {timeout:.0f} s", file=sys.stderr, flush=True)
        return {"part": case, **kw, "error": f"timeout after {timeout:.0f} s", "child_wall": time.perf_counter() - t}
    wall = time.perf_counter() - t
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("BENCH_SCALE_RESULT ")]
    if p.returncode != 0 or not lines:
        err = (p.stderr.strip().splitlines() or ["?"])[-1]
        if p.returncode < 0:
            err = f"killed by signal {-p.returncode}; " + err
        print(f" FAILED ({err[:120]}) {wall:.0f} s", file=sys.stderr, flush=True)
        return {"part": case, **kw, "error": err[-400:], "child_wall": wall}
    rec = json.loads(lines[-1][len("BENCH_SCALE_RESULT "):])
    rec["child_wall"] = wall
    print(f" {wall:.1f} s", file=sys.stderr, flush=True)
    return rec


def machine_info() -> dict:
    import numpy
    import scipy

    import femodes

    cpu = cpu_model("")
    try:
        git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "femodes"], cwd=ROOT, capture_output=True,
                               text=True).stdout.strip()
    except OSError:
        git, dirty = "?", ""
    mem = float("nan")
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    mem = int(line.split()[1]) / 2 ** 20
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "mem_gib": mem, "python": platform.python_version(),
            "numpy": numpy.__version__, "scipy": scipy.__version__,
            "femodes": getattr(femodes, "__version__", "?"), "git": git,
            "femodes_dirty": bool(dirty), "platform": platform.platform(),
            "threads": "children: OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1, RLIMIT_AS 16 GiB"}


def _fit(xs, ys) -> float:
    import numpy as np

    pts = [(a, b) for a, b in zip(xs, ys) if b is not None and b == b and b > 0]
    if len(pts) < 2:
        return float("nan")
    x, y = zip(*pts)
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def _ms(v) -> str:
    return "-" if v is None or v != v else (f"{v * 1e3:.1f}" if v < 10 else f"{v * 1e3:.0f}")


def _mib(v) -> str:
    return "-" if v is None or v != v else f"{v:.0f}"


def _load() -> tuple:
    return os.getloadavg()


# ------------------------------------------------------------------------------------------------
# splu memory/time guard: the assembled matrix is tried only where it fits (estimate from its nnz)
# ------------------------------------------------------------------------------------------------
def _splu_fits(N: int, H: int) -> tuple[bool, str]:
    """SuperLU on the assembled HBM Jacobian: measured ~1 kB of peak memory per unknown for this bar
    (Jacobian assembly + CSC copy + COLAMD factors with nnz(L+U) ~ 12 per unknown); skipped when
    that estimate exceeds 14 GiB (the children's address-space limit is 16 GiB)."""
    n = (2 * H + 1) * N + (2 * H + 1) * N_CONTACTS
    est = 1100.0 * n
    if est > 14 * GIB:
        return False, f"{n:.2e} unknowns: ~{est / GIB:.0f} GiB estimated"
    return True, ""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="N <= 1e4, H in {5, 10}, fewer repeats")
    ap.add_argument("--only", action="append", choices=["floor", "newton", "points", "cb", "dense", "time"],
                    help="run only these parts (repeatable)")
    ap.add_argument("--N", type=int, nargs="+", help="sizes (default 1000 10000 100000)")
    ap.add_argument("--H", type=int, nargs="+", help="harmonics (default 5 10 20 40)")
    ap.add_argument("--json", default=os.path.join(HERE, "results_scale.json"))
    ap.add_argument("--keep-workdir", action="store_true")
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE",
                    help="extra environment variable of the child processes (repeatable), e.g. "
                         "MALLOC_MMAP_THRESHOLD_=1073741824 (see README)")
    ap.add_argument("--report", metavar="JSON", help="only print the report of a saved results file")
    # child arguments
    ap.add_argument("--case", choices=sorted(CASES), help=argparse.SUPPRESS)
    ap.add_argument("--workdir", help=argparse.SUPPRESS)
    ap.add_argument("--method", default="structured", help=argparse.SUPPRESS)
    ap.add_argument("--repeat", type=int, default=5, help=argparse.SUPPRESS)
    ap.add_argument("--dense-repeat", type=int, default=3, help=argparse.SUPPRESS)
    ap.add_argument("--max-points", type=int, default=8, help=argparse.SUPPRESS)
    ap.add_argument("--threads", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--Hs", type=int, nargs="+", help=argparse.SUPPRESS)
    ap.add_argument("--steps", type=int, default=400, help=argparse.SUPPRESS)
    ap.add_argument("--tol", type=float, default=1e-5, help=argparse.SUPPRESS)
    ap.add_argument("--max-periods", type=int, default=400, help=argparse.SUPPRESS)
    ap.add_argument("--theta", type=float, default=1.0, help=argparse.SUPPRESS)
    ap.add_argument("--check-theta05", type=int, default=0, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.case:
        a.N = a.N[0] if isinstance(a.N, list) else a.N
        a.H = a.H[0] if isinstance(a.H, list) else a.H
        return child_main(a)

    if a.report:
        with open(a.report) as f:
            report(json.load(f))
        return 0
    for kv in a.env:
        k, _, v = kv.partition("=")
        CHILD_ENV[k] = v
    parts = a.only or ["floor", "newton", "points", "cb", "dense", "time"]
    Ns = a.N or ([1000, 10000] if a.quick else [1000, 10000, 100000])
    Hs = a.H or ([5, 10] if a.quick else [5, 10, 20, 40])
    R = 3 if a.quick else 5
    K = 4 if a.quick else 6
    info = machine_info()
    load0 = _load()
    print("machine:", json.dumps(info), flush=True)
    print(f"load average at start: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}", flush=True)
    workdir = tempfile.mkdtemp(prefix="bench_scale_")
    t_all = time.perf_counter()
    loads = [load0]
    out = {"machine": info, "settings": {"N": Ns, "H": Hs, "repeat": R, "max_points": K, "quick": a.quick,
                                         "parts": parts, "alpha": ALPHA, "beta": BETA, "force": FORCE, "gap": GAP,
                                         "x_contacts": X_CONTACTS, "rel_dw": REL_DW, "child_env": CHILD_ENV}}
    try:
        ref = run_child("ref", workdir, 900, Hs=sorted(set(Hs) | {10, 20}))
        out["ref"] = ref
        if "error" in ref:
            raise SystemExit(f"reference state failed: {ref['error']}")
        print(f"reference state: N={N_REF} H={H_REF} w={ref['w']:.4f} after {ref['points']} points "
              f"({ref['t']:.1f} s), active contacts {ref['active_contacts']}/{N_CONTACTS}; other H: "
              + ", ".join(f"H={c['H']} from H={c['from']} by {c['how']} ({c['nit']} its, {c['active_contacts']} active)"
                          for c in ref["chain"]), flush=True)
        recs = []

        def save():
            out["records"] = recs
            out["loads"] = loads
            out["wall"] = time.perf_counter() - t_all
            with open(a.json, "w") as f:
                json.dump(out, f, indent=1)

        floor_N = max(Ns)
        # --- 1. per Newton iteration (structured first: it caches the states) ---
        if {"newton", "floor", "points", "time", "dense"} & set(parts):
            for N in Ns:
                for H in Hs:
                    if "newton" not in parts and not ("floor" in parts and N == floor_N and H == 20):
                        continue
                    recs.append(run_child("newton", workdir, 1200, N=N, H=H, method="structured", repeat=R))
                    loads.append(_load())
                    save()
        if "newton" in parts:
            for N in Ns:
                for H in Hs:
                    ok, why = _splu_fits(N, H)
                    if not ok:
                        recs.append({"part": "newton", "N": N, "H": H, "method": "splu", "skipped": why})
                        continue
                    recs.append(run_child("newton", workdir, 900, N=N, H=H, method="splu", repeat=R))
                    loads.append(_load())
                    save()
        # --- 2. floor ---
        if "floor" in parts:
            recs.append(run_child("floor", workdir, 1200, N=floor_N, H=20, repeat=7 if not a.quick else 3))
            loads.append(_load())
            save()
        # --- 3. per continuation point ---
        if "points" in parts:
            for N in Ns:
                for H in Hs:
                    recs.append(run_child("points", workdir, 1200, N=N, H=H, max_points=K))
                    loads.append(_load())
                    save()
        # --- 4. Craig-Bampton ---
        if "cb" in parts:
            for N in Ns:
                for H in Hs:
                    recs.append(run_child("cb", workdir, 1200, N=N, H=H, repeat=R, max_points=K))
                    loads.append(_load())
                    save()
        # --- 5. dense ---
        if "dense" in parts:
            dN = [100, 200] if a.quick else [100, 200, 500]
            for N in dN:
                rd = 5 if N <= 200 else 3
                recs.append(run_child("dense", workdir, 1200, N=N, H=10, repeat=7, dense_repeat=1 if a.quick else rd))
                loads.append(_load())
                save()
        # --- 6. time integration ---
        if "time" in parts:
            tN = [1000] if a.quick else [1000, 10000]
            for N in tN:
                recs.append(run_child("time", workdir, 1500, N=N, H=20, max_points=5 if not a.quick else 3,
                                      check_theta05=(150 if N == 1000 and not a.quick else 0)))
                loads.append(_load())
                save()
        loads.append(_load())
        save()
        report(out)
        save()
    finally:
        if not a.keep_workdir:
            shutil.rmtree(workdir, ignore_errors=True)
    print(f"total wall time {time.perf_counter() - t_all:.0f} s; results in {a.json}")
    return 0


# ================================================================================================
# report
# ================================================================================================
def report(out: dict) -> None:
    import numpy as np

    recs = out["records"]
    info = out["machine"]
    loads = np.array(out["loads"])
    print()
    print(f"- CPU: {info['cpu']}; {info['cores']} logical CPUs; {info['mem_gib']:.1f} GiB")
    print(f"- python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}, femodes {info['femodes']} at git "
          f"{info['git']}{' (uncommitted changes in femodes/)' if info['femodes_dirty'] else ''}")
    print(f"- {info['threads']}")
    print(f"- load average (1 min) during the run: min {loads[:, 0].min():.2f}, median {np.median(loads[:, 0]):.2f}, "
          f"max {loads[:, 0].max():.2f}")
    print(f"- total wall time {out['wall']:.0f} s")

    def get(part, **kw):
        for r in recs:
            if r.get("part") == part and all(r.get(k) == v for k, v in kw.items()):
                return r
        return None

    Ns = out["settings"]["N"]
    Hs = out["settings"]["H"]
    # ---- newton ----
    rows = [r for r in recs if r.get("part") == "newton"]
    if rows:
        print("\n### Per Newton iteration (medians, ms; fresh w every repeat)\n")
        print("| N | H | unknowns | active | structured: res+J | fact. | solve | **total** | cached w: total "
              "| SuperLU: res+J | splu | solve | **total** | SuperLU / structured | RSS model [MiB] "
              "| peak struct. [MiB] | peak SuperLU [MiB] | nnz(L+U) |")
        print("|" + "---|" * 18)
        for N in Ns:
            for H in Hs:
                s = get("newton", N=N, H=H, method="structured")
                u = get("newton", N=N, H=H, method="splu")
                if s is None:
                    continue
                if "error" in s:
                    print(f"| {N} | {H} | - | - | error: {s['error'][:80]} |")
                    continue
                ts = _med(s["t_tot"])
                cells = [N, H, s["unknowns"], f"{s['active_contacts']}/{N_CONTACTS}", _ms(_med(s["t_res"])),
                         _ms(_med(s["t_fac"])), _ms(_med(s["t_sol"])), f"**{_ms(ts)}**", _ms(_med(s["tc_tot"]))]
                if u is None or "skipped" in u or "error" in u or "t_tot" not in u:
                    why = "-" if u is None else (u.get("skipped") or u.get("error", "?"))[:60]
                    cells += [f"n/a ({why})", "", "", "", "", _mib(s["rss_model"]), _mib(s["peak"]), "-", "-"]
                else:
                    tu = _med(u["t_tot"])
                    cells += [_ms(_med(u["t_res"])), _ms(_med(u["t_fac"])), _ms(_med(u["t_sol"])), f"**{_ms(tu)}**",
                              f"{tu / ts:.1f}", _mib(s["rss_model"]), _mib(s["peak"]), _mib(u["peak"]),
                              u.get("nnz_LU", "-")]
                print("| " + " | ".join(str(c) for c in cells) + " |")
        # exponents
        print("\n### Fitted exponents (log-log least squares)\n")
        print("| quantity | " + " | ".join(f"in N at H={H}" for H in Hs) + " | "
              + " | ".join(f"in H at N={N}" for N in Ns) + " |")
        print("|" + "---|" * (1 + len(Hs) + len(Ns)))
        qty = [("structured total / it.", "structured", lambda r: _med(r["t_tot"])),
               ("structured res+J", "structured", lambda r: _med(r["t_res"])),
               ("structured fact.+solve", "structured", lambda r: _med(r["t_fac"]) + _med(r["t_sol"])),
               ("structured cached-w total", "structured", lambda r: _med(r["tc_tot"])),
               ("SuperLU total / it.", "splu", lambda r: _med(r["t_tot"])),
               ("peak RSS - RSS model (structured)", "structured", lambda r: r["peak"] - r["rss_model"]),
               ("peak RSS - RSS model (SuperLU)", "splu", lambda r: r["peak"] - r["rss_model"])]
        fits = {}
        for name, meth, f in qty:
            cells = []
            for H in Hs:
                rr = [get("newton", N=N, H=H, method=meth) for N in Ns]
                rr = [r for r in rr if r and "t_tot" in r]
                e = _fit([r["N"] for r in rr], [f(r) for r in rr])
                fits[(name, "N", H)] = e
                cells.append(f"{e:.2f}" if e == e else "-")
            for N in Ns:
                rr = [get("newton", N=N, H=H, method=meth) for H in Hs]
                rr = [r for r in rr if r and "t_tot" in r]
                e = _fit([r["H"] for r in rr], [f(r) for r in rr])
                fits[(name, "H", N)] = e
                cells.append(f"{e:.2f}" if e == e else "-")
            print(f"| {name} | " + " | ".join(cells) + " |")
        if len(Ns) >= 2:
            a_, b_ = Ns[-2], Ns[-1]
            cells = []
            for H in Hs:
                r1, r2 = (get("newton", N=N, H=H, method="structured") for N in (a_, b_))
                ok = r1 and r2 and "t_tot" in r1 and "t_tot" in r2
                e = _fit([a_, b_], [_med(r1["t_tot"]), _med(r2["t_tot"])]) if ok else float("nan")
                fits[(f"structured total local slope {a_}->{b_}", "N", H)] = e
                cells.append(f"{e:.2f}" if e == e else "-")
            print(f"| structured total / it., local slope N={a_}->{b_} | " + " | ".join(cells)
                  + " | " + " | ".join(["" for _ in Ns]) + " |")
        out["fits"] = {f"{k[0]} | {k[1]} | {k[2]}": v for k, v in fits.items()}
    # ---- floor ----
    fl = get("floor")
    if fl and "error" not in fl:
        print(f"\n### Floor at N={fl['N']}, H={fl['H']} (medians of {fl['repeat']}, ms)\n")
        fm_tot = _med(fl["fm_res"]) + _med(fl["fm_fac"]) + _med(fl["fm_sol"])
        fm1 = _med(fl["fm_res_1t"]) + _med(fl["fm_fac_1t"]) + _med(fl["fm_sol_1t"])
        fl_tot = _med(fl["fl_res"]) + _med(fl["fl_sol"])
        print("| | residual (+J) | factorize + solve | total |")
        print("|---|---|---|---|")
        print(f"| femodes (default threads) | {_ms(_med(fl['fm_res']))} | {_ms(_med(fl['fm_fac']) + _med(fl['fm_sol']))} | {_ms(fm_tot)} |")
        print(f"| femodes (threads=1) | {_ms(_med(fl['fm_res_1t']))} | {_ms(_med(fl['fm_fac_1t']) + _med(fl['fm_sol_1t']))} | {_ms(fm1)} |")
        print(f"| floor (1 thread) | {_ms(_med(fl['fl_res']))} (linear part only) | {_ms(_med(fl['fl_sol']))} | {_ms(fl_tot)} |")
        print(f"\nratio femodes/floor: total {fm_tot / fl_tot:.2f} (threads=1: {fm1 / fl_tot:.2f}); "
              f"solve only {(_med(fl['fm_fac']) + _med(fl['fm_sol'])) / _med(fl['fl_sol']):.2f} "
              f"(threads=1: {(_med(fl['fm_fac_1t']) + _med(fl['fm_sol_1t'])) / _med(fl['fl_sol']):.2f}); "
              f"max rel. difference of the solutions {max(fl['diff']):.1e}; floor |J dx - r|/|r| {max(fl['relres_floor']):.1e}; "
              f"active contacts {fl['active_contacts']}/{N_CONTACTS}; boundary unknowns {fl['n_boundary']}")
    elif fl:
        print(f"\nfloor: error {fl['error']}")
    # ---- points ----
    rows = [r for r in recs if r.get("part") == "points"]
    if rows:
        print("\n### Per continuation point (full model)\n")
        print("| N | H | points | s / point | Newton its / point | rejected | folds | w range | peak RSS [MiB] | status |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            if "error" in r:
                print(f"| {r['N']} | {r['H']} | error: {r['error'][:100]} |")
                continue
            print(f"| {r['N']} | {r['H']} | {r['points']} | {r['t_per_point']:.2f} | {r['its_per_point']:.1f} | "
                  f"{r['n_rejected']} | {r['folds']} | {r['w_state']:.3f}-{r['w_last']:.3f} | {_mib(r['peak'])} | "
                  f"{('ok (max_points)' if 'max_points' in r['message'] else r['message'][:50]) if r['success'] else 'FAILED: ' + r['message'][:50]} |")
        qty = [("s / point", lambda r: r["t_per_point"])]
        for name, f in qty:
            cells = []
            for H in Hs:
                rr = [r for r in rows if r["H"] == H and "error" not in r]
                cells.append(f"{_fit([r['N'] for r in rr], [f(r) for r in rr]):.2f}")
            for N in Ns:
                rr = [r for r in rows if r["N"] == N and "error" not in r]
                cells.append(f"{_fit([r['H'] for r in rr], [f(r) for r in rr]):.2f}")
            print(f"\nexponents of {name}: " + ", ".join(
                [f"N at H={H}: {c}" for H, c in zip(Hs, cells[: len(Hs)])] +
                [f"H at N={N}: {c}" for N, c in zip(Ns, cells[len(Hs):])]))
    # ---- cb ----
    rows = [r for r in recs if r.get("part") == "cb"]
    if rows:
        print("\n### Craig-Bampton (20 modes; ROM keeps 10 contact DOFs + tip)\n")
        print("| N | H | reduction [s] | RSS model [MiB] | RSS after CB [MiB] | ROM DOFs | unknowns | active "
              "| per it. res+J [ms] | fact.+solve [ms] | total [ms] | s / point | its / point | peak RSS [MiB] |")
        print("|" + "---|" * 14)
        for r in rows:
            if "error" in r:
                print(f"| {r['N']} | {r['H']} | error: {r['error'][:100]} |")
                continue
            print(f"| {r['N']} | {r['H']} | {r['t_cb']:.2f} | {_mib(r['rss_model'])} | {_mib(r['rss_cb'])} | "
                  f"{r['n_rom']} | {r['unknowns']} | {r['active_contacts']}/{N_CONTACTS} | {_ms(_med(r['t_res']))} | "
                  f"{_ms(_med(r['t_fs']))} | {_ms(_med(r['t_tot']))} | {r['t_per_point']:.2f} | "
                  f"{r['its_per_point']:.1f} | {_mib(r['peak'])} |")
        cells = []
        for N in Ns:
            rr = [r for r in rows if r["N"] == N and "error" not in r]
            cells.append(f"H at N={N}: {_fit([r['H'] for r in rr], [_med(r['t_tot']) for r in rr]):.2f}")
        for H in Hs:
            rr = [r for r in rows if r["H"] == H and "error" not in r]
            cells.append(f"t_cb in N (H={H}): {_fit([r['N'] for r in rr], [r['t_cb'] for r in rr]):.2f}")
        print("\nexponents of the ROM time per iteration: " + ", ".join(cells))
    # ---- dense ----
    rows = [r for r in recs if r.get("part") == "dense"]
    if rows:
        print("\n### Dense-Jacobian HBM (numpy.linalg.solve on J.toarray()) against the structured solve, H = 10\n")
        print("| N | unknowns | res+J [ms] | structured fact.+solve [ms] | SuperLU [ms] | toarray [ms] | dense solve [ms] "
              "| dense (toarray+solve) / structured | dense / SuperLU | max rel. diff. | peak RSS [MiB] |")
        print("|" + "---|" * 11)
        for r in rows:
            if "error" in r:
                print(f"| {r['N']} | error: {r['error'][:100]} |")
                continue
            st = _med(r["t_struct"])
            de = _med(r["t_toarray"]) + _med(r["t_dense"])
            print(f"| {r['N']} | {r['unknowns']} | {_ms(_med(r['t_res']))} | {_ms(st)} | {_ms(_med(r['t_splu']))} | "
                  f"{_ms(_med(r['t_toarray']))} | {_ms(_med(r['t_dense']))} | {de / st:.0f} | "
                  f"{de / _med(r['t_splu']):.0f} | {max(r['dense_vs_struct']):.1e} | {_mib(r['peak'])} |")
    # ---- time ----
    for r in [r for r in recs if r.get("part") == "time"]:
        if "error" in r:
            print(f"\ntime integration: error {r['error']}")
            continue
        hb = r["hbm"]
        print(f"\n### Time integration (fm.steady_state, theta = {r['theta']}, {r['steps_per_period']} steps/period, tol {r['tol']:g}, warm "
              f"start from the previous frequency) vs HBM (H = {r['H']}) at N = {r['N']}\n")
        print(f"HBM: {hb['points']} points in {hb['t_cont']:.2f} s ({hb['t_per_point']:.2f} s / point after the start, "
              f"{hb['its_per_point']:.1f} Newton its / point)\n")
        print("| w [rad/s] | TI wall [s] | periods | converged | tip amp. HBM | tip amp. TI | rel. diff tip "
              "| max over DOFs abs. diff / max amp. | HBM penetration |")
        print("|---|---|---|---|---|---|---|---|---|")
        for p in r["points"]:
            print(f"| {p['omega']:.4f} | {p['t_ti']:.2f} | {p['periods']} | {p['converged']} | {p['amp_tip_hbm']:.5f} | "
                  f"{p['amp_tip_ti']:.5f} | {p['rel_tip']:.1e} | {p['rel_all']:.1e} | "
                  f"{p['hbm_penetration']:.1e} |")
        if "theta05" in r:
            c = r["theta05"]
            print(f"\ntheta = 0.5 at w = {c['omega']:.4f} from rest: {c['periods']} periods, {c['t_ti']:.1f} s, "
                  f"converged {c['converged']} (nu = {c['nu']}, last period-to-period change {c['change']:.2g}), "
                  f"tip amplitude {c['amp_tip_ti']:.5f} (rel. diff to HBM {c['rel_tip']:.1e})")
        tti = statistics.median([p["t_ti"] for p in r["points"]])
        print(f"\nmedian TI time per frequency {tti:.2f} s vs HBM {hb['t_per_point']:.2f} s per point: "
              f"ratio {tti / hb['t_per_point']:.0f}")
    # ---- targets ----
    print("\n### Targets\n")
    fits = out.get("fits", {})
    e = [v for k, v in fits.items() if k.startswith("structured total / it. | N |")]
    loc = [v for k, v in fits.items() if k.startswith("structured total local slope")]
    if e:
        print(f"1. time per Newton iteration ~ N^a with a <= 1.1: fitted a = {min(e):.2f}..{max(e):.2f} over "
              f"N = {Ns[0]}..{Ns[-1]} -> {'met' if max(e) <= 1.1 else 'NOT met'}; local slope "
              f"{Ns[-2] if len(Ns) > 1 else ''}->{Ns[-1]}: {min(loc):.2f}..{max(loc):.2f}" if loc else "")
    if fl and "error" not in fl:
        fm_tot = _med(fl["fm_res"]) + _med(fl["fm_fac"]) + _med(fl["fm_sol"])
        fm1 = _med(fl["fm_res_1t"]) + _med(fl["fm_fac_1t"]) + _med(fl["fm_sol_1t"])
        fl_tot = _med(fl["fl_res"]) + _med(fl["fl_sol"])
        worst = max(fm_tot, fm1) / fl_tot
        print(f"2. femodes / floor at N={fl['N']}, H={fl['H']} <= 2: {fm_tot / fl_tot:.2f} (default threads), "
              f"{fm1 / fl_tot:.2f} (threads=1) -> {'met' if worst <= 2 else 'NOT met'}")
    d5 = get("dense", N=500)
    if d5 and "error" not in d5:
        ratio = (_med(d5["t_toarray"]) + _med(d5["t_dense"])) / _med(d5["t_struct"])
        ratio_it = ((_med(d5["t_res"]) + _med(d5["t_toarray"]) + _med(d5["t_dense"]))
                    / (_med(d5["t_res"]) + _med(d5["t_struct"])))
        print(f"3. dense / structured at N=500, H=10 >= 100: {ratio:.0f} (linear solve), {ratio_it:.0f} (whole "
              f"iteration incl. residual) -> {'met' if min(ratio, ratio_it) >= 100 else 'NOT met'}")


if __name__ == "__main__":
    sys.exit(main())
