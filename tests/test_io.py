"""Outputs layer: ParaView time series (femodes.io)."""

import re
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import femodes as fm
from femodes.io import write_animation, write_linear_mode

GAP = 0.01


@pytest.fixture(scope="module")
def cantilever_nnm():
    mesh = fm.line_mesh(1.0, 20, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = beam.with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    red = fm.craig_bampton(model, 6)
    nnm = fm.nonlinear_mode(red, 1, energy=(1e-4, 1e-3), harmonics=fm.Harmonics(5))
    return beam, model, red, nnm


def read_pvd(path):
    root = ET.parse(path).getroot()
    assert root.attrib["type"] == "Collection"
    return [(float(d.attrib["timestep"]), d.attrib["file"]) for d in root.iter("DataSet")]


def test_nonlinear_mode_series(cantilever_nnm, tmp_path):
    beam, model, red, nnm = cantilever_nnm
    sol = nnm[-1]
    n = 7
    pvd = write_animation(sol, red, tmp_path / "sub" / "mode1", n_frames=n)
    assert pvd == tmp_path / "sub" / "mode1.pvd" and pvd.is_file()
    entries = read_pvd(pvd)
    assert len(entries) == n
    assert sorted(p.name for p in (tmp_path / "sub").glob("*.vtu")) == [f"mode1_{j:04d}.vtu" for j in range(n)]
    T = sol.period
    fe = beam.fe
    tip = model.dofmap.locations["tip"]
    for j, (t, name) in enumerate(entries):
        assert name == f"mode1_{j:04d}.vtu"
        assert t == j * T / n
        m = meshio.read(pvd.parent / name)
        n_nodes = fe.mesh.p.shape[1]
        assert m.points.shape == (n_nodes, 3)
        np.testing.assert_array_equal(m.points[:, 0], fe.mesh.p[0])
        assert np.all(m.points[:, 1:] == 0)
        np.testing.assert_array_equal(m.cells_dict["line"], fe.mesh.t.T)
        assert set(m.point_data) == {"displacement", "velocity", "rotation", "contact_force"}
        full = red.mesh_map.full_field(sol.displacement([t]))[0]
        vfull = red.mesh_map.full_field(sol.velocity([t]))[0]
        d = m.point_data["displacement"]
        assert d.shape == (n_nodes, 3)
        np.testing.assert_allclose(d[:, 1], full[fe.nodal[0]], rtol=0, atol=1e-12)
        assert np.all(d[:, [0, 2]] == 0)
        np.testing.assert_allclose(m.point_data["velocity"][:, 1], vfull[fe.nodal[0]], rtol=0, atol=1e-12)
        np.testing.assert_allclose(m.point_data["rotation"], full[fe.nodal[1]], rtol=0, atol=1e-12)
        p = m.point_data["contact_force"]
        assert p.shape == (n_nodes,)
        np.testing.assert_allclose(p[tip], sol.contact_force([t])[0, 0], rtol=0, atol=1e-12)
        assert np.all(np.delete(p, tip) == 0)
        assert m.field_data["TimeValue"][0] == t
        assert m.field_data["contact_node"].tolist() == [tip]
        assert m.field_data["contact_gap"].tolist() == [GAP]
        np.testing.assert_allclose(m.field_data["period"], [T])
    # the tip reaches the stop: the written field really is the solution, not zeros
    tip_w = [meshio.read(pvd.parent / f).point_data["displacement"][tip, 1] for _, f in entries]
    assert max(tip_w) > 0.5 * GAP


def test_scale_and_model_from_solution(cantilever_nnm, tmp_path):
    _, _, red, nnm = cantilever_nnm
    sol = nnm[2]
    pvd = write_animation(sol, None, str(tmp_path / "s.pvd"), n_frames=2, scale=50.0)
    assert pvd.name == "s.pvd"
    m = meshio.read(tmp_path / "s_0001.vtu")
    np.testing.assert_allclose(m.point_data["displacement_scaled"], 50.0 * m.point_data["displacement"])
    assert m.field_data["scale"][0] == 50.0


def test_full_model_solution(tmp_path):
    mesh = fm.line_mesh(1.0, 8, boundaries={"clamp": 0.0, "tip": 1.0})
    beam = fm.beam(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    model = beam.with_contact(fm.UnilateralContact(at="tip", gap=GAP))
    nnm = fm.nonlinear_mode(model, 1, energy=(1e-4, 3e-4), harmonics=fm.Harmonics(3))
    sol = nnm[-1]
    pvd = write_animation(sol, model, tmp_path / "full", n_frames=3)
    t, name = read_pvd(pvd)[1]
    m = meshio.read(tmp_path / name)
    full = model.mesh_map.full_field(sol.displacement([t]))[0]
    np.testing.assert_allclose(m.point_data["displacement"][:, 1], full[beam.fe.nodal[0]], atol=1e-12, rtol=0)


def test_bar_displacement_along_x(tmp_path):
    mesh = fm.line_mesh(1.0, 6, boundaries={"clamp": 0.0, "tip": 1.0})
    bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    modes = fm.linear_modes(bar, 2)
    pvd = write_linear_mode(modes, bar, tmp_path / "bar", n_frames=4, mode=1)
    entries = read_pvd(pvd)
    T = 2 * np.pi / modes.omega[0]
    assert [t for t, _ in entries] == [j * T / 4 for j in range(4)]
    m = meshio.read(tmp_path / entries[0][1])
    assert "rotation" not in m.point_data
    d = m.point_data["displacement"]
    phi = bar.mesh_map.full_field(modes.shapes[:, 0])[bar.fe.nodal[0]]
    np.testing.assert_allclose(d[:, 0], phi, atol=1e-12, rtol=0)
    assert np.all(d[:, 1:] == 0)
    assert np.all(m.point_data["contact_force"] == 0)
    # quarter period: u = phi cos(pi/2) ~ 0, velocity = -w phi
    m1 = meshio.read(tmp_path / entries[1][1])
    np.testing.assert_allclose(m1.point_data["displacement"][:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(m1.point_data["velocity"][:, 0], -modes.omega[0] * phi, rtol=1e-12, atol=1e-12)


def test_linear_mode_of_reduced_model(cantilever_nnm, tmp_path):
    beam, _, red, _ = cantilever_nnm
    modes = fm.linear_modes(red, 3)
    pvd = write_linear_mode(modes, red, tmp_path / "lin" / "m2", n_frames=5, scale=2.0, mode=2)
    entries = read_pvd(pvd)
    assert len(entries) == 5
    m = meshio.read(pvd.parent / entries[0][1])
    phi = red.mesh_map.full_field(modes.shapes[:, 1])
    np.testing.assert_allclose(m.point_data["displacement"][:, 1], phi[beam.fe.nodal[0]], atol=1e-12, rtol=0)
    assert m.field_data["contact_gap"].tolist() == [GAP]


def test_frame_names_widen_for_many_frames(cantilever_nnm, tmp_path):
    _, _, red, nnm = cantilever_nnm
    write_animation(nnm[0], red, tmp_path / "w", n_frames=12)
    assert (tmp_path / "w_0011.vtu").is_file()


def test_bad_input(cantilever_nnm, tmp_path):
    beam, model, red, nnm = cantilever_nnm
    sol = nnm[-1]
    for bad in (1, 0):  # too few frames
        with pytest.raises(ValueError, match="n_frames must be an integer >= 2"):
            write_animation(sol, red, tmp_path / "x", n_frames=bad)
    for bad in (2.5, True, "6"):  # not an integer: a type error, as everywhere in femodes
        with pytest.raises(TypeError, match="n_frames must be an integer >= 2"):
            write_animation(sol, red, tmp_path / "x", n_frames=bad)
    with pytest.raises(TypeError, match="solution"):
        write_animation(nnm, red, tmp_path / "x")
    with pytest.raises(TypeError, match="model"):
        write_animation(sol, "model", tmp_path / "x")
    with pytest.raises(ValueError, match="DOFs"):
        write_animation(sol, model, tmp_path / "x")  # the parent, not the model solved on
    with pytest.raises(TypeError, match="path"):
        write_animation(sol, red, 3)
    with pytest.raises(ValueError, match="scale"):
        write_animation(sol, red, tmp_path / "x", scale=0.0)
    with pytest.raises(TypeError, match="scale"):
        write_animation(sol, red, tmp_path / "x", scale="big")
    modes = fm.linear_modes(beam, 2)
    with pytest.raises(ValueError, match=r"mode=3 is out of range.*mode=1 \.\. 2"):
        write_linear_mode(modes, beam, tmp_path / "x", mode=3)
    with pytest.raises(ValueError, match="mode must be an integer >= 1"):
        write_linear_mode(modes, beam, tmp_path / "x", mode=0)
    with pytest.raises(ValueError, match="model"):
        write_linear_mode(modes, None, tmp_path / "x")
    with pytest.raises(TypeError, match="modes"):
        write_linear_mode(sol, beam, tmp_path / "x")
    assert not list(tmp_path.glob("x*"))


def test_loaded_branch_needs_model(cantilever_nnm, tmp_path):
    _, _, red, nnm = cantilever_nnm
    nnm.save(tmp_path / "b.npz")
    loaded = fm.load_branch(tmp_path / "b.npz")
    with pytest.raises(ValueError, match="attach"):
        write_animation(loaded[1], None, tmp_path / "x")
    pvd = write_animation(loaded[1], red, tmp_path / "ok", n_frames=2)
    assert pvd.is_file()


def test_discrete_model_is_rejected(tmp_path):
    M = np.eye(2)
    K = np.array([[2.0, -1.0], [-1.0, 2.0]])
    model = fm.StructuralModel(M=M, K=K).with_contact(fm.UnilateralContact(at=0, gap=0.1))
    nnm = fm.nonlinear_mode(model, 1, energy=(1e-3, 2e-3), harmonics=fm.Harmonics(3))
    with pytest.raises(ValueError, match=re.escape("no mesh")):
        write_animation(nnm[0], model, tmp_path / "x")
    with pytest.raises(ValueError, match="no mesh"):
        write_linear_mode(fm.linear_modes(model, 1), model, tmp_path / "x")


def test_animation_carries_the_floquet_multipliers(tmp_path):
    """A solution of a branch with stability writes its multipliers and stability as field data."""
    mesh = fm.line_mesh(1.0, 6, boundaries={"clamp": 0.0, "tip": 1.0})
    model = (fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
             .with_damping(beta=0.01).with_forcing(fm.HarmonicForce(at="tip", amplitude=0.02))
             .with_contact(fm.PenaltyContact(at="tip", gap=0.02, stiffness=5.0)))
    br = fm.frequency_response(model, (1.4, 1.6), 3, stability=fm.stability_methods.Hill())
    sol = br[1]
    assert sol.stable == bool(br.stable[1]) and sol.multipliers.size == 2 * model.n_dofs
    pvd = write_animation(sol, model, tmp_path / "m", n_frames=2)
    m = meshio.read(pvd.parent / "m_0000.vtu")
    np.testing.assert_array_equal(m.field_data["floquet_multipliers_real"], sol.multipliers.real)
    np.testing.assert_array_equal(m.field_data["floquet_multipliers_imag"], sol.multipliers.imag)
    assert m.field_data["stable"].tolist() == [int(sol.stable)]
    # without stability: no such field data
    plain = fm.frequency_response(model, (1.4, 1.6), 3)[1]
    m2 = meshio.read(write_animation(plain, model, tmp_path / "p", n_frames=2).parent / "p_0000.vtu")
    assert "stable" not in m2.field_data


def test_series_state_units_and_contact_quality(cantilever_nnm, tmp_path):
    """Units in the field data (as array names: meshio reads no VTK strings), the contact quality
    of the solution, and a note when the truncated law penetrates or pulls."""
    _, _, model, branch = cantilever_nnm
    sol = branch[len(branch) - 1]
    pvd = write_animation(sol, model, tmp_path / "si", n_frames=4, units="SI")
    m = meshio.read(tmp_path / read_pvd(pvd)[0][1])
    assert m.field_data["unit displacement: m"][0] == 1 and m.field_data["unit contact_pressure: Pa"][0] == 1
    assert m.field_data["max_penetration"][0] == pytest.approx(sol.penetration, rel=1e-12)
    assert m.field_data["max_tension"][0] == pytest.approx(sol.tension, rel=1e-12)
    assert m.field_data["harmonics"][0] == sol.harmonics.n_harmonics
    notes = [k for k in m.field_data if k.startswith("note:")]
    assert (len(notes) == 1) == (sol.penetration > 0 or sol.tension > 0)
    pvd = write_animation(sol, model, tmp_path / "plain", n_frames=4)
    m = meshio.read(tmp_path / read_pvd(pvd)[0][1])
    assert any(k.startswith("units: those of the model") for k in m.field_data)
    pvd = write_animation(sol, model, tmp_path / "own", n_frames=4, units={"displacement": "mm"})
    assert "unit displacement: mm" in meshio.read(tmp_path / read_pvd(pvd)[0][1]).field_data
    with pytest.raises(ValueError, match="units must be"):
        write_animation(sol, model, tmp_path / "bad", n_frames=4, units="imperial")


def test_linear_mode_series_state_units(tmp_path):
    """write_linear_mode takes ``units`` as write_animation does, and says the shape is
    mass-normalised."""
    mesh = fm.line_mesh(1.0, 4, boundaries={"clamp": 0.0, "tip": 1.0})
    bar = fm.bar(mesh, fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="clamp")
    modes = fm.linear_modes(bar, 1)
    pvd = write_linear_mode(modes, bar, tmp_path / "si", n_frames=2, units="SI")
    fd = meshio.read(tmp_path / read_pvd(pvd)[0][1]).field_data
    assert fd["unit displacement: m"][0] == 1
    assert any(k.startswith("note: linear mode shape, mass-normalised") for k in fd)
    with pytest.raises(ValueError, match="units must be"):
        write_linear_mode(modes, bar, tmp_path / "bad", n_frames=2, units=3)
