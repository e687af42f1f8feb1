"""The kinds every plant of fir_gym.jax shares, against their numpy references.

* ``"measurement-stack"``: :class:`fir_gym.wrappers.measurement_stack.MeasurementStack` (the
  numpy wrapper) replaying the JAX plant's own measurements and applied actions must see the
  same windows as the JAX kind, step for step — the plant's measurement itself is the
  per-plant parity tests' business;
* every plant's :meth:`filter_model` (what the generic filters run on) must be the model its
  own filter uses: the textbook EKF step of :mod:`fir_gym.jax.kalman` on ``filter_model``
  reproduces the plant's inline EKF/KF (which the per-plant tests check against the numpy
  filter) along a whole closed-loop episode.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax_parity import replay  # noqa: E402

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.jax import PLANTS, make  # noqa: E402
from fir_gym.jax.kalman import ekf_predict, kf_update_innovation  # noqa: E402
from fir_gym.robustness.plan import PLANTS as PLANS  # noqa: E402
from fir_gym.wrappers.measurement_stack import MeasurementStack  # noqa: E402

STEPS = 120


def _rollout(env: Any, params: Any, actions: np.ndarray, seed: int) -> tuple[list, list]:
    """The states and infos of a rollout with ``reset_env``/``step_env`` (no auto-reset)."""
    keys = jax.random.split(jax.random.key(seed), len(actions) + 1)
    obs, state = jax.jit(env.reset_env)(keys[0], params)
    step = jax.jit(env.step_env)
    states, infos, observations = [state], [], [obs]
    for key, a in zip(keys[1:], actions, strict=True):
        obs, state, _, _, info = step(key, state, jnp.asarray(a), params)
        states.append(state)
        infos.append(info)
        observations.append(obs)
    return states, infos, observations


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_the_measurement_stack_is_the_numpy_wrappers_window(env_id: str) -> None:
    env, params = make(env_id, "measurement-stack", **PLANS[env_id].env_kwargs)
    numpy_plant = gym.make(env_id).unwrapped
    assert env.horizon == numpy_plant.default_horizon
    rng = np.random.default_rng(3)
    actions = rng.uniform(-1.3, 1.3, (STEPS, 1))          # some clipped
    states, infos, observations = _rollout(env, params, actions, seed=5)
    ys = np.array([np.asarray(s.y) for s in states])
    applied = np.array([np.asarray(i["action"]) for i in infos])
    assert np.any(applied != actions)                      # clipping was exercised
    wrapper = MeasurementStack(replay(ys, applied), horizon=numpy_plant.default_horizon)
    want, _ = wrapper.reset()
    assert env.observation_space(params).shape == want.shape
    np.testing.assert_array_equal(np.asarray(observations[0]), want)
    for k, a in enumerate(actions):
        want = wrapper.step(a)[0]
        np.testing.assert_array_equal(np.asarray(observations[k + 1]), want)


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_the_stack_horizon_is_an_option(env_id: str) -> None:
    env, params = make(env_id, "measurement-stack", kind_kwargs={"horizon": 3})
    obs, _ = env.reset(jax.random.key(0), params)
    assert obs.shape == (3 * (env.n_y + 1),)
    for bad in (0, -2, 2.5, True, "3"):
        with pytest.raises(ValueError, match="horizon"):
            make(env_id, "measurement-stack", kind_kwargs={"horizon": bad})
    with pytest.raises(ValueError, match=r"kind_kwargs.*window"):
        make(env_id, "measurement-stack", kind_kwargs={"window": 3})
    with pytest.raises(ValueError, match="alpha"):
        make(env_id, "ukf", kind_kwargs={"alpha": -1.0})
    with pytest.raises(ValueError, match="horizon"):
        make(env_id, "ukf", kind_kwargs={"horizon": 3})


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_the_filter_model_is_the_model_of_the_plants_own_filter(env_id: str) -> None:
    env, params = make(env_id, **PLANS[env_id].env_kwargs)
    model = env.filter_model(params)
    rng = np.random.default_rng(7)
    actions = rng.uniform(-1.0, 1.0, (STEPS, 1))
    states, infos, _ = _rollout(env, params, actions, seed=11)
    compared = 0
    worst = 0.0
    for k in range(len(actions)):
        old, new = states[k], states[k + 1]
        if bool(new.diverged) or bool(new.terminated):
            break
        u = jnp.asarray(infos[k]["action"])
        xp, Pp = ekf_predict(old.filter_x, old.filter_P, u, model.Q, model.f_and_F)
        np.testing.assert_allclose(np.asarray(model.f(old.filter_x, u)), np.asarray(xp),
                                   rtol=1e-13, atol=0)
        x, P, nis = kf_update_innovation(xp, Pp, new.y - model.H @ xp, model.H, model.R)
        for got, want in ((x, new.filter_x), (P, new.filter_P), (nis, new.nis)):
            got, want = np.asarray(got), np.asarray(want)
            err = np.max(np.abs(got - want)) / max(np.max(np.abs(want)), 1e-300)
            worst = max(worst, float(err))
        compared += 1
    assert compared >= STEPS // 2, f"only {compared} steps before the episode ended"
    assert worst < 1e-11, worst


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_the_params_carry_the_numpy_plants_noise_square_roots(env_id: str) -> None:
    """The builders compute each noise square root once with the numpy plant's psd_sqrt
    (no eigh in the steps); params made without them compute one in the trace
    (_plant.psd_sqrt, LAPACK-free) that squares to the same covariance."""
    from fir_gym.envs._base import psd_sqrt as numpy_psd_sqrt
    from fir_gym.jax._plant import psd_sqrt

    _, params = make(env_id, **PLANS[env_id].env_kwargs)
    pairs = {"initial_sqrt": "initial_state_cov", "process_sqrt": "Q",
             "measurement_sqrt": "R"}
    checked = 0
    for field, cov in pairs.items():
        S = getattr(params, field, None)
        if S is None or not hasattr(params, cov):
            continue
        M = np.asarray(getattr(params, cov))
        np.testing.assert_array_equal(np.asarray(S), numpy_psd_sqrt(M))
        T = np.asarray(jax.jit(psd_sqrt)(jnp.asarray(M)))
        np.testing.assert_allclose(T @ T.T, M, rtol=0, atol=1e-14 * max(np.abs(M).max(), 1e-300))
        checked += 1
    assert checked >= 1
