"""Generate the example line meshes shipped in ``meshes/``.

Run ``python meshes/make_meshes.py`` (from anywhere); the files are written
next to this script.  Only numpy and meshio are used, so the files do not
depend on femodes itself (the tests compare them with
``femodes.fe.mesh.line_mesh``).

Every gmsh file is written in the gmsh 2.2 ascii format with named physical
groups: ``field_data`` (``name -> [tag, dim]``, gmsh ``$PhysicalNames``)
together with the cell data ``"gmsh:physical"`` and ``"gmsh:geometrical"``.
Named points are ``vertex`` cells (dim 0), subdomains are ``line`` cells
(dim 1).

The 2-D and 3-D blade meshes (``blade2d.msh``, ``blade3d.msh``) are made with
the ``gmsh`` Python package (a development dependency, ``pip install
"femodes[meshes]"``), imported only when they are written: named boundaries are
gmsh physical groups of facets (curves in 2-D, surfaces in 3-D), named points
physical points and subdomains physical surfaces/volumes.  ``python
meshes/make_meshes.py --lines`` rewrites the line meshes only (no gmsh).
"""
from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

HERE = Path(__file__).resolve().parent


def graded_coordinates(length: float, n: int, ratio: float = 1.0) -> np.ndarray:
    """Vertex coordinates on [0, length], element lengths in geometric progression.

    Parameters
    ----------
    length : float
        Length of the line.
    n : int
        Number of elements.
    ratio : float
        Last element length divided by first element length.

    Returns
    -------
    numpy.ndarray
        ``n + 1`` increasing coordinates, exactly 0 and ``length`` at the ends.
    """
    if ratio == 1.0 or n == 1:
        return np.linspace(0.0, length, n + 1)
    h = (ratio ** (1.0 / (n - 1))) ** np.arange(n)
    h *= length / h.sum()
    x = np.concatenate(([0.0], np.cumsum(h)))
    x[-1] = length
    return x


def beam_mesh(x: np.ndarray, points: dict[str, float],
              regions: dict[str, tuple[float, float]]) -> meshio.Mesh:
    """Build a meshio line mesh along the x axis with gmsh physical groups.

    Parameters
    ----------
    x : numpy.ndarray
        Increasing vertex coordinates.
    points : dict of str to float
        Named points; each coordinate must be (exactly) a vertex.
    regions : dict of str to (float, float)
        Named subdomains: elements whose midpoint lies in the interval.

    Returns
    -------
    meshio.Mesh
        Mesh with 3-D points ``(x, 0, 0)``, one ``vertex`` cell block per
        named point and one ``line`` cell block per region.
    """
    pts = np.column_stack((x, np.zeros_like(x), np.zeros_like(x)))
    n = len(x) - 1
    mid = 0.5 * (x[:-1] + x[1:])
    elements = np.column_stack((np.arange(n), np.arange(1, n + 1)))
    cells, physical, geometrical, field_data = [], [], [], {}
    tag = 0
    for name, coord in points.items():
        tag += 1
        k = int(np.argmin(np.abs(x - coord)))
        assert x[k] == coord, (name, coord, x[k])
        cells.append(meshio.CellBlock("vertex", np.array([[k]])))
        physical.append(np.array([tag]))
        geometrical.append(np.array([tag]))
        field_data[name] = np.array([tag, 0])
    covered = np.zeros(n, dtype=bool)
    for curve, (name, (a, b)) in enumerate(regions.items(), start=1):
        tag += 1
        sel = (mid >= a) & (mid <= b)
        assert sel.any() and not (covered & sel).any(), name
        covered |= sel
        cells.append(meshio.CellBlock("line", elements[sel]))
        physical.append(np.full(sel.sum(), tag))
        geometrical.append(np.full(sel.sum(), curve))
        field_data[name] = np.array([tag, 1])
    assert covered.all(), "every element must belong to a region"
    return meshio.Mesh(
        pts, cells,
        cell_data={"gmsh:physical": physical, "gmsh:geometrical": geometrical},
        field_data=field_data,
    )


def blade2d(path: Path, *, size: float = 0.025) -> None:
    """2-D tapered blade (gmsh, linear triangles), written as gmsh 4.1 ascii.

    Root chord 0.1 at x = 0 (physical curve ``root``), tip chord 0.06 at x = 1
    (``tip``), the upper and lower sides ``top`` and ``bottom``; physical
    points ``tip_top`` (upper tip corner) and ``tip_mid`` (middle of the tip
    edge); the surface ``blade``.  Mesh size ``size``.
    """
    import gmsh

    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("blade2d")
        geo = gmsh.model.geo
        pts = [geo.addPoint(x, y, 0.0, size) for x, y in
               ((0.0, -0.05), (1.0, -0.03), (1.0, 0.0), (1.0, 0.03), (0.0, 0.05))]
        bottom = geo.addLine(pts[0], pts[1])
        tip_lo = geo.addLine(pts[1], pts[2])
        tip_hi = geo.addLine(pts[2], pts[3])
        top = geo.addLine(pts[3], pts[4])
        root = geo.addLine(pts[4], pts[0])
        loop = geo.addCurveLoop([bottom, tip_lo, tip_hi, top, root])
        surf = geo.addPlaneSurface([loop])
        geo.synchronize()
        for dim, tags, name in ((1, [root], "root"), (1, [tip_lo, tip_hi], "tip"), (1, [top], "top"),
                                (1, [bottom], "bottom"), (0, [pts[3]], "tip_top"), (0, [pts[2]], "tip_mid"),
                                (2, [surf], "blade")):
            gmsh.model.setPhysicalName(dim, gmsh.model.addPhysicalGroup(dim, tags), name)
        gmsh.model.mesh.generate(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def blade3d(path: Path, *, size: float = 0.06) -> None:
    """3-D plate blade (gmsh, linear tetrahedra), written as gmsh 4.1 ascii.

    The box ``[0, 1] x [0, 0.2] x [0, 0.03]`` (length along x, chord along y,
    thickness along z): physical surfaces ``root`` (x = 0) and ``tip``
    (x = 1), physical point ``tip_corner`` at (1, 0.2, 0.03), volume
    ``blade``.  Mesh size ``size``.
    """
    import gmsh

    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("blade3d")
        occ = gmsh.model.occ
        vol = occ.addBox(0.0, 0.0, 0.0, 1.0, 0.2, 0.03)
        occ.synchronize()
        faces = gmsh.model.getBoundary([(3, vol)], oriented=False)
        root, tip = [], []
        for dim, tag in faces:
            x, _, _ = occ.getCenterOfMass(dim, tag)
            if abs(x) < 1e-9:
                root.append(tag)
            elif abs(x - 1.0) < 1e-9:
                tip.append(tag)
        corner = [tag for dim, tag in gmsh.model.getEntities(0)
                  if np.allclose(gmsh.model.getValue(0, tag, []), (1.0, 0.2, 0.03))]
        for dim, tags, name in ((2, root, "root"), (2, tip, "tip"), (0, corner, "tip_corner"), (3, [vol], "blade")):
            gmsh.model.setPhysicalName(dim, gmsh.model.addPhysicalGroup(dim, tags), name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * size)
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def main(lines_only: bool = False) -> None:
    """Write all example meshes next to this script (``lines_only``: the 1-D ones)."""
    cantilever = beam_mesh(graded_coordinates(1.0, 40), {"clamp": 0.0, "tip": 1.0},
                           {"beam": (0.0, 1.0)})
    bar = beam_mesh(graded_coordinates(1.0, 50), {"fixed": 0.0, "free": 1.0},
                    {"bar": (0.0, 1.0)})
    graded = beam_mesh(graded_coordinates(1.0, 30, 0.2), {"clamp": 0.0, "tip": 1.0},
                       {"beam": (0.0, 1.0)})
    two = beam_mesh(graded_coordinates(1.0, 40), {"clamp": 0.0, "mid": 0.5, "tip": 1.0},
                    {"steel": (0.0, 0.5), "aluminium": (0.5, 1.0)})
    files = {
        "cantilever.msh": cantilever,
        "bar.msh": bar,
        "graded_beam.msh": graded,
        "two_material_beam.msh": two,
    }
    for name, mesh in files.items():
        meshio.write(HERE / name, mesh, file_format="gmsh22", binary=False)
        print(f"wrote {HERE / name}")
    # VTU (zlib-compressed binary, exact coordinates) keeps points, cells and
    # the integer tags, but meshio does not write field_data to VTU, so the
    # physical names are lost: the file loads with the names point_1,
    # point_2 and region_3.
    meshio.write(HERE / "cantilever.vtu", cantilever, file_format="vtu")
    print(f"wrote {HERE / 'cantilever.vtu'}")
    if lines_only:
        return
    blade2d(HERE / "blade2d.msh")
    print(f"wrote {HERE / 'blade2d.msh'}")
    blade3d(HERE / "blade3d.msh")
    print(f"wrote {HERE / 'blade3d.msh'}")


if __name__ == "__main__":
    import sys

    main(lines_only="--lines" in sys.argv[1:])
