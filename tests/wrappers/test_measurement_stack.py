"""The measurement-stack memory baseline: the window, its padding, single = vector."""

import gymnasium as gym
import numpy as np
import pytest

from fir_gym.wrappers import MeasurementStack, VectorMeasurementStack


def test_the_window_holds_the_last_measurements_and_the_actions_between_them():
    env = MeasurementStack(gym.make("fir_gym/Orbit-v0"), horizon=3)
    plain = gym.make("fir_gym/Orbit-v0")                  # the same draws: its measurements
    assert env.observation_space.shape == (6,)
    obs, _ = env.reset(seed=0)
    ys = [plain.reset(seed=0)[0][0]]
    np.testing.assert_array_equal(obs, [ys[0]] * 3 + [0.0] * 3)     # padded with y[0], a = 0
    for a in (0.2, 1.7, -0.4):
        obs, *_ = env.step(np.array([a]))
        ys.append(plain.step(np.array([a]))[0][0])
    np.testing.assert_array_equal(obs[:3], ys[1:])
    np.testing.assert_array_equal(obs[3:], [0.2, 1.0, -0.4])           # applied (clipped)


def test_default_horizon_is_the_plants_fir_window():
    env = MeasurementStack(gym.make("fir_gym/CarrierMotion-v0"))
    assert env.horizon == 50 and env.observation_space.shape == (100,)
    with pytest.raises(ValueError, match="horizon"):
        MeasurementStack(gym.make("fir_gym/Orbit-v0"), horizon=0)


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_the_vector_window_equals_the_single_one(mode):
    """Per-env generators: each sub-env's window is the single env's, across resets."""
    n = 3
    venv = VectorMeasurementStack(gym.make_vec(
        "fir_gym/VanDerPol-v0", n, vectorization_mode="vector_entry_point",
        max_episode_steps=4, autoreset_mode=mode, generators="per_env"), horizon=3)
    singles = [MeasurementStack(gym.make("fir_gym/VanDerPol-v0", max_episode_steps=4), 3)
               for _ in range(n)]
    obs, _ = venv.reset(seed=7)
    ref = [s.reset(seed=7 + i)[0] for i, s in enumerate(singles)]
    np.testing.assert_allclose(obs, ref)
    rng = np.random.default_rng(1)
    restart = np.zeros(n, bool)
    for _ in range(13):
        a = rng.uniform(-1, 1, (n, 1))
        obs, _, term, trunc, info = venv.step(a)
        for i, s in enumerate(singles):
            if restart[i]:                                 # next-step mode: reset now
                np.testing.assert_allclose(obs[i], s.reset()[0])
                continue
            o, _, t, tr, _ = s.step(a[i])
            if mode == "SameStep" and (t or tr):
                np.testing.assert_allclose(info["final_obs"][i], o)
                o = s.reset()[0]
            np.testing.assert_allclose(obs[i], o)
        restart = (term | trunc) if mode == "NextStep" else np.zeros(n, bool)
