"""Native vector environments: B copies of a plant stepped as one batch of numpy arrays.

:class:`PlantVectorEnv` runs ``num_envs`` systems of one plant in lock-step with the
plant's own (batched) hooks, so a step costs one call of the dynamics for the whole
batch instead of ``num_envs`` Python-level steps. It follows Gymnasium's
``CartPoleVectorEnv``: its own episode counters and truncation at
``max_episode_steps``, and *next-step* autoreset (``AutoresetMode.NEXT_STEP``): the
step after a sub-environment terminates or is truncated resets it, ignores its
action, and returns the first measurement of the new episode with reward 0 and
``terminated = truncated = False``.

``autoreset_mode=AutoresetMode.SAME_STEP`` resets a finished sub-environment in the
step that finished it, as Gymnasium's ``SyncVectorEnv`` does in that mode: the
observation is the new episode's first one, ``info["final_obs"]`` and
``info["final_info"]`` (masked by ``info["_final_obs"]``) hold the last observation
and step info of the finished episode, and ``info`` itself holds the reset info for
those sub-environments (what stable-baselines3's ``VecEnv`` needs).

``info`` holds ``state`` (the true states, ``(B, n_x)``), ``action`` (the applied
actions after clipping), ``action_clipped`` and each plant's per-step extras, each
with Gymnasium's ``_key`` mask. Rewards and terminal penalties are the plant's
(:mod:`._base`: a terminating sub-environment is paid ``-cost_cap`` for each step left
to ``max_episode_steps``). By default (``generators="shared"``) the plant's noise is
drawn from the vector env's own generator, so a seed gives bit-identical rollouts
(but not the same numbers as ``num_envs`` separate envs, whose generators differ).
With ``generators="per_env"`` every sub-environment draws from its own generator,
seeded ``seed + i`` on ``reset(seed=seed)`` as Gymnasium's and stable-baselines3's
vector envs seed their sub-envs, in the order a single env draws: the numbers are
then those of ``num_envs`` separate envs (one generator call per sub-env and draw,
so slower).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from gymnasium.utils.seeding import np_random
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import ArrayLike, NDArray

from fir_gym.estimators._validation import one_of

from ._base import PlantEnv

FloatArray = NDArray[np.float64]
GENERATORS = ("shared", "per_env")


class PlantVectorEnv(VectorEnv):
    """``num_envs`` copies of ``plant_class(**kwargs)`` stepped as one batch."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [],
                                          "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        plant_class: type[PlantEnv],
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        generators: str = "shared",
        **plant_kwargs: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or num_envs <= 0:
            raise ValueError(f"num_envs must be a positive integer; got {num_envs!r}")
        if max_episode_steps is not None and max_episode_steps <= 0:
            raise ValueError(
                f"max_episode_steps must be positive or None; got {max_episode_steps!r}")
        if render_mode is not None:
            raise ValueError("the native vector envs do not render; use "
                             "gym.make_vec(..., vectorization_mode='sync') for frames")
        modes = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            mode = None
        if mode not in modes:
            raise ValueError(f"autoreset_mode must be one of {[m.value for m in modes]}; got "
                             f"{autoreset_mode!r}")
        one_of("generators", generators, GENERATORS)
        if max_episode_steps is not None:
            plant_kwargs["max_episode_steps"] = max_episode_steps   # the plant's penalty horizon
        self.plant = plant_class(**plant_kwargs)
        self.autoreset_mode = mode
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.generators = generators
        self._generators: list[np.random.Generator] | None = None
        self.num_envs = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.render_mode = None
        self.single_action_space = self.plant.action_space
        self.single_observation_space = self.plant.observation_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        n_x = len(self.plant.state_names)
        self.states = np.tile(self.plant.initial_state, (self.num_envs, 1))
        self.steps = np.zeros(self.num_envs, dtype=np.int64)
        self.prev_done = np.zeros(self.num_envs, dtype=bool)
        self._everyone = np.ones(self.num_envs, dtype=bool)
        self._last_obs = np.zeros((self.num_envs, len(self.plant.measurement_names)))
        self._n_x = n_x

    @property
    def model(self) -> Any:
        """The plant's model (the filter's belief), shared by every sub-environment."""
        return self.plant.model

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[FloatArray, dict[str, Any]]:
        if options:
            raise ValueError(f"reset options {sorted(options)} are not supported by the "
                             "native vector env")
        if self.generators == "per_env":
            self._seed_generators(seed)
        else:
            if isinstance(seed, (list, tuple)):
                raise ValueError("a list of seeds needs generators='per_env' (one generator "
                                 "per sub-env); give one int seed")
            super().reset(seed=seed)
        everyone = np.ones(self.num_envs, dtype=bool)
        self.states = self.plant._sample_initial_state(self._rng(everyone), self.num_envs)
        self.steps[:] = 0
        self.prev_done[:] = False
        obs = self.plant._measure(self.states, None, self._rng(everyone))
        self._last_obs = obs
        return obs, self._info({"state": self.states.copy()})

    def step(self, actions: ArrayLike
             ) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray, dict[str, Any]]:
        A, clipped = self._check_actions(actions)
        x, plant = self.states, self.plant
        done = self.prev_done                       # next-step mode: these reset now
        any_done = bool(done.any())
        live = ~done if any_done else self._everyone
        x_next, extra = plant._transition(x, A, self.steps, self._rng(live))
        with np.errstate(over="ignore", invalid="ignore"):   # rows outside the domain
            reward = np.asarray(plant._reward(x, A, x_next), dtype=np.float64)
        if reward.shape != (self.num_envs,):
            reward = np.broadcast_to(reward, (self.num_envs,)).copy()
        terminated = ~np.asarray(plant._in_domain(x_next), dtype=bool)
        steps = self.steps
        steps += 1
        if terminated.any():
            reward[terminated] = plant._terminal_reward(self.steps[terminated])
        truncated = (steps >= self.max_episode_steps if self.max_episode_steps
                     else np.zeros(self.num_envs, dtype=bool))
        if np.isfinite(x_next).all():
            obs = plant._measure(x_next, extra, self._rng(live))
        else:   # never measure a non-finite state (a single env repeats its last observation)
            finite = np.all(np.isfinite(x_next), axis=1)
            obs = plant._measure(np.where(finite[:, None], x_next, x), extra,
                                 self._rng(live & finite))
            obs[~finite] = self._last_obs[~finite]
        if any_done:                                # next-step autoreset
            self._restart(done, x_next, obs)
            reward[done] = 0.0
            terminated[done] = False
            truncated[done] = False
        info = {"state": x_next.copy(), "action": A, "action_clipped": clipped}
        for key, v in extra.items():
            info[key] = np.broadcast_to(np.asarray(v), (self.num_envs,)).copy()
        ended = terminated | truncated
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            info = self._info(info)
            if ended.any():                         # same-step autoreset
                final_obs = obs.copy()
                final_info = {key: value.copy() if isinstance(value, np.ndarray) else value
                              for key, value in info.items()}
                self._restart(ended, x_next, obs)
                info["state"] = x_next.copy()       # the reset info of the restarted ones
                info["final_obs"], info["_final_obs"] = final_obs, ended
                info["final_info"], info["_final_info"] = final_info, ended
            self.prev_done = np.zeros(self.num_envs, dtype=bool)
        else:
            self.prev_done = ended
            info = self._info(info)
        self.states = x_next
        self._last_obs = obs
        return obs, reward, terminated, truncated, info

    def _restart(self, rows: np.ndarray, x_next: FloatArray, obs: FloatArray) -> None:
        """Start a new episode in ``rows``: a fresh initial state and its measurement."""
        rng = self._rng(rows)
        fresh = self.plant._sample_initial_state(rng, int(rows.sum()))
        x_next[rows] = fresh
        obs[rows] = self.plant._measure(fresh, None, rng)
        self.steps[rows] = 0

    # ------------------------------------------------------------------ generators
    def _seed_generators(self, seed: int | list[int | None] | None) -> None:
        n = self.num_envs
        if isinstance(seed, (list, tuple)):
            if len(seed) != n:
                raise ValueError(f"seed must be an int, None or a list of {n} seeds; got "
                                 f"{len(seed)} seeds")
            seeds: list[int | None] = list(seed)
        elif seed is None:
            seeds = [None] * n
        else:
            seeds = [int(seed) + i for i in range(n)]
        if self._generators is None:
            self._generators = [np_random(s)[0] for s in seeds]
        else:
            self._generators = [g if s is None else np_random(s)[0]
                                for g, s in zip(self._generators, seeds, strict=True)]

    def _rng(self, rows: np.ndarray) -> Any:
        """The generator the plant's hooks draw from for the systems ``rows`` (a mask)."""
        if self._generators is None:
            return self.np_random
        return RowGenerators(self._generators, rows)

    def _check_actions(self, actions: ArrayLike) -> tuple[FloatArray, np.ndarray]:
        shape = self.action_space.shape
        A = np.asarray(actions, dtype=np.float64)
        if A.shape != shape:
            raise ValueError(f"actions must have shape {shape}; got shape {A.shape}")
        if not np.isfinite(A).all():
            raise ValueError("actions must be finite")
        clipped = A.clip(-1.0, 1.0)
        return clipped, (clipped != A).any(axis=1)

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        mask = np.ones(self.num_envs, dtype=bool)         # every sub-env has every key
        out: dict[str, Any] = {}
        for key, value in info.items():
            out[key] = value
            out["_" + key] = mask
        return out


class RowGenerators:
    """One generator per system, behind the ``standard_normal`` the plant hooks draw with.

    A hook draws a batch as ``rng.standard_normal((B,) + shape)`` (batch axis first) where
    one system draws ``standard_normal(shape)``. This stand-in draws row ``i`` from the
    ``i``-th selected generator with ``shape``, so each system's numbers are those of a
    single env with that generator. ``rows`` selects the systems drawing: a draw of
    ``B = len(rows)`` rows gives zeros (without consuming) to the unselected ones (a
    system restarting in this step); a draw of ``rows.sum()`` rows serves only the
    selected ones (their fresh initial states).
    """

    def __init__(self, generators: list[np.random.Generator], rows: np.ndarray) -> None:
        self.generators, self.rows = generators, rows

    def standard_normal(self, size: Any = None) -> FloatArray:
        size = (size,) if isinstance(size, (int, np.integer)) else tuple(size)
        n, shape = size[0], size[1:]
        picked = [g for g, r in zip(self.generators, self.rows.tolist(), strict=True) if r]
        if n == len(picked):
            return np.array([g.standard_normal(shape) for g in picked]).reshape(size)
        if n != len(self.generators):
            raise ValueError(f"a batched draw must have {len(self.generators)} or "
                             f"{len(picked)} rows first; got size {size}")
        out = np.zeros(size)
        for i, (g, r) in enumerate(zip(self.generators, self.rows.tolist(), strict=True)):
            if r:
                out[i] = g.standard_normal(shape)
        return out
