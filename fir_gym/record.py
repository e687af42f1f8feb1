"""Datasets of episodes: ``fir-gym record`` writes a Minari dataset.

:func:`record` plays ``episodes`` episodes of a plant with an estimator in the loop, driven
by a policy, and writes them as a `Minari <https://minari.farama.org>`_ dataset — the
Farama standard for offline-RL data — that ``minari.load_dataset(dataset_id)`` reads
back. The policies are those of ``fir-gym watch`` (:mod:`fir_gym.video`):

* ``"zero"`` — no action (the plant's free motion);
* ``"lqg"`` — :class:`fir_gym.controllers.LQGController` on the estimate;
* a run folder of ``fir-gym train`` — the trained controller, its observations
  normalised with the run's statistics (a run that observes the true state or the raw
  measurement is recorded with ``estimator`` running beside it,
  :class:`~fir_gym.wrappers.ShadowEstimator`).

Each episode's ``observations`` are what the controller saw; its ``infos`` hold, for the
reset and every step, fixed-shape arrays (Minari needs the same structure at every step;
:func:`step_info`): ``state``, ``measurement``, ``estimate``, ``covariance`` (only for
an estimator that has one), ``estimator_diverged``, ``simulation_failed``,
``estimator_info`` (the filter's numeric diagnostics) and, where a condition is active,
``conditions``. Episode ``i`` is reset with seed ``seed + i``, so recording twice gives
the same arrays.

Why not :func:`fir_gym.video._env_and_policy`: it builds the env with
``render_mode="rgb_array"`` (the video draws frames) and does not expose the measurement
the estimator was fed. :func:`build_env_and_policy` mirrors it without rendering, with
:class:`MeasurementInInfo` between the plant and the estimator, and reuses its trained
policy loader (:mod:`fir_gym.episode_policy`) as it is.

Minari, and h5py for its default HDF5 storage, come with the ``dataset`` extra:
``pip install ".[dataset]"``.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from ._extras import INSTALL, MissingExtra, install_hint
from .episode_policy import POLICIES, Policy, classical_policy, run_config, trained_policy

#: the namespace of the datasets :func:`record` names itself
NAMESPACE = "fir_gym"
EXTRA = INSTALL["dataset"]


@dataclass(frozen=True)
class Dataset:
    """What :func:`record` wrote: the dataset's id and folder, its episodes and steps."""

    dataset_id: str
    path: Path
    episodes: int
    steps: int


class MeasurementInInfo(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Copy the plant's observation — the measurement an estimator wrapped around this
    wrapper is fed — into ``info["measurement"]`` (float64) at ``reset`` and every step.

    It records its (empty) constructor arguments, so an env's spec with it in
    ``additional_wrappers`` rebuilds it (``minari``'s ``recover_environment``).
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        y, info = self.env.reset(seed=seed, options=options)
        return y, {**info, "measurement": np.array(y, dtype=np.float64)}

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        y, reward, terminated, truncated, info = self.env.step(action)
        return y, reward, terminated, truncated, {**info,
                                                  "measurement": np.array(y, dtype=np.float64)}


def record(
    env_id: str | None,
    out: str | Path,
    *,
    estimator: str | None,
    policy: str | Path = "zero",
    episodes: int = 10,
    seed: int = 0,
    steps: int | None = None,
    estimator_kwargs: Mapping[str, Any] | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    dataset_id: str | None = None,
) -> Dataset:
    """Record ``episodes`` episodes of ``env_id`` as a Minari dataset under ``out``.

    Args:
        env_id: the environment id (``None`` with a run folder: the run's).
        out: the datasets' root folder (Minari's ``MINARI_DATASETS_PATH``); the dataset
            is written to ``out/<dataset_id>/data``.
        estimator: the estimator in the loop (a registry name); with a run that observes
            an estimator, ``None`` or that estimator.
        policy: ``"zero"``, ``"lqg"`` or a run folder of ``fir-gym train``.
        episodes: how many episodes; episode ``i`` is reset with seed ``seed + i``.
        seed: the first episode's seed.
        steps: at most this many steps per episode (default: the episode's length); an
            episode cut short is marked truncated.
        estimator_kwargs, env_kwargs: options of the estimator and of ``gym.make``.
        dataset_id: Minari's ``namespace/name-vN`` (default
            ``fir_gym/<plant>-<estimator>-<policy>-v0``).

    Returns:
        A :class:`Dataset`. Raises ``ValueError`` naming the argument for bad input
        (also when the dataset already exists) and :class:`MissingExtra` when the
        ``dataset`` extra is missing.
    """
    for name, value in (("episodes", episodes), ("steps", steps)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or value < 1):
            raise ValueError(f"{name} must be a positive integer; got {value!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer; got {seed!r}")
    minari = _minari()                                   # a missing extra fails first
    from minari.data_collector import EpisodeBuffer

    env, act, meta = build_env_and_policy(env_id, estimator, policy,
                                          dict(estimator_kwargs or {}), dict(env_kwargs or {}))
    dataset_id = dataset_id or default_dataset_id(meta["env_id"], meta["estimator"], policy)
    _check_dataset_id(dataset_id)
    root = Path(out)
    if (root / dataset_id).exists():
        raise ValueError(f"out already holds a dataset {dataset_id!r} ({root / dataset_id}); "
                         "give another dataset_id or out")
    buffers = []
    total = 0
    try:
        estimator_obj = env.get_wrapper_attr("estimator")
        for i in range(episodes):
            episode = play_episode(env, act, estimator_obj, seed + i, steps)
            total += len(episode["rewards"])
            buffers.append(EpisodeBuffer(id=i, seed=seed + i, **episode))
        description = (f"{episodes} episode(s) of {meta['env_id']} with the {meta['estimator']} "
                       f"estimator in the loop, policy {meta['policy']}, seeds {seed}.."
                       f"{seed + episodes - 1}; infos: state, measurement, estimate"
                       + (", covariance" if estimator_obj.provides_covariance else
                          " (no covariance: the estimator has none)")
                       + ", estimator_diverged, conditions (fir-gym record)")
        with _datasets_path(root), warnings.catch_warnings():
            # Minari warns about every optional field left empty (author, e-mail, ...)
            warnings.simplefilter("ignore", UserWarning)
            dataset = minari.create_dataset_from_buffers(
                dataset_id, buffers, env=env, algorithm_name=f"fir-gym {meta['policy']}",
                description=description, requirements=[f"fir-gym=={_fir_gym_version()}"])
            dataset.storage.update_metadata({"fir_gym": {
                **meta, "fir_gym_version": _fir_gym_version(), "code_version": _code_version(),
                "seeds": list(range(seed, seed + episodes)), "steps": steps,
                "covariance": bool(estimator_obj.provides_covariance),
                "description": description}})
    finally:
        env.close()
    return Dataset(dataset_id, root / dataset_id, episodes, total)


# ---------------------------------------------------------------------- episodes
def play_episode(env: gym.Env, act: Policy, estimator: Any, seed: int, steps: int | None
                 ) -> dict[str, Any]:
    """One episode as Minari's episode buffer fields: ``observations`` (``T + 1``),
    ``actions``, ``rewards``, ``terminations``, ``truncations`` (``T``) and ``infos``
    (``T + 1``, :func:`step_info` stacked)."""
    obs, info = env.reset(seed=seed)
    shape = InfoShape.of(info)
    observations, infos = [obs], [step_info(info, estimator, shape)]
    actions: list[NDArray[Any]] = []
    rewards: list[float] = []
    terminations: list[bool] = []
    truncations: list[bool] = []
    dtype = getattr(env.action_space, "dtype", None)
    while True:
        action = np.asarray(act(obs), dtype=dtype)
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        infos.append(step_info(info, estimator, shape))
        actions.append(action)
        rewards.append(float(reward))
        cut = steps is not None and len(rewards) >= steps
        terminations.append(bool(terminated))
        truncations.append(bool(truncated) or (cut and not terminated))
        if terminations[-1] or truncations[-1]:
            break
    return {"observations": _stack(observations), "actions": np.stack(actions),
            "rewards": rewards, "terminations": terminations, "truncations": truncations,
            "infos": _stack(infos)}


@dataclass(frozen=True)
class InfoShape:
    """The optional parts of an episode's infos, fixed at ``reset`` so that every step has
    the same keys (a condition's entries are there at reset and every step, or never)."""

    estimator_info: tuple[str, ...]
    conditions: tuple[str, ...]

    @classmethod
    def of(cls, info: Mapping[str, Any]) -> InfoShape:
        numeric = tuple(key for key, value in dict(info.get("estimator_info") or {}).items()
                        if isinstance(value, (int, float, np.number)) and
                        not isinstance(value, (bool, np.bool_)))
        return cls(numeric, tuple(key for key in CONDITION_KEYS if key in info))


#: the condition entries a plant or a faulty sensor puts in ``info`` (only when active)
CONDITION_KEYS = ("measurement_missing", "sensor_faults", "clean_measurement", "true_params",
                  "burst")


def step_info(info: Mapping[str, Any], estimator: Any, shape: InfoShape) -> dict[str, Any]:
    """One step's ``info`` as fixed-shape numpy values (what the dataset stores).

    ``state``, ``measurement``, ``estimate`` (float64 vectors); ``covariance`` (the
    estimator's ``P``, ``n × n``; left out for an estimator without covariance);
    ``estimator_diverged`` and ``simulation_failed`` (bool); ``estimator_info`` (the
    filter's numeric diagnostics present at reset, NaN when a step lacks one) and
    ``conditions`` (the active conditions' entries: ``measurement_missing`` bool,
    ``sensor_faults`` a bool per fault, ``clean_measurement``, ``true_params`` a float per
    parameter, ``burst`` the step's δ).
    """
    out: dict[str, Any] = {
        "state": np.array(info["state"], dtype=np.float64),
        "measurement": np.array(info["measurement"], dtype=np.float64),
        "estimate": np.array(info["estimate"], dtype=np.float64),
        "estimator_diverged": np.bool_(info.get("estimator_diverged", False)),
        "simulation_failed": np.bool_(info.get("simulation_failure") is not None),
    }
    if estimator.provides_covariance:
        out["covariance"] = np.array(estimator.P, dtype=np.float64)
    if shape.estimator_info:
        details = dict(info.get("estimator_info") or {})
        out["estimator_info"] = {key: np.float64(details.get(key, np.nan))
                                 for key in shape.estimator_info}
    if shape.conditions:
        conditions: dict[str, Any] = {}
        for key in shape.conditions:
            value = info[key]
            if isinstance(value, Mapping):
                conditions[key] = {name: (np.bool_(v) if isinstance(v, (bool, np.bool_))
                                          else np.float64(v)) for name, v in value.items()}
            elif isinstance(value, (bool, np.bool_)):
                conditions[key] = np.bool_(value)
            else:
                conditions[key] = np.array(value, dtype=np.float64)
        out["conditions"] = conditions
    return out


def _stack(items: list[Any]) -> Any:
    """A list of (nested dicts of) arrays as (nested dicts of) arrays with a leading time
    axis."""
    if isinstance(items[0], Mapping):
        return {key: _stack([item[key] for item in items]) for key in items[0]}
    return np.stack([np.asarray(item) for item in items])


# ---------------------------------------------------------------------- env and policy
def build_env_and_policy(env_id: str | None, estimator: str | None, policy: str | Path,
                         estimator_kwargs: dict[str, Any], env_kwargs: dict[str, Any]
                         ) -> tuple[gym.Env, Policy, dict[str, Any]]:
    """The env to record (no rendering; the measurement in ``info``), the policy and what
    the dataset's metadata says of them (``env_id``, ``env_kwargs``, ``estimator``,
    ``estimator_kwargs``, ``policy``, ``observation``).

    It mirrors :func:`fir_gym.video._env_and_policy` (the same policies and the same
    checks) without ``render_mode``; see the module docstring.
    """
    from .wrappers import wrap_observation
    from .wrappers.sensor_faults import with_known_delay

    if str(policy) not in POLICIES:
        return _run_env_and_policy(Path(policy), env_id, estimator, estimator_kwargs,
                                   env_kwargs)
    if env_id is None:
        raise ValueError("env is needed unless the policy is a run folder")
    if estimator is None:
        raise ValueError("estimator is needed: the dataset records its estimate")
    kwargs = dict(env_kwargs)
    observation = kwargs.pop("observation", "estimate")
    plant = MeasurementInInfo(gym.make(env_id, **kwargs))
    env = wrap_observation(plant, estimator, observation=observation,
                           **with_known_delay(estimator, estimator_kwargs,
                                              kwargs.get("sensor_faults")))
    meta = {"env_id": env_id, "env_kwargs": env_kwargs, "estimator": estimator,
            "estimator_kwargs": estimator_kwargs, "policy": str(policy),
            "observation": observation}
    return env, classical_policy(env, str(policy)), meta


def _run_env_and_policy(run: Path, env_id: str | None, estimator: str | None,
                        estimator_kwargs: dict[str, Any], env_kwargs: dict[str, Any]
                        ) -> tuple[gym.Env, Policy, dict[str, Any]]:
    """A trained run's controller on the env it was trained on, the measurement in
    ``info`` (:func:`fir_gym.video._run_env_and_policy` without rendering)."""
    from .training.kinds import recipe
    from .wrappers import ShadowEstimator, wrap_observation
    from .wrappers.sensor_faults import with_known_delay

    config = run_config(run, env_id)
    kind = config.observation_kind
    kwargs = {**config.env_kwargs, **env_kwargs}
    made = recipe(kind, config.kind_kwargs, config.observation)
    steps = kwargs.get("max_episode_steps")
    plant = gym.make(config.env_id, **kwargs)
    if steps is not None and steps != -1:   # as training.vec_env.make_single_env does
        plant.unwrapped.max_episode_steps = int(steps)    # type: ignore[attr-defined]
    measured = MeasurementInInfo(plant)
    if made.estimator is not None:
        if estimator is not None and estimator != made.estimator:
            raise ValueError(f"estimator is {estimator!r} but the run's controller observes "
                             f"{made.estimator!r}: leave estimator out (or give "
                             f"{made.estimator!r})")
        if estimator_kwargs:
            raise ValueError("estimator_kwargs cannot change the estimator the run was "
                             "trained with")
        estimator, estimator_kwargs = made.estimator, dict(made.estimator_kwargs)
        env = wrap_observation(measured, made.estimator, observation=made.observation,
                               **with_known_delay(made.estimator, estimator_kwargs,
                                                  kwargs.get("sensor_faults")))
    elif made.observation in ("true", "measurement") and kind != "recurrent":
        if estimator is None:
            raise ValueError(f"estimator is needed: the run's controller observes {kind!r}; "
                             "the dataset records an estimator running beside it")
        env = wrap_observation(ShadowEstimator(measured, estimator, **estimator_kwargs),
                               made.observation)
    else:
        raise ValueError(f"policy: record does not play runs of kind {kind!r} (their "
                         "controller keeps a memory or a measurement stack); use a run that "
                         "observes an estimate, the true state or the measurement")
    meta = {"env_id": config.env_id, "env_kwargs": kwargs, "estimator": estimator,
            "estimator_kwargs": estimator_kwargs, "policy": str(run),
            "observation": made.observation, "run_kind": kind, "run_algo": config.algo}
    return env, trained_policy(run, config.algo_name, env), meta


# ---------------------------------------------------------------------- Minari
def default_dataset_id(env_id: str, estimator: str | None, policy: str | Path) -> str:
    """``fir_gym/<plant>-<estimator>-<policy>-v0`` (a run folder: ``run-<its name>``),
    lower case, anything but letters, digits, ``-`` and ``_`` made ``_``."""
    plant = env_id.split("/")[-1]
    plant = re.sub(r"-v\d+$", "", plant)
    name = f"run-{Path(policy).name}" if str(policy) not in POLICIES else str(policy)
    parts = [plant, str(estimator), name]
    return f"{NAMESPACE}/" + "-".join(re.sub(r"[^\w-]", "_", p.lower()) for p in parts) + "-v0"


def _check_dataset_id(dataset_id: str) -> None:
    from minari.dataset.minari_dataset import DATASET_ID_RE

    if not isinstance(dataset_id, str) or not DATASET_ID_RE.fullmatch(dataset_id) \
            or "-v" not in dataset_id:
        raise ValueError("dataset_id must be Minari's (namespace/)name-vN, e.g. "
                         f"'fir_gym/orbit-ekf-zero-v0'; got {dataset_id!r}")


@contextmanager
def _datasets_path(root: Path) -> Iterator[None]:
    """Minari's ``MINARI_DATASETS_PATH`` set to ``root`` inside the block (Minari reads the
    variable where it writes a dataset and has no argument for it), restored after."""
    before = os.environ.get("MINARI_DATASETS_PATH")
    root.mkdir(parents=True, exist_ok=True)
    os.environ["MINARI_DATASETS_PATH"] = str(root.resolve())
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = before


def _minari() -> Any:
    """The ``minari`` module with its HDF5 storage, else :class:`MissingExtra`."""
    try:
        import h5py  # noqa: F401  (Minari's default storage)
        import minari
    except ModuleNotFoundError as err:
        hint = install_hint(err.name) or f"{err.name} is missing (the dataset extra): {EXTRA}"
        raise MissingExtra(hint) from None
    return minari


def _fir_gym_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fir-gym")
    except PackageNotFoundError:
        return "unknown"


def _code_version() -> str:
    from .code_version import code_version

    return code_version()
