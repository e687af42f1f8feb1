"""make_sb3_vec_env: the same transitions as SB3's DummyVecEnv, and SB3's VecEnv semantics."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from fir_gym.training import SB3VecEnv, make_sb3_vec_env, make_single_env

CASES = [
    ("fir_gym/Orbit-v0", {"estimator": "ekf"}),
    ("fir_gym/Orbit-v0", {"estimator": "efir", "estimator_kwargs": {"horizon": 5},
                          "observation": "estimate+measurement"}),
    ("fir_gym/VanDerPol-v0", {"estimator": "ukf", "observation": "estimate+covariance"}),
    ("fir_gym/CarrierMotion-v0", {"observation": "measurement-stack", "stack_horizon": 3}),
    ("fir_gym/UncertainOscillator-v0", {"observation": "true"}),
    ("fir_gym/VanDerPol-v0", {}),
    # the native env integrates the analytic equations, DummyVecEnv's envs run MuJoCo
    ("fir_gym/PendulumSlider-v0", {"estimator": "ekf", "frame_skip": 10}),
]


def _dummy(env_id, n, seed, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        venv = DummyVecEnv([lambda: make_single_env(env_id, **kwargs) for _ in range(n)])
    venv.seed(seed)
    return venv


def _assert_obs_equal(a, b):
    if isinstance(b, dict):
        assert set(a) == set(b)
        for key in b:
            np.testing.assert_allclose(a[key], b[key], rtol=1e-10, atol=1e-12)
    else:
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_transitions_equal_dummy_vec_env_over_the_same_single_envs(env_id, kwargs):
    """Per-env generators: the same numbers as DummyVecEnv over gym.make envs seeded
    seed + i, through truncations (7-step episodes) and terminations (Orbit, started by
    the planet with a strong reverse push)."""
    n, seed = 3, 11
    extra = {"max_episode_steps": 7}
    if env_id == "fir_gym/Orbit-v0":
        extra["initial_state"] = (1.15, -3.0)
        extra["initial_state_cov"] = [[0.0025, 0.0], [0.0, 1.0]]
    fast = make_sb3_vec_env(env_id, n, seed=seed, generators="per_env", **kwargs, **extra)
    ref = _dummy(env_id, n, seed, **kwargs, **extra)
    assert isinstance(fast, SB3VecEnv)
    _assert_obs_equal(fast.reset(), ref.reset())
    rng = np.random.default_rng(0)
    ended = terminated = 0
    for _ in range(30):
        actions = rng.uniform(-1.3, 1.3, (n, 1)).astype(np.float32)
        obs_a, rew_a, done_a, info_a = fast.step(actions)
        obs_b, rew_b, done_b, info_b = ref.step(actions)
        _assert_obs_equal(obs_a, obs_b)
        np.testing.assert_allclose(rew_a, rew_b, rtol=1e-10)
        assert rew_a.dtype == rew_b.dtype == np.float32
        np.testing.assert_array_equal(done_a, done_b)
        for a, b in zip(info_a, info_b, strict=True):
            assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
            assert ("terminal_observation" in a) == ("terminal_observation" in b)
            if "terminal_observation" in b:
                _assert_obs_equal(a["terminal_observation"], b["terminal_observation"])
                terminated += not b["TimeLimit.truncated"]
            np.testing.assert_allclose(a["state"], b["state"], rtol=1e-12)
            if "estimate" in b:
                np.testing.assert_allclose(a["estimate"], b["estimate"], rtol=1e-10,
                                           atol=1e-12)
                assert a["estimator_diverged"] == b["estimator_diverged"]
            assert set(b) - set(a) <= {"estimator_info"}
        ended += done_b.sum()
        for i in np.flatnonzero(done_b):
            np.testing.assert_allclose(fast.reset_infos[i]["state"],
                                       ref.reset_infos[i]["state"])
    assert ended >= n * 3
    if env_id == "fir_gym/Orbit-v0":
        assert terminated > 0


def test_the_shared_generator_keeps_the_semantics():
    fast = make_sb3_vec_env("fir_gym/Orbit-v0", 4, estimator="ekf", seed=0, max_episode_steps=5)
    obs = fast.reset()
    assert obs.shape == (4, 2)
    for _k in range(5):
        obs, _reward, done, infos = fast.step(np.zeros((4, 1), np.float32))
    assert done.all() and all(i["TimeLimit.truncated"] for i in infos)
    for info in infos:
        assert info["terminal_observation"].shape == (2,)
        assert not np.array_equal(info["terminal_observation"], obs[0])
    # a seed gives the same rollout
    runs = []
    for _ in range(2):
        venv = make_sb3_vec_env("fir_gym/Orbit-v0", 4, estimator="ekf", seed=3)
        out = [venv.reset()] + [venv.step(np.full((4, 1), 0.3, np.float32))[0]
                                for _ in range(5)]
        runs.append(np.array(out))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_vec_env_api_get_attr_env_method_and_the_dummy_fallback():
    fast = make_sb3_vec_env("fir_gym/Orbit-v0", 3, estimator="ekf")
    assert isinstance(fast, VecEnv) and fast.num_envs == 3
    assert fast.get_attr("r_ref") == [8.0] * 3
    assert fast.get_attr("unwrapped", [1])[0] is fast.plant
    assert len(fast.env_method("make_model", mu=19.9)) == 3
    assert fast.env_is_wrapped(gym.Wrapper) == [False] * 3
    for vec_env, kind in (("auto", SB3VecEnv), ("dummy", DummyVecEnv)):
        slider = make_sb3_vec_env("fir_gym/PendulumSlider-v0", 2, estimator="ekf",
                                  max_episode_steps=4, frame_skip=5, vec_env=vec_env)
        assert isinstance(slider, kind) and slider.observed == "estimate"
        slider.reset()
        for _ in range(4):
            _, _, done, infos = slider.step(np.zeros((2, 1), np.float32))
        assert done.all() and "terminal_observation" in infos[0]


def test_bad_arguments_are_refused_by_name():
    with pytest.raises(ValueError, match="num_envs"):
        make_sb3_vec_env("fir_gym/Orbit-v0", 0)
    with pytest.raises(ValueError, match="observation"):
        make_sb3_vec_env("fir_gym/Orbit-v0", 2, observation="estimate+covariance")
    with pytest.raises(ValueError, match="vec_env"):
        make_sb3_vec_env("fir_gym/Orbit-v0", 2, vec_env="threads")
    with pytest.raises(ValueError, match="no native vector env"):
        make_sb3_vec_env("CartPole-v1", 2, vec_env="native")
    with pytest.raises(ValueError, match="friction='coulomb'"):       # MuJoCo's contact
        make_sb3_vec_env("fir_gym/PendulumSlider-v0", 2, vec_env="native", friction="coulomb")
    with pytest.raises(ValueError, match="estimator_kwargs"):
        make_sb3_vec_env("fir_gym/Orbit-v0", 2, estimator_kwargs={"horizon": 3})
    with pytest.raises(ValueError, match="generators"):
        make_sb3_vec_env("fir_gym/Orbit-v0", 2, generators="each")


def test_ppo_learns_on_it():
    from stable_baselines3 import PPO

    venv = make_sb3_vec_env("fir_gym/Orbit-v0", 8, estimator="ekf", seed=0, max_episode_steps=50)
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=256, seed=0, device="cpu")
    model.learn(1024)
    assert model.num_timesteps >= 1024
