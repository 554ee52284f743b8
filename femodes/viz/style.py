"""Outputs layer: what an animation shows: its style (:class:`AnimationStyle`) and the contact quality it states.

For periodic solutions with contacts the contact quality is shown, not hidden
(:func:`contact_quality`): a caption states the maximum penetration over the period (relative to
the gap; a truncated Fourier series lets the structure pass the obstacle slightly), each frame
states the current gap, and the contact node is drawn as a ball that turns red in frames where
it is inside the obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..solvers.checks import InputTypeError, InputValueError, entry_point


__all__ = ["AnimationStyle", "ContactQuality", "check_style", "contact_quality", "frame_label"]

def _check_window(window_size: Any) -> tuple[int, int]:
    if (not isinstance(window_size, (tuple, list)) or len(window_size) != 2
            or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 16 <= v <= 8192 for v in window_size)):
        raise InputValueError(f"window_size must be (width, height) integers in [16, 8192], got {window_size!r}")
    return int(window_size[0]), int(window_size[1])


class ContactQuality:
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


def contact_quality(solution: Any, f: Any, model: Any) -> ContactQuality | None:
    """Gaps of the contacts that sit on mesh nodes, at the frames and over a fine grid; None if none."""
    from ..results import PeriodicSolution

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
    return ContactQuality(nodes=[int(f.contact_nodes[c]) for c in keep],
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

    @entry_point("AnimationStyle")
    def __post_init__(self):
        object.__setattr__(self, "window_size", _check_window(self.window_size))
        fps = self.fps
        if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or not 0 < fps <= 240:
            raise InputValueError(f"fps must be a number in (0, 240], got {fps!r}")
        r = self.radius
        if r is not None and (isinstance(r, bool) or not isinstance(r, (int, float)) or not r > 0):
            raise InputValueError(f"radius must be a positive number or None, got {r!r}")
        for name in ("unit", "title"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, str):
                raise InputTypeError(f"{name} must be a str or None, got {type(value).__name__}")
        for name in ("cmap", "pressure_cmap"):
            if not isinstance(getattr(self, name), str):
                raise InputTypeError(f"{name} must be a colormap name (str), "
                                f"got {type(getattr(self, name)).__name__}")
        if not isinstance(self.show_contact, (bool, np.bool_)):
            raise InputTypeError(f"show_contact must be True or False, got {self.show_contact!r}")
        if self.scalars not in ("displacement", "contact_pressure"):
            raise InputValueError(f"scalars must be 'displacement' or 'contact_pressure' (the point data of "
                             f"femodes.io.write_animation that colours the structure), got {self.scalars!r}")


def check_style(style: Any) -> AnimationStyle:
    style = AnimationStyle() if style is None else style
    if not isinstance(style, AnimationStyle):
        raise InputTypeError(f"style must be a femodes.viz.AnimationStyle, got {type(style).__name__}")
    return style


def frame_label(quality: ContactQuality | None, j: int, n_frames: int) -> tuple[str, str]:
    """The time label of frame ``j`` (``t/T``, with the contact quality when shown; the label
    also keeps frames distinct, as GIF writers merge identical ones) and its colour (red while a
    contact penetrates)."""
    now = f"t/T = {j / n_frames:.3f}"
    if quality is None:
        return now, "black"
    return now + "   " + quality.frame_text(j), "red" if quality.penetrating(j).any() else "black"
