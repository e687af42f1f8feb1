"""VectorEstimatorObservation against one estimator per sub-env, across autoresets.

The oracle replays each sub-env's measurements and applied actions through its own
one-system filter, restarting it from the prior whenever its sub-env starts a new
episode — what an EstimatorObservation on a single env does.
"""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym
from fir_gym.estimators import make_estimator
from fir_gym.wrappers import VectorEstimatorObservation


def rollout(mode, env_id, name, n=3, max_steps=7, steps=25, seed=5, **options):
    """``steps`` wrapped vector steps with random actions, keeping observations and infos."""
    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode=mode,
                        max_episode_steps=max_steps)
    wrapped = VectorEstimatorObservation(venv, name, observation="estimate+measurement",
                                         **options)
    obs, info = wrapped.reset(seed=seed)
    record = [(obs, info, np.zeros(n, bool))]
    rng = np.random.default_rng(0)
    for _ in range(steps):
        obs, _, term, trunc, info = wrapped.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
        record.append((obs, info, term | trunc))
    return wrapped, record


@pytest.mark.parametrize("mode", ["sync", "vector_entry_point"])
@pytest.mark.parametrize("name", ["kf", "ekf", "ukf", "efir", "fir"])
def test_equals_one_estimator_per_env_across_autoresets(mode, name):
    linear = name in ("kf", "fir")
    env_id = "fir_gym/CarrierMotion-v0" if linear else "fir_gym/UncertainOscillator-v0"
    windowed = name in ("efir", "fir")
    # windows of 4 fill inside the 9-step episodes, so both start-up and full windows restart
    wrapped, record = rollout(mode, env_id, name, max_steps=9 if windowed else 7,
                              **({"horizon": 4} if windowed else {}))
    n = wrapped.num_envs
    prior = {"x0": wrapped.estimator._x0, "P0": wrapped.estimator._P0}
    if windowed:
        prior["horizon"] = 4
    if name == "efir":
        prior["startup"] = wrapped.estimator.startup
    model = gym.make(env_id).unwrapped.model
    filters = [make_estimator(name, model, **prior) for _ in range(n)]
    new_episode = np.ones(n, bool)
    restarts = 0
    for obs, info, done in record:
        for i in range(n):
            y = obs["measurement"][i]
            if new_episode[i]:
                filters[i].reset(prior["x0"], prior["P0"])
                expected = filters[i].step(y)
                restarts += 1
            else:
                expected = filters[i].step(y, info["action"][i])
            np.testing.assert_allclose(obs["estimate"][i], expected, rtol=0, atol=1e-10)
            np.testing.assert_allclose(info["estimate"][i], expected, rtol=0, atol=1e-10)
        new_episode = done
    assert restarts >= 3 * n                        # the first episode and two autoresets each


@pytest.mark.parametrize("env_id", fir_gym.VECTOR_ENV_IDS)
def test_info_and_spaces(env_id):
    venv = gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point")
    wrapped = VectorEstimatorObservation(venv, "ekf", observation="estimate+covariance")
    obs, info = wrapped.reset(seed=0)
    assert wrapped.observation_space.contains(obs)
    obs, _, _, _, info = wrapped.step(wrapped.action_space.sample())
    assert wrapped.observation_space.contains(obs)
    assert info["estimation_error"].shape == (4, wrapped.estimator.model.n_x)
    assert info["estimator_diverged"].shape == (4,) and info["_estimate"].all()


def test_bad_arguments():
    venv = gym.make_vec("fir_gym/Orbit-v0", num_envs=2, vectorization_mode="sync")
    with pytest.raises(ValueError, match="unknown estimator"):
        VectorEstimatorObservation(venv, "nope")
    with pytest.raises(TypeError, match="instance"):
        VectorEstimatorObservation(venv, make_estimator("ekf", venv.get_attr("model")[0]))
    with pytest.raises(ValueError, match="observation must be"):
        VectorEstimatorObservation(venv, "ekf", observation="all")
    # same-step autoreset is supported too (make_sb3_vec_env's mode); disabled is not
    disabled = gym.make_vec("fir_gym/Orbit-v0", num_envs=2, vectorization_mode="sync",
                            vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.DISABLED})
    with pytest.raises(ValueError, match="next-step or same-step autoreset"):
        VectorEstimatorObservation(disabled, "ekf")


def test_same_step_autoreset_over_sync_equals_one_env_per_sub_env():
    """A sync vector env in same-step mode: the estimates, and the final estimates of ended
    episodes, are those of a single-env EstimatorObservation per sub-env."""
    from fir_gym.wrappers import EstimatorObservation

    n = 2
    venv = VectorEstimatorObservation(gym.make_vec(
        "fir_gym/VanDerPol-v0", num_envs=n, vectorization_mode="sync", max_episode_steps=3,
        vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}), "ekf")
    singles = [EstimatorObservation(gym.make("fir_gym/VanDerPol-v0", max_episode_steps=3), "ekf")
               for _ in range(n)]
    obs, _ = venv.reset(seed=5)
    np.testing.assert_allclose(obs, [s.reset(seed=5 + i)[0] for i, s in enumerate(singles)],
                               rtol=1e-12)
    rng = np.random.default_rng(0)
    for _ in range(7):
        actions = rng.uniform(-1, 1, (n, 1))
        obs, _, _, _, info = venv.step(actions)
        for i, single in enumerate(singles):
            o, _, t, tr, _ = single.step(actions[i])
            if t or tr:
                np.testing.assert_allclose(info["final_obs"][i], o, rtol=1e-12)
                o = single.reset()[0]
            np.testing.assert_allclose(obs[i], o, rtol=1e-12)


def test_async_vector_env_gives_the_same_numbers_as_sync():
    _, sync = rollout("sync", "fir_gym/UncertainOscillator-v0", "ekf", steps=15)
    _, asyn = rollout("async", "fir_gym/UncertainOscillator-v0", "ekf", steps=15)
    for (a, _, _), (b, _, _) in zip(sync, asyn, strict=True):
        np.testing.assert_array_equal(a["estimate"], b["estimate"])


def test_in_the_loop_efir_uses_the_prior_while_its_window_fills():
    venv = gym.make_vec("fir_gym/Orbit-v0", num_envs=2, vectorization_mode="sync")
    assert VectorEstimatorObservation(venv, "efir").estimator.startup == "prior"
    explicit = VectorEstimatorObservation(venv, "efir", startup="diffuse")
    assert explicit.estimator.startup == "diffuse"
