"""SensorFaults and VectorSensorFaults: each fault against what it must do, missing readings
reaching the estimator as missing, one seed one faulty episode single and vectorised,
checks, copies and refusals (docs/robustness.md#sensor-faults)."""

from __future__ import annotations

import copy
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from plant_cases import applicable

import fir_gym
from fir_gym.wrappers import (
    EstimatorObservation,
    SensorFaults,
    VectorEstimatorObservation,
    VectorSensorFaults,
)
from fir_gym.wrappers.faulty_sensor import FLAGS

ORBIT = "fir_gym/Orbit-v0"


def plant(env_id=ORBIT, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make(env_id, **kwargs)


def rollout(env, steps, seed=0, action=0.2):
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for _ in range(steps):
        obs, _, term, trunc, info = env.step(np.array([action], dtype=np.float32))
        out.append((obs, info))
        if term or trunc:
            break
    return out


def test_no_fault_is_the_plain_plant():
    a = rollout(plant(), 30, seed=4)
    b = rollout(SensorFaults(plant()), 30, seed=4)
    for (oa, _), (ob, ib) in zip(a, b, strict=True):
        np.testing.assert_array_equal(oa, ob)
        assert ib["measurement_missing"] is False
        assert not any(ib["sensor_faults"].values())


def test_delay_delivers_the_measurement_of_d_steps_before():
    d = 3
    steps = rollout(SensorFaults(plant(), delay=d), 25, seed=1)
    clean = [info["clean_measurement"] for _, info in steps]
    for k, (obs, info) in enumerate(steps):
        if k < d:
            assert info["measurement_missing"] and info["sensor_faults"]["late"]
        else:
            assert not info["measurement_missing"]
            np.testing.assert_array_equal(obs, clean[k - d])


def test_every_samples_at_the_multiples_and_holds_in_between():
    every = 4
    steps = rollout(SensorFaults(plant(), every=every), 21, seed=2)
    last = None
    for k, (obs, info) in enumerate(steps):
        due = k % every == 0
        assert info["measurement_missing"] is (not due)
        assert info["sensor_faults"]["unsampled"] is (not due)
        if due:
            np.testing.assert_array_equal(obs, info["clean_measurement"])
            last = obs
        else:
            np.testing.assert_array_equal(obs, last)      # the held reading, never NaN


def test_bias_is_added_from_its_step_and_reaches_the_filter_as_a_number():
    k_bias, value = 6, 0.7
    for k, (obs, info) in enumerate(rollout(SensorFaults(plant(), bias=(k_bias, value)), 15)):
        expected = info["clean_measurement"] + (value if k >= k_bias else 0.0)
        np.testing.assert_array_equal(obs, expected)
        assert info["sensor_faults"]["biased"] is (k >= k_bias)
        assert info["measurement_missing"] is False


def test_full_dropout_makes_every_reading_missing():
    for obs, info in rollout(SensorFaults(plant(), dropout=1.0), 20):
        assert info["measurement_missing"] and info["sensor_faults"]["dropped"]
        assert np.all(np.isfinite(obs))


def test_outliers_have_the_stated_size_and_frequency():
    """Over many steps: the hit fraction within a binomial bound of p, and the hits' errors
    with the standard deviation scale·√R (a χ² bound on the sample variance)."""
    p, scale = 0.3, 20.0
    env = SensorFaults(plant(max_episode_steps=1000), outliers=(p, scale))
    steps = rollout(env, 999, seed=3)
    hits = np.array([info["sensor_faults"]["outlier"] for _, info in steps])
    n = len(hits)
    assert abs(hits.mean() - p) < 4 * np.sqrt(p * (1 - p) / n)
    errors = np.array([obs - info["clean_measurement"] for obs, info in steps])[hits, 0]
    sigma = scale * np.sqrt(env.unwrapped.measurement_cov[0, 0])
    ratio = np.var(errors) / sigma**2
    m = len(errors)
    assert abs(ratio - 1) < 5 * np.sqrt(2 / m)
    clean = np.array([obs - info["clean_measurement"] for obs, info in steps])[~hits]
    assert np.all(clean == 0)


def test_stuck_sensor_is_detected_and_lasts_as_documented():
    """A stuck reading is missing; stuck runs last 1/release steps on average (geometric)."""
    p, mean_steps = 0.02, 8.0
    env = SensorFaults(plant(max_episode_steps=1000), stuck=(p, mean_steps))
    runs, current, stuck_steps = [], 0, 0
    for seed in range(3):
        for _, info in rollout(env, 999, seed=seed):
            stuck = info["sensor_faults"]["stuck"]
            assert info["measurement_missing"] is stuck
            stuck_steps += stuck
            if stuck:
                current += 1
            elif current:
                runs.append(current)
                current = 0
    assert len(runs) > 20
    # geometric with mean 8: the sample mean within four standard errors
    assert abs(np.mean(runs) - mean_steps) < 4 * np.sqrt(mean_steps * (mean_steps - 1)
                                                         / len(runs))


CASES = [(env_id, name) for env_id, name in applicable() if name != "fir-smoother"]


@pytest.mark.parametrize(("env_id", "name"), CASES)
def test_full_dropout_makes_every_filter_predict_only(env_id, name):
    """With every reading dropped, the estimator in the loop equals a twin stepped with no
    measurement at all (predictions only), step by step — on every plant and filter; the
    recursive FIR filter, which needs every measurement, refuses instead."""
    env = EstimatorObservation(SensorFaults(plant(env_id), dropout=1.0), name)
    estimator = env.get_wrapper_attr("estimator")
    twin = copy.deepcopy(estimator)
    if not estimator.accepts_missing:
        with pytest.raises(ValueError, match="needs every measurement"):
            env.reset(seed=0)
        return
    x_hat, info = env.reset(seed=0)
    np.testing.assert_array_equal(x_hat, twin.step(None))
    for _ in range(10):
        x_hat, _, term, trunc, info = env.step(np.zeros(env.action_space.shape,
                                                        dtype=np.float32))
        np.testing.assert_array_equal(x_hat, twin.step(None, info["action"]))
        if term or trunc:
            break
    if estimator.provides_covariance:
        np.testing.assert_array_equal(estimator.P, twin.P)


def test_dropped_readings_in_a_vector_env_are_masked_per_system():
    venv = gym.make_vec(ORBIT, 4, vectorization_mode="vector_entry_point", generators="per_env")
    faulty = VectorEstimatorObservation(VectorSensorFaults(venv, dropout=0.5), "ekf")
    faulty.reset(seed=10)
    estimator = faulty.estimator
    twin = copy.deepcopy(estimator)
    seen_missing = seen_present = False
    for _ in range(12):
        _, _, _, _, info = faulty.step(np.full((4, 1), 0.1, dtype=np.float32))
        missing = info["measurement_missing"]
        seen_missing |= bool(missing.any())
        seen_present |= bool((~missing).any())
        Y = np.ma.masked_array(info["clean_measurement"], mask=missing[:, None])
        np.testing.assert_array_equal(estimator.x, twin.step(Y, info["action"]))
    assert seen_missing and seen_present


@pytest.mark.parametrize("faults", [{"dropout": 0.3}, {"outliers": (0.2, 10.0)},
                                    {"stuck": 0.1}, {"bias": (5, 0.4)}, {"delay": 2},
                                    {"every": 3},
                                    {"dropout": 0.2, "delay": 1, "every": 2,
                                     "outliers": (0.1, 5.0), "stuck": (0.05, 4)}])
def test_vector_sub_env_i_sees_the_faults_of_a_single_env_seeded_s_plus_i(faults):
    n, seed = 3, 20
    venv = gym.make_vec(ORBIT, n, vectorization_mode="vector_entry_point", generators="per_env",
                        max_episode_steps=15)
    wrapped = VectorSensorFaults(venv, **faults)
    obs, info = wrapped.reset(seed=seed)
    vec = [(obs, info["measurement_missing"])]
    for _ in range(32):           # through two autoresets
        obs, _, _, _, info = wrapped.step(np.full((n, 1), 0.2, dtype=np.float32))
        vec.append((obs, info["measurement_missing"]))
    for i in range(n):
        env = SensorFaults(plant(max_episode_steps=15), **faults)
        obs, info = env.reset(seed=seed + i)
        single = [(obs, info["measurement_missing"])]
        done = False
        for _ in range(32):
            if done:
                obs, info = env.reset()
                done = False
            else:
                obs, _, term, trunc, info = env.step(np.array([0.2], dtype=np.float32))
                done = term or trunc
            single.append((obs, info["measurement_missing"]))
        for (vo, vm), (so, sm) in zip(vec, single, strict=True):
            np.testing.assert_array_equal(vo[i], so)
            assert bool(vm[i]) is sm


def test_same_step_autoreset_reads_the_last_reading_then_the_first():
    """In same-step mode the ended episodes' last readings go through their sensors before
    the sensors restart: final_obs and the new first reading are both faulted readings."""
    from gymnasium.vector import AutoresetMode

    venv = gym.make_vec(ORBIT, 2, vectorization_mode="vector_entry_point", generators="per_env",
                        max_episode_steps=5, autoreset_mode=AutoresetMode.SAME_STEP)
    wrapped = VectorSensorFaults(venv, delay=2)
    wrapped.reset(seed=0)
    for _ in range(5):
        _, _, _, trunc, info = wrapped.step(np.zeros((2, 1), dtype=np.float32))
    assert np.all(trunc)
    # the new episode's first reading is late (delay 2): missing, the prior's reading held
    assert np.all(info["measurement_missing"])
    assert np.all(info["final_info"]["measurement_missing"] == np.array([False, False]))


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
@pytest.mark.parametrize("faults", [{"dropout": 0.3}, {"outliers": (0.1, 20.0)},
                                    {"stuck": 0.05}, {"bias": (3, 1.0)}, {"delay": 2},
                                    {"every": 3}])
def test_every_sensor_fault_on_every_plant_passes_check_env(env_id, faults):
    env = SensorFaults(plant(env_id), **faults)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(env, skip_render_check=True)


def test_copies_mid_episode_continue_identically():
    env = SensorFaults(plant(), dropout=0.3, outliers=(0.2, 5.0), stuck=0.1, delay=2, every=2)
    env.reset(seed=5)
    for _ in range(6):
        env.step(np.array([0.1], dtype=np.float32))
    twins = [copy.deepcopy(env), pickle.loads(pickle.dumps(env))]
    ours = [env.step(np.array([0.3], dtype=np.float32)) for _ in range(8)]
    for twin in twins:
        theirs = [twin.step(np.array([0.3], dtype=np.float32)) for _ in range(8)]
        for a, b in zip(ours, theirs, strict=True):
            np.testing.assert_array_equal(a[0], b[0])
            assert a[4]["sensor_faults"] == b[4]["sensor_faults"]


def test_flags_are_reported_every_step():
    for _, info in rollout(SensorFaults(plant(), dropout=0.2), 5):
        assert set(info["sensor_faults"]) == set(FLAGS)


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"dropout": 1.5}, "dropout"), ({"dropout": "x"}, "dropout"),
    ({"outliers": 0.1}, "outliers"), ({"outliers": (0.1, -1.0)}, "outliers"),
    ({"stuck": (0.1, 0.5)}, "stuck"), ({"bias": (2,)}, "bias"),
    ({"bias": (2, [1.0, 2.0])}, "bias"), ({"bias": (-1, 1.0)}, "bias"),
    ({"delay": 1000}, "delay"), ({"delay": -1}, "delay"), ({"delay": 1.5}, "delay"),
    ({"every": 0}, "every"), ({"every": 1000}, "every")])
def test_bad_arguments_are_refused_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name):
        SensorFaults(plant(), **kwargs)


def test_gym_make_puts_the_sensor_between_plant_and_estimator_and_tells_it_the_delay():
    env = plant(ORBIT, estimator="ekf", sensor_faults={"delay": 2})
    chain = []
    while isinstance(env, gym.Wrapper):
        chain.append(type(env))
        env = env.env
    assert chain.index(EstimatorObservation) < chain.index(SensorFaults)
    built = plant(ORBIT, estimator="ekf", sensor_faults={"delay": 2})
    assert built.get_wrapper_attr("estimator").delay == 2
