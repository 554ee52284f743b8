"""Models layer: what built and read meshes share: the reserved end names, the canonical line mesh and named points.

:func:`build_line_mesh` makes the canonical ``MeshLine`` (see :mod:`femodes.fe.mesh`) from sorted
coordinates and named index sets; :func:`named_points` reads back the named points of any mesh
(the named vertices of a line mesh, the gmsh physical points that :func:`~femodes.fe.mesh.load_mesh`
kept for a 2-D/3-D mesh, registered with :func:`remember_points`).
"""
from __future__ import annotations

import weakref

import numpy as np
import skfem

__all__ = ["RESERVED", "build_line_mesh", "named_points", "remember_points"]

#: Names that always denote the two ends of a line mesh.
RESERVED = ("left", "right")


def build_line_mesh(x: np.ndarray, boundaries: dict, subdomains: dict):
    """Create the canonical MeshLine from sorted coordinates and index sets."""
    mesh = skfem.MeshLine(np.asarray(x, dtype=np.float64)[None, :])
    mesh = mesh.with_boundaries(
        {k: np.asarray(v, dtype=np.int32).reshape(-1) for k, v in boundaries.items()}
    )
    mesh = mesh.with_subdomains(
        {k: np.asarray(v, dtype=np.int32).reshape(-1) for k, v in subdomains.items()}
    )
    return mesh


# named points of 2-D/3-D meshes: scikit-fem meshes hold named facet sets (boundaries) and cell
# sets (subdomains) but no point sets, so load_mesh keeps them here, keyed by the id of the mesh
# object (entries are removed when the mesh is garbage-collected)
_NAMED_POINTS: dict[int, dict[str, np.ndarray]] = {}


def named_points(mesh) -> dict[str, np.ndarray]:
    """Named points of a mesh: ``{name: vertex indices}``.

    For a line mesh these are its named points (``mesh.boundaries``: facets are vertices). For
    a 2-D/3-D mesh read by :func:`load_mesh` they are the gmsh physical points (``vertex``
    cells) of the file. A mesh derived from it (``with_boundaries``, ``refined``, ...) is a new
    object without them: pass ``points=`` to :func:`femodes.solid` instead.
    """
    if isinstance(mesh, skfem.MeshLine):
        return {k: np.asarray(v, dtype=np.int64) for k, v in (mesh.boundaries or {}).items()}
    return {k: v.copy() for k, v in _NAMED_POINTS.get(id(mesh), {}).items()}


def remember_points(mesh, points: dict[str, np.ndarray]) -> None:
    """Keep the named points of a 2-D/3-D mesh for :func:`named_points` (until it is collected)."""
    if not points:
        return
    key = id(mesh)
    _NAMED_POINTS[key] = points
    weakref.finalize(mesh, _NAMED_POINTS.pop, key, None)

