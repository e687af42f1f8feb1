"""A known sensor delay (estimators/delay.py): the lagged filter is the undelayed one fed the
sequence d steps late, the estimate is the model's d-step prediction from it, the first d
steps carry no measurement, restarted systems wait their own d steps; refusals, copies,
and the delay through the sensor-fault wrapper."""

from __future__ import annotations

import copy
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from compiled_paths import TWINS, step_on
from plant_cases import applicable

import fir_gym  # noqa: F401  (registers the ids)
from fir_gym.estimators import (
    LinearModel,
    TimeVaryingLinearModel,
    estimator_class,
    make_estimator,
)
from fir_gym.wrappers import EstimatorObservation, SensorFaults
from fir_gym.wrappers.estimator_observation import build_estimator

CASES = [(env_id, name) for env_id, name in applicable() if name != "fir-smoother"]
PATHS = [True, False] if TWINS else [False]


def _episode(env_id, steps=40, seed=0):
    """Measurements, applied inputs and true states of one episode under a slow sine input."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(env_id)
    y, info = env.reset(seed=seed)
    ys, us, xs = [y], [], [info["state"]]
    for k in range(steps):
        y, _, term, trunc, info = env.step(np.full(env.action_space.shape, 0.3 * np.sin(0.2 * k),
                                                   dtype=np.float32))
        ys.append(y)
        us.append(info["action"])
        xs.append(info["state"])
        if term or trunc:
            break
    return env, ys, us, xs


def _build(env, name, **options):
    """``name`` built for the plant as the wrappers build it (its prior, its horizon)."""
    plant = env.unwrapped
    return build_estimator(estimator_class(name), lambda a: getattr(plant, a, None), options)


@pytest.mark.parametrize(("env_id", "name"), CASES)
@pytest.mark.parametrize("twin", PATHS)
def test_the_lagged_filter_is_the_undelayed_one_fed_d_steps_late(env_id, name, twin):
    env, ys, us, _ = _episode(env_id)
    d = 3
    delayed = _build(env, name, delay=d)
    reference = _build(env, name)
    for k in range(len(ys)):
        step_on(delayed, twin, ys[k - d] if k >= d else None, us[k - 1] if k >= 1 else None)
        if k >= d:
            j = k - d
            expected = step_on(reference, twin, ys[j], us[j - 1] if j >= 1 else None)
            np.testing.assert_array_equal(delayed.last_info["delayed_estimate"], expected)


@pytest.mark.parametrize(("env_id", "name"), CASES)
def test_the_estimate_is_the_models_d_step_prediction(env_id, name):
    """From the lagged estimate and covariance, d applications of the model's f (and
    F P Fᵀ + G Q Gᵀ), one system, looped by hand."""
    env, ys, us, _ = _episode(env_id)
    d = 2
    est = _build(env, name, delay=d)
    model = est.model
    lagged = _build(env, name)
    for k in range(len(ys)):
        x_ahead = est.step(ys[k - d] if k >= d else None, us[k - 1] if k >= 1 else None)
        if k >= d:
            j = k - d
            x = lagged.step(ys[j], us[j - 1] if j >= 1 else None)
            P = lagged.P
        else:
            x, P = est._x0.copy(), est._P0.copy()
        for u in us[max(0, k - d):k]:
            F = model.F(x, u)
            x = model.f(x, u)
            if P is not None:
                P = F @ P @ F.T + model.GQGT
        np.testing.assert_allclose(x_ahead, x, rtol=1e-12, atol=1e-12)
        if P is not None:
            np.testing.assert_allclose(est.P, P, rtol=1e-10, atol=1e-12)


def test_a_measurement_before_anything_can_arrive_is_refused():
    env, ys, us, _ = _episode("fir_gym/Orbit-v0")
    est = _build(env, "ekf", delay=2)
    est.step(None)
    with pytest.raises(ValueError, match=r"y: with delay=2"):
        est.step(ys[0], us[0])


def test_restarted_systems_wait_their_own_d_steps():
    """A batch of two: system 1 restarts at step 6; each system equals a single delayed
    filter fed its own stream (system 1's from its restart)."""
    env, ys, us, _ = _episode("fir_gym/Orbit-v0", steps=30)
    d = 2
    batch = _build(env, "ekf", delay=d)
    first, second = _build(env, "ekf", delay=d), _build(env, "ekf", delay=d)
    restart = 6
    for k in range(len(ys)):
        if k == restart:
            batch.restart([1])
        k1 = k - restart if k >= restart else k
        rows = [ys[kk - d] if kk >= d else None for kk in (k, k1)]
        Y = np.ma.masked_array([r if r is not None else [0.0] for r in rows],
                               mask=[[r is None] for r in rows])
        u = np.array([us[k - 1] if k >= 1 else [0.0], us[k - 1] if k >= 1 else [0.0]])
        x = batch.step(Y, u if k >= 1 else None)
        x0 = first.step(rows[0], us[k - 1] if k >= 1 else None)
        if k >= restart:
            # a fresh filter's first step has no input, as the restarted system's
            x1 = second.step(rows[1], us[k - 1] if k > restart else None)
            np.testing.assert_allclose(x[1], x1, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(x[0], x0, rtol=1e-13, atol=1e-13)


def test_delay_is_refused_where_it_cannot_work():
    model = LinearModel(A=np.eye(2), C=np.array([[1.0, 0.0]]), Q=np.eye(2), R=np.eye(1))
    for bad in (-1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="delay"):
            make_estimator("kf", model, delay=bad)
    varying = TimeVaryingLinearModel(A=lambda k: np.eye(2), C=np.array([[1.0, 0.0]]),
                                     Q=np.eye(2), R=np.eye(1))
    with pytest.raises(ValueError, match="time-invariant"):
        make_estimator("kf", varying, delay=1)
    kf = make_estimator("kf", model, delay=1)
    with pytest.raises(ValueError, match="predict"):
        kf.predict()
    with pytest.raises(ValueError, match="update"):
        kf.update(np.zeros(1))
    with pytest.raises(ValueError, match="smooth"):
        kf.smooth(np.zeros((5, 1)))


def test_copies_mid_run_continue_identically():
    env, ys, us, _ = _episode("fir_gym/Orbit-v0")
    d = 3
    est = _build(env, "ukf", delay=d)
    for k in range(10):
        est.step(ys[k - d] if k >= d else None, us[k - 1] if k >= 1 else None)
    twins = [copy.deepcopy(est), pickle.loads(pickle.dumps(est))]
    ours = [est.step(ys[k - d], us[k - 1]) for k in range(10, 20)]
    for twin in twins:
        theirs = [twin.step(ys[k - d], us[k - 1]) for k in range(10, 20)]
        np.testing.assert_array_equal(np.array(ours), np.array(theirs))


def test_through_the_sensor_wrapper_the_estimator_is_told_the_delay():
    """gym.make(id, sensor_faults={'delay': d}, estimator=...) delivers y[k − d] and the
    estimator, told the delay, lags the undelayed filter fed the clean sequence d steps late."""
    d = 2
    env = EstimatorObservation(SensorFaults(gym.make("fir_gym/Orbit-v0"), delay=d), "ekf",
                               delay=d)
    reference = EstimatorObservation(gym.make("fir_gym/Orbit-v0"), "ekf").estimator
    _, info = env.reset(seed=3)
    clean, actions = [info["clean_measurement"]], []
    for k in range(1, 25):
        _, _, _, _, info = env.step(np.array([0.1], dtype=np.float32))
        clean.append(info["clean_measurement"])
        actions.append(info["action"])
        if k >= d:
            j = k - d
            expected = reference.step(clean[j], actions[j - 1] if j >= 1 else None)
            np.testing.assert_array_equal(info["estimator_info"]["delayed_estimate"], expected)


@pytest.mark.parametrize("name", ["kf", "ekf", "ukf", "fir", "efir"])
def test_a_gated_outlier_under_a_delay_is_a_missing_reading(name):
    """delay and gate together: a 100σ outlier among the delayed readings leaves the delayed,
    gated filter exactly where a delayed filter fed that reading as missing ends."""
    env, ys, us, _ = _episode("fir_gym/CarrierMotion-v0")
    d, hit = 2, 15
    gated, twin = _build(env, name, delay=d, gate=0.999), _build(env, name, delay=d, gate=0.999)
    sigma = float(np.sqrt(env.unwrapped.measurement_cov[0, 0]))
    for k in range(len(ys)):
        y = ys[k - d] if k >= d else None
        u = us[k - 1] if k >= 1 else None
        outlier = y + 100 * sigma if k == hit else y
        a = gated.step(outlier, u)
        b = twin.step(None if k == hit else y, u)
        np.testing.assert_array_equal(a, b)
        if k == hit:
            assert gated.last_info["gated"]
    assert gated.last_info["gated_count"] == 1
