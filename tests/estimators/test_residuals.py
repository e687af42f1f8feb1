"""Residual and mean hooks of a model: a bearing that crosses ±π.

Oracles: Stone Soup's extended Kalman predictor/updater (whose ``Bearing`` type wraps angles)
on the same measurements; the plain unscented sums (hooks that are the identity must change
nothing); the truth (the error stays at the sensor-noise level only with the hooks).
"""

from __future__ import annotations

import datetime

import numpy as np
import pytest

from fir_gym.estimators import ExtendedKalmanFilter, StateSpaceModel, UnscentedKalmanFilter

DT, T = 1.0, 40
A = np.array([[1, DT, 0, 0], [0, 1, 0, 0], [0, 0, 1, DT], [0, 0, 0, 1]], dtype=float)
Q1 = np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]])
R = np.diag([0.01**2, 1.0**2])                    # bearing (rad), range (m)


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def residual_y(a, b):
    d = np.asarray(a) - np.asarray(b)
    return np.concatenate([wrap(d[..., :1]), d[..., 1:]], axis=-1)


def circular_mean_y(Z, w):
    s = np.einsum("n,bn->b", w, np.sin(Z[..., 0]))
    c = np.einsum("n,bn->b", w, np.cos(Z[..., 0]))
    return np.stack([np.arctan2(s, c), np.einsum("n,bn->b", w, Z[..., 1])], axis=-1)


def h(x):
    return np.stack([np.arctan2(x[..., 2], x[..., 0]), np.hypot(x[..., 0], x[..., 2])], -1)


def H(x):
    px, py = x[..., 0], x[..., 2]
    r2 = px**2 + py**2
    r = np.sqrt(r2)
    J = np.zeros((*x.shape[:-1], 2, 4))
    J[..., 0, 0], J[..., 0, 2] = -py / r2, px / r2
    J[..., 1, 0], J[..., 1, 2] = px / r, py / r
    return J


def bearing_model(q: float = 0.01, **hooks) -> StateSpaceModel:
    Qd = q * np.block([[Q1, np.zeros((2, 2))], [np.zeros((2, 2)), Q1]])
    return StateSpaceModel(f=lambda x, u: x @ A.T, h=h, H=H, F=lambda x, u: np.broadcast_to(
        A, (*x.shape[:-1], 4, 4)), Q=Qd, R=R, dt=DT, **hooks)


def crossing_track(seed: int = 0):
    """A target passing behind the sensor along the negative x axis: its bearing jumps from
    +π to −π half-way."""
    rng = np.random.default_rng(seed)
    x = np.array([-100.0, 0.0, 50.0, -2.5])
    xs, ys = [], []
    for _ in range(T):
        xs.append(x)
        ys.append(h(x) + rng.normal(size=2) * np.sqrt(np.diag(R)))
        x = A @ x + rng.normal(size=4) * 0.02
    ys = np.array(ys)
    ys[:, 0] = wrap(ys[:, 0])                      # a sensor reports bearings in [−π, π)
    return np.array(xs), ys


PRIOR = (np.array([-100.0, 0.0, 50.0, -2.5]), np.diag([25.0, 1.0, 25.0, 1.0]))


def run(flt, ys):
    out = []
    for y in ys:                                   # predict first, as Stone Soup does
        flt.predict()
        out.append(flt.update(y))
    return np.array(out)


def test_bearing_crossing_pi_without_hooks_breaks_the_ekf_and_with_them_matches_stone_soup():
    ss = pytest.importorskip("stonesoup")  # noqa: F841
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.types.angle import Bearing
    from stonesoup.types.array import StateVector
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    truth, ys = crossing_track()
    assert np.ptp(ys[:, 0]) > 6.0                       # the bearing does cross ±π
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.01)] * 2)
    sensor = CartesianToBearingRange(ndim_state=4, mapping=(0, 2), noise_covar=R)
    predictor, updater = ExtendedKalmanPredictor(transition), ExtendedKalmanUpdater(sensor)
    t0 = datetime.datetime(2026, 1, 1)
    state = GaussianState(StateVector(PRIOR[0]), PRIOR[1], timestamp=t0)
    stone = []
    for k, y in enumerate(ys):
        when = t0 + datetime.timedelta(seconds=DT * (k + 1))
        pred = predictor.predict(state, timestamp=when)
        det = Detection(StateVector([Bearing(y[0]), y[1]]), timestamp=when,
                        measurement_model=sensor)
        state = updater.update(SingleHypothesis(pred, det))
        stone.append(np.asarray(state.state_vector, dtype=float).ravel())
    stone = np.array(stone)
    # ys[k] measures truth[k]; both filters predict first (the prior is of the state before
    # the first measurement), so the k-th estimate is of truth[k]
    plain = run(ExtendedKalmanFilter(bearing_model(), x0=PRIOR[0], P0=PRIOR[1]), ys)
    hooked = run(ExtendedKalmanFilter(bearing_model(residual_y=residual_y), x0=PRIOR[0],
                                      P0=PRIOR[1]), ys)
    # Stone Soup's measurement Jacobian is a forward difference (step 1e-8): ~1e-7 relative
    np.testing.assert_allclose(hooked, stone, rtol=1e-5, atol=1e-4)
    pos = [0, 2]
    stone_err = np.hypot(*(stone[:, pos] - truth[:, pos]).T).max()
    plain_err = np.hypot(*(plain[:, pos] - truth[:, pos]).T).max()
    print(f"largest position error: Stone Soup {stone_err:.2f} m, ours with residual_y the "
          f"same, without {plain_err:.1f} m")
    assert stone_err < 5.0 and plain_err > 10 * stone_err


def test_ukf_with_angle_hooks_tracks_through_the_crossing_and_identity_hooks_change_nothing():
    truth, ys = crossing_track()
    kw = {"x0": PRIOR[0], "P0": PRIOR[1], "alpha": 1.0}
    plain = run(UnscentedKalmanFilter(bearing_model(), **kw), ys)
    hooked = run(UnscentedKalmanFilter(bearing_model(residual_y=residual_y,
                                                     mean_y=circular_mean_y), **kw), ys)
    pos = [0, 2]
    hooked_err = np.hypot(*(hooked[:, pos] - truth[:, pos]).T).max()
    plain_err = np.hypot(*(plain[:, pos] - truth[:, pos]).T).max()
    print(f"UKF largest position error: with the hooks {hooked_err:.2f} m, without "
          f"{plain_err:.1f} m")
    # without hooks the UKF survives: sigma points straddling ±π inflate S, so that step all
    # but ignores the bearing (hence a larger error, not a divergence)
    assert hooked_err < 5.0 and hooked_err < plain_err
    identity = bearing_model(residual_x=lambda a, b: a - b, residual_y=lambda a, b: a - b,
                             mean_x=lambda Z, w: np.einsum("n,bnk->bk", w, Z),
                             mean_y=lambda Z, w: np.einsum("n,bnk->bk", w, Z))
    same = run(UnscentedKalmanFilter(identity, **kw), ys)
    np.testing.assert_allclose(same, plain, rtol=1e-9, atol=1e-9)


def test_smoothers_use_the_state_residual():
    """A state that holds an angle wrapped by ``f``: with ``residual_x`` (and, for the UKF,
    ``mean_x``) the smoothed angle stays near the truth across the wrap and improves on the
    filter."""
    def f(x, u):
        return np.stack([wrap(x[..., 0] + DT * x[..., 1]), x[..., 1]], -1)

    def hh(x):
        return np.stack([np.cos(x[..., 0]), np.sin(x[..., 0])], -1)

    def res_x(a, b):
        d = np.asarray(a) - np.asarray(b)
        return np.concatenate([wrap(d[..., :1]), d[..., 1:]], axis=-1)

    def mean_x(X, w):                              # circular in the angle
        s = np.einsum("n,bn->b", w, np.sin(X[..., 0]))
        c = np.einsum("n,bn->b", w, np.cos(X[..., 0]))
        return np.stack([np.arctan2(s, c), np.einsum("n,bn->b", w, X[..., 1])], axis=-1)

    def F(x, u):                                   # analytic: f's wrap is not differentiable
        return np.broadcast_to(np.array([[1.0, DT], [0.0, 1.0]]), (*x.shape[:-1], 2, 2))

    rng = np.random.default_rng(2)
    theta = wrap(3.0 + 0.1 * np.arange(60))
    ys = np.stack([np.cos(theta), np.sin(theta)], -1) + 0.05 * rng.normal(size=(60, 2))
    for cls in (ExtendedKalmanFilter, UnscentedKalmanFilter):
        kw = {"alpha": 1.0} if cls is UnscentedKalmanFilter else {}
        model = StateSpaceModel(f=f, h=hh, F=F, Q=np.diag([1e-6, 1e-6]),
                                R=0.05**2 * np.eye(2), residual_x=res_x, mean_x=mean_x)
        sm = cls(model, x0=[3.0, 0.1], P0=np.diag([0.1, 0.01]), **kw).smooth(ys)
        filtered_err = np.abs(wrap(sm.filtered.x[:, 0] - theta)).max()
        assert np.abs(wrap(sm.x[:, 0] - theta)).max() < min(0.05, filtered_err)
        assert np.abs(sm.x[:, 1] - 0.1).max() < 0.02


def test_ukf_smoother_with_only_a_default_mean_hook_is_the_plain_smoother():
    """A ``mean_x`` hook that computes the default weighted mean, and no ``residual_x``: the
    smoother's hooked path (its backward pass's cross-covariance with the default residual)
    gives the hook-free smoother's estimates (mutation testing found that path untested)."""
    _, ys = crossing_track()
    kw = {"x0": PRIOR[0], "P0": PRIOR[1], "alpha": 1.0}
    plain = UnscentedKalmanFilter(bearing_model(), **kw).smooth(ys)
    hooked = UnscentedKalmanFilter(bearing_model(
        mean_x=lambda Z, w: np.einsum("n,bnk->bk", w, Z)), **kw).smooth(ys)
    np.testing.assert_allclose(hooked.x, plain.x, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(hooked.P, plain.P, rtol=1e-9, atol=1e-12)
