"""Outputs layer: the off-screen OpenGL backend of femodes.viz and the lazy import of pyvista.

:func:`render_backend` says which backend renders (EGL, OSMesa or a display) or raises with the
packages to install; :func:`import_pyvista` imports pyvista only when an animation is rendered.
Rendering is headless: with the pip VTK wheels it goes through EGL on Mesa's software renderer
(llvmpipe), which needs the system libraries ``libEGL.so.1`` and Mesa's EGL driver (Debian /
Ubuntu: ``apt-get install libegl1 libgl1-mesa-dri``); OSMesa (``libosmesa6``) or an X display
work too.
"""

from __future__ import annotations

import ctypes
import os

from ..solvers.checks import entry_name

__all__ = ["render_backend", "import_pyvista", "INSTALL_HINT", "snapshot"]

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


def import_pyvista():
    render_backend()
    try:
        import pyvista
    except ImportError as exc:
        raise ImportError(f"femodes.viz needs pyvista and imageio: pip install 'femodes[render]' ({exc})") from exc
    return pyvista


def snapshot(plotter):
    """The rendered frame of ``plotter`` as an RGB array (a RuntimeError with the install hint if
    the renderer returns none)."""
    import numpy as np

    plotter.render()
    img = plotter.screenshot(return_img=True)
    if img is None or img.size == 0:
        raise RuntimeError(f"{entry_name()}: the renderer returned no image. {INSTALL_HINT}")
    return np.asarray(img)[..., :3].copy()
