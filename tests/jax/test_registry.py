"""fir_gym.jax.make: every plant of the JAX backend, every kind, as gymnax's API promises
(reset and step under jit and vmap, finite, the auto-reset's time counter), and bad input
refused naming the argument."""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import fir_gym  # noqa: E402
from fir_gym.jax import PLANTS, make  # noqa: E402

CASES = [(env_id, kind) for env_id, plant in PLANTS.items() for kind in plant.kinds]


def test_every_jax_plant_is_a_registered_numpy_plant() -> None:
    assert "fir_gym/Orbit-v0" in PLANTS
    for env_id in PLANTS:
        assert env_id in fir_gym.ENV_IDS and env_id in gym.registry


@pytest.mark.parametrize("env_id,kind", CASES)
def test_reset_and_step_run_jitted_and_vmapped(env_id: str, kind: str) -> None:
    env, params = make(env_id, kind)
    n, steps = 3, 5
    keys = jax.random.split(jax.random.PRNGKey(0), n)
    obs, state = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, params)
    space = env.action_space(params)
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))
    for k in range(steps):
        keys = jax.random.split(jax.random.PRNGKey(k + 1), n)
        action = jnp.full((n, *space.shape), 0.1)
        obs, state, reward, terminated, truncated, _ = step(keys, state, action, params)
        for leaf in jax.tree.leaves(obs):
            assert leaf.shape[0] == n and np.isfinite(np.asarray(leaf)).all()
        assert reward.shape == (n,) and np.isfinite(np.asarray(reward)).all()
        assert terminated.dtype == jnp.bool_ and truncated.dtype == jnp.bool_
    assert env.observation_space(params).contains(jax.tree.map(lambda x: x[0], obs))


def test_bad_input_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match="env_id"):
        make("fir_gym/NoSuchPlant-v0")
    with pytest.raises(ValueError, match="kind"):
        make("fir_gym/Orbit-v0", "nope")
    with pytest.raises(ValueError, match="no_such_option"):
        make("fir_gym/Orbit-v0", no_such_option=1.0)
