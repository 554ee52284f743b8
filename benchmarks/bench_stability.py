#!/usr/bin/env python
"""Cost of the stability of one periodic solution, relative to the cost of the solution itself.

Run from the repository root::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_stability.py          # full run (~10.5 min here)
    python benchmarks/bench_stability.py --quick                          # N = 1e2, 1e3, H = 5, no shooting (~2 min)
    python benchmarks/bench_stability.py --sizes 100 1000 --H 5 --contacts penalty --no-shooting
    python benchmarks/bench_stability.py --sizes 100 --H 10 --no-shooting --compare-H 10 \
        --profile-N 0 --profile-unilateral-N 0    # dense vs shift-invert at 2100-2121 unknowns (~3 min)
    python benchmarks/bench_stability.py --json out/bench_stability.json  # also keep the raw numbers

This is a script, not a pytest test. Results and discussion: ``benchmarks/README_stability.md``.
The markdown report goes to stdout, progress to stderr. Every measurement runs in a fresh child
process (same interpreter) with ``OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1``.

Model. Clamped P1 bar (``fm.line_mesh(1, N)``, ``fm.bar(mesh, fm.Material(E=1, rho=1),
fm.Section(area=1), clamped="clamp")``: N DOFs), Rayleigh damping ``beta = 0.01`` (0.8 % on mode 1),
tip force ``0.01 cos(w t)`` and a stop at the tip with gap ``0.05``:

``penalty``     ``fm.PenaltyContact(at="tip", gap=0.05, stiffness=5)`` (consistent mass);
``unilateral``  ``fm.UnilateralContact(at="tip", gap=0.05)`` with ``contact_mass=fm.ConsistentMass()``
                (femodes' default for FE models, ``RedistributeMass``, leaves the contact DOF
                without mass, and shooting refuses such a model).

The first resonance is ``w1 = pi/2``; the linear tip amplitude reaches the gap at w ~ 1.42 and the
contact branch bends to the right (fold at w ~ 1.87). ``fm.frequency_response(model, (1.3, 1.9), H)``
with ``frequency_response``'s default options capped at ``max_points = 25`` ends on the stiffened
contact branch (w ~ 1.80-1.85). The point measured is the one of these 25 with the deepest tip
penetration ``max_t q_tip(t) - gap`` (contact active; for ``unilateral`` the largest contact force).

Measured for every (contact, N, H), medians of R repeats (``--repeat``, default 3; 5 for Newton):

(a1) ``point (Newton)``: ``fm.semismooth_newton`` on ``ForcedResponseProblem.residual(., w_i)`` at
     the point's frequency from a slightly perturbed start, ``x_i (1 + 0.01 xi)`` with ``xi`` standard
     normal (seed 0), ``NewtonOptions(atol=1e-9, max_iter=20)`` as ``frequency_response``; it takes
     3 iterations, as the continuation's corrector does per point here. The cached per-harmonic
     factorisations of the system are dropped before every repeat. This is the denominator of the
     ratios. (Starting from the previous branch point instead, 12-14 % away at the end of the
     25-point run, took 8-11 iterations, and did not converge for the 1e3-DOF unilateral case.)
(a2) ``point (cont.)``: continuation wall time / number of points of the 25-point run (includes the
     tangent and the bordered corrector solves, rejected steps, the start).
(b)  ``fm.stability(sol, method=fm.stability_methods.Hill())``: Hill's method; dense up to ``hill.DENSE_LIMIT`` (1500)
     unknowns, ARPACK shift-invert with SuperLU above. Reported: the path, how many multipliers it
     returns, ``max |mu|``.
(c)  ``fm.stability(sol, method=fm.stability_methods.Shooting())`` (N <= ``shooting.MAX_DOFS`` = 500, H in ``--shoot-H``,
     default 5: shooting uses H only for its start state), in its own child killed after
     ``--shoot-timeout`` seconds (default 300). A failure is not repeated. Above 500 DOFs the call is
     made once to record the refusal.

``compare`` (N = 100, ``--compare-H``, default H = 5: 1100-1111 unknowns, where both Hill paths run):
the dense path against the shift-invert path forced by monkeypatching ``femodes.hbm.hill.DENSE_LIMIT``
(femodes' defaults ``n_shifts=4``; the ``n_shifts=6, k_per_shift=24`` of the tests) and against the
benchmark-local variants below; agreement of the largest ``|mu|``, the timing of the dense path's
pieces, and the dense spectrum around the leading exponent with each eigenvector's harmonic
centroid (which copy of an exponent family is the central one).

``profile`` (``--profile-N`` = 1e4 penalty and ``--profile-unilateral-N`` = 1e3 unilateral, H = 5):
cProfile of ``fm.stability(sol, "hill")`` (where the time goes), then *benchmark-local* variants of
the shift-invert solve on the same Hill matrices (:func:`sparse_variant`, a copy of ``hill._sparse``
with its knobs exposed: shifts, ``k``, ARPACK ``tol`` and ``ncv``, the linear solver -- SuperLU as
femodes, or :class:`StructuredShift`, an experimental band-LU-per-harmonic + Schur solver of the
shifted Hill matrix in the spirit of ``femodes.hbm.linsolve`` -- and the selection: femodes', or the
experimental :func:`family_select` / ``"recentre"``). femodes itself is not modified; the variants
reuse its ``hill_matrices``, ``_select``, ``_centroids``, ``_fold`` and ``CENTRAL``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time

from _machine import cpu_model  # noqa: E402 - benchmarks/ is on sys.path when run as a script

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WINDOW = (1.3, 1.9)
FORCE = 0.01
GAP = 0.05
K_PENALTY = 5.0
BETA = 0.01
MAX_POINTS = 25
ATOL = 1e-9
PERTURBATION = 1e-2  # relative perturbation of the start of the Newton correction (a1)
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
MARK = "@@RESULT@@"


# ----------------------------------------------------------------------------------------------
# child side: model, branch, point
# ----------------------------------------------------------------------------------------------
def build(ne: int, contact: str):
    import femodes as fm

    mesh = fm.line_mesh(length=1.0, n_elements=ne, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_damping(beta=BETA)
             .with_forcing(fm.HarmonicForce(at="tip", amplitude=FORCE)))
    if contact == "penalty":
        return model.with_contact(fm.PenaltyContact(at="tip", gap=GAP, stiffness=K_PENALTY))
    if contact == "unilateral":
        return model.with_contact(fm.UnilateralContact(at="tip", gap=GAP), contact_mass=fm.ConsistentMass())
    raise ValueError(f"unknown contact {contact!r}")


def branch_and_point(ne: int, H: int, contact: str, rec: dict):
    """The 25-point branch (timed) and the index of the deepest-contact point (>= 1)."""
    import numpy as np

    import femodes as fm

    t = time.perf_counter()
    model = build(ne, contact)
    rec["t_model"] = time.perf_counter() - t
    opts = fm.ContinuationOptions(step=0.05, max_step=0.5, max_points=MAX_POINTS,
                                  newton=fm.NewtonOptions(atol=ATOL, max_iter=20))
    t = time.perf_counter()
    b = fm.frequency_response(model, WINDOW, H, options=opts)
    rec["t_continuation"] = time.perf_counter() - t
    rec["points"] = len(b)
    rec["cont_success"] = bool(b.success)
    rec["t_per_point_cont"] = rec["t_continuation"] / max(len(b), 1)
    rec["cont_nit_mean"] = float(np.mean(b.nit[1:])) if len(b) > 1 else float("nan")
    tip = model.dof("tip")
    pen = []
    for i in range(len(b)):
        sol = b[i]
        tt = np.linspace(0.0, sol.period, 512, endpoint=False)
        pen.append(float(np.max(sol.displacement(tt)[:, tip])) - GAP)
    pen = np.array(pen)
    if contact == "unilateral" and b.P.size:
        score = b.P[:, 0, 0]  # mean contact force
    else:
        score = pen
    i = int(np.argmax(score[1:])) + 1
    rec.update(index=i, omega=float(b.omega[i]), penetration=float(pen[i]),
               contact_force_mean=float(b.P[i, 0, 0]) if b.P.size else None,
               n_unknowns=int(b[i].Q.size + b[i].P.size))
    return model, b, i


def _median(v):
    return statistics.median(v) if v else float("nan")


def _mu_summary(mu) -> dict:
    import numpy as np

    mu = np.asarray(mu)
    if mu.size == 0:
        return {"n_mu": 0, "max_abs_mu": None, "lead_mu": None}
    j = int(np.argmax(np.abs(mu)))
    return {"n_mu": int(mu.size), "max_abs_mu": float(np.abs(mu[j])), "lead_mu": [float(mu[j].real), float(mu[j].imag)]}


def child_case(ne: int, H: int, contact: str, repeat: int) -> dict:
    import resource

    import numpy as np

    import femodes as fm
    from femodes.hbm import hill as hill_mod
    from femodes.time.shooting import MAX_DOFS

    rec: dict = {"kind": "case", "N": ne, "H": H, "contact": contact, "repeat": repeat}
    model, b, i = branch_and_point(ne, H, contact, rec)
    sol = b[i]
    rec["dense_limit"] = int(hill_mod.DENSE_LIMIT)
    reduced = ne > hill_mod.REDUCE_MIN_DOFS and rec["n_unknowns"] > hill_mod.DENSE_LIMIT
    rec["hill_path"] = ("Craig-Bampton" if reduced else
                        "dense" if rec["n_unknowns"] <= hill_mod.DENSE_LIMIT else "shift-invert")

    # (a1) Newton correction at fixed w from the previous point
    pr = fm.ForcedResponseProblem(model, fm.Harmonics(H))
    w = float(b.omega[i])
    x_ref = pr.pack(b.Q[i], b.P[i], w)
    x0 = x_ref * (1.0 + PERTURBATION * np.random.default_rng(0).standard_normal(x_ref.size))
    opts = fm.NewtonOptions(atol=ATOL, max_iter=20)

    def fun(x):
        r, J, _ = pr.residual(x, w)
        return r, J

    t_newton, nits, nfev = [], [], []
    res = None
    for _ in range(max(repeat, 5)):
        pr.system._cache.pop("factors", None)  # no reuse of the last repeat's factorisations
        t = time.perf_counter()
        res = fm.semismooth_newton(fun, x0, options=opts)
        t_newton.append(time.perf_counter() - t)
        nits.append(int(res.nit))
        nfev.append(int(res.nfev))
    rec.update(t_newton=t_newton, newton_nit=nits, newton_nfev=nfev, newton_success=bool(res.success),
               newton_residual=float(res.residual_norm),
               newton_dx_start=float(np.max(np.abs(x0 - x_ref)) / np.max(np.abs(x_ref))),
               newton_dx_end=float(np.max(np.abs(res.x - x_ref)) / np.max(np.abs(x_ref))))
    log(f"  Newton {_median(t_newton):.3f} s ({nits[0]} its), continuation {rec['t_per_point_cont']:.3f} s/point")

    # (b) Hill
    t_hill, r = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        r = fm.stability(sol, method=fm.stability_methods.Hill())
        t_hill.append(time.perf_counter() - t)
        log(f"  hill {t_hill[-1]:.2f} s")
    rec["t_hill"] = t_hill
    rec["hill"] = dict(_mu_summary(r.multipliers), stable=bool(r.stable))
    if reduced:  # the reduction's size and error estimate, from the result's own Hill solve
        from femodes.hbm.system import HBMSystem
        system = HBMSystem(model, sol.harmonics)
        hr = hill_mod.hill_exponents(system, system.join(sol.Q, sol.P), sol.omega)
        rec["hill_path"] = f"Craig-Bampton, {hr.n_modes} modes, est. {hr.reduction_error:.0e}"

    # (c) shooting: only the refusal here (the real run is a separate child with a timeout)
    if model.n_dofs > MAX_DOFS:
        t = time.perf_counter()
        try:
            fm.stability(sol, method=fm.stability_methods.Shooting())
            rec["shooting_refused"] = None
        except ValueError as exc:
            rec["shooting_refused"] = str(exc)[:160]
        rec["t_shooting_refusal"] = time.perf_counter() - t
    rec["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return rec


def child_shoot(ne: int, H: int, contact: str, repeat: int) -> dict:
    import importlib

    import femodes as fm

    rec: dict = {"kind": "shoot", "N": ne, "H": H, "contact": contact}
    model, b, i = branch_and_point(ne, H, contact, rec)
    sol = b[i]
    fl = importlib.import_module(fm.stability.__module__)  # femodes.floquet (was femodes.stability)
    orig = fl.shoot
    shots = []

    def shoot_w(*a, **k):
        res = orig(*a, **k)
        shots.append(res)
        return res

    fl.shoot = shoot_w
    times, err, r = [], None, None
    for _ in range(repeat):
        t = time.perf_counter()
        try:
            r = fm.stability(sol, method=fm.stability_methods.Shooting())
        except Exception as exc:  # noqa: BLE001 - reported, not raised
            times.append(time.perf_counter() - t)
            err = f"{type(exc).__name__}: {exc}"
            break
        times.append(time.perf_counter() - t)
        log(f"  shooting {times[-1]:.1f} s")
    fl.shoot = orig
    rec["t_shooting"] = times
    rec["shooting_error"] = err[:300] if err else None
    if r is not None:
        rec["shooting"] = dict(_mu_summary(r.multipliers), stable=bool(r.stable),
                               orbit_correction=float(r.orbit_correction))
    if shots:
        s = shots[-1]
        rec["shoot_nit"] = int(s.nit)
        rec["shoot_impacts"] = len(getattr(s, "impacts", []) or [])
    rec["monodromy_size"] = 2 * model.n_dofs
    return rec


# ----------------------------------------------------------------------------------------------
# child side: dense vs shift-invert Hill
# ----------------------------------------------------------------------------------------------
def child_compare(ne: int, H: int, contact: str, repeat: int) -> dict:
    import numpy as np
    import scipy.linalg as sla

    from femodes.hbm import HBMSystem
    from femodes.hbm import hill as hm
    from femodes.hbm.hill_dense import dense_spectrum

    rec: dict = {"kind": "compare", "N": ne, "H": H, "contact": contact}
    model, b, i = branch_and_point(ne, H, contact, rec)
    sol = b[i]
    system = HBMSystem(model, sol.harmonics)
    y = system.join(sol.Q, sol.P)
    w = float(sol.omega)
    saved = hm.DENSE_LIMIT

    def run(label, limit, reps, **kw):
        hm.DENSE_LIMIT = limit
        times, res = [], None
        for _ in range(reps):
            t = time.perf_counter()
            res = hm.hill_exponents(system, y, w, **kw)
            times.append(time.perf_counter() - t)
        hm.DENSE_LIMIT = saved
        j = int(np.argmax(np.abs(res.multipliers)))
        out = dict(_mu_summary(res.multipliers), t=times, complete=bool(res.complete),
                   lead_centroid=float(res.centroids[j]),
                   lead_exponent=[float(res.exponents[j].real), float(res.exponents[j].imag)])
        log(f"  {label}: {_median(times):.3f} s, {out['n_mu']} mu, max|mu| {out['max_abs_mu']:.6f}")
        return out, res

    rec["dense"], dres = run("dense", 10**9, 1)
    rec["sparse_default"], _ = run("shift-invert (n_shifts=4)", 0, repeat)
    rec["sparse_test"], _ = run("shift-invert (n_shifts=6, k=24)", 0, repeat, n_shifts=6, k_per_shift=24)
    J0, J1, J2 = hm.hill_matrices(system, y, w)
    st: dict = {}
    t = time.perf_counter()
    mu, cen, _ = sparse_variant(system, J0, J1, J2, w, im=[1.0], k=4, tol=1e-8, stats=st)
    rec["sparse_shift_at_w"] = dict(_mu_summary(mu), t=[time.perf_counter() - t],
                                    lead_centroid=float(cen[0]) if len(cen) else None)
    t = time.perf_counter()
    mu, cen, _ = sparse_variant(system, J0, J1, J2, w, im=[0.0, 1.0], k=4, tol=1e-8, select="family")
    rec["sparse_family"] = dict(_mu_summary(mu), t=[time.perf_counter() - t],
                                lead_centroid=float(cen[0]) if len(cen) else None)
    st = {}
    t = time.perf_counter()
    mu, cen, _ = sparse_variant(system, J0, J1, J2, w, im=[0.0], k=4, tol=1e-8, select="recentre", stats=st)
    rec["sparse_recentre"] = dict(_mu_summary(mu), t=[time.perf_counter() - t], n_factor=st["n_factor"],
                                  lead_centroid=float(cen[0]) if len(cen) else None)
    st = {}
    t = time.perf_counter()
    mu, cen, _ = sparse_variant(system, J0, J1, J2, w, n_shifts=4, k=12, select="recentre", stats=st)
    rec["sparse_default_recentre"] = dict(_mu_summary(mu), t=[time.perf_counter() - t], n_factor=st["n_factor"],
                                          lead_centroid=float(cen[0]) if len(cen) else None)
    st = {}
    t = time.perf_counter()
    mu, cen, _ = sparse_variant(system, J0, J1, J2, w, im=[0.0, 0.5], k=6, tol=1e-8, select="recentre", stats=st)
    rec["sparse_cheap_recentre"] = dict(_mu_summary(mu), t=[time.perf_counter() - t], n_factor=st["n_factor"],
                                        lead_centroid=float(cen[0]) if len(cen) else None)
    ref = rec["dense"]["max_abs_mu"]
    for key in ("sparse_default", "sparse_test", "sparse_shift_at_w", "sparse_family", "sparse_recentre",
                "sparse_default_recentre", "sparse_cheap_recentre"):
        m = rec[key]["max_abs_mu"]
        rec[key]["rel_diff_max_abs_mu"] = (m - ref) / ref if m is not None else None

    # pieces of the dense path (as in hill_dense.dense_pencil) when it is femodes' path, and the dense spectrum
    # near the leading exponent with the eigenvectors' harmonic centroids (the exponent families)
    N = J0.shape[0]
    if system.size <= saved:
        A0, A1, A2 = J0.toarray(), J1.toarray(), J2.toarray()
        sigma = 0.37 * w
        t = time.perf_counter()
        lu = sla.lu_factor(A0 + sigma * A1 + sigma * sigma * A2, check_finite=False)
        t_lu = time.perf_counter() - t
        t = time.perf_counter()
        Z1 = sla.lu_solve(lu, np.hstack([-(A1 + sigma * A2), -A2]), check_finite=False)
        t_solve = time.perf_counter() - t
        OP = np.empty((2 * N, 2 * N))
        OP[:N] = Z1
        OP[N:] = sigma * Z1
        OP[N:, :N] += np.eye(N)
        t = time.perf_counter()
        theta, Zv = sla.eig(OP, check_finite=False)
        t_eig = time.perf_counter() - t
        t = time.perf_counter()
        sla.eigvals(OP, check_finite=False)
        t_eigvals = time.perf_counter() - t
        rec["dense_pieces"] = dict(order=2 * N, lu=t_lu, lu_solve=t_solve, eig_with_vectors=t_eig, eigvals_only=t_eigvals)
        finite = np.abs(theta) > 1e-10 * max(1.0, float(np.max(np.abs(theta))))
        s_all, V_all = sigma + 1.0 / theta[finite], Zv[:N, finite]
    else:
        s_all, V_all, _ = dense_spectrum(J0, J1, J2, w)
    cen_all = hm._centroids(system, V_all)
    lead_re = rec["dense"]["lead_exponent"][0]
    near = np.flatnonzero(np.abs(s_all.real - lead_re) < 0.25 * abs(lead_re) + 1e-12)
    near = near[np.argsort(np.abs(cen_all[near]))][:10]
    rec["dense_spectrum_near_lead"] = [[float(s_all[k].real), float(s_all[k].imag), float(cen_all[k])] for k in near]
    return rec


# ----------------------------------------------------------------------------------------------
# benchmark-local variants of the shift-invert Hill solve (femodes is not modified)
# ----------------------------------------------------------------------------------------------
class StructuredShift:
    """Experimental solver of ``J(sigma) z = r``, ``J(sigma) = J0 + sigma J1 + sigma^2 J2`` (complex
    ``sigma``): the linear DOFs ("interior") split by harmonic, each harmonic's (cos, sin) pair
    interleaved DOF by DOF so that the block is banded (bandwidth 3 for a P1 bar), LAPACK complex band
    LU per block (``zgbtrf``), and a dense Schur complement on the contact DOF's coefficients and the
    contact-force unknowns (the only unknowns that couple harmonics). It exists to measure what
    reusing the structure of ``femodes.hbm.linsolve`` for a complex shift would cost."""

    def __init__(self, system, J0, J1, J2, sigma):
        import numpy as np
        import scipy.linalg as sla
        from scipy.linalg import lapack

        h, n = system.h, system.n
        bd = np.asarray(system.nonlinear_dofs, dtype=int)
        mask = np.ones(n, dtype=bool)
        mask[bd] = False
        interior = np.flatnonzero(mask)
        groups = [0 * n + interior]
        for k in range(1, h.n_harmonics + 1):
            c, s = h.layout.cos_index(k), h.layout.sin_index(k)
            g = np.empty(2 * interior.size, dtype=int)
            g[0::2], g[1::2] = c * n + interior, s * n + interior
            groups.append(g)
        B = np.concatenate([np.array([c * n + d for c in range(h.n_coef) for d in bd], dtype=int),
                            np.arange(system.nq, system.size)])
        perm = np.concatenate(groups + [B])
        Js = (J0 + sigma * J1 + (sigma * sigma) * J2).tocsr()[perm][:, perm].tocsr()
        nI = perm.size - B.size
        self.perm, self.nI = perm, nI
        self.bounds = np.cumsum([0] + [g.size for g in groups])
        JII = Js[:nI, :nI].tocoo()
        grp = np.searchsorted(self.bounds, JII.row, side="right")
        if np.any(grp != np.searchsorted(self.bounds, JII.col, side="right")):
            raise RuntimeError("the interior couples harmonics: not the structure assumed")
        self.lus = []
        for j in range(len(groups)):
            a, e = self.bounds[j], self.bounds[j + 1]
            sel = grp == j + 1
            r, c = JII.row[sel] - a, JII.col[sel] - a
            kl = int(np.max(np.abs(r - c))) if r.size else 0
            ab = np.zeros((3 * kl + 1, e - a), dtype=complex, order="F")
            ab[2 * kl + r - c, c] = JII.data[sel]
            lu, piv, info = lapack.zgbtrf(ab, kl, kl, overwrite_ab=True)
            if info != 0:
                raise RuntimeError(f"zgbtrf info {info}")
            self.lus.append((lu, piv, kl))
        self._gbtrs = lapack.zgbtrs
        CIB = Js[:nI, nI:].toarray()
        self.CBI = Js[nI:, :nI].tocsr()
        self.W = self._interior(CIB)
        self.S = sla.lu_factor(Js[nI:, nI:].toarray() - self.CBI @ self.W)
        self._lu_solve = sla.lu_solve

    def _interior(self, R):
        import numpy as np

        out = np.empty(R.shape, dtype=complex)
        for j, (lu, piv, kl) in enumerate(self.lus):
            a, e = self.bounds[j], self.bounds[j + 1]
            out[a:e], _ = self._gbtrs(lu, kl, kl, np.asfortranarray(R[a:e], dtype=complex), piv)
        return out

    def solve(self, r):
        import numpy as np

        rp = r[self.perm]
        nI = self.nI
        yI = self._interior(rp[:nI, None])[:, 0]
        zB = self._lu_solve(self.S, rp[nI:] - self.CBI @ yI)
        z = np.empty(rp.shape, dtype=complex)
        z[:nI] = yI - self.W @ zB
        z[nI:] = zB
        out = np.empty_like(z)
        out[self.perm] = z
        return out


def family_select(system, s, V, base):
    """Experimental selection: the found exponents completed by their conjugates (the Hill problem
    is real: ``conj(s)`` is an exponent, its eigenvector has the centroid ``-c``), taken by increasing
    ``|centroid|`` up to ``hill.CENTRAL``, skipping any that is a copy of one already taken: exact
    (femodes' rule, ``s_i - s_j = i m base`` to 1e-6) *or inexact*: ``m = round(Im(s_i - s_j) / base)
    != 0`` with the centroid shifted accordingly (``|c_i - c_j + m| < 0.25``) and ``|Re(s_i - s_j)|
    <= 0.5 |Re s_j|`` (a shifted copy carries the truncation error of the harmonics it lost).
    Returns ``(s, centroids)``. A heuristic of this benchmark, not femodes' method."""
    import numpy as np

    from femodes.hbm import hill as hm

    cen = hm._centroids(system, V)
    s2, c2 = np.concatenate([s, s.conj()]), np.concatenate([cen, -cen])
    taken: list[int] = []
    for i in np.argsort(np.abs(c2), kind="stable"):
        if abs(c2[i]) > hm.CENTRAL:
            break
        dup = False
        for j in taken:
            d = s2[i] - s2[j]
            m = round(d.imag / base)
            if m == 0:
                dup = abs(d) <= 1e-8 * base
            elif abs(d - 1j * m * base) <= 1e-6 * base:
                dup = True
            else:
                dup = abs(c2[i] - c2[j] + m) < 0.25 and abs(d.real) <= 0.5 * abs(s2[j].real) + 1e-6 * base
            if dup:
                break
        if not dup:
            taken.append(int(i))
    return s2[taken], c2[taken]


def sparse_variant(system, J0, J1, J2, base, *, n_shifts=None, im=None, k=12, tol=1e-12, ncv=None,
                   solver="superlu", select="femodes", k_recentre=4, stats=None):
    """A copy of ``femodes.hbm.hill._sparse`` + the selection of ``hill_exponents``, with its knobs
    exposed: the shifts ``sigma_j = 1e-3 base + i base im[j]`` (default: femodes' ``n_shifts`` evenly
    in ``[0, 1/2]``), ARPACK's ``k``, ``tol``, ``ncv`` and the linear solver (``"superlu"`` as
    femodes, or ``"structured"``: :class:`StructuredShift`). ``select``:

    ``"femodes"``   ``hill._select`` then ``|centroid| <= hill.CENTRAL``, as ``hill_exponents``;
    ``"family"``    :func:`family_select` (experimental);
    ``"recentre"``  (experimental) every found exponent with ``1/2 < |centroid| <= 1.5`` is taken
                    for a copy shifted by ``m = round(centroid)`` (at least 1) harmonics: one more
                    shift-invert (``k_recentre`` eigenvalues) at ``sigma = s + i m base``, where its
                    central copy should lie, replaces it by the eigenvalue nearest to ``sigma``;
                    repeated (at most 4 steps) until ``|centroid| <= 1/2``. Shifts are cached (a
                    conjugate target reuses the conjugate result). Then conjugates are added, exact
                    copies removed and ``|centroid| <= CENTRAL`` kept.

    Returns ``(multipliers, centroids, stats)`` sorted by decreasing ``|mu|``; ``stats`` splits the
    time."""
    import numpy as np
    import scipy.sparse.linalg as spla

    from femodes.hbm import hill as hm

    if im is None:
        im = [0.5 * j / max(n_shifts - 1, 1) for j in range(n_shifts or 4)]
    st = stats if stats is not None else {}
    for key in ("t_factor", "t_solve", "t_eigs", "t_matvec_other"):
        st.setdefault(key, 0.0)
    st.setdefault("n_solve", 0)
    st.setdefault("n_factor", 0)
    t_all = time.perf_counter()
    N = J0.shape[0]
    J0c, J1c, J2c = (A.astype(complex).tocsc() for A in (J0, J1, J2))

    def one_shift(sigma, kk):
        t = time.perf_counter()
        if solver == "superlu":
            lu = spla.splu((J0c + sigma * J1c + sigma * sigma * J2c).tocsc())
        else:
            lu = StructuredShift(system, J0, J1, J2, sigma)
        st["t_factor"] += time.perf_counter() - t
        st["n_factor"] += 1
        S1 = J1c + sigma * J2c

        def op(yv):
            t0 = time.perf_counter()
            y1, y2 = yv[:N], yv[N:]
            rhs = -(J2c @ y2) - S1 @ y1
            t1 = time.perf_counter()
            z1 = lu.solve(rhs)
            t2 = time.perf_counter()
            out = np.concatenate([z1, y1 + sigma * z1])
            st["t_solve"] += t2 - t1
            st["t_matvec_other"] += (t1 - t0) + (time.perf_counter() - t2)
            st["n_solve"] += 1
            return out

        L = spla.LinearOperator((2 * N, 2 * N), matvec=op, dtype=complex)
        t = time.perf_counter()
        theta, Z = spla.eigs(L, k=min(kk, 2 * N - 2), which="LM", tol=tol, ncv=ncv)
        st["t_eigs"] += time.perf_counter() - t
        good = np.abs(theta) > 0
        return sigma + 1.0 / theta[good], Z[:N, good]

    found = [one_shift(1e-3 * base + 1j * base * x, k) for x in im]
    s, V = np.concatenate([f[0] for f in found]), np.hstack([f[1] for f in found])
    keep: list[int] = []
    for i in np.argsort(np.abs(s)):
        if all(abs(s[i] - s[j]) > 1e-8 * base for j in keep):
            keep.append(int(i))
    s, V = s[keep], V[:, keep]
    if select == "family":
        s_sel, c_sel = family_select(system, s, V, base)
    elif select == "recentre":
        cen = hm._centroids(system, V)
        out_s, out_c, done = [], [], []  # done: (target, eigenvalues, centroids) of the extra shifts

        def near_target(target):
            for t_, s2, c2 in done:
                if abs(target - t_) <= 1e-6 * base:
                    return s2, c2
                if abs(np.conj(target) - t_) <= 1e-6 * base:
                    return np.conj(s2), -c2
            s2, V2 = one_shift(target, k_recentre)
            c2 = hm._centroids(system, V2)
            done.append((target, s2, c2))
            return s2, c2

        for si, ci in zip(s, cen):
            if abs(ci) > 1.5:
                continue
            for _ in range(4):  # walk towards the central copy: one harmonic shift per step
                if abs(ci) <= 0.5:
                    out_s.append(si)
                    out_c.append(ci)
                    break
                target = si + 1j * np.sign(ci) * max(1, round(abs(float(ci)))) * base
                s2, c2 = near_target(target)
                j = int(np.argmin(np.abs(s2 - target)))
                si, ci = s2[j], c2[j]
        s_all = np.concatenate([np.array(out_s, dtype=complex), np.conj(np.array(out_s, dtype=complex))])
        c_all = np.concatenate([np.array(out_c, dtype=float), -np.array(out_c, dtype=float)])
        taken: list[int] = []
        for i in np.argsort(np.abs(c_all), kind="stable"):
            if abs(c_all[i]) > hm.CENTRAL:
                break
            dup = False
            for j in taken:
                d = s_all[i] - s_all[j]
                mm = round(d.imag / base)
                if abs(d - 1j * mm * base) <= 1e-6 * base:
                    dup = True
                    break
            if not dup:
                taken.append(int(i))
        s_sel, c_sel = s_all[taken], c_all[taken]
    else:
        idx, cen = hm._select(system, s, V, base, 2 * hm._n_dynamic(system))
        idx = idx[np.abs(cen[idx]) <= hm.CENTRAL]
        s_sel, c_sel = s[idx], cen[idx]
    mu = np.exp(hm._fold(s_sel, base) * system.h.grid.period(base))
    order = np.argsort(-np.abs(mu), kind="stable")
    st["t_total"] = time.perf_counter() - t_all
    st["t_arpack_internal"] = st["t_eigs"] - st["t_solve"] - st["t_matvec_other"]
    return mu[order], np.asarray(c_sel)[order], st


VARIANTS = [
    # label, kwargs of sparse_variant, repeats (0: use --repeat)
    ("copy of femodes: SuperLU, 4 shifts Im in [0, w/2], k=12, tol=1e-12", dict(n_shifts=4, k=12), 1),
    ("structured solver, 4 shifts, k=12, tol=1e-12", dict(n_shifts=4, k=12, solver="structured"), 1),
    ("SuperLU, 1 shift at Im 0, k=12, tol=1e-12", dict(im=[0.0], k=12), 0),
    ("SuperLU, 1 shift at Im 0, k=4, tol=1e-8", dict(im=[0.0], k=4, tol=1e-8), 0),
    ("structured, 1 shift at Im 0, k=4, tol=1e-8", dict(im=[0.0], k=4, tol=1e-8, solver="structured"), 0),
    ("structured, 1 shift at Im w, k=4, tol=1e-8", dict(im=[1.0], k=4, tol=1e-8, solver="structured"), 0),
    ("structured, 1 shift at Im w, k=4, tol=1e-8, ncv=10", dict(im=[1.0], k=4, tol=1e-8, ncv=10, solver="structured"), 0),
    ("SuperLU, 4 shifts, k=12, tol=1e-12, re-centred", dict(n_shifts=4, k=12, select="recentre"), 1),
    ("SuperLU, 2 shifts at Im {0, w/2}, k=6, tol=1e-8, re-centred", dict(im=[0.0, 0.5], k=6, tol=1e-8, select="recentre"), 0),
    ("structured, 2 shifts at Im {0, w/2}, k=6, tol=1e-8, re-centred",
     dict(im=[0.0, 0.5], k=6, tol=1e-8, solver="structured", select="recentre"), 0),
    ("SuperLU, 1 shift at Im 0, k=4, tol=1e-8, re-centred (misses a family at H=10, compare table)",
     dict(im=[0.0], k=4, tol=1e-8, select="recentre"), 0),
]


def child_profile(ne: int, H: int, contact: str, repeat: int) -> dict:
    import cProfile
    import io
    import pstats

    import numpy as np
    import scipy.sparse.linalg as spla

    import femodes as fm
    from femodes.hbm import HBMSystem
    from femodes.hbm import hill as hm

    rec: dict = {"kind": "profile", "N": ne, "H": H, "contact": contact}
    model, b, i = branch_and_point(ne, H, contact, rec)
    sol = b[i]
    prof = cProfile.Profile()
    t = time.perf_counter()
    prof.enable()
    r = fm.stability(sol, method=fm.stability_methods.Hill())
    prof.disable()
    rec["t_hill_profiled"] = time.perf_counter() - t
    rec["hill"] = _mu_summary(r.multipliers)
    st = pstats.Stats(prof)
    groups = {"ARPACK internals (znaupd/zneupd)": ("_arpacklib",), "SuperLU solve": ("of 'SuperLU' objects",),
              "SuperLU factorisation (gstrf)": ("gstrf",), "sparse matvecs (J1, J2 products)": ("csc_matvec", "csr_matvec"),
              "sparse adds / conversions": ("csr_plus_csr", "csr_tocsc", "coo_tocsr", "_mul_scalar", "tocsc", "astype"),
              "eigenvector selection (_centroids/_select)": ("_complex_harmonics", "_select", "_centroids")}
    split = {}
    for (fn, line, name), (cc, nc, tt, ct, callers) in st.stats.items():
        label = f"{fn}:{line}({name})" if not fn.startswith("~") else name
        for g, keys in groups.items():
            if any(k in label for k in keys):
                d = split.setdefault(g, [0.0, 0])
                d[0] += tt
                d[1] += nc
                break
    split["total (profiled)"] = [st.total_tt, 0]
    rec["profile_split"] = split
    s = io.StringIO()
    pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(12)
    rec["profile_top"] = s.getvalue()

    # matrix sizes and one factorisation / solve
    system = HBMSystem(model, sol.harmonics)
    y = system.join(sol.Q, sol.P)
    w = float(sol.omega)
    t = time.perf_counter()
    J0, J1, J2 = hm.hill_matrices(system, y, w)
    rec["t_hill_matrices"] = time.perf_counter() - t
    sigma = 1e-3 * w + 0.5j * w / 3
    Js = (J0 + sigma * J1 + sigma * sigma * J2).astype(complex).tocsc()
    t = time.perf_counter()
    lu = spla.splu(Js)
    rec["t_splu_one"] = time.perf_counter() - t
    rec["nnz_J"] = int(Js.nnz)
    rec["nnz_LU"] = int(lu.L.nnz + lu.U.nnz)
    rhs = np.random.default_rng(0).standard_normal(Js.shape[0]) + 0j
    ts = []
    for _ in range(5):
        t = time.perf_counter()
        z = lu.solve(rhs)
        ts.append(time.perf_counter() - t)
    rec["t_superlu_solve"] = _median(ts)
    rec["superlu_relres"] = float(np.max(np.abs(Js @ z - rhs)) / np.max(np.abs(rhs)))
    t = time.perf_counter()
    S = StructuredShift(system, J0, J1, J2, sigma)
    rec["t_structured_factor"] = time.perf_counter() - t
    ts = []
    for _ in range(5):
        t = time.perf_counter()
        z = S.solve(rhs)
        ts.append(time.perf_counter() - t)
    rec["t_structured_solve"] = _median(ts)
    rec["structured_relres"] = float(np.max(np.abs(Js @ z - rhs)) / np.max(np.abs(rhs)))
    del lu, S

    out = []
    for label, kw, reps in VARIANTS:
        reps = reps or repeat
        times, stats = [], []
        for _ in range(reps):
            stv: dict = {}
            mu, cen, stv = sparse_variant(system, J0, J1, J2, w, stats=stv, **kw)
            times.append(stv["t_total"])
            stats.append(stv)
        j = int(np.argmin(np.abs(np.array(times) - _median(times))))
        out.append(dict(label=label, t=times, stats=stats[j], **_mu_summary(mu),
                        lead_centroid=float(cen[0]) if len(cen) else None,
                        moduli=[float(v) for v in np.abs(mu[:6])]))
        log(f"  {label}: {_median(times):.2f} s, {len(mu)} mu, max|mu| {out[-1]['max_abs_mu']}")
    rec["variants"] = out
    return rec


# ----------------------------------------------------------------------------------------------
# parent side
# ----------------------------------------------------------------------------------------------
def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def run_child(mode: str, ne: int, H: int, contact: str, repeat: int, timeout: float):
    env = dict(os.environ)
    for v in THREAD_VARS:
        env[v] = "1"
    cmd = [sys.executable, os.path.abspath(__file__), "--child", mode, str(ne), str(H), contact, str(repeat)]
    t = time.perf_counter()
    try:
        p = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=None, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"kind": mode, "N": ne, "H": H, "contact": contact, "timeout": timeout,
                "child_wall": time.perf_counter() - t}
    for line in p.stdout.splitlines():
        if line.startswith(MARK):
            rec = json.loads(line[len(MARK):])
            rec["child_wall"] = time.perf_counter() - t
            return rec
    return {"kind": mode, "N": ne, "H": H, "contact": contact, "failed": f"exit {p.returncode}",
            "child_wall": time.perf_counter() - t}


def _loadavg() -> str:
    try:
        return " / ".join(f"{x:.2f}" for x in os.getloadavg())
    except (AttributeError, OSError):
        return "unavailable"


def machine_lines(load_start: str) -> list[str]:
    import numpy
    import scipy

    try:
        from importlib.metadata import version

        skfem = version("scikit-fem")
    except Exception:  # pragma: no cover
        skfem = "?"
    import femodes

    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                                text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "femodes"], cwd=REPO, capture_output=True,
                               text=True).stdout.strip()
        commit += " (uncommitted changes in femodes/)" if dirty else " (femodes/ clean)"
    except OSError:
        commit = "unknown"
    try:
        with open("/proc/meminfo") as f:
            mem = f"{int(f.readline().split()[1]) / 2**20:.1f} GiB"
    except (OSError, ValueError, IndexError):
        mem = "?"
    return [
        f"- date: {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}",
        f"- CPU: {cpu_model('unknown')}; logical CPUs: {os.cpu_count()}; memory: {mem}",
        f"- OS: {platform.platform()}",
        f"- python {platform.python_version()}, numpy {numpy.__version__}, scipy {scipy.__version__}, "
        f"scikit-fem {skfem}, femodes {getattr(femodes, '__version__', '?')} at git {commit}",
        "- child processes run with OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=1 (one fresh process per case)",
        f"- load average (1/5/15 min) at start: {load_start}",
    ]


def _f(x, fmt="{:.3f}"):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return fmt.format(x)


def _t(x):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x:.3f}" if x < 10 else f"{x:.1f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000], help="numbers of DOFs (= elements)")
    ap.add_argument("--H", type=int, nargs="+", default=[5, 10], help="numbers of harmonics")
    ap.add_argument("--contacts", nargs="+", default=["penalty", "unilateral"], choices=["penalty", "unilateral"])
    ap.add_argument("--repeat", type=int, default=3, help="repeats of Hill and shooting (Newton: max(repeat, 5))")
    ap.add_argument("--shoot-H", type=int, nargs="*", default=[5], help="H at which shooting runs (N <= 500)")
    ap.add_argument("--no-shooting", action="store_true")
    ap.add_argument("--shoot-timeout", type=float, default=300.0, help="seconds; the shooting child is killed after")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per other child")
    ap.add_argument("--compare-H", type=int, nargs="*", default=[5],
                    help="H of the dense vs shift-invert comparison at N = 100 (10: dense at 2100-2121 unknowns, ~45 s each)")
    ap.add_argument("--profile-N", type=int, default=10000, help="size of the Hill profile, penalty (0: none)")
    ap.add_argument("--profile-unilateral-N", type=int, default=1000,
                    help="size of the same profile and variants for the unilateral contact (0: none)")
    ap.add_argument("--quick", action="store_true", help="N = 100, 1000; H = 5; no shooting; profile at N = 1000")
    ap.add_argument("--json", help="write the raw records to this file")
    ap.add_argument("--child", nargs=5, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)

    if a.child:
        mode, ne, H, contact, rep = a.child[0], int(a.child[1]), int(a.child[2]), a.child[3], int(a.child[4])
        fn = {"case": child_case, "shoot": child_shoot, "compare": child_compare, "profile": child_profile}[mode]
        rec = fn(ne, H, contact, rep)
        print(MARK + json.dumps(rec))
        return 0

    if a.quick:
        a.sizes, a.H, a.no_shooting, a.profile_N, a.profile_unilateral_N = [100, 1000], [5], True, 1000, 1000
    t_all = time.perf_counter()
    load_start = _loadavg()
    cases, shoots, compares, profiles = [], {}, [], []
    for contact in a.contacts:
        for ne in a.sizes:
            for H in a.H:
                log(f"case {contact} N={ne} H={H} ...")
                cases.append(run_child("case", ne, H, contact, a.repeat, a.timeout))
                if not a.no_shooting and ne <= 500 and H in a.shoot_H:
                    log(f"shooting {contact} N={ne} H={H} (timeout {a.shoot_timeout:.0f} s) ...")
                    shoots[(contact, ne, H)] = run_child("shoot", ne, H, contact, a.repeat, a.shoot_timeout)
    for contact in a.contacts:
        for H in a.compare_H:
            log(f"compare dense / shift-invert {contact} N=100 H={H} ...")
            compares.append(run_child("compare", 100, H, contact, a.repeat, a.timeout))
    for contact, n_prof in (("penalty", a.profile_N), ("unilateral", a.profile_unilateral_N)):
        if n_prof and contact in a.contacts:
            log(f"profile N={n_prof} H=5 {contact} ...")
            profiles.append(run_child("profile", n_prof, 5, contact, a.repeat, a.timeout))

    out = ["## femodes benchmark: stability (Floquet multipliers) of one periodic solution vs the solution", ""]
    out += machine_lines(load_start)
    out.append(f"- load average at end: {_loadavg()}")
    out.append(f"- command: {' '.join([os.path.basename(sys.executable)] + [os.path.relpath(__file__, REPO)] + sys.argv[1:])}")
    out += ["", f"Clamped P1 bar, beta = {BETA}, tip force {FORCE} cos(w t), stop at gap {GAP}; point: deepest contact "
            f"of a {MAX_POINTS}-point `frequency_response` on {WINDOW}. Times in s, medians; "
            "ratios to (a1) and, in brackets, to (a2).", ""]
    hdr = ("| contact | N | H | unknowns | w | (a1) point: Newton [s] (its) | (a2) point: cont. [s] (its) | (b) Hill [s] (first call) | Hill path "
           "| #mu | max abs(mu) Hill | (b)/(a1) [(b)/(a2)] | (c) shooting [s] | (c)/(a1) [(c)/(a2)] | max abs(mu) shooting "
           "| peak RSS [MiB] |")
    out += [hdr, "|" + "|".join(["---"] * (hdr.count("|") - 1)) + "|"]
    for r in cases:
        if "timeout" in r or "failed" in r:
            out.append(f"| {r['contact']} | {r['N']} | {r['H']} | " + " | ".join(["-"] * 12)
                       + f" | {'timeout' if 'timeout' in r else r['failed']} |")
            continue
        tn = _median(r["t_newton"])
        tc = r["t_per_point_cont"]
        # the first call builds the Craig-Bampton reduction of large models (cached on the model);
        # the next ones are what each further point of a branch costs
        th = _median(r["t_hill"][1:]) if len(r["t_hill"]) > 1 else r["t_hill"][0]
        th_first = r["t_hill"][0]
        sh = shoots.get((r["contact"], r["N"], r["H"]))
        if r["N"] > 500:
            c_t, c_ratio, c_mu = "refused (> 500 DOFs)", "-", "-"
        elif sh is None:
            c_t, c_ratio, c_mu = "not run", "-", "-"
        elif "timeout" in sh:
            c_t, c_ratio, c_mu = f"> {sh['timeout']:.0f} (killed)", f"> {sh['timeout'] / tn:.0f}", "-"
        elif sh.get("shooting_error"):
            c_t = f"failed after {sh['t_shooting'][0]:.1f}: {sh['shooting_error'][:90]}"
            c_ratio, c_mu = "-", "-"
        else:
            ts = _median(sh["t_shooting"])
            c_t = f"{_t(ts)} (R={len(sh['t_shooting'])}, {sh.get('shoot_nit', '?')} Newton its)"
            c_ratio = f"{ts / tn:.0f} [{ts / tc:.0f}]"
            c_mu = f"{sh['shooting']['max_abs_mu']:.5f} (orbit corr. {sh['shooting']['orbit_correction']:.2f})"
        out.append(
            f"| {r['contact']} | {r['N']} | {r['H']} | {r['n_unknowns']} | {r['omega']:.4f} | {_t(tn)} ({r['newton_nit'][0]}) "
            f"| {_t(tc)} ({r['cont_nit_mean']:.1f}) | {_t(th)} (first {_t(th_first)}) | {r['hill_path']} | {r['hill']['n_mu']} | {_f(r['hill']['max_abs_mu'], '{:.5f}')} "
            f"| {th / tn:.1f} [{th / tc:.1f}] | {c_t} | {c_ratio} | {c_mu} | {r['peak_rss_mib']:.0f} |")
    out += ["", f"(a1) Newton at fixed w from x_i (1 + {PERTURBATION:g} xi): converged in all rows unless marked. "
            "(a2) includes the tangent and the corrector iterations of the continuation (its per point: `nit` of the branch). #mu = multipliers returned by Hill "
            "(dense: all 2 x (DOFs with mass); shift-invert: those it keeps near the stability boundary)."]
    bad = [r for r in cases if "t_newton" in r and not r["newton_success"]]
    for r in bad:
        out.append(f"- Newton did NOT converge: {r['contact']} N={r['N']} H={r['H']} (residual {r['newton_residual']:.1e})")

    if compares:
        out += ["", "### Dense vs shift-invert Hill at N = 100 (same point)", ""]
        hdr = "| contact | H | unknowns | path | time [s] | #mu | max abs(mu) | rel. diff. to dense | centroid of the leading exponent |"
        out += [hdr, "|" + "|".join(["---"] * (hdr.count("|") - 1)) + "|"]
        for c in compares:
            if "timeout" in c or "failed" in c:
                out.append(f"| {c['contact']} | {c['H']} | - | {'timeout' if 'timeout' in c else c['failed']} | | | | | |")
                continue
            for key, label in (("dense", "dense (femodes)"), ("sparse_default", "shift-invert, femodes defaults"),
                               ("sparse_test", "shift-invert, n_shifts=6, k_per_shift=24"),
                               ("sparse_shift_at_w", "bench variant: 1 shift at Im = w, k=4, tol 1e-8"),
                               ("sparse_family", "bench variant: 2 shifts at Im {0, w}, k=4, tol 1e-8, family-aware selection"),
                               ("sparse_recentre", "bench variant: 1 shift at Im 0, k=4, tol 1e-8, re-centred"),
                               ("sparse_default_recentre", "bench variant: femodes' 4 shifts, k=12, tol 1e-12, re-centred"),
                               ("sparse_cheap_recentre", "bench variant: 2 shifts at Im {0, w/2}, k=6, tol 1e-8, re-centred")):
                v = c[key]
                out.append(f"| {c['contact']} | {c['H']} | {c['n_unknowns']} | {label} | {_t(_median(v['t']))} | {v['n_mu']} "
                           f"| {_f(v['max_abs_mu'], '{:.6f}')} | {_f(v.get('rel_diff_max_abs_mu'), '{:+.1e}')} "
                           f"| {_f(v.get('lead_centroid'), '{:+.3f}')} |")
        for c in compares:
            if "dense_pieces" in c:
                p = c["dense_pieces"]
                out.append(f"\nDense path pieces ({c['contact']}, H={c['H']}, eigenproblem of order {p['order']}): LU "
                           f"{p['lu']:.2f} s, LU solve with {p['order']} right-hand sides {p['lu_solve']:.2f} s, "
                           f"`scipy.linalg.eig` with vectors {p['eig_with_vectors']:.2f} s (eigenvalues only: "
                           f"{p['eigvals_only']:.2f} s).")
            if "dense_spectrum_near_lead" in c:
                sp_ = ", ".join(f"{re_:.5f}{im_:+.4f}i (c={cc:+.2f})" for re_, im_, cc in c["dense_spectrum_near_lead"][:6])
                out.append(f"\nDense Hill eigenvalues near the leading exponent ({c['contact']}, H={c['H']}), by "
                           f"increasing abs(centroid): {sp_}")

    for profile in profiles:
        out += ["", f"### Where the shift-invert Hill time goes (N = {profile['N']}, H = {profile['H']}, {profile['contact']})", ""]
        if "timeout" in profile or "failed" in profile:
            out.append("profile child: " + ("timeout" if "timeout" in profile else profile["failed"]))
        else:
            p = profile
            out.append(f"`fm.stability(sol, 'hill')` under cProfile: {p['t_hill_profiled']:.2f} s, "
                       f"{p['hill']['n_mu']} multipliers, max abs(mu) {p['hill']['max_abs_mu']:.6f}. "
                       f"Hill matrix: {p['n_unknowns']} unknowns, nnz(J(sigma)) = {p['nnz_J']}, nnz(L+U) = {p['nnz_LU']}.")
            out += ["", "| part | self time [s] | calls |", "|---|---|---|"]
            for g, (tt, nc) in sorted(p["profile_split"].items(), key=lambda kv: -kv[1][0]):
                out.append(f"| {g} | {tt:.2f} | {nc or ''} |")
            out.append(f"\nOne complex SuperLU factorisation of J(sigma): {p['t_splu_one']:.3f} s, one solve "
                       f"{p['t_superlu_solve'] * 1e3:.1f} ms (rel. residual {p['superlu_relres']:.0e}); the experimental "
                       f"structured solver: factorisation {p['t_structured_factor']:.3f} s, solve "
                       f"{p['t_structured_solve'] * 1e3:.1f} ms (rel. residual {p['structured_relres']:.0e}); "
                       f"`hill_matrices` {p['t_hill_matrices']:.3f} s.")
            out += ["", "Benchmark-local variants of the shift-invert solve (same Hill matrices; medians):", "",
                    "| variant | time [s] | factorisations [s] (count) | solves [s] (count) | J1/J2 products + copies [s] "
                    "| ARPACK internals [s] | #mu | max abs(mu) | centroid of leading |",
                    "|---|---|---|---|---|---|---|---|---|"]
            for v in p["variants"]:
                s_ = v["stats"]
                out.append(f"| {v['label']} | {_t(_median(v['t']))} | {s_['t_factor']:.2f} ({s_['n_factor']}) | {s_['t_solve']:.2f} ({s_['n_solve']}) "
                           f"| {s_['t_matvec_other']:.2f} | {s_['t_arpack_internal']:.2f} | {v['n_mu']} "
                           f"| {_f(v['max_abs_mu'], '{:.6f}')} | {_f(v['lead_centroid'], '{:+.3f}')} |")
            out += ["", "cProfile, top entries by self time:", "", "```", p["profile_top"].strip(), "```"]

    out += ["", f"Total benchmark wall time: {time.perf_counter() - t_all:.0f} s"]
    print("\n".join(out))
    if a.json:
        os.makedirs(os.path.dirname(os.path.abspath(a.json)), exist_ok=True)
        with open(a.json, "w") as f:
            json.dump({"cases": cases, "shooting": [dict(v) for v in shoots.values()], "compare": compares,
                       "profiles": profiles}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
