"""Shared fixtures: small meshes and models used across the test modules."""

import contextlib
import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

import femodes as fm  # noqa: E402


@pytest.fixture
def unit():
    """Unit material and section: EA = EI = rho A = 1."""
    return fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0)


def cantilever(n_elements=10, length=1.0):
    mesh = fm.line_mesh(length=length, n_elements=n_elements, boundaries={"clamp": 0.0, "tip": length})
    return fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")


def fixed_free_bar(n_elements=10, order=1, **kw):
    mesh = fm.line_mesh(length=1.0, n_elements=n_elements, boundaries={"clamp": 0.0, "tip": 1.0})
    return fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), order=order, clamped="clamp", **kw)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def cheap_location(monkeypatch):
    """A context in which bifurcations are located by bracketing as on a large problem
    (``branch_stability.PRECISE_MAX_UNKNOWNS`` lowered to 0) and every corrector solve of the
    location is counted: it yields the list of the solves' secant parameters, filled inside."""
    from femodes import branch_stability

    @contextlib.contextmanager
    def cheap():
        solves = []
        orig = branch_stability.solve_on_secant

        def counted(*args, **kwargs):
            solves.append(args[3])
            return orig(*args, **kwargs)

        with monkeypatch.context() as m:
            m.setattr(branch_stability, "PRECISE_MAX_UNKNOWNS", 0)
            m.setattr(branch_stability, "solve_on_secant", counted)
            yield solves

    return cheap


def roundoff_rtol(K, M=None, multiple: float = 1.0) -> float:
    """Relative round-off scale of the lowest eigenvalue of ``(K, M)``: ``multiple x eps x
    lambda_max / lambda_min``. A normwise perturbation ``eps ||K||`` of the pencil moves
    ``lambda_i`` by up to ``eps ||K|| ||x_i||^2`` (``x_i`` mass-normalised; Stewart & Sun,
    *Matrix Perturbation Theory*, 1990, ch. VI), that is ``eps lambda_max / lambda_i`` relative.
    Tests that compare two computations of eigenvalues of a fine mesh take their tolerance from
    this, not from what one BLAS kernel printed."""
    import scipy.linalg as sla

    K = K.toarray() if hasattr(K, "toarray") else np.asarray(K)
    M = np.eye(K.shape[0]) if M is None else (M.toarray() if hasattr(M, "toarray") else np.asarray(M))
    lam = sla.eigh(K, M, eigvals_only=True)
    return multiple * np.finfo(float).eps * float(lam[-1] / lam[0])


#: Test modules whose results sit at the round-off level of BLAS (linear algebra, reduction,
#: harmonic transforms and the positive part, Hill, the exact flow, accuracy, and every module with
#: many round-off-level literal tolerances: tests/test_suite_rules.py keeps this list complete): CI
#: runs them again under other OpenBLAS kernels and thread counts (`make test-kernels`).
NUMERICS_MODULES = {
    "test_linsolve", "test_reduction", "test_harmonics", "test_laws", "test_hill", "test_hill_reduced",
    "test_exact_flow", "test_exact_branch", "test_accuracy", "test_modal_damping", "test_linear_modes",
    "test_stability", "test_shooting", "test_solid", "test_inclined_contact", "test_hbm", "test_solvers",
    "test_solid_outputs", "test_time", "test_mesh", "test_impact_reference", "test_results", "test_time_units",
    "test_io", "test_validation_impact_oscillator", "test_switching_branch_point", "test_phase_predictor", "test_sweep",
    "test_solid_contact", "test_resume", "test_examples_solids", "test_examples_accuracy",
    "test_dynamic_stiffness", "test_silent_answers",
}


def pytest_configure(config):
    config.addinivalue_line("markers", "numerics: round-off-sensitive tests, rerun by CI under other BLAS kernels")
    _limit_blas_threads_in_workers()


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.module.__name__.rsplit(".", 1)[-1] in NUMERICS_MODULES:
            item.add_marker(pytest.mark.numerics)


def _limit_blas_threads_in_workers():
    """One BLAS thread per pytest-xdist worker unless the environment asks otherwise: two workers
    with OpenBLAS's default of one thread per core oversubscribe a 2-core machine, and OpenBLAS's
    spinning threads then made a suite 2x (quiet) to 7x (another busy process) slower."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    if any(os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")):
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency of femodes
        return
    global _WORKER_LIMIT
    _WORKER_LIMIT = threadpool_limits(1)  # kept for the worker's lifetime


_WORKER_LIMIT = None
