"""The two reference observations an estimate-fed controller is compared with.

* :class:`TrueStateObservation` — the controller sees the true state: the upper
  bound of what any estimator can give it.
* :class:`MeasurementObservation` — the controller sees the raw noisy measurement
  (what the plant returns anyway); a named wrapper so that the three kinds are
  built, recorded in the spec and reported on equal terms.
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces


class TrueStateObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Observe ``info["state"]`` (the true state) instead of the measurement."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        plant = env.unwrapped
        n_x = len(getattr(plant, "state_names", ())) or getattr(plant, "model").n_x  # noqa: B009
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(n_x,), dtype=np.float64)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        _, info = self.env.reset(seed=seed, options=options)
        return self._state(info), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        _, reward, terminated, truncated, info = self.env.step(action)
        return self._state(info), reward, terminated, truncated, info

    @staticmethod
    def _state(info: dict[str, Any]) -> np.ndarray:
        if "state" not in info:
            raise KeyError("TrueStateObservation needs info['state'] from the plant")
        return np.asarray(info["state"], dtype=np.float64).copy()


class MeasurementObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Observe the raw measurement (the plant's own observation), unchanged."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
