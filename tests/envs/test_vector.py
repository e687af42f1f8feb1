"""Native vector envs: batched plants with their own truncation and next-step autoreset."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym
from fir_gym.envs._vector import PlantVectorEnv


def make(env_id, num_envs=3, **kwargs):
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


@pytest.mark.parametrize("env_id", fir_gym.VECTOR_ENV_IDS)
def test_vector_step_equals_the_plant_hooks_applied_system_by_system(env_id):
    """Replay the vector env's draws through the single plant's hooks, one system at a time."""
    venv = make(env_id, 3)
    plant = venv.unwrapped.plant
    venv.reset(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(5):
        X = venv.unwrapped.states.copy()
        k = venv.unwrapped.steps.copy()
        A = rng.uniform(-1.5, 1.5, (3, 1))
        state = venv.unwrapped.np_random.bit_generator.state
        _, reward, _, _, info = venv.step(A)
        # the same draws, consumed in the same order, with the whole batch
        replay = np.random.default_rng()
        replay.bit_generator.state = state
        X_next, _ = plant._transition(X, np.clip(A, -1, 1), k, replay)
        np.testing.assert_array_equal(info["state"], X_next)
        for i in range(3):
            x_i, _ = plant._transition(X[i], np.clip(A[i], -1, 1), int(k[i]),
                                       _ZeroNoise())
            x_b, _ = plant._transition(X, np.clip(A, -1, 1), k, _ZeroNoise())
            np.testing.assert_allclose(x_b[i], x_i, rtol=1e-14, atol=1e-14)
            assert reward[i] == pytest.approx(float(plant._reward(X[i], np.clip(A[i], -1, 1),
                                                                  X_next[i])), rel=1e-12)
        np.testing.assert_array_equal(info["action"], np.clip(A, -1, 1))


class _ZeroNoise:
    """A stand-in generator that draws zeros: compares noise-free dynamics."""

    def standard_normal(self, shape=None):
        return np.zeros(shape if shape is not None else ())


@pytest.mark.parametrize("env_id", fir_gym.VECTOR_ENV_IDS)
def test_same_seed_is_bit_identical(env_id):
    runs = []
    for _ in range(2):
        venv = make(env_id, 4)
        obs, _ = venv.reset(seed=11)
        out = [obs]
        for t in range(20):
            out.append(venv.step(np.full((4, 1), 0.1 * (t % 5)))[0])
        runs.append(np.array(out))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_truncation_and_next_step_autoreset():
    venv = make("fir_gym/CarrierMotion-v0", 2, max_episode_steps=3)
    venv.reset(seed=0)
    for _ in range(3):
        _, reward, term, trunc, _ = venv.step(np.zeros((2, 1)))
    assert np.all(trunc) and not np.any(term)
    _, reward, term, trunc, _ = venv.step(np.ones((2, 1)))          # the reset step
    assert np.all(reward == 0) and not np.any(trunc | term)
    assert np.all(venv.unwrapped.steps == 0)
    _, reward, _, _, _ = venv.step(np.zeros((2, 1)))
    assert np.all(venv.unwrapped.steps == 1) and np.all(reward != 0)


def test_termination_resets_only_the_finished_system():
    venv = PlantVectorEnv(fir_gym.envs.OrbitEnv, num_envs=2, max_episode_steps=1000)
    venv.reset(seed=0)
    venv.states[0] = [1.05, -5.0]                         # about to hit the planet
    _, _, term, _, info = venv.step(np.zeros((2, 1)))
    assert term.tolist() == [True, False]
    kept = info["state"][1].copy()
    _, reward, term, _, info = venv.step(np.zeros((2, 1)))
    assert reward[0] == 0 and not term[0]
    np.testing.assert_array_equal(info["state"][0], venv.unwrapped.plant.initial_state)
    assert not np.array_equal(info["state"][1], kept)        # the other one kept going


def test_bad_actions_and_options():
    venv = make("fir_gym/Orbit-v0", 2)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="actions must have shape"):
        venv.step(np.zeros(2))
    with pytest.raises(ValueError, match="actions must be finite"):
        venv.step(np.array([[0.0], [np.nan]]))
    with pytest.raises(ValueError, match="estimator"):
        make("fir_gym/Orbit-v0", 2, estimator="ekf")


def test_the_vector_env_exposes_the_plant_model_and_respects_kwargs():
    venv = make("fir_gym/Orbit-v0", 2, nominal={"mu": 19.92244165})
    assert venv.unwrapped.model.f(np.array([8.0, 0.0]))[0] == pytest.approx(
        gym.make("fir_gym/Orbit-v0", nominal={"mu": 19.92244165}).unwrapped.model.f(
            np.array([8.0, 0.0]))[0], rel=1e-15)
