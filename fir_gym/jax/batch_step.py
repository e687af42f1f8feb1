"""gymnax's auto-resetting ``step`` over a batch of envs, the resets computed only where an
episode ended.

``jax.vmap(env.step)`` computes every env's reset at every step (gymnax's ``Environment.step``
draws it, then a select keeps it where the episode ended): for Orbit-v0 with its EKF, a
quarter of a step's time on two CPU cores went to resets almost all of which were thrown
away. :func:`batch_step` steps the batch (``step_env`` vmapped), gathers the envs whose episode
ended into ``slots`` places, computes their resets there and scatters them back; when more
than ``slots`` episodes end at once, it resets the whole batch as gymnax does (a
``lax.cond``: only one of the two runs). Each env gets the same key, the same reset and the
same info as from gymnax's ``step`` (its key split into the step's and the reset's, the
reset kept where ``terminated | truncated``, ``info["final_observation"]`` the observation
before the reset) — the same numbers: ``tests/jax/test_batch_step.py`` steps Orbit-v0 with
its EKF both ways, through hundreds of episode ends, under the robustness conditions too.

This is the numpy vector env's way (a reset only for the envs that need one), kept within
gymnax's noise contract.
"""

from __future__ import annotations

from typing import Any

import gymnax.environments.environment as gymnax_env
import jax
import jax.numpy as jnp


def default_slots(n_envs: int) -> int:
    """The reset places :func:`batch_step` keeps for ``n_envs`` envs: one per 32 envs, at
    least 4 (at most ``n_envs``) — ample for episodes of hundreds of steps (Orbit-v0's 1000:
    two endings per step at 2048 envs on average), and a batch where more end at once is
    reset whole, as gymnax does."""
    return min(n_envs, max(4, n_envs // 32))


def batch_step(env: Any, keys: jax.Array, states: Any, actions: jax.Array, params: Any,
               slots: int | None = None) -> tuple[Any, Any, jax.Array, jax.Array, jax.Array,
                                                  dict[str, Any]]:
    """``jax.vmap(env.step, in_axes=(0, 0, 0, None))(keys, states, actions, params)`` — the
    same ``(obs, states, rewards, terminated, truncated, info)`` — with the resets computed
    only for the envs whose episode ended (:func:`default_slots` places unless ``slots``;
    module docstring). ``params`` are shared by the batch."""
    if type(env).step is not gymnax_env.Environment.step:
        raise ValueError(f"env must step as gymnax's Environment.step (batch_step computes "
                         f"what it computes); {type(env).__name__} has a step of its own")
    typed = jax.dtypes.issubdtype(keys.dtype, jax.dtypes.prng_key)
    if keys.ndim != (1 if typed else 2):
        raise ValueError(f"keys must be one key per env (jax.random.split(key, n_envs)); got "
                         f"an array of shape {keys.shape} and dtype {keys.dtype}")
    n = keys.shape[0]
    if jnp.ndim(actions) < 1 or jnp.shape(actions)[0] != n:
        raise ValueError(f"actions must have one row per env ({n}); got shape "
                         f"{jnp.shape(actions)}")
    slots = default_slots(n) if slots is None else slots
    if isinstance(slots, bool) or not isinstance(slots, int) or not 1 <= slots <= n:
        raise ValueError(f"slots must be an integer from 1 to the batch's {n} envs; got "
                         f"{slots!r}")
    split = jax.vmap(jax.random.split)(keys)
    key_step, key_reset = split[:, 0], split[:, 1]
    obs_st, state_st, reward, terminated, info = jax.vmap(
        env.step_env, in_axes=(0, 0, 0, None))(key_step, states, actions, params)
    truncated = jax.vmap(env.is_truncated, in_axes=(0, None))(state_st, params)
    done = jnp.logical_or(terminated, truncated)

    def select(reset: jax.Array, stepped: jax.Array) -> jax.Array:
        """The reset where ``done``, the step elsewhere (gymnax's select, per env)."""
        return jnp.where(done.reshape(done.shape + (1,) * (stepped.ndim - 1)), reset, stepped)

    def every_env(_: Any) -> tuple[Any, Any]:
        obs_re, state_re = jax.vmap(env.reset_env, in_axes=(0, None))(key_reset, params)
        return jax.tree.map(select, obs_re, obs_st), jax.tree.map(select, state_re, state_st)

    def ended_only(_: Any) -> tuple[Any, Any]:
        at = jnp.nonzero(done, size=slots, fill_value=n)[0]      # n: an empty place
        obs_re, state_re = jax.vmap(env.reset_env, in_axes=(0, None))(
            key_reset[jnp.minimum(at, n - 1)], params)

        def put(stepped: jax.Array, reset: jax.Array) -> jax.Array:
            return stepped.at[at].set(reset, mode="drop")        # empty places dropped
        return jax.tree.map(put, obs_st, obs_re), jax.tree.map(put, state_st, state_re)

    obs, state = jax.lax.cond(jnp.sum(done) <= slots, ended_only, every_env, None)
    info = {**info, "terminated": terminated, "truncated": truncated,
            "final_observation": obs_st}
    return obs, state, reward, terminated, truncated, info
