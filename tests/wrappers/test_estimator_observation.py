"""EstimatorObservation and the baselines, with a small test-local estimator.

The registry's filters are exercised in tests/wrappers/test_filters_in_the_loop.py;
here a fixed-gain observer (an estimator the wrapper cannot share bugs with) pins
down the wrapper's own contract.
"""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

import fir_gym
from fir_gym.estimators import Estimator
from fir_gym.wrappers import (
    EstimatorObservation,
    MeasurementObservation,
    TrueStateObservation,
    wrap_observation,
)


class FixedGainObserver(Estimator):
    """x⁺ = f(x, u); x ← x + L (y - h(x)) with a constant gain L (no covariance)."""

    provides_covariance = False

    def __init__(self, model, *, gain=0.3, **kwargs):
        self.gain = gain
        super().__init__(model, **kwargs)

    def _update(self, x, P, y, valid):
        L = np.zeros((self.model.n_x, self.model.n_y))
        L[: self.model.n_y] = self.gain * np.eye(self.model.n_y)
        return x + (y - self.model.h(x)) @ L.T, None, None

    def _predict_update(self, x, P, y, u, valid):
        return self._update(self.model.f(x, u), None, y, valid)


def run(env, actions, seed=0):
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for a in actions:
        obs, _, _, _, info = env.step(a)
        out.append((obs, info))
    return out


ACTIONS = [np.array([a], dtype=np.float32) for a in (0.2, -0.5, 3.0, 0.0, 0.7)]


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
def test_wrapper_equals_the_estimator_run_by_hand(env_id):
    wrapped = EstimatorObservation(gym.make(env_id), FixedGainObserver, gain=0.4)
    plain = gym.make(env_id)
    by_hand = FixedGainObserver(plain.unwrapped.model, gain=0.4,
                                x0=wrapped.estimator.x, P0=wrapped.estimator.P)
    for (x_hat, info), (y, plain_info) in zip(run(wrapped, ACTIONS), run(plain, ACTIONS),
                                              strict=True):
        expected = by_hand.step(y, plain_info.get("action"))
        np.testing.assert_array_equal(x_hat, expected)
        np.testing.assert_array_equal(info["estimate"], expected)
        np.testing.assert_array_equal(info["estimation_error"], plain_info["state"] - expected)
        assert info["estimator_diverged"] is False


def test_filter_is_fed_the_applied_clipped_action():
    env = EstimatorObservation(gym.make("fir_gym/Orbit-v0"), FixedGainObserver)
    twin = EstimatorObservation(gym.make("fir_gym/Orbit-v0"), FixedGainObserver)
    env.reset(seed=0)
    twin.reset(seed=0)
    big, _, _, _, _ = env.step(np.array([5.0]))
    one, _, _, _, _ = twin.step(np.array([1.0]))
    np.testing.assert_array_equal(big, one)


def test_reset_restarts_the_estimator_from_its_prior():
    env = EstimatorObservation(gym.make("fir_gym/CarrierMotion-v0"), FixedGainObserver)
    first = run(env, ACTIONS, seed=3)
    again = run(env, ACTIONS, seed=3)
    for (a, _), (b, _) in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    assert env.estimator.time_step == len(ACTIONS) + 1


def test_default_prior_is_the_plants_initial_distribution():
    env = EstimatorObservation(gym.make("fir_gym/Orbit-v0"), FixedGainObserver)
    np.testing.assert_array_equal(env.estimator.x, [7.99, 1.99])
    assert np.all(np.linalg.eigvalsh(env.estimator.P) > 0)
    paper = EstimatorObservation(gym.make("fir_gym/Orbit-v0"), FixedGainObserver,
                                 x0=[7.997, 1.992], P0=2 * np.eye(2))
    np.testing.assert_array_equal(paper.estimator.P, 2 * np.eye(2))


def test_observation_kinds_and_spaces():
    base = gym.make("fir_gym/CarrierMotion-v0")
    with_y = EstimatorObservation(base, FixedGainObserver, observation="estimate+measurement")
    obs, _ = with_y.reset(seed=0)
    assert set(obs) == {"estimate", "measurement"} and with_y.observation_space.contains(obs)
    with pytest.raises(ValueError, match="has no covariance"):
        EstimatorObservation(gym.make("fir_gym/CarrierMotion-v0"), FixedGainObserver,
                             observation="estimate+covariance")
    with pytest.raises(ValueError, match="observation must be one of"):
        EstimatorObservation(gym.make("fir_gym/CarrierMotion-v0"), FixedGainObserver,
                             observation="everything")


def test_bad_estimator_arguments():
    env = gym.make("fir_gym/Orbit-v0")
    with pytest.raises(ValueError, match="unknown estimator 'nope'"):
        EstimatorObservation(env, "nope")
    with pytest.raises(TypeError, match="estimator must be"):
        EstimatorObservation(env, 42)
    instance = FixedGainObserver(env.unwrapped.model)
    with pytest.raises(ValueError, match="options"):
        EstimatorObservation(env, instance, gain=0.1)


def test_constructor_arguments_are_recorded():
    env = EstimatorObservation(gym.make("fir_gym/Orbit-v0"), FixedGainObserver, gain=0.25)
    assert env.spec.additional_wrappers[-1].kwargs["gain"] == 0.25
    clone = pickle.loads(pickle.dumps(env))
    clone.reset(seed=1)


def test_true_state_and_measurement_baselines():
    true_env = TrueStateObservation(gym.make("fir_gym/Orbit-v0"))
    obs, info = true_env.reset(seed=0)
    np.testing.assert_array_equal(obs, info["state"])
    obs, _, _, _, info = true_env.step(np.zeros(1))
    np.testing.assert_array_equal(obs, info["state"])
    meas = MeasurementObservation(gym.make("fir_gym/Orbit-v0"))
    raw = gym.make("fir_gym/Orbit-v0")
    np.testing.assert_array_equal(meas.reset(seed=2)[0], raw.reset(seed=2)[0])
    assert isinstance(wrap_observation(gym.make("fir_gym/Orbit-v0"), "true"), TrueStateObservation)
    assert isinstance(wrap_observation(gym.make("fir_gym/Orbit-v0"), "measurement"),
                      MeasurementObservation)


def test_gym_make_true_state_shortcut_and_errors():
    env = gym.make("fir_gym/VanDerPol-v0", observation="true")
    obs, info = env.reset(seed=0)
    np.testing.assert_array_equal(obs, info["state"])
    with pytest.raises(ValueError, match="estimator_kwargs given without"):
        gym.make("fir_gym/VanDerPol-v0", estimator_kwargs={"horizon": 3})
    with pytest.raises(ValueError, match="observation must be"):
        gym.make("fir_gym/VanDerPol-v0", observation="estimate")


@pytest.mark.parametrize(("env_id", "name", "options"), [
    ("fir_gym/Orbit-v0", "ekf", {"x0": [7.997, 1.992], "P0": 2 * np.eye(2)}),
    ("fir_gym/Orbit-v0", "efir", {"horizon": 3}),
    ("fir_gym/UncertainOscillator-v0", "ukf", {}),
    ("fir_gym/CarrierMotion-v0", "kf", {}),
])
def test_registry_filters_in_the_wrapper_equal_the_filter_run_by_hand(env_id, name, options):
    from fir_gym.estimators import make_estimator

    wrapped = EstimatorObservation(gym.make(env_id), name, **options)
    plain = gym.make(env_id)
    same = {"startup": wrapped.estimator.startup} if name == "efir" else {}
    by_hand = make_estimator(name, plain.unwrapped.model,
                             **{**options, **same, "x0": wrapped.estimator.x,
                                "P0": wrapped.estimator.P})
    for (x_hat, _), (y, info) in zip(run(wrapped, ACTIONS * 2), run(plain, ACTIONS * 2),
                                     strict=True):
        np.testing.assert_array_equal(x_hat, by_hand.step(y, info.get("action")))
