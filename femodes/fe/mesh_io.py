"""Models layer: reading meshes from files (:func:`load_mesh`): meshio and gmsh parsing, region tags and names.

:func:`load_mesh` reads any meshio format (gmsh ``.msh`` first) and returns either the canonical
line mesh of :mod:`femodes.fe.mesh` (straight, duplicate-free, numbered from left to right) or a
2-D/3-D scikit-fem mesh with named boundaries, subdomains and points (gmsh physical groups);
duplicate nodes and zero-length elements are checked here.  ``meshio.read`` calls
``sys.exit(1)`` (after printing to the console) when a reader rejects a file; :func:`load_mesh`
guards against that and turns it into a ``ValueError``.
"""
from __future__ import annotations

import contextlib
import io
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import meshio
import numpy as np
import skfem
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .mesh_names import RESERVED, build_line_mesh, remember_points

__all__ = ["load_mesh", "COLLINEAR_RTOL"]

#: Relative tolerance (times the end-to-end length) for the distance of a
#: vertex from the straight line in :func:`load_mesh`.  Generous enough for
#: single-precision coordinates of tilted lines.
COLLINEAR_RTOL = 1e-6

# relative length below which an element read from a file counts as zero
_ZERO_LENGTH_RTOL = 1e-12

# cell_data arrays that carry region tags, in order of preference
_TAG_KEYS = ("gmsh:physical", "region", "regions", "subdomain", "subdomains")

# ---------------------------------------------------------------------------
# reading files
# ---------------------------------------------------------------------------
def _candidate_formats(fname: str) -> list[str]:
    """meshio format names for the file's extension (gmsh first)."""
    ext = ""
    out: list[str] = []
    for suffix in reversed(Path(fname).suffixes):
        ext = (suffix + ext).lower()
        for fmt in meshio.extension_to_filetypes.get(ext, []):
            if fmt not in out:
                out.append(fmt)
    out.sort(key=lambda fmt: fmt != "gmsh")  # ".msh" is also claimed by ansys
    return out


def _read_meshio(fname: str) -> meshio.Mesh:
    """Read with meshio, turning every failure into a ValueError."""
    formats = _candidate_formats(fname)
    if not formats:
        raise ValueError(
            f"load_mesh: cannot read {fname!r}: meshio does not know the file "
            f"extension {Path(fname).suffix!r} (use e.g. .msh, .vtu, .vtk, .xdmf)"
        )
    complaints = []
    for fmt in formats:
        buf = io.StringIO()
        try:
            with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
                return meshio.read(fname, file_format=fmt)
        except SystemExit:
            # meshio prints the reader's ReadError and calls sys.exit(1)
            lines = [
                ln.strip() for ln in buf.getvalue().splitlines()
                if ln.strip() and "couldn't read file" not in ln.lower()
            ]
            complaints.append(f"{fmt} reader: " + ("; ".join(lines) or "not a valid file"))
        except Exception as exc:  # noqa: BLE001 - reader errors are arbitrary
            complaints.append(f"{fmt} reader: {type(exc).__name__}: {exc}")
    raise ValueError(
        f"load_mesh: cannot read mesh file {fname!r}: " + " | ".join(complaints)
    )


def _tag_key(cell_data: Mapping) -> str | None:
    lower = {k.lower(): k for k in cell_data}
    for key in _TAG_KEYS:
        if key in lower:
            return lower[key]
    return None


def _int_tags(fname: str, key: str, data, ncells: int) -> np.ndarray:
    arr = np.asarray(data)
    if arr.ndim == 2 and arr.shape[1] == 1:
        arr = arr[:, 0]
    if arr.ndim != 1 or arr.shape[0] != ncells:
        raise ValueError(
            f"load_mesh: {fname!r}: cell data {key!r} has shape {np.shape(data)}, "
            f"expected one integer tag per cell ({ncells})"
        )
    if arr.dtype.kind in "iu":
        return arr.astype(np.int64)
    if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
        return arr.astype(np.int64)
    raise ValueError(
        f"load_mesh: {fname!r}: cell data {key!r} must hold integer region tags, "
        f"got dtype {arr.dtype} (e.g. {arr.ravel()[:3].tolist()})"
    )


def _field_names(field_data: Mapping) -> dict[tuple[int, int], str]:
    """gmsh-style ``name -> [tag, dim]`` as ``(dim, tag) -> name``."""
    names = {}
    for name, value in field_data.items():
        arr = np.asarray(value)
        if arr.shape != (2,) or arr.dtype.kind not in "iuf":
            continue  # not a physical-name entry (e.g. a VTK TimeValue)
        tag, dim = arr.tolist()
        if tag != int(tag) or dim not in (0, 1, 2, 3):
            continue
        names[(int(dim), int(tag))] = str(name)
    return names


def _fmt_point(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"


def _is_line_type(cell_type: str) -> bool:
    return cell_type == "line" or (
        cell_type.startswith("line") and cell_type[4:].isdigit()
    )


def load_mesh(path) -> skfem.Mesh:
    """Read a straight 1-D mesh (bar or beam), or a 2-D/3-D solid mesh, from a file.

    A file with triangle/quadrilateral (2-D) or tetrahedron/hexahedron (3-D) cells is read as a solid
    mesh; any other file as a line mesh. ``line`` cells are the elements (higher-order ones by their
    end vertices), ``vertex`` cells carry named points, and gmsh physical groups become names (unnamed
    tags: ``"point_<tag>"``, ``"region_<tag>"``). The line must be one straight, unbranched chain; its
    coordinate ``s`` is ``p . d`` along its unit direction ``d`` (for a line along an axis, that
    coordinate). Quadratic solid cells are read by their corner nodes. The full rules (cells,
    geometry, names, solids): :doc:`/howto/gmsh-mesh`.

    Parameters
    ----------
    path : str or os.PathLike
        Mesh file in any format meshio reads (gmsh ``.msh`` v2/v4 ascii or binary, ``.vtu``, ``.vtk``,
        ``.xdmf``, ...).

    Returns
    -------
    skfem.MeshLine, or skfem.MeshTri/MeshQuad/MeshTet/MeshHex
        Canonical line mesh (see the module docstring) with the coordinate ``s`` along the line; named
        points in ``mesh.boundaries`` and subdomains in ``mesh.subdomains``. For a solid mesh: named
        boundaries (facet sets) in ``mesh.boundaries``, subdomains in ``mesh.subdomains`` and named
        points from :func:`named_points`.

    Raises
    ------
    TypeError
        If ``path`` is not a str or path-like.
    FileNotFoundError
        If the file does not exist.
    ValueError
        If meshio cannot read the file, or the mesh is not a single straight unbranched line; the
        message names the file and the problem.
    """
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(
            f"load_mesh: argument 'path' must be a str or os.PathLike, got {path!r} "
            f"of type {type(path).__name__}"
        )
    fname = os.fspath(path)
    if not isinstance(fname, str):
        raise TypeError(f"load_mesh: argument 'path' must name a file as str, got {path!r}")
    if not os.path.exists(fname):
        raise FileNotFoundError(f"load_mesh: mesh file {fname!r} does not exist")
    if os.path.isdir(fname):
        raise ValueError(f"load_mesh: {fname!r} is a directory, not a mesh file")

    raw = _read_meshio(fname)
    _warn_shared_physical_groups(fname)
    if any(block.type in _SOLID_TYPES for block in raw.cells):
        mesh = _from_meshio_solid(raw, fname)
        _warn_duplicate_nodes(mesh, fname)
        return mesh
    return _from_meshio(raw, fname)


def _gmsh4_shared_groups(fname: str) -> list[tuple[int, int, list[str]]]:
    """``[(dim, entity tag, [physical group names])]`` of the entities of an ASCII gmsh 4 file that
    belong to more than one physical group (read from its ``$Entities`` and ``$PhysicalNames``);
    ``[]`` for other files, binary ones included."""
    try:
        with open(fname, "rb") as f:
            head = f.read(64)
            if not head.startswith(b"$MeshFormat") or head.split()[1:3] != [b"4.1", b"0"]:
                return []
            f.seek(0)
            names: dict[tuple[int, int], str] = {}
            shared = []
            section = None
            counts: list[int] = []
            for raw in f:
                line = raw.decode("utf-8", "replace").strip()
                if line.startswith("$"):
                    if line == "$EndEntities":
                        break
                    section, counts = line, []
                    continue
                if section == "$PhysicalNames" and line.count('"') == 2:
                    d_text, t_text, name = line.split(maxsplit=2)
                    names[(int(d_text), int(t_text))] = name.strip('"')
                elif section == "$Entities":
                    words = line.split()
                    if not counts:
                        counts = [int(w) for w in words[:4]]
                        dims = [d for d in range(4) for _ in range(counts[d])]
                        row = 0
                        continue
                    dim = dims[row]
                    row += 1
                    k = 4 if dim == 0 else 7          # tag, x y z | tag, min xyz, max xyz
                    n_phys = int(words[k])
                    if n_phys > 1:
                        tags = [abs(int(w)) for w in words[k + 1:k + 1 + n_phys]]
                        shared.append((dim, int(words[0]), [names.get((dim, t), f"region_{t}") for t in tags]))
            return shared
    except (OSError, ValueError, IndexError):
        return []


def _warn_shared_physical_groups(fname: str) -> None:
    """Warn when an entity of a gmsh 4 file is in several physical groups: meshio gives its cells
    the first group only, so the others lose them without a word (a corner point in "tip" and
    "tipcorners": "tipcorners" had 3 of its 4 nodes, and clamped="tipcorners" clamped 3)."""
    shared = _gmsh4_shared_groups(fname)
    if not shared:
        return
    dim, tag, groups = shared[0]
    warnings.warn(
        f"load_mesh: {fname!r}: {len(shared)} gmsh {'entities belong' if len(shared) > 1 else 'entity belongs'} to "
        f"more than one physical group (e.g. the {('point', 'curve', 'surface', 'volume')[dim]} {tag} in "
        f"{', '.join(map(repr, groups))}); meshio keeps only the first group of each, so the group"
        f"{'s' * (len(groups) > 2)} {', '.join(map(repr, groups[1:]))} miss its elements or nodes; save the mesh in gmsh's 2.2 format (gmsh.option.setNumber('Mesh.MshFileVersion', 2.2)), which keeps "
        "every group, or put each entity in one group", UserWarning, stacklevel=3)


def _warn_duplicate_nodes(mesh, fname: str) -> None:
    """Nodes at the same position (to 1e-9 of the mesh size) are not shared by the elements that
    meet there: an unmerged mesh (gmsh volumes meshed apart without ``Coherence``), whose parts are
    not connected and float free (``linear_modes`` finds near-zero frequencies)."""
    p = np.asarray(mesh.p, dtype=float).T
    if p.shape[0] < 2:
        return
    size = float(np.max(np.ptp(p, axis=0))) or 1.0
    keys = np.round(p / (1e-9 * size)).astype(np.int64)
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    n_dup = int(np.sum(counts - 1))
    if n_dup:
        i = int(first[np.argmax(counts > 1)])
        warnings.warn(f"load_mesh: {fname!r} has {n_dup} node(s) at the position of another node (e.g. node {i} at "
                      f"{tuple(float(v) for v in p[i])}): the mesh is not merged, so its parts are not connected and "
                      "float free; merge the duplicate nodes (gmsh: Coherence before meshing, or "
                      "Mesh.RemoveDuplicateNodes) and load it again", UserWarning, stacklevel=3)


@dataclass
class _Cells:
    """Line and vertex cells of a meshio mesh, with the names of their physical groups."""

    conn: np.ndarray                           # (n_lines, 2) node indices of the line elements
    line_groups: dict[str, list[np.ndarray]]   # name -> indices into conn
    point_groups: dict[str, list[np.ndarray]]  # name -> node indices
    note: str                                  # the ignored 2-D/3-D cells, for error messages


def _from_meshio(raw: meshio.Mesh, fname: str):
    """Convert a meshio mesh to the canonical MeshLine (see load_mesh)."""
    pts = np.asarray(raw.points, dtype=np.float64)
    if pts.ndim == 1:
        pts = pts[:, None]
    if pts.ndim != 2 or not np.all(np.isfinite(pts)):
        raise ValueError(f"load_mesh: {fname!r}: point coordinates are not finite numbers")
    cells = _collect_cells(raw, pts.shape[0], fname)
    uniq, inverse, used, local = _unique_elements(cells.conn, pts, fname)
    P = pts[used]
    _check_single_open_line(local, P, fname, cells.note)
    x, rank = _positions_along_line(local, P, fname, cells.note)
    old_to_vertex = np.full(pts.shape[0], -1, dtype=np.int64)
    old_to_vertex[used] = rank
    points = _named_points(cells.point_groups, old_to_vertex, pts, x, fname)
    new_elem = rank[local].min(axis=1)  # element number of each unique element
    regions = {name: np.unique(new_elem[inverse[np.concatenate(chunks)]]) for name, chunks in cells.line_groups.items()}
    return build_line_mesh(x, points, regions)


def _collect_cells(raw: meshio.Mesh, npts: int, fname: str) -> _Cells:
    """Line elements and named point/line groups (gmsh physical groups or other integer tags)."""
    key = _tag_key(raw.cell_data)
    names = _field_names(raw.field_data or {})

    def label(dim: int, tag: int) -> str | None:
        if (dim, tag) in names:
            return names[(dim, tag)]
        if key == "gmsh:physical" and tag == 0:
            return None
        return f"point_{tag}" if dim == 0 else f"region_{tag}"

    conns = []
    line_groups: dict[str, list[np.ndarray]] = {}
    point_groups: dict[str, list[np.ndarray]] = {}
    others: dict[str, int] = {}
    nlines = 0
    for ib, block in enumerate(raw.cells):
        ctype = block.type
        data = np.asarray(block.data)
        if _is_line_type(ctype):
            dim = 1
        elif ctype == "vertex":
            dim = 0
        else:
            others[ctype] = others.get(ctype, 0) + len(data)
            continue
        if data.size and (data.min() < 0 or data.max() >= npts):
            raise ValueError(
                f"load_mesh: {fname!r}: {ctype} cells refer to missing nodes "
                f"(node index out of range 0..{npts - 1})"
            )
        tags = _int_tags(fname, key, raw.cell_data[key][ib], len(data)) if key is not None else None
        if dim == 1:
            conn = data[:, :2].astype(np.int64)
            conns.append(conn)
            if tags is not None:
                for tag in np.unique(tags):
                    name = label(1, int(tag))
                    if name is not None:
                        line_groups.setdefault(name, []).append(nlines + np.nonzero(tags == tag)[0])
            nlines += len(conn)
        elif tags is not None:
            for tag in np.unique(tags):
                name = label(0, int(tag))
                if name is not None:
                    point_groups.setdefault(name, []).append(data[tags == tag, 0])
    if nlines == 0:
        found = ", ".join(f"{n} {t}" for t, n in others.items()) or "no cells"
        raise ValueError(
            f"load_mesh: {fname!r} contains no line cells (1-D elements); it has "
            f"{found}.  A bar/beam mesh needs 'line' elements (in gmsh, put the "
            f"curve in a Physical Curve so that its elements are saved)"
        )
    # mention ignored 2-D/3-D cells in topology errors (e.g. boundary lines of a surface mesh
    # are not a beam)
    note = (" (cells ignored by load_mesh: "
            + ", ".join(f"{n} {t}" for t, n in others.items()) + ")") if others else ""
    return _Cells(conn=np.vstack(conns), line_groups=line_groups, point_groups=point_groups, note=note)


def _unique_elements(conn: np.ndarray, pts: np.ndarray, fname: str):
    """Elements without repeats (gmsh 2.2 repeats elements in several groups) on the used nodes.

    Returns ``(uniq, inverse, used, local)``: unique elements (old node numbers), the unique
    element of each input element, the used old nodes, and the unique elements in used-node
    numbering."""
    bad = np.nonzero(conn[:, 0] == conn[:, 1])[0]
    if bad.size:
        raise ValueError(
            f"load_mesh: {fname!r}: {bad.size} degenerate line element(s) with "
            f"both ends at the same node, e.g. at {_fmt_point(pts[conn[bad[0], 0]])}"
        )
    uniq, inverse = np.unique(np.sort(conn, axis=1), axis=0, return_inverse=True)
    used, local = np.unique(uniq, return_inverse=True)
    return uniq, np.asarray(inverse).reshape(-1), used, np.asarray(local).reshape(uniq.shape)


def _check_single_open_line(local: np.ndarray, P: np.ndarray, fname: str, note: str) -> None:
    """One connected, unbranched, open chain of elements."""
    nel, nv = local.shape[0], P.shape[0]
    degree = np.bincount(local.ravel(), minlength=nv)
    branch = np.nonzero(degree > 2)[0]
    if branch.size:
        where = "; ".join(f"{_fmt_point(P[v])} ({degree[v]} elements)" for v in branch[:3])
        raise ValueError(
            f"load_mesh: {fname!r}: the line mesh branches: {branch.size} vertex/vertices "
            f"shared by more than 2 line elements, at {where}"
            f"{' ...' if branch.size > 3 else ''}; a bar/beam mesh must be a single "
            f"unbranched line{note}"
        )
    graph = coo_matrix((np.ones(nel), (local[:, 0], local[:, 1])), shape=(nv, nv))
    ncomp, comp = connected_components(graph, directed=False)
    if ncomp > 1:
        sizes = np.bincount(comp[local[:, 0]], minlength=ncomp)
        parts = ", ".join(str(s) for s in sorted(sizes.tolist(), reverse=True)[:5])
        raise ValueError(
            f"load_mesh: {fname!r}: the line mesh is disconnected: {ncomp} separate "
            f"parts with {parts}{' ...' if ncomp > 5 else ''} elements; a bar/beam "
            f"mesh must be one connected line (note: coincident nodes with different "
            f"indices are not merged - remove duplicate nodes, e.g. gmsh 'Coherence Mesh')"
            f"{note}"
        )
    if nel != nv - 1:
        raise ValueError(
            f"load_mesh: {fname!r}: the line elements form a closed loop; a bar/beam "
            f"mesh must be an open line with two ends{note}"
        )


def _positions_along_line(local: np.ndarray, P: np.ndarray, fname: str, note: str):
    """Abscissa of the vertices along the straight line through the two ends, sorted, and the
    rank of each vertex in that order; checks collinearity and element order."""
    nv = P.shape[0]
    degree = np.bincount(local.ravel(), minlength=nv)
    ends = np.nonzero(degree == 1)[0]
    a = P[ends[0]]
    dist = np.linalg.norm(P - a, axis=1)
    far = int(np.argmax(dist))
    length = float(dist[far])
    if not length > 0.0:
        raise ValueError(f"load_mesh: {fname!r}: all vertices coincide (zero length)")
    d = (P[far] - a) / length
    first = int(np.nonzero(np.abs(d) >= np.abs(d).max() - 1e-12)[0][0])
    if d[first] < 0:
        d = -d
    rel = P - a
    dev = np.linalg.norm(rel - np.outer(rel @ d, d), axis=1)
    worst = int(np.argmax(dev))
    tol = COLLINEAR_RTOL * length
    if dev[worst] > tol:
        raise ValueError(
            f"load_mesh: {fname!r}: the points are not collinear: max deviation from "
            f"the straight line through the end points is {dev[worst]:.6g} (at point "
            f"{_fmt_point(P[worst])}; line length {length:.6g}, tolerance {tol:.3g}); "
            f"bar/beam meshes must be straight{note}"
        )
    s = P @ d
    order = np.argsort(s, kind="stable")
    x = s[order]
    small = np.nonzero(np.diff(x) <= _ZERO_LENGTH_RTOL * length)[0]
    if small.size:
        raise ValueError(
            f"load_mesh: {fname!r}: two vertices coincide at "
            f"{_fmt_point(P[order[small[0]]])} (zero-length element or the line "
            f"folds back on itself)"
        )
    rank = np.empty(nv, dtype=np.int64)
    rank[order] = np.arange(nv)
    r = rank[local]
    if np.any(np.abs(r[:, 0] - r[:, 1]) != 1):
        e = int(np.nonzero(np.abs(r[:, 0] - r[:, 1]) != 1)[0][0])
        raise ValueError(
            f"load_mesh: {fname!r}: the line folds back on itself: the element from "
            f"{_fmt_point(P[local[e, 0]])} to {_fmt_point(P[local[e, 1]])} overlaps "
            f"other elements"
        )
    return x, rank


def _named_points(point_groups: dict, old_to_vertex: np.ndarray, pts: np.ndarray, x: np.ndarray, fname: str) -> dict:
    """Vertices of the named point groups, plus the two ends "left" and "right"."""
    nv = x.size
    points: dict[str, np.ndarray] = {"left": np.array([0]), "right": np.array([nv - 1])}
    for name, chunks in point_groups.items():
        old = np.unique(np.concatenate(chunks))
        verts = old_to_vertex[old]
        if np.any(verts < 0):
            off = old[verts < 0][0]
            raise ValueError(
                f"load_mesh: {fname!r}: named point {name!r} at "
                f"{_fmt_point(pts[off])} is not a vertex of any line element"
            )
        verts = np.unique(verts)
        if name in RESERVED and not np.array_equal(verts, points[name]):
            raise ValueError(
                f"load_mesh: {fname!r}: point group {name!r} does not denote the "
                f"{name} end of the line (s = {x[points[name][0]]:.6g}); the name is "
                f"reserved, rename the group"
            )
        points[name] = verts
    return points


# meshio cell types of solid cells; their dimension
_SOLID_TYPES = {"triangle": 2, "triangle6": 2, "quad": 2, "quad8": 2, "quad9": 2,
                "tetra": 3, "tetra10": 3, "hexahedron": 3, "hexahedron20": 3, "hexahedron27": 3}

# quadratic cells -> (linear type, number of corners; meshio stores the corners first)
_QUADRATIC = {"line3": ("line", 2), "triangle6": ("triangle", 3), "quad8": ("quad", 4), "quad9": ("quad", 4),
              "tetra10": ("tetra", 4), "hexahedron20": ("hexahedron", 8), "hexahedron27": ("hexahedron", 8)}


def _from_meshio_solid(raw: meshio.Mesh, fname: str):
    """A 2-D/3-D scikit-fem mesh with named boundaries, subdomains and points (see load_mesh)."""
    from skfem.io.meshio import from_meshio

    pts = np.asarray(raw.points, dtype=np.float64)
    if pts.ndim != 2 or not np.all(np.isfinite(pts)):
        raise ValueError(f"load_mesh: {fname!r}: point coordinates are not finite numbers")
    dim = max(_SOLID_TYPES[b.type] for b in raw.cells if b.type in _SOLID_TYPES)
    kinds = sorted({b.type for b in raw.cells if _SOLID_TYPES.get(b.type) == dim})
    if len(kinds) > 1:
        raise ValueError(
            f"load_mesh: {fname!r}: mixed {dim}-D cell types {kinds}; femodes solids need one cell type "
            "(in gmsh, mesh with only triangles/quadrilaterals or only tetrahedra/hexahedra)"
        )
    cell_type = _QUADRATIC.get(kinds[0], (kinds[0], 0))[0]
    linear = []  # (type, connectivity) of every block, quadratic cells by their corners
    for block in raw.cells:
        conn = np.asarray(block.data)
        if block.type in _QUADRATIC:
            ctype, corners = _QUADRATIC[block.type]
            linear.append((ctype, conn[:, :corners]))
        else:
            linear.append((block.type, conn))
    if dim == 2 and pts.shape[1] > 2 and np.ptp(pts[:, 2]) > 1e-9 * max(np.ptp(pts[:, :2]), 1e-300):
        raise ValueError(
            f"load_mesh: {fname!r}: a 2-D mesh ({cell_type} cells) must lie in a plane z = const, "
            f"but z ranges over {pts[:, 2].min():.6g}..{pts[:, 2].max():.6g}"
        )
    # drop nodes used by no solid cell (they would carry DOFs without stiffness or mass)
    used = np.unique(np.concatenate([conn.ravel() for ctype, conn in linear if ctype == cell_type]))
    new = np.full(pts.shape[0], -1, dtype=np.int64)
    new[used] = np.arange(used.size)
    point_groups: dict[str, list] = {}
    names = _field_names(raw.field_data or {})
    key = _tag_key(raw.cell_data)
    blocks: list = []
    data: dict = {}
    for ib, (ctype, conn) in enumerate(linear):
        if ctype == "vertex":
            if key is not None:
                tags = _int_tags(fname, key, raw.cell_data[key][ib], len(conn))
                for tag in np.unique(tags):
                    name = names.get((0, int(tag)))
                    if name is not None:
                        point_groups.setdefault(name, []).append(conn[tags == tag, 0])
            continue
        if np.any(new[conn] < 0):
            continue  # facets/lines not on the solid cells
        blocks.append(meshio.CellBlock(ctype, new[conn]))
        for k, arrays in raw.cell_data.items():
            data.setdefault(k, []).append(np.asarray(arrays[ib]))
    clean = meshio.Mesh(pts[used], blocks, cell_data=data, field_data=raw.field_data)
    # meshio builds the named cell sets from gmsh:physical and field_data
    try:
        clean.cell_sets = {}
        if key == "gmsh:physical" and names:
            sets: dict[str, list] = {}
            for ib, block in enumerate(clean.cells):
                tags = np.asarray(clean.cell_data[key][ib]).reshape(-1)
                d = 1 if _is_line_type(block.type) else _SOLID_TYPES.get(block.type, -1)
                for (ndim, tag), name in names.items():
                    sets.setdefault(name, [np.zeros(0, dtype=np.int64) for _ in clean.cells])
                    if ndim == d:
                        sets[name][ib] = np.nonzero(tags == tag)[0]
            clean.cell_sets = {k: v for k, v in sets.items() if any(a.size for a in v)}
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            mesh = from_meshio(clean, ignore_orientation=True)
    except (ValueError, IndexError, KeyError, NotImplementedError) as exc:
        raise ValueError(f"load_mesh: {fname!r}: cannot build a {cell_type} mesh: {exc}") from exc
    boundaries = {k: np.asarray(v, dtype=np.int32) for k, v in (mesh.boundaries or {}).items()}
    subdomains = {k: np.asarray(v, dtype=np.int32) for k, v in (mesh.subdomains or {}).items()
                  if not k.startswith("gmsh:")}
    mesh = mesh.with_boundaries(boundaries, boundaries_only=False) if boundaries else mesh
    mesh = mesh.with_subdomains(subdomains) if subdomains else mesh
    points = {}
    for name, chunks in point_groups.items():
        nodes = new[np.unique(np.concatenate(chunks))]
        if np.any(nodes < 0):
            raise ValueError(f"load_mesh: {fname!r}: named point {name!r} is not a node of any {cell_type} cell")
        points[name] = nodes
    remember_points(mesh, points)
    return mesh
