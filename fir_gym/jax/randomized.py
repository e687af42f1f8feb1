"""The ``mismatch`` condition in JAX: the truth's parameters drawn at every reset.

:class:`Randomized` wraps a plant of :mod:`fir_gym.jax` as the numpy plants' ``randomize=``
keyword does (:mod:`fir_gym.envs._conditions`, docs/robustness.md#plant-conditions): at every
reset — the first and gymnax's auto-resets — each named parameter of the truth is drawn as
``θ = θ_nominal (1 + s ξ)``, ``ξ ~ U(−1, 1)``, around the value the filter's model believes
(the ``nominal_*`` field; the numpy plant's ``nominal_params``), and the plant runs the
episode with those values; the model is not touched. ``fir_gym.jax.make(env_id, kind,
randomize={"mu": 0.1})`` builds it; ``randomize`` takes exactly the numpy keyword's values,
validated by the same function.

**Streams.** The draws come from ``jax.random.fold_in(key, CONDITION_STREAM)`` of the
reset's key (the numpy plants' tag, :data:`fir_gym.envs._conditions.CONDITION_STREAM`):
the plant's own noise, drawn from ``key`` itself, is the same as without the wrapper, so an
episode under the condition and the nominal one on the same key see the same noise — the
paired comparison the numpy benchmark makes. ``ξ`` is one ``uniform`` draw of one value per
parameter, in the sorted order of the names (the numpy draw's order); the values differ
from numpy's for the same seed (JAX's generator is not numpy's), the law and the order do
not. :meth:`Randomized.values_of` turns given ``ξ`` into the parameters, so a test can replay
the numpy plant's own draws.

The drawn values and the params fields of the truth they make — the plant's
:meth:`~fir_gym.jax._plant.FilteredPlant.true_fields`, computed once per episode at the reset
(CarrierMotion-v0 samples its continuous model again there, not at every step) — ride in the
state (:class:`RandomizedState`); every step runs on the params given with those fields in
place, and ``info["true_params"]`` reports the values, as the numpy plant's ``info`` does.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnax.environments.environment as gymnax_env
import jax
import jax.numpy as jnp
from flax import struct

from fir_gym.envs._conditions import CONDITION_STREAM, check_randomize


@struct.dataclass
class RandomizedState(gymnax_env.EnvState):
    """The wrapped plant's state (``plant``), the episode's drawn true parameters
    (``true_params``, by name) and the params fields of that truth (``truth``: the plant's
    ``true_fields``); ``time`` mirrors the plant's (gymnax's truncation reads it)."""

    plant: Any
    true_params: Any
    truth: Any


class Randomized(gymnax_env.Environment[Any, Any]):
    """``env`` (a :class:`~fir_gym.jax._plant.FilteredPlant`) with the truth's parameters
    ``randomize`` (``{name: relative spread}``, names among ``env.randomizable``) drawn at
    every reset (module docstring). Everything else — observations, spaces, the kind and its
    options — is the plant's.

    Raises:
        ValueError, TypeError: ``randomize`` as the numpy plants refuse it (a name the plant
            cannot randomize, a spread outside ``[0, 1)``), naming it.
    """

    def __init__(self, env: Any, randomize: Mapping[str, float]) -> None:
        super().__init__()
        self.env = env
        self.spreads = check_randomize(randomize, env.randomizable, env.name)

    def __getattr__(self, name: str) -> Any:
        if name == "env":                    # not set yet (a copy being built): no recursion
            raise AttributeError(name)
        return getattr(self.env, name)

    @property
    def name(self) -> str:
        return self.env.name

    @property
    def default_params(self) -> Any:
        return self.env.default_params

    @property
    def num_actions(self) -> int:
        return int(self.env.num_actions)

    def observation_space(self, params: Any) -> Any:
        return self.env.observation_space(params)

    def action_space(self, params: Any = None) -> Any:
        return self.env.action_space(params)

    # ------------------------------------------------------------------ the draws
    def values_of(self, xi: jax.Array, params: Any) -> dict[str, jax.Array]:
        """The true parameters ``θ_nominal (1 + s ξ)`` for ``ξ`` (one entry per parameter, in
        the sorted order of the names), ``θ_nominal`` the model's values
        (:func:`fir_gym.envs._conditions.draw_params` with given ``ξ``)."""
        centres = self.env.draw_centres(params)
        return {name: centres[name] * (1.0 + s * xi[i])
                for i, (name, s) in enumerate(self.spreads.items())}

    def draw(self, key: jax.Array, params: Any) -> dict[str, jax.Array]:
        """One episode's true parameters from the reset's ``key`` (its condition stream)."""
        xi = jax.random.uniform(jax.random.fold_in(key, CONDITION_STREAM), (len(self.spreads),),
                                dtype=jnp.float64, minval=-1.0, maxval=1.0)
        return self.values_of(xi, params)

    def episode_params(self, state: RandomizedState, params: Any) -> Any:
        """``params`` with the episode's drawn truth in place (its fields, kept in the
        state since the reset)."""
        return params.replace(**state.truth)

    # ------------------------------------------------------------------ the env
    def reset_env(self, key: jax.Array, params: Any) -> tuple[Any, RandomizedState]:
        values = self.draw(key, params)
        truth = self.env.true_fields(params, values)
        obs, plant = self.env.reset_env(key, params.replace(**truth))
        return obs, RandomizedState(time=plant.time, plant=plant, true_params=values,
                                    truth=truth)

    def step_env(self, key: jax.Array, state: RandomizedState, action: Any, params: Any
                 ) -> tuple[Any, RandomizedState, jax.Array, jax.Array, dict[str, Any]]:
        obs, plant, reward, terminated, info = self.env.step_env(
            key, state.plant, action, self.episode_params(state, params))
        info = {**info, "true_params": state.true_params}
        return obs, state.replace(time=plant.time, plant=plant), reward, terminated, info

    def get_obs(self, state: RandomizedState, params: Any = None, key: Any = None) -> Any:
        return self.env.get_obs(state.plant, params, key)

    def is_terminated(self, state: RandomizedState, params: Any) -> jax.Array:
        return self.env.is_terminated(state.plant, params)
