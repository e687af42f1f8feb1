"""The parity tests' tools (tests/jax): the numpy env driven by given standard normals and
the observations and errors compared as flat float64 vectors."""

from __future__ import annotations

from typing import Any

import numpy as np


class QueuedNormals:
    """Stands in for the plant's ``np_random``: serves the queued standard normals, in
    order, each call's shape checked."""

    def __init__(self) -> None:
        self.queue: list[np.ndarray] = []

    def standard_normal(self, size: Any = None) -> np.ndarray:
        z = self.queue.pop(0)
        want = (size,) if isinstance(size, int) else tuple(size)
        assert z.shape == want, f"the plant drew {want}, the queue had {z.shape}"
        return z.copy()


def flat(obs: Any) -> np.ndarray:
    """An observation as one float64 vector (a dict's entries in key order)."""
    if isinstance(obs, dict):
        return np.concatenate([np.asarray(obs[key], dtype=np.float64).reshape(-1)
                               for key in sorted(obs)])
    return np.asarray(obs, dtype=np.float64).reshape(-1)


def flat_jax(obs: Any) -> Any:
    """:func:`flat` inside a JAX trace."""
    import jax.numpy as jnp

    if isinstance(obs, dict):
        return jnp.concatenate([jnp.reshape(obs[key], (-1,)) for key in sorted(obs)])
    return jnp.reshape(obs, (-1,))


def relative_error(got: np.ndarray, want: np.ndarray) -> float:
    """``max |got − want| / |want|`` elementwise (where ``want`` is 0, ``got`` must be 0)."""
    diff = np.abs(got - want)
    scale = np.abs(want)
    if np.any((scale == 0) & (diff > 0)):
        return float("inf")
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.nanmax(np.where(scale > 0, diff / scale, 0.0)))


#: what a numpy plant publishes for the wrappers to build a filter from
PUBLISHED = ("model", "initial_state", "initial_state_cov", "default_horizon")


def replay(ys: np.ndarray, applied: np.ndarray, plant: Any = None,
           missing: np.ndarray | None = None) -> Any:
    """A numpy env (a :class:`gymnasium.Env`) replaying recorded measurements ``ys`` (the
    reset's first) and reporting the recorded applied actions ``applied`` in
    ``info["action"]`` — what the numpy wrappers (``MeasurementStack``,
    ``EstimatorObservation``) read — and, given a numpy ``plant``, publishing its
    :data:`PUBLISHED` attributes. Given ``missing`` (one bool per reading, the reset's
    first), the reset's and every step's ``info["measurement_missing"]`` report it, as
    :class:`fir_gym.wrappers.SensorFaults` does (``EstimatorObservation`` then gives its
    filter no measurement there)."""
    import gymnasium as gym
    from gymnasium import spaces

    class Replay(gym.Env):
        def __init__(self) -> None:
            self.ys, self.applied, self.k = ys, applied, 0
            for name in PUBLISHED if plant is not None else ():
                setattr(self, name, getattr(plant, name))
            self.observation_space = spaces.Box(-np.inf, np.inf, ys.shape[1:], np.float64)
            self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

        def reset(self, *, seed: int | None = None, options: Any = None) -> Any:
            self.k = 0
            return self.ys[0], self.faults()

        def step(self, action: Any) -> Any:
            self.k += 1
            info = {"action": self.applied[self.k - 1], **self.faults()}
            return self.ys[self.k], 0.0, False, False, info

        def faults(self) -> dict[str, Any]:
            return {} if missing is None else {"measurement_missing": bool(missing[self.k])}

    return Replay()


def normwise(got: np.ndarray, want: np.ndarray) -> float:
    """``max |got − want| / max |want|`` (a covariance's off-diagonal entries may be exact
    zeros in one filter and round-off in the other)."""
    return float(np.max(np.abs(got - want)) / max(float(np.max(np.abs(want))), 1e-300))


def compare_with_numpy_filter(run: list[Any], numpy_env: Any,
                              missing: list[bool] | None = None, *,
                              std_floor: bool = False) -> dict[str, float]:
    """A JAX filter kind's closed-loop run (``[(state, info)]``, the reset's first) against
    the numpy ``EstimatorObservation`` replaying it (``numpy_env``, stepped here with the
    recorded applied actions): the divergence flag asserted equal at every step, the NIS
    NaN in the JAX record wherever the numpy filter has none (or the reading is
    ``missing``); returns the worst estimate and covariance differences relative to their
    largest entry (the estimate's, with ``std_floor``, relative to the larger of its largest
    entry and the numpy filter's largest standard deviation ``√max diag P``: an estimate at
    zero, predicted through missing readings, is round-off of zero in both) and the worst NIS
    difference relative to ``1 + NIS``."""
    applied = [np.asarray(info["action"]) for _, info in run[1:]]
    estimate, _ = numpy_env.reset()
    worst = {"x": 0.0, "P": 0.0, "nis": 0.0}
    for k, (state, _) in enumerate(run):
        if k:
            estimate = numpy_env.step(applied[k - 1])[0]
        est = numpy_env.estimator
        assert bool(state.diverged) == bool(est.diverged), f"step {k}"
        if std_floor:        # relative to the estimate's size or its own uncertainty
            scale = max(float(np.max(np.abs(estimate))),
                        float(np.sqrt(np.max(np.diag(np.asarray(est.P))))), 1e-300)
            gap = float(np.max(np.abs(np.asarray(state.filter_x) - estimate))) / scale
            worst["x"] = max(worst["x"], gap)
        else:
            worst["x"] = max(worst["x"], normwise(np.asarray(state.filter_x), estimate))
        worst["P"] = max(worst["P"], normwise(np.asarray(state.filter_P), np.asarray(est.P)))
        nis, got = float(est.last_info.get("nis", np.nan)), float(state.nis)
        if np.isnan(nis) or (missing is not None and missing[k]):
            assert np.isnan(got), f"step {k}: NIS {got} where the numpy filter has none"
        else:
            worst["nis"] = max(worst["nis"], abs(got - nis) / (1.0 + abs(nis)))
    return worst


def open_loop(env: Any, params: Any, actions: np.ndarray, seed: int) -> list[Any]:
    """A JAX env run open loop on ``actions`` from ``jax.random.key(seed)`` (until it
    terminates): ``[(key, state, info)]``, the reset's first, its info the sensor's reading of
    the reset (``measurement_missing`` and ``sensor_faults``, as a step's info has them)."""
    import jax
    import jax.numpy as jnp

    keys = jax.random.split(jax.random.key(seed), len(actions) + 1)
    _, state = jax.jit(env.reset_env)(keys[0], params)
    first = env.sensor_reading(keys[0], 0, params)
    step = jax.jit(env.step_env)
    out: list[Any] = [(keys[0], state, {"measurement_missing": first.missing,
                                        "sensor_faults": first.flags()})]
    for key, a in zip(keys[1:], actions, strict=True):
        _, state, _, _, info = step(key, state, jnp.asarray(a), params)
        out.append((key, state, info))
        if bool(state.terminated):
            break
    return out


#: the UKF's options in the plant-level parity tests (tests/jax/test_filter_kinds.py's
#: docstring says why: at its default alpha the UKF agrees to 1e-8 only)
TEST_OPTIONS = {"ukf": {"alpha": 1.0, "kappa": 1.0}}


def filter_cases() -> list[tuple[str, str]]:
    """Every (plant, filter kind) pair of :mod:`fir_gym.jax`: the plant's own filter and the
    generic ones it has."""
    from fir_gym.jax import PLANTS
    from fir_gym.jax.filters import GENERIC_FILTERS

    return [(env_id, kind) for env_id, plant in PLANTS.items() for kind in plant.kinds
            if kind == plant.env_class.estimator or kind in GENERIC_FILTERS]

