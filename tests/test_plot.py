"""Outputs layer: matplotlib figures (femodes.plot), Agg backend."""

import subprocess
import sys

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import femodes as fm  # noqa: E402
from femodes import plot  # noqa: E402
from femodes.results import Branch  # noqa: E402

GAP = 0.01


@pytest.fixture(scope="module")
def study():
    mesh = fm.line_mesh(1.0, 20, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = beam.with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    red = fm.craig_bampton(model, 6)
    nnm = fm.nonlinear_mode(red, 1, energy=(1e-4, 1e-3), harmonics=fm.Harmonics(5))
    rom = fm.craig_bampton(model.with_damping(alpha=0.02).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.004)), 6)
    forced = fm.frequency_response(rom, (3.0, 4.2), fm.Harmonics(5))
    return beam, red, nnm, rom, forced


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def with_folds(br, folds):
    """The same branch with fold indices set (the smooth test branch has none)."""
    return Branch(kind=br.kind, harmonics=br.harmonics, contacts=br.contacts, omega=br.omega, Q=br.Q, P=br.P,
                  energy=br.energy, xi=br.xi, residual_norm=br.residual_norm, nit=br.nit, parameter=br.parameter,
                  folds=folds, model=br.model, meta=br.meta)


def saved(ax, path):
    ax.figure.savefig(path)
    assert path.stat().st_size > 1000
    return path


def test_import_femodes_does_not_import_matplotlib_or_pyvista():
    code = ("import sys, femodes, femodes.io, femodes.plot, femodes.viz; "
            "print(any(m.split('.')[0] in ('matplotlib', 'pyvista', 'vtk', 'vtkmodules') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_frequency_energy(study, tmp_path):
    _, _, nnm, _, forced = study
    ax = plot.frequency_energy([nnm, with_folds(forced, [3, 10])])
    lines = ax.get_lines()
    assert len(lines) == 3
    np.testing.assert_array_equal(lines[0].get_xdata(), nnm.omega)
    np.testing.assert_array_equal(lines[0].get_ydata(), nnm.energy)
    np.testing.assert_array_equal(lines[1].get_ydata(), forced.energy)
    np.testing.assert_array_equal(lines[2].get_xdata(), forced.omega[[3, 10]])
    assert ax.get_yscale() == "log"
    assert lines[0].get_linestyle() == "-" and lines[1].get_linestyle() == "--"
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["nonlinear mode 1", "forced"]
    saved(ax, tmp_path / "fe.png")
    ax = plot.frequency_energy(nnm, hz=True, labels=["backbone"])
    np.testing.assert_allclose(ax.get_lines()[0].get_xdata(), nnm.omega / (2 * np.pi))
    with pytest.raises(ValueError, match="labels"):
        plot.frequency_energy([nnm, forced], labels=["one"])
    with pytest.raises(TypeError, match="branches"):
        plot.frequency_energy([])


def test_frequency_response(study, tmp_path):
    _, _, _, rom, forced = study
    tip = rom.dof("tip")
    ax = plot.frequency_amplitude(forced, tip)
    assert len(ax.get_lines()) == 1  # no folds on this branch
    np.testing.assert_array_equal(ax.get_lines()[0].get_xdata(), forced.omega)
    np.testing.assert_array_equal(ax.get_lines()[0].get_ydata(), forced.amplitude(tip))
    br = with_folds(forced, [5, 10])
    fig, existing = plt.subplots()
    ax = plot.frequency_amplitude(br, "tip", ax=existing)
    assert ax is existing
    lines = ax.get_lines()
    assert len(lines) == 2
    np.testing.assert_array_equal(lines[1].get_xdata(), forced.omega[[5, 10]])
    np.testing.assert_array_equal(lines[1].get_ydata(), forced.amplitude(tip)[[5, 10]])
    assert lines[1].get_marker() == "x"
    saved(ax, tmp_path / "fr.png")
    with pytest.raises(ValueError, match="dof"):
        plot.frequency_amplitude(forced, 99)
    with pytest.raises(TypeError, match="dof"):
        plot.frequency_amplitude(forced, 1.5)
    with pytest.raises(TypeError, match="branch"):
        plot.frequency_amplitude(forced[0], 0)
    with pytest.raises(TypeError, match="ax"):
        plot.frequency_amplitude(forced, 0, ax="axes")


def test_time_history(study, tmp_path):
    _, _, _, _, forced = study
    sol = forced[len(forced) // 2]
    ax = plot.time_history(sol, n_periods=2)
    line = ax.get_lines()[0]
    t = line.get_xdata()
    assert t[0] == 0 and t[-1] == pytest.approx(2 * sol.period)
    np.testing.assert_allclose(line.get_ydata(), sol.displacement(t)[:, sol.contacts.dofs[0]])
    twins = [a for a in ax.figure.axes if a is not ax]
    assert len(twins) == 1
    np.testing.assert_allclose(twins[0].get_lines()[0].get_ydata(), sol.contact_force(t)[:, 0])
    assert any(np.all(np.asarray(ln.get_ydata()) == GAP) for ln in ax.get_lines()[1:])  # the gap line
    saved(ax, tmp_path / "th.png")
    ax = plot.time_history(sol, dof=2, contact=False)
    assert len(ax.figure.axes) == 1 and len(ax.get_lines()) == 1
    with pytest.raises(ValueError, match="n_periods"):
        plot.time_history(sol, n_periods=0)
    with pytest.raises(TypeError, match="solution"):
        plot.time_history(forced)


def test_phase_portrait(study, tmp_path):
    _, _, nnm, _, _ = study
    sol = nnm[-1]
    ax = plot.phase_portrait(sol, 0, n_points=100)
    line = ax.get_lines()[0]
    t = np.linspace(0, sol.period, 101)
    np.testing.assert_allclose(line.get_xdata(), sol.displacement(t)[:, 0])
    np.testing.assert_allclose(line.get_ydata(), sol.velocity(t)[:, 0])
    assert len(ax.get_lines()) == 2  # orbit + gap
    saved(ax, tmp_path / "pp.png")


def test_mode_shape_reduced_solution(study, tmp_path):
    beam, red, nnm, _, _ = study
    sol = nnm[-1]
    ax = plot.mode_shape(sol, n_snapshots=5)
    lines = ax.get_lines()
    assert len(lines) == 6  # 5 snapshots + the obstacle
    x = beam.fe.mesh.p[0]
    for k in range(5):
        t = k * sol.period / 5
        w = red.mesh_map.full_field(sol.displacement([t]))[0][beam.fe.nodal[0]]
        np.testing.assert_array_equal(lines[k].get_xdata(), x)
        np.testing.assert_allclose(lines[k].get_ydata(), w, atol=1e-14)
    assert lines[5].get_xdata()[0] == 1.0 and lines[5].get_ydata()[0] == GAP
    saved(ax, tmp_path / "ms.png")


def test_mode_shape_linear_and_discrete(study, tmp_path):
    beam, _, _, _, _ = study
    modes = fm.linear_modes(beam, 3)
    ax = plot.mode_shape(modes, beam, mode=3, n_snapshots=1)
    phi = beam.mesh_map.full_field(modes.shapes[:, 2])[beam.fe.nodal[0]]
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), phi)
    with pytest.raises(ValueError, match="model"):
        plot.mode_shape(modes)
    with pytest.raises(ValueError, match="n_snapshots"):
        plot.mode_shape(modes, beam, n_snapshots=0)
    # discrete model: markers against the DOF index
    model = fm.StructuralModel(M=np.eye(2), K=np.array([[2.0, -1.0], [-1.0, 2.0]]), dof_names=["x1", "x2"])
    dm = fm.linear_modes(model, 2)
    ax = plot.mode_shape(dm, model, n_snapshots=3)
    assert len(ax.get_lines()) == 3
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), dm.shapes[:, 0])
    assert [t.get_text() for t in ax.get_xticklabels()] == ["x1", "x2"]
    saved(ax, tmp_path / "discrete.png")
