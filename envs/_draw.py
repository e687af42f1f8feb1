"""A tiny headless rasteriser for the plants' ``rgb_array`` schematics.

Pure numpy, no display and no extra dependency: filled circles, thick line
segments, rectangles and polylines, anti-aliasing-free. World coordinates are
mapped to pixels by :meth:`Canvas.set_view` (y up).

Any coordinate may be NaN, infinite or huge (a plant drawn at a broken state): a
shape whose pixel box is not finite is not drawn, one that reaches off the canvas is
cut at its edge, so drawing never fails on the numbers it is given.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

Color = tuple[int, int, int]
#: world coordinates of several points along one axis
Points = Sequence[float] | NDArray[np.floating[Any]]

BACKGROUND: Color = (250, 250, 247)
INK: Color = (40, 40, 48)
ACCENT: Color = (210, 85, 45)
BLUE: Color = (45, 105, 190)
GREEN: Color = (60, 150, 80)
GREY: Color = (170, 170, 175)
#: the estimate drawn over a plant's frame (a colour no plant uses)
ESTIMATE: Color = (175, 40, 170)
#: the measurement drawn over a plant's frame
MEASUREMENT: Color = (0, 140, 130)


class Canvas:
    """An RGB image with drawing primitives in world coordinates."""

    def __init__(self, width: int, height: int, background: Color = BACKGROUND) -> None:
        self.image: NDArray[np.uint8] = np.empty((height, width, 3), dtype=np.uint8)
        self.image[:] = background
        self.width, self.height = width, height
        self._cols = np.arange(width) + 0.5
        self._rows = np.arange(height) + 0.5
        self.set_view((0.0, float(width)), (0.0, float(height)))

    def set_view(self, x_range: tuple[float, float], y_range: tuple[float, float]) -> None:
        """Map the world box ``x_range x y_range`` onto the canvas, keeping aspect ratio."""
        sx = self.width / (x_range[1] - x_range[0])
        sy = self.height / (y_range[1] - y_range[0])
        self._scale = min(sx, sy)
        cx, cy = 0.5 * (x_range[0] + x_range[1]), 0.5 * (y_range[0] + y_range[1])
        self._offset = (self.width / 2 - cx * self._scale, self.height / 2 + cy * self._scale)

    def to_pixels(self, x: float, y: float) -> tuple[float, float]:
        return self._offset[0] + x * self._scale, self._offset[1] - y * self._scale

    def circle(self, x: float, y: float, radius: float, color: Color) -> None:
        """A filled circle of world radius ``radius``."""
        px, py = self.to_pixels(x, y)
        r = max(radius * self._scale, 1.0)
        c0, c1 = _span(px - r, px + r, self.width)
        r0, r1 = _span(py - r, py + r, self.height)
        if c0 >= c1 or r0 >= r1:
            return
        dx = self._cols[c0:c1][None, :] - px
        dy = self._rows[r0:r1][:, None] - py
        self.image[r0:r1, c0:c1][dx * dx + dy * dy <= r * r] = color

    def ring(self, x: float, y: float, radius: float, color: Color, width: float = 1.5) -> None:
        """A circle outline; ``width`` in pixels."""
        px, py = self.to_pixels(x, y)
        r = radius * self._scale
        c0, c1 = _span(px - r - width, px + r + width, self.width)
        r0, r1 = _span(py - r - width, py + r + width, self.height)
        if c0 >= c1 or r0 >= r1:
            return
        dx = self._cols[c0:c1][None, :] - px
        dy = self._rows[r0:r1][:, None] - py
        self.image[r0:r1, c0:c1][np.abs(np.hypot(dx, dy) - r) <= width / 2] = color

    def line(self, x0: float, y0: float, x1: float, y1: float, color: Color,
             width: float = 2.0) -> None:
        """A segment of ``width`` pixels between two world points."""
        p0 = np.array(self.to_pixels(x0, y0))
        p1 = np.array(self.to_pixels(x1, y1))
        h = width / 2
        c0, c1 = _span(min(p0[0], p1[0]) - h, max(p0[0], p1[0]) + h, self.width)
        r0, r1 = _span(min(p0[1], p1[1]) - h, max(p0[1], p1[1]) + h, self.height)
        if c0 >= c1 or r0 >= r1:
            return
        px = self._cols[c0:c1][None, :]
        py = self._rows[r0:r1][:, None]
        d = p1 - p0
        length2 = float(d @ d)
        if length2 == 0.0:
            t = np.zeros_like(px + py)
        else:
            t = np.clip(((px - p0[0]) * d[0] + (py - p0[1]) * d[1]) / length2, 0.0, 1.0)
        ex = px - (p0[0] + t * d[0])
        ey = py - (p0[1] + t * d[1])
        self.image[r0:r1, c0:c1][ex * ex + ey * ey <= h * h] = color

    def polyline(self, xs: Points, ys: Points, color: Color, width: float = 1.5) -> None:
        for i in range(len(xs) - 1):
            self.line(xs[i], ys[i], xs[i + 1], ys[i + 1], color, width)

    def rect(self, x0: float, y0: float, x1: float, y1: float, color: Color) -> None:
        """A filled axis-aligned rectangle between two world corners."""
        (a0, b0), (a1, b1) = self.to_pixels(x0, y0), self.to_pixels(x1, y1)
        c0, c1 = _span(min(a0, a1), max(a0, a1), self.width)
        r0, r1 = _span(min(b0, b1), max(b0, b1), self.height)
        if c0 < c1 and r0 < r1:
            self.image[r0:r1, c0:c1] = color

    def frame(self, color: Color, width: int = 6) -> None:
        """A border of ``width`` pixels around the whole canvas."""
        image = self.image
        image[:width], image[-width:] = color, color
        image[:, :width], image[:, -width:] = color, color

    def polygon(self, xs: Points, ys: Points, color: Color) -> None:
        """A filled simple polygon (even-odd rule)."""
        pts = np.array([self.to_pixels(x, y) for x, y in zip(xs, ys, strict=True)])
        c0, c1 = _span(pts[:, 0].min(), pts[:, 0].max(), self.width)
        r0, r1 = _span(pts[:, 1].min(), pts[:, 1].max(), self.height)
        if c0 >= c1 or r0 >= r1:
            return
        px = self._cols[c0:c1][None, :]
        py = self._rows[r0:r1][:, None]
        inside = np.zeros((r1 - r0, c1 - c0), dtype=bool)
        for (xa, ya), (xb, yb) in zip(pts, np.roll(pts, -1, axis=0), strict=True):
            if ya == yb:
                continue
            crosses = (ya > py) != (yb > py)
            x_at = xa + (py - ya) * (xb - xa) / (yb - ya)
            inside ^= crosses & (px < x_at)
        self.image[r0:r1, c0:c1][inside] = color


    # ---------------------------------------------------------------- frames and text
    @classmethod
    def over(cls, image: NDArray[np.uint8]) -> Canvas:
        """A canvas that draws onto ``image`` (``(height, width, 3)`` uint8, changed in place).

        Its view is the default one: world ``(x, y)`` is pixel column ``x``, and row
        ``height - y`` (y up from the bottom edge).
        """
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(f"image must be an (height, width, 3) uint8 array; got "
                             f"{image.dtype} of shape {image.shape}")
        canvas = cls(image.shape[1], image.shape[0])
        canvas.image = image
        return canvas

    @property
    def view(self) -> tuple[float, tuple[float, float]]:
        """The world-to-pixel map as ``(scale, (column offset, row offset))``:
        pixel ``(offset[0] + x scale, offset[1] - y scale)`` (see :meth:`to_pixels`)."""
        return self._scale, self._offset

    def text(self, column: float, row: float, text: str, color: Color, scale: int = 1) -> None:
        """One line of ``text`` in the 5 × 9 bitmap font (:mod:`fir_gym.envs._font`), its
        top-left corner at pixel ``(column, row)``; ``scale`` pixels per font pixel."""
        from ._font import text_mask

        mask = text_mask(text)
        if scale != 1:
            mask = mask.repeat(scale, axis=0).repeat(scale, axis=1)
        c, r = round(column), round(row)
        c0, r0 = max(c, 0), max(r, 0)
        c1, r1 = min(c + mask.shape[1], self.width), min(r + mask.shape[0], self.height)
        if c0 < c1 and r0 < r1:
            self.image[r0:r1, c0:c1][mask[r0 - r:r1 - r, c0 - c:c1 - c]] = color


def _span(lo: float, hi: float, limit: int) -> tuple[int, int]:
    """The pixel range ``[lo, hi]`` covers on an axis of ``limit`` pixels, cut to the
    canvas; empty when either end is NaN (``inf`` ends are cut like any other)."""
    if not (lo <= hi):                         # NaN (or an empty range): nothing to draw
        return 0, 0
    lo, hi = max(lo, -1.0), min(hi, limit + 1.0)
    if lo > hi:                                # entirely off the canvas
        return 0, 0
    return max(int(np.floor(lo)), 0), min(int(np.ceil(hi)) + 1, limit)
