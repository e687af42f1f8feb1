"""Drawing over a frame in pixel coordinates: the pen of the estimate overlay.

:class:`Pen` wraps a :class:`~fir_gym.envs._draw.Canvas` laid over an existing frame and
takes pixel ``(column, row)`` coordinates (rows grow downwards), as a frame's view
(:mod:`fir_gym.envs._overlay`) gives them. A point that is not finite or lies far off
the frame (:data:`FAR`) is not drawn, so drawing never raises on the numbers it is given.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._draw import ACCENT, BACKGROUND, GREY, INK, Canvas, Color
from ._font import ADVANCE, GLYPH_HEIGHT

FloatArray = NDArray[np.float64]

#: pixels: the estimate's ring, the measurement's cross, the error bar's caps
RING_RADIUS, CROSS_SIZE, CAP = 6.0, 4.0, 3.0
#: a point this far outside the frame (pixels) is not drawn
FAR = 1e5


class Pen:
    """Drawing on a frame in pixel coordinates (column, row; rows grow downwards).

    It draws onto the array it is given, in place: a whole frame, or a view of part of
    one (an inset), which then clips everything drawn to that part.
    """

    def __init__(self, image: NDArray[np.uint8]) -> None:
        self.canvas = Canvas.over(image)
        self.height, self.width = image.shape[:2]

    def _world(self, p: Any) -> tuple[float, float] | None:
        """The canvas's world coordinates of pixel ``p``, or None if it is not drawable."""
        c, r = float(p[0]), float(p[1])
        if not (math.isfinite(c) and math.isfinite(r)) or abs(c) > FAR or abs(r) > FAR:
            return None
        return c, self.height - r

    def line(self, p: Any, q: Any, color: Color, width: float = 1.5) -> None:
        a, b = self._world(p), self._world(q)
        if a is not None and b is not None:
            self.canvas.line(a[0], a[1], b[0], b[1], color, width)

    def polyline(self, points: Any, color: Color, width: float = 1.5) -> None:
        for p, q in itertools.pairwise(points):
            self.line(p, q, color, width)

    def ring(self, p: Any, radius: float, color: Color, width: float = 2.0) -> None:
        a = self._world(p)
        if a is not None:
            self.canvas.ring(a[0], a[1], radius, color, width)

    def dot(self, p: Any, radius: float, color: Color) -> None:
        a = self._world(p)
        if a is not None:
            self.canvas.circle(a[0], a[1], radius, color)

    def cross(self, p: Any, color: Color, size: float = CROSS_SIZE) -> None:
        c, r = float(p[0]), float(p[1])
        self.line((c - size, r - size), (c + size, r + size), color)
        self.line((c - size, r + size), (c + size, r - size), color)

    def through(self, p: Any, direction: Any, color: Color) -> None:
        """A line through ``p`` along ``direction`` (pixels) across the whole frame."""
        d = np.asarray(direction, dtype=np.float64)
        norm = float(np.hypot(d[0], d[1]))
        if not math.isfinite(norm) or norm == 0.0:
            self.cross(p, color)
            return
        d = d / norm * (self.width + self.height)
        self.line(np.asarray(p) - d, np.asarray(p) + d, color, width=1.0)

    def region(self, p: Any, S: FloatArray, sigma: float, color: Color) -> None:
        """The ``sigma`` ellipse ``{p + v : vᵀ S⁻¹ v = sigma²}`` of a pixel covariance ``S``;
        an error bar (with caps) where it is thinner than a pixel."""
        if not np.all(np.isfinite(S)) or self._world(p) is None:
            return
        w, V = np.linalg.eigh(0.5 * (S + S.T))
        radii = sigma * np.sqrt(np.clip(w, 0.0, None))
        if radii[1] < 1.0:                                   # smaller than a pixel
            return
        c = np.asarray(p, dtype=np.float64)
        major = V[:, 1] * radii[1]
        if radii[0] < 1.0:                                   # an error bar
            cap = V[:, 0] * CAP
            for end in (c - major, c + major):
                self.line(end - cap, end + cap, color)
            self.line(c - major, c + major, color)
            return
        n = int(np.clip(2 * np.pi * radii[1] / 3, 24, 240))
        t = np.linspace(0.0, 2 * np.pi, n + 1)
        outline = c + (np.outer(np.cos(t), V[:, 1] * radii[1])
                       + np.outer(np.sin(t), V[:, 0] * radii[0]))
        self.polyline(outline, color)

    def legend(self, entries: list[tuple[str, str, Color]]) -> None:
        """The legend in the top-left corner: a symbol and a name per entry."""
        row_height, margin = GLYPH_HEIGHT + 4, 6
        width = 26 + ADVANCE * max(len(text) for text, _, _ in entries)
        height = 4 + row_height * len(entries)
        self.box(margin, margin, margin + width, margin + height, BACKGROUND, GREY)
        for i, (text, symbol, color) in enumerate(entries):
            top = margin + 3 + i * row_height
            centre = (margin + 11, top + GLYPH_HEIGHT / 2 - 0.5)
            if symbol == "dot":
                self.dot(centre, 3.5, color)
            elif symbol == "ring":
                self.ring(centre, 4.0, color, width=1.6)
            else:
                self.cross(centre, color, size=3.0)
            self.canvas.text(margin + 20, top, text, INK)

    def clock(self, step: int, dt: float, diverged: bool) -> None:
        """``t = … s  k = …`` (time step ``step`` of a plant sampled every ``dt`` s) in the
        top-right corner, and "diverged" under it."""
        decimals = int(np.clip(math.ceil(-math.log10(dt)) if dt > 0 else 2, 0, 4))
        text = f"t = {step * dt:.{decimals}f} s  k = {step}"
        lines = [(text, INK)] + ([("estimator diverged", ACCENT)] if diverged else [])
        right = self.width - 6
        width = ADVANCE * max(len(t) for t, _ in lines) + 6
        self.box(right - width, 6, right, 10 + (GLYPH_HEIGHT + 4) * len(lines), BACKGROUND,
                 GREY)
        for i, (line, color) in enumerate(lines):
            self.canvas.text(right - width + 3, 9 + i * (GLYPH_HEIGHT + 4), line, color)

    def box(self, c0: float, r0: float, c1: float, r1: float, fill: Color,
            border: Color) -> None:
        image = self.canvas.image
        c0, r0 = max(int(c0), 0), max(int(r0), 0)
        c1, r1 = min(int(c1), self.width), min(int(r1), self.height)
        if c0 >= c1 or r0 >= r1:
            return
        image[r0:r1, c0:c1] = border
        image[r0 + 1:r1 - 1, c0 + 1:c1 - 1] = fill
