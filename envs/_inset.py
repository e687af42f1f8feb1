"""A magnified inset for a 2σ region too small to see on the frame.

A filter's covariance is often far below a pixel of the plant's picture: Orbit-v0's
frame spans radii up to 20 while an EKF knows the radius to σ ≈ 1e-3, so its ±2σ bar
is a few hundredths of a pixel, hidden under the estimate's ring, and looks the same
whether it grows or shrinks. Where a region would be drawn smaller than
:data:`MIN_MAGNIFICATION` times the inset's reach, :func:`draw_insets` draws a box in a
bottom corner of the frame that shows the neighbourhood of the estimate magnified by a
power of ten (labelled ``×1000`` and so on), with a grey leader line to the estimate:

* the estimate's ``±2σ`` region (an ellipse, or an error bar) at that magnification,
  around a small ring at the box's centre;
* the truth (a dot in the plant's truth colour) and the measurement (a cross, or a
  line) at the same magnification, where they fall inside the box.

The magnification is a power of ten chosen from the region's size alone
(:func:`magnification`): between two powers of ten the region is drawn to scale, so it
grows and shrinks in the box as the covariance does (a region twice as wide is drawn
twice as wide), and the label changes where it crosses a power of ten.

All coordinates here are frame pixels ``(column, row)``, as :mod:`fir_gym.envs._overlay`
computes them; nothing is drawn for numbers that are not finite.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._draw import BACKGROUND, ESTIMATE, GREY, INK, MEASUREMENT, Color
from ._pen import FAR, RING_RADIUS, Pen

FloatArray = NDArray[np.float64]
#: a point of the picture and its region: ``(pixel (2,), pixel covariance (2, 2))``
Region = tuple[FloatArray, FloatArray]
#: a measurement's mark: ``(pixel (2,), None)`` for a point, ``(pixel, pixel direction)``
#: for a line through it
Mark = tuple[FloatArray, FloatArray | None]

#: pixels: the inset's side (at most; 40 % of a smaller frame's short side), its distance
#: from the frame's edges
SIZE, MARGIN = 100, 6
#: the region's largest radius is drawn at most this fraction of the inset's side
REACH = 0.4
#: an inset is drawn where the region needs at least this magnification to fill its reach
#: (on a 100-pixel inset: where its largest ``±2σ`` radius is under 4 pixels)
MIN_MAGNIFICATION = 10.0
#: no inset beyond this: float64 pixel positions no longer place the truth within the region
MAX_MAGNIFICATION = 1e9
#: no inset on a frame whose short side is under this many pixels
MIN_FRAME = 120
#: pixels: the estimate's ring in the inset
INSET_RING = 2.5


@dataclass(frozen=True)
class Inset:
    """A box of the frame that shows the neighbourhood of one frame pixel magnified.

    ``centre`` is the frame pixel drawn at the box's centre (the estimate's point),
    ``box`` the box's columns and rows in the frame, ``(c0, r0, c1, r1)`` (ends
    excluded; its one-pixel border included).
    """

    centre: tuple[float, float]
    magnification: float
    box: tuple[int, int, int, int]

    @property
    def label(self) -> str:
        """The magnification as the box states it: ``×1000``, …, ``×1e7``."""
        k = round(math.log10(self.magnification))
        return f"×{10 ** k}" if k < 6 else f"×1e{k}"

    def to_box(self, p: FloatArray) -> FloatArray:
        """Frame pixel(s) ``p`` → pixel(s) of the box's inside (its border excluded)."""
        c0, r0, c1, r1 = self.box
        middle = np.array([(c1 - c0 - 2) / 2, (r1 - r0 - 2) / 2])
        return middle + self.magnification * (np.asarray(p, dtype=np.float64)
                                               - np.asarray(self.centre))


def inset_size(width: int, height: int) -> int:
    """The side (pixels) of an inset on a ``width × height`` frame, 0 if it has none."""
    if min(width, height) < MIN_FRAME:
        return 0
    return min(SIZE, int(0.4 * min(width, height)))


def magnification(radius: float, size: int) -> float | None:
    """The power of ten that draws a region of largest radius ``radius`` (frame pixels) at
    most ``REACH · size`` pixels in an inset of side ``size`` — or ``None`` when the region
    needs no inset (less than :data:`MIN_MAGNIFICATION`), has no size, is not finite or
    would need more than :data:`MAX_MAGNIFICATION`."""
    if not (math.isfinite(radius) and radius > 0.0) or size <= 0:
        return None
    m = 10.0 ** math.floor(math.log10(REACH * size / radius))
    return m if MIN_MAGNIFICATION <= m <= MAX_MAGNIFICATION else None


def draw_insets(pen: Pen, regions: Sequence[Region], sigma: float, *,
                truth: FloatArray | None = None, marks: Sequence[Mark] = (),
                truth_color: Color = GREY) -> list[Inset]:
    """Draw, over ``pen``'s frame, an inset for each of the first two ``regions`` that are
    too small to see; return them (an empty list where every region shows on the frame).

    Args:
        pen: the pen of the whole frame.
        regions: each picture point of the estimate with its pixel covariance.
        sigma: the region's size in standard deviations.
        truth: the pixels ``(m, 2)`` of the truth's picture, drawn where they fall inside.
        marks: the measurement's marks, drawn where they cross an inset.
        truth_color: the colour the plant draws its truth in.

    The first inset goes in the bottom corner farther from its point, the second in the
    other bottom corner.
    """
    size = inset_size(pen.width, pen.height)
    chosen: list[tuple[FloatArray, FloatArray, float]] = []
    for point, S in regions:
        p = np.asarray(point, dtype=np.float64)
        if not (np.all(np.isfinite(p)) and np.all(np.abs(p) < FAR)
                and np.all(np.isfinite(S))):
            continue
        radius = sigma * math.sqrt(max(float(np.linalg.eigvalsh(0.5 * (S + S.T))[-1]), 0.0))
        m = magnification(radius, size)
        if m is not None and len(chosen) < 2:
            chosen.append((p, np.asarray(S, dtype=np.float64), m))
    if not chosen:
        return []
    top = pen.height - MARGIN - size
    corners = [(MARGIN, top, MARGIN + size, top + size),
               (pen.width - MARGIN - size, top, pen.width - MARGIN, top + size)]
    first = chosen[0][0]
    corners.sort(key=lambda b: -math.hypot((b[0] + b[2]) / 2 - first[0],
                                           (b[1] + b[3]) / 2 - first[1]))
    insets = []
    for (p, S, m), box in zip(chosen, corners, strict=False):
        inset = Inset((float(p[0]), float(p[1])), m, box)
        _leader(pen, inset)
        _draw_inset(pen, inset, S, sigma, truth, marks, truth_color)
        insets.append(inset)
    return insets


def _leader(pen: Pen, inset: Inset) -> None:
    """A grey line from the box's nearest edge to just outside the estimate's ring."""
    c0, r0, c1, r1 = inset.box
    p = np.asarray(inset.centre)
    edge = np.array([np.clip(p[0], c0, c1 - 1), np.clip(p[1], r0, r1 - 1)])
    gap = p - edge
    length = float(np.hypot(gap[0], gap[1]))
    if length > RING_RADIUS + 3:
        pen.line(edge, p - gap / length * (RING_RADIUS + 2), GREY, width=1.0)


def _draw_inset(pen: Pen, inset: Inset, S: FloatArray, sigma: float,
                truth: FloatArray | None, marks: Sequence[Mark], truth_color: Color) -> None:
    """The box: its border, the measurement, the truth, the region, the ring, the label."""
    c0, r0, c1, r1 = inset.box
    pen.box(c0, r0, c1, r1, BACKGROUND, GREY)
    inside = Pen(pen.canvas.image[r0 + 1:r1 - 1, c0 + 1:c1 - 1])   # clips to the box
    centre = inset.to_box(np.asarray(inset.centre))
    for q, direction in marks:
        if direction is None:
            inside.cross(inset.to_box(q), MEASUREMENT)
            continue
        d = np.asarray(direction, dtype=np.float64)
        norm = float(np.hypot(d[0], d[1]))
        if not (math.isfinite(norm) and norm > 0.0):
            continue
        u = d / norm          # the line's point nearest the estimate, so it stays in range
        nearest = np.asarray(q) + float(np.dot(np.asarray(inset.centre) - q, u)) * u
        inside.through(inset.to_box(nearest), u, MEASUREMENT)
    if truth is not None:
        for t in np.asarray(truth, dtype=np.float64).reshape(-1, 2):
            inside.dot(inset.to_box(t), 3.0, truth_color)
    inside.region(centre, inset.magnification ** 2 * S, sigma, ESTIMATE)
    inside.ring(centre, INSET_RING, ESTIMATE, width=1.5)
    inside.canvas.text(3, 3, inset.label, INK)
