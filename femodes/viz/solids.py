"""Outputs layer: rendering meshed solids (2-D and 3-D): the deformed mesh, its obstacle and contact nodes.

Meshed solids (:func:`femodes.solid`, 2-D and 3-D) are drawn as the deformed mesh (surface
with element edges; quadratic cells subdivided so that P2 elements curve), coloured by the
displacement magnitude or the contact pressure (``AnimationStyle(scalars=...)``), with the
obstacle at the (scaled) gap of every contact node: a band along the boundary in 2-D, a
translucent surface in 3-D (a gap that varies along the boundary, e.g. a curved casing, shows
as a curved obstacle), and the contact nodes grey when open, blue when closed and red when
penetrating. 2-D solids are seen in the xy-plane, 3-D ones from a fixed oblique direction
(z up), both with a parallel projection fitted to the whole period.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..solvers.checks import entry_name
from ..fields import VTK_QUADRATIC_NODES
from .backend import INSTALL_HINT, snapshot
from .lines import fix_camera
from .style import AnimationStyle, ContactQuality, frame_label

__all__ = ["solid_scene", "render_solid"]

log = logging.getLogger(__name__)

#: Fraction of the gap within which a contact node counts as closed (drawn blue); beyond
#: ``-_PENETRATION_TOL`` of the gap inside the obstacle it is penetrating (red), as for 1-D.
_CLOSED_TOL = 1e-2
_PENETRATION_TOL = 1e-3


def _pv_cell_type(pv, cell_type: str):
    return {"triangle": pv.CellType.TRIANGLE, "triangle6": pv.CellType.QUADRATIC_TRIANGLE,
            "quad": pv.CellType.QUAD, "quad9": pv.CellType.BIQUADRATIC_QUAD,
            "tetra": pv.CellType.TETRA, "tetra10": pv.CellType.QUADRATIC_TETRA,
            "hexahedron": pv.CellType.HEXAHEDRON, "hexahedron27": pv.CellType.TRIQUADRATIC_HEXAHEDRON}[cell_type]


def _cell_edges(cell_type: str, cells: np.ndarray) -> np.ndarray:
    """Unique element edges as node triples ``(a, mid, b)`` (``mid = a`` for linear cells) for drawing.

    The edges of a cell are the vertex pairs of :data:`VTK_QUADRATIC_NODES`, listed first and in
    the order of the mid-side nodes of the quadratic cell."""
    quadratic = {"triangle": "triangle6", "quad": "quad9", "tetra": "tetra10", "hexahedron": "hexahedron27"}
    is_quadratic = cell_type not in quadratic
    q = quadratic.get(cell_type, cell_type)
    pairs = [s for s in VTK_QUADRATIC_NODES[q] if len(s) == 2]
    n_vertices = {"triangle6": 3, "quad9": 4, "tetra10": 4, "hexahedron27": 8}[q]
    rows = []
    for k, (a, b) in enumerate(pairs):
        mid = n_vertices + k if is_quadratic else a
        rows.append(np.stack([cells[:, a], cells[:, mid], cells[:, b]], axis=1))
    edges = np.vstack(rows)
    key = np.sort(edges[:, [0, 2]], axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    return edges[np.sort(first)]


@dataclass(frozen=True)
class _SolidScene:
    """What :func:`animate` draws for a meshed solid, in drawing coordinates."""

    frames_pts: np.ndarray   # (n_frames, n_nodes, 3), displacement magnified by scale
    values: np.ndarray       # (n_frames, n_nodes): the colouring field (true |u|, or the pressure)
    clim: tuple[float, float]
    label: str               # colour bar title
    pressure: bool           # colour by contact pressure (2-D: along the contact boundary)
    cell_type: str
    cells: np.ndarray
    edges: np.ndarray        # (n_edges, 3) node triples
    paths: list              # 2-D: ordered contact nodes of each contact boundary
    obstacles: list          # pyvista meshes in drawing coordinates
    lo: np.ndarray
    hi: np.ndarray
    length: float            # largest extent of the undeformed mesh
    scale: float
    dim: int

    def structure(self, pv, j: int):
        """Surface of frame ``j`` (quadratic cells subdivided, so that P2 edges curve) with the values."""
        grid = pv.UnstructuredGrid({_pv_cell_type(pv, self.cell_type): self.cells}, self.frames_pts[j])
        grid.point_data["value"] = self.values[j]
        quadratic = self.cell_type in ("triangle6", "quad9", "tetra10", "hexahedron27")
        return grid.extract_surface(nonlinear_subdivision=2 if quadratic else 0, algorithm="dataset_surface")

    def mesh_lines(self, pv, j: int):
        """Element edges of frame ``j`` (through the mid-side nodes of quadratic cells)."""
        e = self.edges
        return pv.PolyData(self.frames_pts[j], lines=np.hstack([np.full((e.shape[0], 1), 3), e]).ravel())

    def boundary_lines(self, pv, j: int) -> list:
        """2-D pressure colouring: one polyline per contact boundary through its contact nodes."""
        out = []
        for nodes in self.paths:
            line = pv.lines_from_points(self.frames_pts[j, nodes])
            line.point_data["value"] = self.values[j, nodes]
            out.append(line.tube(radius=0.008 * self.length, n_sides=12))
        return out


def _solid_obstacles(pv, f, scale: float, length: float, paths: list) -> list:
    """The obstacles at ``x_node + scale * gap * direction``: a band behind a polyline in 2-D
    (one per contact boundary, along the boundary), a surface in 3-D (the contact facets moved
    onto the obstacle points; curved casings follow the gap function)."""
    obstacle = f.obstacle_points(scale)
    out = []
    if f.dim == 2:
        for nodes, contacts in paths:
            P = obstacle[contacts]
            band = P + 0.03 * length * f.contact_direction[contacts]
            pts = np.vstack([P, band])
            n = P.shape[0]
            quads = [[4, k, k + 1, n + k + 1, n + k] for k in range(n - 1)]
            if n >= 2:
                out.append(pv.PolyData(pts, faces=np.asarray(quads).ravel()))
            else:  # a single contact node: a small block
                out.append(pv.Sphere(radius=0.01 * length, center=P[0]))
        return out
    by_node: dict = {}
    for c, (node, b) in enumerate(zip(f.contact_nodes, f.contact_boundary)):
        if node >= 0:
            by_node.setdefault(b, {})[int(node)] = c
    for b, lookup in by_node.items():
        facets = f.boundary_facets.get(b)
        if facets is None:
            out.append(pv.PolyData(obstacle[list(lookup.values())]))
            continue
        keep = facets[np.all(np.isin(facets, list(lookup)), axis=1)]
        if not keep.size:
            out.append(pv.PolyData(obstacle[list(lookup.values())]))
            continue
        idx = np.vectorize(lookup.get)(keep)
        faces = np.hstack([np.full((keep.shape[0], 1), keep.shape[1]), idx]).ravel()
        out.append(pv.PolyData(obstacle, faces=faces))
    return out


def _contact_paths(f) -> list:
    """2-D: for each contact boundary, its contact nodes ordered along it and their contact indices."""
    paths = []
    for b in sorted(set(f.contact_boundary)):
        contacts = [c for c, (node, cb) in enumerate(zip(f.contact_nodes, f.contact_boundary)) if cb == b and node >= 0]
        if not contacts:
            continue
        if b:
            order, _ = f.boundary_coordinate(b)
            rank = {int(n): k for k, n in enumerate(order)}
            contacts.sort(key=lambda c: rank[int(f.contact_nodes[c])])
        paths.append((f.contact_nodes[contacts], np.asarray(contacts)))
    return paths


def solid_scene(pv, f, scale: float | None, pressure: bool, unit: str | None) -> _SolidScene:
    """Displacement scale (default: the largest |u| over the period drawn as 15 % of the largest
    extent of the mesh), frames, colouring, obstacles and the bounds over the period."""
    X = f.points()
    length = float(np.ptp(X, axis=0).max()) or 1.0
    mag = np.linalg.norm(f.displacement, axis=2)
    umax = float(mag.max())
    if scale is None:
        scale = 0.15 * length / umax if umax > 0 else 1.0
        log.info("%s: displacement scale %.4g (max |u| = %.4g drawn as 15%% of the largest extent)", entry_name(), scale, umax)
    frames_pts = X[None] + scale * f.displacement
    paths = _contact_paths(f)
    if pressure:
        values = f.contact_pressure()
        label = "contact pressure"
    else:
        values, label = mag, "displacement magnitude"
        if unit:
            label += f" [{unit}]"
    top = float(values.max())
    clim = (0.0, top if top > 0 else 1.0)
    obstacles = _solid_obstacles(pv, f, scale, length, paths)
    lo, hi = frames_pts.reshape(-1, 3).min(axis=0), frames_pts.reshape(-1, 3).max(axis=0)
    for ob in obstacles:
        b = np.asarray(ob.bounds).reshape(3, 2)
        lo, hi = np.minimum(lo, b[:, 0]), np.maximum(hi, b[:, 1])
    return _SolidScene(frames_pts=frames_pts, values=values, clim=clim, label=label, pressure=pressure,
                       cell_type=f.cell_type, cells=f.cells, edges=_cell_edges(f.cell_type, f.cells),
                       paths=[p[0] for p in paths], obstacles=obstacles, lo=lo, hi=hi, length=length, scale=scale,
                       dim=f.dim)


def _fix_camera_3d(plotter, scene: _SolidScene, width: int, height: int) -> None:
    """Fixed camera for 3-D solids: a parallel projection from (1, -1.6, 1.1) (z up), fitted to the
    bounds over the whole period."""
    view = np.array([1.0, -1.6, 1.1])
    view /= np.linalg.norm(view)
    up = np.array([0.0, 0.0, 1.0])
    right = np.cross(-view, up)
    right /= np.linalg.norm(right)
    up = np.cross(right, -view)
    corners = np.array([[x, y, z] for x in (scene.lo[0], scene.hi[0]) for y in (scene.lo[1], scene.hi[1])
                        for z in (scene.lo[2], scene.hi[2])])
    center = 0.5 * (scene.lo + scene.hi)
    pr, pu = (corners - center) @ right, (corners - center) @ up
    aspect = 0.78 * width / height  # leave room for the colour bar
    half_w, half_h = 0.5 * np.ptp(pr), 0.5 * np.ptp(pu)
    center = center + right * 0.5 * (pr.max() + pr.min()) + up * 0.5 * (pu.max() + pu.min())
    plotter.enable_parallel_projection()
    cam = plotter.camera
    scale = 1.1 * max(half_h, half_w / aspect, 1e-3 * scene.length)
    focal = center + right * 0.1 * 2 * scale * width / height  # shift the body left of the colour bar
    cam.focal_point = tuple(focal)
    cam.position = tuple(focal + view * 10 * scene.length)
    cam.up = tuple(up)
    cam.parallel_scale = scale
    cam.clipping_range = (0.01 * scene.length, 30 * scene.length)


def _draw_solid(pv, plotter, scene: _SolidScene, style: AnimationStyle, j: int, first: bool) -> None:
    """The deformed solid of frame ``j`` (and the colour bar on the first frame)."""
    bar = {"title": scene.label, "color": "black", "vertical": True, "position_x": 0.82, "position_y": 0.12,
           "height": 0.7, "width": 0.05, "fmt": "%.1e", "title_font_size": 12, "label_font_size": 11}
    surface = scene.structure(pv, j)
    common = {"reset_camera": False}
    if scene.pressure and scene.dim == 2:
        plotter.add_mesh(surface, color="#c9d3de", name="structure", **common)
        for k, line in enumerate(scene.boundary_lines(pv, j)):
            plotter.add_mesh(line, scalars="value", cmap=style.pressure_cmap, clim=scene.clim, name=f"pressure{k}",
                             show_scalar_bar=first and k == 0, scalar_bar_args=bar, **common)
    else:
        plotter.add_mesh(surface, scalars="value", cmap=style.pressure_cmap if scene.pressure else style.cmap,
                         clim=scene.clim, name="structure",
                         show_scalar_bar=first, scalar_bar_args=bar, smooth_shading=scene.dim == 3, **common)
    plotter.add_mesh(scene.mesh_lines(pv, j), color="#333333", line_width=1, name="edges", **common)


def _draw_solid_contacts(pv, plotter, scene: _SolidScene, quality: ContactQuality, j: int) -> None:
    """Contact nodes of frame ``j``: grey open, blue closed (within 1 % of the gap of the
    obstacle), red penetrating (beyond 0.1 % of the gap)."""
    g = quality.frame_gaps[j]
    scale = np.maximum(np.abs(quality.gaps), 1e-12)
    pen = g < -_PENETRATION_TOL * scale
    closed = ~pen & (g <= _CLOSED_TOL * scale)
    nodes = np.asarray(quality.nodes)
    size = max(5, int(0.02 * max(plotter.window_size)))
    for name, mask, color, s in (("open", ~pen & ~closed, "#777777", 0.6 * size), ("closed", closed, "#1f6fd1", size),
                                 ("pen", pen, "red", size)):
        if mask.any():
            pts = scene.frames_pts[j, nodes[mask]]
            if scene.dim == 2:
                pts = pts + np.array([0.0, 0.0, 0.05 * scene.length])  # in front of the band and the tube
            plotter.add_mesh(pv.PolyData(pts), color=color, point_size=s, render_points_as_spheres=True,
                             name=f"contact_{name}", reset_camera=False)
        else:
            plotter.remove_actor(f"contact_{name}")


def render_solid(pv, f, scene: _SolidScene, quality: ContactQuality | None, style: AnimationStyle, caption: str,
                  size: tuple[int, int], n_frames: int) -> list[np.ndarray]:
    """All frames of a meshed solid, off screen with a fixed camera."""
    plotter = pv.Plotter(off_screen=True, window_size=size)
    images = []
    try:
        plotter.set_background("white")
        for k, ob in enumerate(scene.obstacles):
            plotter.add_mesh(ob, color="dimgray", opacity=0.9 if scene.dim == 2 else 0.35, name=f"obstacle{k}",
                             reset_camera=False)
        if scene.dim == 2:
            fix_camera(plotter, scene.lo, scene.hi, scene.length, *size)
        else:
            _fix_camera_3d(plotter, scene, *size)
        plotter.add_text(caption, font_size=9, color="black", position="upper_left", name="title")
        for j in range(n_frames):
            _draw_solid(pv, plotter, scene, style, j, first=j == 0)
            now, color = frame_label(quality, j, n_frames)
            if quality is not None:
                _draw_solid_contacts(pv, plotter, scene, quality, j)
            plotter.add_text(now, font_size=9, color=color, position="lower_left", name="time")
            images.append(snapshot(plotter))
    finally:
        plotter.close()
    if np.all(images[0] == images[0].reshape(-1, 3)[0]):
        raise RuntimeError(f"{entry_name()}: the renderer produced a blank frame (broken OpenGL?). {INSTALL_HINT}")
    return images
