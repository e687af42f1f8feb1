"""The sensor's delay on the JAX plants (``fir_gym.jax.make(env_id, kind, sensor_faults=
{"delay": d, ...})``): the transmission line in the state, every filter kind told the delay.

Oracles:

* per plant, the numpy env ``gym.make(env_id, sensor_faults={"delay": d}, estimator=<its
  own filter>, burst=...)`` — the numpy sensor's line and the numpy filter told the delay
  (``with_known_delay``: it runs ``d`` steps behind and predicts ahead) — on the same
  standard normals (``tests/helpers/jax_conditions.py``): states, observations (the
  predicted estimate), rewards, covariance, NIS, ``info["burst"]`` to 1e-9 of each
  quantity's scale, the flags (``late``, ``measurement_missing``, terminated, truncated,
  diverged) exactly;
* with every other fault on as well, the same JAX env without the delay on the same keys
  (the plant and the sensor's draws are the same): what is delivered at ``k`` is what that
  env delivered at ``k − d`` (held where it was missing, and before anything is due), with
  its flags; the measurement stack stacks the delivered readings (numpy's
  ``MeasurementStack`` replaying them);
* each filter kind against the numpy env's filter built as ``gym.make(id, estimator=kind,
  sensor_faults={"delay": d})`` builds it (``delay=d`` among its options), replaying the
  delivered readings with ``None`` where missing — on CarrierMotion-v0 every kind it has,
  on Orbit-v0 the UKF and the EFIR.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax_conditions import (  # noqa: E402
    SETTINGS,
    draws,
    jax_record,
    jax_rollout,
    nis_difference,
    numpy_run,
    worst_differences,
)
from jax_parity import TEST_OPTIONS, compare_with_numpy_filter, replay  # noqa: E402

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.jax import PLANTS, make  # noqa: E402
from fir_gym.wrappers.estimator_observation import EstimatorObservation  # noqa: E402
from fir_gym.wrappers.measurement_stack import MeasurementStack  # noqa: E402

STEPS = 40
DELAY = 3
BURST = ((4, 9, 0.5),)
RTOL = 1e-9


def _actions(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.2, 1.2, (STEPS, 1)).astype(np.float32)


def _faults(env_id: str) -> dict[str, Any]:
    """Every fault of the sensor, the delay among them."""
    n_y = PLANTS[env_id].env_class.n_y
    return {"delay": DELAY, "dropout": 0.1, "outliers": (0.2, 4.0), "every": 2,
            "bias": (10, list(np.linspace(0.5, 1.5, n_y))), "stuck": (0.05, 2.0)}


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_a_delayed_episode_matches_the_numpy_env(env_id: str) -> None:
    own = PLANTS[env_id].env_class.estimator
    kwargs = {**SETTINGS[env_id], "max_episode_steps": STEPS, "burst": BURST}
    env, params = make(env_id, own, sensor_faults={"delay": DELAY}, **kwargs)
    keys = jax.random.split(jax.random.key(11), STEPS + 1)
    actions = _actions(3)
    obs0, state0, trace = jax_rollout(env)(keys, jnp.asarray(actions), params)
    want = numpy_run(gym.make(env_id, estimator=own, sensor_faults={"delay": DELAY}, **kwargs),
                     draws(env_id, env, params, keys), actions)
    got = jax_record(obs0, state0, trace, len(want["reward"]), first_late=True)
    assert len(want["reward"]) == STEPS + 1 and want["truncated"][-1]
    np.testing.assert_array_equal(want["late"], np.arange(STEPS + 1) < DELAY)
    for flag in ("late", "missing", "terminated", "truncated", "diverged"):
        np.testing.assert_array_equal(got[flag], want[flag], err_msg=flag)
    worst = worst_differences(got, want, ("state", "obs", "reward", "burst", "P"))
    worst["nis"] = nis_difference(got["nis"], want["nis"])
    print(env_id, own, f"delay {DELAY}, worst relative differences:",
          ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    assert max(worst.values()) < RTOL, worst


def _run(env: Any, params: Any, keys: Any, actions: np.ndarray) -> tuple[Any, Any, Any]:
    return jax_rollout(env)(keys, jnp.asarray(actions), params)


def test_the_line_delivers_what_the_undelayed_sensor_read_d_steps_before() -> None:
    env_id = "fir_gym/UncertainOscillator-v0"
    kwargs = {**SETTINGS[env_id], "max_episode_steps": STEPS}
    faults = _faults(env_id)
    undelayed = {k: v for k, v in faults.items() if k != "delay"}
    keys = jax.random.split(jax.random.key(2), STEPS + 1)
    actions = _actions(6)
    env, params = make(env_id, "measurement-stack", sensor_faults=faults, **kwargs)
    ref_env, _ = make(env_id, "measurement", sensor_faults=undelayed, **kwargs)
    _, s0, (obs, states, _, _, _, info) = _run(env, params, keys, actions)
    _, r0, (_, ref, _, _, _, ref_info) = _run(ref_env, params, keys, actions)
    np.testing.assert_array_equal(np.asarray(states.x), np.asarray(ref.x))   # same plant
    first = env.sensor_reading(keys[0], 0, params)
    ref_y = np.concatenate([np.asarray(r0.y)[None], np.asarray(ref.y)])
    ref_missing = np.concatenate([[bool(first.missing)], np.asarray(ref_info[
        "measurement_missing"])])
    ref_flags = {name: np.concatenate([[bool(getattr(first, name))],
                                       np.asarray(ref_info["sensor_faults"][name])])
                 for name in ("dropped", "stuck", "outlier", "biased", "unsampled")}
    y = np.concatenate([np.asarray(s0.y)[None], np.asarray(states.y)])
    held = np.asarray(env.first_hold(params))
    missing = [True]                                   # the reset's reading is late
    np.testing.assert_array_equal(y[0], held)
    for k in range(1, STEPS + 1):
        due = k - DELAY
        late = due < 0
        flags = {name: bool(info["sensor_faults"][name][k - 1]) for name in ref_flags}
        assert bool(info["sensor_faults"]["late"][k - 1]) == late
        assert flags == ({name: False for name in flags} if late
                         else {name: bool(v[due]) for name, v in ref_flags.items()}), k
        gone = late or bool(ref_missing[due])
        assert bool(info["measurement_missing"][k - 1]) == gone
        held = held if gone else ref_y[due]
        np.testing.assert_array_equal(y[k], held)
        missing.append(gone)
    assert 5 < sum(missing) < STEPS - 5 and sum(ref_flags["outlier"]) > 0
    applied = np.asarray(info["action"])
    stack = MeasurementStack(replay(y, applied), horizon=env.horizon)
    want, _ = stack.reset()
    got = np.concatenate([np.asarray(env.get_obs(s0, params))[None], np.asarray(obs)])
    np.testing.assert_array_equal(got[0], want)
    for k in range(1, STEPS + 1):
        np.testing.assert_array_equal(got[k], stack.step(applied[k - 1])[0])


FILTER_CASES = [("fir_gym/CarrierMotion-v0", kind) for kind in ("kf", "ukf", "fir", "ufir")] + \
    [("fir_gym/Orbit-v0", "ukf"), ("fir_gym/Orbit-v0", "efir")]


@pytest.mark.parametrize("env_id,kind", FILTER_CASES)
def test_each_filter_kind_runs_behind_as_the_numpy_filter_told_the_delay(env_id: str,
                                                                        kind: str) -> None:
    """The JAX filter kind against the numpy env's ``EstimatorObservation`` with the filter
    ``gym.make(env_id, estimator=kind, sensor_faults=...)`` builds (the delay told to it),
    replaying the delivered readings, ``None`` where missing: the predicted estimate to 1e-9
    of the larger of its largest entry and standard deviation, the covariance to 1e-9 of its
    largest entry, NIS to 1e-9 (1 + NIS), the divergence flag exactly."""
    options = {**({"horizon": 8} if kind in ("efir", "fir", "ufir") else {}),
               **TEST_OPTIONS.get(kind, {})}
    kwargs = {**SETTINGS[env_id], "max_episode_steps": STEPS, "burst": BURST}
    env, params = make(env_id, kind, kind_kwargs=options, sensor_faults=_faults(env_id),
                       **kwargs)
    keys = jax.random.split(jax.random.key(7), STEPS + 1)
    applied = np.clip(_actions(5), -1, 1).astype(np.float64)
    _, s0, (_, states, _, _, _, info) = _run(env, params, keys, applied)
    run = [(s0, {})] + [(jax.tree.map(lambda a, k=k: a[k], states),
                         {"action": applied[k]}) for k in range(STEPS)]
    missing = [True] + [bool(m) for m in np.asarray(info["measurement_missing"])]
    ys = np.concatenate([np.asarray(s0.y)[None], np.asarray(states.y)])
    plant = gym.make(env_id, **kwargs)
    numpy_env = EstimatorObservation(replay(ys, applied, plant.unwrapped, np.array(missing)),
                                     kind, delay=DELAY, **options)
    plant.close()
    assert numpy_env.estimator.delay == DELAY
    worst = compare_with_numpy_filter(run, numpy_env, missing, std_floor=True)
    print(env_id, kind, f"delay {DELAY}: {sum(missing)} of {len(missing)} missing; worst",
          ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    assert STEPS // 4 < sum(missing) < STEPS
    assert max(worst.values()) < RTOL, worst


def test_a_delay_as_long_as_an_episode_is_refused_in_one_line() -> None:
    with pytest.raises(ValueError, match="delay=50 is not shorter than an episode"):
        make("fir_gym/CarrierMotion-v0", sensor_faults={"delay": 50}, max_episode_steps=50)
    with pytest.raises(ValueError, match="delay must be an integer >= 0"):
        make("fir_gym/CarrierMotion-v0", sensor_faults={"delay": 1.5})
    env, _ = make("fir_gym/CarrierMotion-v0", "ukf", sensor_faults={"delay": 2})
    assert env.delay == 2 and not env.runs_own_filter and env.can_miss
