"""The memory baseline without a model: the last K measurements and actions.

A controller on one raw measurement has no velocity; one that sees a window of past
measurements and the actions between them can infer it, as a FIR filter does, but
with a learned map instead of the model. The observation is

    [y[k−K+1], …, y[k], a[k−K], …, a[k−1]]        (oldest first, K·n_y + K·n_u numbers)

— the measurement window of a FIR filter with ``horizon = K`` and its inputs. Before K
measurements exist the window is padded with the episode's first measurement and
zero actions (Gymnasium's ``FrameStackObservation`` pads with the reset observation
too). ``K`` defaults to the plant's ``default_horizon``, the window the FIR filters
use, so the two memories are the same length. :class:`MeasurementStack` wraps one env,
:class:`VectorMeasurementStack` a vector env (next-step or same-step autoreset; in
same-step mode ``info["final_obs"]`` becomes the ended episodes' last windows).
"""

from __future__ import annotations

from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from fir_gym.estimators._validation import positive

from .vector_estimator_observation import same_step_mode

FloatArray = NDArray[np.float64]


def _window_space(n_y: int, n_u: int, horizon: int) -> spaces.Box:
    return spaces.Box(-np.inf, np.inf, shape=(horizon * (n_y + n_u),), dtype=np.float64)


def _flat_size(space: spaces.Space) -> int:
    return int(np.prod(space.shape or ()))


def _horizon_of(plant: Any, horizon: int | None) -> int:
    if horizon is None:
        return int(getattr(plant, "default_horizon", 10))
    return int(positive("horizon", horizon, integer=True))


class MeasurementStack(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Observe the last ``horizon`` measurements and actions (see the module docstring)."""

    def __init__(self, env: gym.Env, horizon: int | None = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, horizon=horizon)
        gym.Wrapper.__init__(self, env)
        self.horizon = _horizon_of(env.unwrapped, horizon)
        self._n_y = _flat_size(env.observation_space)
        self._n_u = _flat_size(env.action_space)
        self.observation_space = _window_space(self._n_y, self._n_u, self.horizon)
        self._y = np.zeros((self.horizon, self._n_y))
        self._a = np.zeros((self.horizon, self._n_u))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[FloatArray, dict[str, Any]]:
        y, info = self.env.reset(seed=seed, options=options)
        self._y[:] = np.asarray(y, dtype=np.float64).reshape(self._n_y)
        self._a[:] = 0.0
        return self._window(), info

    def step(self, action: Any) -> tuple[FloatArray, SupportsFloat, bool, bool, dict[str, Any]]:
        y, reward, terminated, truncated, info = self.env.step(action)
        applied = info.get("action", action)
        self._y = np.roll(self._y, -1, axis=0)
        self._y[-1] = np.asarray(y, dtype=np.float64).reshape(self._n_y)
        self._a = np.roll(self._a, -1, axis=0)
        self._a[-1] = np.asarray(applied, dtype=np.float64).reshape(self._n_u)
        return self._window(), reward, terminated, truncated, info

    def _window(self) -> FloatArray:
        return np.concatenate([self._y.ravel(), self._a.ravel()])


class VectorMeasurementStack(gym.vector.VectorWrapper):
    """:class:`MeasurementStack` for every sub-env of a vector env, as one array."""

    def __init__(self, env: VectorEnv, horizon: int | None = None) -> None:
        super().__init__(env)
        self._same_step = same_step_mode(env, type(self).__name__)
        plant = getattr(env.unwrapped, "plant", None)
        if plant is None:
            plant = cast(Any, env.unwrapped).get_attr("unwrapped")[0]
        self.horizon = _horizon_of(plant, horizon)
        self._n_y = _flat_size(env.single_observation_space)
        self._n_u = _flat_size(env.single_action_space)
        self.single_observation_space = _window_space(self._n_y, self._n_u, self.horizon)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        n, K = self.num_envs, self.horizon
        self._y = np.zeros((n, K, self._n_y))
        self._a = np.zeros((n, K, self._n_u))
        self._prev_done = np.zeros(n, dtype=bool)

    def reset(self, *, seed: int | list[int] | None = None,
              options: dict[str, Any] | None = None) -> tuple[FloatArray, dict[str, Any]]:
        y, info = cast(Any, self.env).reset(seed=seed, options=options)
        self._y[:] = np.asarray(y, dtype=np.float64).reshape(self.num_envs, 1, self._n_y)
        self._a[:] = 0.0
        self._prev_done[:] = False
        return self._window(), info

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        y, reward, terminated, truncated, info = self.env.step(actions)
        Y = np.asarray(y, dtype=np.float64).reshape(self.num_envs, self._n_y)
        u = np.asarray(info.get("action", actions), dtype=np.float64).reshape(self.num_envs,
                                                                              self._n_u)
        fresh = self._prev_done                         # next-step mode: reset this step
        ended = info.get("_final_obs") if self._same_step else None
        self._push(Y, u)
        if ended is not None and ended.any():
            final = info["final_obs"]      # an array, or (sync/async) an object array
            for i in np.flatnonzero(ended):
                self._y[i, -1] = np.asarray(final[i], dtype=np.float64).reshape(self._n_y)
            info = dict(info)
            info["final_obs"] = self._window()
            fresh = ended
        if fresh.any():
            self._y[fresh] = Y[fresh, None, :]
            self._a[fresh] = 0.0
        if not self._same_step:
            self._prev_done = np.logical_or(terminated, truncated)
        return self._window(), reward, terminated, truncated, info

    def _push(self, Y: FloatArray, u: FloatArray) -> None:
        self._y[:, :-1] = self._y[:, 1:]
        self._y[:, -1] = Y
        self._a[:, :-1] = self._a[:, 1:]
        self._a[:, -1] = u

    def _window(self) -> FloatArray:
        n = self.num_envs
        return np.concatenate([self._y.reshape(n, -1), self._a.reshape(n, -1)], axis=1)
