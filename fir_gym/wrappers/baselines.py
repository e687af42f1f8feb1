"""The two reference observations an estimate-fed controller is compared with.

* :class:`TrueStateObservation` — the controller sees the true state: the upper
  bound of what any estimator can give it.
* :class:`MeasurementObservation` — the controller sees the raw noisy measurement
  (what the plant returns anyway); a named wrapper so that the three kinds are
  built, recorded in the spec and reported on equal terms.
"""

from __future__ import annotations

import math
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces


class TrueStateObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Observe ``info["state"]`` (the true state) instead of the measurement.

    fir-gym's plants never report a state that is not finite (a failed step ends the
    episode at the last valid state); should another env do so, the observation
    repeats the last finite state, the episode terminates and
    ``info["simulation_failure"]`` is set (to ``"nonfinite_state"`` unless the env
    said why).
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        names, model = getattr(env.unwrapped, "state_names", ()), getattr(env.unwrapped,
                                                                        "model", None)
        if names:
            n_x = len(names)
        elif model is not None:
            n_x = int(model.n_x)
        else:
            raise TypeError("TrueStateObservation needs a plant that names its state "
                            "(state_names) or publishes a model")
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(n_x,), dtype=np.float64)
        self._last = np.zeros(n_x)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        _, info = self.env.reset(seed=seed, options=options)
        self._last = self._state(info)
        if not np.isfinite(self._last).all():
            raise ValueError(f"the env's reset returned a state that is not finite: "
                             f"{info['state']}")
        return self._last.copy(), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        _, reward, terminated, truncated, info = self.env.step(action)
        state = self._state(info)
        if not (math.isfinite(sum(state.tolist())) or np.isfinite(state).all()):
            info = {**info, "simulation_failure": info.get("simulation_failure",
                                                           "nonfinite_state")}
            return self._last.copy(), reward, True, truncated, info
        self._last = state
        return state.copy(), reward, terminated, truncated, info

    @staticmethod
    def _state(info: dict[str, Any]) -> np.ndarray:
        if "state" not in info:
            raise KeyError("TrueStateObservation needs info['state'] from the plant")
        return np.array(info["state"], dtype=np.float64)


class MeasurementObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Observe the raw measurement (the plant's own observation), unchanged."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)


class VectorTrueStateObservation(gym.vector.VectorWrapper):
    """:class:`TrueStateObservation` for a native fir-gym vector env: the true states
    ``info["state"]`` ``(B, n_x)`` as the observation (next-step or same-step autoreset; in
    same-step mode ``info["final_obs"]`` becomes the ended episodes' last states)."""

    def __init__(self, env: gym.vector.VectorEnv) -> None:
        super().__init__(env)
        plant = getattr(env.unwrapped, "plant", None)
        if plant is None:
            raise TypeError("VectorTrueStateObservation needs a native fir-gym vector env "
                            "(gym.make_vec(id, n, vectorization_mode='vector_entry_point'))")
        n_x = len(plant.state_names)
        self.single_observation_space = spaces.Box(-np.inf, np.inf, shape=(n_x,),
                                                   dtype=np.float64)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space,
                                                              self.num_envs)

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        _, info = self.env.reset(**kwargs)
        return info["state"].copy(), info

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        _, reward, terminated, truncated, info = self.env.step(actions)
        if "_final_obs" in info:
            info = dict(info)
            info["final_obs"] = info["final_info"]["state"].copy()
        return info["state"].copy(), reward, terminated, truncated, info
