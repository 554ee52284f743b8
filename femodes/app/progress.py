"""Application layer: text progress displays of the command line.

:class:`ProgressBar` fills with a known fraction of work (cases of a study).
:class:`BranchProgress` follows a continuation: the total work of a branch is not known before it
is traced (a branch may fold back and spend most of its points between two folds), so it shows
no invented percentage; it shows where the branch is in the span, which way it travels, and the
work done (points, scaled arclength, folds, time), all of which move with every point.
"""

from __future__ import annotations

import sys
import time

__all__ = ["ProgressBar", "BranchProgress"]


class ProgressBar:
    """Text progress bar on a stream: ``[#####.....]  45%  p = ...  points 37``."""

    def __init__(self, span: tuple[float, float], label: str = "p", stream=None, width: int = 30):
        self.p0, self.p1 = span
        self.label, self.width = label, width
        self.stream = stream if stream is not None else sys.stderr
        self.n = 0
        self.best = 0.0
        self.shown = False

    def fraction(self, p: float) -> float:
        if self.p1 == self.p0:
            return 1.0
        return min(1.0, max(0.0, (p - self.p0) / (self.p1 - self.p0)))

    def write(self, line: str) -> str:
        self.stream.write(line)
        self.stream.flush()
        self.shown = True
        return line

    def update(self, p: float, n: int | None = None) -> str:
        self.n = self.n + 1 if n is None else n
        f = self.fraction(p)
        self.best = max(self.best, f)
        k = int(round(self.best * self.width))
        return self.write(f"\r[{'#' * k}{'.' * (self.width - k)}] {100 * self.best:3.0f}%  {self.label} = {p:.6g}  "
                          f"points {self.n}")

    def close(self) -> None:
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()
            self.shown = False


class BranchProgress(ProgressBar):
    """Progress of a continuation, fed one accepted point at a time (``progress=bar.update``).

    ``[#######<######..........] w = 1.2520  back (fold 1 at 1.385)  point 270  s = 35.2  4.1 s``:
    ``#`` covers the part of the span the branch has reached, the cursor (``>`` forwards, ``<``
    backwards after a fold) is where it is now; ``s`` is the pseudo-arclength travelled (the
    continuation's scaled norm), the measure of work that grows with every point.
    """

    def __init__(self, span: tuple[float, float], label: str = "p", stream=None, width: int = 30):
        super().__init__(span, label, stream, width)
        self.arclength = 0.0
        self.folds: list[float] = []
        self.last_p: float | None = None
        self.t0 = time.perf_counter()

    def update(self, point) -> str:  # type: ignore[override]
        """Show one accepted :class:`~femodes.solvers.ContinuationPoint` (``p``, ``step``, ``is_fold``)."""
        p = float(point.p)
        self.n += 1
        self.arclength += float(point.step)
        if point.is_fold:
            self.folds.append(p)
        f = self.fraction(p)
        self.best = max(self.best, f)
        forward = self.last_p is None or (p - self.last_p) * (self.p1 - self.p0) >= 0
        self.last_p = p
        k = int(round(self.best * self.width))
        cells = ["#"] * k + ["."] * (self.width - k)
        cells[min(self.width - 1, int(f * self.width))] = ">" if forward else "<"
        way = "" if forward else "  back"
        if self.folds:
            way += f" (fold {len(self.folds)} at {self.folds[-1]:.6g})"
        return self.write(f"\r[{''.join(cells)}] {self.label} = {p:.6g}{way}  point {self.n}  "
                          f"s = {self.arclength:.4g}  {time.perf_counter() - self.t0:.1f} s\x1b[K")
