"""``predict``/``update`` as public steps, per-call noise, and attributes that take effect.

Oracles: filterpy's ``KalmanFilter`` (predict-first loop, ``update(z, R=..., H=...)``, ``R``
changed mid-run), and the filter's own ``step`` (``predict + update == step``).
"""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest
from compiled_paths import on_path
from plant_cases import kalman_filters
from sequence_data import tracking

from fir_gym.estimators import (
    ExtendedKalmanFilter,
    FIRFilter,
    KalmanFilter,
    LinearModel,
    StateSpaceModel,
    UnscentedKalmanFilter,
)

fk = pytest.importorskip("filterpy.kalman")

KALMAN = kalman_filters()


def filterpy_kf(model: LinearModel) -> object:
    f = fk.KalmanFilter(dim_x=model.n_x, dim_z=model.n_y, dim_u=model.n_u)
    f.F, f.H, f.B = np.array(model.A), np.array(model.C), np.array(model.B)
    f.Q, f.R = np.array(model.GQGT), np.array(model.R)
    f.x, f.P = np.zeros(model.n_x), np.eye(model.n_x)
    return f


@pytest.mark.parametrize("path", ["compiled", "numpy"])
@pytest.mark.parametrize("cls", KALMAN)
def test_predict_then_update_equals_step(cls, path):
    model, Y, U = tracking(T=40, B=3)
    Y = np.ma.masked_invalid(Y)
    Y[7, 2] = np.ma.masked                             # one system misses one measurement
    with on_path(path):
        a, b = cls(model), cls(model)
        for k in range(40):
            u = None if k == 0 else U[k - 1]
            xa = a.step(Y[k], u)
            if k:
                b.predict(u)
            xb = b.update(Y[k])
            np.testing.assert_allclose(xb, xa, rtol=1e-13, atol=1e-13)
            np.testing.assert_allclose(b.P, a.P, rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(b.last_info["log_likelihood"],
                                       a.last_info["log_likelihood"], rtol=1e-12)
        assert b.time_step == a.time_step == 40


@pytest.mark.parametrize("cls", [KalmanFilter, ExtendedKalmanFilter])
def test_predict_first_per_call_R_and_H_equal_filterpy(cls):
    model, Y, U = tracking(T=60, B=1)
    ys, us = Y[:, 0], U[:, 0]
    f, ours = filterpy_kf(model), cls(model, x0=[0.0, 0.0], P0=np.eye(2))
    for k in range(60):
        u = None if k == 0 else us[k - 1]
        f.predict(u=u)
        ours.predict(u)
        R = 0.01 * (1 + k % 5)                     # a measurement-dependent R
        if k % 3 == 0:
            f.update(ys[k], R=np.array([[R]]))
            x = ours.update(ys[k], R=lambda x, R=R: np.array([[R]]))    # callable R(x)
        else:
            f.update(ys[k], R=np.array([[R]]))
            x = ours.update(ys[k], R=R)
        np.testing.assert_allclose(x, f.x, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(ours.P, f.P, rtol=1e-12, atol=1e-14)
    assert ours.model.R[0, 0] == model.R[0, 0]     # the call's R was for that call only
    if cls is KalmanFilter:                        # a per-call H (here: velocity measured)
        H = np.array([[0.0, 1.0]])
        f.update(np.array([0.3]), R=np.array([[0.5]]), H=H)
        np.testing.assert_allclose(ours.update([0.3], R=0.5, H=H), f.x, rtol=1e-12)


@pytest.mark.parametrize("cls", KALMAN)
def test_assigning_a_model_takes_effect_at_the_next_step(cls):
    model, Y, U = tracking(T=30, B=1)
    ys, us = Y[:, 0], U[:, 0]
    f, ours = filterpy_kf(model), cls(model, x0=[0.0, 0.0], P0=np.eye(2))
    for k in range(30):
        if k == 12:
            ours.model = ours.model.replace(R=9.0 * model.R)
            f.R = 9.0 * np.array(model.R)
        u = None if k == 0 else us[k - 1]
        f.predict(u=u)
        ours.predict(u)
        f.update(ys[k])
        ours.update(ys[k])
    tol = 1e-6 if cls is UnscentedKalmanFilter else 1e-12
    np.testing.assert_allclose(ours.x, f.x, rtol=tol, atol=tol)
    np.testing.assert_allclose(ours.P, f.P, rtol=tol, atol=tol)


def test_ekf_takes_a_nonlinear_model_after_a_linear_one_in_a_batch():
    """A plain LinearModel's EKF shares one covariance over the batch; a nonlinear model
    assigned mid-run gives every system its own (and the step goes on, on both paths)."""
    model, Y, U = tracking(T=20, B=4)
    same = StateSpaceModel(f=lambda x, u: x @ model.A.T + u @ model.B.T, h=lambda x: x @ model.C.T,
                           Q=model.Q, G=model.G, R=model.R, n_u=1)
    a, b = ExtendedKalmanFilter(model), ExtendedKalmanFilter(model)
    for k in range(20):
        u = None if k == 0 else U[k - 1]
        if k == 10:
            b.model = same
        a.step(Y[k], u)
        b.step(Y[k], u)
    np.testing.assert_allclose(b.x, a.x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.P, a.P, rtol=1e-9, atol=1e-12)


def test_assignments_that_cannot_take_effect_are_refused_clearly():
    model, Y, _ = tracking(T=5, B=1)
    fir = FIRFilter(model, horizon=4)
    with pytest.raises(AttributeError, match=r"cannot be reassigned.*Build a new FIRFilter"):
        fir.model = model.replace(R=1.0)
    kf = KalmanFilter(model)
    bigger = LinearModel(A=np.eye(3), C=np.ones((1, 3)), Q=np.eye(3), R=1.0)
    with pytest.raises(ValueError, match="model must keep the sizes"):
        kf.model = bigger
    with pytest.raises(TypeError, match="model must be a StateSpaceModel"):
        kf.model = "kf"
    kf.step(Y[0, 0])
    with pytest.raises(ValueError, match="R must be positive semi-definite"):
        kf.update(Y[1, 0], R=-1.0)
    with pytest.raises(ValueError, match=r"R must have shape \(1, 1\)"):
        kf.update(Y[1, 0], R=np.eye(2))
    with pytest.raises(ValueError, match="H must"):
        kf.update(Y[1, 0], H=np.eye(2))
    with pytest.raises(TypeError, match="H: ExtendedKalmanFilter"):
        ExtendedKalmanFilter(model).update(Y[1, 0], H=[[1.0, 0.0]])
    with pytest.raises(ValueError, match="nan_policy"):
        kf.nan_policy = "ignore"
    kf.max_covariance_trace = 1e-9                 # takes effect at the next step
    kf.step(Y[1, 0])
    assert kf.diverged


@pytest.mark.parametrize("cls", KALMAN)
def test_copies_between_predict_and_update_have_the_same_future(cls):
    model, Y, U = tracking(T=10, B=2)
    flt = cls(model)
    flt.step(Y[0])
    flt.predict(U[0])
    for twin in (copy.deepcopy(flt), pickle.loads(pickle.dumps(flt))):
        np.testing.assert_array_equal(twin.update(Y[1]), copy.deepcopy(flt).update(Y[1]))


@pytest.mark.parametrize("cls", [ExtendedKalmanFilter, UnscentedKalmanFilter])
def test_a_one_point_model_callable_gets_a_message_that_says_what_to_do(cls):
    """filterpy's ``fx(x, dt)`` indexes ``x[i]``: on a batch it fails or (for ``B = n``)
    returns a transposed result. The filter refuses it at construction, with the fix."""
    def f_one(x, u):
        return np.array([x[0] + 0.1 * x[1], 0.9 * x[1]])

    def f_batched(x, u):
        return np.stack([x[..., 0] + 0.1 * x[..., 1], 0.9 * x[..., 1]], axis=-1)

    def h(x):
        return x[..., :1]

    one = StateSpaceModel(f=f_one, h=h, Q=np.eye(2), R=1.0)
    with pytest.raises(TypeError, match=r"model.f must take a leading batch axis.*x\[\.\.\., i\]"):
        cls(one)
    with pytest.raises(TypeError, match=r"model\.h must take a leading batch axis"):
        cls(StateSpaceModel(f=f_batched, h=lambda x: np.array([x[0]]), Q=np.eye(2), R=1.0))
    wrapped = one.replace(f=np.vectorize(f_one, signature="(n),(m)->(k)"))   # as suggested
    ys = np.sin(np.arange(20.0))[:, None]
    np.testing.assert_allclose(
        cls(wrapped).filter(ys).x,
        cls(StateSpaceModel(f=f_batched, h=h, Q=np.eye(2), R=1.0)).filter(ys).x, rtol=1e-9)


def test_ukf_points_and_jitter_take_effect_when_assigned():
    from fir_gym.estimators import CubatureSigmaPoints

    model, Y, U = tracking(T=15, B=2)
    a = UnscentedKalmanFilter(model, points=CubatureSigmaPoints(2))
    b = UnscentedKalmanFilter(model)
    for k in range(15):
        if k == 5:
            b.points = CubatureSigmaPoints(2)      # fewer points: the next step uses them
        xa = a.step(Y[k], None if k == 0 else U[k - 1])
        xb = b.step(Y[k], None if k == 0 else U[k - 1])
    np.testing.assert_allclose(xb, xa, rtol=1e-6)   # the scheme is exact on a linear model
    with pytest.raises(ValueError, match="points must be for n = 2"):
        b.points = CubatureSigmaPoints(3)
    with pytest.raises(ValueError, match="jitter must be"):
        b.jitter = -1.0
