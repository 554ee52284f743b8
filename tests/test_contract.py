"""The public API contract of the design document (``DESIGN.md``, section 3) runs as written.

Every call of the contract is made here with small numbers, with femodes' DeprecationWarnings
turned into errors: a contract name that a refactoring moved or deprecated fails this test. The
contract spellings that this release deprecates are listed in :data:`DEPRECATED_IN_CONTRACT`;
each is called once and must still work and warn (the closing note of the release lists them as
names to change in the contract).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import femodes as fm

ROOT = Path(__file__).resolve().parents[1]

#: contract spellings deprecated in this release (old spelling -> the one to write instead)
DEPRECATED_IN_CONTRACT = {
    'fm.stability(sol, method="auto")': "fm.stability(sol, fm.stability_methods.Auto())",
}


@pytest.fixture(autouse=True)
def _deprecations_are_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        yield


def test_models_of_the_contract():
    mesh = fm.line_mesh(length=1.0, n_elements=12, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    loaded = fm.load_mesh(ROOT / "meshes" / "cantilever.msh")
    assert fm.beam(loaded, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0),
                   clamped="clamp").n_dofs > 0
    for order in (1, 2):
        bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp", order=order)
        assert bar.n_dofs == 12 * order
    M, K = np.diag([1.0, 1.0]), np.array([[2.0, -1.0], [-1.0, 2.0]])
    discrete = fm.StructuralModel(M=M, K=K, C=0.01 * K)
    model = (beam.with_damping(alpha=0.0, beta=1e-4)
                 .with_forcing(fm.HarmonicForce(at="tip", amplitude=1.0))
                 .with_contact(fm.UnilateralContact(at="tip", gap=0.01))
                 .with_nonlinearity(fm.CubicSpring(at=0, k3=0.5)))
    assert model.contacts and model.nonlinearities
    # at= by name, by (location, component) and by DOF index
    for at in ("tip", ("tip", "u_y"), 0):
        assert discrete.with_contact(fm.PenaltyContact(at=at if at == 0 else 1, gap=0.1, stiffness=10.0)).contacts
        beam.with_forcing(fm.HarmonicForce(at=at, amplitude=1.0))
    modes = fm.linear_modes(model, n=6)
    assert modes.omega.shape == (6,) and modes.shapes.shape[1] == 6
    rom = fm.craig_bampton(model, n_modes=4)
    assert rom.expand(np.zeros(rom.n_dofs)).shape == (model.n_dofs,)


def test_analyses_results_and_outputs_of_the_contract(tmp_path):
    mesh = fm.line_mesh(length=1.0, n_elements=10, boundaries={"clamp": 0.0, "tip": 1.0})
    free = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp").with_contact(
        fm.UnilateralContact(at="tip", gap=0.01))
    model = free.with_damping(beta=0.02).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004))
    rom = fm.craig_bampton(model, n_modes=4)
    H = fm.Harmonics(n_harmonics=5, n_time=None, subharmonic=1)
    w1 = float(fm.linear_modes(model, 1).omega[0])
    frc = fm.frequency_response(rom, omega=(0.9 * w1, 1.3 * w1), harmonics=H, stability=True)
    assert isinstance(frc, fm.Branch)
    nnm = fm.nonlinear_mode(free, mode=1, energy=(0.5 * fm.grazing_energy(free, 1), 2 * fm.grazing_energy(free, 1)),
                            harmonics=H)
    assert isinstance(nnm, fm.Branch)
    for name in ("ForcedResponseProblem", "NonlinearModeProblem", "continuation", "ContinuationOptions",
                 "semismooth_newton", "switch_branch"):
        assert callable(getattr(fm, name))
    n = len(frc)
    assert frc.omega.shape == frc.energy.shape == frc.converged.shape == (n,)
    sol = frc[n // 2]
    t = np.linspace(0.0, 2 * np.pi / sol.omega, 8)
    assert np.isfinite(sol.omega) and np.isfinite(sol.energy)
    assert sol.displacement(t).shape == (8, rom.n_dofs)
    assert sol.contact_force(t).shape == (8, 1)
    assert np.isfinite([sol.penetration, sol.tension, sol.residual_norm]).all()
    # stability and bifurcations
    assert frc.stable.shape == (n,) and frc.multipliers.shape[0] == n
    for b in frc.bifurcations:
        assert b.kind in {"fold", "branch_point", "period_doubling", "neimark_sacker", "nonsmooth"}
        assert 0 <= b.index < n and np.isfinite(b.omega)
    for old, new in DEPRECATED_IN_CONTRACT.items():
        with pytest.warns(DeprecationWarning, match=r"stability_methods\.Auto"):
            res = fm.stability(sol, method="auto")  # the contract's spelling (old)
        assert res.multipliers.size > 0, new
    # time stepping, saving, plots and ParaView series
    hist = fm.simulate(model, t_end=1.0, dt=1e-3, u0=np.zeros(model.n_dofs), v0=np.zeros(model.n_dofs), omega=w1)
    assert hist.u.shape[0] == hist.t.size == hist.v.shape[0]
    frc.save(tmp_path / "frc.h5")
    assert np.array_equal(fm.load_branch(tmp_path / "frc.h5").omega, frc.omega)
    ax = fm.plot.frequency_energy(nnm, ax=None)
    assert ax.get_lines()
    assert fm.io.write_animation(sol, rom, tmp_path / "mode1", n_frames=4, scale=1.0).is_file()
    assert callable(fm.viz.animate)


def test_error_control_of_the_contract():
    model = fm.StructuralModel(M=np.eye(1), K=np.eye(1), C=0.1 * np.eye(1)).with_forcing(
        fm.HarmonicForce(at=0, amplitude=0.2)).with_contact(fm.UnilateralContact(at=0, gap=1.0))
    frc = fm.frequency_response(model, omega=(0.5, 2.0), harmonics=fm.Harmonics(n_harmonics=10), rtol=1e-2)
    assert frc.error_estimate is not None and frc[0].error_estimate is not None


def test_solids_of_the_contract():
    mesh = fm.rectangle_mesh(length=1.0, height=0.05, nx=8, ny=2)
    assert {"left", "right", "bottom", "top"} <= set(mesh.boundaries)
    assert fm.box_mesh(nx=2).p.shape[0] == 3
    model = fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.3), clamped="left", plane="stress",
                     thickness=1.0, order=1)
    assert model.with_contact(fm.UnilateralContact(at="right", gap=0.01, direction=(1.0, 0.0))).contacts
    varying = model.with_contact(fm.UnilateralContact(at="right", gap=lambda x: 0.01 + x[1], direction=(1.0, 0.0)))
    gaps = sorted(c.item.gap for c in varying.contacts)  # one contact per node of the edge (ny + 1)
    np.testing.assert_allclose(gaps, 0.01 + np.linspace(0.0, 0.05, 3), rtol=1e-12)
