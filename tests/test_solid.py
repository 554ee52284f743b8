"""Meshed solids (fm.solid, fm.rectangle_mesh, fm.box_mesh, gmsh meshes): patch tests, mass,
modes against beam and bar theory, convergence rates (references.md, "Solids")."""

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse.linalg as sla

import femodes as fm
from femodes.fe.mesh import named_points

MESHES = Path(__file__).resolve().parents[1] / "meshes"
E, RHO = 210.0, 7.8  # arbitrary consistent units


def lowest(model, n=1):
    """Lowest ``n`` angular frequencies (shift-invert Lanczos)."""
    w2 = sla.eigsh(model.K, n, model.M, sigma=0.0, which="LM")[0]
    return np.sort(np.sqrt(np.abs(w2)))


def full_vector(model, field):
    """Model DOF vector of a displacement field ``field(x) -> (dim, n_nodes)`` at the nodes."""
    fe = model.fe
    u = np.zeros(fe.n_full)
    vals = field(fe.node_coordinates)
    for c in range(fe.nodal.shape[0]):
        u[fe.nodal[c]] = vals[c]
    return u[fe.free]


def distorted(mesh, amount=0.25, seed=0):
    """The mesh with its interior vertices moved by up to ``amount`` times the grid spacing."""
    p = mesh.p.copy()
    boundary = np.zeros(p.shape[1], dtype=bool)
    boundary[mesh.boundary_nodes()] = True
    rng = np.random.default_rng(seed)
    h = np.array([np.min(np.diff(np.unique(x))) for x in p])
    p[:, ~boundary] += amount * h[:, None] * rng.uniform(-1, 1, size=(p.shape[0], (~boundary).sum()))
    return type(mesh)(p, mesh.t).with_boundaries({k: v for k, v in mesh.boundaries.items()})


MESH_2D = {"tri": lambda: fm.rectangle_mesh(2.0, 1.0, 4, 3), "quad": lambda: fm.rectangle_mesh(2.0, 1.0, 4, 3, quadrilaterals=True)}
MESH_3D = {"tet": lambda: fm.box_mesh(2.0, 1.0, 0.5, 3, 2, 2), "hex": lambda: fm.box_mesh(2.0, 1.0, 0.5, 2, 2, 1, hexahedra=True)}


# -- material and meshes --------------------------------------------------------------------------
def test_material_nu():
    assert fm.Material(E=1.0, rho=1.0).nu == 0.3
    lam, mu = fm.Material(E=2.6, rho=1.0, nu=0.3).lame
    assert mu == pytest.approx(1.0) and lam == pytest.approx(1.5)
    for bad in (0.5, -1.0, 0.7):
        with pytest.raises(ValueError, match="nu"):
            fm.Material(E=1.0, rho=1.0, nu=bad)
    with pytest.raises(TypeError, match="nu"):
        fm.Material(E=1.0, rho=1.0, nu="0.3")


def test_rectangle_and_box_boundaries():
    m = fm.rectangle_mesh(2.0, 0.5, 4, 2)
    assert sorted(m.boundaries) == ["bottom", "left", "right", "top"]
    assert np.allclose(m.p[0, m.facets[:, m.boundaries["right"]]], 2.0)
    assert np.allclose(m.p[1, m.facets[:, m.boundaries["top"]]], 0.5)
    b = fm.box_mesh(1.0, 0.2, 0.1, 3, 2, 1)
    assert sorted(b.boundaries) == ["back", "bottom", "front", "left", "right", "top"]
    for name, axis, value in (("front", 1, 0.0), ("back", 1, 0.2), ("bottom", 2, 0.0), ("top", 2, 0.1)):
        assert np.allclose(b.p[axis, b.facets[:, b.boundaries[name]]], value)
    with pytest.raises(ValueError, match="height"):
        fm.rectangle_mesh(1.0, -1.0, 2, 2)
    with pytest.raises(TypeError, match="nx"):
        fm.box_mesh(1.0, 1.0, 1.0, 2.5, 1, 1)


# -- patch tests ------------------------------------------------------------------------------------
def rigid_fields(dim):
    if dim == 2:
        return [lambda x: np.vstack([np.ones_like(x[0]), 0 * x[0]]), lambda x: np.vstack([0 * x[0], np.ones_like(x[0])]),
                lambda x: np.vstack([-x[1], x[0]])]
    return [lambda x, c=c: np.eye(3)[c][:, None] * np.ones_like(x[0]) for c in range(3)] + [
        lambda x: np.vstack([-x[1], x[0], 0 * x[0]]), lambda x: np.vstack([0 * x[0], -x[2], x[1]]),
        lambda x: np.vstack([x[2], 0 * x[0], -x[0]])]


@pytest.mark.parametrize("kind", ["tri", "quad", "tet", "hex"])
@pytest.mark.parametrize("order", [1, 2])
def test_rigid_motion_has_no_elastic_force(kind, order):
    mesh = {**MESH_2D, **MESH_3D}[kind]()
    model = fm.solid(distorted(mesh), fm.Material(E=E, rho=RHO, nu=0.3), order=order)
    scale = abs(model.K).max()
    for field in rigid_fields(mesh.dim()):
        u = full_vector(model, field)
        assert np.abs(model.K @ u).max() < 1e-10 * scale * np.abs(u).max()


@pytest.mark.parametrize("kind", ["tri", "quad"])
@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("plane", ["stress", "strain"])
def test_uniaxial_stress_patch_2d(kind, order, plane):
    """u = (eps x, -nu' eps y) is uniaxial stress: no force inside, reaction sigma H t on each end."""
    nu, eps, t, H = 0.3, 1e-3, 0.2, 1.0
    model = fm.solid(distorted(MESH_2D[kind]()), fm.Material(E=E, rho=RHO, nu=nu), plane=plane, thickness=t, order=order)
    if plane == "stress":
        sigma, lateral = E * eps, nu
    else:  # eps_zz = 0, sigma_yy = 0
        sigma, lateral = E * eps / (1 - nu**2), nu / (1 - nu)
    f = model.K @ full_vector(model, lambda x: np.vstack([eps * x[0], -lateral * eps * x[1]]))
    dm = model.dofmap
    ux = dm.node_dof[:, 0]
    left, right = dm.groups["left"], dm.groups["right"]
    assert f[ux[left]].sum() == pytest.approx(-sigma * H * t, rel=1e-10)
    assert f[ux[right]].sum() == pytest.approx(sigma * H * t, rel=1e-10)
    inside = np.setdiff1d(np.arange(dm.node_dof.shape[0]), np.concatenate([dm.groups[k] for k in dm.groups]))
    assert np.abs(f[dm.node_dof[inside]]).max() < 1e-10 * sigma * H * t


@pytest.mark.parametrize("kind", ["tet", "hex"])
@pytest.mark.parametrize("order", [1, 2])
def test_uniaxial_stress_patch_3d(kind, order):
    nu, eps = 0.25, 1e-3
    model = fm.solid(distorted(MESH_3D[kind]()), fm.Material(E=E, rho=RHO, nu=nu), order=order)
    f = model.K @ full_vector(model, lambda x: np.vstack([eps * x[0], -nu * eps * x[1], -nu * eps * x[2]]))
    dm = model.dofmap
    area = 1.0 * 0.5
    assert f[dm.node_dof[dm.groups["right"], 0]].sum() == pytest.approx(E * eps * area, rel=1e-10)
    assert f[dm.node_dof[dm.groups["left"], 0]].sum() == pytest.approx(-E * eps * area, rel=1e-10)


@pytest.mark.parametrize("kind", ["tri", "quad", "tet", "hex"])
@pytest.mark.parametrize("order", [1, 2])
def test_total_mass(kind, order):
    mesh = {**MESH_2D, **MESH_3D}[kind]()
    dim = mesh.dim()
    kw = {"thickness": 0.3} if dim == 2 else {}
    model = fm.solid(distorted(mesh), fm.Material(E=E, rho=RHO), order=order, **kw)
    expected = RHO * 2.0 * 1.0 * 0.3 if dim == 2 else RHO * 2.0 * 1.0 * 0.5
    for c in range(dim):
        r = full_vector(model, lambda x, c=c: np.eye(dim)[c][:, None] * np.ones_like(x[0]))
        assert r @ (model.M @ r) == pytest.approx(expected, rel=1e-12)


# -- modes -------------------------------------------------------------------------------------------
def test_slender_cantilever_against_euler_bernoulli():
    """Plane-stress strip L/h = 50, Q2 and P2: w1 within 0.1 % of Euler-Bernoulli.

    Shear and rotary inertia lower w1 by about 2.4e-4 here (Timoshenko: beta1^2 r^2 (1 + E/(kappa G))
    / 2 with beta1 L = 1.875, r^2 = h^2/12, kappa = 5/6), the clamped root (no Poisson contraction)
    stiffens it by a similar amount, and the discretisation error at 100 x 2 elements is 1.3e-4
    (P2 triangles) / 1.7e-5 (Q2): measured +1.7e-5 (Q2) and +1.3e-4 (P2), tolerance 1e-3.
    """
    L, h = 1.0, 0.02
    expected = 3.5160152 * np.sqrt(E * h**2 / 12 / (RHO * L**4))
    for quad in (True, False):
        model = fm.solid(fm.rectangle_mesh(L, h, 100, 2, quadrilaterals=quad), fm.Material(E=E, rho=RHO, nu=0.3),
                         clamped="left", order=2)
        assert lowest(model)[0] / expected - 1 == pytest.approx(0.0, abs=1e-3)


def test_strip_axial_mode_is_the_bar_mode():
    """nu = 0: the clamped strip has the bar's quarter-wave axial mode among its modes (measured: 1e-6)."""
    L = 1.0
    model = fm.solid(fm.rectangle_mesh(L, 0.1, 40, 2, quadrilaterals=True), fm.Material(E=E, rho=RHO, nu=0.0),
                     clamped="left", order=2)
    w = lowest(model, 6)
    expected = np.pi / 2 * np.sqrt(E / RHO) / L
    assert np.min(np.abs(w / expected - 1)) < 1e-5


@pytest.mark.parametrize("order, slope", [(1, 2.0), (2, 4.0)])
def test_axial_frequency_convergence_rate(order, slope):
    """Frequency error ~ h^2 (P1) and h^4 (P2) (measured slopes 2.01 and 4.10)."""
    L = 1.0
    expected = np.pi / 2 * np.sqrt(E / RHO) / L
    hs, errs = [], []
    for nx in (4, 8, 16, 32):
        model = fm.solid(fm.rectangle_mesh(L, 0.1, nx, 1), fm.Material(E=E, rho=RHO, nu=0.0), order=order,
                         supports={"left": ("u_x",), "bottom": ("u_y",), "top": ("u_y",)})
        hs.append(L / nx)
        errs.append(lowest(model)[0] / expected - 1)
    assert np.all(np.array(errs) > 0)  # consistent mass: frequencies from above
    fitted = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert fitted == pytest.approx(slope, abs=0.2)


def test_box_cantilever_against_beam_theory():
    """3-D square box L/H = 20, P2 tetrahedra 20 x 1 x 1: both bending modes within 1 % (measured
    +0.56 % and +0.66 %: coarse cross-section, clamped root)."""
    L, H = 1.0, 0.05
    model = fm.solid(fm.box_mesh(L, H, H, 20, 1, 1), fm.Material(E=E, rho=RHO, nu=0.3), clamped="left", order=2)
    expected = 3.5160152 * np.sqrt(E * H**2 / 12 / (RHO * L**4))
    w = lowest(model, 2)
    assert np.all(np.abs(w / expected - 1) < 1e-2)


# -- arguments ---------------------------------------------------------------------------------------
def test_solid_arguments():
    mesh2, mesh3 = fm.rectangle_mesh(1.0, 0.1, 4, 1), fm.box_mesh(1.0, 0.1, 0.1, 2, 1, 1)
    mat = fm.Material(E=1.0, rho=1.0)
    with pytest.raises(ValueError, match="2-D meshes only"):
        fm.solid(mesh3, mat, plane="stress")
    with pytest.raises(ValueError, match="2-D meshes only"):
        fm.solid(mesh3, mat, thickness=2.0)
    with pytest.raises(ValueError, match="plane"):
        fm.solid(mesh2, mat, plane="membrane")
    with pytest.raises(ValueError, match="thickness"):
        fm.solid(mesh2, mat, thickness=0.0)
    with pytest.raises(ValueError, match="order"):
        fm.solid(mesh2, mat, order=3)
    with pytest.raises(TypeError, match="mesh"):
        fm.solid(fm.line_mesh(1.0, 4), mat)
    with pytest.raises(ValueError, match="'nowhere'.*bottom"):
        fm.solid(mesh2, mat, clamped="nowhere")
    with pytest.raises(ValueError, match="u_w"):
        fm.solid(mesh2, mat, supports={"bottom": ("u_w",)})
    with pytest.raises(ValueError, match="not a node"):
        fm.solid(mesh2, mat, points={"probe": (0.1, 0.05)})


def test_supports_named_points_and_forces():
    mesh = fm.rectangle_mesh(1.0, 0.1, 4, 2)
    model = fm.solid(mesh, fm.Material(E=1.0, rho=1.0), clamped="left", supports={"bottom": "u_y"}, order=2,
                     points={"tip": (1.0, 0.05)})
    dm = model.dofmap
    assert model.fe.kind == "solid" and dm.components == ("u_x", "u_y")
    bottom = dm.groups["bottom"]
    assert np.all(dm.node_dof[bottom, 1] == -1) and np.sum(dm.node_dof[bottom, 0] >= 0) == bottom.size - 1
    assert bottom.size == 2 * 4 + 1  # P2: vertices and mid-side nodes
    assert dm.label(model.dof(("tip", "u_y"))) == "tip.u_y"
    cornered = fm.solid(mesh, fm.Material(E=1.0, rho=1.0), clamped="left", points={"corner": (0.0, 0.0)})
    with pytest.raises(ValueError, match="constrained by \"clamped='left'\""):
        cornered.dof("corner")
    with pytest.raises(ValueError, match="boundary with .* nodes"):
        model.dof(("right", "u_x"))
    # a force on a boundary is a resultant shared with the consistent weights (P2: 1/6, 2/3, 1/6 per edge)
    forced = model.with_forcing(fm.HarmonicForce(at=("right", "u_x"), amplitude=3.0))
    amps = np.array([a.item.amplitude for a in forced.forces])
    assert amps.sum() == pytest.approx(3.0) and amps.size == 5
    assert np.sort(amps)[[0, -1]] == pytest.approx([3.0 / 12, 3.0 / 3])
    # the share of a supported node (bottom-right corner, u_y) goes to the support
    held = model.with_forcing(fm.HarmonicForce(at=("right", "u_y"), amplitude=3.0))
    assert sum(a.item.amplitude for a in held.forces) == pytest.approx(3.0 - 3.0 / 12)
    one = model.with_forcing(fm.HarmonicForce(at=("tip", "u_y")))
    assert one.forces[0].dof == model.dof(("tip", "u_y"))


# -- gmsh meshes -------------------------------------------------------------------------------------
def test_gmsh_blade2d():
    mesh = fm.load_mesh(MESHES / "blade2d.msh")
    assert {"root", "tip", "top", "bottom"} <= set(mesh.boundaries)
    assert set(named_points(mesh)) == {"tip_top", "tip_mid"}
    assert "blade" in mesh.subdomains
    model = fm.solid(mesh, {"blade": fm.Material(E=E, rho=RHO)}, clamped="root", order=2)
    w = fm.linear_modes(model, 3).omega
    assert np.all(np.isfinite(w)) and np.all(w > 0)
    assert model.dof(("tip_top", "u_y")) >= 0
    assert np.allclose(model.fe.node_coordinates[:, model.dofmap.locations["tip_top"]], (1.0, 0.03))


def test_gmsh_blade3d():
    mesh = fm.load_mesh(MESHES / "blade3d.msh")
    assert {"root", "tip"} <= set(mesh.boundaries)
    assert set(named_points(mesh)) == {"tip_corner"}
    model = fm.solid(mesh, fm.Material(E=E, rho=RHO), clamped="root")
    w = fm.linear_modes(model, 3).omega
    assert np.all(np.isfinite(w)) and np.all(w > 0)
    assert np.allclose(model.fe.node_coordinates[:, model.dofmap.locations["tip_corner"]], (1.0, 0.2, 0.03))
    for f in ("blade2d.msh", "blade3d.msh"):
        assert (MESHES / f).stat().st_size < 300_000


def write_gmsh(path, points, blocks, names):
    """gmsh 2.2 file: ``blocks`` = [(cell type, connectivity, physical tag)], ``names`` = {name: (tag, dim)}."""
    import meshio

    cells = [meshio.CellBlock(t, np.asarray(c)) for t, c, _ in blocks]
    tags = [np.full(len(c), tag) for _, c, tag in blocks]
    meshio.write(path, meshio.Mesh(np.asarray(points, dtype=float), cells,
                                   cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                                   field_data={k: np.array(v) for k, v in names.items()}), file_format="gmsh22")
    return path


def test_load_quad_and_hex_meshes(tmp_path):
    """meshio/gmsh quadrilaterals and hexahedra (VTK node order, converted by scikit-fem)."""
    pts2 = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]]
    path = write_gmsh(tmp_path / "quads.msh", pts2, [
        ("quad", [[0, 1, 4, 3], [1, 2, 5, 4]], 3), ("line", [[0, 3]], 1), ("line", [[2, 5]], 2), ("vertex", [[5]], 4)],
        {"plate": (3, 2), "root": (1, 1), "tip": (2, 1), "corner": (4, 0)})
    mesh = fm.load_mesh(path)
    assert type(mesh).__name__ == "MeshQuad1" and len(mesh.boundaries["root"]) == 1
    free = fm.solid(mesh, fm.Material(E=E, rho=RHO), thickness=0.5)
    r = full_vector(free, lambda x: np.vstack([np.ones_like(x[0]), 0 * x[0]]))
    assert r @ free.M @ r == pytest.approx(RHO * 2.0 * 0.5)
    model = fm.solid(mesh, fm.Material(E=E, rho=RHO), clamped="root", thickness=0.5)
    assert model.dofmap.label(model.dof(("corner", "u_y"))) == "corner.u_y"
    z = [[x, y, 1.0] for x, y, _ in pts2]
    path = write_gmsh(tmp_path / "hexes.msh", pts2 + z, [
        ("hexahedron", [[0, 1, 4, 3, 6, 7, 10, 9], [1, 2, 5, 4, 7, 8, 11, 10]], 1), ("quad", [[0, 3, 9, 6]], 2)],
        {"block": (1, 3), "root": (2, 2)})
    mesh = fm.load_mesh(path)
    model = fm.solid(mesh, fm.Material(E=E, rho=RHO), clamped="root", order=2)
    assert len(model.dofmap.groups["root"]) == 9  # Q2 face: 4 vertices, 4 edges, 1 centre
    free = fm.solid(mesh, fm.Material(E=E, rho=RHO), order=2)
    r = full_vector(free, lambda x: np.vstack([0 * x[0], 0 * x[0], np.ones_like(x[0])]))
    assert r @ free.M @ r == pytest.approx(RHO * 2.0)
    assert np.abs(free.K @ full_vector(free, lambda x: np.vstack([-x[1], x[0], 0 * x[0]]))).max() < 1e-9
    assert np.all(fm.linear_modes(model, 2).omega > 0)


def test_load_quadratic_triangles_by_their_corners(tmp_path):
    pts = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0, 0], [1, 0.5, 0], [0.5, 0.5, 0], [0.5, 1, 0], [0, 0.5, 0]]
    path = write_gmsh(tmp_path / "tri6.msh", pts, [
        ("triangle6", [[0, 1, 2, 4, 5, 6], [0, 2, 3, 6, 7, 8]], 1), ("line3", [[0, 3, 8]], 2)],
        {"body": (1, 2), "root": (2, 1)})
    mesh = fm.load_mesh(path)
    assert mesh.p.shape == (2, 4) and len(mesh.boundaries["root"]) == 1
    model = fm.solid(mesh, fm.Material(E=E, rho=RHO), clamped="root", order=2)
    assert len(model.dofmap.groups["root"]) == 3


def test_named_set_of_points_takes_supports_and_refuses_laws(tmp_path):
    """A gmsh physical point of several vertices (the two ends of a pinned arch, "left" with its inner
    and outer corner) was dropped: clamped="left" read "the mesh has the named locations ['crown']".
    Supports now take every point of the set; a contact law or a force names the set and the fix."""
    pts = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]]
    path = write_gmsh(tmp_path / "pinned.msh", pts, [
        ("quad", [[0, 1, 4, 3], [1, 2, 5, 4]], 3), ("vertex", [[0], [3]], 1), ("vertex", [[2], [5]], 2),
        ("vertex", [[4]], 4)], {"plate": (3, 2), "left": (1, 0), "right": (2, 0), "top": (4, 0)})
    mesh = fm.load_mesh(path)
    model = fm.solid(mesh, fm.Material(E=E, rho=RHO), clamped=["left", "right"], order=2)
    fixed = {node for node, _ in model.dofmap.constrained_by}
    assert fixed == {0, 3, 2, 5} and model.n_dofs == 2 * 15 - 8  # Q2: 15 nodes, 4 pinned
    assert np.all(fm.linear_modes(model, 2).omega > 0)
    pinned = fm.solid(mesh, fm.Material(E=E, rho=RHO), supports={"left": ["u_y"]}, clamped="right")
    assert set(pinned.dofmap.constrained_by) == {(0, 1), (3, 1), (2, 0), (2, 1), (5, 0), (5, 1)}
    with pytest.raises(ValueError, match=r"'left' is a set of 2 points .* name each point alone"):
        model.with_contact(fm.UnilateralContact(at=("left", "u_y"), gap=0.1))
    with pytest.raises(ValueError, match=r"'right' is a set of 2 points"):
        model.with_forcing(fm.HarmonicForce(at="right"))
    with pytest.raises(ValueError, match=r"points\['left'\]: the name is a set of points of the mesh"):
        fm.solid(mesh, fm.Material(E=E, rho=RHO), points={"left": (1.0, 1.0)})
    assert model.dofmap.label(model.dof(("top", "u_y"))) == "top.u_y"  # a single point stays a location
