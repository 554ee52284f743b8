"""Outputs layer: rendering bars and beams: the deformed structure as a tube, the obstacles as blocks.

The deformed line structure is drawn as a tube coloured by the displacement magnitude, the
obstacle of each contact as a small block at the gap, with a fixed camera and a fixed colour
range over the period so that frames are comparable (:func:`line_geometry`,
:func:`render_line_frames`; :func:`make_caption` and :func:`fix_camera` serve solids too).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..solvers.checks import entry_name
from .backend import INSTALL_HINT, snapshot
from .style import AnimationStyle, ContactQuality, frame_label

__all__ = ["line_geometry", "render_line_frames", "make_caption", "fix_camera"]

log = logging.getLogger(__name__)

@dataclass(frozen=True)
class _Geometry:
    """What :func:`animate` draws, in drawing coordinates: the deformed structure in every frame,
    the obstacles, and the bounds over the whole period."""

    frames_pts: np.ndarray  # (n_frames, n_points, 3), displacement magnified by scale
    magnitude: np.ndarray   # true |u|, (n_frames, n_points)
    clim: tuple[float, float]
    lines: np.ndarray       # VTK line cells of the mesh
    obstacles: list         # pyvista boxes, one per contact on a mesh node
    lo: np.ndarray          # lower corner of the bounds over the period
    hi: np.ndarray          # upper corner
    length: float
    radius: float
    scale: float
    axis: int               # 0: axial (bars), 1: deflection

    def structure(self, pv, j: int):
        """The tube of frame ``j`` with ``|u|`` as point data."""
        poly = pv.PolyData(self.frames_pts[j], lines=self.lines)
        poly.point_data["|u|"] = self.magnitude[j]
        return poly.tube(radius=self.radius, n_sides=16)


def _obstacle_boxes(pv, f, scale: float, length: float, axis: int) -> list:
    """One block per contact on a mesh node, its face at the (scaled) gap."""
    x = f.x
    obstacles = []
    for node, gap in zip(f.contact_nodes, f.contact_gaps):
        if node < 0:
            continue
        c = np.zeros(3)
        c[0] = x[node]
        th = 0.02 * length  # obstacle thickness, its face at the (scaled) gap
        if axis == 1:
            c[1] = scale * gap + th / 2
            obstacles.append(pv.Box(bounds=(c[0] - 0.06 * length, c[0] + 0.06 * length, c[1] - th / 2, c[1] + th / 2,
                                            -0.06 * length, 0.06 * length)))
        else:
            c[0] += scale * gap + th / 2
            obstacles.append(pv.Box(bounds=(c[0] - th / 2, c[0] + th / 2, -0.08 * length, 0.08 * length,
                                            -0.08 * length, 0.08 * length)))
    return obstacles


def _period_bounds(frames_pts: np.ndarray, radius: float, obstacles: list) -> tuple[np.ndarray, np.ndarray]:
    lo = frames_pts.reshape(-1, 3).min(axis=0) - radius
    hi = frames_pts.reshape(-1, 3).max(axis=0) + radius
    for ob in obstacles:
        b = np.asarray(ob.bounds).reshape(3, 2)
        lo, hi = np.minimum(lo, b[:, 0]), np.maximum(hi, b[:, 1])
    return lo, hi


def line_geometry(pv, f, n_frames: int, scale: float | None, radius: float | None) -> _Geometry:
    """Displacement scale (default: max |u| drawn as 15 % of the length), frames, obstacles and bounds."""
    length = float(np.ptp(f.x)) or 1.0
    umax = float(np.max(np.abs(f.displacement)))
    if scale is None:
        scale = 0.15 * length / umax if umax > 0 else 1.0
        log.info("%s: displacement scale %.4g (max |u| = %.4g drawn as 15%% of the length)", entry_name(), scale, umax)
    radius = 0.01 * length if radius is None else float(radius)
    axis = 0 if f.kind == "bar" else 1
    frames_pts = np.repeat(f.points()[None], n_frames, axis=0)
    frames_pts[:, :, axis] += scale * f.displacement
    magnitude = np.abs(f.displacement)
    clim = (0.0, float(magnitude.max()) if magnitude.max() > 0 else 1.0)
    obstacles = _obstacle_boxes(pv, f, scale, length, axis)
    lo, hi = _period_bounds(frames_pts, radius, obstacles)
    lines = np.hstack([np.full((f.cells.shape[0], 1), 2), f.cells]).ravel()
    return _Geometry(frames_pts=frames_pts, magnitude=magnitude, clim=clim, lines=lines, obstacles=obstacles,
                     lo=lo, hi=hi, length=length, radius=radius, scale=scale, axis=axis)


def fix_camera(plotter, lo: np.ndarray, hi: np.ndarray, length: float, width: int, height: int) -> None:
    """Fixed camera: orthographic view of the xy-plane, fitted to the bounds ``lo, hi`` of the whole period."""
    center = 0.5 * (lo + hi)
    half_w, half_h = 0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1])
    aspect = 0.78 * width / height  # leave room for the colour bar
    cam = plotter.camera
    plotter.enable_parallel_projection()
    cam.focal_point = tuple(center)
    cam.position = (center[0], center[1], center[2] + 10 * length)
    cam.up = (0.0, 1.0, 0.0)
    cam.parallel_scale = 1.1 * max(half_h, half_w / aspect, 1e-3 * length)
    cam.focal_point = (center[0] + 0.1 * 2 * cam.parallel_scale * width / height, center[1], center[2])
    cam.position = (cam.focal_point[0], center[1], center[2] + 10 * length)


def make_caption(style: AnimationStyle, f, scale: float, quality: ContactQuality | None) -> str:
    caption = [style.title] if style.title else []
    caption.append(f"w = {f.omega:.5g} rad/s, displacement x{scale:.3g}")
    if quality is not None:
        caption.append(quality.caption)
    return "\n".join(caption)


def _setup_scene(pv, plotter, geom: _Geometry, style: AnimationStyle, caption: str, size: tuple[int, int]) -> None:
    """Background, frame 0 with the colour bar, obstacles, camera and caption."""
    plotter.set_background("white")
    label = "abs. axial displ." if geom.axis == 0 else "abs. deflection"  # VTK fonts have no "|"
    if style.unit:
        label += f" [{style.unit}]"
    plotter.add_mesh(geom.structure(pv, 0), scalars="|u|", cmap=style.cmap, clim=geom.clim, name="structure",
                     smooth_shading=True,
                     scalar_bar_args={"title": label, "color": "black", "vertical": True, "position_x": 0.82,
                                      "position_y": 0.12, "height": 0.7, "width": 0.05, "fmt": "%.1e",
                                      "title_font_size": 12, "label_font_size": 11})
    for k, ob in enumerate(geom.obstacles):
        plotter.add_mesh(ob, color="dimgray", opacity=0.9, name=f"obstacle{k}")
    fix_camera(plotter, geom.lo, geom.hi, geom.length, *size)
    plotter.add_text(caption, font_size=9, color="black", position="upper_left", name="title")


def _draw_contacts(pv, plotter, geom: _Geometry, quality: ContactQuality, j: int) -> None:
    """A ball at each contact node of frame ``j``, red where it is inside the obstacle."""
    ball = 2.2 * geom.radius
    # the contact balls sit in front of the obstacle blocks (same x, y in the orthographic view)
    z_front = 0.1 * geom.length + ball
    for c, node in enumerate(quality.nodes):
        plotter.add_mesh(pv.Sphere(radius=ball, center=geom.frames_pts[j, node] + (0.0, 0.0, z_front)),
                         name=f"contact{c}",
                         color="red" if quality.penetrating(j)[c] else "black", reset_camera=False)


def _render_frame(pv, plotter, geom: _Geometry, quality: ContactQuality | None, j: int, n_frames: int,
                  cmap: str) -> np.ndarray:
    """Draw frame ``j`` (structure, contact overlay, time label) and return its RGB image."""
    if j:
        plotter.add_mesh(geom.structure(pv, j), scalars="|u|", cmap=cmap, clim=geom.clim, name="structure",
                         smooth_shading=True, show_scalar_bar=False, reset_camera=False)
    now, color = frame_label(quality, j, n_frames)
    if quality is not None:
        _draw_contacts(pv, plotter, geom, quality, j)
    plotter.add_text(now, font_size=9, color=color, position="lower_left", name="time")
    return snapshot(plotter)


def render_line_frames(pv, geom: _Geometry, quality: ContactQuality | None, style: AnimationStyle, caption: str,
                   size: tuple[int, int], n_frames: int) -> list[np.ndarray]:
    """All frames, off screen with a fixed camera; raises RuntimeError on blank output."""
    plotter = pv.Plotter(off_screen=True, window_size=size)
    images = []
    try:
        _setup_scene(pv, plotter, geom, style, caption, size)
        for j in range(n_frames):
            images.append(_render_frame(pv, plotter, geom, quality, j, n_frames, style.cmap))
    finally:
        plotter.close()
    if np.all(images[0] == images[0].reshape(-1, 3)[0]):
        raise RuntimeError(f"{entry_name()}: the renderer produced a blank frame (broken OpenGL?). {INSTALL_HINT}")
    return images
