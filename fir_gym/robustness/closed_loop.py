"""Closed-loop episodes under a condition, many at once: the robustness benchmark's evaluator.

:func:`build_env` stacks, on a native vector env of ``n`` sub-envs (next-step autoreset,
``generators="per_env"``: sub-env ``i`` reset with seed ``s`` plays the episode a single env
reset with seed ``s + i`` plays — the same draws; on Orbit-v0, UncertainOscillator-v0 and
VanDerPol-v0 the returns compared were the same bits too, while the batched arithmetic of
CarrierMotion-v0 and PendulumSlider-v0 differs from their single env's in the last bits),
the plant's condition keywords (``randomize``, ``burst``), a
:class:`~fir_gym.wrappers.VectorSensorFaults` for the sensor conditions, and what the
controller sees: an estimator (:class:`~fir_gym.wrappers.VectorEstimatorObservation`, told a
sensor delay), the true state, the raw measurement or a window of measurements.

:func:`play` runs one episode in every sub-env under a policy and records, per episode,
its return and length, and where the controller sees an estimate: the squared
estimation error per state summed over the episode's steps (reset step included), every
step's NEES ``(x − x̂)ᵀ P⁻¹ (x − x̂)`` (NaN where ``P`` is not positive definite, or the
filter has none), whether the divergence flag rose, and the error trajectory from which
:func:`~.recovery.recovery_time` measures the recovery after a burst. A sub-env that
has ended keeps running (autoreset) but nothing after its first episode is recorded.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from fir_gym.conditions import ConditionSetup

FloatArray = NDArray[np.float64]

#: what the controller sees: an estimator's name, or one of these
PLAIN = ("true", "measurement", "measurement-stack")


@dataclass
class Episodes:
    """The record of ``n`` closed-loop episodes (one per sub-env; see the module)."""

    returns: FloatArray
    lengths: NDArray[np.int64]
    squared_error: FloatArray | None = None     # (n, n_x): sums over each episode's steps
    nees: FloatArray | None = None              # (T, n): per step, NaN after an episode
    errors: FloatArray | None = None            # (T, n, n_x): x − x̂ per step, NaN after
    diverged: NDArray[np.bool_] | None = None   # (n,)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def rmse(self) -> FloatArray | None:
        """Per state, ``sqrt`` of the mean squared error over every step of every episode."""
        if self.squared_error is None:
            return None
        steps = float(np.sum(self.lengths + 1))
        return np.sqrt(self.squared_error.sum(axis=0) / steps)


def build_env(env_id: str, n: int, observed: str, setup: ConditionSetup, *,
              env_kwargs: Mapping[str, Any] | None = None,
              estimator_kwargs: Mapping[str, Any] | None = None,
              stack_horizon: int | None = None) -> gym.vector.VectorEnv:
    """``n`` sub-envs of ``env_id`` under ``setup``'s condition, observing ``observed`` (an
    estimator's registry name or one of :data:`PLAIN`)."""
    from fir_gym.wrappers import (
        VectorEstimatorObservation,
        VectorMeasurementStack,
        VectorSensorFaults,
        VectorTrueStateObservation,
    )

    plant_kwargs = {**dict(env_kwargs or {}), **setup.plant_kwargs}
    venv: gym.vector.VectorEnv = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point",
                                              generators="per_env", **plant_kwargs)
    if setup.sensor_faults:
        venv = VectorSensorFaults(venv, **setup.sensor_faults)
    if observed == "true":
        return VectorTrueStateObservation(venv)
    if observed == "measurement":
        return venv
    if observed == "measurement-stack":
        return VectorMeasurementStack(venv, stack_horizon)
    options = {**dict(estimator_kwargs or {}), **setup.estimator_kwargs}
    return VectorEstimatorObservation(venv, observed, **options)


#: a policy: ``(observations, episode_start (n,), state) -> (actions (n, n_u), state)``
Policy = Callable[[Any, NDArray[np.bool_], Any], tuple[np.ndarray, Any]]


def play(venv: gym.vector.VectorEnv, policy: Policy, seed: int,
         keep_errors: bool = False) -> Episodes:
    """One episode per sub-env, seeds ``seed + i``, under ``policy`` (module docstring).
    ``keep_errors`` keeps the per-step error trajectories (for the recovery time)."""
    n = venv.num_envs
    obs, info = venv.reset(seed=seed)
    estimator = _estimator_of(venv)
    returns, lengths = np.zeros(n), np.zeros(n, dtype=np.int64)
    done = np.zeros(n, dtype=bool)
    n_x = np.asarray(info["state"]).shape[1]
    squared = np.zeros((n, n_x)) if estimator is not None else None
    nees_steps: list[FloatArray] = []
    error_steps: list[FloatArray] = []
    diverged = np.zeros(n, dtype=bool)
    start = np.ones(n, dtype=bool)
    state: Any = None

    def record(info: dict[str, Any], live: NDArray[np.bool_]) -> None:
        if estimator is None or squared is None:
            return
        err = np.asarray(info["estimation_error"], dtype=np.float64)
        squared[live] += err[live] ** 2
        diverged[live] |= np.asarray(info["estimator_diverged"], dtype=bool)[live]
        step_nees = np.full(n, np.nan)
        P = estimator.P
        if P is not None:
            step_nees = nees_rows(err, np.asarray(P, dtype=np.float64)[:, :n_x, :n_x])
        nees_steps.append(np.where(live, step_nees, np.nan))
        if keep_errors:
            error_steps.append(np.where(live[:, None], err, np.nan))

    record(info, ~done)
    while not done.all():
        actions, state = policy(obs, start, state)
        start = np.zeros(n, dtype=bool)
        obs, reward, terminated, truncated, info = venv.step(actions)
        live = ~done
        returns[live] += np.asarray(reward, dtype=np.float64)[live]
        lengths[live] += 1
        record(info, live)
        ended = np.logical_or(terminated, truncated)
        done |= ended & live
        start = ended.copy()            # the next step is their new episode's first
    return Episodes(
        returns=returns, lengths=lengths, squared_error=squared,
        nees=np.array(nees_steps) if estimator is not None else None,
        errors=np.array(error_steps) if keep_errors and estimator is not None else None,
        diverged=diverged if estimator is not None else None)


def nees_rows(err: FloatArray, P: FloatArray) -> FloatArray:
    """Per row, ``eᵀ P⁻¹ e`` (``err (n, m)``, ``P (n, m, m)``); NaN where ``P`` is not
    positive definite."""
    out = np.full(err.shape[0], np.nan)
    try:
        L = np.linalg.cholesky(P)
        w = np.linalg.solve(L, err[..., None])[..., 0]
        return np.einsum("bi,bi->b", w, w)
    except np.linalg.LinAlgError:
        for i in range(err.shape[0]):
            try:
                L = np.linalg.cholesky(P[i])
            except np.linalg.LinAlgError:
                continue
            w = np.linalg.solve(L, err[i])
            out[i] = float(w @ w)
    return out


def _estimator_of(venv: Any) -> Any:
    """The batched estimator of a ``VectorEstimatorObservation`` in the wrapper chain."""
    env = venv
    while env is not None:
        estimator = getattr(env, "estimator", None)
        if estimator is not None:
            return estimator
        env = getattr(env, "env", None)
    return None
