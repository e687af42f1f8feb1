"""Reading the plants' frames back: where a plant drew its true state, and overlay colours.

The oracle of the estimate-drawing tests is the plant's own drawing: the centroid of
the patch each plant paints for its true state (the orbit's body, the oscillator's
mass, the carrier's deck, the Van der Pol phase point; for a MuJoCo plant — the
pendulum — the slider and bob geoms, read from MuJoCo's segmentation rendering). A
marker drawn for an estimate ``x̂`` must sit where the plant, put at ``x̂``, draws its
own bodies. The patch is found by the colour the plant's legend gives its truth (its
public ``truth_color``), so a body painted in another colour than the legend says has no
pixels and fails the test; nothing here is keyed by a plant's class name.
"""

from __future__ import annotations

import copy

import gymnasium as gym
import mujoco
import numpy as np

from fir_gym.envs import _draw

ESTIMATE = np.array(_draw.ESTIMATE, dtype=np.uint8)
MEASUREMENT = np.array(_draw.MEASUREMENT, dtype=np.uint8)

#: a state inside each plant's frame, away from its other drawn parts
STATES = {
    "fir_gym/Orbit-v0": (8.3, 1.0),
    "fir_gym/UncertainOscillator-v0": (0.8, 0.0, 0.5),
    "fir_gym/CarrierMotion-v0": (0.2, 0.0),
    "fir_gym/VanDerPol-v0": (1.2, -0.7),
    "fir_gym/PendulumSlider-v0": (0.05, 0.0, 0.6, 0.0),
}


def plant_in_state(env_id: str):
    """The bare plant of ``env_id`` at its :data:`STATES` entry, rendered once (its frame view
    set)."""
    import fir_gym  # noqa: F401  (registers the ids)

    p = gym.make(env_id, render_mode="rgb_array").unwrapped
    p.reset(seed=0, options={"state": STATES[env_id]})
    p.render()
    return p


def pixels_of(frame: np.ndarray, colour) -> np.ndarray:
    """Pixel centres ``(n, 2)`` as (column, row) of the pixels of exactly ``colour``."""
    rows, cols = np.nonzero(np.all(frame == np.asarray(colour, dtype=np.uint8), axis=-1))
    return np.stack([cols + 0.5, rows + 0.5], axis=1)


def centroid(points: np.ndarray) -> np.ndarray:
    assert len(points), "no pixels of that colour"
    return points.mean(axis=0)


def near(points: np.ndarray, centre, radius: float) -> np.ndarray:
    return points[np.hypot(*(points - np.asarray(centre)).T) <= radius]


def truth_centroids(plant) -> np.ndarray:
    """Where ``plant`` (rendered just now) drew its true state: ``(m, 2)`` pixel centroids."""
    if getattr(plant, "mj_model", None) is not None:   # a MuJoCo scene (the pendulum geoms)
        renderer = mujoco.Renderer(plant.mj_model, plant.height, plant.width)
        try:
            renderer.enable_segmentation_rendering()
            renderer.update_scene(plant.mj_data, camera="side")
            seg = renderer.render()
        finally:
            renderer.close()
        out = []
        for geom in ("slider", "bob"):
            mask = (seg[..., 0] == plant.mj_model.geom(geom).id) & \
                (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)
            rows, cols = np.nonzero(mask)
            out.append((cols.mean() + 0.5, rows.mean() + 0.5))
        return np.array(out)
    frame = plant.render()
    return centroid(pixels_of(frame, plant.truth_color))[None]


def plant_at(plant, x) -> object:
    """A copy of ``plant`` whose true state is ``x`` (rendered once, so it has a view)."""
    other = copy.deepcopy(plant)
    other.state = np.asarray(x, dtype=np.float64).copy()
    if hasattr(other, "_write_state"):                   # MuJoCo: the simulation too
        other._write_state(other.state)
    other.render()
    return other


def same_mapping(a, b) -> bool:
    """Whether two frame views map the world to pixels alike (times may differ)."""
    strip = lambda v: {k: val for k, val in vars(v).items() if k not in ("step", "dt")}  # noqa: E731
    return type(a) is type(b) and strip(a) == strip(b)
