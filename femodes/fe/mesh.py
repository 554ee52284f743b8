"""Models layer: the built-in meshes: line meshes for bars and beams, structured rectangles and boxes for solids.

This module builds the 1-D meshes of axial bars and Euler-Bernoulli beams (:func:`line_mesh`) and
the structured 2-D/3-D meshes of solids (:func:`rectangle_mesh`, :func:`box_mesh`); reading meshes
from files (:func:`load_mesh`) lives in :mod:`femodes.fe.mesh_io` and the named points both share
in :mod:`femodes.fe.mesh_names`, re-exported here. :func:`line_mesh` and :func:`load_mesh` return
a ``skfem`` line mesh (``skfem.mesh.MeshLine1``) in the same *canonical form*:

* ``m.p`` has shape ``(1, n + 1)`` and ``m.p[0]`` is strictly increasing;
* ``m.t`` is ``[[0, 1, ..., n-1], [1, 2, ..., n]]``: element ``e`` joins vertices ``e`` and
  ``e + 1``, elements are numbered from left to right;
* every vertex is used by an element.

Named points and subdomains use scikit-fem's public mechanisms (``Mesh.with_boundaries`` /
``Mesh.with_subdomains``) and are read back through its public properties:

* ``m.boundaries[name]`` -- ``numpy.int32`` array of facet indices of the named point(s); a facet
  index *is* the vertex index, so ``m.p[0, m.boundaries["tip"]]`` is the coordinate of "tip".
  Named points may be interior vertices (a contact point at mid span), and the names can be
  passed to scikit-fem, e.g. ``Basis(m, e).get_dofs("clamp")``.
* ``m.subdomains[name]`` -- sorted ``numpy.int32`` array of element indices; ``m.subdomains`` is
  always a ``dict`` (possibly empty), never ``None``.

The names ``"left"`` and ``"right"`` are reserved: always present, they denote the vertex with the
smallest and the largest coordinate, and a user may name them only if they point at those ends.
Several names may refer to the same vertex. Subdomains may overlap and need not cover the mesh;
what an element in zero or several material subdomains means is left to the model layer.
The scikit-fem quirks this works around: :doc:`/guide/models` (Design notes).
"""
from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Mapping

import numpy as np
import skfem

from .mesh_io import COLLINEAR_RTOL, load_mesh
from .mesh_names import RESERVED, build_line_mesh, named_points

__all__ = ["line_mesh", "load_mesh", "rectangle_mesh", "box_mesh", "named_points", "POINT_RTOL", "COLLINEAR_RTOL",
           "MAX_ELEMENTS", "MAX_GRID_CELLS"]

#: Relative tolerance (times the mesh length) for a named point of
#: :func:`line_mesh` to coincide with a vertex.
POINT_RTOL = 1e-9

#: Largest number of elements :func:`line_mesh` builds (1e8 elements: 0.8 GB of
#: coordinates alone, several GB once assembled).
MAX_ELEMENTS = 10**8
#: Most cells of the structured grid of :func:`rectangle_mesh` and :func:`box_mesh` (``nx ny`` or
#: ``nx ny nz``): checked before numpy allocates the vertices and cells, which would fail as
#: "Unable to allocate 74.5 GiB" at 1e5 x 1e5. A grid of 1e7 cells is already about 1.5 GiB of
#: mesh arrays as triangles (6 tetrahedra per cell in 3-D: about 10 GiB), before any FE matrix.
MAX_GRID_CELLS = 10**7


# ---------------------------------------------------------------------------
# argument checking
# ---------------------------------------------------------------------------
def _real(func: str, what: str, value, *, positive: bool = False) -> float:
    """Return ``value`` as a finite float or raise naming ``what``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(
            f"{func}: {what} must be a real number, got {value!r} "
            f"of type {type(value).__name__}"
        )
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{func}: {what} must be finite, got {value!r}")
    if positive and not x > 0.0:
        raise ValueError(f"{func}: {what} must be > 0, got {value!r}")
    return x


def _name(func: str, argname: str, key) -> str:
    """Check that a dictionary key is a usable name."""
    if not isinstance(key, str):
        raise TypeError(
            f"{func}: names in '{argname}' must be str, got {key!r} "
            f"of type {type(key).__name__}"
        )
    if not key.strip():
        raise ValueError(f"{func}: names in '{argname}' must be non-empty, got {key!r}")
    return key


def _mapping(func: str, argname: str, value) -> Mapping:
    if not isinstance(value, Mapping):
        raise TypeError(
            f"{func}: argument '{argname}' must be a dict or None, got {value!r} "
            f"of type {type(value).__name__}"
        )
    return value


# ---------------------------------------------------------------------------
# construction of the skfem mesh
# ---------------------------------------------------------------------------

def _coordinates(start: float, length: float, n: int, grading: float) -> np.ndarray:
    """Vertex coordinates, element lengths in geometric progression."""
    if grading == 1.0 or n == 1:
        return np.linspace(start, start + length, n + 1)
    q = grading ** (1.0 / (n - 1))
    h = q ** np.arange(n, dtype=np.float64)
    h *= length / h.sum()
    x = np.empty(n + 1)
    x[0] = start
    x[1:] = start + np.cumsum(h)
    x[-1] = start + length
    return x


def line_mesh(
    length: float = 1.0,
    n_elements: int = 10,
    *,
    boundaries: dict[str, float] | None = None,
    subdomains: dict[str, tuple[float, float]] | None = None,
    grading: float = 1.0,
    start: float = 0.0,
) -> skfem.MeshLine:
    """Create a straight line mesh with named points and subdomains.

    Parameters
    ----------
    length : float
        Length of the line, finite and > 0.  The mesh covers ``[start, start + length]``.
    n_elements : int
        Number of elements, an integer >= 1 (``bool`` is rejected).
    boundaries : dict of str to float, optional
        Named points, ``name -> coordinate``, each at a vertex within ``POINT_RTOL * length`` (else a
        ``ValueError`` names the nearest vertex). ``"left"`` and ``"right"`` are always added at the ends.
    subdomains : dict of str to (float, float), optional
        Named subdomains, ``name -> (x0, x1)`` with ``x0 < x1``: the elements whose midpoint lies in
        ``[x0, x1]``, at least one. Subdomains may overlap and need not cover the line.
    grading : float
        Ratio of the last to the first element length (> 0), lengths in geometric progression: ``1``
        uniform, ``< 1`` refined towards ``start + length``.
    start : float
        Coordinate of the left end.

    Returns
    -------
    skfem.MeshLine
        Canonical line mesh (module docstring): vertex ``k`` is the ``k``-th from the left,
        ``boundaries[name]`` holds vertex (= facet) indices, ``subdomains[name]`` element indices.

    Raises
    ------
    TypeError
        If an argument has the wrong type; the message names the argument.
    ValueError
        An invalid value, a named point not at a vertex or a subdomain without an element.

    Examples
    --------
    >>> m = line_mesh(2.0, 4, boundaries={"clamp": 0.0, "contact": 1.5})
    >>> m.p[0, m.boundaries["contact"]]
    array([1.5])
    """
    length, start, grading, n = _line_arguments(length, n_elements, grading, start)
    x = _line_coordinates(start, length, n, grading, n_elements)
    points = _vertex_points(boundaries, x, length)
    regions = _interval_subdomains(subdomains, x)
    return build_line_mesh(x, points, regions)


def _line_arguments(length, n_elements, grading, start) -> tuple[float, float, float, int]:
    """Checked ``(length, start, grading, n)`` of :func:`line_mesh`."""
    f = "line_mesh"
    length = _real(f, "argument 'length'", length, positive=True)
    start = _real(f, "argument 'start'", start)
    grading = _real(f, "argument 'grading'", grading, positive=True)
    if isinstance(n_elements, (bool, np.bool_)) or not isinstance(n_elements, numbers.Integral):
        raise TypeError(
            f"{f}: argument 'n_elements' must be an int, got {n_elements!r} "
            f"of type {type(n_elements).__name__}"
        )
    n = int(n_elements)
    if n < 1:
        raise ValueError(f"{f}: argument 'n_elements' must be >= 1, got {n_elements!r}")
    if n > MAX_ELEMENTS:
        # fail here, naming the argument, rather than in a numpy allocation
        raise ValueError(
            f"{f}: argument 'n_elements' must be <= {MAX_ELEMENTS:.0e} (a line mesh of that size "
            f"does not fit in memory with its FE matrices), got {n_elements!r}"
        )
    if not math.isfinite(start + length):
        raise ValueError(
            f"{f}: arguments 'start' + 'length' overflow: start={start!r}, length={length!r}"
        )
    return length, start, grading, n


def _line_coordinates(start: float, length: float, n: int, grading: float, n_elements) -> np.ndarray:
    """Vertex coordinates of :func:`line_mesh`, checked for element lengths that underflow."""
    x = _coordinates(start, length, n, grading)
    if not np.all(np.diff(x) > 0.0):
        raise ValueError(
            f"line_mesh: element lengths underflow for length={length!r}, "
            f"n_elements={n_elements!r}, grading={grading!r}, start={start!r}"
        )
    return x


def _vertex_points(boundaries, x: np.ndarray, length: float) -> dict[str, np.ndarray]:
    """Named points of :func:`line_mesh`: ``"left"``, ``"right"`` and ``boundaries`` snapped to vertices."""
    f = "line_mesh"
    points: dict[str, np.ndarray] = {"left": np.array([0]), "right": np.array([x.size - 1])}
    if boundaries is None:
        return points
    _mapping(f, "boundaries", boundaries)
    tol = POINT_RTOL * length
    for key, value in boundaries.items():
        name = _name(f, "boundaries", key)
        c = _real(f, f"boundaries[{name!r}]", value)
        k = int(np.argmin(np.abs(x - c)))
        dist = abs(x[k] - c)
        if dist > tol:
            raise ValueError(
                f"{f}: boundaries[{name!r}] = {value!r} is not at a mesh vertex: "
                f"nearest vertex is x = {float(x[k])!r} (distance {dist:.3g} > tolerance "
                f"{tol:.3g}); move the point or choose n_elements/grading so that "
                f"a vertex falls on it"
            )
        if name in RESERVED and k != points[name][0]:
            end = "start" if name == "left" else "start + length"
            raise ValueError(
                f"{f}: boundaries[{name!r}] = {value!r}: the name {name!r} is "
                f"reserved for the end x = {float(x[points[name][0]])!r} ({end}); use "
                f"another name for this point"
            )
        points[name] = np.array([k])
    return points


def _interval_subdomains(subdomains, x: np.ndarray) -> dict[str, np.ndarray]:
    """Named subdomains of :func:`line_mesh`: the elements whose midpoint lies in each interval."""
    f = "line_mesh"
    regions: dict[str, np.ndarray] = {}
    if subdomains is None:
        return regions
    _mapping(f, "subdomains", subdomains)
    n = x.size - 1
    mid = 0.5 * (x[:-1] + x[1:])
    for key, value in subdomains.items():
        name = _name(f, "subdomains", key)
        what = f"subdomains[{name!r}]"
        if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__") \
                or len(value) != 2:
            raise TypeError(
                f"{f}: {what} must be an interval (x0, x1), got {value!r}"
            )
        x0 = _real(f, f"{what}[0]", value[0])
        x1 = _real(f, f"{what}[1]", value[1])
        if not x0 < x1:
            raise ValueError(f"{f}: {what} = {value!r} must satisfy x0 < x1")
        elems = np.nonzero((mid >= x0) & (mid <= x1))[0]
        if elems.size == 0:
            raise ValueError(
                f"{f}: {what} = {value!r} contains no element midpoint "
                f"(mesh spans [{float(x[0])!r}, {float(x[-1])!r}] with {n} elements)"
            )
        regions[name] = elems
    return regions


# ---------------------------------------------------------------------------
# 2-D and 3-D meshes for solids
# ---------------------------------------------------------------------------
def _count(func: str, what: str, value) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{func}: argument {what!r} must be an int >= 1, got {value!r} of type {type(value).__name__}")
    if not 1 <= int(value) <= 100_000:
        raise ValueError(f"{func}: argument {what!r} must be an int in [1, 100000], got {value!r}")
    return int(value)


def _faces(mesh, spec: dict[str, tuple[int, float]]):
    """``mesh.with_boundaries`` from ``{name: (axis, coordinate)}`` (facets in that plane)."""
    span = np.ptp(mesh.p, axis=1).max()
    sel = {name: (lambda x, a=axis, c=coord: np.abs(x[a] - c) <= 1e-9 * span) for name, (axis, coord) in spec.items()}
    return mesh.with_boundaries(sel)


def _check_grid(func: str, **counts: int) -> None:
    """ValueError naming the divisions when their product exceeds :data:`MAX_GRID_CELLS`."""
    cells = math.prod(counts.values())
    if cells > MAX_GRID_CELLS:
        names = " * ".join(counts)
        raise ValueError(f"{func}: {names} = {' * '.join(map(str, counts.values()))} = {cells:.3g} grid cells, more "
                         f"than {MAX_GRID_CELLS:.0e} (the mesh alone would not fit in memory, nor its FE matrices); "
                         f"use fewer divisions")


def rectangle_mesh(length: float = 1.0, height: float = 0.1, nx: int = 20, ny: int = 2, *,
                   quadrilaterals: bool = False, quad: bool | None = None) -> skfem.Mesh:
    """Structured mesh of the rectangle ``[0, length] x [0, height]`` (x: length, y: height).

    Parameters
    ----------
    length, height : float
        Sides, finite and > 0.
    nx, ny : int
        Number of element divisions along x and y (>= 1).
    quadrilaterals : bool
        Bilinear quadrilaterals (``skfem.MeshQuad``) instead of triangles (``skfem.MeshTri``,
        each cell of the grid split in two); the cells named in full, as ``box_mesh(hexahedra=)``.
    quad : bool, optional
        Deprecated spelling of ``quadrilaterals`` (a ``DeprecationWarning``).

    Returns
    -------
    skfem.MeshTri or skfem.MeshQuad
        With the boundaries ``"left"`` (x = 0), ``"right"`` (x = length), ``"bottom"``
        (y = 0) and ``"top"`` (y = height) as facet sets.
    """
    f = "rectangle_mesh"
    length = _real(f, "argument 'length'", length, positive=True)
    height = _real(f, "argument 'height'", height, positive=True)
    nx, ny = _count(f, "nx", nx), _count(f, "ny", ny)
    _check_grid(f, nx=nx, ny=ny)
    if quad is not None:
        if quadrilaterals is not False:
            raise TypeError(f"{f}: give quadrilaterals= only (quad= is its deprecated spelling), not both")
        warnings.warn(f"{f}(quad=...) is deprecated; use {f}(quadrilaterals=...), as box_mesh(hexahedra=...)",
                      DeprecationWarning, stacklevel=2)
        quadrilaterals = quad
    if not isinstance(quadrilaterals, (bool, np.bool_)):
        raise TypeError(f"{f}: argument 'quadrilaterals' must be True or False, got {quadrilaterals!r}")
    x, y = np.linspace(0.0, length, nx + 1), np.linspace(0.0, height, ny + 1)
    mesh = (skfem.MeshQuad if quadrilaterals else skfem.MeshTri).init_tensor(x, y)
    return _faces(mesh, {"left": (0, 0.0), "right": (0, length), "bottom": (1, 0.0), "top": (1, height)})


def box_mesh(length: float = 1.0, width: float = 0.1, height: float = 0.1, nx: int = 10, ny: int = 1,
             nz: int = 1, *, hexahedra: bool = False) -> skfem.Mesh:
    """Structured mesh of the box ``[0, length] x [0, width] x [0, height]``.

    The x axis is the length, y the width and z the height.

    Parameters
    ----------
    length, width, height : float
        Sides, finite and > 0.
    nx, ny, nz : int
        Number of element divisions along x, y and z (>= 1).
    hexahedra : bool
        Trilinear hexahedra (``skfem.MeshHex``) instead of tetrahedra (``skfem.MeshTet``, each
        cell of the grid split in several).

    Returns
    -------
    skfem.MeshTet or skfem.MeshHex
        With the boundaries ``"left"`` (x = 0), ``"right"`` (x = length), ``"front"``
        (y = 0), ``"back"`` (y = width), ``"bottom"`` (z = 0) and ``"top"`` (z = height).
    """
    f = "box_mesh"
    length = _real(f, "argument 'length'", length, positive=True)
    width = _real(f, "argument 'width'", width, positive=True)
    height = _real(f, "argument 'height'", height, positive=True)
    nx, ny, nz = _count(f, "nx", nx), _count(f, "ny", ny), _count(f, "nz", nz)
    _check_grid(f, nx=nx, ny=ny, nz=nz)
    if not isinstance(hexahedra, (bool, np.bool_)):
        raise TypeError(f"{f}: argument 'hexahedra' must be True or False, got {hexahedra!r}")
    axes = (np.linspace(0.0, length, nx + 1), np.linspace(0.0, width, ny + 1), np.linspace(0.0, height, nz + 1))
    mesh = (skfem.MeshHex if hexahedra else skfem.MeshTet).init_tensor(*axes)
    return _faces(mesh, {"left": (0, 0.0), "right": (0, length), "front": (1, 0.0), "back": (1, width),
                         "bottom": (2, 0.0), "top": (2, height)})
