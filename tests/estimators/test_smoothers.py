"""Fixed-interval smoothers (``smooth``): RTS for the KF and EKF, unscented RTS for the UKF.

Oracles: pykalman's robot data set ships a reference implementation's smoothed means and
covariances; filterpy's ``rts_smoother`` (linear) and ``UnscentedKalmanFilter.rts_smoother``
(nonlinear, on our filtered estimates: the backward pass alone); the smoother's defining
property that it uses the whole record (its last estimate is the filter's, its RMSE lower).
"""

from __future__ import annotations

import numpy as np
import pytest
from compiled_paths import needs_twins, numpy_path, on_path
from sequence_data import robot, tracking

from fir_gym.estimators import (
    ExtendedKalmanFilter,
    KalmanFilter,
    LinearModel,
    StateSpaceModel,
    UnscentedKalmanFilter,
)

filterpy = pytest.importorskip("filterpy.kalman")

SMOOTHERS = [KalmanFilter, ExtendedKalmanFilter, UnscentedKalmanFilter]


@pytest.mark.parametrize("cls", SMOOTHERS)
@pytest.mark.parametrize("path", ["compiled", "numpy"])
def test_smoother_equals_pykalmans_reference_on_the_robot_data(cls, path):
    model, d, ys, us = robot()
    flt = cls(model, x0=d["initial_state_mean"], P0=d["initial_state_covariance"])
    with on_path(path):
        res = flt.smooth(ys, us)
    tol = 1e-6 if cls is UnscentedKalmanFilter else 1e-9          # the UT's round-off
    np.testing.assert_allclose(res.x, d["smoothed_state_means"], rtol=tol, atol=tol)
    np.testing.assert_allclose(res.P, d["smoothed_state_covariances"], rtol=tol, atol=tol)
    np.testing.assert_allclose(res.filtered.x, d["filtered_state_means"], rtol=tol, atol=tol)
    np.testing.assert_array_equal(res.x[-1], res.filtered.x[-1])  # nothing after the last


def test_rts_equals_filterpys_rts_smoother_and_beats_the_filter():
    model, Y, _ = tracking(T=200, B=1)
    ys = Y[:, 0]
    kf = KalmanFilter(model, x0=[0.0, 0.0], P0=np.eye(2))
    res = kf.smooth(ys)
    T = len(ys)
    Xs, Ps, _, _ = filterpy.rts_smoother(res.filtered.x, res.filtered.P, [model.A] * T,
                                         [model.GQGT] * T)
    np.testing.assert_allclose(res.x, Xs, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res.P, Ps, rtol=1e-10, atol=1e-14)
    assert (np.trace(res.P, axis1=1, axis2=2) <= np.trace(res.filtered.P, axis1=1, axis2=2)
            + 1e-12).all()


def pendulum() -> StateSpaceModel:
    """A damped pendulum, the sine of the angle measured (both nonlinear)."""
    dt = 0.05

    def f(x, u):
        return np.stack([x[..., 0] + dt * x[..., 1],
                         0.99 * x[..., 1] - dt * 9.81 * np.sin(x[..., 0]) + dt * u[..., 0]], -1)

    def h(x):
        return np.stack([np.sin(x[..., 0]), x[..., 1]], -1)

    return StateSpaceModel(f=f, h=h, Q=np.diag([1e-5, 4e-3]), R=np.diag([0.02, 0.3]), dt=dt,
                           n_u=1)


def pendulum_data(T: int = 150, B: int = 2, seed: int = 4):
    model = pendulum()
    rng = np.random.default_rng(seed)
    x = np.array([[1.0, 0.0]] * B) + 0.1 * rng.normal(size=(B, 2))
    us = 0.5 * rng.normal(size=(T - 1, B, 1))
    xs, ys = [], []
    for k in range(T):
        xs.append(x)
        ys.append(model.h(x) + rng.normal(size=(B, 2)) * np.sqrt(np.diag(model.R)))
        if k < T - 1:
            x = model.f(x, us[k]) + rng.normal(size=(B, 2)) * np.sqrt(np.diag(model.Q))
    return model, np.stack(xs), np.stack(ys), us


@pytest.mark.parametrize("alpha", [1e-3, 0.5])
def test_unscented_rts_equals_filterpys_urts_on_a_nonlinear_model(alpha):
    model, _, Y, U = pendulum_data(B=1)
    ys, us = Y[:, 0], U[:, 0]
    ukf = UnscentedKalmanFilter(model, x0=[1.0, 0.0], P0=0.1 * np.eye(2), alpha=alpha)
    res = ukf.smooth(ys, us)
    points = filterpy.MerweScaledSigmaPoints(2, alpha=alpha, beta=2.0, kappa=0.0)
    step = {"k": 0}

    def fx(x, dt):                                 # filterpy's fx(x, dt): one point
        return model.f(x, us[step["k"]])

    fp = filterpy.UnscentedKalmanFilter(dim_x=2, dim_z=2, dt=model.dt, hx=model.h, fx=fx,
                                        points=points)
    fp.Q = np.array(model.GQGT)
    # filterpy's smoother passes dts[k] to fx: use it to carry the step index k
    fp.fx = lambda x, k: model.f(x, us[int(k)])
    Xs, Ps, _ = fp.rts_smoother(res.filtered.x, res.filtered.P, dts=np.arange(len(ys)))
    tol = 1e-7 if alpha < 0.01 else 1e-10
    np.testing.assert_allclose(res.x, Xs, rtol=tol, atol=tol)
    np.testing.assert_allclose(res.P, Ps, rtol=tol, atol=tol)


@pytest.mark.parametrize("cls", [ExtendedKalmanFilter, UnscentedKalmanFilter])
def test_nonlinear_smoothers_beat_their_filters_batched_equals_looped(cls):
    model, X, Y, U = pendulum_data(T=300, B=3)
    batch = cls(model, x0=[1.0, 0.0], P0=0.1 * np.eye(2)).smooth(Y, U)
    assert batch.x.shape == (300, 3, 2) and batch.P.shape == (300, 3, 2, 2)
    err_s = np.sqrt(np.mean((batch.x - X) ** 2))
    err_f = np.sqrt(np.mean((batch.filtered.x - X) ** 2))
    assert err_s < 0.8 * err_f
    for b in range(3):
        one = cls(model, x0=[1.0, 0.0], P0=0.1 * np.eye(2)).smooth(Y[:, b], U[:, b])
        np.testing.assert_allclose(batch.x[:, b], one.x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(batch.P[:, b], one.P, rtol=1e-9, atol=1e-14)


@needs_twins
@pytest.mark.parametrize("cls", SMOOTHERS)
def test_smoother_on_the_compiled_path_equals_the_numpy_path(cls):
    model, _, Y, U = pendulum_data(T=100, B=2)
    if cls is KalmanFilter:
        model = LinearModel(A=[[1.0, 0.05], [-0.5, 0.99]], C=np.eye(2), B=[[0.0], [0.05]],
                            Q=model.Q, R=model.R)
    kw = {"alpha": 1.0} if cls is UnscentedKalmanFilter else {}
    fast = cls(model, **kw).smooth(Y, U)
    with numpy_path():
        slow = cls(model, **kw).smooth(Y, U)
    # round-off relative to each array's scale (entries cross zero), as in test_compiled
    np.testing.assert_allclose(fast.x, slow.x, rtol=1e-9, atol=1e-9 * np.abs(slow.x).max())
    np.testing.assert_allclose(fast.P, slow.P, rtol=1e-9, atol=1e-9 * np.abs(slow.P).max())


@pytest.mark.parametrize("kind", ["kalman", "unscented"])
def test_smoothers_equal_stone_soups_on_a_constant_velocity_track(kind):
    """Stone Soup's ``KalmanSmoother`` / ``UnscentedKalmanSmoother`` over its own filter's
    track. Stone Soup predicts first: our prior is the one after its first prediction."""
    pytest.importorskip("stonesoup")
    import datetime

    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor, UnscentedKalmanPredictor
    from stonesoup.smoother.kalman import KalmanSmoother, UnscentedKalmanSmoother
    from stonesoup.types.array import StateVector
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater, UnscentedKalmanUpdater

    step = datetime.timedelta(seconds=1.0)
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.05)] * 2)
    sensor = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag([0.5, 0.5]))
    A, Qd, C = transition.matrix(time_interval=step), transition.covar(time_interval=step), \
        sensor.matrix()
    rng = np.random.default_rng(0)
    x, ys = np.array([0.0, 1.0, 0.0, 0.5]), []
    for _ in range(40):
        x = A @ x + rng.multivariate_normal(np.zeros(4), Qd)
        ys.append(C @ x + np.sqrt(0.5) * rng.normal(size=2))
    x0, P0 = np.zeros(4), 10.0 * np.eye(4)
    if kind == "kalman":
        predictor, updater, smoother = (KalmanPredictor(transition), KalmanUpdater(sensor),
                                        KalmanSmoother(transition))
    else:
        predictor, updater, smoother = (UnscentedKalmanPredictor(transition),
                                        UnscentedKalmanUpdater(sensor),
                                        UnscentedKalmanSmoother(transition))
    t0 = datetime.datetime(2026, 1, 1)
    state, track = GaussianState(StateVector(x0), P0, timestamp=t0), Track()
    for k, y in enumerate(ys):
        when = t0 + (k + 1) * step
        prediction = predictor.predict(state, timestamp=when)
        state = updater.update(SingleHypothesis(
            prediction, Detection(StateVector(y), timestamp=when, measurement_model=sensor)))
        track.append(state)
    theirs = smoother.smooth(track)
    want_x = np.array([np.asarray(s.state_vector, float).ravel() for s in theirs])
    want_P = np.array([np.asarray(s.covar, float) for s in theirs])
    model = LinearModel(A=A, C=C, Q=Qd, R=np.diag([0.5, 0.5]))
    # the UKF with Stone Soup's spread (alpha 0.5): the default 1e-3 weighs round-off by 1e6
    flt = (KalmanFilter(model, x0=A @ x0, P0=A @ P0 @ A.T + Qd) if kind == "kalman" else
           UnscentedKalmanFilter(model, x0=A @ x0, P0=A @ P0 @ A.T + Qd, alpha=predictor.alpha))
    ours = flt.smooth(np.array(ys))
    np.testing.assert_allclose(ours.x, want_x, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(ours.P, want_P, rtol=1e-10, atol=1e-10)
