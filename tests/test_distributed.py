"""femodes.app.distributed: a harmonic balance Newton step with one Dask actor per harmonic block
(2 workers), against the direct solve of the assembled Jacobian."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import femodes as fm
from femodes.app.distributed import assembled_jacobian, distributed_newton_step

distributed = pytest.importorskip("distributed", reason="the sweep extra (dask[distributed]) is installed by make test")


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as c, \
            distributed.Client(c) as cl:
        yield cl


def test_distributed_step_solves_the_assembled_system(client):
    mesh = fm.line_mesh(1.0, 30, boundaries={"clamp": 0.0, "tip": 1.0})
    bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    K, M = bar.K, bar.M
    C = 0.01 * K
    H, omega = 3, 1.3
    contact = [bar.n_dofs - 1, bar.n_dofs - 6]
    rng = np.random.default_rng(3)
    m = len(contact) * (2 * H + 1)
    A = rng.standard_normal((m, m)) * 0.5  # a linearised contact law: any real coupling of the coefficients
    r = rng.standard_normal(bar.n_dofs * (2 * H + 1))
    x = distributed_newton_step(client, K, M, C, omega, H, contact, A, r)
    J = assembled_jacobian(K, M, C, omega, H, contact, A)
    ref = spla.spsolve(J, r)
    # both solves are backward stable: the difference is bounded by a small multiple of eps cond(J)
    cond = np.linalg.cond(J.toarray())
    assert np.linalg.norm(x - ref) <= 100 * np.finfo(float).eps * cond * np.linalg.norm(ref)
    # and it is the solution: relative residual at round-off
    assert np.linalg.norm(J @ x - r) <= 1e3 * np.finfo(float).eps * (abs(J).sum(axis=1).max() * np.linalg.norm(x))


def test_bad_sizes_name_the_argument(client):
    K = sp.identity(4, format="csr")
    with pytest.raises(ValueError, match="A must be"):
        distributed_newton_step(client, K, K, 0 * K, 1.0, 1, [0], np.zeros((2, 2)), np.zeros(12))
    with pytest.raises(ValueError, match="r must have"):
        distributed_newton_step(client, K, K, 0 * K, 1.0, 1, [0], np.zeros((3, 3)), np.zeros(5))
