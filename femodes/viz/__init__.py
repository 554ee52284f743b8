"""Outputs layer: off-screen 3-D rendering of periodic motions to GIF / MP4 (pyvista, imageio).

The package re-exports its public names; the rooms are :mod:`~femodes.viz.movie` (:func:`animate`),
:mod:`~femodes.viz.style` (:class:`AnimationStyle`, contact quality), :mod:`~femodes.viz.lines` (bars and
beams), :mod:`~femodes.viz.solids` (meshed solids) and :mod:`~femodes.viz.backend` (:func:`render_backend`).

:func:`animate` renders one period of a periodic solution (or of a linear mode) on the FE mesh:
the deformed structure as a tube coloured by the displacement magnitude, the obstacle of each
contact as a small block at the gap, with a fixed camera and a fixed colour range over the
period so that frames are comparable. For periodic solutions with contacts the contact quality
is shown, not hidden: a caption states the maximum penetration over the period (relative to the
gap; a truncated Fourier series lets the structure pass the obstacle slightly), each frame states
the current gap, and the contact node is drawn as a ball that turns red in frames where it is
inside the obstacle.

pyvista is imported only when :func:`animate` is called (``pip install 'femodes[render]'``).
"""

from .backend import INSTALL_HINT as INSTALL_HINT, render_backend
from .movie import animate
from .style import AnimationStyle

__all__ = ["animate", "AnimationStyle", "render_backend"]
