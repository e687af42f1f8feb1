"""A tiny deterministic gymnax plant for the JAX training tests: :class:`Ticker`.

Its observation climbs by one a step whatever the action, so every stored quantity of a
rollout is computable by hand: ``x`` starts at :data:`X0`, the observation is
``(x, x² / 4)``, the reward ``-x``; episodes are :data:`EPISODE` steps (gymnax's time limit)
and terminate at step ``terminate_at`` (0: never).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct
from gymnax.environments import environment, spaces

EPISODE = 3          # steps to the time limit
X0 = 0.5             # the first observation's x


@struct.dataclass
class TickerState(environment.EnvState):
    x: jax.Array


@struct.dataclass
class TickerParams(environment.EnvParams):
    max_steps_in_episode: int = EPISODE
    terminate_at: int = 0            # the episode step that terminates (0: none)


class Ticker(environment.Environment):
    """``x`` starts at 0.5 and climbs by one a step whatever the action; the observation is
    ``(x, x² / 4)``, the reward ``-x``; terminated at step ``terminate_at`` of an episode."""

    @property
    def default_params(self) -> TickerParams:
        return TickerParams()

    def obs(self, x: jax.Array) -> jax.Array:
        return jnp.stack([x, x * x / 4.0])

    def reset_env(self, key: jax.Array, params: TickerParams) -> Any:
        x = jnp.asarray(X0)
        return self.obs(x), TickerState(time=0, x=x)

    def step_env(self, key: jax.Array, state: TickerState, action: Any, params: TickerParams
                 ) -> Any:
        x, time = state.x + 1.0, state.time + 1
        terminated = time == params.terminate_at
        new = TickerState(time=time, x=x)
        return self.obs(x), new, -x, terminated, {}

    def observation_space(self, params: TickerParams) -> spaces.Box:
        return spaces.Box(-jnp.inf, jnp.inf, (2,), jnp.float64)

    def action_space(self, params: Any = None) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (1,), jnp.float32)
