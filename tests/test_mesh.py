"""Tests for femodes.fe.mesh (line_mesh, load_mesh) and the shipped meshes."""
from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path

import meshio
import numpy as np
import pytest
import skfem
from hypothesis import given, settings
from hypothesis import strategies as st
from skfem import Basis, ElementLineHermite, ElementLineP1

from femodes.fe.mesh import line_mesh, load_mesh

MESHES = Path(__file__).resolve().parents[1] / "meshes"


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------
def assert_canonical(m):
    """Vertices sorted, element e joins e and e+1, facet index == vertex index."""
    assert isinstance(m, skfem.MeshLine)
    n = m.nelements
    assert m.p.shape == (1, n + 1)
    assert np.all(np.diff(m.p[0]) > 0)
    np.testing.assert_array_equal(m.t, np.vstack((np.arange(n), np.arange(1, n + 1))))
    np.testing.assert_array_equal(m.facets[0], np.arange(n + 1))
    np.testing.assert_array_equal(m.boundary_facets(), [0, n])
    assert isinstance(m.subdomains, dict)
    assert m.boundaries["left"].tolist() == [0]
    assert m.boundaries["right"].tolist() == [n]
    for v in m.boundaries.values():
        assert v.dtype == np.int32
    for v in m.subdomains.values():
        assert v.dtype == np.int32
        assert np.all(np.diff(v) > 0)


def to_meshio(m, *, point_dim=3):
    """Write a named MeshLine as a meshio mesh with gmsh physical groups."""
    x = m.p[0]
    pts = np.zeros((x.size, point_dim))
    pts[:, 0] = x
    cells, phys, field = [], [], {}
    tag = 0
    for name, verts in m.boundaries.items():
        tag += 1
        cells.append(meshio.CellBlock("vertex", np.asarray(verts).reshape(-1, 1)))
        phys.append(np.full(len(verts), tag))
        field[name] = np.array([tag, 0])
    for name, elems in m.subdomains.items():
        tag += 1
        cells.append(meshio.CellBlock("line", m.t[:, elems].T))
        phys.append(np.full(len(elems), tag))
        field[name] = np.array([tag, 1])
    rest = np.setdiff1d(np.arange(m.nelements),
                        np.concatenate([np.zeros(0, int), *m.subdomains.values()]))
    if rest.size:
        tag += 1
        cells.append(meshio.CellBlock("line", m.t[:, rest].T))
        phys.append(np.full(rest.size, tag))
    return meshio.Mesh(pts, cells,
                       cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                       field_data=field)


def write(path, points, cells, *, tags=None, names=None, key="gmsh:physical",
          file_format="gmsh22", **kw):
    """Write a small mesh; ``cells`` is a list of (type, connectivity)."""
    points = np.asarray(points, dtype=float)
    blocks = [meshio.CellBlock(t, np.asarray(c, dtype=int)) for t, c in cells]
    cell_data = {}
    if tags is not None:
        cell_data[key] = [np.asarray(t) for t in tags]
        if key == "gmsh:physical":
            cell_data["gmsh:geometrical"] = [np.asarray(t) for t in tags]
    meshio.write(path, meshio.Mesh(points, blocks, cell_data=cell_data,
                                   field_data=names or {}),
                 file_format=file_format, **kw)
    return path


def chain(n):
    return np.column_stack((np.arange(n), np.arange(1, n + 1)))


def xyz(x):
    x = np.asarray(x, dtype=float)
    return np.column_stack((x, 0 * x, 0 * x))


def names_of(m):
    return {k: v.tolist() for k, v in m.boundaries.items()}, \
        {k: v.tolist() for k, v in m.subdomains.items()}


# ---------------------------------------------------------------------------
# line_mesh
# ---------------------------------------------------------------------------
def test_default_mesh():
    m = line_mesh()
    assert_canonical(m)
    assert m.nelements == 10 and m.p.shape[1] == 11
    np.testing.assert_allclose(m.p[0], np.linspace(0, 1, 11), rtol=0, atol=1e-15)
    assert set(m.boundaries) == {"left", "right"}
    assert m.subdomains == {}


def test_start_and_length():
    m = line_mesh(2.5, 5, start=-1.0)
    assert_canonical(m)
    np.testing.assert_allclose(m.p[0], [-1.0, -0.5, 0.0, 0.5, 1.0, 1.5], atol=1e-15)
    assert m.p[0, 0] == -1.0 and m.p[0, -1] == 1.5


def test_numpy_scalars_accepted():
    m = line_mesh(np.float64(2.0), np.int64(4), grading=np.float32(1.0))
    assert m.nelements == 4 and m.p[0, -1] == 2.0


@pytest.mark.parametrize("grading", [0.2, 5.0, 0.9])
def test_graded_ratio(grading):
    m = line_mesh(1.0, 30, grading=grading)
    assert_canonical(m)
    h = np.diff(m.p[0])
    assert abs(h[-1] / h[0] - grading) < 1e-12
    q = h[1:] / h[:-1]
    np.testing.assert_allclose(q, grading ** (1 / 29), rtol=1e-10)
    assert m.p[0, 0] == 0.0 and m.p[0, -1] == 1.0
    if grading < 1:
        assert h[-1] < h[0]  # finer towards the end


def test_single_element_ignores_grading():
    m = line_mesh(3.0, 1, grading=0.1)
    np.testing.assert_array_equal(m.p[0], [0.0, 3.0])


def test_named_points():
    m = line_mesh(2.0, 10, boundaries={"clamp": 0.0, "contact": 1.2, "tip": 2.0})
    assert_canonical(m)
    assert m.boundaries["clamp"].tolist() == [0]
    assert m.boundaries["contact"].tolist() == [6]
    assert m.boundaries["tip"].tolist() == [10]
    assert m.p[0, m.boundaries["contact"]][0] == pytest.approx(1.2, abs=1e-15)
    # skfem resolves the names (facet index == vertex index)
    assert Basis(m, ElementLineP1()).get_dofs("contact").all().tolist() == [6]
    assert Basis(m, ElementLineHermite()).get_dofs("tip").all().tolist() == [20, 21]


def test_named_point_tolerance():
    m = line_mesh(1.0, 10, boundaries={"p": 0.6 + 1e-11})
    assert m.boundaries["p"].tolist() == [6]
    with pytest.raises(ValueError, match=r"boundaries\['p'\].*nearest vertex is x = 0\.6"):
        line_mesh(1.0, 10, boundaries={"p": 0.63})


def test_named_point_on_graded_mesh():
    ref = line_mesh(1.0, 8, grading=0.5)
    x3 = ref.p[0, 3]
    m = line_mesh(1.0, 8, grading=0.5, boundaries={"p": float(x3)})
    assert m.boundaries["p"].tolist() == [3]


def test_reserved_names():
    m = line_mesh(1.0, 4, boundaries={"left": 0.0, "right": 1.0, "clamp": 0.0})
    assert m.boundaries["left"].tolist() == [0] == m.boundaries["clamp"].tolist()
    with pytest.raises(ValueError, match=r"boundaries\['left'\].*reserved"):
        line_mesh(1.0, 4, boundaries={"left": 0.5})
    with pytest.raises(ValueError, match=r"boundaries\['right'\].*reserved"):
        line_mesh(1.0, 4, boundaries={"right": 0.0})


def test_subdomains():
    m = line_mesh(1.0, 10, subdomains={"steel": (0.0, 0.5), "alu": (0.5, 1.0)})
    assert_canonical(m)
    assert m.subdomains["steel"].tolist() == [0, 1, 2, 3, 4]
    assert m.subdomains["alu"].tolist() == [5, 6, 7, 8, 9]
    # overlaps allowed, coverage not required, lists accepted
    m = line_mesh(1.0, 10, subdomains={"a": [0.0, 0.6], "b": (0.4, 0.7)})
    assert m.subdomains["a"].tolist() == [0, 1, 2, 3, 4, 5]
    assert m.subdomains["b"].tolist() == [4, 5, 6]
    # skfem uses them
    assert Basis(m, ElementLineP1(), elements="b").nelems == 3


NAN, INF = float("nan"), float("inf")

BAD = [
    # (kwargs, exception, argument name in message, quoted bad value)
    (dict(length=0.0), ValueError, "length", "0.0"),
    (dict(length=-1.0), ValueError, "length", "-1.0"),
    (dict(length=NAN), ValueError, "length", "nan"),
    (dict(length=INF), ValueError, "length", "inf"),
    (dict(length="1"), TypeError, "length", "'1'"),
    (dict(length=True), TypeError, "length", "True"),
    (dict(length=None), TypeError, "length", "None"),
    (dict(n_elements=0), ValueError, "n_elements", "0"),
    (dict(n_elements=-3), ValueError, "n_elements", "-3"),
    (dict(n_elements=2.0), TypeError, "n_elements", "2.0"),
    (dict(n_elements=2.5), TypeError, "n_elements", "2.5"),
    (dict(n_elements=True), TypeError, "n_elements", "True"),
    (dict(n_elements="10"), TypeError, "n_elements", "'10'"),
    (dict(n_elements=None), TypeError, "n_elements", "None"),
    (dict(grading=0.0), ValueError, "grading", "0.0"),
    (dict(grading=-2.0), ValueError, "grading", "-2.0"),
    (dict(grading=NAN), ValueError, "grading", "nan"),
    (dict(grading=INF), ValueError, "grading", "inf"),
    (dict(grading="x"), TypeError, "grading", "'x'"),
    (dict(grading=False), TypeError, "grading", "False"),
    (dict(start=NAN), ValueError, "start", "nan"),
    (dict(start=-INF), ValueError, "start", "-inf"),
    (dict(start="0"), TypeError, "start", "'0'"),
    (dict(start=None), TypeError, "start", "None"),
    (dict(boundaries=[("a", 0.0)]), TypeError, "boundaries", "[('a', 0.0)]"),
    (dict(boundaries={1: 0.0}), TypeError, "boundaries", "1"),
    (dict(boundaries={"": 0.0}), ValueError, "boundaries", "''"),
    (dict(boundaries={"tip": "1"}), TypeError, r"boundaries\['tip'\]", "'1'"),
    (dict(boundaries={"tip": NAN}), ValueError, r"boundaries\['tip'\]", "nan"),
    (dict(boundaries={"tip": True}), TypeError, r"boundaries\['tip'\]", "True"),
    (dict(boundaries={"tip": 1.05}), ValueError, r"boundaries\['tip'\]", "1.05"),
    (dict(subdomains=[(0.0, 1.0)]), TypeError, "subdomains", "[(0.0, 1.0)]"),
    (dict(subdomains={2: (0.0, 1.0)}), TypeError, "subdomains", "2"),
    (dict(subdomains={"s": (1.0, 0.0)}), ValueError, r"subdomains\['s'\]", "(1.0, 0.0)"),
    (dict(subdomains={"s": (0.5, 0.5)}), ValueError, r"subdomains\['s'\]", "(0.5, 0.5)"),
    (dict(subdomains={"s": (0.0,)}), TypeError, r"subdomains\['s'\]", "(0.0,)"),
    (dict(subdomains={"s": "ab"}), TypeError, r"subdomains\['s'\]", "'ab'"),
    (dict(subdomains={"s": 0.5}), TypeError, r"subdomains\['s'\]", "0.5"),
    (dict(subdomains={"s": (0.0, NAN)}), ValueError, r"subdomains\['s'\]", "nan"),
    (dict(subdomains={"s": (0.0, "1")}), TypeError, r"subdomains\['s'\]", "'1'"),
    (dict(subdomains={"s": (2.0, 3.0)}), ValueError, r"subdomains\['s'\]", "(2.0, 3.0)"),
    (dict(subdomains={"s": (0.01, 0.02)}), ValueError, r"subdomains\['s'\].*no element",
     "(0.01, 0.02)"),
]


@pytest.mark.parametrize("kwargs, exc, name, quoted", BAD,
                         ids=[f"{k}={v!r}" for k, *_ in BAD for v in [list(k.values())[0]]])
def test_line_mesh_bad_arguments(kwargs, exc, name, quoted):
    with pytest.raises(exc, match=name) as info:
        line_mesh(**kwargs)
    assert quoted in str(info.value)


def test_overflowing_extent():
    with pytest.raises(ValueError, match="start"):
        line_mesh(1e308, 2, start=1e308)


# ---------------------------------------------------------------------------
# load_mesh: shipped files
# ---------------------------------------------------------------------------
SHIPPED = {
    # file: (line_mesh reference, named points, subdomain element counts)
    "cantilever.msh": (line_mesh(1.0, 40), {"clamp": 0.0, "tip": 1.0}, {"beam": 40}),
    "bar.msh": (line_mesh(1.0, 50), {"fixed": 0.0, "free": 1.0}, {"bar": 50}),
    "graded_beam.msh": (line_mesh(1.0, 30, grading=0.2), {"clamp": 0.0, "tip": 1.0},
                        {"beam": 30}),
    "two_material_beam.msh": (line_mesh(1.0, 40), {"clamp": 0.0, "mid": 0.5, "tip": 1.0},
                              {"steel": 20, "aluminium": 20}),
    "cantilever.vtu": (line_mesh(1.0, 40), {"point_1": 0.0, "point_2": 1.0},
                       {"region_3": 40}),
}


@pytest.mark.parametrize("fname", sorted(SHIPPED))
def test_shipped_mesh(fname):
    ref, points, regions = SHIPPED[fname]
    m = load_mesh(MESHES / fname)
    assert_canonical(m)
    assert m.nelements == ref.nelements
    np.testing.assert_allclose(m.p, ref.p, rtol=0, atol=1e-12)
    assert set(m.boundaries) == {"left", "right", *points}
    for name, x in points.items():
        assert len(m.boundaries[name]) == 1
        assert abs(m.p[0, m.boundaries[name][0]] - x) < 1e-12
    assert {k: len(v) for k, v in m.subdomains.items()} == regions


def test_shipped_files_exist():
    listed = (MESHES / "README.md").read_text()
    for fname in SHIPPED:
        assert (MESHES / fname).is_file()
        assert f"`{fname}`" in listed


def test_shipped_graded_ratio():
    m = load_mesh(MESHES / "graded_beam.msh")
    h = np.diff(m.p[0])
    assert abs(h[-1] / h[0] - 0.2) < 1e-12


def test_shipped_two_materials_split_at_mid():
    m = load_mesh(str(MESHES / "two_material_beam.msh"))
    mid = m.p[0, m.t].mean(axis=0)
    np.testing.assert_array_equal(m.subdomains["steel"], np.nonzero(mid < 0.5)[0])
    np.testing.assert_array_equal(m.subdomains["aluminium"], np.nonzero(mid > 0.5)[0])
    assert m.boundaries["mid"].tolist() == [20]


# ---------------------------------------------------------------------------
# load_mesh: formats, renumbering, geometry
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("binary", [False, True])
def test_round_trip_gmsh22(tmp_path, binary):
    x7 = float(line_mesh(3.0, 12, grading=2.5, start=-2.0).p[0, 7])
    m = line_mesh(3.0, 12, grading=2.5, start=-2.0,
                  boundaries={"clamp": -2.0, "contact": x7},
                  subdomains={"a": (-2.0, 0.0), "b": (-1.0, 1.0)})
    assert m.boundaries["contact"].tolist() == [7]
    path = tmp_path / "rt.msh"
    meshio.write(path, to_meshio(m), file_format="gmsh22", binary=binary)
    r = load_mesh(path)
    assert_canonical(r)
    np.testing.assert_array_equal(r.p, m.p)
    np.testing.assert_array_equal(r.t, m.t)
    assert names_of(r) == names_of(m)


def test_round_trip_2d_points_vtu(tmp_path):
    m = line_mesh(1.0, 7, boundaries={"tip": 1.0}, subdomains={"s": (0.0, 0.5)})
    path = tmp_path / "rt.vtu"
    meshio.write(path, to_meshio(m, point_dim=2))
    r = load_mesh(path)
    np.testing.assert_array_equal(r.p, m.p)
    # no names in VTU: fallback names from the tags (tip has tag 3, s tag 4)
    assert r.boundaries["point_3"].tolist() == [7]
    assert r.subdomains["region_4"].tolist() == m.subdomains["s"].tolist()


def test_renumbering_and_unused_nodes(tmp_path):
    """Shuffled nodes, reversed/shuffled elements and unused nodes."""
    rng = np.random.default_rng(0)
    x = np.linspace(0.0, 2.0, 9)
    extra = np.array([5.0, -3.0, 0.7])          # geometry points not in elements
    allx = np.concatenate((x, extra))
    perm = rng.permutation(allx.size)           # new position of old node i
    pts = np.zeros((allx.size, 3))
    pts[perm, 0] = allx
    conn = perm[chain(8)]
    conn[::2] = conn[::2, ::-1]                  # flip every other element
    order = rng.permutation(8)
    path = write(tmp_path / "shuffled.msh", pts,
                 [("vertex", [[perm[0]]]), ("vertex", [[perm[8]], [perm[4]]]),
                  ("line", conn[order])],
                 tags=[[1], [2, 2], np.where(order < 4, 3, 4)],
                 names={"clamp": np.array([1, 0]), "ends": np.array([2, 0]),
                        "inner": np.array([3, 1]), "outer": np.array([4, 1])})
    m = load_mesh(path)
    assert_canonical(m)
    np.testing.assert_array_equal(m.p[0], x)
    assert m.boundaries["clamp"].tolist() == [0]
    assert m.boundaries["ends"].tolist() == [4, 8]
    assert m.subdomains["inner"].tolist() == [0, 1, 2, 3]
    assert m.subdomains["outer"].tolist() == [4, 5, 6, 7]


GMSH41 = """$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
3
0 1 "clamp"
0 2 "tip"
1 3 "beam"
$EndPhysicalNames
$Entities
3 1 0 0
1 0 0 0 1 1
2 1 0 0 1 2
3 2 0 0 0
1 0 0 0 1 0 0 1 3 2 1 -2
$EndEntities
$Nodes
4 6 1 6
0 1 0 1
1
0 0 0
0 2 0 1
2
1 0 0
0 3 0 1
6
2 0 0
1 1 0 3
3
4
5
0.25 0 0
0.5 0 0
0.75 0 0
$EndNodes
$Elements
3 6 1 6
0 1 15 1
1 1
0 2 15 1
2 2
1 1 1 4
3 1 3
4 3 4
5 4 5
6 5 2
$EndElements
"""


def test_gmsh41_with_unused_geometry_point(tmp_path):
    path = tmp_path / "v41.msh"
    path.write_text(GMSH41)
    m = load_mesh(path)
    assert_canonical(m)
    np.testing.assert_array_equal(m.p[0], [0.0, 0.25, 0.5, 0.75, 1.0])  # node at x=2 dropped
    assert m.boundaries["clamp"].tolist() == [0]
    assert m.boundaries["tip"].tolist() == [4]
    assert m.subdomains["beam"].tolist() == [0, 1, 2, 3]


def test_tilted_3d_line(tmp_path):
    d = np.array([1.0, 2.0, 2.0]) / 3.0
    s = np.array([0.0, 0.5, 1.25, 2.0, 3.0])
    path = write(tmp_path / "tilted.msh", s[:, None] * d,
                 [("vertex", [[4]]), ("line", chain(4)[::-1])],
                 tags=[[1], [2, 2, 2, 2]],
                 names={"tip": np.array([1, 0]), "beam": np.array([2, 1])})
    m = load_mesh(path)
    assert_canonical(m)
    np.testing.assert_allclose(m.p[0], s, rtol=0, atol=1e-12)
    assert abs(m.p[0, m.boundaries["tip"][0]] - 3.0) < 1e-12


def test_line_along_negative_direction_offset(tmp_path):
    """Line along y at x=5 listed from the top: s is y (origin kept)."""
    y = np.array([4.0, 3.0, 1.5, 1.0])
    pts = np.column_stack((5.0 + 0 * y, y))
    path = write(tmp_path / "vertical.msh", pts, [("line", chain(3))])
    m = load_mesh(path)
    np.testing.assert_array_equal(m.p[0], [1.0, 1.5, 3.0, 4.0])
    assert m.subdomains == {}


def test_antidiagonal_line_orientation(tmp_path):
    """Tie between |dx| and |dy|: x component positive, s = p . d."""
    t = np.linspace(0.0, 1.0, 5)
    pts = np.column_stack((1.0 - t, t))
    m = load_mesh(write(tmp_path / "anti.msh", pts, [("line", chain(4))]))
    d = np.array([1.0, -1.0]) / math.sqrt(2)
    np.testing.assert_allclose(m.p[0], np.sort(pts @ d), atol=1e-12)


def test_line3_uses_end_vertices(tmp_path):
    x = np.linspace(0.0, 1.0, 9)  # vertices 0,2,4,6,8 are ends; odd ones midpoints
    conn = np.array([[0, 2, 1], [2, 4, 3], [4, 6, 5], [6, 8, 7]])
    path = write(tmp_path / "quad.msh", xyz(x), [("line3", conn)], tags=[[1, 1, 1, 1]],
                 names={"beam": np.array([1, 1])}, binary=True)
    m = load_mesh(path)
    np.testing.assert_array_equal(m.p[0], x[::2])
    assert m.subdomains["beam"].tolist() == [0, 1, 2, 3]


def test_repeated_elements_in_two_groups(tmp_path):
    """gmsh 2.2 writes an element once per physical group: merge them."""
    x = np.linspace(0.0, 1.0, 5)
    path = write(tmp_path / "dup.msh", xyz(x),
                 [("line", chain(4)), ("line", chain(4)[1:3, ::-1])],
                 tags=[[1, 1, 1, 1], [2, 2]],
                 names={"all": np.array([1, 1]), "middle": np.array([2, 1])})
    m = load_mesh(path)
    assert m.nelements == 4
    assert m.subdomains["all"].tolist() == [0, 1, 2, 3]
    assert m.subdomains["middle"].tolist() == [1, 2]


def test_region_cell_data_and_tag_names(tmp_path):
    x = np.linspace(0.0, 1.0, 5)
    path = write(tmp_path / "reg.vtu", xyz(x), [("vertex", [[2]]), ("line", chain(4))],
                 tags=[[7], [1, 1, 2, 2]], key="Region", file_format="vtu")
    m = load_mesh(path)
    assert m.boundaries["point_7"].tolist() == [2]
    assert m.subdomains["region_1"].tolist() == [0, 1]
    assert m.subdomains["region_2"].tolist() == [2, 3]


def test_names_matched_on_dimension(tmp_path):
    """gmsh physical tags are per dimension: tag 1 in dim 0 and dim 1."""
    x = np.linspace(0.0, 1.0, 3)
    path = write(tmp_path / "dims.msh", xyz(x), [("vertex", [[2]]), ("line", chain(2))],
                 tags=[[1], [1, 1]],
                 names={"tip": np.array([1, 0]), "beam": np.array([1, 1])})
    m = load_mesh(path)
    assert m.boundaries["tip"].tolist() == [2]
    assert m.subdomains["beam"].tolist() == [0, 1]
    assert "point_1" not in m.boundaries and "region_1" not in m.subdomains


def test_gmsh_physical_zero_is_ignored(tmp_path):
    x = np.linspace(0.0, 1.0, 4)
    path = write(tmp_path / "zero.msh", xyz(x), [("line", chain(3))], tags=[[0, 0, 5]])
    m = load_mesh(path)
    assert m.subdomains == {"region_5": np.array([2])}


def test_xdmf_line_mesh(tmp_path):
    x = np.linspace(0.0, 2.0, 6)
    path = write(tmp_path / "beam.xdmf", xyz(x), [("line", chain(5))],
                 tags=[[1, 1, 1, 2, 2]], key="subdomain", file_format="xdmf",
                 data_format="XML")
    m = load_mesh(path)
    np.testing.assert_allclose(m.p[0], x, atol=1e-12)
    assert m.subdomains["region_2"].tolist() == [3, 4]


# ---------------------------------------------------------------------------
# load_mesh: bad input
# ---------------------------------------------------------------------------
def raises_naming(path, exc, problem):
    with pytest.raises(exc) as info:
        load_mesh(path)
    msg = str(info.value)
    assert Path(path).name in msg
    assert re.search(problem, msg), msg
    return msg


def test_missing_file(tmp_path):
    raises_naming(tmp_path / "nothere.msh", FileNotFoundError, "does not exist")


def test_garbage_msh(tmp_path, capsys):
    path = tmp_path / "garbage.msh"
    path.write_text("this is not a mesh\n1 2 3\n")
    raises_naming(path, ValueError, "cannot read mesh file.*gmsh")
    out = capsys.readouterr()
    assert "garbage" not in out.out + out.err  # meshio's console output swallowed


def test_unknown_extension(tmp_path):
    path = tmp_path / "mesh.foo"
    path.write_text("0 1\n")
    raises_naming(path, ValueError, r"extension '\.foo'")


def test_directory(tmp_path):
    d = tmp_path / "adir.msh"
    d.mkdir()
    raises_naming(d, ValueError, "directory")


@pytest.mark.parametrize("bad", [123, None, b"mesh.msh", 1.5])
def test_path_type(bad):
    with pytest.raises(TypeError, match="path"):
        load_mesh(bad)


def test_triangle_mesh_loads_as_a_2d_mesh(tmp_path):
    """A surface mesh is no longer refused as "not a beam": it is a 2D mesh for fm.solid (issue
    15); its boundary lines (without physical names) add nothing."""
    path = write(tmp_path / "tri.msh", [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
                 [("triangle", [[0, 1, 2], [1, 3, 2]])])
    mesh = load_mesh(path)
    assert mesh.dim() == 2 and mesh.t.shape == (3, 2) and mesh.p.shape == (2, 4)
    path = write(tmp_path / "tri_lines.msh", [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                 [("triangle", [[0, 1, 2]]), ("line", [[0, 1], [1, 2], [2, 0]])])
    mesh = load_mesh(path)
    assert mesh.dim() == 2 and mesh.t.shape == (3, 1)


def test_branching_t_shape(tmp_path):
    pts = [[-1, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0]]
    path = write(tmp_path / "tee.msh", pts, [("line", [[0, 1], [1, 2], [1, 3]])])
    msg = raises_naming(path, ValueError, "branches")
    assert "(0, 0, 0)" in msg


def test_non_collinear(tmp_path):
    pts = [[0, 0, 0], [0.5, 0.1, 0], [1, 0, 0]]
    path = write(tmp_path / "kink.msh", pts, [("line", [[0, 1], [1, 2]])])
    raises_naming(path, ValueError, r"not collinear: max deviation .* is 0\.1 ")


def test_disconnected(tmp_path):
    x = [0.0, 0.3, 0.6, 1.0]
    path = write(tmp_path / "gap.msh", xyz(x), [("line", [[0, 1], [2, 3]])])
    raises_naming(path, ValueError, "disconnected: 2 separate parts")


def test_duplicate_nodes_are_not_merged(tmp_path):
    x = [0.0, 0.5, 0.5, 1.0]
    path = write(tmp_path / "dupnode.msh", xyz(x), [("line", [[0, 1], [2, 3]])])
    raises_naming(path, ValueError, "disconnected.*not merged")


def test_closed_loop(tmp_path):
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    path = write(tmp_path / "loop.msh", pts, [("line", [[0, 1], [1, 2], [2, 0]])])
    raises_naming(path, ValueError, "closed loop")


def test_fold_back(tmp_path):
    path = write(tmp_path / "fold.msh", xyz([0.0, 1.0, 0.5]), [("line", [[0, 1], [1, 2]])])
    raises_naming(path, ValueError, "folds back")


def test_zero_length_element(tmp_path):
    path = write(tmp_path / "zero.msh", xyz([0.0, 0.5, 0.5, 1.0]),
                 [("line", [[0, 1], [1, 2], [2, 3]])])
    raises_naming(path, ValueError, "coincide")


def test_named_point_off_the_line(tmp_path):
    path = write(tmp_path / "off.msh", xyz([0.0, 0.5, 1.0, 3.0]),
                 [("vertex", [[3]]), ("line", chain(2))], tags=[[1], [2, 2]],
                 names={"probe": np.array([1, 0])})
    raises_naming(path, ValueError, "'probe'.*not a vertex")


def test_reserved_point_group(tmp_path):
    path = write(tmp_path / "res.msh", xyz([0.0, 0.5, 1.0]),
                 [("vertex", [[1]]), ("line", chain(2))], tags=[[1], [2, 2]],
                 names={"left": np.array([1, 0])})
    raises_naming(path, ValueError, "'left'.*reserved")


def test_non_integer_tags(tmp_path):
    path = write(tmp_path / "float.vtu", xyz([0.0, 0.5, 1.0]), [("line", chain(2))],
                 tags=[[1.5, 2.0]], key="region", file_format="vtu")
    raises_naming(path, ValueError, "'region' must hold integer")


# ---------------------------------------------------------------------------
# property-based round trip
# ---------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(length=st.floats(1e-3, 1e3), n=st.integers(1, 120), grading=st.floats(0.05, 20.0),
       binary=st.booleans())
def test_round_trip_property(length, n, grading, binary):
    m = line_mesh(length, n, grading=grading,
                  boundaries={"tip": length}, subdomains={"all": (0.0, length)})
    h = np.diff(m.p[0])
    if n > 1:
        assert abs(h[-1] / h[0] - grading) <= 1e-9 * grading
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "prop.msh"
        meshio.write(path, to_meshio(m), file_format="gmsh22", binary=binary)
        r = load_mesh(path)
    np.testing.assert_array_equal(r.p, m.p)
    np.testing.assert_array_equal(r.t, m.t)
    assert names_of(r) == names_of(m)
