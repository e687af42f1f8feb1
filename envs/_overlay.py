"""Drawing an estimate over a plant's frame, in the plant's own coordinates.

A plant's ``render()`` draws its true state and remembers how that frame maps the
plant's world to pixels (a :class:`FrameView`: :class:`PlaneView` for the numpy
drawings of :mod:`fir_gym.envs._draw`, :class:`CameraView` for MuJoCo's camera).
:meth:`EstimateDrawing.draw_estimate` then draws, over that frame, an estimate (a
ring where the estimate puts the drawing's bodies), its ``±2σ`` region (the
covariance carried to pixels through the Jacobian of the state-to-pixel map: an
ellipse, or an error bar where the picture moves along one direction only), the
measurement (a cross, or a line where the measurement leaves a direction open), a
legend and the time; a region too small to see on the frame is drawn magnified in an
inset (:mod:`fir_gym.envs._inset`). :class:`~fir_gym.wrappers.EstimatorObservation` and
:class:`~fir_gym.wrappers.VectorEstimatorObservation` call it from their ``render()``.

A plant takes part through two hooks, both in its world coordinates:

* ``_picture(x)`` — the points of the drawing that the state ``x`` places, ``(m, d)``
  (``d = 2`` for a numpy drawing, 3 for MuJoCo's world): Orbit-v0's body, the
  oscillator's mass, the carrier's deck, the Van der Pol phase point, the pendulum
  slider's slider and bob. The estimate's rings go where ``_picture(x̂)`` puts them.
* ``_measurement_picture(y)`` — where the measurement ``y`` puts those points, as
  ``(point, direction)`` pairs; ``direction`` is ``None`` for a point, or a world
  direction the measurement says nothing about (drawn as a line through ``point``).

Nothing is drawn for a point that is not finite or lies far off the frame; drawing
never raises on the numbers it is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._draw import ACCENT, ESTIMATE, MEASUREMENT, Canvas, Color
from ._inset import Mark, Region, draw_insets
from ._pen import RING_RADIUS, Pen

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FrameView:
    """How one rendered frame maps the plant's world to pixels, and when it was drawn.

    ``to_pixels(points)`` maps world points ``(m, d)`` to pixel ``(column, row)``
    coordinates ``(m, 2)`` (rows grow downwards; pixel ``(c, r)`` covers
    ``[c, c+1) × [r, r+1)``). ``step`` is the plant's time index, ``dt`` its sample
    period (s), so the frame shows time ``step · dt``.
    """

    width: int
    height: int
    step: int
    dt: float

    @property
    def time(self) -> float:
        return self.step * self.dt

    def to_pixels(self, points: ArrayLike) -> FloatArray:
        raise NotImplementedError


@dataclass(frozen=True)
class PlaneView(FrameView):
    """A numpy drawing's view: pixel ``(offset₀ + x scale, offset₁ − y scale)``."""

    scale: float
    offset: tuple[float, float]

    def to_pixels(self, points: ArrayLike) -> FloatArray:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        return np.stack([self.offset[0] + p[:, 0] * self.scale,
                         self.offset[1] - p[:, 1] * self.scale], axis=1)


@dataclass(frozen=True)
class CameraView(FrameView):
    """A pinhole camera: ``position`` (world), ``axes`` (rows: the camera's right, up and
    backward directions in world coordinates, MuJoCo's ``cam_xmat`` transposed) and the
    vertical field of view ``fovy`` (degrees), as MuJoCo renders a fixed camera."""

    position: tuple[float, float, float]
    axes: tuple[tuple[float, float, float], ...]
    fovy: float

    def to_pixels(self, points: ArrayLike) -> FloatArray:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3) - np.asarray(self.position)
        right, up, back = (p @ np.asarray(self.axes).T).T
        focal = 0.5 * self.height / math.tan(math.radians(self.fovy) / 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = np.where(-back > 0, -back, np.nan)      # behind the camera: not drawn
            return np.stack([0.5 * self.width + focal * right / depth,
                             0.5 * self.height - focal * up / depth], axis=1)


class EstimateDrawing:
    """What :class:`~fir_gym.envs._base.PlantEnv` offers to draw an estimate over its frames.

    See the module docstring for the two hooks a plant implements.
    """

    #: how the legend names and marks what the plant itself draws
    truth_label: ClassVar[str] = "truth"
    truth_color: ClassVar[Color] = ACCENT

    state: FloatArray
    time_step: int
    _frame_view: FrameView | None

    # ------------------------------------------------------------------ hooks
    def _picture(self, x: FloatArray) -> FloatArray:
        """World points ``(m, d)`` of the drawing that the state ``x`` places (none here)."""
        return np.zeros((0, 2))

    def _measurement_picture(self, y: FloatArray
                             ) -> list[tuple[FloatArray, FloatArray | None]]:
        """Where the measurement ``y`` puts the picture's points (none here)."""
        return []

    # ------------------------------------------------------------------ views
    @property
    def frame_view(self) -> FrameView | None:
        """The view of the last frame :meth:`render` drew (``None`` before the first)."""
        return getattr(self, "_frame_view", None)

    def _sample_period(self) -> float:
        """The plant's true sample period (s), from its true parameters (cached)."""
        dt = getattr(self, "_true_dt", None)
        if dt is None:
            dt = self._true_dt = float(self.make_model(**self.params).dt)  # type: ignore[attr-defined]
        return dt

    def _plane_view(self, canvas: Canvas) -> PlaneView:
        """The view of a numpy drawing just made on ``canvas``, at the current time."""
        scale, offset = canvas.view
        return PlaneView(canvas.width, canvas.height, int(self.time_step), self._sample_period(),
                         float(scale), (float(offset[0]), float(offset[1])))

    def state_to_pixels(self, x: ArrayLike, view: FrameView | None = None) -> FloatArray:
        """The pixels ``(m, 2)`` where the frame of ``view`` (default: the last frame
        rendered) draws the picture's points for the state ``x``."""
        view = self._require_view(view)
        return view.to_pixels(self._picture(self._as_state(x)))

    def pixel_jacobian(self, x: ArrayLike, view: FrameView | None = None) -> FloatArray:
        """``∂ pixels / ∂ x`` at ``x``, ``(m, 2, n_x)``, by central differences."""
        view = self._require_view(view)
        x = self._as_state(x)
        J = np.zeros(self.state_to_pixels(x, view).shape + (x.size,))
        for i in range(x.size):
            h = 1e-6 * max(1.0, abs(x[i]))
            step = np.zeros_like(x)
            step[i] = h
            J[..., i] = (view.to_pixels(self._picture(x + step))
                         - view.to_pixels(self._picture(x - step))) / (2 * h)
        return J

    # ------------------------------------------------------------------ the overlay
    def draw_estimate(
        self,
        frame: NDArray[np.uint8],
        estimate: ArrayLike,
        covariance: ArrayLike | None = None,
        measurement: ArrayLike | None = None,
        *,
        label: str = "estimate",
        sigma: float = 2.0,
        diverged: bool = False,
        view: FrameView | None = None,
        truth: ArrayLike | None = None,
        inset: bool = True,
    ) -> NDArray[np.uint8]:
        """A copy of ``frame`` (one this plant rendered) with an estimate drawn over it.

        Args:
            frame: an ``(height, width, 3)`` uint8 frame from this plant's ``render()``.
            estimate: the estimated state ``(n_x,)``, drawn as rings where it puts the
                drawing's points (magenta).
            covariance: its covariance ``(n_x, n_x)``; the ``sigma``-σ region of each
                point is drawn around its ring (an ellipse, or an error bar).
            measurement: the measurement ``(n_y,)``, drawn as crosses (teal), or as a
                line where it leaves a direction open.
            label: the estimate's name in the legend (e.g. ``"EKF"``).
            sigma: the size of the region, in standard deviations.
            diverged: say "diverged" under the time.
            view: the frame's view (default: that of the last frame rendered).
            truth: the true state, drawn in an inset (default: the plant's own state
                when ``view`` is the last frame's; none with another ``view``).
            inset: where a region is too small to see on the frame, draw it magnified in
                a box in a bottom corner (:mod:`fir_gym.envs._inset`), with the truth
                and the measurement at the same magnification.
        """
        given_view, view = view, self._require_view(view)
        image = np.array(frame, dtype=np.uint8)
        if image.shape != (view.height, view.width, 3):
            raise ValueError(f"frame must be a {view.height}x{view.width} RGB frame of this "
                             f"plant; got shape {image.shape}")
        x = self._as_state(estimate)
        if truth is None and given_view is None:
            truth = getattr(self, "state", None)
        x_true = None if truth is None else np.asarray(truth, dtype=np.float64).ravel()
        if x_true is not None and x_true.size != x.size:
            raise ValueError(f"truth must have {x.size} components, as the estimate; "
                             f"got {x_true.size}")
        pen = Pen(image)
        entries: list[tuple[str, str, Color]] = [(self.truth_label, "dot", self.truth_color)]
        marks: list[Mark] = []
        regions: list[Region] = []
        with np.errstate(all="ignore"):
            if measurement is not None:
                y = np.asarray(measurement, dtype=np.float64).ravel()
                for point, direction in self._measurement_picture(y):
                    p = view.to_pixels(point)[0]
                    if direction is None:
                        pen.cross(p, MEASUREMENT)
                        marks.append((p, None))
                    else:
                        d = view.to_pixels(np.asarray(point) + direction)[0] - p
                        pen.through(p, d, MEASUREMENT)
                        marks.append((p, d))
            points = view.to_pixels(self._picture(x))
            name = label
            if covariance is not None:
                P = np.asarray(covariance, dtype=np.float64)
                if P.shape != (x.size, x.size):
                    raise ValueError(f"covariance must have shape {(x.size, x.size)}; "
                                     f"got {P.shape}")
                for p, J in zip(points, self.pixel_jacobian(x, view), strict=True):
                    S = J @ P @ J.T
                    pen.region(p, S, sigma, ESTIMATE)
                    regions.append((p, S))
                name = f"{label} ±{sigma:g}σ"
            if len(points) > 1:
                pen.polyline(points, ESTIMATE, width=1.0)
            for p in points:
                pen.ring(p, RING_RADIUS, ESTIMATE)
            if inset and regions:
                true_points = None if x_true is None else view.to_pixels(self._picture(x_true))
                draw_insets(pen, regions, sigma, truth=true_points, marks=marks,
                            truth_color=self.truth_color)
        entries.append((name, "ring", ESTIMATE))
        if measurement is not None:
            entries.append(("measurement", "cross", MEASUREMENT))
        pen.legend(entries)
        pen.clock(view.step, view.dt, diverged)
        return image

    # ------------------------------------------------------------------ helpers
    def _require_view(self, view: FrameView | None) -> FrameView:
        view = view if view is not None else self.frame_view
        if view is None:
            raise ValueError("no frame view: render() a frame first (with render_mode="
                             "'rgb_array'), or pass the view of the frame")
        return view

    def _as_state(self, x: ArrayLike) -> FloatArray:
        x = np.asarray(x, dtype=np.float64).ravel()
        n_x = len(getattr(self, "state_names", ())) or x.size
        if x.size != n_x:
            raise ValueError(f"the estimate must have {n_x} components (the state "
                             f"{list(getattr(self, 'state_names', ()))}); got {x.size}")
        return x
