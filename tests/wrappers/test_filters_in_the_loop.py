"""Every plant with every applicable filter in the loop passes Gymnasium's and SB3's checkers."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from applicable import APPLICABLE
from gymnasium.utils.env_checker import check_env

import fir_gym  # noqa: F401
from fir_gym.estimators import estimator_names
from fir_gym.wrappers import EstimatorObservation

CASES = [(env_id, name) for env_id, names in APPLICABLE.items() for name in names]
EXPECTED_WARNINGS = ("minimum value is -infinity", "maximum value is infinity")


def test_every_registered_estimator_is_placed():
    placed = {name for names in APPLICABLE.values() for name in names} | {"fir-smoother"}
    assert placed == set(estimator_names())


@pytest.mark.parametrize(("env_id", "name"), CASES)
def test_wrapped_env_passes_both_checkers(env_id, name):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    for observation in ("estimate", "estimate+measurement"):
        env = gym.make(env_id, estimator=name, observation=observation)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env, skip_render_check=True)
            sb3_checker.check_env(env, warn=True)
        unexpected = [str(w.message) for w in caught
                      if not any(e in str(w.message) for e in EXPECTED_WARNINGS)
                      and "wrapped" not in str(w.message)]
        assert unexpected == [], unexpected


@pytest.mark.parametrize(("env_id", "name"), CASES)
def test_rollout_is_finite_and_reports_the_error(env_id, name):
    env = gym.make(env_id, estimator=name, observation="estimate")
    obs, info = env.reset(seed=0)
    for _ in range(15):
        obs, _, terminated, truncated, info = env.step(env.action_space.sample())
        assert np.all(np.isfinite(obs)) and obs.shape == info["state"].shape
        np.testing.assert_allclose(info["estimation_error"], info["state"] - obs)
        if terminated or truncated:
            break


@pytest.mark.parametrize(("env_id", "name"), [("fir_gym/Orbit-v0", "kf"),
                                              ("fir_gym/Orbit-v0", "bpf-kf"),
                                              ("fir_gym/PendulumSlider-v0", "cd-ekf")])
def test_inapplicable_filters_fail_clearly(env_id, name):
    with pytest.raises((TypeError, ValueError), match="model"):
        gym.make(env_id, estimator=name)


def test_windowed_filters_take_the_plants_default_horizon():
    env = gym.make("fir_gym/CarrierMotion-v0", estimator="fir")
    assert env.unwrapped.default_horizon == 50
    wrapper = env
    while not isinstance(wrapper, EstimatorObservation):
        wrapper = wrapper.env
    assert wrapper.estimator.horizon == 50
    explicit = gym.make("fir_gym/CarrierMotion-v0", estimator="fir",
                        estimator_kwargs={"horizon": 7})
    wrapper = explicit
    while not isinstance(wrapper, EstimatorObservation):
        wrapper = wrapper.env
    assert wrapper.estimator.horizon == 7
