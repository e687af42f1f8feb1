"""The JAX sensor's faults beyond dropout: ``outliers``, ``bias``, ``every`` and ``stuck``
(``fir_gym.jax.make(..., sensor_faults={...})``), all at once with dropout.

Oracles: the same env without faults on the same keys (the plant must move exactly as
without them: every fault draw comes from the key's fault stream), the numpy sensor's rules
written out here (:mod:`fir_gym.wrappers.faulty_sensor`: the bias from its step on, an outlier
of ``scale`` standard deviations — its normals recomputed from the documented stream — the
multi-rate sensor's samples at ``k = 0, every, 2·every, …``, the stuck sensor's two-state
chain replayed from its uniforms, the hold of a missing reading),
the outliers' law over many readings, and the numpy env's own
:class:`~fir_gym.wrappers.EstimatorObservation` replaying the delivered readings with their
missing flags — every plant's filter kinds fed the biased and contaminated numbers as the
numpy filter is fed them, ``None`` where a reading is missing.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402
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
from fir_gym.wrappers.faulty_sensor import FAULT_STREAM  # noqa: E402

STEPS = 120
BIAS_STEP = 40
P_OUT, SCALE = 0.2, 6.0
EVERY = 3
P_DROP = 0.2
P_STUCK, STUCK_STEPS = 0.1, 3.0
RTOL = 1e-9
FILTER_CASES = filter_cases()


def faults(env_id: str) -> dict[str, Any]:
    n_y = PLANTS[env_id].env_class.n_y
    return {"dropout": P_DROP, "outliers": (P_OUT, SCALE), "every": EVERY,
            "bias": (BIAS_STEP, list(np.linspace(0.5, 1.5, n_y))),
            "stuck": (P_STUCK, STUCK_STEPS)}


def _episode(env_id: str, kind: str, options: dict[str, Any] | None = None) -> Any:
    plan = PLANS[env_id]
    env, params = make(env_id, kind, kind_kwargs=options or {},
                       sensor_faults=faults(env_id), **plan.env_kwargs)
    clean_env, _ = make(env_id, kind, kind_kwargs=options or {}, **plan.env_kwargs)
    actions = np.random.default_rng(5).uniform(-1.2, 1.2, (STEPS, 1))
    return env, params, open_loop(env, params, actions, 7), open_loop(clean_env, params,
                                                                      actions, 7)


@pytest.mark.parametrize("env_id", list(PLANTS))
def test_the_sensor_biases_contaminates_and_samples_as_the_numpy_one(env_id: str) -> None:
    env, params, run, clean = _episode(env_id, "measurement")
    assert len(run) == len(clean) > STEPS // 2
    spec = faults(env_id)
    bias = np.asarray(spec["bias"][1])
    root = np.asarray(env.measurement_noise_sqrt(params))
    np.testing.assert_allclose(root @ root.T, np.atleast_2d(_true_measurement_cov(env_id)),
                               rtol=1e-12)
    held = np.asarray(env.first_hold(params))
    seen_outliers, was_stuck, stuck_steps = 0, False, 0
    for k, ((key, state, info), (_, ref, _)) in enumerate(zip(run, clean, strict=True)):
        np.testing.assert_array_equal(np.asarray(state.x), np.asarray(ref.x))   # untouched
        flags = {name: bool(v) for name, v in info["sensor_faults"].items()}
        stream = jax.random.fold_in(key, FAULT_STREAM)
        assert flags["unsampled"] == (k % EVERY != 0)
        assert flags["biased"] == (k >= BIAS_STEP)
        assert flags["dropped"] == bool(jax.random.uniform(stream, dtype=jnp.float64) < P_DROP)
        u = jax.random.uniform(jax.random.fold_in(stream, 1), dtype=jnp.float64)
        assert flags["outlier"] == bool(u < P_OUT)
        u = float(jax.random.uniform(jax.random.fold_in(stream, 3), dtype=jnp.float64))
        was_stuck = u >= 1.0 / STUCK_STEPS if was_stuck else u < P_STUCK   # the chain
        assert flags["stuck"] == was_stuck == bool(state.sensor_stuck)
        stuck_steps += was_stuck
        missing = flags["dropped"] or flags["unsampled"] or flags["stuck"]
        assert bool(info["measurement_missing"]) == missing
        expected = np.asarray(ref.y) + (bias if flags["biased"] else 0.0)
        if flags["outlier"]:
            z = np.asarray(jax.random.normal(jax.random.fold_in(stream, 2),
                                             (env.n_y,), jnp.float64))
            expected = expected + SCALE * root @ z
            seen_outliers += 1
        if not missing:
            held = expected
        np.testing.assert_allclose(np.asarray(state.y), held, rtol=1e-14, atol=1e-14)
    assert seen_outliers > 0 and 0 < stuck_steps < len(run) // 2


def _true_measurement_cov(env_id: str) -> np.ndarray:
    """The numpy plant's own ``measurement_cov`` (what its sensor's outliers scale by)."""
    plant = gym.make(env_id, **PLANS[env_id].env_kwargs).unwrapped
    return np.asarray(plant.measurement_cov, dtype=np.float64)


def test_the_outliers_have_the_documented_law() -> None:
    """Over 20 000 readings of Orbit-v0 (no other fault): the outliers' frequency within
    four standard errors of ``p``, and their size over ``scale · √R`` standard normal
    (mean and variance within four standard errors)."""
    env, params = make("fir_gym/Orbit-v0", "measurement",
                       sensor_faults={"outliers": (P_OUT, SCALE)})
    keys = jax.random.split(jax.random.key(3), 20_000)
    readings = jax.vmap(lambda key: env.sensor_reading(key, 5, params))(keys)
    hit = np.asarray(readings.outlier)
    n = hit.size
    assert abs(hit.mean() - P_OUT) <= 4 * np.sqrt(P_OUT * (1 - P_OUT) / n)
    z = np.asarray(readings.offset)[hit, 0] / (SCALE * np.sqrt(params.R))
    assert np.all(np.asarray(readings.offset)[~hit] == 0.0)
    assert abs(z.mean()) <= 4 / np.sqrt(z.size) and abs(z.var() - 1) <= 4 * np.sqrt(2 / z.size)
    assert not np.asarray(readings.missing).any()


@pytest.mark.parametrize("env_id,kind", FILTER_CASES)
def test_the_filters_read_what_the_faulty_sensor_delivers(env_id: str, kind: str) -> None:
    """Every filter kind against the numpy env's filter replaying the delivered readings —
    biased, contaminated, held — with ``None`` where missing: the estimate to 1e-9 of the
    larger of its largest entry and its largest standard deviation (CarrierMotion-v0's starts
    at 0 and the multi-rate sensor's first step is a prediction: an estimate of 1e-18 against
    3e-18, round-off of zero, is no 100 % error), the covariance to 1e-9 of its largest entry,
    NIS to 1e-9 (1 + NIS) and NaN where missing, the divergence flag exactly."""
    plan = PLANS[env_id]
    options = {**plan.estimator_kwargs.get(kind, {}), **TEST_OPTIONS.get(kind, {})}
    _, _, run, _ = _episode(env_id, kind, options)
    flags = [bool(i["measurement_missing"]) for _, _, i in run]
    outliers = sum(bool(i["sensor_faults"]["outlier"]) for _, _, i in run)
    ys = np.array([np.asarray(s.y) for _, s, _ in run])
    applied = np.array([np.asarray(i["action"]) for _, _, i in run[1:]])
    with_plant = gym.make(env_id, **plan.env_kwargs)
    numpy_env = EstimatorObservation(replay(ys, applied, with_plant.unwrapped, flags), kind,
                                     **options)
    with_plant.close()
    worst = compare_with_numpy_filter([(s, i) for _, s, i in run], numpy_env, flags,
                                      std_floor=True)
    print(env_id, kind, f"{sum(flags)} of {len(flags)} missing, {outliers} outliers", worst)
    assert len(flags) // 2 < sum(flags) < len(flags) and outliers > 0
    assert max(worst.values()) < RTOL, worst


def test_what_the_jax_sensor_lacks_or_refuses_is_one_line() -> None:
    with pytest.raises(ValueError, match=r"sensor_faults names \['jitter'\]; the sensor's faults "
                                         r"are dropout, outliers, bias, every, stuck, delay"):
        make("fir_gym/Orbit-v0", sensor_faults={"dropout": 0.1, "jitter": 2})
    with pytest.raises(ValueError, match="delay=1000 is not shorter than an episode"):
        make("fir_gym/Orbit-v0", sensor_faults={"delay": 1000})
    with pytest.raises(ValueError, match="stuck's mean number of steps must be >= 1"):
        make("fir_gym/Orbit-v0", sensor_faults={"stuck": (0.1, 0.5)})
    with pytest.raises(ValueError, match="outliers' scale must be a positive"):
        make("fir_gym/Orbit-v0", sensor_faults={"outliers": (0.1, -1.0)})
    with pytest.raises(ValueError, match="every=1000 is not shorter than an episode"):
        make("fir_gym/Orbit-v0", sensor_faults={"every": 1000})
    with pytest.raises(ValueError, match="bias' value must be"):
        make("fir_gym/PendulumSlider-v0", sensor_faults={"bias": (3, [1.0, 2.0])})
    env, params = make("fir_gym/Orbit-v0")            # no fault: nothing drawn, nothing added
    reading = env.sensor_reading(jax.random.key(0), 4, params)
    assert not bool(reading.missing) and np.all(np.asarray(reading.offset) == 0.0)


def test_a_faulty_env_survives_deepcopy_and_pickle() -> None:
    """The copies deliver the same readings on the same keys (the faults are part of the
    env, not of a generator it holds)."""
    import copy
    import pickle

    env, params = make("fir_gym/UncertainOscillator-v0", "ekf",
                       sensor_faults=faults("fir_gym/UncertainOscillator-v0"))
    actions = np.zeros((30, 1))
    want = [np.asarray(s.y) for _, s, _ in open_loop(env, params, actions, 2)]
    for other in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        assert other.faults.describe() == env.faults.describe()
        got = [np.asarray(s.y) for _, s, _ in open_loop(other, params, actions, 2)]
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)
