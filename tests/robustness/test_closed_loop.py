"""The batched closed-loop evaluator against single envs played one by one."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import fir_gym  # noqa: F401
from fir_gym.conditions import condition_setup
from fir_gym.controllers import LQGController
from fir_gym.robustness.closed_loop import build_env, nees_rows, play
from fir_gym.robustness.lqg_grid import ControllerPolicy
from fir_gym.wrappers import EstimatorObservation, SensorFaults

ORBIT = "fir_gym/Orbit-v0"
KWARGS = {"max_episode_steps": 40, "initial_state_cov": [[0.0025, 0.0], [0.0, 0.04]]}


def _single(seed, setup, estimator="ekf"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(ORBIT, **KWARGS, **setup.plant_kwargs)
    env.unwrapped.max_episode_steps = KWARGS["max_episode_steps"]
    if setup.sensor_faults:
        env = SensorFaults(env, **setup.sensor_faults)
    env = EstimatorObservation(env, estimator, **setup.estimator_kwargs)
    controller = LQGController(env)
    obs, info = env.reset(seed=seed)
    total, errors = 0.0, [info["estimation_error"]]
    while True:
        obs, reward, term, trunc, info = env.step(controller.predict(obs)[0])
        total += reward
        errors.append(info["estimation_error"])
        if term or trunc:
            return total, np.array(errors)


@pytest.mark.parametrize(("condition", "strength"), [("nominal", 0.0), ("mismatch", 0.1),
                                                     ("dropout", 0.3), ("delay", 2)])
def test_play_equals_single_envs_seeded_s_plus_i(condition, strength):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plant = gym.make(ORBIT, **KWARGS).unwrapped
    setup = condition_setup(condition, strength, plant, KWARGS["max_episode_steps"])
    venv = build_env(ORBIT, 4, "ekf", setup, env_kwargs=KWARGS)
    episodes = play(venv, ControllerPolicy(LQGController(venv)), seed=100, keep_errors=True)
    squared = np.zeros(2)
    steps = 0
    for i in range(4):
        total, errors = _single(100 + i, setup)
        assert episodes.returns[i] == pytest.approx(total, rel=1e-12)
        assert episodes.lengths[i] == len(errors) - 1
        np.testing.assert_allclose(episodes.errors[:len(errors), i], errors, rtol=1e-10,
                                   atol=1e-12)
        assert np.all(np.isnan(episodes.errors[len(errors):, i]))
        squared += (errors ** 2).sum(axis=0)
        steps += len(errors)
    np.testing.assert_allclose(episodes.rmse, np.sqrt(squared / steps), rtol=1e-10)


def test_nees_rows_against_the_definition():
    rng = np.random.default_rng(0)
    L = rng.normal(size=(5, 3, 3))
    P = L @ L.transpose(0, 2, 1) + 0.1 * np.eye(3)
    e = rng.normal(size=(5, 3))
    expected = np.array([e[i] @ np.linalg.inv(P[i]) @ e[i] for i in range(5)])
    np.testing.assert_allclose(nees_rows(e, P), expected, rtol=1e-10)
    P[2] = -np.eye(3)                                # not positive definite: NaN, others kept
    out = nees_rows(e, P)
    assert np.isnan(out[2])
    np.testing.assert_allclose(np.delete(out, 2), np.delete(expected, 2), rtol=1e-10)
