"""fir_gym.jax.batch_step against gymnax's own ``step`` vmapped (the oracle it must equal):
Orbit-v0 with its EKF, episodes cut short so that hundreds end in the run — some steps
within the reset places, some beyond them (the whole batch reset) —, plain and under the
robustness conditions (the truth's parameters drawn at every reset, readings lost); every
output compared bit for bit. And its refusals."""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import jax.numpy as jnp  # noqa: E402

from fir_gym.jax import make  # noqa: E402
from fir_gym.jax.batch_step import batch_step, default_slots  # noqa: E402
from fir_gym.jax.ppo import Gymnax0  # noqa: E402


def rollout(env, params, step, n_envs: int, steps: int):  # type: ignore[no-untyped-def]
    keys = jax.random.split(jax.random.key(11), n_envs)
    obs, states = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
    # each env starts at its own point of its episode, so that episodes end at different steps
    time = jnp.asarray(np.random.default_rng(0).integers(0, 20, n_envs))
    states = states.replace(time=time)
    if hasattr(states, "plant"):                     # the mismatch condition's wrapper
        states = states.replace(plant=states.plant.replace(time=time))

    def body(carry, key):  # type: ignore[no-untyped-def]
        obs, states = carry
        actions = jnp.clip(0.3 - 0.5 * (obs[:, :1] - 8.0), -1.0, 1.0)
        obs, states, reward, terminated, truncated, info = step(
            jax.random.split(key, n_envs), states, actions)
        return (obs, states), (obs, reward, terminated, truncated, info, states)

    return jax.jit(lambda k: jax.lax.scan(body, (obs, states), jax.random.split(k, steps)))(
        jax.random.key(5))


@pytest.mark.parametrize("conditions", [{}, {"randomize": {"mu": 0.1, "thrust_max": 0.1},
                                             "sensor_faults": {"dropout": 0.3}}])
@pytest.mark.parametrize("slots", [2, None])
def test_batch_step_is_gymnax_step_vmapped(conditions: dict, slots: int | None) -> None:
    env, params = make("fir_gym/Orbit-v0", "ekf", max_episode_steps=20, **conditions)
    n = 64

    def gymnax_step(keys, states, actions):  # type: ignore[no-untyped-def]
        return jax.vmap(env.step, in_axes=(0, 0, 0, None))(keys, states, actions, params)

    def ours(keys, states, actions):  # type: ignore[no-untyped-def]
        return batch_step(env, keys, states, actions, params, slots)

    want = rollout(env, params, gymnax_step, n, 60)
    got = rollout(env, params, ours, n, 60)
    for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
        np.testing.assert_array_equal(np.asarray(g), np.asarray(w))
    ended = np.asarray(want[1][2] | want[1][3]).sum(axis=1)     # episodes ended per step
    assert ended.sum() >= 150                                    # resets happened
    places = default_slots(n) if slots is None else slots
    assert (ended > places).any() and ((ended > 0) & (ended <= places)).any(), \
        "both branches (the ended envs only, the whole batch) ran"


def test_default_slots() -> None:
    assert [default_slots(n) for n in (1, 4, 16, 128, 2048)] == [1, 4, 4, 4, 64]


def test_batch_step_refuses() -> None:
    env, params = make("fir_gym/Orbit-v0", "ekf")
    keys = jax.random.split(jax.random.key(0), 4)
    _, states = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
    actions = jnp.zeros((4, 1))
    for slots in (0, 5, 2.0, True):
        with pytest.raises(ValueError, match="slots must be an integer from 1 to the batch's 4"):
            batch_step(env, keys, states, actions, params, slots)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"env must step as gymnax's Environment\.step"):
        batch_step(Gymnax0(env), keys, states, actions, params)
    with pytest.raises(ValueError, match="keys must be one key per env"):
        batch_step(env, jax.random.key(0), states, actions, params)
    with pytest.raises(ValueError, match=r"actions must have one row per env \(4\)"):
        batch_step(env, keys, states, jnp.zeros((3, 1)), params)
    # raw uint32 keys (jax.random.PRNGKey) are one key per row
    raw = jax.random.split(jax.random.PRNGKey(0), 4)
    assert batch_step(env, raw, states, actions, params)[0].shape == (4, 2)
