"""Sensor faults between a plant and what reads it: dropout, outliers, a stuck sensor, a
bias, a delay and a multi-rate sensor (docs/robustness.md#sensor-faults).

``SensorFaults(env, dropout=p, outliers=(p, scale), stuck=p, bias=(step, value), delay=d,
every=k)`` wraps a plant; :class:`VectorSensorFaults` does the same to every sub-env of a
native vector env. What the faults do, step by step, and the order of the random draws
are :mod:`.faulty_sensor`'s.

* A reading that is dropped, stuck (detected), not sampled or not yet due is **missing**:
  ``info["measurement_missing"]`` is True, and an estimator wrapped around this wrapper
  (:class:`~fir_gym.wrappers.EstimatorObservation`, ``VectorEstimatorObservation``) takes
  a prediction step, ``step(None)`` — the number is never fed to a filter. The
  observation itself is the last reading delivered (a zero-order hold: what a controller
  reading the sensor directly sees), never NaN.
* ``info["sensor_faults"]`` says every step which faults acted on what was delivered
  (``dropped``, ``stuck``, ``outlier``, ``biased``, ``unsampled``, ``late``), and
  ``info["clean_measurement"]`` is the plant's own measurement of the step.
* With ``delay=d`` the reading delivered at ``k`` is ``y[k − d]``: tell the estimator
  (``estimator_kwargs={"delay": d}``, which ``gym.make(id, sensor_faults=..., estimator=...)``
  does by default) so that it filters it as ``y[k − d]`` and predicts ahead.
* Random draws come from the sensor's own generators, seeded from ``reset(seed=...)``
  (:func:`.faulty_sensor.fault_generators`), never from the plant's: the plant's noise is
  the same with and without faults on the same seed. :class:`VectorSensorFaults` seeds
  sub-env ``i``'s sensor with ``seed + i`` (or the ``i``-th of a list of seeds), so sub-env
  ``i`` sees the faults of a single env reset with seed ``seed + i``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium.vector import VectorEnv
from numpy.typing import NDArray

from .faulty_sensor import FLAGS, FaultySensor, check_faults, flag_dict
from .vector_estimator_observation import same_step_mode

FloatArray = NDArray[np.float64]


def with_known_delay(estimator: Any, estimator_kwargs: Mapping[str, Any] | None,
                     sensor_faults: Mapping[str, Any] | None) -> dict[str, Any]:
    """The estimator's options with the sensor's ``delay`` told to it (a known delay), unless
    the options set one themselves or there is no estimator."""
    options = dict(estimator_kwargs or {})
    delay = int((sensor_faults or {}).get("delay", 0) or 0)
    if estimator is not None and delay and "delay" not in options:
        options["delay"] = delay
    return options


def _plant_of(env: Any) -> Any:
    """The fir-gym plant behind a single env or a native vector env."""
    base = env.unwrapped
    return getattr(base, "plant", base)


def _sensor_setup(plant: Any, n_y: int) -> tuple[FloatArray, FloatArray]:
    """The plant's measurement noise square root (the outliers' scale) and the reading held
    before the first one arrives, ``h(initial_state)`` of its model (zeros without one)."""
    cov = getattr(plant, "measurement_cov", None)
    sqrt = np.linalg.cholesky(np.asarray(cov, dtype=np.float64)) if cov is not None \
        else np.eye(n_y)
    model, x0 = getattr(plant, "model", None), getattr(plant, "initial_state", None)
    hold = np.zeros(n_y)
    if model is not None and x0 is not None:
        hold = np.asarray(model.h(np.asarray(x0, dtype=np.float64)),
                          dtype=np.float64).reshape(n_y)
    return sqrt, hold


def _episode_steps(env: Any, plant: Any) -> int | None:
    """The episode's length: the shorter of the plant's horizon and the env's time limit
    (``gym.make(id, max_episode_steps=N)`` gives ``N`` to the plant before it builds this
    wrapper; a ``TimeLimit`` put on by hand may be shorter than the plant's horizon)."""
    spec = getattr(env, "spec", None)
    known = [int(n) for n in (getattr(plant, "max_episode_steps", None),
                              getattr(spec, "max_episode_steps", None)) if n]
    return min(known) if known else None


class SensorFaults(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Faults of the sensor between a plant and its reader (module docstring).

    Args:
        env: a fir-gym plant (or a wrapper of one that still returns its measurement).
        dropout: probability that a reading is lost, in ``[0, 1]``.
        outliers: ``(probability, scale)``: an outlier adds ``scale`` standard deviations of
            the plant's measurement noise.
        stuck: probability that a working sensor freezes, or ``(probability, mean stuck
            steps)`` (default mean: 10 steps).
        bias: ``(step, value)``: from that step on ``value`` (a number, or one per channel)
            is added, undetected.
        delay: readings arrive ``delay`` steps late (an integer shorter than an episode).
        every: the sensor samples every ``every``-th step (1: every step).
    """

    def __init__(self, env: gym.Env, *, dropout: float = 0.0, outliers: Any = None,
                 stuck: Any = None, bias: Any = None, delay: int = 0, every: int = 1) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, dropout=dropout, outliers=outliers,
                                                 stuck=stuck, bias=bias, delay=delay,
                                                 every=every)
        gym.Wrapper.__init__(self, env)
        plant = _plant_of(env)
        self.n_y = int(np.prod(env.observation_space.shape or (1,)))
        self.spec_faults = check_faults(n_y=self.n_y, episode_steps=_episode_steps(env, plant),
                                        dropout=dropout, outliers=outliers, stuck=stuck,
                                        bias=bias, delay=delay, every=every)
        self.delay = self.spec_faults.delay
        sqrt, hold = _sensor_setup(plant, self.n_y)
        self.sensor = FaultySensor(self.spec_faults, self.n_y, 1, sqrt, hold)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        y, info = self.env.reset(seed=seed, options=options)
        self.sensor.seed([seed])
        self.sensor.restart(np.ones(1, dtype=bool))
        return self._read(y, info)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        y, reward, terminated, truncated, info = self.env.step(action)
        obs, info = self._read(y, info)
        return obs, reward, terminated, truncated, info

    def _read(self, y: Any, info: dict[str, Any]) -> tuple[FloatArray, dict[str, Any]]:
        clean = np.array(y, dtype=np.float64).reshape(1, self.n_y)
        delivered, missing, flags = self.sensor.read(clean)
        info = dict(info)
        info["clean_measurement"] = clean[0].copy()
        info["measurement_missing"] = bool(missing[0])
        info["sensor_faults"] = flag_dict(flags, single=True)
        shape = np.shape(y)
        return delivered[0].reshape(shape), info


class VectorSensorFaults(gym.vector.VectorWrapper):
    """:class:`SensorFaults` on every sub-env of a native fir-gym vector env (next-step or
    same-step autoreset): one faulty sensor per sub-env, restarted with its episode."""

    def __init__(self, env: VectorEnv, *, dropout: float = 0.0, outliers: Any = None,
                 stuck: Any = None, bias: Any = None, delay: int = 0, every: int = 1) -> None:
        super().__init__(env)
        self._same_step = same_step_mode(env, type(self).__name__)
        plant = _plant_of(env)
        self.n_y = int(np.prod(env.single_observation_space.shape or (1,)))
        self.spec_faults = check_faults(
            n_y=self.n_y, episode_steps=_episode_steps(env, plant), dropout=dropout,
            outliers=outliers, stuck=stuck, bias=bias, delay=delay, every=every)
        self.delay = self.spec_faults.delay
        sqrt, hold = _sensor_setup(plant, self.n_y)
        self.sensor = FaultySensor(self.spec_faults, self.n_y, self.num_envs, sqrt, hold)
        self._prev_done = np.zeros(self.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        y, info = cast(Any, self.env).reset(seed=seed, options=options)
        self._seed(seed)
        self.sensor.restart(np.ones(self.num_envs, dtype=bool))
        self._prev_done[:] = False
        return self._read(y, dict(info))

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        y, reward, terminated, truncated, info = self.env.step(actions)
        info = dict(info)
        if self._prev_done.any():                  # next-step mode: these reset this step
            self.sensor.restart(self._prev_done)
        ended = info.get("_final_obs") if self._same_step else None
        if ended is not None and ended.any():      # the ended episodes' last readings first
            Y = np.array(y, dtype=np.float64).reshape(self.num_envs, self.n_y)
            last = Y.copy()
            for i in np.flatnonzero(ended):
                last[i] = np.asarray(info["final_obs"][i], dtype=np.float64).reshape(self.n_y)
            final_obs, final_info = self._read(last, dict(info.get("final_info", {})),
                                               rows=ended)
            info["final_obs"], info["final_info"] = final_obs, final_info
            self.sensor.restart(ended)
        obs, info = self._read(y, info)
        if not self._same_step:
            self._prev_done = np.logical_or(terminated, truncated)
        return obs, reward, terminated, truncated, info

    def _seed(self, seed: int | list[int | None] | None) -> None:
        """Sub-env ``i``'s sensor seeded ``seed + i`` (or the ``i``-th of a list); ``None``
        keeps each sensor's streams (fresh ones the first time)."""
        n = self.num_envs
        if isinstance(seed, (list, tuple)):
            if len(seed) != n:
                raise ValueError(f"seed must be an int, None or a list of {n} seeds; got "
                                 f"{len(seed)} seeds")
            self.sensor.seed(list(seed))
        else:
            self.sensor.seed([None if seed is None else int(seed) + i for i in range(n)])

    def _read(self, y: Any, info: dict[str, Any], rows: NDArray[np.bool_] | None = None
              ) -> tuple[FloatArray, dict[str, Any]]:
        """Read one step's measurements. With ``rows`` (same-step mode: the ended episodes'
        last readings) only those systems read; the others' entries are their clean
        measurement, not missing, unflagged (``final_info`` masks them out)."""
        n = self.num_envs
        clean = np.array(y, dtype=np.float64).reshape(n, self.n_y)
        if rows is None:
            delivered, missing, flags = self.sensor.read(clean)
        else:
            delivered, missing = clean.copy(), np.zeros(n, dtype=bool)
            flags = np.zeros((n, len(FLAGS)), dtype=bool)
            delivered[rows], missing[rows], flags[rows] = self.sensor.read(clean[rows], rows)
        everyone = np.ones(n, dtype=bool)
        info["clean_measurement"], info["_clean_measurement"] = clean, everyone
        info["measurement_missing"], info["_measurement_missing"] = missing, everyone
        info["sensor_faults"] = flag_dict(flags, single=False)
        info["_sensor_faults"] = everyone
        return delivered.reshape(np.shape(y)), info
