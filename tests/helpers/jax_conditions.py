"""The condition tests' tools (tests/jax/test_burst.py, tests/jax/test_sensor_delay.py): a
numpy env and a JAX env run on the same standard normals — the JAX env's own, recomputed
from the keys it steps with and served to the numpy plant in its draw order — and their
records compared quantity by quantity.

The JAX plants draw one ``jax.random.normal(key, (size,))`` per reset and per step, the
state's part first, the measurement's last (docs/jax.md, "The noise contract"); the numpy
plant draws the same numbers as one ``standard_normal`` call per part, in the same order.
:class:`FedNormals` stands in for the numpy plant's ``np_random`` and serves each call the
next numbers of the step's draw, asserting that a step uses its draw up: the settings of
:data:`SETTINGS` give every plant process noise, so that every step draws both parts.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from jax_parity import flat, flat_jax

#: per plant, the env keywords of the test episodes (both backends): process noise on
#: (Orbit-v0 and PendulumSlider-v0 draw none without it), a random start, UncertainOscillator
#: -v0's own δ schedule overlapping the bursts of the tests
SETTINGS: dict[str, dict[str, Any]] = {
    "fir_gym/Orbit-v0": {"Q": [[1e-6, 0.0], [0.0, 4e-6]],
                         "initial_state_cov": [[0.0025, 0.0], [0.0, 0.04]]},
    "fir_gym/UncertainOscillator-v0": {
        "delta_schedule": ((6, 14, 0.1),), "uncertainty": "rate",
        "initial_state_cov": [[0.01, 0, 0], [0, 0.04, 0], [0, 0, 0.0025]]},
    "fir_gym/CarrierMotion-v0": {},
    "fir_gym/VanDerPol-v0": {},
    "fir_gym/PendulumSlider-v0": {"frame_skip": 10, "Q": list(np.diag([1e-8, 1e-6, 1e-8,
                                                                        1e-6]))},
}


def step_draw_size(env_id: str, params: Any) -> int:
    """How many standard normals the JAX plant draws per step (docs/jax.md's plants table)."""
    if env_id == "fir_gym/VanDerPol-v0":
        return int(params.substeps) + 1
    return {"fir_gym/Orbit-v0": 3, "fir_gym/UncertainOscillator-v0": 2,
            "fir_gym/CarrierMotion-v0": 3, "fir_gym/PendulumSlider-v0": 8}[env_id]


def draws(env_id: str, env: Any, params: Any, keys: Any) -> list[np.ndarray]:
    """The standard normals the JAX env draws from ``keys`` (the reset's key first): ``n_x +
    n_y`` at the reset, :func:`step_draw_size` at a step."""
    import jax
    import jax.numpy as jnp

    sizes = [env.n_x + env.n_y] + [step_draw_size(env_id, params)] * (len(keys) - 1)
    return [np.asarray(jax.random.normal(key, (size,), dtype=jnp.float64))
            for key, size in zip(keys, sizes, strict=True)]


class FedNormals:
    """Stands in for a numpy plant's ``np_random``: each ``standard_normal`` call is served
    the next numbers of the draw last :meth:`feed`-ed (in its requested shape)."""

    def __init__(self) -> None:
        self.buffer = np.empty(0)

    def feed(self, z: np.ndarray) -> None:
        assert self.buffer.size == 0, f"the plant left {self.buffer.size} numbers undrawn"
        self.buffer = np.asarray(z, dtype=np.float64).copy()

    def standard_normal(self, size: Any = None) -> np.ndarray:
        shape = () if size is None else (size,) if isinstance(size, int) else tuple(size)
        n = int(np.prod(shape))
        assert n <= self.buffer.size, f"the plant drew {n}, the step had {self.buffer.size}"
        out, self.buffer = self.buffer[:n].reshape(shape), self.buffer[n:]
        return out.copy()

    def used_up(self) -> bool:
        return self.buffer.size == 0


def numpy_run(env: Any, normals: list[np.ndarray], actions: np.ndarray) -> dict[str, np.ndarray]:
    """An episode of the numpy ``env`` (``gym.make``'s, any wrappers) on the given draws (the
    reset's first) and open-loop ``actions``, until it ends or the actions do: per reset and
    step the observation, reward, flags, true state, ``info["burst"]`` (0 where absent), the
    sensor's ``late`` and ``measurement_missing`` flags and, with an estimator, its
    covariance, NIS and divergence flag."""
    plant = env.unwrapped
    fed = FedNormals()
    plant.np_random = fed
    try:
        estimator = env.get_wrapper_attr("estimator")
    except AttributeError:
        estimator = None
    out: dict[str, list[Any]] = {key: [] for key in (
        "obs", "reward", "terminated", "truncated", "state", "burst", "late", "missing",
        "P", "nis", "diverged")}

    def record(obs: Any, reward: float, terminated: bool, truncated: bool,
               info: dict[str, Any]) -> None:
        assert fed.used_up(), f"the plant left {fed.buffer.size} numbers undrawn"
        out["obs"].append(flat(obs))
        out["reward"].append(reward)
        out["terminated"].append(terminated)
        out["truncated"].append(truncated)
        out["state"].append(np.asarray(info["state"], dtype=np.float64))
        out["burst"].append(float(info.get("burst", 0.0)))
        out["late"].append(bool(info.get("sensor_faults", {}).get("late", False)))
        out["missing"].append(bool(info.get("measurement_missing", False)))
        if estimator is not None:
            out["P"].append(np.asarray(estimator.P, dtype=np.float64))
            nis = estimator.last_info.get("nis")
            out["nis"].append(np.nan if nis is None else float(nis))
            out["diverged"].append(bool(estimator.diverged))

    fed.feed(normals[0])
    obs, info = env.reset()
    record(obs, 0.0, False, False, info)
    for z, a in zip(normals[1:], actions, strict=False):
        fed.feed(z)
        obs, reward, terminated, truncated, info = env.step(a)
        record(obs, float(reward), bool(terminated), bool(truncated), info)
        if terminated or truncated:
            break
    env.close()
    return {key: np.array(value) for key, value in out.items()}


def jax_rollout(env: Any) -> Any:
    """A jitted open-loop rollout of the JAX ``env``: ``rollout(keys, actions, params)`` →
    ``(obs0, state0, trace)``, the reset on ``keys[0]``, then one ``step_env`` per further
    key and action (a scan; no auto-reset), ``trace`` holding each step's ``(obs, state,
    reward, terminated, truncated, info)``. One compilation per env and params structure."""
    import jax

    def rollout(keys: Any, actions: Any, params: Any) -> Any:
        obs0, state0 = env.reset_env(keys[0], params)

        def body(state: Any, step: Any) -> Any:
            key, a = step
            obs, state, reward, terminated, info = env.step_env(key, state, a, params)
            return state, (obs, state, reward, terminated, env.is_truncated(state, params),
                           info)

        _, trace = jax.lax.scan(body, state0, (keys[1:], actions))
        return obs0, state0, trace

    return jax.jit(rollout)


def plant_of(state: Any) -> Any:
    """The plant's state inside a :class:`fir_gym.jax.randomized.RandomizedState` (or the
    state itself)."""
    return getattr(state, "plant", state)


def jax_record(obs0: Any, state0: Any, trace: Any, n: int, first_late: bool = False
               ) -> dict[str, np.ndarray]:
    """:func:`jax_rollout`'s result as :func:`numpy_run`'s record, its first ``n`` entries
    (the reset's included; ``first_late``: the reset's reading is late, so missing — the
    reset returns no ``info``)."""
    import jax

    obs, states, reward, terminated, truncated, info = trace
    s0, s = plant_of(state0), plant_of(states)

    def joined(first: Any, rest: Any) -> np.ndarray:
        return np.concatenate([np.asarray(first)[None], np.asarray(rest)])[:n]

    flat_obs = np.asarray(jax.vmap(lambda o: flat_jax(o))(obs))
    late0 = first_late
    faults = info.get("sensor_faults", {})
    late = np.asarray(faults["late"]) if "late" in faults else np.zeros(len(flat_obs), bool)
    missing = np.asarray(info.get("measurement_missing", np.zeros(len(flat_obs), bool)))
    return {
        "obs": joined(np.asarray(flat_jax(obs0)), flat_obs),
        "reward": joined(0.0, reward), "terminated": joined(False, terminated),
        "truncated": joined(False, truncated), "state": joined(s0.x, s.x),
        "burst": joined(0.0, info.get("burst", np.zeros(len(flat_obs)))),
        "late": joined(late0, late), "missing": joined(late0, missing),
        "P": joined(s0.filter_P, s.filter_P), "nis": joined(s0.nis, s.nis),
        "diverged": joined(s0.diverged, s.diverged),
        "estimate": joined(s0.filter_x, s.filter_x)}


def worst_differences(got: dict[str, np.ndarray], want: dict[str, np.ndarray],
                      keys: tuple[str, ...]) -> dict[str, float]:
    """Per quantity, ``max |got − want|`` over the episode relative to ``max |want|`` of the
    same component (its scale over the episode; at least 1e-300)."""
    out = {}
    for key in keys:
        g, w = np.asarray(got[key], dtype=np.float64), np.asarray(want[key], dtype=np.float64)
        assert g.shape == w.shape, (key, g.shape, w.shape)
        scale = np.maximum(np.max(np.abs(w), axis=0), 1e-300)
        out[key] = float(np.max(np.abs(g - w) / scale))
    return out


def nis_difference(got: np.ndarray, want: np.ndarray) -> float:
    """The NIS compared as the parity tests do, ``|Δ| / (1 + NIS)``, with NaN required at the
    same steps."""
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    ok = ~np.isnan(want)
    return float(np.max(np.abs(got[ok] - want[ok]) / (1.0 + np.abs(want[ok])), initial=0.0))
