"""Outputs layer: :func:`animate`: one period of a periodic motion rendered off screen to a GIF or an MP4 file.

It checks the arguments, samples the motion on the mesh (:func:`femodes.fields.mesh_fields`),
renders the frames of a line structure (:mod:`femodes.viz.lines`) or of a meshed solid
(:mod:`femodes.viz.solids`) and writes them with imageio.
"""

from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..fields import check_scale, sample_fields
from ..solvers.checks import InputTypeError, InputValueError, check_int, entry_point
from .backend import import_pyvista
from .lines import make_caption, line_geometry, render_line_frames
from .solids import render_solid, solid_scene
from .style import AnimationStyle, check_style, contact_quality

__all__ = ["animate"]

log = logging.getLogger(__name__)

def _check_path(path: Any) -> tuple[Path, str]:
    """The output path and its lower-case suffix (``.gif`` or ``.mp4``)."""
    if not isinstance(path, (str, os.PathLike)):
        raise InputTypeError(f"path must be a str or os.PathLike ending in .gif or .mp4, got {type(path).__name__}")
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise InputValueError(f"path must end in .gif or .mp4, got {str(path)!r}")
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


def _write_movie(iio, path: Path, suffix: str, images: list[np.ndarray], fps: float) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".gif":
        iio.mimsave(path, images, duration=1000.0 / fps, loop=0)
    else:
        with iio.get_writer(path, fps=fps, codec="libx264", quality=7, macro_block_size=16) as w:
            for img in images:
                w.append_data(img)




@entry_point("animate")
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
    n_frames : int, default 36
        Frames per period (>= 2), at ``t_j = j T / n_frames``; the animation loops.
    scale : float, optional
        Displacement magnification. Default: the largest displacement is drawn as 15 % of the
        structure's length (solids: largest side of the bounding box); logged and in the caption.
        The obstacle is drawn at ``scale * gap``, so contact is shown where it happens.
    mode : int, optional
        Mode number (1 = the first mode) for ``LinearModes``.
    style : AnimationStyle, optional
        Window size, frame rate, colours, scalars, tube radius, contact overlay, unit and title
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
    n_frames = check_int("n_frames", n_frames, 2)
    scale = check_scale(scale)
    style = check_style(style)
    path, suffix = _check_path(path)
    width, height = _frame_size(style, suffix)
    f = sample_fields(solution, model, n_frames=n_frames, mode=mode)
    if f.dim == 1 and style.scalars == "contact_pressure":
        raise InputValueError("style.scalars='contact_pressure' needs a meshed solid (femodes.solid); bars and "
                         "beams are coloured by the displacement (scalars='displacement')")
    quality = contact_quality(solution, f, model) if style.show_contact else None
    iio = _import_imageio(suffix)
    pv = import_pyvista()

    t0 = time.perf_counter()
    if f.dim == 1:
        geom = line_geometry(pv, f, n_frames, scale, style.radius)
        caption = make_caption(style, f, geom.scale, quality)
        images = render_line_frames(pv, geom, quality, style, caption, (width, height), n_frames)
    else:
        scene = solid_scene(pv, f, scale, style.scalars == "contact_pressure", style.unit)
        caption = make_caption(style, f, scene.scale, quality)
        if quality is not None:
            caption += "\ncontact nodes: grey open, blue closed, red penetrating"
        images = render_solid(pv, f, scene, quality, style, caption, (width, height), n_frames)
    t_render = time.perf_counter() - t0

    _write_movie(iio, path, suffix, images, style.fps)
    log.info("animate: %d frames %dx%d rendered in %.2f s, wrote %s (%d bytes)", n_frames, width, height, t_render,
             path, path.stat().st_size)
    return path
