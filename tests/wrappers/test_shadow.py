"""ShadowEstimator: the estimator runs beside the loop; the observation stays the plant's."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from fir_gym.wrappers import EstimatorObservation, ShadowEstimator, TrueStateObservation


def test_the_observation_is_the_plants_and_the_estimate_that_of_estimator_observation():
    bare = gym.make("fir_gym/CarrierMotion-v0")
    shadow = ShadowEstimator(gym.make("fir_gym/CarrierMotion-v0"), "kf")
    fed = EstimatorObservation(gym.make("fir_gym/CarrierMotion-v0"), "kf")
    assert shadow.observation_space == bare.observation_space
    y, _ = bare.reset(seed=5)
    obs, info = shadow.reset(seed=5)
    x_hat, _ = fed.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(20):
        np.testing.assert_array_equal(obs, y)
        np.testing.assert_array_equal(info["estimate"], x_hat)
        a = rng.uniform(-1, 1, (1,))
        y, *_ = bare.step(a)
        obs, _, _, _, info = shadow.step(a)
        x_hat, *_ = fed.step(a)
    assert "estimation_error" in info and info["estimator_diverged"] is False


def test_under_a_true_state_observation_it_still_draws_its_estimate():
    env = TrueStateObservation(ShadowEstimator(
        gym.make("fir_gym/CarrierMotion-v0", render_mode="rgb_array"), "kf"))
    obs, info = env.reset(seed=1)
    np.testing.assert_array_equal(obs, info["state"])
    frame = env.render()
    assert np.any(np.all(frame == (175, 40, 170), axis=-1))        # the estimate's rings
