#!/usr/bin/env python
"""Scale of meshed solids (issue 15, item 6): time and peak memory of every stage of a contact
analysis against the number of DOFs, for a 2-D strip and a 3-D box with a stop on the tip face.

Run from the repository root::

    python3 benchmarks/bench_solids_scale.py                      # everything (hours; resumable)
    python3 benchmarks/bench_solids_scale.py --geometry strip2d --max-dofs 1e5
    python3 benchmarks/bench_solids_scale.py --stages assembly,modes --timeout 1800
    python3 benchmarks/bench_solids_scale.py --report             # tables + fits of the saved runs
    python3 benchmarks/bench_solids_scale.py --report --before benchmarks/results_solids_scale_before.json
                                                                   # + before/after of the block ordering

This is a script, not a pytest test. Raw results: ``benchmarks/results_solids_scale.json``
(rewritten after every run, so an interrupted study keeps what it measured; a rerun skips the
runs already there unless ``--force``); tables and conclusions: ``benchmarks/README_solids_scale.md``.

Models (the case files of ``femodes run``, :func:`case_text`; E = rho = 1, nu = 0.3, clamped on
"left", Rayleigh ``beta = 0.02``, a rigid stop 0.01 in front of the tip face "right": one
complementarity contact per node, normal +x; an axial force spread over the tip face whose static
tip displacement is 0.004, so the first axial mode (w ~ pi/2) hits the stop):

strip2d  plane-stress strip 1 x 0.1, Q1 quadrilaterals, nx = 10 ny (square elements), size = ny;
         N ~ 20 ny^2, ny + 1 contact nodes.
box3d    box 1 x 0.1 x 0.1, P2 tetrahedra (``box_mesh`` cells split in 6), nx = 10 n, ny = nz = n,
         size = n; N ~ 240 n^3, (2 n + 1)^2 contact nodes (vertices and mid-side nodes).

Stages, each in its own child process (this file re-invoked with ``--child``; ``OPENBLAS_NUM_THREADS
= OMP_NUM_THREADS = 1``; resident memory limited to ``--mem-gib`` (10 GiB): a watchdog thread of the
driver sums the RSS of all its descendant processes every 0.1 s and kills them above the limit, the
run being recorded as ``MemoryError: RSS > 10 GiB`` so that a stage that does not fit fails instead
of swapping the shared machine), timed with
``time.perf_counter``, repeated while the repeats fit in ``--budget`` seconds (median reported):

assembly   ``fm.solid`` (mesh + scikit-fem assembly of K, M) and the contact/force/damping
           declarations (``with_contact`` expands the law to one contact per node and
           redistributes the mass of the contact nodes). The models are then pickled to
           ``--cache`` and the next stages of that size load them (so their peak memory is the
           model's plus the stage's, not the assembly's transient); the file is removed after the
           last stage of the size.
modes      ``fm.linear_modes(model, 6)`` of the model without contact (ARPACK shift-invert at 0 on
           SuperLU of K, what femodes does above 400 DOFs).
cb         ``fm.craig_bampton(model, n_modes=20)`` of the contact model (kept: the contact DOFs,
           which carry the force too).
floor:V    one harmonic block ``Z = K_II - (k w)^2 M_II + i k w C_II`` of the HBM (interior DOFs:
           all but the contact DOFs, k w = 1.5) factorised by variant V, then solved for one
           right-hand side and for the ``n_b`` condensation columns ``Z_II^-1 Z_Ib`` (what
           ``femodes.hbm.linsolve.LinearFactors`` does per harmonic):
           ``femodes``   ``BlockLU`` as femodes chooses: LAPACK band LU after RCM when
                         ``(3 kl + 1) n_I <= BAND_MAX_FILL nnz``, else SuperLU with
                         ``linsolve.SUPERLU_OPTIONS`` on the RCM order. Since the change
                         recorded in ``README_solids_scale.md`` ``BAND_MAX_FILL = 7`` and
                         ``MMD_AT_PLUS_A``, ``SymmetricMode``, ``diag_pivot_thresh = 0.1``;
                         before, 50 and COLAMD (those runs are kept in
                         ``results_solids_scale_before.json``; every run stores the SHA-1 of
                         ``linsolve.py`` it measured, under ``code``);
           ``band``      LAPACK ``zgbtrf`` after RCM, forced (skipped above 2 GiB of band storage);
           ``colamd``    SuperLU, COLAMD column ordering of the RCM-ordered matrix, forced;
           ``mmd``       SuperLU, ``MMD_AT_PLUS_A``, ``SymmetricMode``, ``diag_pivot_thresh = 0.01``;
           ``nd``        geometric nested dissection (:func:`nested_dissection`) then SuperLU
                         ``NATURAL``, ``SymmetricMode``, ``diag_pivot_thresh = 0.01``.
           Fill = entries SuperLU stores for L and U (``SuperLU.nnz``, supernodes included; not
           ``L.nnz + U.nnz``, whose copies alone exceed the memory limit at 5e5 DOFs) / nnz(Z)
           (band: its LAPACK storage (3 kl + 1) n_I / nnz(Z)).
hbm_setup  ``fm.ForcedResponseProblem(model, fm.Harmonics(5))`` of the full contact model. Its
           ``HBMSystem`` computes the default complementarity constant of every contact,
           ``c = 1 / (K^-1)_dd``, by ``femodes.hbm.system.default_contact_parameters``: ONE SuperLU
           factorisation of K (default COLAMD) for all contacts, then solves with their unit columns
           in blocks of 256; the rest of the setup (CSR copies of M, K, C, the harmonic operators)
           is small beside it. ``onelu_s`` is the script's own version of the same computation (one
           ``splu(K)``, one solve with all n_c columns) and ``onelu_max_rel_diff`` its largest
           relative difference from femodes' constants (0 to 4e-15), so ``time_s ~ onelu_s``.
           Runs made before commit 45e8d54 (one factorisation of K per contact) have
           ``time_s >> onelu_s``; all sizes were rerun after it.
hbm_full, hbm_cb
           ``femodes scaling``'s own child (:func:`femodes.app.scaling.child.run_child`) on the
           case file at H = 5, without and with ``[reduction] craig_bampton = 20``:
           ``fm.frequency_response`` over w = [1.5, 2.5] capped at ``--points`` points (per point =
           wall time / points; the start at w = 1.5 is in contact), then Newton iterations
           (residual + ``default_linear_solver``) at the point of largest contact force.

Issue 38 (item 3) added, all timed in CPU time (``time.process_time``) as well as wall time, the
machine being shared:

cb_floor:V what back-end V (``cholmod``, ``mumps``) itself costs for the work of ``cb`` on the same
           matrices, called directly: factorisation of ``K_II``, solve with the ``n_b`` columns of
           ``K_IB``, ARPACK shift-invert for 20 modes with the factor as ``OPinv`` (:func:`_cb_floor`).
hbm_iter   full HBM (H = 5): setup, then Newton iterations (residual + linear solve) at frequencies
           shifted by 1 % so that every block is factorised again (:func:`_hbm_iter`).
block_floor MUMPS alone on one complex harmonic block: factorisation + ``n_b`` solves + Schur
           complement, and the same Schur complement by MUMPS' Schur option (:func:`_block_floor`).
pipeline   mesh, assembly, contact declaration and Craig-Bampton in one process, each stage with its
           own peak RSS (:func:`pipeline`; contacts on a pad of the tip face, :func:`pad_box`).

``--report --issue38`` prints their tables (``README_solids_scale.md``, issue 38 section).

Memory limit. Until the block-ordering change the limit was ``RLIMIT_AS`` (address space, the runs
in ``results_solids_scale_before.json``). That is unfair to SuperLU: each ``splu`` keeps the
storage SuperLU reserved for L and U, about 30 x nnz(A) entries (``sp_ienv(6)``) whatever the fill,
most of it never touched (strip2d size 40: +656 MiB of address space, +72 MiB resident per
factorisation), so the 12 factorisations alive in a full-HBM Newton step (6 harmonics, old and new
frequency) exhausted 10 GiB of address space at 2 GiB resident. The band storage is all touched,
so the old limit was a resident limit for the band runs. ``--as-gib X`` restores an address-space
limit.

A stage that fails or times out at one size is skipped at the larger ones, and so is a stage whose
time, extrapolated from the last two sizes, would exceed the timeout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results_solids_scale.json"

GEOMETRIES = {
    # size lists: N doubles roughly from step to step, ~1e3 to ~1e6
    "strip2d": [7, 10, 14, 20, 28, 40, 57, 80, 113, 160, 226],
    "box3d": [1, 2, 3, 4, 5, 6, 8, 10, 12, 14, 16],
    # the pipeline only: a blade-like plate 1 x 0.2 x 0.02 of P2 tetrahedra, nx = 5 n, ny = n, nz = 4
    "plate3d": [10, 20, 30, 44],
}
STAGES = ("assembly", "modes", "cb", "floor:femodes", "floor:band", "floor:colamd", "floor:mmd", "floor:nd",
          "hbm_setup", "hbm_full", "hbm_cb", "cb_floor:cholmod", "cb_floor:mumps", "hbm_iter", "block_floor", "pipeline")
H = 5
CB_MODES = 20
OMEGA_BLOCK = 1.5  # k w of the factorised block: near the first axial mode, above the first bending ones
BAND_MAX_BYTES = 2 * 2**30


# ---------------------------------------------------------------------------------------------
# The models, as case files
# ---------------------------------------------------------------------------------------------
def case_text(geometry: str, size: int, *, reduced: bool = False, harmonics: int = H) -> str:
    """The case file of ``geometry`` at ``size`` (module docstring)."""
    if geometry == "strip2d":
        mesh = f"length = 1.0\nheight = 0.1\nnx = {10 * size}\nny = {size}\nquad = true"
        model = 'plane = "stress"\nthickness = 1.0\norder = 1'
        direction, amplitude = "[1.0, 0.0]", 0.1 * 0.004  # E A u / L with A = 0.1 x 1
    elif geometry == "box3d":
        mesh = f"length = 1.0\nwidth = 0.1\nheight = 0.1\nnx = {10 * size}\nny = {size}\nnz = {size}"
        model = "order = 2"
        direction, amplitude = "[1.0, 0.0, 0.0]", 0.01 * 0.004
    else:
        raise ValueError(f"unknown geometry {geometry!r}; known: {', '.join(GEOMETRIES)}")
    reduction = f"\n[reduction]\ncraig_bampton = {CB_MODES}\n" if reduced else ""
    return f"""[mesh]
{mesh}

[model]
kind = "solid"
E = 1.0
rho = 1.0
nu = 0.3
clamped = "left"
{model}

[damping]
beta = 0.02

[[contact]]
at = "right"
direction = {direction}
gap = 0.01

[[force]]
at = ["right", "u_x"]
amplitude = {amplitude!r}
{reduction}
[analysis]
type = "frequency_response"
omega = [1.5, 2.5]
harmonics = {harmonics}
"""


def expected_dofs(geometry: str, size: int) -> int:
    """Free DOFs of the model (the clamped face removed), for the tables before a run."""
    if geometry == "strip2d":
        return 2 * 10 * size * (size + 1)
    if geometry == "plate3d":
        return 3 * 10 * size * (2 * size + 1) * 9
    return 3 * 20 * size * (2 * size + 1) ** 2


# ---------------------------------------------------------------------------------------------
# Child: one stage of one size
# ---------------------------------------------------------------------------------------------
def _rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _repeat(fn, budget: float, repeat: int):
    """Run ``fn`` once, then again while the repeats fit in ``budget`` seconds (at most ``repeat``);
    the median time, all times and the last result."""
    times, out = [], None
    while True:
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
        if len(times) >= repeat or sum(times) + times[-1] > budget:
            break
    return statistics.median(times), times, out


def _models(geometry: str, size: int, rec: dict):
    """(plain solid with damping, the same with contact and force) built by the case-file path."""
    from femodes.app import cases

    case = cases.parse_case(case_text(geometry, size), f"{geometry}_{size}.toml")
    api = cases._Api(case)
    t = time.perf_counter()
    solid = cases._fe_model(case, api)
    rec["assembly_solid_s"] = time.perf_counter() - t
    t = time.perf_counter()
    plain = cases._add_damping(case, api, solid)
    model = cases._add_forces(case, api, cases._add_contacts(case, api, plain))
    rec["assembly_contact_s"] = time.perf_counter() - t
    rec.update(N=int(model.n_dofs), nnz_K=int(model.K.nnz), n_contacts=len(model.contacts))
    return plain, model


def nested_dissection(A, X, leaf: int = 64):
    """Geometric nested dissection of the graph of ``A`` (square sparse) with vertex coordinates
    ``X`` (dim, n): split at the median of the widest coordinate, the vertices of the lower half
    adjacent to the upper half are the separator (numbered last), recurse. A permutation."""
    import numpy as np

    A = A.tocsr()
    out = []
    stack = [(np.arange(A.shape[0]), 0)]
    # iterative post-order: (left, right, separator) with the separator after both halves
    while stack:
        idx, state = stack.pop()
        if state == 1:
            out.append(idx)
            continue
        if idx.size <= leaf:
            out.append(idx)
            continue
        c = X[:, idx]
        ax = int(np.argmax(np.ptp(c, axis=1)))
        low = c[ax] < np.median(c[ax])
        if low.all() or not low.any():
            out.append(idx)
            continue
        left, right = idx[low], idx[~low]
        s = np.diff(A[left][:, right].indptr) > 0
        sep, left = left[s], left[~s]
        # pushed in reverse: left, right, then the separator
        stack.append((sep, 1))
        stack.append((right, 0))
        stack.append((left, 0))
    p = np.concatenate(out)
    assert np.unique(p).size == A.shape[0]
    return p


def _block(model):
    """The interior block of one harmonic and what its variants need."""
    import numpy as np
    import scipy.sparse as sp

    from femodes.hbm.linsolve import build_pattern

    bd = np.array(sorted({c.dof for c in model.contacts}))
    t = time.perf_counter()
    pat = build_pattern(model.M, model.K, model.C, bd)
    pattern_s = time.perf_counter() - t
    a, b = OMEGA_BLOCK ** 2, OMEGA_BLOCK
    vals = pat.II.harmonic(OMEGA_BLOCK)
    nI = pat.perm.size
    Z_rcm = sp.csc_matrix((vals, (pat.rows, pat.cols)), shape=(nI, nI))
    # condensation columns Z_II^-1 Z_Ib (in the RCM order of Z_rcm)
    inv = np.empty(nI, dtype=int)
    inv[pat.perm] = np.arange(nI)
    Zib = pat.Ib.harmonic(OMEGA_BLOCK)
    cols = np.zeros((nI, bd.size), dtype=complex)
    cols[inv[pat.R]] = Zib
    return pat, (a, b), Z_rcm, cols, pattern_s


def _dof_coordinates(model):
    import numpy as np

    fe = model.fe
    X = np.zeros((fe.dim, fe.n_full))
    for c in range(fe.nodal.shape[0]):
        X[:, fe.nodal[c]] = fe.node_coordinates
    return X[:, fe.free]


def _floor(model, variant: str, rec: dict, budget: float, repeat: int) -> None:
    import numpy as np
    import scipy.sparse.linalg as spla

    from femodes.hbm.linsolve import BlockLU

    pat, (a, b), Z, cols, rec["pattern_s"] = _block(model)
    nI = Z.shape[0]
    rec.update(n_interior=int(nI), nnz_block=int(Z.nnz), kl=int(pat.kl), femodes_banded=bool(pat.banded),
               n_b=int(cols.shape[1]))
    rhs = np.random.default_rng(0).standard_normal((nI, 1)) + 0j
    band_bytes = 16 * (3 * pat.kl + 1) * nI
    if variant in ("femodes", "band"):
        if variant == "band" and band_bytes > BAND_MAX_BYTES:
            raise MemoryError(f"band storage {band_bytes / 2**30:.1f} GiB > {BAND_MAX_BYTES / 2**30:.0f} GiB (kl={pat.kl})")
        if variant == "band":
            pat.banded = True
        from femodes.hbm.linsolve import BlockSolverOptions

        opts = BlockSolverOptions().superlu_options
        rec["path"] = (f"LAPACK band LU, kl={pat.kl}" if pat.banded else
                       f"SuperLU {opts.get('permc_spec', 'COLAMD')} on the RCM order")
        med, times, lu = _repeat(lambda: BlockLU(pat, b), budget, repeat)
        # BlockLU takes and returns the original interior order
        perm = pat.perm
        rhs_o = np.empty_like(rhs)
        rhs_o[perm] = rhs
        cols_o = np.empty_like(cols)
        cols_o[perm] = cols

        def solve1():
            return lu.solve(rhs_o)

        def solve_b():
            return lu.solve(cols_o)
        if pat.banded:
            rec["fill"] = (3 * pat.kl + 1) * nI / Z.nnz
        else:
            # SuperLU says how many entries its factors hold; the other back-ends do not here
            rec["fill"] = lu.factor.nnz / Z.nnz if lu.factor.nnz is not None else None
            rec["backend"] = lu.factor.backend
        x = solve1()[perm]
    else:
        if variant == "colamd":
            A, kw = Z, dict(permc_spec="COLAMD")
        elif variant == "mmd":
            A, kw = Z, dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01, options=dict(SymmetricMode=True))
        elif variant == "nd":
            X = _dof_coordinates(model)[:, pat.interior][:, pat.perm]  # coordinates in the order of Z
            t = time.perf_counter()
            p = nested_dissection(Z, X)
            rec["ordering_s"] = time.perf_counter() - t
            A = Z[p][:, p].tocsc()
            rhs, cols = rhs[p], cols[p]
            kw = dict(permc_spec="NATURAL", diag_pivot_thresh=0.01, options=dict(SymmetricMode=True))
        else:
            raise ValueError(f"unknown floor variant {variant!r}")
        rec["path"] = f"SuperLU {kw['permc_spec']}" + (" SymmetricMode" if "options" in kw else "")
        med, times, lu = _repeat(lambda: spla.splu(A, **kw), budget, repeat)
        rec["fill"] = lu.nnz / A.nnz

        def solve1():
            return lu.solve(rhs)

        def solve_b():
            return lu.solve(cols)
        x = solve1()
        Z = A
    rec["factor_s"], rec["factor_times"] = med, times
    rec["residual"] = float(np.linalg.norm(Z @ x - rhs) / np.linalg.norm(rhs))
    rec["solve1_s"] = _repeat(solve1, budget / 4, repeat)[0]
    rec["solve_nb_s"] = _repeat(solve_b, budget / 4, repeat)[0]
    rec["block_s"] = rec["factor_s"] + rec["solve_nb_s"]  # one harmonic of LinearFactors


def _cached_models(spec: dict, rec: dict, *, write: bool = False):
    """The models of ``spec``'s size: loaded from the cache if there, else built (and written)."""
    import pickle

    path = Path(spec["cache"]) / f"{spec['geometry']}_{spec['size']}.pkl"
    if not write and path.is_file():
        t = time.perf_counter()
        with open(path, "rb") as fh:
            plain, model, built = pickle.load(fh)
        rec.update(built, model_load_s=time.perf_counter() - t)
        return plain, model
    built: dict = {}
    plain, model = _models(spec["geometry"], spec["size"], built)
    rec.update(built)
    if write:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        with open(tmp, "wb") as fh:
            pickle.dump((plain, model, built), fh, protocol=5)
        os.replace(tmp, path)
    return plain, model


def _hbm_setup(model, rec: dict, budget: float, repeat: int) -> None:
    import numpy as np
    import scipy.sparse.linalg as spla

    import femodes as fm

    med, times, pr = _repeat(lambda: fm.ForcedResponseProblem(model, fm.Harmonics(H)), budget, repeat)
    rec.update(time_s=med, times=times)
    dofs = np.array([c.dof for c in pr.system.unilateral])
    c_femodes = np.array([c.c for c in pr.system.unilateral])

    def one_lu():
        E = np.zeros((model.n_dofs, dofs.size))
        E[dofs, np.arange(dofs.size)] = 1.0
        X = spla.splu(model.K.tocsc()).solve(E)
        return 1.0 / X[dofs, np.arange(dofs.size)]
    med, _, c1 = _repeat(one_lu, budget, repeat)
    rec["onelu_s"] = med
    rec["onelu_max_rel_diff"] = float(np.max(np.abs(c1 / c_femodes - 1.0)))


def _cpu_wall(fn):
    """``(result, wall s, CPU s of this process)`` of ``fn()``."""
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


#: Right-hand sides per solve in the floor's ``n_b`` solves: 637 columns of a 7.9e4-DOF ``K_II``
#: took 3.9-4.7 s in blocks of 106-320 and 5.3-7.3 s at once, under CHOLMOD and MUMPS alike.
FLOOR_SOLVE_COLUMNS = 128


def _cb_floor(model, backend: str, rec: dict, repeat: int) -> None:
    """What the back-end itself costs for the work of ``fm.craig_bampton(model, CB_MODES)`` on the
    same matrices: factorisation of ``K_II`` (analysis included), the solve with the ``n_b``
    columns of ``K_IB`` (in blocks of :data:`FLOOR_SOLVE_COLUMNS`), and ARPACK shift-invert at 0
    for the ``CB_MODES`` lowest modes of ``(K_II, M_II)`` with the factor's solve as ``OPinv``
    (femodes' settings: ``tol=1e-12``). The
    library is called directly (scikit-sparse's ``cholesky``, python-mumps' ``Context``), without
    femodes' checks, copies or projections; extracting ``K_II``, ``K_IB``, ``M_II`` is not timed."""
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from femodes import reduction

    kept = reduction.kept_dofs(model)
    interior = np.setdiff1d(np.arange(model.n_dofs), kept)
    K, M = model.K.tocsr(), model.M.tocsr()
    KII = K[interior][:, interior].tocsc()
    MII = M[interior][:, interior].tocsc()
    KIB = np.asfortranarray(K[interior][:, kept].toarray())
    rec.update(n_interior=int(interior.size), n_b=int(kept.size), backend=backend)
    if backend == "cholmod":
        from sksparse.cholmod import cholesky

        def factor():
            f = cholesky(KII)
            return lambda b: f(np.asfortranarray(b)), f
    elif backend == "mumps":
        import mumps

        def factor():
            ctx = mumps.Context()
            ctx.set_matrix(sp.triu(KII, format="coo"), symmetric=True)
            ctx.factor(ordering="pord")
            return ctx.solve, ctx
    else:
        raise ValueError(f"unknown cb_floor back-end {backend!r}")
    def once():  # one repeat; its factor is freed on return
        (solve, _keep), tf, cf = _cpu_wall(factor)
        # in blocks of FLOOR_SOLVE_COLUMNS right-hand sides: the libraries' supernodal solves run
        # faster so than on all n_b columns at once (README_backends.md)
        _psi, ts, cs = _cpu_wall(lambda: [-solve(KIB[:, c:c + FLOOR_SOLVE_COLUMNS])
                                          for c in range(0, KIB.shape[1], FLOOR_SOLVE_COLUMNS)])
        op = spla.LinearOperator(KII.shape, matvec=solve, dtype=float)
        (lam, _), te, ce = _cpu_wall(lambda: spla.eigsh(KII, k=CB_MODES, M=MII, sigma=0.0, which="LM", OPinv=op,
                                                         tol=1e-12, maxiter=max(500, 50 * CB_MODES)))
        r = dict(factor_s=tf, factor_cpu_s=cf, solve_nb_s=ts, solve_nb_cpu_s=cs, eigen_s=te, eigen_cpu_s=ce)
        r["time_s"], r["cpu_s"] = tf + ts + te, cf + cs + ce
        return r, lam

    best = None
    for _ in range(repeat):
        r, lam = once()
        rec.setdefault("repeats", []).append(r)
        if best is None or r["cpu_s"] < best["cpu_s"]:
            best = r
    for k in best:  # the repeat of least CPU time
        rec[k] = best[k]
    rec["interface_omega_1"] = float(np.sqrt(np.sort(lam)[0]))


def _block_floor(model, rec: dict, repeat: int) -> None:
    """What MUMPS itself costs for the harmonic blocks of one full-HBM Newton iteration (CPU time):
    the complex block ``Z = K - (k w)^2 M + i k w C`` at k w = ``OMEGA_BLOCK`` on the interior
    (all DOFs but the contact DOFs) factorised (``LDL^T``, PORD, as ``femodes.sparse_direct``) and
    solved with its ``n_b`` condensation columns plus the Schur complement ``Z_BB - Z_BI W``
    (``factor_solve``); and the same Schur complement by MUMPS' own Schur option on the whole
    block (``Context.schur``: no column solves), with its largest difference from the first.
    The real block of harmonic 0 (``K_II``) is the ``cb_floor`` factorisation and ``n_b`` solve."""
    import numpy as np
    import scipy.sparse as sp

    import mumps

    from femodes import reduction

    bd = reduction.kept_dofs(model)
    interior = np.setdiff1d(np.arange(model.n_dofs), bd)
    a, b = OMEGA_BLOCK ** 2, OMEGA_BLOCK
    Zf = (model.K - a * model.M + 1j * b * model.C).tocsr()
    ZI = Zf[interior]
    Z, ZIB = ZI[:, interior].tocsc(), ZI[:, bd].toarray()
    del ZI
    ZB = Zf[bd]
    ZBB, ZBI = ZB[:, bd].toarray(), ZB[:, interior].tocsr()
    Zc = sp.triu(Zf, format="coo")
    rec.update(n_interior=int(interior.size), n_b=int(bd.size), backend="mumps")

    def factor_solve():
        ctx = mumps.Context()
        ctx.set_matrix(sp.triu(Z, format="coo"), symmetric=True)
        ctx.factor(ordering="pord")
        return ZBB - ZBI @ ctx.solve(ZIB)

    def schur():
        ctx = mumps.Context()
        ctx.set_matrix(Zc, symmetric=True)
        S = ctx.schur(bd, ordering="pord")
        return np.tril(S) + np.tril(S, -1).T  # MUMPS fills the lower triangle of a symmetric Schur block

    runs = {"factor_solve": [], "schur": []}
    for _ in range(repeat):
        S1, _, c1 = _cpu_wall(factor_solve)
        runs["factor_solve"].append(c1)
        S2, _, c2 = _cpu_wall(schur)
        runs["schur"].append(c2)
    rec.update(factor_solve_cpu_s=min(runs["factor_solve"]), schur_cpu_s=min(runs["schur"]), runs=runs,
               schur_rel_diff=float(np.abs(S2 - S1).max() / np.abs(S1).max()))
    rec["time_s"] = rec["cpu_s"] = rec["factor_solve_cpu_s"]


def _hbm_iter(model, rec: dict, repeat: int, reuse: bool = False) -> None:
    """Full HBM (H = ``H``): ``ForcedResponseProblem`` setup, then ``repeat`` Newton iterations
    (``residual`` + ``newton.default_linear_solver``, i.e. ``J.factorize().solve(r)``) near the
    linear guess at w = 1.5 moved by one Newton step (contacts active), each at a frequency
    shifted by 1 % so that every harmonic block is factorised again, as in a corrector step;
    wall and CPU time of each iteration. ``reuse``: the problem's solver is ``BlockSolver(reuse=True)``
    (the factors of the last frequency precondition GMRES, ``femodes/hbm/linsolve/krylov.py``),
    its counters in ``solver_stats``."""
    import numpy as np

    import femodes as fm
    from femodes.solvers import newton

    from femodes.hbm.linsolve import BlockSolver
    solver = BlockSolver(reuse=bool(reuse))  # forced either way (the default "auto" reuses at 3-D sizes)
    (pr, ts, cs) = _cpu_wall(lambda: fm.ForcedResponseProblem(model, fm.Harmonics(H), solver=solver))
    rec.update(setup_s=ts, setup_cpu_s=cs, unknowns=int(pr.size), backend=fm.sparse_backend_info().indefinite)
    p0 = 1.5
    x = pr.initial_guess(p0)
    r, J, _ = pr.residual(x, p0)
    x = x - newton.default_linear_solver(J, r)
    walls, cpus, res_w, sol_w = [], [], [], []
    for i in range(repeat):
        p = p0 * (1.0 + 0.01 * (i + 1))
        w0, c0 = time.perf_counter(), time.process_time()
        r, J, _ = pr.residual(x, p)
        w1 = time.perf_counter()
        dx = newton.default_linear_solver(J, r)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
        res_w.append(w1 - w0)
        sol_w.append(walls[-1] - res_w[-1])
    P = np.asarray(pr.unpack(x, p0).P)
    rec.update(iteration_s=walls, iteration_cpu_s=cpus, residual_s=res_w, solve_s=sol_w,
               iteration_median_s=float(np.median(walls)), iteration_cpu_median_s=float(np.median(cpus)),
               time_s=float(np.median(walls)), cpu_s=float(np.median(cpus)),
               contact_active=bool(P.size and np.max(np.abs(P)) > 0),
               step_norm=float(np.linalg.norm(dx)), reuse=bool(reuse),
               solver_stats=dict(solver.stats) if solver is not None else None)


#: Half side of the square contact pad centred on the tip face of the pipeline's box (section 0.1 x 0.1):
#: (0.8 n + 1)^2 P2 nodes, 169 at n = 16 (1.05e6 DOFs).
PAD_HALF = 0.02


def pad_box(size: int, geometry: str = "box3d"):
    """``fm.box_mesh`` of box3d at ``size`` with one more boundary, ``"pad"``: the facets of the tip
    face whose midpoints lie in the square of half side :data:`PAD_HALF` centred on it. ``plate3d``:
    the plate 1 x 0.2 x 0.02 (nx = 5 n, ny = n, nz = 4), its pad the band ``|y - 0.1| <= PAD_HALF``
    of the tip face through the thickness."""
    import numpy as np

    import femodes as fm

    tol = 1e-9
    if geometry == "plate3d":
        mesh = fm.box_mesh(1.0, 0.2, 0.02, 5 * size, size, 4)
        return mesh.with_boundaries({"pad": lambda x: (np.abs(x[0] - 1.0) < tol)
                                     & (np.abs(x[1] - 0.1) <= PAD_HALF + tol)})
    mesh = fm.box_mesh(1.0, 0.1, 0.1, 10 * size, size, size)
    return mesh.with_boundaries({"pad": lambda x: (np.abs(x[0] - 1.0) < tol) & (np.abs(x[1] - 0.05) <= PAD_HALF + tol)
                                 & (np.abs(x[2] - 0.05) <= PAD_HALF + tol)})


def _vm_hwm_mib() -> float:
    """Peak resident memory of this process since the last :func:`_reset_hwm` (VmHWM)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _vm_rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _reset_hwm() -> None:
    """Set VmHWM to the current RSS (Linux: ``5`` to ``/proc/self/clear_refs``), so that each stage
    reports its own peak."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def pipeline(size: int, rec: dict, geometry: str = "box3d") -> None:
    """From nothing to a Craig-Bampton model, in one process, each stage timed (wall and CPU) with
    its peak resident memory (VmHWM reset at its start) and the resident memory after it:

    ``mesh``      :func:`pad_box` (``fm.box_mesh``, P2 tetrahedra once ``fm.solid`` numbers them);
    ``assembly``  ``fm.solid(mesh, E = rho = 1, nu = 0.3, clamped="left", order=2)``;
    ``contact``   ``with_damping(beta=0.02)``, one ``UnilateralContact`` per node of "pad"
                  (gap 0.01, normal +x) and a ``HarmonicForce`` on the same nodes (their u_x);
    ``cb``        ``fm.craig_bampton(model, CB_MODES)`` (kept: the pad's u_x).
    """
    import gc

    import femodes as fm

    stages = rec.setdefault("stages", {})
    state: dict = {}

    def stage(name, fn):
        gc.collect()
        _reset_hwm()
        rss0 = _vm_rss_mib()
        w, c = time.perf_counter(), time.process_time()
        fn()
        stages[name] = {"wall_s": time.perf_counter() - w, "cpu_s": time.process_time() - c,
                        "rss_before_mib": rss0, "peak_mib": _vm_hwm_mib(), "rss_after_mib": _vm_rss_mib()}
        print(f"pipeline {name}: {stages[name]}", file=sys.stderr, flush=True)

    def mesh():
        state["mesh"] = pad_box(size, geometry)

    def assembly():
        state["solid"] = fm.solid(state.pop("mesh"), fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left", order=2)

    def contact():
        state["model"] = (state.pop("solid").with_damping(beta=0.02)
                          .with_contact(fm.UnilateralContact(at="pad", gap=0.01, direction=(1.0, 0.0, 0.0)))
                          .with_forcing(fm.HarmonicForce(at=("pad", "u_x"), amplitude=1e-5)))

    def cb():
        state["rom"] = fm.craig_bampton(state["model"], CB_MODES)

    stage("mesh", mesh)
    stage("assembly", assembly)
    stage("contact", contact)
    model = state["model"]
    rec.update(N=int(model.n_dofs), nnz_K=int(model.K.nnz), n_contacts=len(model.contacts),
               backend=fm.sparse_backend_info().positive_definite)
    stage("cb", cb)
    rom = state["rom"]
    rec.update(n_reduced=int(rom.n_dofs), interface_omega_1=float(rom.interface_omega[0]))
    rec["time_s"] = sum(v["wall_s"] for v in stages.values())
    rec["cpu_s"] = sum(v["cpu_s"] for v in stages.values())
    rec["peak_mib"] = max(v["peak_mib"] for v in stages.values())


#: Sources whose version a measurement depends on (others edit the checkout meanwhile): their
#: SHA-1 prefixes are stored with every run.
CODE_FILES = ("femodes/hbm/linsolve/blocks.py", "femodes/hbm/linsolve/factors.py", "femodes/hbm/system.py",
              "femodes/fe/solid.py", "femodes/eigen.py", "femodes/reduction.py", "femodes/model/structural.py",
              "femodes/fe/redistribution.py", "femodes/sparse_direct.py", "femodes/fe/assembly.py")


def code_versions() -> dict:
    import hashlib

    return {f: hashlib.sha1((ROOT / f).read_bytes()).hexdigest()[:10] for f in CODE_FILES if (ROOT / f).is_file()}


def git_state() -> str:
    """``HEAD`` commit (12 digits), ``+dirty`` if femodes/ has uncommitted changes (read-only git)."""
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              timeout=30).stdout.strip()[:12]
        dirty = subprocess.run(["git", "status", "--short", "femodes"], cwd=ROOT, capture_output=True, text=True,
                               timeout=30).stdout.strip()
        return head + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def child(spec: dict) -> dict:
    """Measure one stage of one size (``spec``: geometry, size, stage, budget, repeat)."""
    rec: dict = {"baseline_mib": None, "code": code_versions()}
    import numpy as np  # noqa: F401 - the imports count in the baseline

    import femodes as fm

    rec["baseline_mib"] = _rss_mib()
    geometry, size, stage = spec["geometry"], spec["size"], spec["stage"]
    budget, repeat = float(spec["budget"]), int(spec["repeat"])
    try:
        if stage == "pipeline":
            pipeline(size, rec, geometry)
        elif stage == "assembly":
            times, solid_s, contact_s = [], [], []
            for _ in range(repeat):
                r: dict = {}
                t = time.perf_counter()
                _models(geometry, size, r)
                times.append(time.perf_counter() - t)
                solid_s.append(r["assembly_solid_s"])
                contact_s.append(r["assembly_contact_s"])
                rec.update(r)
                if sum(times) + times[-1] > budget:
                    break
            rec.update(time_s=statistics.median(times), times=times, assembly_solid_s=statistics.median(solid_s),
                       assembly_contact_s=statistics.median(contact_s))
            rec["peak_mib"] = _rss_mib()  # before the cache copy (pickling needs a second copy)
            if spec.get("cache"):
                _cached_models(spec, {}, write=True)
        else:
            plain, model = _cached_models(spec, rec) if spec.get("cache") else _models(geometry, size, rec)
            rec["model_mib"] = _rss_mib()
            if stage == "modes":
                med, times, modes = _repeat(lambda: fm.linear_modes(plain, 6), budget, repeat)
                rec.update(time_s=med, times=times, omega=[float(w) for w in modes.omega])
            elif stage == "cb":
                del plain
                walls, cpus = [], []
                for _ in range(repeat):
                    rom = None
                    rom, w, c = _cpu_wall(lambda: fm.craig_bampton(model, CB_MODES))
                    walls.append(w)
                    cpus.append(c)
                    if sum(walls) + w > budget:
                        break
                rec.update(time_s=min(walls), times=walls, cpu_s=min(cpus), cpu_times=cpus, n_reduced=int(rom.n_dofs),
                           interface_omega_1=float(rom.interface_omega[0]),
                           backend=fm.sparse_backend_info().positive_definite)
            elif stage == "hbm_setup":
                del plain
                _hbm_setup(model, rec, budget, repeat)
            elif stage.startswith("floor:"):
                del plain
                _floor(model, stage.split(":", 1)[1], rec, budget, repeat)
                rec["time_s"] = rec["block_s"]
            elif stage.startswith("cb_floor:"):
                del plain
                _cb_floor(model, stage.split(":", 1)[1], rec, repeat)
            elif stage == "hbm_iter":
                del plain
                _hbm_iter(model, rec, repeat)
            elif stage == "block_floor":
                del plain
                _block_floor(model, rec, repeat)
            else:
                raise ValueError(f"unknown stage {stage!r}")
    except MemoryError as exc:
        rec["error"] = f"MemoryError: {exc}"
    except Exception as exc:  # recorded; the study goes on
        rec["error"] = f"{type(exc).__name__}: {exc}"
    rec.setdefault("peak_mib", _rss_mib())
    return rec


# ---------------------------------------------------------------------------------------------
# Driver
# ---------------------------------------------------------------------------------------------
def _load() -> list[float]:
    try:
        return [float(v) for v in Path("/proc/loadavg").read_text().split()[:3]]
    except OSError:
        return []


class RssWatchdog:
    """Kill this process's descendants when their summed resident memory exceeds ``limit`` bytes
    (checked every ``period`` s); ``fired`` then holds the RSS seen, ``peak`` the largest sum."""

    def __init__(self, limit: float, period: float = 0.1):
        import threading

        self.limit, self.period = limit, period
        self.fired: float | None = None
        self.peak = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        import psutil

        me = psutil.Process()
        while not self._stop.wait(self.period):
            procs = me.children(recursive=True)
            total = 0.0
            for p in procs:
                try:
                    total += p.memory_info().rss
                except psutil.Error:
                    pass
            self.peak = max(self.peak, total)
            if total > self.limit:
                self.fired = total
                for p in procs:  # only the processes this driver started
                    try:
                        p.kill()
                    except psutil.Error:
                        pass


def run_stage(geometry: str, size: int, stage: str, args) -> dict:
    """One stage of one size in a child process with a timeout and an RSS limit; its record."""
    base = {"geometry": geometry, "size": size, "stage": stage, "N_expected": expected_dofs(geometry, size),
            "load_before": _load()}
    t = time.perf_counter()
    with RssWatchdog(args.mem_gib * 2**30) as dog:
        rec = _run_stage(geometry, size, stage, args)
    if dog.fired is not None:
        rec["error"] = f"MemoryError: RSS > {args.mem_gib:g} GiB ({dog.fired / 2**30:.1f} GiB; killed)"
    rec["tree_peak_rss_mib"] = dog.peak / 2**20
    rec.update(base, wall_s=time.perf_counter() - t, load_after=_load())
    rec.setdefault("code", code_versions())  # the HBM stages: as at the end of the run
    rec["git"] = git_state()
    rec["mem_limit"] = f"RSS {args.mem_gib:g} GiB" + (f", RLIMIT_AS {args.as_gib:g} GiB" if args.as_gib else "")
    return rec


def _run_stage(geometry: str, size: int, stage: str, args) -> dict:
    if stage in ("hbm_full", "hbm_cb"):
        rec = _run_hbm(geometry, size, stage == "hbm_cb", args)
    else:
        spec = {"geometry": geometry, "size": size, "stage": stage, "budget": args.budget, "repeat": args.repeat,
                "cache": str(args.cache) if args.cache else None}
        cmd = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(spec)]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        try:
            out, err = proc.communicate(timeout=args.timeout)
            line = [ln for ln in out.splitlines() if ln.startswith("RESULT ")]
            rec = json.loads(line[-1][7:]) if line else {
                "error": f"child failed (exit {proc.returncode}): {(err.strip().splitlines() or ['no message'])[-1]}"}
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            rec = {"error": f"timed out after {args.timeout:g} s"}
    return rec


def _run_hbm(geometry: str, size: int, reduced: bool, args) -> dict:
    from femodes.app.cases import parse_case
    from femodes.app.scaling.child import run_child

    text = case_text(geometry, size, reduced=reduced)
    path = ROOT / f"{geometry}_{size}.toml"  # never written: the name in messages
    case = parse_case(text, path)
    spec = {"path": str(path), "text": text, "data": case.data, "name": case.name, "repeat": args.repeat,
            "points": args.points}
    rec = run_child(spec, args.timeout)
    if "point_s" in rec:
        rec["time_s"] = rec["point_s"]
    return rec


def _key(r: dict) -> tuple:
    return (r["geometry"], r["size"], r["stage"])


def load_results(path: Path) -> dict:
    if path.is_file():
        return json.loads(path.read_text())
    return {"runs": []}


def save_results(path: Path, doc: dict) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    os.replace(tmp, path)


def _machine() -> dict:
    sys.path.insert(0, str(HERE))
    from _machine import cpu_model

    import numpy as np
    import scipy

    return {"cpu": cpu_model(), "cpus": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__,
            "mem_limit_gib": None, "threads": {v: os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}}


def _skip_reason(done: list[dict], stage: str, N_next: int, timeout: float) -> str | None:
    """Why ``stage`` is not run at the next size: failed or timed out before, or predicted too long."""
    prev = sorted((r for r in done if r["stage"] == stage), key=lambda r: r["size"])
    if not prev:
        return None
    last = prev[-1]
    if last.get("error"):
        return f"skipped: failed at a smaller size ({last['error'][:80]})"
    pts = [(r.get("N") or r["N_expected"], r["wall_s"]) for r in prev if not r.get("error") and r.get("wall_s")]
    if len(pts) >= 2:
        (n0, t0), (n1, t1) = pts[-2], pts[-1]
        a = max(1.0, math.log(t1 / t0) / math.log(n1 / n0)) if n1 > n0 and t0 > 0 and t1 > 0 else 1.5
        pred = t1 * (N_next / n1) ** a
        if pred > timeout:
            return f"skipped: predicted {pred:.0f} s (wall ~ N^{a:.2f}) > timeout {timeout:g} s"
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--geometry", default=",".join(GEOMETRIES))
    ap.add_argument("--stages", default=",".join(STAGES))
    ap.add_argument("--sizes", default=None, help="comma-separated sizes (ny of strip2d, n of box3d)")
    ap.add_argument("--max-dofs", type=float, default=1.1e6)
    ap.add_argument("--timeout", type=float, default=1200.0, help="seconds per stage and size")
    ap.add_argument("--budget", type=float, default=60.0, help="seconds of repeats per timed quantity")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--points", type=int, default=4, help="continuation points of the HBM stages")
    ap.add_argument("--mem-gib", type=float, default=10.0, help="resident memory limit of a stage (watchdog)")
    ap.add_argument("--as-gib", type=float, default=0.0,
                    help="also limit the address space (RLIMIT_AS) to this; 0: no (module docstring)")
    ap.add_argument("--json", type=Path, default=RESULTS)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/femodes_solids_cache"),
                    help="folder for the pickled models of one size (removed after its last stage)")
    ap.add_argument("--force", action="store_true", help="rerun runs already in the results")
    ap.add_argument("--report", action="store_true", help="print the tables and fits of the saved results")
    ap.add_argument("--issue38", action="store_true",
                    help="with --report: the tables of README_solids_scale.md's issue-38 section (cb against "
                         "cb_floor, hbm_iter, block_floor, pipeline; --before: the cb runs of the code before)")
    ap.add_argument("--before", type=Path, default=None,
                    help="with --report: also compare floor:femodes and hbm_full with the runs in this file")
    args = ap.parse_args(argv)
    if args.child:
        rec = child(json.loads(args.child))
        sys.stdout.write("\nRESULT " + json.dumps(rec) + "\n")
        return 0
    if args.report:
        doc = load_results(args.json)
        if args.issue38:
            print(report38(doc, load_results(args.before) if args.before else None))
            return 0
        print(report(doc))
        if args.before:
            print(compare(load_results(args.before), doc))
        return 0
    for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[v] = "1"
    if args.as_gib:
        lim = int(args.as_gib * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))  # inherited by every child
    doc = load_results(args.json)
    doc["machine"] = {**_machine(), "mem_limit_gib": args.mem_gib}
    doc.setdefault("settings", {})
    doc["settings"].update(H=H, cb_modes=CB_MODES, omega_block=OMEGA_BLOCK, points=args.points,
                           timeout_s=args.timeout, budget_s=args.budget, repeat=args.repeat)
    stages = [s for s in args.stages.split(",") if s]
    for s in stages:
        if s not in STAGES:
            ap.error(f"unknown stage {s!r}; known: {', '.join(STAGES)}")
    for geometry in args.geometry.split(","):
        sizes = [int(s) for s in args.sizes.split(",")] if args.sizes else GEOMETRIES[geometry]
        for size in sizes:
            if expected_dofs(geometry, size) > args.max_dofs:
                break
            for stage in stages:
                done = [r for r in doc["runs"] if r["geometry"] == geometry and r["size"] < size]
                old = [r for r in doc["runs"] if _key(r) == (geometry, size, stage)]
                if old and not args.force and not old[-1].get("skipped"):
                    continue
                why = _skip_reason(done, stage, expected_dofs(geometry, size), args.timeout)
                if why:
                    rec = {"geometry": geometry, "size": size, "stage": stage, "skipped": why,
                           "N_expected": expected_dofs(geometry, size), "error": why}
                    print(f"{geometry} size={size} {stage}: {why}", flush=True)
                else:
                    rec = run_stage(geometry, size, stage, args)
                    print(f"{geometry} size={size} N={rec.get('N')} {stage}: "
                          + (f"ERROR {rec['error']}" if rec.get("error") else f"{rec.get('time_s', float('nan')):.3g} s")
                          + f" peak {rec.get('peak_mib', float('nan')):.0f} MiB wall {rec['wall_s']:.1f} s "
                            f"load {rec['load_before']}", flush=True)
                doc["runs"] = [r for r in doc["runs"] if _key(r) != _key(rec)] + [rec]
                save_results(args.json, doc)
            (args.cache / f"{geometry}_{size}.pkl").unlink(missing_ok=True)
    print(report(doc))
    return 0


# ---------------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------------
def _slope(pts) -> float | None:
    import numpy as np

    pts = [(x, y) for x, y in pts if x and y and y > 0]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def _fmt(v, f="{:.3g}") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f.format(v)


def report(doc: dict) -> str:
    """Markdown tables (per geometry: time and peak memory of every stage per size) and fits."""
    lines = []
    runs = doc.get("runs", [])
    for geometry in GEOMETRIES:
        rs = [r for r in runs if r["geometry"] == geometry]
        if not rs:
            continue
        sizes = sorted({r["size"] for r in rs})
        stages = [s for s in STAGES if any(r["stage"] == s for r in rs)]
        lines.append(f"\n### {geometry}: time [s] / peak RSS [MiB] per stage\n")
        lines.append("| size | N | contacts | " + " | ".join(stages) + " | load (1 min) |")
        lines.append("|" + "---|" * (len(stages) + 4))
        for size in sizes:
            by = {r["stage"]: r for r in rs if r["size"] == size}
            N = next((r.get("N") for r in by.values() if r.get("N")), expected_dofs(geometry, size))
            nc = next((r.get("n_contacts") for r in by.values() if r.get("n_contacts")), None)
            cells = []
            for s in stages:
                r = by.get(s)
                if r is None:
                    cells.append("")
                elif r.get("skipped"):
                    cells.append("skip")
                elif r.get("error"):
                    cells.append("fail: " + r["error"][:40].replace("|", "/"))
                else:
                    cells.append(f"{_fmt(r.get('time_s'))} / {_fmt(r.get('peak_mib'), '{:.0f}')}")
            loads = [r["load_before"][0] for r in by.values() if r.get("load_before")]
            lines.append(f"| {size} | {N} | {_fmt(nc, '{}')} | " + " | ".join(cells)
                         + f" | {_fmt(statistics.median(loads) if loads else None, '{:.1f}')} |")
        lines.append("\nfitted exponents (least squares on log-log of the measured sizes; time ~ N^a, memory above "
                     "the baseline ~ N^b):\n")
        for s in stages:
            ok = [r for r in rs if r["stage"] == s and not r.get("error") and r.get("time_s")]
            if len(ok) < 2:
                continue
            a = _slope([(r["N"], r["time_s"]) for r in ok])
            b = _slope([(r["N"], r["peak_mib"] - (r.get("baseline_mib") or 0)) for r in ok])
            big = [r for r in ok if r["N"] >= 1e4]
            a_big = _slope([(r["N"], r["time_s"]) for r in big]) if len(big) >= 2 else None
            lines.append(f"- {s}: a = {_fmt(a, '{:.2f}')} (N >= 1e4: {_fmt(a_big, '{:.2f}')}), b = {_fmt(b, '{:.2f}')}"
                         f"  (N = {min(r['N'] for r in ok)}..{max(r['N'] for r in ok)})")
        fl = [r for r in rs if r["stage"].startswith("floor:") and not r.get("error")]
        if fl:
            lines.append(f"\n#### {geometry}: one harmonic block (k w = {OMEGA_BLOCK}), factorisation / "
                         "condensation solve of the n_b columns [s], fill\n")
            variants = [s for s in STAGES if s.startswith("floor:") and any(r["stage"] == s for r in fl)]
            lines.append("| size | n_I | kl | femodes banded | n_b | " + " | ".join(v.split(':')[1] for v in variants) + " |")
            lines.append("|" + "---|" * (len(variants) + 5))
            for size in sizes:
                by = {r["stage"]: r for r in fl if r["size"] == size}
                if not by:
                    continue
                r0 = by.get("floor:femodes") or next(iter(by.values()))  # banded: femodes' choice at that run
                cells = []
                for v in variants:
                    r = by.get(v)
                    cells.append("" if r is None else
                                 f"{_fmt(r['factor_s'])} / {_fmt(r['solve_nb_s'])}, fill {_fmt(r['fill'], '{:.1f}')}")
                lines.append(f"| {size} | {r0['n_interior']} | {r0['kl']} | {r0['femodes_banded']} | {r0['n_b']} | "
                             + " | ".join(cells) + " |")
        hb = [r for r in rs if r["stage"] in ("hbm_full", "hbm_cb") and not r.get("error")]
        if hb:
            lines.append(f"\n#### {geometry}: HBM (H = {H}), per point and per Newton iteration\n")
            lines.append("| size | N | stage | n_reduced | unknowns | per point [s] | points | Newton its | "
                         "iteration [s] | solve [s] | setup [s] | peak [MiB] |")
            lines.append("|" + "---|" * 12)
            for r in sorted(hb, key=lambda r: (r["size"], r["stage"])):
                lines.append(f"| {r['size']} | {r.get('N')} | {r['stage']} | {_fmt(r.get('n_reduced'), '{}')} | "
                             f"{r.get('unknowns')} | {_fmt(r.get('point_s'))} | {r.get('points')} | "
                             f"{r.get('newton_iterations')} | {_fmt(r.get('iteration_median_s'))} | "
                             f"{_fmt(r.get('solve_median_s'))} | {_fmt(r.get('setup_s'))} | "
                             f"{_fmt(r.get('peak_mib'), '{:.0f}')} |")
    return "\n".join(lines)


def report38(doc: dict, before: dict | None = None) -> str:
    """The issue-38 tables: Craig-Bampton against its back-end floor, full HBM per Newton iteration
    with MUMPS' own cost of a block, the pipeline from mesh to Craig-Bampton, and fitted exponents
    (CPU time)."""
    runs = [r for r in doc.get("runs", []) if r["geometry"] == "box3d"]
    old = {r["size"]: r for r in (before or {}).get("runs", []) if r["stage"] == "cb" and not r.get("error")}

    def by(stage):
        return {r["size"]: r for r in runs if r["stage"] == stage and not r.get("error")}
    cb, ch, mu = by("cb"), by("cb_floor:cholmod"), by("cb_floor:mumps")
    lines = ["\n#### Craig-Bampton (20 modes) against the back-end's own cost, CPU s (best of the repeats)\n",
             "| size | N | n_b | cb before | cb | CHOLMOD: factor + n_b solve + eigsh | MUMPS: same | cb / best floor "
             "| cb before / best floor | peak cb / floor [MiB] |",
             "|" + "---|" * 10]
    fit = {"cb": [], "floor": []}
    for size in sorted(set(cb) | set(ch)):
        c, h, m, o = cb.get(size), ch.get(size), mu.get(size), old.get(size)
        floors = [r for r in (h, m) if r]
        best = min(floors, key=lambda r: r["cpu_s"]) if floors else None

        def fl(r):
            return "-" if r is None else (f"{r['cpu_s']:.3g} = {r['factor_cpu_s']:.3g} + {r['solve_nb_cpu_s']:.3g} "
                                          f"+ {r['eigen_cpu_s']:.3g}")
        N = (c or h or {}).get("N")
        ratio = c["cpu_s"] / best["cpu_s"] if c and best else None
        ratio_old = o["cpu_s"] / best["cpu_s"] if o and best and o.get("cpu_s") else None
        lines.append(f"| {size} | {N} | {(h or {}).get('n_b', '-')} | {_fmt(o.get('cpu_s') if o else None)} | "
                     f"{_fmt(c['cpu_s'] if c else None)} | {fl(h)} | {fl(m)} | {_fmt(ratio, '{:.2f}')} | "
                     f"{_fmt(ratio_old, '{:.2f}')} | {_fmt(c.get('peak_mib') if c else None, '{:.0f}')} / "
                     f"{_fmt(best.get('peak_mib') if best else None, '{:.0f}')} |")
        if c and N:
            fit["cb"].append((N, c["cpu_s"]))
        if best and N:
            fit["floor"].append((N, best["cpu_s"]))
    lines.append("\nfitted CPU exponents: cb N^" + _fmt(_slope(fit["cb"]), "{:.2f}") + ", best floor N^"
                 + _fmt(_slope(fit["floor"]), "{:.2f}"))
    hb, bf = by("hbm_iter"), by("block_floor")
    if hb:
        lines += ["\n#### Full HBM (H = 5), one Newton iteration (residual + factorisations + solve)\n",
                  "| size | N | unknowns | back-end | iteration CPU [s] | iteration wall [s] | MUMPS complex block: "
                  "factor + n_b solves + Schur [CPU s] | same by MUMPS' Schur option [CPU s] | peak [MiB] | load |",
                  "|" + "---|" * 10]
        pts = []
        for size in sorted(hb):
            r, b = hb[size], bf.get(size)
            lines.append(f"| {size} | {r.get('N')} | {r.get('unknowns')} | {r.get('backend')} | "
                         f"{_fmt(r['iteration_cpu_median_s'])} | {_fmt(r['iteration_median_s'])} | "
                         f"{_fmt(b['factor_solve_cpu_s'] if b else None)} | {_fmt(b['schur_cpu_s'] if b else None)} | "
                         f"{_fmt(r.get('peak_mib'), '{:.0f}')} | {_fmt((r.get('load_before') or [None])[0], '{:.1f}')} |")
            pts.append((r.get("N"), r["iteration_cpu_median_s"]))
        lines.append("\nfitted CPU exponent of the iteration: N^" + _fmt(_slope(pts), "{:.2f}"))
    for geometry in ("box3d", "plate3d"):
        pl = {r["size"]: r for r in doc.get("runs", []) if r["geometry"] == geometry and r["stage"] == "pipeline"
              and not r.get("error")}
        lines += _pipeline_table(geometry, pl)
    return "\n".join(lines)


def _pipeline_table(geometry: str, pl: dict) -> list:
    """The pipeline's table (:func:`report38`) of one geometry."""
    lines = []
    if pl:
        names = ("mesh", "assembly", "contact", "cb")
        lines += [f"\n#### {geometry}: from mesh to Craig-Bampton in one process: CPU s / wall s / peak RSS MiB per stage\n",
                  "| size | N | contacts | n_reduced | " + " | ".join(names) + " | total CPU / wall [s] | load |",
                  "|" + "---|" * 10]
        fits = {k: [] for k in names}
        for size in sorted(pl):
            r = pl[size]
            st = r["stages"]
            cells = [f"{st[k]['cpu_s']:.3g} / {st[k]['wall_s']:.3g} / {st[k]['peak_mib']:.0f}" for k in names]
            lines.append(f"| {size} | {r['N']} | {r['n_contacts']} | {r['n_reduced']} | " + " | ".join(cells)
                         + f" | {r['cpu_s']:.3g} / {r['time_s']:.3g} | {_fmt((r.get('load_before') or [None])[0], '{:.1f}')} |")
            for k in names:
                fits[k].append((r["N"], st[k]["cpu_s"]))
        lines.append("\nfitted CPU exponents: " + ", ".join(f"{k} N^{_fmt(_slope(v), '{:.2f}')}" for k, v in fits.items()))
    return lines


def _cell(r, fmt) -> str:
    if r is None:
        return ""
    if r.get("skipped"):
        return "skip"
    if r.get("error"):
        return "fail: " + r["error"][:30].replace("|", "/")
    return fmt(r)


def compare(before: dict, after: dict) -> str:
    """Before/after tables of the stages the block ordering changes (``floor:femodes``, ``hbm_full``)."""
    lines = []
    for geometry in GEOMETRIES:
        rb = {(r["size"], r["stage"]): r for r in before.get("runs", []) if r["geometry"] == geometry}
        ra = {(r["size"], r["stage"]): r for r in after.get("runs", []) if r["geometry"] == geometry}
        sizes = sorted({k[0] for k in ra if k[1] in ("floor:femodes", "hbm_full")
                        and not ra[k].get("skipped")})
        if not sizes:
            continue
        lines.append(f"\n#### {geometry}: one harmonic block as femodes factorises it, before / after\n")
        lines.append("| size | n_I | band/nnz | path before | path after | fill before | fill after | "
                     "factor + n_b solves before [s] | after [s] | peak before [MiB] | after [MiB] |")
        lines.append("|" + "---|" * 11)
        for size in sizes:
            b, a = rb.get((size, "floor:femodes")), ra.get((size, "floor:femodes"))
            if a is None or a.get("skipped"):
                continue
            r0 = a if not a.get("error") else (b or {})
            kl, nI, nnz = r0.get("kl"), r0.get("n_interior"), r0.get("nnz_block")
            ratio = (3 * kl + 1) * nI / nnz if kl is not None and nI and nnz else None

            def path(r):
                return _cell(r, lambda r: "band" if r.get("femodes_banded") else
                             " ".join(r.get("path", "SuperLU").split()[:2]))
            lines.append(f"| {size} | {_fmt(nI, '{}')} | {_fmt(ratio, '{:.1f}')} | {path(b)} | {path(a)} | "
                         f"{_cell(b, lambda r: _fmt(r.get('fill'), '{:.1f}'))} | {_cell(a, lambda r: _fmt(r.get('fill'), '{:.1f}'))} | "
                         f"{_cell(b, lambda r: _fmt(r.get('block_s')))} | {_cell(a, lambda r: _fmt(r.get('block_s')))} | "
                         f"{_cell(b, lambda r: _fmt(r.get('peak_mib'), '{:.0f}'))} | "
                         f"{_cell(a, lambda r: _fmt(r.get('peak_mib'), '{:.0f}'))} |")
        lines.append(f"\n#### {geometry}: full HBM (H = {H}), before / after\n")
        lines.append("| size | N | unknowns | Newton iteration before [s] | after [s] | per point before [s] | "
                     "after [s] | peak before [MiB] | after [MiB] | load (1 min) before / after |")
        lines.append("|" + "---|" * 10)
        for size in sizes:
            b, a = rb.get((size, "hbm_full")), ra.get((size, "hbm_full"))
            if a is None or a.get("skipped") or (b is not None and b.get("skipped") and a.get("error")):
                continue
            r0 = a if a.get("N") else (b or {})
            lb = _fmt((b or {}).get("load_before", [None])[0] if (b or {}).get("load_before") else None, "{:.1f}")
            la = _fmt(a.get("load_before", [None])[0] if a.get("load_before") else None, "{:.1f}")
            lines.append(f"| {size} | {_fmt(r0.get('N') or expected_dofs(geometry, size), '{}')} | "
                         f"{_fmt(r0.get('unknowns'), '{}')} | "
                         f"{_cell(b, lambda r: _fmt(r.get('iteration_median_s')))} | "
                         f"{_cell(a, lambda r: _fmt(r.get('iteration_median_s')))} | "
                         f"{_cell(b, lambda r: _fmt(r.get('point_s')))} | {_cell(a, lambda r: _fmt(r.get('point_s')))} | "
                         f"{_cell(b, lambda r: _fmt(r.get('peak_mib'), '{:.0f}'))} | "
                         f"{_cell(a, lambda r: _fmt(r.get('peak_mib'), '{:.0f}'))} | {lb} / {la} |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
