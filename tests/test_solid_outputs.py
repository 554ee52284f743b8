"""Outputs of meshed solids (issue 15 item 3): mesh fields, ParaView series, rendering and the
contact-pressure map for 2-D and 3-D solids, P1 and P2, full and Craig-Bampton models.

The solutions are cheap forced responses of a strip/bar clamped on "left" that hits a stop on
"right" (one contact per boundary node, gap varying across the face), two continuation points,
three harmonics: accuracy is beside the point here, the outputs must carry exactly the solution.
"""

import importlib.util
import math
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import femodes as fm
from femodes.fields import VTK_QUADRATIC_NODES, mesh_fields, tributary_measure

HAS_RENDER = importlib.util.find_spec("pyvista") is not None and importlib.util.find_spec("imageio") is not None

#: name -> (mesh, order, options): 2-D Q1 (thickness 0.5), 2-D P2 triangles, 3-D Q1 hexahedra,
#: 3-D P2 tetrahedra
CASES = {
    "quad-P1": (lambda: fm.rectangle_mesh(1.0, 0.1, 6, 2, quadrilaterals=True), 1, {"thickness": 0.5}),
    "tri-P2": (lambda: fm.rectangle_mesh(1.0, 0.1, 4, 2), 2, {}),
    "hex-P1": (lambda: fm.box_mesh(1.0, 0.2, 0.1, 3, 2, 1, hexahedra=True), 1, {}),
    "tet-P2": (lambda: fm.box_mesh(1.0, 0.2, 0.1, 2, 1, 1), 2, {}),
}
CELLS = {"quad-P1": ("quad", 12), "tri-P2": ("triangle6", 16), "hex-P1": ("hexahedron", 6), "tet-P2": ("tetra10", 12)}


def stop_model(name):
    make, order, kw = CASES[name]
    mesh = make()
    dim = mesh.p.shape[0]
    model = fm.solid(mesh, fm.Material(E=1.0, rho=1.0, nu=0.0), clamped="left", order=order, **kw)
    direction = (1.0, 0.0) if dim == 2 else (1.0, 0.0, 0.0)
    return (model.with_damping(beta=1e-3)
            .with_forcing(fm.HarmonicForce(at=("right", "u_x"), amplitude=0.02))
            .with_contact(fm.UnilateralContact(at="right", gap=lambda x: 0.01 + 0.02 * x[1], direction=direction)))


def solve(model):
    frc = fm.frequency_response(model, omega=(1.2, 1.8), harmonics=3,
                                options=fm.ContinuationOptions(step=0.05, max_step=0.2, max_points=2))
    assert frc.converged[0]
    sol = frc[0]
    assert sol.contact_force(np.linspace(0.0, sol.period, 8)).max() > 1e-3  # the stop is hit
    return sol


@pytest.fixture(scope="module")
def solved():
    out = {}
    for name in CASES:
        model = stop_model(name)
        out[name] = (model, solve(model))
    return out


def read_pvd(path):
    root = ET.parse(path).getroot()
    return [(float(d.attrib["timestep"]), d.attrib["file"]) for d in root.iter("DataSet")]


def nodal_reference(parent, q):
    """Displacement vectors at the nodes through the DofMap (node, component) -> DOF table: an
    independent route from model DOFs to nodes (constrained components zero)."""
    nd = np.asarray(parent.dofmap.node_dof)
    out = np.zeros(q.shape[:-1] + (nd.shape[0], 3))
    held = nd < 0
    out[..., : nd.shape[1]] = np.where(held, 0.0, q[..., np.where(held, 0, nd)])
    return out


def signed_measure(points, cells, cell_type):
    """Area (2-D) or volume sign of every cell from its VTK vertices (a corner Jacobian)."""
    P = points[cells]
    if cell_type.startswith(("triangle", "quad")):
        a, b = P[:, 1] - P[:, 0], P[:, 2 if cell_type.startswith("tri") else 3] - P[:, 0]
        return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    third = 2 if cell_type.startswith("tetra") else 3
    top = 3 if cell_type.startswith("tetra") else 4
    return np.einsum("nd,nd->n", np.cross(P[:, 1] - P[:, 0], P[:, third] - P[:, 0]), P[:, top] - P[:, 0])


# -- cells -----------------------------------------------------------------------------------------
def test_quadratic_node_tables_match_vtk():
    """The VTK node order the writer uses: each node after the vertices is the mean of the listed
    vertices, checked against VTK's own parametric coordinates of the cell."""
    vtk = pytest.importorskip("vtk")
    classes = {"triangle6": vtk.vtkQuadraticTriangle, "quad9": vtk.vtkBiQuadraticQuad,
               "tetra10": vtk.vtkQuadraticTetra, "hexahedron27": vtk.vtkTriQuadraticHexahedron}
    for name, cls in classes.items():
        cell = cls()
        n = cell.GetNumberOfPoints()
        pc = np.array([cell.GetParametricCoords()[i] for i in range(3 * n)]).reshape(n, 3)
        higher = VTK_QUADRATIC_NODES[name]
        nv = n - len(higher)
        np.testing.assert_array_equal(np.array([pc[list(s)].mean(axis=0) for s in higher]), pc[nv:], err_msg=name)


@pytest.mark.parametrize("name", list(CASES))
def test_series_carries_the_solution(name, solved, tmp_path):
    model, sol = solved[name]
    n = 4
    pvd = fm.io.write_animation(sol, model, tmp_path / name, n_frames=n, scale=5.0)
    entries = read_pvd(pvd)
    T = sol.period
    assert [t for t, _ in entries] == [j * T / n for j in range(n)]
    fe, groups = model.fe, model.dofmap.groups
    dim = fe.dim
    cell_type, n_cells = CELLS[name]
    X = np.zeros((fe.nodal.shape[1], 3))
    X[:, :dim] = fe.node_coordinates.T
    right = np.asarray(groups["right"])
    # the tributary measure of the "right" face: length x thickness (2-D), area (3-D)
    face = 0.1 * 0.5 if name == "quad-P1" else (0.1 if dim == 2 else 0.2 * 0.1)
    total_force = sol.contact_force([t for t, _ in entries]).sum(axis=1)
    assert total_force.max() > 0
    for j, (t, fname) in enumerate(entries):
        m = meshio.read(pvd.parent / fname)
        assert [(c.type, len(c.data)) for c in m.cells] == [(cell_type, n_cells)]
        np.testing.assert_array_equal(m.points, X)
        cells = m.cells[0].data
        assert np.unique(cells).size == X.shape[0]  # every node (P2 mid-side nodes too) is in a cell
        assert np.all(signed_measure(m.points, cells, cell_type) > 0)  # VTK orientation
        if cell_type in VTK_QUADRATIC_NODES:  # higher nodes where VTK expects them (straight cells)
            nv = cells.shape[1] - len(VTK_QUADRATIC_NODES[cell_type])
            for k, s in enumerate(VTK_QUADRATIC_NODES[cell_type]):
                np.testing.assert_allclose(m.points[cells[:, nv + k]], m.points[cells[:, list(s)]].mean(axis=1),
                                           atol=1e-14)
        u = nodal_reference(model, sol.displacement([t]))[0]
        v = nodal_reference(model, sol.velocity([t]))[0]
        np.testing.assert_allclose(m.point_data["displacement"], u, rtol=0, atol=1e-13 * np.abs(u).max())
        np.testing.assert_allclose(m.point_data["velocity"], v, rtol=0, atol=1e-13 * np.abs(v).max())
        np.testing.assert_allclose(m.point_data["displacement_scaled"], 5.0 * m.point_data["displacement"])
        # contact force: -p along +x at the contact nodes, summing to the solution's total
        f = m.point_data["contact_force"]
        nodes = m.field_data["contact_node"]
        assert sorted(nodes.tolist()) == sorted(right.tolist())  # one contact per node of "right"
        np.testing.assert_array_equal(m.field_data["contact_direction"], np.tile([1.0, 0.0, 0.0], (nodes.size, 1)))
        assert np.all(f[:, 1:] == 0) and np.all(np.delete(f[:, 0], nodes) == 0)
        np.testing.assert_allclose(-f[:, 0].sum(), total_force[j], rtol=1e-12, atol=1e-15)
        # pressure: zero off the contact boundary, integral over the tributary measures = total force
        pressure, a = m.point_data["contact_pressure"], m.field_data["contact_measure"]
        assert np.all(np.delete(pressure, nodes) == 0)
        np.testing.assert_allclose(pressure[nodes] * a, -f[nodes, 0], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose((pressure[nodes] * a).sum(), total_force[j], rtol=1e-12, atol=1e-15)
    # tributary measures: positive, summing to the face measure; equal to the consistent weights
    # int N_k ds = group_weight x face (an independent assembly in fm.solid) except at the vertices
    # of P2 triangle facets, where the consistent weight is zero
    assert np.all(a > 0)
    assert a.sum() == pytest.approx(face, rel=1e-12)
    w = dict(zip(right.tolist(), np.asarray(model.dofmap.group_weights["right"]) * face))
    consistent = np.array([w[int(k)] for k in nodes])
    if name == "tet-P2":
        # the 4 vertices of the face: zero up to round-off (exact values: the test below)
        assert np.count_nonzero(consistent < 1e-12 * consistent.max()) == 4
    else:
        np.testing.assert_allclose(a, consistent, rtol=1e-12)
    # the obstacle points x_node + scale * gap(y) * e_x of the renderer and of ParaView's field data
    fields = mesh_fields(sol, model, n_frames=2)
    obstacle = fields.obstacle_points(scale=5.0)
    Xc = X[fields.contact_nodes]
    np.testing.assert_allclose(obstacle, Xc + np.outer(5.0 * (0.01 + 0.02 * Xc[:, 1]), [1.0, 0.0, 0.0]), rtol=1e-14)
    np.testing.assert_allclose(m.field_data["contact_gap"], 0.01 + 0.02 * Xc[:, 1], rtol=1e-14)


def test_reduced_model_expands_to_the_full_mesh(tmp_path):
    model = stop_model("quad-P1")
    rom = fm.craig_bampton(model, 4)
    sol = solve(rom)
    pvd = fm.io.write_animation(sol, rom, tmp_path / "rom", n_frames=3)
    f = mesh_fields(sol, rom, n_frames=3)
    assert f.kind == "solid" and f.dim == 2 and f.n_nodes == model.fe.nodal.shape[1] == 21
    for j, (t, fname) in enumerate(read_pvd(pvd)):
        m = meshio.read(pvd.parent / fname)
        assert m.points.shape == (21, 3) and m.cells[0].type == "quad" and len(m.cells[0].data) == 12
        u = nodal_reference(model, rom.expand(sol.displacement([t])))[0]
        np.testing.assert_allclose(m.point_data["displacement"], u, rtol=0, atol=1e-13 * np.abs(u).max())
        total = sol.contact_force([t])[0].sum()
        np.testing.assert_allclose(-m.point_data["contact_force"][:, 0].sum(), total, rtol=1e-12, atol=1e-15)
        nodes, a = m.field_data["contact_node"], m.field_data["contact_measure"]
        np.testing.assert_allclose((m.point_data["contact_pressure"][nodes] * a).sum(), total, rtol=1e-12, atol=1e-15)


def test_linear_mode_of_a_quadratic_hexahedron_mesh(tmp_path):
    model = fm.solid(fm.box_mesh(1.0, 0.2, 0.1, 2, 1, 1, hexahedra=True), fm.Material(E=1.0, rho=1.0),
                     clamped="left", order=2)
    modes = fm.linear_modes(model, 2)
    pvd = fm.io.write_linear_mode(modes, model, tmp_path / "hex27", n_frames=4, mode=2)
    entries = read_pvd(pvd)
    # frame times to round-off (a few ulps: the period and its fractions are computed in a different order)
    assert [t for t, _ in entries] == pytest.approx([j * 2 * math.pi / modes.omega[1] / 4 for j in range(4)],
                                                    rel=16 * np.finfo(float).eps)
    m = meshio.read(pvd.parent / entries[0][1])
    cells = m.cells[0].data
    assert m.cells[0].type == "hexahedron27" and cells.shape == (2, 27) and m.points.shape == (5 * 3 * 3, 3)
    assert np.all(signed_measure(m.points, cells, "hexahedron27") > 0)
    for k, s in enumerate(VTK_QUADRATIC_NODES["hexahedron27"]):
        np.testing.assert_allclose(m.points[cells[:, 8 + k]], m.points[cells[:, list(s)]].mean(axis=1), atol=1e-14)
    phi = nodal_reference(model, modes.shapes[:, 1])
    np.testing.assert_allclose(m.point_data["displacement"], phi, rtol=0, atol=1e-13 * np.abs(phi).max())
    assert np.all(m.point_data["contact_force"] == 0) and np.all(m.point_data["contact_pressure"] == 0)
    m1 = meshio.read(pvd.parent / entries[1][1])  # a quarter period: u ~ 0, v = -w phi
    np.testing.assert_allclose(m1.point_data["velocity"], -modes.omega[1] * phi, rtol=1e-12, atol=1e-12)


def test_tributary_measure_of_p2_tetrahedra_is_positive():
    """P2 triangle facets: the consistent weight of a vertex is zero (no pressure would be
    defined there), the lumped tributary measure is positive and sums to the face area."""
    model = fm.solid(fm.box_mesh(1.0, 0.2, 0.1, 2, 2, 1), fm.Material(E=1.0, rho=1.0), order=2)
    nodes, a = tributary_measure(model, "right")
    np.testing.assert_array_equal(nodes, model.dofmap.groups["right"])
    with pytest.raises(ValueError, match="unknown boundary 'tip'; the mesh has 'back', 'bottom', 'front', 'left'"):
        tributary_measure(model, "tip")
    bar = fm.bar(fm.line_mesh(1.0, 4), fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0))
    with pytest.raises(ValueError, match="model must be a meshed solid"):
        tributary_measure(bar, "right")
    w = np.asarray(model.dofmap.group_weights["right"])
    vertex = w < 1e-12 * w.max()  # zero up to round-off
    assert np.count_nonzero(vertex) == 6 and np.all(a > 0)
    assert a.sum() == pytest.approx(0.2 * 0.1, rel=1e-12)
    # exact values: the face is 2 squares 0.1 x 0.1 of 2 right triangles each (area 0.005); the
    # diagonal of the P2 triangle mass matrix is A (6, 6, 6, 32, 32, 32) / 180, so a vertex gets
    # 6/114 A per triangle it belongs to and a mid-side node 32/114 A per triangle: 16/57 A on the
    # 6 edges of the face's border, 32/57 A on the 3 edges shared by two triangles
    A = 0.005
    np.testing.assert_allclose(np.sort(a[~vertex]) / A, [16 / 57] * 6 + [32 / 57] * 3, rtol=1e-12)
    mesh = model.fe.mesh
    triangles = np.asarray(mesh.facets)[:, mesh.boundaries["right"]]  # vertex nodes = mesh vertices
    per_vertex = np.array([np.count_nonzero(triangles == v) for v in nodes[vertex]])
    assert per_vertex.sum() == 12
    np.testing.assert_allclose(a[vertex] / A, per_vertex * 6 / 114, rtol=1e-12)


# -- rendering -------------------------------------------------------------------------------------
@pytest.mark.skipif(not HAS_RENDER, reason="pyvista/imageio not installed (pip install 'femodes[render]')")
@pytest.mark.parametrize("name, scalars", [("tri-P2", "displacement"), ("quad-P1", "contact_pressure"),
                                           ("hex-P1", "contact_pressure")])
def test_animate_writes_a_gif(name, scalars, solved, tmp_path):
    import imageio.v3 as iio

    from femodes.viz import AnimationStyle, animate

    model, sol = solved[name]
    n = 3
    path = animate(sol, model, tmp_path / f"{name}.gif", n_frames=n,
                   style=AnimationStyle(window_size=(240, 144), scalars=scalars))
    frames = iio.imread(path, index=None)
    assert frames.shape == (n, 144, 240, 3)
    assert min(np.abs(frames[k].astype(int) - frames[0].astype(int)).sum() for k in range(1, n)) > 0  # it moves
    assert frames[0].std() > 5  # not blank


def test_animate_errors(solved):
    from femodes.viz import AnimationStyle, animate

    with pytest.raises(ValueError, match="scalars must be 'displacement' or 'contact_pressure'"):
        AnimationStyle(scalars="pressure")
    with pytest.raises(TypeError, match="pressure_cmap must be a colormap name"):
        AnimationStyle(pressure_cmap=3)
    bar = fm.bar(fm.line_mesh(1.0, 4), fm.Material(E=1.0, rho=1.0), fm.Section(area=1.0), clamped="left")
    with pytest.raises(ValueError, match="contact_pressure' needs a meshed solid"):
        animate(fm.linear_modes(bar, 1), bar, "x.gif", mode=1, style=AnimationStyle(scalars="contact_pressure"))


# -- contact-pressure map --------------------------------------------------------------------------
def test_contact_pressure_map_2d(solved):
    from matplotlib.collections import QuadMesh

    model, sol = solved["tri-P2"]
    n = 16
    fig = fm.plot.contact_pressure(sol, model, n_frames=n)
    assert len(fig.axes) == 3
    ax, side, cbar = fig.axes
    assert ax.get_xlabel() == "s: arc length along 'right'" and ax.get_ylabel() == "t / T"
    assert side.get_title() == "total force" and cbar.get_ylabel() == "contact pressure"
    (quad,) = [c for c in ax.collections if isinstance(c, QuadMesh)]
    # the arc length along the straight right edge is the distance from its end: y or 0.1 - y
    right = np.asarray(model.dofmap.groups["right"])
    y = np.sort(model.fe.node_coordinates[1, right])
    # one band per node: edges at the ends and half-way between nodes
    s = np.unique(quad.get_coordinates()[..., 0])
    edges = [np.concatenate([[v[0]], 0.5 * (v[:-1] + v[1:]), [v[-1]]]) for v in (y, np.sort(0.1 - y))]
    assert any(np.allclose(s, e, atol=1e-14) for e in edges)
    # total force panel: the solution's contact forces over one closed period
    t = np.arange(n) * sol.period / n
    total = sol.contact_force(t).sum(axis=1)
    line = side.get_lines()[0]
    np.testing.assert_allclose(line.get_xdata(), np.append(total, total[0]), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(line.get_ydata(), np.append(np.arange(n) / n, 1.0))
    # the map's largest value is the largest nodal force / tributary measure
    f = mesh_fields(sol, model, n_frames=n)
    peak = (f.contact_force / f.contact_measure).max()
    assert quad.get_array().max() == pytest.approx(peak, rel=1e-12)
    # drawn into given axes: the map keeps them
    import matplotlib.pyplot as plt

    fig2, given = plt.subplots()
    assert fm.plot.contact_pressure(sol, model, ax=given, n_frames=4) is fig2 and fig2.axes[0] is given
    plt.close("all")


def test_contact_pressure_map_3d(solved):
    import matplotlib.pyplot as plt
    from matplotlib.collections import QuadMesh

    model, sol = solved["hex-P1"]
    fig = fm.plot.contact_pressure(sol, model, boundary="right", n_frames=8)
    ax = fig.axes[0]
    assert "principal axis of 'right'" in ax.get_xlabel()
    (quad,) = [c for c in ax.collections if isinstance(c, QuadMesh)]
    # the right face is 0.2 (y) x 0.1 (z) with 2 x 1 elements: three columns along y (nodes at 0,
    # 0.1, 0.2: bands with edges half-way), max over z
    np.testing.assert_allclose(np.unique(quad.get_coordinates()[..., 0]), [0.0, 0.05, 0.15, 0.2], atol=1e-14)
    values = quad.get_array().reshape(9, 3)
    f = mesh_fields(sol, model, n_frames=8)
    p = f.contact_force / f.contact_measure
    y = f.coordinates[f.contact_nodes, 1]
    for k, yk in enumerate(np.unique(np.round(y, 12))):
        col = p[:, np.isclose(y, yk)].max(axis=1)
        np.testing.assert_allclose(values[:8, k], col, rtol=1e-12)
    plt.close("all")


def test_contact_pressure_errors(solved):
    import matplotlib.pyplot as plt

    model, sol = solved["quad-P1"]
    with pytest.raises(ValueError, match=r"unknown boundary 'tip'; the mesh has 'bottom', 'left', 'right', 'top' "
                                         r"\(contacts on 'right'\)"):
        fm.plot.contact_pressure(sol, model, boundary="tip")
    with pytest.raises(ValueError, match="boundary 'top' carries no contacts; contacts are on 'right'"):
        fm.plot.contact_pressure(sol, model, boundary="top")
    with pytest.raises(TypeError, match="boundary must be the name of a boundary"):
        fm.plot.contact_pressure(sol, model, boundary=1)
    with pytest.raises(ValueError, match="n_frames"):
        fm.plot.contact_pressure(sol, model, n_frames=1)
    with pytest.raises(TypeError, match="PeriodicSolution"):
        fm.plot.contact_pressure(fm.linear_modes(model, 1), model)
    # a solid without contacts
    free = fm.solid(fm.rectangle_mesh(1.0, 0.1, 4, 1, quadrilaterals=True), fm.Material(E=1.0, rho=1.0, nu=0.0),
                    clamped="left").with_damping(beta=1e-2).with_forcing(fm.HarmonicForce(at=("right", "u_x"),
                                                                                         amplitude=0.01))
    lin = fm.frequency_response(free, omega=(1.0, 1.1), harmonics=1, options=fm.ContinuationOptions(max_points=2))
    with pytest.raises(ValueError, match="no contacts on a named boundary"):
        fm.plot.contact_pressure(lin[0], free)
    # a beam: no solid mesh
    beam = fm.beam(fm.line_mesh(1.0, 6, boundaries={"clamp": 0.0, "tip": 1.0}), fm.Material(E=1.0, rho=1.0),
                   fm.Section(area=1.0, inertia=1.0), clamped="clamp")
    beam = beam.with_contact(fm.UnilateralContact(at="tip", gap=0.01))
    nnm = fm.nonlinear_mode(beam, 1, energy=(1e-4, 2e-4), harmonics=3, options=fm.ContinuationOptions(max_points=2))
    with pytest.raises(ValueError, match="needs a meshed solid"):
        fm.plot.contact_pressure(nnm[0], beam)
    # the 1-D snapshot plot refuses solids, naming the outputs that draw them
    with pytest.raises(ValueError, match="for a 2-D solid use femodes.viz.animate"):
        fm.plot.mode_shape(sol, model)
    f = mesh_fields(sol, model, n_frames=2)
    with pytest.raises(ValueError, match="use displacement_vectors"):
        f.vector(f.displacement[..., 0])
    with pytest.raises(ValueError, match="unknown boundary 'casing'; the mesh has 'bottom', 'left', 'right', 'top'"):
        f.boundary_coordinate("casing")
    plt.close("all")


def test_contact_pressure_map_says_what_truncation_costs(solved):
    """Negative pressures (drawn as 0) and penetration are said on the picture, with their size."""
    model, sol = solved["tri-P2"]
    fig = fm.plot.contact_pressure(sol, model, n_frames=16)
    notes = [t.get_text() for t in fig.axes[0].texts if "Fourier truncation" in t.get_text()]
    f = fm.fields.mesh_fields(sol, model, n_frames=16)
    leaks = bool((f.contact_force < 0).any()) or sol.penetration > 0
    assert len(notes) == int(leaks)
    if leaks:
        assert f"H = {sol.harmonics.n_harmonics}" in notes[0] and "raise the harmonics" in notes[0]
