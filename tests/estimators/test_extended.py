"""Extended Kalman filter: equals the KF on linear models, matches a textbook EKF loop written
here, batches exactly, and flags divergence (paper 000's orbit) without returning NaN."""

from __future__ import annotations

import numpy as np
import pytest

from fir_gym.envs.orbit import TRUE_MU, OrbitDynamics
from fir_gym.estimators import LinearModel, StateSpaceModel
from fir_gym.estimators.extended import ExtendedKalmanFilter
from fir_gym.estimators.kalman import KalmanFilter
from fir_gym.estimators.metrics import chi2_band
from fir_gym.estimators.registry import make_estimator


def orbit_model(mu=19.91):
    dyn = OrbitDynamics(mu, 1e-4, 100, 1.0)
    return StateSpaceModel(f=dyn.f, h=dyn.h, F=dyn.F, H=dyn.H, Q=np.zeros((2, 2)), R=1e-3,
                           dt=0.01, n_u=1)


def pendulum_model(analytic=True):
    dt = 0.02

    def f(x, u):
        return np.stack([x[..., 0] + dt * x[..., 1],
                         x[..., 1] - dt * (9.8 * np.sin(x[..., 0]) + 0.3 * x[..., 1])
                         + dt * u[..., 0]], -1)

    def F(x, u):
        J = np.zeros(x.shape[:-1] + (2, 2))
        J[..., 0, 0] = 1.0
        J[..., 0, 1] = dt
        J[..., 1, 0] = -dt * 9.8 * np.cos(x[..., 0])
        J[..., 1, 1] = 1.0 - 0.3 * dt
        return J

    def h(x):
        return np.stack([np.sin(x[..., 0]), x[..., 1] ** 2 / 10], -1)

    def H(x):
        z = np.zeros_like(x[..., 0])
        return np.stack([np.stack([np.cos(x[..., 0]), z], -1),
                         np.stack([z, x[..., 1] / 5], -1)], -2)

    return StateSpaceModel(f=f, h=h, F=F if analytic else None, H=H if analytic else None,
                           Q=np.diag([1e-4, 1e-3]), R=np.diag([1e-2, 1e-2]), n_u=1, dt=dt)


def test_equals_kf_on_linear_model():
    rng = np.random.default_rng(0)
    A, C = rng.normal(size=(3, 3)) * 0.6, rng.normal(size=(2, 3))
    model = LinearModel(A=A, C=C, B=rng.normal(size=(3, 1)), Q=np.eye(3) * 0.1, R=np.eye(2))
    kf, ekf = KalmanFilter(model), ExtendedKalmanFilter(model)
    for _ in range(100):
        y, u = rng.normal(size=2), rng.normal(size=1)
        np.testing.assert_allclose(ekf.step(y, u), kf.step(y, u), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(ekf.P, kf.P, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("analytic", [True, False])
def test_matches_textbook_ekf(analytic):
    model = pendulum_model(analytic)
    ref_model = pendulum_model(True)
    rng = np.random.default_rng(1)
    x0, P0 = np.array([0.5, 0.0]), np.eye(2) * 0.3
    ekf = ExtendedKalmanFilter(model, x0=x0, P0=P0)
    x, P = x0.copy(), P0.copy()
    Q, R = model.Q, model.R
    for k in range(100):
        y, u = rng.normal(size=2) * 0.1, rng.normal(size=1)
        if k:
            F = ref_model.F(x, u)
            x, P = ref_model.f(x, u), F @ P @ F.T + Q
        H = ref_model.H(x)
        S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T
        x = x + K @ (y - ref_model.h(x))
        P = (np.eye(2) - K @ H) @ P @ (np.eye(2) - K @ H).T + K @ R @ K.T
        tol = 1e-10 if analytic else 1e-7            # finite-difference Jacobians
        np.testing.assert_allclose(ekf.step(y, u), x, rtol=tol, atol=tol)
        np.testing.assert_allclose(ekf.P, P, rtol=tol, atol=tol)


def test_batched_equals_looped():
    model = pendulum_model()
    rng = np.random.default_rng(2)
    B = 5
    x0 = rng.normal(size=(B, 2)) * 0.3
    batch = ExtendedKalmanFilter(model, x0=x0, P0=np.eye(2))
    singles = [ExtendedKalmanFilter(model, x0=x0[i], P0=np.eye(2)) for i in range(B)]
    for _ in range(100):
        Y, U = rng.normal(size=(B, 2)) * 0.1, rng.normal(size=(B, 1))
        X = batch.step(Y, U)
        for i, f in enumerate(singles):
            np.testing.assert_allclose(X[i], f.step(Y[i], U[i]), rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(batch.P[i], f.P, rtol=1e-12, atol=1e-14)


def test_orbit_ekf_wrong_mu_becomes_inconsistent():
    """Paper 000, sim 1: EKF with μ = 19.91 (truth 19.92244165), P0 = 2I, x̂0 = [7.997, 1.992].

    The error grows while P shrinks: the NEES averaged over 32 runs rises from inside its
    χ² band to > 5 by k = 2000 (> 1e3 by k = 10 000, see the report). The innovations
    stay below the measurement noise, so
    the innovation test does not flag it — the filter is not yet numerically diverged.
    """
    truth = OrbitDynamics(TRUE_MU, 1e-4, 100, 1.0)
    M = 32
    rng = np.random.default_rng(3)
    ekf = ExtendedKalmanFilter(orbit_model(), x0=np.tile([7.997, 1.992], (M, 1)),
                               P0=2 * np.eye(2))
    x, u = np.tile([7.99, 1.99], (M, 1)), np.zeros((M, 1))
    nees = {}
    for k in range(2001):
        est = ekf.step(x[:, :1] + np.sqrt(1e-3) * rng.standard_normal((M, 1)), u if k else None)
        if k in (200, 2000):
            e = est - x
            nees[k] = np.mean(np.einsum("bi,bij,bj->b", e, np.linalg.inv(ekf.P), e))
        x = truth.f(x, u)
    lo, hi = chi2_band(2, M)
    assert lo <= nees[200] <= hi and nees[2000] > 5 and not ekf.diverged.any()


def test_overconfident_orbit_ekf_is_flagged():
    """A confident, wrong prior (P0 = 1e-12 I, r off by 0.5, no process noise) ignores the
    data: the NIS stays far above its χ² tail and the filter is flagged, never NaN."""
    truth = OrbitDynamics(TRUE_MU, 1e-4, 100, 1.0)
    rng = np.random.default_rng(4)
    ekf = ExtendedKalmanFilter(orbit_model(), x0=[8.49, 1.99], P0=1e-12 * np.eye(2))
    x, u = np.array([7.99, 1.99]), np.zeros(1)
    for k in range(30):
        est = ekf.step(x[:1] + np.sqrt(1e-3) * rng.standard_normal(1), u if k else None)
        assert np.all(np.isfinite(est))
        assert ekf.diverged == (k >= ekf.nis_patience - 1)
        x = truth.f(x, u)


def test_overflow_is_flagged_and_never_nan():
    model = StateSpaceModel(f=lambda x, u: x * x * 1e3, h=lambda x: 0.0 * x, Q=1.0, R=1.0,
                            F=lambda x, u: (2e3 * x)[..., None],
                            H=lambda x: np.zeros(x.shape + (1,)))
    ekf = ExtendedKalmanFilter(model, x0=[10.0])
    for _ in range(20):
        out = ekf.step([10.0])
        assert np.all(np.isfinite(out))
    assert ekf.diverged and np.all(np.isfinite(ekf.P))


def test_bad_input_and_registry():
    model = pendulum_model()
    with pytest.raises(ValueError, match="P0 must be positive semi-definite"):
        ExtendedKalmanFilter(model, P0=[[1.0, 3.0], [3.0, 1.0]])
    with pytest.raises(ValueError, match="x0"):
        ExtendedKalmanFilter(model, x0=[1.0])
    with pytest.raises(TypeError, match="model"):
        ExtendedKalmanFilter("not a model")
    ekf = make_estimator("ekf", model)
    with pytest.raises(ValueError, match="y must have shape"):
        ekf.step([1.0])
    with pytest.raises(ValueError, match="u must have shape"):
        ekf.step([1.0, 1.0], u=[1.0, 2.0])


# ---------------------------------------------------------------- from the mutation run
# (docs/mutation.md: each test below kills mutants that survived the tests above)

def gaussian_log_density(e: np.ndarray, S: np.ndarray) -> float:
    """``log N(e; 0, S)`` written out."""
    return float(-0.5 * (e @ np.linalg.solve(S, e) + np.log(np.linalg.det(2 * np.pi * S))))


@pytest.mark.parametrize("kind", ["ekf", "lkf"])
def test_the_log_likelihood_is_the_gaussian_density_of_the_innovation(kind):
    """``info["log_likelihood"]`` of each step is ``log N(e; 0, S)`` of the textbook KF's
    innovation on a linear model (where both filters are the KF)."""
    rng = np.random.default_rng(5)
    A, C = rng.normal(size=(2, 2)) * 0.6, rng.normal(size=(2, 2))
    Q, R = np.eye(2) * 0.1, np.diag([0.5, 0.2])
    flt = make_estimator(kind, LinearModel(A=A, C=C, Q=Q, R=R), x0=np.zeros(2), P0=np.eye(2))
    x, P = np.zeros(2), np.eye(2)
    for k in range(20):
        y = rng.normal(size=2)
        if k:
            x, P = A @ x, A @ P @ A.T + Q
        e, S = y - C @ x, C @ P @ C.T + R
        K = np.linalg.solve(S, C @ P).T
        x, P = x + K @ e, (np.eye(2) - K @ C) @ P @ (np.eye(2) - K @ C).T + K @ R @ K.T
        flt.step(y)
        assert flt.last_info["log_likelihood"] == pytest.approx(gaussian_log_density(e, S),
                                                                rel=1e-10)


@pytest.mark.parametrize("batch", [None, 3])
def test_the_lkf_nominal_is_the_open_loop_trajectory(batch):
    """``x_nominal``: ``None`` before the first step, then ``x0`` propagated through ``f`` with
    the inputs alone (the measurements never move it), one row per system of a batch."""
    model = pendulum_model()
    x0 = np.array([0.5, 0.0]) if batch is None else np.array([[0.5, 0.0], [0.1, 0.2],
                                                             [-0.3, 0.0]])
    lkf = make_estimator("lkf", model, x0=x0, P0=np.eye(2) * 0.3)
    assert lkf.x_nominal is None
    rng = np.random.default_rng(6)
    nominal = x0.copy()
    for k in range(6):
        shape = (2,) if batch is None else (batch, 2)
        y, u = rng.normal(size=shape), rng.normal(size=shape[:-1] + (1,))
        lkf.step(y, u)
        if k:
            nominal = model.f(nominal, u)
        assert lkf.x_nominal.shape == x0.shape
        np.testing.assert_allclose(lkf.x_nominal, nominal, rtol=1e-14, atol=1e-15)


def test_an_ekf_whose_model_becomes_nonlinear_mid_run_continues_as_one_built_on_it():
    """A batch started on a plain linear model (one shared covariance, the KF's shortcut)
    whose model is replaced by a general one with the same dynamics continues exactly as an
    EKF that had the general model from the start: the shared covariance becomes one per
    system."""
    rng = np.random.default_rng(8)
    A, B, C = rng.normal(size=(2, 2)) * 0.6, rng.normal(size=(2, 1)), rng.normal(size=(1, 2))
    Q, R = np.eye(2) * 0.1, np.array([[0.3]])
    linear = LinearModel(A=A, B=B, C=C, Q=Q, R=R)
    general = StateSpaceModel(f=lambda x, u: x @ A.T + u @ B.T, h=lambda x: x @ C.T,
                              F=lambda x, u: np.broadcast_to(A, x.shape[:-1] + (2, 2)),
                              H=lambda x: np.broadcast_to(C, x.shape[:-1] + (1, 2)),
                              Q=Q, R=R, n_u=1)
    switched = ExtendedKalmanFilter(linear, x0=np.zeros(2), P0=np.eye(2))
    reference = ExtendedKalmanFilter(general, x0=np.zeros(2), P0=np.eye(2))
    for k in range(12):
        if k == 5:
            switched.model = general
        Y, U = rng.normal(size=(4, 1)), rng.normal(size=(4, 1))
        np.testing.assert_allclose(switched.step(Y, U), reference.step(Y, U), rtol=1e-10,
                                   atol=1e-12)
        np.testing.assert_allclose(switched.P, reference.P, rtol=1e-10, atol=1e-12)


def test_a_time_varying_model_is_refused_with_the_filter_that_takes_it():
    from fir_gym.estimators import TimeVaryingLinearModel
    tv = TimeVaryingLinearModel(A=lambda k: np.eye(2), C=lambda k: np.eye(1, 2), Q=np.eye(2),
                                R=np.eye(1))
    with pytest.raises(TypeError, match=r"time-free f/h .*use KalmanFilter"):
        ExtendedKalmanFilter(tv)
