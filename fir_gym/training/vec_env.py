"""stable-baselines3 at vector speed: a ``VecEnv`` driven by the native batched plant.

``PPO("MlpPolicy", gym.make_vec(...))`` fails: stable-baselines3 has its own
``VecEnv`` API. :func:`make_sb3_vec_env` builds one for a fir-gym id:

* where the plant has a native vector env (every plant; PendulumSlider-v0's integrates
  the equations MuJoCo simulates; a plant registered with :func:`fir_gym.register_plant`)
  it is
  :class:`SB3VecEnv` over that env in same-step autoreset mode, with one batched
  estimator (:class:`~fir_gym.wrappers.VectorEstimatorObservation`) or one batched
  measurement window (:class:`~fir_gym.wrappers.VectorMeasurementStack`) on top;
* otherwise (``vec_env="dummy"``, e.g. for PendulumSlider-v0's ``friction="coulomb"``,
  which its native env refuses) it is SB3's ``DummyVecEnv`` (or ``SubprocVecEnv``,
  ``vec_env="subproc"``) over single envs built the same way.

The semantics are SB3's exactly (those of ``DummyVecEnv``): ``step`` returns
``(obs, rewards, dones, infos)``; a finished sub-env is reset in the same step, its
last observation in ``infos[i]["terminal_observation"]``; every ``infos[i]`` has
``"TimeLimit.truncated"`` (truncated and not terminated); ``seed(s)`` makes the next
``reset`` seed sub-env ``i`` with ``s + i``; ``reset_infos`` holds the reset infos.
With ``generators="per_env"`` each sub-env draws from its own generator as a single
env does, so the transitions are *the same numbers* as a ``DummyVecEnv`` over
``gym.make`` envs with the same seeds (the tests check it); the default
``"shared"`` draws every sub-env's noise from one generator (same distributions,
fewer generator calls: the fast path).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, cast

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv

from fir_gym.estimators._validation import one_of
from fir_gym.wrappers import (
    MeasurementStack,
    VectorEstimatorObservation,
    VectorSensorFaults,
    VectorTrueStateObservation,
    wrap_observation,
)
from fir_gym.wrappers.measurement_stack import VectorMeasurementStack
from fir_gym.wrappers.sensor_faults import with_known_delay

#: what a controller may observe without an estimator
PLAIN_OBSERVATIONS = ("measurement", "true", "measurement-stack")
VEC_ENVS = ("auto", "native", "dummy", "subproc")

_SKIP = frozenset({"final_obs", "final_info"})


class SB3VecEnv(VecEnv):
    """A stable-baselines3 ``VecEnv`` over a Gymnasium vector env in same-step autoreset.

    Args:
        venv: a Gymnasium ``VectorEnv`` with ``autoreset_mode=SAME_STEP`` (fir-gym's
            native vector env, possibly wrapped), whose ``info`` arrays carry
            Gymnasium's ``_key`` masks.
        observed: what the controller sees (``"estimate"``, ``"true"``, ``"measurement"``);
            the classical controllers read it.
        plant: the plant behind ``venv`` (``get_attr`` answers from it).

    ``get_attr``/``set_attr``/``env_method`` address the one plant every sub-env
    shares (its parameters, ``model``, ``unwrapped``): the answer is the same for every
    index, and ``set_attr`` changes every sub-env.
    """

    def __init__(self, venv: VectorEnv, observed: str, plant: Any) -> None:
        if venv.metadata.get("autoreset_mode") != AutoresetMode.SAME_STEP:
            raise ValueError("SB3VecEnv needs a vector env in same-step autoreset mode")
        self.venv, self.observed, self.plant = venv, observed, plant
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None

    # ------------------------------------------------------------------ SB3 API
    def reset(self) -> Any:
        seeds = self._seeds
        seed: Any = None
        if any(s is not None for s in seeds):
            seed = seeds if getattr(self.venv.unwrapped, "generators", "") == "per_env" \
                else seeds[0]
        options = self._options[0] if any(self._options) else None
        obs, info = self.venv.reset(seed=seed, options=options or None)
        self.reset_infos = _rows(info, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        dones = terminated | truncated
        if dones.any():
            ended = info["_final_obs"]
            infos = _rows(info, self.num_envs, final=ended)
            self.reset_infos = _rows(info, self.num_envs)
            final = info["final_obs"]
            for i in np.flatnonzero(ended):
                infos[i]["terminal_observation"] = _row(final, int(i))
            for row, timeout in zip(infos, (truncated & ~terminated).tolist(), strict=True):
                row["TimeLimit.truncated"] = timeout
        else:
            infos = _rows(info, self.num_envs)
            for row in infos:
                row["TimeLimit.truncated"] = False
        return obs, reward.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        value = self.plant if attr_name == "unwrapped" else getattr(self.plant, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.plant, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        method = getattr(self.plant, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: Any = None
                       ) -> list[bool]:
        return [False for _ in self._get_indices(indices)]


def _row(value: Any, i: int) -> Any:
    if isinstance(value, dict):
        return {k: _row(v, i) for k, v in value.items()}
    return value[i]


def _rows(info: dict[str, Any], n: int, final: np.ndarray | None = None
          ) -> list[dict[str, Any]]:
    """Gymnasium's vector ``info`` (arrays with ``_key`` masks) as ``n`` per-env dicts.

    With ``final``, the sub-envs it marks get their ``final_info`` (the last step's
    info) instead of the reset info, as ``DummyVecEnv`` reports them.
    """
    rows = _columns_to_rows(info, n)
    if final is not None:
        ended = _columns_to_rows(info.get("final_info", {}), n)
        for i in np.flatnonzero(final):
            rows[i] = ended[i]
    return rows


def _columns_to_rows(info: dict[str, Any], n: int) -> list[dict[str, Any]]:
    keys: list[str] = []
    columns: list[list[Any]] = []
    partial: list[tuple[str, list[Any], np.ndarray]] = []
    full: Any = None                                 # the all-true mask last seen
    for key, value in info.items():
        if key[0] == "_" or key in _SKIP:
            continue
        if isinstance(value, np.ndarray):
            column = value.tolist() if value.ndim == 1 else list(value)
        else:
            column = [_row(value, i) for i in range(n)]
        mask = info.get("_" + key)
        if mask is None or mask is full or mask.all():
            full = mask if mask is not None else full
            keys.append(key)
            columns.append(column)
        else:
            partial.append((key, column, mask))
    # (all columns have n entries: zip without strict's per-item check, on the hot path)
    rows = [dict(zip(keys, values)) for values in zip(*columns)] if columns else \
        [{} for _ in range(n)]  # noqa: B905
    for key, column, mask in partial:
        for i in np.flatnonzero(mask):
            rows[i][key] = column[i]
    return rows


def make_sb3_vec_env(
    env_id: str,
    num_envs: int,
    *,
    estimator: str | None = None,
    estimator_kwargs: dict[str, Any] | None = None,
    observation: str = "estimate",
    seed: int | None = None,
    vec_env: str = "auto",
    generators: str = "shared",
    stack_horizon: int | None = None,
    **env_kwargs: Any,
) -> VecEnv:
    """A stable-baselines3 ``VecEnv`` of ``num_envs`` copies of ``env_id`` (module docstring).

    Args:
        env_id: a fir-gym id (``"fir_gym/Orbit-v0"``).
        num_envs: the number of sub-envs.
        estimator: a registry name (``"ekf"``, ``"efir"``, ...): the controller sees its
            estimate; ``None``: no estimator.
        estimator_kwargs: the estimator's options (``{"horizon": 50}``).
        observation: with an estimator, ``"estimate"``, ``"estimate+covariance"`` or
            ``"estimate+measurement"``; without one, ``"measurement"`` (the default
            ``"estimate"`` means the same: there is no estimate), ``"true"`` (the true
            state) or ``"measurement-stack"`` (the last ``stack_horizon`` measurements and
            actions; default the plant's ``default_horizon``).
        seed: seed the first ``reset`` (sub-env ``i`` gets ``seed + i``) and the action
            spaces, as SB3's ``make_vec_env`` does.
        vec_env: ``"auto"`` (native where the plant has a vector env, else
            ``DummyVecEnv``), ``"native"``, ``"dummy"`` or ``"subproc"``.
        generators: ``"shared"`` or ``"per_env"`` (native only; see the module docstring).
        stack_horizon: the window of ``observation="measurement-stack"``.
        **env_kwargs: the plant's options (the plant conditions ``randomize`` and ``burst``
            among them), ``max_episode_steps`` (the time limit, given to both the plant and
            its truncation) and ``sensor_faults`` (the keywords of
            :class:`~fir_gym.wrappers.SensorFaults`: a faulty sensor on every sub-env,
            between the plant and the estimator; its ``delay`` is told to the estimator
            unless ``estimator_kwargs`` sets one).
    """
    one_of("vec_env", vec_env, VEC_ENVS)
    n = int(num_envs) if not isinstance(num_envs, bool) and isinstance(
        num_envs, (int, np.integer)) else 0
    if n <= 0:
        raise ValueError(f"num_envs must be a positive integer; got {num_envs!r}")
    if estimator is None:
        if estimator_kwargs:
            raise ValueError("estimator_kwargs given without an estimator")
        observation = "measurement" if observation == "estimate" else observation
        one_of("observation", observation, PLAIN_OBSERVATIONS)
    if stack_horizon is not None and observation != "measurement-stack":
        raise ValueError("stack_horizon is an option of observation='measurement-stack'")
    estimator_kwargs = with_known_delay(estimator, estimator_kwargs,
                                        env_kwargs.get("sensor_faults"))
    native = _has_native(env_id)
    if vec_env == "native" and not native:
        raise ValueError(f"{env_id} has no native vector env; use vec_env='dummy' or 'subproc'")
    if vec_env in ("auto", "native") and native:
        venv: VecEnv = _native(env_id, n, estimator, dict(estimator_kwargs or {}), observation,
                               generators, stack_horizon, env_kwargs)
    else:
        if generators != "shared":
            one_of("generators", generators, ("shared", "per_env"))
        factory = _single_factory(env_id, estimator, dict(estimator_kwargs or {}), observation,
                                  stack_horizon, env_kwargs)
        cls = SubprocVecEnv if vec_env == "subproc" else DummyVecEnv
        venv = cls([factory] * n)
    if not isinstance(venv, SB3VecEnv):
        venv.observed = _observed(estimator, observation)    # type: ignore[attr-defined]
    if seed is not None:
        venv.seed(int(seed))
        venv.action_space.seed(int(seed))
    return venv


def _has_native(env_id: str) -> bool:
    """Whether ``env_id`` has a plant's native vector env: a fir-gym id of
    :data:`fir_gym.VECTOR_ENV_IDS`, or a user's plant registered with
    :func:`fir_gym.register_plant` (its ``vector_entry_point`` is a plant's)."""
    from fir_gym import VECTOR_ENV_IDS
    from fir_gym.wrappers.factory import PlantVectorEntryPoint

    if env_id in VECTOR_ENV_IDS:
        return True
    spec = gym.registry.get(env_id)
    return spec is not None and isinstance(spec.vector_entry_point, PlantVectorEntryPoint)


def _observed(estimator: str | None, observation: str) -> str:
    """What a controller on this env sees (the classical controllers read it)."""
    if estimator is not None:
        return "estimate"
    return "true" if observation == "true" else "measurement"


def _native(env_id: str, n: int, estimator: str | None, estimator_kwargs: dict[str, Any],
            observation: str, generators: str, stack_horizon: int | None,
            env_kwargs: dict[str, Any]) -> SB3VecEnv:
    env_kwargs = dict(env_kwargs)
    faults = env_kwargs.pop("sensor_faults", None)
    base: VectorEnv = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point",
                                   vector_kwargs=None, autoreset_mode=AutoresetMode.SAME_STEP,
                                   generators=generators, **env_kwargs)
    plant = cast(Any, base.unwrapped).plant
    if faults:
        base = VectorSensorFaults(base, **dict(faults))
    venv: VectorEnv = base
    if estimator is not None:
        venv = VectorEstimatorObservation(base, estimator, observation=observation,
                                          **estimator_kwargs)
    elif observation == "true":
        venv = VectorTrueStateObservation(base)
    elif observation == "measurement-stack":
        venv = VectorMeasurementStack(base, stack_horizon)
    return SB3VecEnv(venv, _observed(estimator, observation), plant)


def _single_factory(env_id: str, estimator: str | None, estimator_kwargs: dict[str, Any],
                    observation: str, stack_horizon: int | None, env_kwargs: dict[str, Any]
                    ) -> Callable[[], gym.Env]:
    return _SingleEnv(env_id, estimator, estimator_kwargs, observation, stack_horizon,
                      env_kwargs)


class _SingleEnv:
    """A picklable factory of one wrapped env (``SubprocVecEnv`` pickles it)."""

    def __init__(self, env_id: str, estimator: str | None, estimator_kwargs: dict[str, Any],
                 observation: str, stack_horizon: int | None, env_kwargs: dict[str, Any]
                 ) -> None:
        self.env_id, self.estimator, self.estimator_kwargs = env_id, estimator, estimator_kwargs
        self.observation, self.stack_horizon = observation, stack_horizon
        self.env_kwargs = env_kwargs

    def __call__(self) -> gym.Env:
        return make_single_env(self.env_id, estimator=self.estimator,
                               estimator_kwargs=self.estimator_kwargs,
                               observation=self.observation, stack_horizon=self.stack_horizon,
                               **self.env_kwargs)


def make_single_env(env_id: str, *, estimator: str | None = None,
                    estimator_kwargs: dict[str, Any] | None = None,
                    observation: str = "estimate", stack_horizon: int | None = None,
                    **env_kwargs: Any) -> gym.Env:
    """One env as :func:`make_sb3_vec_env` builds each sub-env (``gym.make`` and a wrapper).

    ``max_episode_steps`` goes to Gymnasium's ``TimeLimit`` and to the plant (whose
    terminal penalty counts the steps left to it).
    """
    steps = env_kwargs.get("max_episode_steps")
    env = gym.make(env_id, **env_kwargs)
    # A fir-gym id's entry point has given the plant the limit already; this covers an id
    # registered otherwise. -1: no TimeLimit, and the plant keeps its own horizon.
    if steps is not None and steps != -1:
        cast(Any, env.unwrapped).max_episode_steps = int(steps)
    if estimator is not None:
        return wrap_observation(env, estimator, observation=observation,
                                **with_known_delay(estimator, estimator_kwargs,
                                                   env_kwargs.get("sensor_faults")))
    observation = "measurement" if observation == "estimate" else observation
    if observation == "measurement-stack":
        return MeasurementStack(env, stack_horizon)
    return wrap_observation(env, observation)
