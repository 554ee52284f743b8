"""Responses at a boundary without rebuilding the model: model.mesh_map.probe and the plots that
read it (mean or max over the boundary's nodes; a Craig-Bampton model reads its parent's
boundaries through its basis, kept or not)."""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import femodes as fm  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import user_blade_3d as ub  # noqa: E402  (the blade of the example: 6 x 2 Q2 mesh, stop, force, damping)


@pytest.fixture(scope="module")
def blade():
    model = ub.with_stop(fm.solid(fm.load_mesh(ub.MESHES[True]), ub.STEEL, clamped="root", order=2))
    rom = fm.craig_bampton(model, 6)
    return model, rom


def test_probe_reads_a_boundary_mean_and_max(blade):
    model, rom = blade
    dm = model.dofmap
    nodes = np.asarray(dm.groups["tip"])
    dofs = dm.node_dof[nodes, 2]
    wts = np.asarray(dm.group_weights["tip"], dtype=float)
    q = np.random.default_rng(0).standard_normal(model.n_dofs)
    # the mean: the consistent weights (a uniform traction's shares), none of the tip is supported
    assert (dofs >= 0).all()
    assert model.mesh_map.probe(("tip", "u_z")) @ q == pytest.approx(float(wts @ q[dofs] / wts.sum()), rel=1e-12)
    W = model.mesh_map.probe(("tip", "u_z"), how="max")
    assert W.shape == (nodes.size, model.n_dofs) and sorted(np.flatnonzero(W.sum(axis=0))) == sorted(dofs)
    with pytest.raises(ValueError, match="how must be"):
        model.mesh_map.probe("tip", how="median")


def test_reduced_model_reads_boundaries_it_does_not_keep(blade):
    """The tip is not kept (only the pad's contact DOFs are): its mean on the reduced model is the
    mean of the expanded field, exactly."""
    model, rom = blade
    with pytest.raises(ValueError):
        rom.dof(("tip", "u_z"))
    r = np.random.default_rng(1).standard_normal(rom.n_dofs)
    full = rom.expand(r)
    assert rom.mesh_map.probe(("tip", "u_z")) @ r == pytest.approx(model.mesh_map.probe(("tip", "u_z")) @ full, rel=1e-12)


def test_plots_at_a_boundary_of_a_reduced_model(blade):
    _, rom = blade
    w1 = float(fm.linear_modes(rom, 1).omega[0])
    b = fm.frequency_response(rom, (0.9 * w1, 0.95 * w1), 3, options=fm.ContinuationOptions(max_points=4))
    ax = fm.plot.frequency_amplitude(b, ("tip", "u_z"))
    amp = ax.lines[0].get_ydata()
    tip = rom.mesh_map.probe(("tip", "u_z"))
    expected = [np.max(np.abs(b[i].displacement(np.linspace(0, b[i].period, 513)) @ tip)) for i in range(len(b))]
    np.testing.assert_allclose(amp, expected, rtol=1e-3)  # 512 vs 513 samples of a smooth 3-harmonic signal
    ax_max = fm.plot.frequency_amplitude(b, ("tip", "u_z"), how="max")
    assert np.all(ax_max.lines[0].get_ydata() >= amp * (1 - 1e-12))  # no node moves less than the mean's max
    ax = fm.plot.time_history(b[len(b) - 1], ("tip", "u_z"), how="max")
    assert "tip u_z, max" in ax.get_ylabel()
