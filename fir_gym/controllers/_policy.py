"""What the classical controllers share: stable-baselines3's ``predict`` and finding the plant.

A controller is built for an env — a Gymnasium env (``gym.make(id, estimator=...)``,
:func:`fir_gym.wrappers.wrap_observation`), a native fir-gym vector env and its wrappers
(``VectorEstimatorObservation``, ``VectorTrueStateObservation``) or a stable-baselines3
``VecEnv`` over such envs (:func:`fir_gym.training.make_sb3_vec_env`, ``DummyVecEnv``) —
and reads from it
the plant (``env.unwrapped``: its nominal model and operating point) and what the
controller sees (the true state, an estimate, or the raw measurement).
``predict(observation, state=None, episode_start=None, deterministic=True)`` has
stable-baselines3's signature, so ``evaluate_policy`` and fir-gym's evaluation treat a
controller as a policy: one observation gives one action, a batch ``(n_envs, ...)``
gives ``(n_envs, n_u)`` actions, in float32 and inside the action Box.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: what a controller may see: the true state, a state estimate, the raw measurement
SEEN = ("true", "estimate", "measurement")


def plant_of(env: Any) -> Any:
    """The fir-gym plant behind a Gymnasium env or a stable-baselines3 ``VecEnv``."""
    plant: Any
    if isinstance(env, gym.Env):
        plant = env.unwrapped
    elif isinstance(env, gym.vector.VectorEnv):        # a native vector env (wrapped)
        plant = getattr(env.unwrapped, "plant", None)
    elif hasattr(env, "get_attr"):                     # a stable-baselines3 VecEnv
        plant = env.get_attr("unwrapped", [0])[0]
    else:
        raise TypeError(f"env must be a Gymnasium env or a stable-baselines3 VecEnv; got "
                        f"{type(env).__name__}")
    if plant is None or not hasattr(plant, "nominal_params"):
        raise TypeError(f"env must be a fir-gym plant (possibly wrapped); got "
                        f"{type(plant).__name__}")
    return plant


def seen_by(env: Any) -> str:
    """What ``env`` observes: ``"true"``, ``"estimate"`` or ``"measurement"``."""
    from fir_gym.wrappers import (
        EstimatorObservation,
        TrueStateObservation,
        VectorEstimatorObservation,
        VectorTrueStateObservation,
    )

    seen = getattr(env, "observed", None)             # fir-gym's SB3 VecEnv says it
    if seen is not None:
        return str(seen)
    while isinstance(env, gym.vector.VectorWrapper):  # a native vector env's wrappers
        if isinstance(env, VectorEstimatorObservation):
            return "estimate"
        if isinstance(env, VectorTrueStateObservation):
            return "true"
        env = env.env
    if isinstance(env, gym.vector.VectorEnv):
        return "measurement"
    if hasattr(env, "envs"):                           # DummyVecEnv: look at the first env
        env = env.envs[0]
    while isinstance(env, gym.Wrapper):
        if isinstance(env, EstimatorObservation):
            return "estimate"
        if isinstance(env, TrueStateObservation):
            return "true"
        env = env.env
    if isinstance(env, gym.Env):
        return "measurement"
    return "estimate" if _has_estimate_key(env) else "measurement"


def _has_estimate_key(env: Any) -> bool:
    space = getattr(env, "observation_space", None)
    return isinstance(space, gym.spaces.Dict) and "estimate" in space.spaces


class Controller:
    """Base class: stable-baselines3's ``predict`` around a batched :meth:`act`."""

    def __init__(self, env: Any) -> None:
        self.plant = plant_of(env)
        self.observed = seen_by(env)
        space = self.plant.action_space
        self.action_space = space
        self._low = np.asarray(space.low, dtype=np.float64)
        self._high = np.asarray(space.high, dtype=np.float64)

    def act(self, observation: FloatArray, state: Any, episode_start: np.ndarray
            ) -> tuple[FloatArray, Any]:
        """Actions ``(n, n_u)`` (before clipping) for a batch ``(n, ...)`` of observations."""
        raise NotImplementedError

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """stable-baselines3's ``predict``: ``(actions, state)``, actions clipped to the Box.

        The controllers are deterministic; ``deterministic`` is accepted for the
        signature's sake. ``state`` carries a controller's memory between calls (the
        PID's integral; ``None`` for the LQG, whose memory is the estimator), and
        ``episode_start`` (one bool per env) clears it where an episode starts.
        """
        obs = observation["estimate"] if isinstance(observation, dict) else observation
        obs = np.asarray(obs, dtype=np.float64)
        single = obs.ndim == 1
        batch = obs[None] if single else obs
        starts = np.ones(len(batch), dtype=bool) if episode_start is None else \
            np.asarray(episode_start, dtype=bool).reshape(len(batch))
        actions, state = self.act(batch, state, starts)
        actions = np.clip(actions, self._low, self._high).astype(self.action_space.dtype)
        return (actions[0] if single else actions), state
