"""Native vector environments: B copies of a plant stepped as one batch of numpy arrays.

:class:`PlantVectorEnv` runs ``num_envs`` systems of one plant in lock-step with the
plant's own (batched) hooks, so a step costs one call of the dynamics for the whole
batch instead of ``num_envs`` Python-level steps. It follows Gymnasium's
``CartPoleVectorEnv``: its own episode counters and truncation at
``max_episode_steps`` (``None`` or ``-1``, as for ``gym.make``: none, the plant keeping its
own penalty horizon), and *next-step* autoreset (``AutoresetMode.NEXT_STEP``): the
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
(:mod:`fir_gym.envs._base`: a terminating sub-environment is paid ``-cost_cap`` for
each step left to ``max_episode_steps``, which the vector env gives its plant). By
default (``generators="shared"``) the plant's noise is drawn from the vector env's own
generator, so a seed gives bit-identical rollouts (but not the same numbers as
``num_envs`` separate envs, whose generators differ). With ``generators="per_env"``
every sub-environment draws from its own generator, seeded ``seed + i`` on
``reset(seed=seed)`` as Gymnasium's and stable-baselines3's vector envs seed their
sub-envs, in the order a single env draws: the numbers are then those of
``num_envs`` separate envs (one generator call per sub-env and draw, so slower).

With ``render_mode="rgb_array"`` (``gym.make_vec(id, n, vectorization_mode=
"vector_entry_point", render_mode="rgb_array")``), ``render()`` returns one frame per
sub-environment, a tuple as Gymnasium's ``SyncVectorEnv`` does, and
:attr:`PlantVectorEnv.frame_views` the view of each (for drawing estimates over them).

The single plant's rules hold per sub-environment (:mod:`fir_gym.envs._base`):
actions must be real numbers (:mod:`fir_gym.envs._inputs`); ``reset(options={"state":
x0})`` takes one valid state ``(n_x,)`` for every sub-env or one per sub-env
``(B, n_x)``; a sub-env whose simulation fails terminates at its last valid state,
with its last observation and the terminal penalty, and
``info["simulation_failure"]`` (an object array, ``None`` elsewhere, with its
``_simulation_failure`` mask) says why; non-finite per-step extras of that sub-env
are masked out (0, with their ``_key`` mask off).

The plant's robustness conditions (:mod:`fir_gym.envs._conditions`) hold per
sub-environment: with ``randomize`` every sub-env draws its own true parameters when it
(re)starts an episode (the plant's :meth:`~fir_gym.envs._base.PlantEnv._apply_params`
then gets one value per sub-env), and ``burst`` follows each sub-env's own step count;
``info["true_params"]`` (a dict of ``(B,)`` arrays) and ``info["burst"]`` report them.
Their draws come from a condition generator of the vector env's own (one per sub-env
with ``generators="per_env"``, seeded as a single env seeded ``seed + i`` seeds its own).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils.seeding import np_random
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import ArrayLike, NDArray

from fir_gym.estimators._validation import one_of

from ._base import RESET_OPTIONS, PlantEnv, state_failure, valid_states
from ._conditions import burst_delta, condition_generator, draw_params
from ._inputs import real_array, reset_options
from ._streams import RowStreams

FloatArray = NDArray[np.float64]
GENERATORS = ("shared", "per_env")


class PlantVectorEnv(VectorEnv):
    """``num_envs`` copies of ``plant_class(**kwargs)`` stepped as one batch."""

    metadata = {"render_modes": ["rgb_array"],  # noqa: RUF012
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
        if max_episode_steps == -1:     # gym.make's "no TimeLimit" (make_vec passes it here)
            max_episode_steps = None
        if max_episode_steps is not None and max_episode_steps <= 0:
            raise ValueError(f"max_episode_steps must be positive, -1 or None (no truncation); "
                             f"got {max_episode_steps!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array' for a native vector env; "
                             f"got {render_mode!r}")
        modes = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)
        try:
            mode: AutoresetMode | None = AutoresetMode(autoreset_mode)
        except ValueError:
            mode = None
        if mode not in modes:
            raise ValueError(f"autoreset_mode must be one of {[m.value for m in modes]}; got "
                             f"{autoreset_mode!r}")
        one_of("generators", generators, GENERATORS)
        if max_episode_steps is not None:
            plant_kwargs["max_episode_steps"] = max_episode_steps   # the plant's penalty horizon
        self.plant = plant_class(render_mode=render_mode, **plant_kwargs)
        self.autoreset_mode = mode
        self.generators = generators
        #: ``per_env``: each sub-env's generator, served through buffered streams
        self._normals: RowStreams | None = None
        #: the condition draws' generator(s): one, or one per sub-env (``per_env``)
        self._condition_rngs: list[np.random.Generator] | None = None
        self.num_envs = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.render_mode = render_mode
        # the plant's frame rate (instance metadata, as Gymnasium's wrappers set theirs)
        self.metadata = {**type(self).metadata,
                         "render_fps": self.plant.metadata.get("render_fps", 30),
                         "autoreset_mode": mode}
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
        self._everyone = np.ones(self.num_envs, dtype=bool)      # read-only: never returned

    @property
    def model(self) -> Any:
        """The plant's model (the filter's belief), shared by every sub-environment."""
        return self.plant.model

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[FloatArray, dict[str, Any]]:
        given = reset_options(options, RESET_OPTIONS)
        states = self._check_states(given["state"]) if "state" in given else None
        if self.generators == "per_env":
            self._seed_generators(seed)
        else:
            if isinstance(seed, (list, tuple)):
                raise ValueError("a list of seeds needs generators='per_env' (one generator "
                                 "per sub-env); give one int seed")
            super().reset(seed=seed)
        everyone = self._everyone
        if self.plant.randomize:
            self._seed_conditions(seed)
            self.plant.true_params = {**self.plant.params, **draw_params(
                self._condition_rng(everyone), self.plant.nominal_params, self.plant.randomize,
                self.num_envs)}
            self.plant._apply_params(self.plant.true_params)
        self.states = self.plant._sample_initial_state(self._rng(everyone), self.num_envs) \
            if states is None else states
        self.steps[:] = 0
        self.prev_done[:] = False
        obs = self.plant._measure(self.states, None, self._rng(everyone))
        self._last_obs = obs.copy()
        info: dict[str, Any] = {"state": self.states.copy()}
        self._condition_info(info, np.zeros(self.num_envs) if self.plant.burst else None)
        return obs, self._info(info)

    def step(self, actions: ArrayLike
             ) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray, dict[str, Any]]:
        A, clipped = self._check_actions(actions)
        x, plant = self.states, self.plant
        done = self.prev_done                       # next-step mode: these reset now
        any_done = bool(done.any())
        live = ~done if any_done else self._everyone
        x_next, extra = plant._transition(x, A, self.steps, self._rng(live))
        delta: Any = None
        if plant.burst:
            delta = burst_delta(plant.burst, self.steps)
            if delta.any():
                x_next, extra = plant._perturb(x, x_next, extra, delta)
        limit = plant.state_limit
        # one reduction each way in the common case (NaN fails the comparisons)
        all_valid = bool(x_next.max() <= limit and x_next.min() >= -limit)
        valid = self._everyone if all_valid else valid_states(x_next, limit)
        # a failed sub-env stays at its state: never measure or reward an invalid one
        safe = x_next if all_valid else np.where(valid[:, None], x_next, x)
        reward = np.asarray(plant._reward(x, A, safe), dtype=np.float64)
        if reward.shape != (self.num_envs,):
            reward = np.broadcast_to(reward, (self.num_envs,)).copy()
        terminated = ~np.asarray(plant._in_domain(x_next), dtype=bool)
        steps = self.steps
        steps += 1
        if terminated.any():                        # paid for the steps left (honest tasks)
            reward[terminated] = plant._terminal_reward(steps[terminated])
        truncated = (steps >= self.max_episode_steps if self.max_episode_steps
                     else np.zeros(self.num_envs, dtype=bool))
        obs = plant._measure(safe, extra, self._rng(live if all_valid else live & valid))
        failure = None if all_valid and math.isfinite(reward.sum() + obs.sum()) else \
            self._failures(x_next, valid, reward, obs, done)
        masks: dict[str, np.ndarray] = {}
        if failure is not None:                                # end them at their last state
            failed = failure != None                           # noqa: E711 (object array)
            x_next = np.array(x_next)
            x_next[failed] = x[failed]
            obs[failed] = self._last_obs[failed]
            reward[failed] = plant._terminal_reward(steps[failed])
            terminated |= failed
            extra = dict(extra)
            for key, value in extra.items():
                arr = np.array(np.broadcast_to(np.asarray(value), (self.num_envs,)))
                if arr.dtype.kind in "fc":
                    masks[key] = np.isfinite(arr)
                    arr[~masks[key]] = 0.0
                extra[key] = arr
        if any_done:                                            # next-step autoreset
            self._restart(done, x_next, obs)
            reward[done] = 0.0
            terminated[done] = False
            truncated[done] = False
        info = {"state": x_next.copy(), "action": A, "action_clipped": clipped}
        for key, v in extra.items():
            info[key] = np.broadcast_to(np.asarray(v), (self.num_envs,)).copy()
        self._condition_info(info, delta)
        if failure is not None:
            info["simulation_failure"] = failure
            masks["simulation_failure"] = failure != None     # noqa: E711
        info = self._info(info, masks)
        ended = terminated | truncated
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            if ended.any():                                     # same-step autoreset
                final_obs = obs.copy()
                final_info = {key: value.copy() if isinstance(value, np.ndarray) else value
                              for key, value in info.items()}
                self._restart(ended, x_next, obs)
                info["state"] = x_next.copy()        # the reset info of the restarted ones
                self._condition_info(info, None if delta is None else
                                     np.where(ended, 0.0, delta))
                info["final_obs"], info["_final_obs"] = final_obs, ended
                info["final_info"], info["_final_info"] = final_info, ended
            self.prev_done = np.zeros(self.num_envs, dtype=bool)
        else:
            self.prev_done = ended
        self.states = x_next
        self._last_obs = obs.copy()
        return obs, reward, terminated, truncated, info

    def _restart(self, rows: np.ndarray, x_next: FloatArray, obs: FloatArray) -> None:
        """Start a new episode in ``rows``: fresh true parameters (with ``randomize``), a fresh
        initial state and its measurement."""
        plant = self.plant
        if plant.randomize:
            drawn = draw_params(self._condition_rng(rows), plant.nominal_params,
                                plant.randomize, int(rows.sum()))
            for name, values in drawn.items():
                column = np.array(plant.true_params[name], dtype=np.float64)
                column[rows] = values
                plant.true_params[name] = column
            plant._apply_params(plant.true_params)
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
        if self._normals is None:
            self._normals = RowStreams([np_random(s)[0] for s in seeds], "normal")
        else:
            for i, s in enumerate(seeds):
                if s is not None:
                    self._normals.replace(i, np_random(s)[0])

    def _seed_conditions(self, seed: int | list[int | None] | None) -> None:
        """(Re)seed the condition generator(s) as :meth:`reset` seeds the plant's: sub-env ``i``
        of a ``per_env`` vector env reset with seed ``s`` draws the parameters a single env
        reset with seed ``s + i`` draws."""
        n = self.num_envs
        if self.generators != "per_env":
            if seed is not None or self._condition_rngs is None:
                one = None if seed is None or isinstance(seed, (list, tuple)) else int(seed)
                self._condition_rngs = [condition_generator(one)]
            return
        seeds: list[int | None]
        if isinstance(seed, (list, tuple)):
            seeds = list(seed)
        else:
            seeds = [None if seed is None else int(seed) + i for i in range(n)]
        old = self._condition_rngs
        self._condition_rngs = [condition_generator(s) if s is not None or old is None
                                else old[i] for i, s in enumerate(seeds)]

    def _condition_rng(self, rows: np.ndarray) -> Any:
        """The condition generator for the systems ``rows`` (see :meth:`_rng`)."""
        rngs = self._condition_rngs
        if rngs is None:                                   # not yet seeded: fresh entropy
            self._seed_conditions(None)
            rngs = self._condition_rngs
        assert rngs is not None
        return rngs[0] if self.generators != "per_env" else RowGenerators(rngs, rows)

    def _condition_info(self, info: dict[str, Any], delta: Any) -> None:
        """Add ``true_params`` (copies: a restart changes them) and ``burst`` where set."""
        plant = self.plant
        if plant.randomize:
            info["true_params"] = {
                name: np.array(np.broadcast_to(plant.true_params[name], (self.num_envs,)),
                               dtype=np.float64) for name in plant.randomize}
        if plant.burst:
            info["burst"] = np.zeros(self.num_envs) if delta is None else \
                np.asarray(delta, dtype=np.float64).copy()

    def _rng(self, rows: np.ndarray) -> Any:
        """The generator the plant's hooks draw from for the systems ``rows`` (a mask)."""
        if self._normals is None:
            return self.np_random
        return RowNormals(self._normals, rows)

    def _failures(self, x_next: FloatArray, valid: np.ndarray, reward: FloatArray,
                  obs: FloatArray, done: np.ndarray) -> np.ndarray | None:
        """Per sub-env, why its step failed (an object array, ``None`` where it did not),
        or ``None`` when no step failed; sub-envs being autoreset do not count."""
        reward_ok, obs_ok = np.isfinite(reward), np.all(np.isfinite(obs), axis=1)
        ok = valid & reward_ok & obs_ok | done
        if ok.all():
            return None
        failure = np.full(self.num_envs, None, dtype=object)
        for i in np.flatnonzero(~ok):
            failure[i] = (state_failure(x_next[i], self.plant.state_limit) if not valid[i] else
                          "nonfinite_reward" if not reward_ok[i] else "nonfinite_observation")
        return failure

    def render(self) -> tuple[NDArray[np.uint8], ...] | None:
        """One ``rgb_array`` frame per sub-environment (the plant's drawing of its state)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass "
                            "render_mode='rgb_array' to gym.make_vec")
            return None
        plant = self.plant
        frames: list[NDArray[np.uint8]] = []
        views = []
        for i in range(self.num_envs):
            frame = plant.render_state(self.states[i], int(self.steps[i]))
            assert frame is not None                    # the plant has render_mode rgb_array
            frames.append(frame)
            views.append(plant.frame_view)
        self._frame_views = tuple(views)
        return tuple(frames)

    @property
    def frame_views(self) -> tuple[Any, ...]:
        """The view of each frame the last :meth:`render` returned (see
        :class:`fir_gym.envs._overlay.FrameView`)."""
        return self._frame_views

    def _check_actions(self, actions: ArrayLike) -> tuple[FloatArray, np.ndarray]:
        shape = self.action_space.shape
        A = actions if type(actions) is np.ndarray and actions.dtype.kind == "f" else \
            real_array("actions", actions, lambda: f"real numbers in [-1, 1] of shape {shape}")
        if A.shape != shape:
            raise ValueError(f"actions must have shape {shape}; got shape {A.shape}")
        if not np.all(np.isfinite(A)):
            raise ValueError("actions must be finite")
        clipped = np.clip(A, -1.0, 1.0).astype(np.float64, copy=False)
        return clipped, (clipped != A).any(axis=1)

    def _check_states(self, value: Any) -> FloatArray:
        """``reset``'s ``options['state']``: one state for all sub-envs, or one each."""
        n, names = self.num_envs, self.plant.state_names
        X = real_array("options['state']", value,
                       f"real numbers of shape ({len(names)},) or ({n}, {len(names)})")
        if X is value:                                     # the vector env keeps it
            X = X.copy()
        if X.shape == (len(names),):
            X = np.tile(X, (n, 1))
        elif X.shape != (n, len(names)):
            raise ValueError(f"options['state'] must have shape ({len(names)},) (one state "
                             f"{list(names)} for every sub-env) or ({n}, {len(names)}); got "
                             f"shape {X.shape}")
        for i, row in enumerate(X):
            self.plant._check_state(f"options['state'][{i}]", row)
        return X

    def _info(self, info: dict[str, Any], masks: dict[str, np.ndarray] | None = None
              ) -> dict[str, Any]:
        everyone = np.ones(self.num_envs, dtype=bool)
        masks = masks or {}
        out: dict[str, Any] = {}
        for key, value in info.items():
            out[key] = value
            out["_" + key] = masks.get(key, everyone)
        return out


class RowNormals:
    """Each system's own normal stream behind the ``standard_normal`` the plant hooks draw
    with (``generators="per_env"``).

    A hook draws a batch as ``rng.standard_normal((B,) + shape)`` (batch axis first) where
    one system draws ``standard_normal(shape)``. This stand-in serves row ``i`` the next
    numbers of the ``i``-th selected system's stream (:class:`~._streams.RowStreams`: its
    generator's numbers, in order), so each system's numbers are those of a single env with
    that generator. ``rows`` selects the systems drawing: a draw of ``B = len(rows)`` rows
    gives zeros (without consuming) to the unselected ones (a system restarting in this
    step); a draw of ``rows.sum()`` rows serves only the selected ones (their fresh initial
    states).
    """

    def __init__(self, streams: RowStreams, rows: np.ndarray) -> None:
        self.streams, self.rows = streams, rows

    def standard_normal(self, size: Any = None) -> FloatArray:
        size = (size,) if isinstance(size, (int, np.integer)) else tuple(size)
        n, shape = size[0], size[1:]
        k = int(np.prod(shape)) if shape else 1
        picked = int(self.rows.sum())
        if n == picked:
            return self.streams.draw(self.rows, k).reshape(size)
        total = len(self.streams.generators)
        if n != total:
            raise ValueError(f"a batched draw must have {total} or {picked} rows first; got "
                             f"size {size}")
        out = np.zeros(size)
        out[self.rows] = self.streams.draw(self.rows, k).reshape((picked, *shape))
        return out


class RowGenerators:
    """One ``uniform(low, high)`` draw per selected system from its own generator, as a
    single env draws it (a float): the condition draws of a ``per_env`` vector env, made
    once per (re)start, so no buffering is needed."""

    def __init__(self, generators: list[np.random.Generator], rows: np.ndarray) -> None:
        self.generators, self.rows = generators, rows

    def uniform(self, low: float = 0.0, high: float = 1.0, size: Any = None) -> FloatArray:
        """One draw per selected system, as an array of ``size`` rows: the selected ones
        (``rows.sum()``), or all of them with zeros for the unselected (which do not draw)."""
        n = int(size if isinstance(size, (int, np.integer)) else next(iter(size)))
        picked = [g for g, r in zip(self.generators, self.rows.tolist(), strict=True) if r]
        if n == len(picked):
            return np.array([g.uniform(low, high) for g in picked], dtype=np.float64)
        if n != len(self.generators):
            raise ValueError(f"a batched draw must have {len(self.generators)} or "
                             f"{len(picked)} rows; got size {size}")
        return np.array([g.uniform(low, high) if r else 0.0
                         for g, r in zip(self.generators, self.rows.tolist(), strict=True)])
