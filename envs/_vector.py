"""Native vector environments: B copies of a plant stepped as one batch of numpy arrays.

:class:`PlantVectorEnv` runs ``num_envs`` systems of one plant in lock-step with the
plant's own (batched) hooks, so a step costs one call of the dynamics for the whole
batch instead of ``num_envs`` Python-level steps. It follows Gymnasium's
``CartPoleVectorEnv``: its own episode counters and truncation at
``max_episode_steps``, and *next-step* autoreset (``AutoresetMode.NEXT_STEP``): the
step after a sub-environment terminates or is truncated resets it, ignores its
action, and returns the first measurement of the new episode with reward 0 and
``terminated = truncated = False``.

``info`` holds ``state`` (the true states, ``(B, n_x)``), ``action`` (the applied
actions after clipping) and each plant's per-step extras, each with Gymnasium's
``_key`` mask. The plant's noise is drawn from the vector env's own generator, so a
seed gives bit-identical rollouts (but not the same numbers as ``num_envs``
separate envs, whose generators differ).

With ``render_mode="rgb_array"`` (``gym.make_vec(id, n, vectorization_mode=
"vector_entry_point", render_mode="rgb_array")``), ``render()`` returns one frame per
sub-environment, a tuple as Gymnasium's ``SyncVectorEnv`` does, and
:attr:`PlantVectorEnv.frame_views` the view of each (for drawing estimates over them).
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import ArrayLike, NDArray

from ._base import PlantEnv

FloatArray = NDArray[np.float64]


class PlantVectorEnv(VectorEnv):
    """``num_envs`` copies of ``plant_class(**kwargs)`` stepped as one batch."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"],
                                          "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        plant_class: type[PlantEnv],
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        **plant_kwargs: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or num_envs <= 0:
            raise ValueError(f"num_envs must be a positive integer; got {num_envs!r}")
        if max_episode_steps is not None and max_episode_steps <= 0:
            raise ValueError(
                f"max_episode_steps must be positive or None; got {max_episode_steps!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array' for a native vector env; "
                             f"got {render_mode!r}")
        self.plant = plant_class(render_mode=render_mode, **plant_kwargs)
        self.num_envs = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.render_mode = render_mode
        # the plant's frame rate (instance metadata, as Gymnasium's wrappers set theirs)
        self.metadata = {**type(self).metadata,  # type: ignore[misc]
                         "render_fps": self.plant.metadata.get("render_fps", 30)}
        self._frame_views: tuple[Any, ...] = ()
        self.single_action_space = self.plant.action_space
        self.single_observation_space = self.plant.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        n_x = len(self.plant.state_names)
        self.states = np.tile(self.plant.initial_state, (self.num_envs, 1))
        self.steps = np.zeros(self.num_envs, dtype=np.int64)
        self.prev_done = np.zeros(self.num_envs, dtype=bool)
        self._n_x = n_x

    @property
    def model(self) -> Any:
        """The plant's model (the filter's belief), shared by every sub-environment."""
        return self.plant.model

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[FloatArray, dict[str, Any]]:
        super().reset(seed=seed)
        if options:
            raise ValueError(f"reset options {sorted(options)} are not supported by the "
                             "native vector env")
        self.states = self.plant._sample_initial_state(self.np_random, self.num_envs)
        self.steps[:] = 0
        self.prev_done[:] = False
        obs = self.plant._measure(self.states, None, self.np_random)
        return obs, self._info({"state": self.states.copy()})

    def step(self, actions: ArrayLike
             ) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray, dict[str, Any]]:
        A = self._check_actions(actions)
        x = self.states
        x_next, extra = self.plant._transition(x, A, self.steps, self.np_random)
        reward = np.broadcast_to(np.asarray(self.plant._reward(x, A, x_next), dtype=np.float64),
                                 (self.num_envs,)).copy()
        terminated = ~np.asarray(self.plant._in_domain(x_next), dtype=bool)
        self.steps += 1
        truncated = (self.steps >= self.max_episode_steps if self.max_episode_steps
                     else np.zeros(self.num_envs, dtype=bool))
        finite = np.all(np.isfinite(x_next), axis=1)
        safe = np.where(finite[:, None], x_next, x)            # never measure a non-finite state
        obs = self.plant._measure(safe, extra, self.np_random)

        done = self.prev_done
        if np.any(done):                                        # next-step autoreset
            fresh = self.plant._sample_initial_state(self.np_random, int(done.sum()))
            x_next[done] = fresh
            obs[done] = self.plant._measure(fresh, None, self.np_random)
            self.steps[done] = 0
            reward[done] = 0.0
            terminated[done] = False
            truncated[done] = False
        self.states = x_next
        self.prev_done = terminated | truncated
        info = {"state": x_next.copy(), "action": A}
        info.update({key: np.broadcast_to(np.asarray(v), (self.num_envs,)).copy()
                     for key, v in extra.items()})
        return obs, reward, terminated, truncated, self._info(info)

    def render(self) -> tuple[NDArray[np.uint8], ...] | None:
        """One ``rgb_array`` frame per sub-environment (the plant's drawing of its state)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass "
                            "render_mode='rgb_array' to gym.make_vec")
            return None
        plant = self.plant
        kept = plant.state, plant.time_step, plant._last_extra
        frames: list[NDArray[np.uint8]] = []
        views = []
        try:
            for i in range(self.num_envs):
                plant.state, plant.time_step, plant._last_extra = self.states[i], \
                    int(self.steps[i]), {}
                frame = plant.render()
                assert frame is not None                # the plant has render_mode rgb_array
                frames.append(frame)
                views.append(plant.frame_view)
        finally:
            plant.state, plant.time_step, plant._last_extra = kept
        self._frame_views = tuple(views)
        return tuple(frames)

    @property
    def frame_views(self) -> tuple[Any, ...]:
        """The view of each frame the last :meth:`render` returned (see
        :class:`fir_gym.envs._overlay.FrameView`)."""
        return self._frame_views

    def _check_actions(self, actions: ArrayLike) -> FloatArray:
        shape = self.action_space.shape
        A = np.asarray(actions, dtype=np.float64)
        if A.shape != shape:
            raise ValueError(f"actions must have shape {shape}; got shape {A.shape}")
        if not np.all(np.isfinite(A)):
            raise ValueError("actions must be finite")
        return np.clip(A, -1.0, 1.0)

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        mask = np.ones(self.num_envs, dtype=bool)
        out: dict[str, Any] = {}
        for key, value in info.items():
            out[key] = value
            out["_" + key] = mask
        return out
