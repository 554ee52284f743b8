"""Outputs layer: off-screen 3-D rendering of periodic motions to GIF / MP4 (pyvista, imageio).

:func:`animate` renders one period of a periodic solution (or of a linear mode) on the FE mesh:
the deformed structure as a tube coloured by the displacement magnitude, the obstacle of each
contact as a small block at the gap, with a fixed camera and a fixed colour range over the
period so that frames are comparable. For periodic solutions with contacts the contact quality
is shown, not hidden: a caption states the maximum penetration over the period (relative to the
gap; a truncated Fourier series lets the structure pass the obstacle slightly), each frame states
the current gap, and the contact node is drawn as a ball that turns red in frames where it is
inside the obstacle.

Meshed solids (:func:`femodes.solid`, 2-D and 3-D) are drawn as the deformed mesh (surface
with element edges; quadratic cells subdivided so that P2 elements curve), coloured by the
displacement magnitude or the contact pressure (``AnimationStyle(scalars=...)``), with the
obstacle at the (scaled) gap of every contact node: a band along the boundary in 2-D, a
translucent surface in 3-D (a gap that varies along the boundary, e.g. a curved casing, shows
as a curved obstacle), and the contact nodes grey when open, blue when closed and red when
penetrating. 2-D solids are seen in the xy-plane, 3-D ones from a fixed oblique direction
(z up), both with a parallel projection fitted to the whole period.

pyvista is imported only when :func:`animate` is called (``pip install 'femodes[render]'``).
Rendering is headless: with the pip VTK wheels it goes through EGL on Mesa's software renderer
(llvmpipe), which needs the system libraries ``libEGL.so.1`` and Mesa's EGL driver (Debian /
Ubuntu: ``apt-get install libegl1 libgl1-mesa-dri``); OSMesa (``libosmesa6``) or an X display
work too.
"""

from __future__ import annotations

import ctypes
import logging
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .fields import VTK_QUADRATIC_NODES, check_scale, mesh_fields
from .solvers.checks import check_int

__all__ = ["animate", "AnimationStyle", "render_backend"]

log = logging.getLogger(__name__)

INSTALL_HINT = (
    "Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri (EGL + Mesa software rendering), "
    "or libosmesa6 for OSMesa; then pip install 'femodes[render]' (pyvista, imageio; imageio-ffmpeg for .mp4)"
)


def _loadable(*names: str) -> bool:
    for name in names:
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            continue
    return False


def render_backend() -> str:
    """Choose (and set, if unset) VTK's off-screen window class before pyvista is imported.

    Returns
    -------
    str
        ``"egl"``, ``"osmesa"`` or ``"x"`` (a display is available), or whatever
        ``VTK_DEFAULT_OPENGL_WINDOW`` was already set to.

    Raises
    ------
    RuntimeError
        No EGL, no OSMesa and no display: nothing VTK can render with (the message says what to install).
    """
    preset = os.environ.get("VTK_DEFAULT_OPENGL_WINDOW")
    if preset:
        return preset
    if _loadable("libEGL.so.1", "libEGL.so"):
        os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = "vtkEGLRenderWindow"
        return "egl"
    if _loadable("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so"):
        os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = "vtkOSOpenGLRenderWindow"
        return "osmesa"
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return "x"
    raise RuntimeError(f"animate: no OpenGL backend for off-screen rendering (libEGL.so.1 not found, no display). {INSTALL_HINT}")


def _import_pyvista():
    render_backend()
    try:
        import pyvista
    except ImportError as exc:
        raise ImportError(f"femodes.viz needs pyvista and imageio: pip install 'femodes[render]' ({exc})") from exc
    return pyvista


def _check_window(window_size: Any, owner: str) -> tuple[int, int]:
    if (not isinstance(window_size, (tuple, list)) or len(window_size) != 2
            or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 16 <= v <= 8192 for v in window_size)):
        raise ValueError(f"{owner}: window_size must be (width, height) integers in [16, 8192], got {window_size!r}")
    return int(window_size[0]), int(window_size[1])


class _ContactQuality:
    """Contact state of a periodic solution over the animated frames (for the overlay of :func:`animate`)."""

    def __init__(self, nodes, gaps, frame_gaps, penetration, label):
        self.nodes = nodes                  # mesh node of each drawn contact
        self.gaps = gaps                    # initial gap of each drawn contact
        self.frame_gaps = frame_gaps        # g_N(t_j), (n_frames, n_drawn)
        self.penetration = penetration      # max_t(-g_N) over a fine grid, per drawn contact
        self.label = label                  # DOF label of each drawn contact ("" if unknown)
        w = int(np.argmax(self._relative(penetration)))
        pen, gap = float(penetration[w]), float(gaps[w])
        rel = f" = {100 * pen / gap:.1f} % of the gap {gap:.3g}" if gap > 0 else f" (gap {gap:.3g})"
        where = f" at {label[w]}" if label[w] else ""
        self.caption = (f"max penetration{where}: {pen:.2e}{rel}" if pen > 0
                        else f"no penetration{where} (gap {gap:.3g})")
        scale = np.maximum(np.abs(gaps), 1e-12)
        self.tol = 1e-3 * scale

    def _relative(self, values):
        return np.where(self.gaps > 0, values / np.where(self.gaps > 0, self.gaps, 1.0), values)

    def penetrating(self, j: int) -> np.ndarray:
        return self.frame_gaps[j] < -self.tol

    def frame_text(self, j: int) -> str:
        g = self.frame_gaps[j]
        c = int(np.argmin(g))
        if g[c] < -self.tol[c]:
            rel = f" ({100 * -g[c] / self.gaps[c]:.1f} % of gap)" if self.gaps[c] > 0 else ""
            return f"penetration now {-g[c]:.2e}{rel}"
        return f"gap now {max(g[c], 0.0):.2e}"


def _contact_quality(solution: Any, f: Any, model: Any) -> _ContactQuality | None:
    """Gaps of the contacts that sit on mesh nodes, at the frames and over a fine grid; None if none."""
    from .results import PeriodicSolution

    if not isinstance(solution, PeriodicSolution) or not solution.contacts.kinds:
        return None
    keep = [c for c, node in enumerate(f.contact_nodes) if node >= 0]
    if not keep:
        return None
    # a fine grid as for PeriodicSolution.penetration (64 samples per Fourier coefficient): the frames
    # alone would miss the deepest instant
    n = max(2048, 64 * solution.harmonics.n_coef)
    fine = solution.gap(np.arange(n) * (solution.period / n))[:, keep]
    frame_gaps = solution.gap(f.t)[:, keep]
    model = model if model is not None else solution.model
    labels = []
    for c in keep:
        dof = int(solution.contacts.dofs[c])
        try:
            labels.append(model.dofmap.label(dof) if model.dofmap.labels else "")
        except (AttributeError, IndexError):  # pragma: no cover - models without DOF labels
            labels.append("")
    return _ContactQuality(nodes=[int(f.contact_nodes[c]) for c in keep],
                           gaps=np.asarray(f.contact_gaps, dtype=float)[keep], frame_gaps=frame_gaps,
                           penetration=np.maximum(0.0, np.max(-fine, axis=0)), label=labels)


@dataclass(frozen=True, kw_only=True)
class AnimationStyle:
    """How :func:`animate` draws (validated at construction; change with ``dataclasses.replace``).

    Parameters
    ----------
    window_size : (int, int)
        Frame size in pixels (width, height), each in [16, 8192].
    fps : float
        Frames per second of the output, in (0, 240].
    cmap : str
        Matplotlib colormap name for ``|displacement|`` (true, unscaled magnitude; the colour
        range is fixed over the period).
    radius : float, optional
        Tube radius of bars and beams (default 1 % of the length).
    show_contact : bool
        For a :class:`~femodes.results.PeriodicSolution` with contacts: caption line with the
        maximum penetration ``max_t (-g_N)`` over a fine time grid (the value of
        ``solution.penetration``) as a length and as a percentage of the gap of the worst
        contact; per frame the smallest current gap ``g_N(t_j)`` (red with the penetration
        when negative); a ball at each contact node, red in frames where ``g_N < 0`` beyond
        ``1e-3`` of the gap (solids: a point at every contact node, red as for bars, blue
        when closed, ``g_N`` within 1 % of the gap, grey when open). Linear modes (arbitrary
        amplitude) get no contact overlay.
    unit : str, optional
        Length unit shown in the colour bar title, e.g. ``"m"`` or ``"L"`` (dimensionless
        models); default: no unit.
    title : str, optional
        Extra first caption line (e.g. what is shown); the frequency and the displacement
        scale are always stated below it.
    scalars : {"displacement", "contact_pressure"}
        What colours a meshed solid: the true (unscaled) displacement magnitude, or the nodal
        contact pressure (``"contact_pressure"`` of :func:`femodes.io.write_animation`; 2-D:
        a band along each contact boundary on the grey body, 3-D: the body surface, zero off
        the contact faces). Bars and beams are always coloured by ``|u|``
        (``"contact_pressure"`` is an error there).
    pressure_cmap : str
        Matplotlib colormap name for the contact pressure (default ``"YlOrRd"``: zero pressure
        pale, so that the loaded part stands out; the range ``[0, max]`` over the period is
        fixed, the small negative values a truncated Fourier series leaks are drawn as zero).
    """

    window_size: tuple[int, int] = (640, 360)
    fps: float = 12
    cmap: str = "plasma"
    radius: float | None = None
    show_contact: bool = True
    unit: str | None = None
    title: str | None = None
    scalars: str = "displacement"
    pressure_cmap: str = "YlOrRd"

    def __post_init__(self):
        owner = "AnimationStyle"
        object.__setattr__(self, "window_size", _check_window(self.window_size, owner))
        fps = self.fps
        if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or not 0 < fps <= 240:
            raise ValueError(f"{owner}: fps must be a number in (0, 240], got {fps!r}")
        r = self.radius
        if r is not None and (isinstance(r, bool) or not isinstance(r, (int, float)) or not r > 0):
            raise ValueError(f"{owner}: radius must be a positive number or None, got {r!r}")
        for name in ("unit", "title"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, str):
                raise TypeError(f"{owner}: {name} must be a str or None, got {type(value).__name__}")
        for name in ("cmap", "pressure_cmap"):
            if not isinstance(getattr(self, name), str):
                raise TypeError(f"{owner}: {name} must be a colormap name (str), "
                                f"got {type(getattr(self, name)).__name__}")
        if not isinstance(self.show_contact, (bool, np.bool_)):
            raise TypeError(f"{owner}: show_contact must be True or False, got {self.show_contact!r}")
        if self.scalars not in ("displacement", "contact_pressure"):
            raise ValueError(f"{owner}: scalars must be 'displacement' or 'contact_pressure' (the point data of "
                             f"femodes.io.write_animation that colours the structure), got {self.scalars!r}")


def _check_style(style: Any, owner: str) -> AnimationStyle:
    style = AnimationStyle() if style is None else style
    if not isinstance(style, AnimationStyle):
        raise TypeError(f"{owner}: style must be a femodes.viz.AnimationStyle, got {type(style).__name__}")
    return style


def _check_path(path: Any, owner: str) -> tuple[Path, str]:
    """The output path and its lower-case suffix (``.gif`` or ``.mp4``)."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{owner}: path must be a str or os.PathLike ending in .gif or .mp4, got {type(path).__name__}")
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise ValueError(f"{owner}: path must end in .gif or .mp4, got {str(path)!r}")
    return path, suffix


def _frame_size(style: AnimationStyle, suffix: str) -> tuple[int, int]:
    """The window size; for ``.mp4`` rounded up to multiples of 16 pixels (macro blocks)."""
    width, height = style.window_size
    if suffix == ".mp4":
        width, height = 16 * math.ceil(width / 16), 16 * math.ceil(height / 16)
    return width, height


def _import_imageio(suffix: str):
    try:
        import imageio.v2 as iio
    except ImportError as exc:
        raise ImportError("animate needs imageio: pip install 'femodes[render]'") from exc
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError as exc:
            raise ImportError("writing .mp4 needs imageio-ffmpeg: pip install imageio-ffmpeg (or write a .gif)") from exc
    return iio


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


def _geometry(pv, f, n_frames: int, scale: float | None, radius: float | None, owner: str) -> _Geometry:
    """Displacement scale (default: max |u| drawn as 15 % of the length), frames, obstacles and bounds."""
    length = float(np.ptp(f.x)) or 1.0
    umax = float(np.max(np.abs(f.displacement)))
    if scale is None:
        scale = 0.15 * length / umax if umax > 0 else 1.0
        log.info("%s: displacement scale %.4g (max |u| = %.4g drawn as 15%% of the length)", owner, scale, umax)
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


def _fix_camera(plotter, lo: np.ndarray, hi: np.ndarray, length: float, width: int, height: int) -> None:
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


def _caption(style: AnimationStyle, f, scale: float, quality: _ContactQuality | None) -> str:
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
    _fix_camera(plotter, geom.lo, geom.hi, geom.length, *size)
    plotter.add_text(caption, font_size=9, color="black", position="upper_left", name="title")


def _draw_contacts(pv, plotter, geom: _Geometry, quality: _ContactQuality, j: int) -> None:
    """A ball at each contact node of frame ``j``, red where it is inside the obstacle."""
    ball = 2.2 * geom.radius
    # the contact balls sit in front of the obstacle blocks (same x, y in the orthographic view)
    z_front = 0.1 * geom.length + ball
    for c, node in enumerate(quality.nodes):
        plotter.add_mesh(pv.Sphere(radius=ball, center=geom.frames_pts[j, node] + (0.0, 0.0, z_front)),
                         name=f"contact{c}",
                         color="red" if quality.penetrating(j)[c] else "black", reset_camera=False)


def _render_frame(pv, plotter, geom: _Geometry, quality: _ContactQuality | None, j: int, n_frames: int,
                  cmap: str, owner: str) -> np.ndarray:
    """Draw frame ``j`` (structure, contact overlay, time label) and return its RGB image."""
    if j:
        plotter.add_mesh(geom.structure(pv, j), scalars="|u|", cmap=cmap, clim=geom.clim, name="structure",
                         smooth_shading=True, show_scalar_bar=False, reset_camera=False)
    # the time label also keeps frames distinct (GIF writers merge identical frames)
    now = f"t/T = {j / n_frames:.3f}"
    color = "black"
    if quality is not None:
        now += "   " + quality.frame_text(j)
        color = "red" if quality.penetrating(j).any() else "black"
        _draw_contacts(pv, plotter, geom, quality, j)
    plotter.add_text(now, font_size=9, color=color, position="lower_left", name="time")
    plotter.render()
    img = plotter.screenshot(return_img=True)
    if img is None or img.size == 0:
        raise RuntimeError(f"{owner}: the renderer returned no image. {INSTALL_HINT}")
    return np.asarray(img)[..., :3].copy()


def _render_frames(pv, geom: _Geometry, quality: _ContactQuality | None, style: AnimationStyle, caption: str,
                   size: tuple[int, int], n_frames: int, owner: str) -> list[np.ndarray]:
    """All frames, off screen with a fixed camera; raises RuntimeError on blank output."""
    plotter = pv.Plotter(off_screen=True, window_size=size)
    images = []
    try:
        _setup_scene(pv, plotter, geom, style, caption, size)
        for j in range(n_frames):
            images.append(_render_frame(pv, plotter, geom, quality, j, n_frames, style.cmap, owner))
    finally:
        plotter.close()
    if np.all(images[0] == images[0].reshape(-1, 3)[0]):
        raise RuntimeError(f"{owner}: the renderer produced a blank frame (broken OpenGL?). {INSTALL_HINT}")
    return images


# --------------------------------------------------------------------------------------------
# Meshed solids (2-D and 3-D)
# --------------------------------------------------------------------------------------------
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


def _solid_scene(pv, f, scale: float | None, pressure: bool, unit: str | None, owner: str) -> _SolidScene:
    """Displacement scale (default: the largest |u| over the period drawn as 15 % of the largest
    extent of the mesh), frames, colouring, obstacles and the bounds over the period."""
    X = f.points()
    length = float(np.ptp(X, axis=0).max()) or 1.0
    mag = np.linalg.norm(f.displacement, axis=2)
    umax = float(mag.max())
    if scale is None:
        scale = 0.15 * length / umax if umax > 0 else 1.0
        log.info("%s: displacement scale %.4g (max |u| = %.4g drawn as 15%% of the largest extent)", owner, scale, umax)
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


def _draw_solid_contacts(pv, plotter, scene: _SolidScene, quality: _ContactQuality, j: int) -> None:
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


def _render_solid(pv, f, scene: _SolidScene, quality: _ContactQuality | None, style: AnimationStyle, caption: str,
                  size: tuple[int, int], n_frames: int, owner: str) -> list[np.ndarray]:
    """All frames of a meshed solid, off screen with a fixed camera."""
    plotter = pv.Plotter(off_screen=True, window_size=size)
    images = []
    try:
        plotter.set_background("white")
        for k, ob in enumerate(scene.obstacles):
            plotter.add_mesh(ob, color="dimgray", opacity=0.9 if scene.dim == 2 else 0.35, name=f"obstacle{k}",
                             reset_camera=False)
        if scene.dim == 2:
            _fix_camera(plotter, scene.lo, scene.hi, scene.length, *size)
        else:
            _fix_camera_3d(plotter, scene, *size)
        plotter.add_text(caption, font_size=9, color="black", position="upper_left", name="title")
        for j in range(n_frames):
            _draw_solid(pv, plotter, scene, style, j, first=j == 0)
            now, color = f"t/T = {j / n_frames:.3f}", "black"
            if quality is not None:
                now += "   " + quality.frame_text(j)
                color = "red" if quality.penetrating(j).any() else "black"
                _draw_solid_contacts(pv, plotter, scene, quality, j)
            plotter.add_text(now, font_size=9, color=color, position="lower_left", name="time")
            plotter.render()
            img = plotter.screenshot(return_img=True)
            if img is None or img.size == 0:
                raise RuntimeError(f"{owner}: the renderer returned no image. {INSTALL_HINT}")
            images.append(np.asarray(img)[..., :3].copy())
    finally:
        plotter.close()
    if np.all(images[0] == images[0].reshape(-1, 3)[0]):
        raise RuntimeError(f"{owner}: the renderer produced a blank frame (broken OpenGL?). {INSTALL_HINT}")
    return images


def _write_movie(iio, path: Path, suffix: str, images: list[np.ndarray], fps: float) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".gif":
        iio.mimsave(path, images, duration=1000.0 / fps, loop=0)
    else:
        with iio.get_writer(path, fps=fps, codec="libx264", quality=7, macro_block_size=16) as w:
            for img in images:
                w.append_data(img)


def animate(solution: Any, model: Any, path: Any, n_frames: int = 36, scale: float | None = None, *,
            mode: int | None = None, style: AnimationStyle | None = None) -> Path:
    """Render one period of a periodic motion to an animated GIF or an MP4 video, off screen.

    Parameters
    ----------
    solution : PeriodicSolution or LinearModes
        E.g. ``branch[i]``; for linear modes pass ``mode`` (1 = the first mode), motion ``phi cos(w t)``.
    model : StructuralModel or None
        The model the result lives on (None: ``solution.model``); reduced models are expanded
        to the full mesh. Discrete models (no mesh) raise ValueError.
    path : str or os.PathLike
        Output file ending in ``.gif`` (imageio + pillow) or ``.mp4`` (needs imageio-ffmpeg;
        the window is rounded up to multiples of 16 pixels). Parent folders are created.
    n_frames : int
        Frames per period (>= 2), at ``t_j = j T / n_frames``; the animation loops.
    scale : float, optional
        Displacement magnification. Default: the largest displacement over the period is drawn
        as 15 % of the structure's length (solids: of the largest side of the mesh's bounding
        box, and ``|u|`` is the length of the displacement vector); the value is logged and
        shown in the caption. The obstacle is drawn at ``scale * gap`` (solids: at
        ``x_node + scale * gap * direction`` for every contact node), so contact is shown where
        it happens.
    mode : int, optional
        Mode number (1 = the first mode) for ``LinearModes``.
    style : AnimationStyle, optional
        Window size, frame rate, colours, what colours a solid, tube radius, contact overlay, unit and title
        (default ``AnimationStyle()``: 640 x 360 pixels, 12 frames per second).

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ValueError
        Bad ``n_frames``, suffix, or a discrete model (bad style values: at ``AnimationStyle(...)``);
        ``style.scalars="contact_pressure"`` for a bar or beam.
    RuntimeError
        No off-screen OpenGL available (the message names the packages to install), or the
        renderer produced blank frames.
    ImportError
        pyvista / imageio (/ imageio-ffmpeg for ``.mp4``) not installed.
    """
    owner = "animate"
    n_frames = check_int("n_frames", n_frames, 2, owner=owner)
    scale = check_scale(scale, owner)
    style = _check_style(style, owner)
    path, suffix = _check_path(path, owner)
    width, height = _frame_size(style, suffix)
    f = mesh_fields(solution, model, n_frames=n_frames, mode=mode, owner=owner)
    if f.dim == 1 and style.scalars == "contact_pressure":
        raise ValueError(f"{owner}: style.scalars='contact_pressure' needs a meshed solid (femodes.solid); bars and "
                         "beams are coloured by the displacement (scalars='displacement')")
    quality = _contact_quality(solution, f, model) if style.show_contact else None
    iio = _import_imageio(suffix)
    pv = _import_pyvista()

    t0 = time.perf_counter()
    if f.dim == 1:
        geom = _geometry(pv, f, n_frames, scale, style.radius, owner)
        caption = _caption(style, f, geom.scale, quality)
        images = _render_frames(pv, geom, quality, style, caption, (width, height), n_frames, owner)
    else:
        scene = _solid_scene(pv, f, scale, style.scalars == "contact_pressure", style.unit, owner)
        caption = _caption(style, f, scene.scale, quality)
        if quality is not None:
            caption += "\ncontact nodes: grey open, blue closed, red penetrating"
        images = _render_solid(pv, f, scene, quality, style, caption, (width, height), n_frames, owner)
    t_render = time.perf_counter() - t0

    _write_movie(iio, path, suffix, images, style.fps)
    log.info("%s: %d frames %dx%d rendered in %.2f s, wrote %s (%d bytes)", owner, n_frames, width, height, t_render,
             path, path.stat().st_size)
    return path
