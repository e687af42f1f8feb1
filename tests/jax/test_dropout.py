"""The JAX sensor's dropout (``fir_gym.jax.make(..., sensor_faults={"dropout": p})``).

Oracles: the same env without dropout on the same keys (the plant's trajectory and clean
readings must not change: the dropout draws come from the key's fault stream), the numpy
sensor's hold rule written out (the last delivered reading, ``H x0`` before the first), the
numpy :class:`~fir_gym.wrappers.MeasurementStack` and the numpy env's own
:class:`~fir_gym.wrappers.EstimatorObservation` replaying the JAX plant's delivered readings
with its ``measurement_missing`` flags — the filter as ``gym.make(env_id, estimator=kind,
sensor_faults=...)`` runs it, fed ``None`` where a reading is missing.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
from jax_parity import (  # noqa: E402
    TEST_OPTIONS,
    compare_with_numpy_filter,
    filter_cases,
    open_loop,
    replay,
)

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.jax import PLANTS, make  # noqa: E402
from fir_gym.robustness.plan import PLANTS as PLANS  # noqa: E402
from fir_gym.wrappers.estimator_observation import EstimatorObservation  # noqa: E402
from fir_gym.wrappers.measurement_stack import MeasurementStack  # noqa: E402

P_DROP = 0.35
STEPS = 120
RTOL = 1e-9
#: one plant per filter kind (the first that has it): every (plant, kind) pair predicts
#: through lost readings in tests/jax/test_sensor_faults.py, dropout among the faults there
FILTER_CASES = [(env_id, kind) for i, (env_id, kind) in enumerate(filter_cases())
                if kind not in {k for _, k in filter_cases()[:i]}]


def _rollout(env: Any, params: Any, actions: np.ndarray, seed: int) -> list[Any]:
    """Open loop (the actions given): ``[(state, info)]``, the reset's first."""
    return [(state, info) for _, state, info in open_loop(env, params, actions, seed)]


def _episode(env_id: str, kind: str, options: dict[str, Any] | None = None) -> Any:
    plan = PLANS[env_id]
    env, params = make(env_id, kind, kind_kwargs=options or {},
                       sensor_faults={"dropout": P_DROP}, **plan.env_kwargs)
    clean_env, _ = make(env_id, kind, kind_kwargs=options or {}, **plan.env_kwargs)
    actions = np.random.default_rng(5).uniform(-1.2, 1.2, (STEPS, 1))
    run = _rollout(env, params, actions, seed=31)
    clean = _rollout(clean_env, params, actions, seed=31)
    return env, params, run, clean, actions


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_the_plant_is_untouched_and_the_reading_is_held(env_id: str) -> None:
    """With dropout the plant moves exactly as without (same keys): the draws are the fault
    stream's; the raw-measurement observation is the last delivered clean reading, ``H x0``
    (the model's ``H``, the plant's initial-state mean) before the first; about ``p`` of the
    readings are lost."""
    env, params, run, clean, _ = _episode(env_id, "measurement")
    assert len(run) == len(clean) > STEPS // 2
    held = np.asarray(env.first_hold(params))
    flags = []
    for (state, info), (ref, _) in zip(run, clean, strict=True):
        np.testing.assert_array_equal(np.asarray(state.x), np.asarray(ref.x))
        missing = bool(info["measurement_missing"])
        flags.append(missing)
        if not missing:
            held = np.asarray(ref.y)
        np.testing.assert_array_equal(np.asarray(state.y), held)
    n = len(flags)
    assert abs(np.mean(flags) - P_DROP) <= 4 * np.sqrt(P_DROP * (1 - P_DROP) / n)
    assert flags.count(True) > 0 and flags.count(False) > 0


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_the_stack_stacks_what_the_sensor_delivers(env_id: str) -> None:
    """The numpy ``MeasurementStack`` on the delivered readings (its env reads the sensor's
    output, a held reading included)."""
    env, _, run, _, _ = _episode(env_id, "measurement-stack")
    ys = np.array([np.asarray(s.y) for s, _ in run])
    applied = np.array([np.asarray(i["action"]) for _, i in run[1:]])
    numpy_env = MeasurementStack(replay(ys, applied), env.horizon)
    obs, _ = numpy_env.reset()
    for k, (state, _) in enumerate(run):
        if k:
            obs = numpy_env.step(applied[k - 1])[0]
        np.testing.assert_allclose(np.asarray(env.get_obs(state)), obs, rtol=0, atol=0)


@pytest.mark.parametrize("env_id,kind", FILTER_CASES)
def test_the_filter_predicts_through_a_lost_reading(env_id: str, kind: str) -> None:
    """Every filter kind (the plant's own and the generic ones) against the numpy env's
    filter fed ``None`` where the reading is missing: estimate and covariance to 1e-9 of
    their largest entry, NIS NaN on the missing steps and to 1e-9 (1 + NIS) elsewhere, the
    divergence flag exactly; a lost reading at the reset included (seeded so that one is)."""
    plan = PLANS[env_id]
    options = {**plan.estimator_kwargs.get(kind, {}), **TEST_OPTIONS.get(kind, {})}
    _, _, run, _, _ = _episode(env_id, kind, options)
    flags = [bool(i["measurement_missing"]) for _, i in run]
    ys = np.array([np.asarray(s.y) for s, _ in run])
    applied = np.array([np.asarray(i["action"]) for _, i in run[1:]])
    with_plant = gym.make(env_id, **plan.env_kwargs)
    numpy_env = EstimatorObservation(replay(ys, applied, with_plant.unwrapped, flags), kind,
                                     **options)
    with_plant.close()
    worst = compare_with_numpy_filter(run, numpy_env, flags)
    print(env_id, kind, f"{sum(flags)} of {len(flags)} readings lost", worst)
    assert flags[0] and sum(flags) > 1
    assert max(worst.values()) < RTOL, worst


def test_no_dropout_draws_nothing_and_a_bad_fault_is_refused() -> None:
    env, _ = make("fir_gym/Orbit-v0")
    assert env.dropout == 0.0 and not bool(env.reading_missing(jax.random.key(0)))
    with pytest.raises(ValueError, match="the sensor's faults are dropout, outliers"):
        make("fir_gym/Orbit-v0", sensor_faults={"dropout": 0.1, "jitter": 2})
    with pytest.raises(ValueError, match="dropout"):
        make("fir_gym/Orbit-v0", sensor_faults={"dropout": 1.5})
