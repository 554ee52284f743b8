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


def main() -> None:
    """Write all example meshes next to this script."""
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


if __name__ == "__main__":
    main()
