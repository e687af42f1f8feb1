"""Contract tests every registered plant must pass (issue 2's acceptance list)."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import fir_gym
from fir_gym.estimators.model import _central_jacobian

ENV_IDS = fir_gym.ENV_IDS

#: Warnings the checkers may raise, each justified in the plants' docstrings.
EXPECTED_WARNINGS = (
    "A Box observation space minimum value is -infinity",   # Gaussian measurement noise
    "A Box observation space maximum value is infinity",
)


def rollout(env_id: str, seed: int, steps: int = 200, **kwargs):
    env = gym.make(env_id, **kwargs)
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(1234)                      # the same actions for every seed
    observations, states = [obs], [info["state"]]
    for _ in range(steps):
        obs, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape))
        observations.append(obs)
        states.append(info["state"])
        if terminated or truncated:
            break
    return np.array(observations), np.array(states)


def test_registration_lists_every_plant():
    assert set(ENV_IDS) == {"fir_gym/Orbit-v0", "fir_gym/UncertainOscillator-v0",
                            "fir_gym/CarrierMotion-v0", "fir_gym/VanDerPol-v0",
                            "fir_gym/PendulumSlider-v0"}
    assert set(fir_gym.VECTOR_ENV_IDS) == set(ENV_IDS)
    for env_id in ENV_IDS:
        assert gym.spec(env_id).max_episode_steps is not None


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_check_env(env_id):
    env = gym.make(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    unexpected = [str(w.message) for w in caught
                  if not any(e in str(w.message) for e in EXPECTED_WARNINGS)]
    assert unexpected == []


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_check_env(env_id):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_checker.check_env(env.unwrapped, warn=True)
    unexpected = [str(w.message) for w in caught
                  if not any(e in str(w.message) for e in EXPECTED_WARNINGS)]
    assert unexpected == []


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_is_bit_identical_and_seeds_differ(env_id):
    obs_a, states_a = rollout(env_id, seed=7)
    obs_b, states_b = rollout(env_id, seed=7)
    obs_c, _ = rollout(env_id, seed=8)
    assert np.array_equal(obs_a, obs_b)
    assert np.array_equal(states_a, states_b)
    assert obs_a.shape == obs_c.shape and not np.array_equal(obs_a, obs_c)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reset_without_seed_continues_the_generator(env_id):
    env = gym.make(env_id)
    first, _ = env.reset(seed=3)
    second, _ = env.reset()
    again, _ = env.reset(seed=3)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, second)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_pickle_round_trip_continues_identically(env_id):
    env = gym.make(env_id).unwrapped
    env.reset(seed=11)
    env.step(np.full(env.action_space.shape, 0.3, dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    action = np.full(env.action_space.shape, -0.2, dtype=np.float32)
    out_a, out_b = env.step(action), clone.step(action)
    assert np.array_equal(out_a[0], out_b[0])
    assert np.array_equal(out_a[4]["state"], out_b[4]["state"])
    # the model survives pickling too and gives the same numbers
    x = env.state
    assert np.array_equal(pickle.loads(pickle.dumps(env.model)).f(x), env.model.f(x))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_make_vec_sync_steps(env_id):
    envs = gym.make_vec(env_id, num_envs=4, vectorization_mode="sync")
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (4,) + envs.single_observation_space.shape
    for _ in range(3):
        obs, reward, *_ = envs.step(envs.action_space.sample())
    assert reward.shape == (4,) and np.all(np.isfinite(obs))
    assert len({tuple(o) for o in obs}) == 4          # sub-environments are seeded apart
    envs.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_rgb_array_frames_are_not_blank(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) >= 3   # background plus drawn parts


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_info_state_is_a_fresh_copy(env_id):
    env = gym.make(env_id).unwrapped
    _, info = env.reset(seed=0)
    info["state"][:] = 123.0
    assert not np.any(env.state == 123.0)


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_action_raises_naming_action(env_id, bad):
    env = gym.make(env_id)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(np.full(env.action_space.shape, bad))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_wrongly_shaped_action_raises_naming_action(env_id):
    env = gym.make(env_id)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(np.zeros(env.action_space.shape[0] + 1))
    with pytest.raises(ValueError, match="action"):
        env.step(np.zeros((1, 1, 1)))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_out_of_bounds_action_is_clipped_and_reported(env_id):
    plain, big = gym.make(env_id).unwrapped, gym.make(env_id).unwrapped
    plain.reset(seed=5)
    big.reset(seed=5)
    _, _, _, _, info_plain = plain.step(np.ones(plain.action_space.shape))
    _, _, _, _, info_big = big.step(np.full(big.action_space.shape, 7.0))
    assert info_big["action_clipped"] and not info_plain["action_clipped"]
    assert np.array_equal(info_big["action"], np.ones(big.action_space.shape))
    assert info_big["action"].dtype == np.float64
    assert np.array_equal(info_plain["state"], info_big["state"])


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_unknown_arguments_are_rejected_clearly(env_id):
    with pytest.raises(TypeError, match="not_a_parameter"):
        gym.make(env_id, not_a_parameter=1.0)
    with pytest.raises(ValueError, match="nominal"):
        gym.make(env_id, nominal={"not_a_parameter": 1.0})
    with pytest.raises(ValueError, match="render_mode"), warnings.catch_warnings():
        warnings.simplefilter("ignore")               # gymnasium warns before we raise
        gym.make(env_id, render_mode="ansi")
    env = gym.make(env_id)
    with pytest.raises(ValueError, match="reset options"):
        env.reset(options={"not_an_option": 1})


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reset_from_a_given_state(env_id):
    env = gym.make(env_id).unwrapped
    x0 = env.initial_state + 0.01
    _, info = env.reset(seed=0, options={"state": x0})
    assert np.array_equal(info["state"], x0)
    with pytest.raises(ValueError, match="state"):
        env.reset(options={"state": np.zeros(len(x0) + 1)})


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_model_batched_calls_equal_looped_calls(env_id):
    env = gym.make(env_id).unwrapped
    model = env.model
    rng = np.random.default_rng(0)
    X = env.initial_state + 0.05 * rng.standard_normal((6, model.n_x))
    U = rng.uniform(-1, 1, (6, model.n_u))
    for batched, looped in (
        (model.f(X, U), [model.f(x, u) for x, u in zip(X, U, strict=True)]),
        (model.F(X, U), [model.F(x, u) for x, u in zip(X, U, strict=True)]),
        (model.h(X), [model.h(x) for x in X]),
        (model.H(X), [model.H(x) for x in X]),
    ):
        np.testing.assert_allclose(batched, np.array(looped), rtol=0, atol=1e-13)


@pytest.mark.parametrize("env_id", ENV_IDS)
@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_model_jacobians_match_finite_differences(env_id, data):
    env = gym.make(env_id).unwrapped
    model = env.model
    n = model.n_x
    offsets = data.draw(st.lists(st.floats(-0.5, 0.5), min_size=n, max_size=n))
    u = data.draw(st.floats(-1.0, 1.0))
    x = env.initial_state + np.array(offsets) * np.maximum(1.0, np.abs(env.initial_state)) * 0.2
    x_u = np.array([u])
    F_fd = _central_jacobian(lambda z, uu: model.f(z, uu), x, x_u)
    H_fd = _central_jacobian(lambda z, _u: model.h(z), x, None)
    scale = max(1.0, float(np.max(np.abs(F_fd))))
    np.testing.assert_allclose(model.F(x, x_u), F_fd, rtol=0, atol=1e-7 * scale)
    np.testing.assert_allclose(model.H(x), H_fd, rtol=0, atol=1e-8)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_nominal_overrides_reach_the_model_but_not_the_plant(env_id):
    env = gym.make(env_id).unwrapped
    key = "R" if "R" in env.params else "v"
    value = np.asarray(env.params[key]) * 4.0
    other = gym.make(env_id, nominal={key: value}).unwrapped
    assert not np.allclose(other.model.R, env.model.R)
    assert np.allclose(other.model.R, 4.0 * env.model.R)
    # the plant is untouched: the same seed gives the same rollout
    obs_env, states_env = rollout(env_id, seed=4, steps=20)
    obs_other, states_other = rollout(env_id, seed=4, steps=20, nominal={key: value})
    assert np.array_equal(obs_env, obs_other) and np.array_equal(states_env, states_other)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_model_linearize_equals_f_and_F(env_id):
    env = gym.make(env_id).unwrapped
    model = env.model
    X = env.initial_state + 0.05 * np.random.default_rng(2).standard_normal((4, model.n_x))
    U = np.full((4, model.n_u), 0.3)
    fx, Fx = model.linearize(X, U)
    np.testing.assert_allclose(fx, model.f(X, U), rtol=0, atol=1e-15)
    np.testing.assert_allclose(Fx, model.F(X, U), rtol=0, atol=1e-15)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_plant_options_are_keyword_only(env_id):
    """``gym.make(env_id, sample_period=...)``: every option of a plant is passed by name, so
    a positional slip cannot land in the wrong parameter (a constructor called directly
    refuses a positional option)."""
    import inspect
    cls = type(gym.make(env_id).unwrapped)
    params = list(inspect.signature(cls).parameters.values())
    assert params
    late = [p.name for p in params if p.kind not in (p.KEYWORD_ONLY, p.VAR_KEYWORD)]
    assert not late, f"{env_id}: options not keyword-only: {late}"
    with pytest.raises(TypeError):
        cls(0.5)
