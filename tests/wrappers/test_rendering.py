"""Frames through gym.make and make_vec, and the estimate drawn over them.

The acceptance test of issue 17 ("see it"): each plant rendered with and without an
estimator in the loop; with one, its marker is drawn where the plant, put at the
estimate, draws its own bodies (tests/helpers/frames.py reads them back). ``"human"``
rendering is only built, never run (CI has no display).
"""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from frames import (
    ESTIMATE,
    MEASUREMENT,
    centroid,
    near,
    pixels_of,
    plant_at,
    same_mapping,
    truth_centroids,
)
from gymnasium.wrappers import HumanRendering, RenderCollection

import fir_gym
from fir_gym.envs import _inset
from fir_gym.envs._overlay import RING_RADIUS
from fir_gym.wrappers import EstimatorObservation, VectorEstimatorObservation

ENV_IDS = fir_gym.ENV_IDS
#: an estimator with a covariance for each plant, one of each family
ESTIMATORS = {
    "fir_gym/Orbit-v0": "ekf",
    "fir_gym/UncertainOscillator-v0": "ukf",
    "fir_gym/CarrierMotion-v0": "kf",
    "fir_gym/VanDerPol-v0": "bpf-kf",
    "fir_gym/PendulumSlider-v0": "ukf",
}
STEPS = 12


def rollout_frames(env_id, **kwargs):
    """Frames of the same seeded episode with zero actions, and the last step's info."""
    env = gym.make(env_id, render_mode="rgb_array", **kwargs)
    _, info = env.reset(seed=3)
    for _ in range(STEPS):
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape))
    return env, env.render(), info


def outside_legend(points):
    return points[~((points[:, 0] < 40) & (points[:, 1] < 60))]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_with_an_estimator_its_marker_is_drawn_where_the_estimate_is(env_id):
    bare_env, bare, _ = rollout_frames(env_id)
    env, framed, info = rollout_frames(env_id, estimator=ESTIMATORS[env_id])
    plant = env.unwrapped
    # the same episode: the estimator draws nothing from the plant's generator
    assert np.array_equal(plant.state, bare_env.unwrapped.state)
    assert np.array_equal(plant.render(), bare)
    assert not len(pixels_of(bare, ESTIMATE)) and not len(pixels_of(bare, MEASUREMENT))
    assert framed.shape == bare.shape and not np.array_equal(framed, bare)
    # the marker: where the plant would draw itself at the estimate
    oracle = plant_at(plant, info["estimate"])
    assert same_mapping(oracle.frame_view, plant.frame_view)
    marks = pixels_of(framed, ESTIMATE)
    for where in truth_centroids(oracle):
        ring = near(marks, where, RING_RADIUS + 3)
        assert len(ring) >= 2 * np.pi * RING_RADIUS
        np.testing.assert_allclose(centroid(ring), where, atol=1.5)
    # the legend and the clock are drawn (ink inside the two boxes)
    assert np.any(np.all(framed[8:50, 8:120] == (40, 40, 48), axis=-1))
    assert np.any(np.all(framed[8:24, -120:-8] == (40, 40, 48), axis=-1))


def test_the_measurement_is_drawn_and_a_filter_without_covariance_draws_no_region():
    env, framed, info = rollout_frames("fir_gym/Orbit-v0", estimator="efir")
    plant = env.unwrapped
    # EFIR's 2σ bar is far under a pixel: not on the frame, magnified in an inset at the
    # bottom (envs/_inset.py, tested in tests/envs/test_inset.py), left out here
    above_inset = lambda points: points[points[:, 1] < framed.shape[0] - _inset.MARGIN  # noqa: E731
                                        - _inset.SIZE]
    marks = above_inset(outside_legend(pixels_of(framed, ESTIMATE)))
    where = plant.state_to_pixels(info["estimate"])[0]
    assert len(near(marks, where, RING_RADIUS + 2)) == len(marks)       # a ring only
    y = env.get_wrapper_attr("_last_measurement")
    crosses = above_inset(outside_legend(pixels_of(framed, MEASUREMENT)))
    implied = plant_at(plant, [y[0], plant.state[1]])
    np.testing.assert_allclose(centroid(crosses), truth_centroids(implied)[0], atol=1.5)


def test_render_before_reset_and_without_render_mode():
    env = gym.make("fir_gym/Orbit-v0", render_mode="rgb_array", estimator="ekf")
    while not isinstance(env, EstimatorObservation):       # past Gymnasium's order check
        env = env.env
    env.unwrapped.reset(seed=0)                   # the plant alone: no estimate yet
    frame = env.render()
    assert frame.shape == (300, 400, 3) and not len(pixels_of(frame, ESTIMATE))
    quiet = gym.make("fir_gym/Orbit-v0", estimator="ekf")
    quiet.reset(seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert quiet.render() is None


def test_a_wrapped_env_with_its_estimate_survives_pickle_and_renders_alike():
    # (the UKF: the KF's and EKF's single-system fast paths do not pickle yet, issue 14)
    env, framed, _ = rollout_frames("fir_gym/Orbit-v0", estimator="ukf")
    copy = pickle.loads(pickle.dumps(env))
    assert np.array_equal(copy.render(), framed)
    step = np.full(env.action_space.shape, 0.3)
    env.step(step)
    copy.step(step)
    assert np.array_equal(copy.render(), env.render())


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_rgb_array_list_through_gym_make(env_id):
    """Gymnasium wraps the plant in RenderCollection, as it does its own envs."""
    env = gym.make(env_id, render_mode="rgb_array_list", estimator=ESTIMATORS[env_id])
    assert isinstance(env, RenderCollection) and env.render_mode == "rgb_array_list"
    assert env.unwrapped.render_mode == "rgb_array"
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(env.action_space.shape))
    frames = env.render()
    assert isinstance(frames, list) and len(frames) == 4          # reset + 3 steps
    assert all(f.dtype == np.uint8 and f.shape == frames[0].shape for f in frames)
    assert all(len(pixels_of(f, ESTIMATE)) for f in frames)        # the estimate on each
    assert env.render() == []                                      # collected once


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_human_mode_through_gym_make_builds_a_human_rendering_wrapper(env_id):
    """Built only: stepping would open a window (pygame and a display)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")            # Gymnasium says it applies the wrapper
        env = gym.make(env_id, render_mode="human")
    assert isinstance(env, HumanRendering) and env.render_mode == "human"
    assert env.unwrapped.render_mode == "rgb_array"
    assert env.metadata["render_fps"] == type(env.unwrapped).metadata["render_fps"]


def test_an_unknown_render_mode_is_still_refused_naming_it():
    with pytest.raises(ValueError, match="render_mode"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gym.make("fir_gym/Orbit-v0", render_mode="ansi_list")


def test_the_entry_points_publish_the_plant_metadata_without_importing_it_early():
    from fir_gym import _registration
    from fir_gym.envs.orbit import OrbitEnv

    assert _registration.orbit.metadata == OrbitEnv.metadata
    assert _registration.orbit.metadata is not OrbitEnv.metadata          # a copy


@pytest.mark.parametrize("env_id", fir_gym.VECTOR_ENV_IDS)
def test_native_vector_env_renders_one_frame_per_sub_env(env_id):
    """Gymnasium's convention (SyncVectorEnv, CartPoleVectorEnv): a sequence of frames,
    one per sub-env; each is what the plant draws at that sub-env's state and time."""
    envs = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point",
                        render_mode="rgb_array")
    assert envs.render_mode == "rgb_array" and "rgb_array" in envs.metadata["render_modes"]
    envs.reset(seed=0)
    for _ in range(4):
        envs.step(np.zeros(envs.action_space.shape))
    frames = envs.render()
    assert isinstance(frames, tuple) and len(frames) == 3
    single = gym.make(env_id, render_mode="rgb_array").unwrapped
    single.reset(seed=0)
    base = envs.unwrapped
    for i, frame in enumerate(frames):
        single.state, single.time_step = base.states[i].copy(), int(base.steps[i])
        if hasattr(single, "_trail"):
            single._trail = []                    # the native env keeps no trail
        assert np.array_equal(frame, single.render())
        assert base.frame_views[i] == single.frame_view
    with pytest.raises(ValueError, match="render_mode"):
        gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                     render_mode="human")


@pytest.mark.parametrize("mode", ["vector_entry_point", "sync"])
def test_vector_estimator_observation_draws_each_systems_estimate(mode):
    env_id = "fir_gym/Orbit-v0"
    envs = gym.make_vec(env_id, num_envs=3, vectorization_mode=mode, render_mode="rgb_array")
    wrapped = VectorEstimatorObservation(envs, "ekf")
    _, info = wrapped.reset(seed=1)
    for _ in range(5):
        _, _, _, _, info = wrapped.step(np.zeros((3, 1)))
    frames = wrapped.render()
    assert len(frames) == 3
    plant = gym.make(env_id, render_mode="rgb_array").unwrapped
    plant.reset(seed=0)
    plant.render()
    for i, frame in enumerate(frames):
        oracle = truth_centroids(plant_at(plant, info["estimate"][i]))[0]
        ring = near(pixels_of(frame, ESTIMATE), oracle, RING_RADIUS + 3)
        assert len(ring) >= 2 * np.pi * RING_RADIUS
        np.testing.assert_allclose(centroid(ring), oracle, atol=1.5)
