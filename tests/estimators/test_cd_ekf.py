"""Continuous–discrete EKF: on a linear model it is the exact discrete-time Kalman filter of the
sampled system (Van Loan), for both measurement models; RK4 stays stable where the Van der Pol
oscillator is stiff; the Estimator contract."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from fir_gym.envs.van_der_pol import van_der_pol_continuous_model
from fir_gym.estimators import LinearModel
from fir_gym.estimators.cd_ekf import ContinuousDiscreteEKF, cd_ekf_propagate
from fir_gym.estimators.continuous import ContinuousModel
from fir_gym.estimators.discretize import discretize_lti
from fir_gym.estimators.kalman import kf_update
from fir_gym.estimators.registry import estimator_class

A = np.array([[0.0, 1.0], [-0.36, -0.06]])
C = np.array([[1.0, 0.0]])
G = np.array([[0.6], [-0.036]])
Q, V, h = 0.035, 1.0, 0.1
VDP = {"epsilon": 1.0, "u_max": 5.0, "Q": 5.0, "R": 5.0, "h": 0.1}


def carrier():
    return ContinuousModel.linear(A=A, C=C, G=G, Q=Q, R=V, dt=h)


def exact_step(x, P, y, average):
    """One step of the exact discrete KF of the sampled linear system (Van Loan)."""
    if not average:
        Ad, _, Qd = discretize_lti(A, h, G=G, Q=Q)
        x_, P_ = Ad @ x, Ad @ P @ Ad.T + Qd
        x_, P_, _ = kf_update(x_, P_, y, C, V / h)
        return x_, P_
    # [x; s] with ṡ = C x / h over the interval, s = 0 at its start: ȳ = s + v̄
    Aa = np.block([[A, np.zeros((2, 1))], [C / h, np.zeros((1, 1))]])
    Ga = np.vstack([G, np.zeros((1, 1))])
    Ad, _, Qd = discretize_lti(Aa, h, G=Ga, Q=Q)
    z = Ad @ np.append(x, 0.0)
    S = Ad @ scipy.linalg.block_diag(P, 0.0) @ Ad.T + Qd
    z, S, _ = kf_update(z, S, y, np.array([[0.0, 0.0, 1.0]]), V / h)
    return z[:2], S[:2, :2]


@pytest.mark.parametrize("measurement", ["average", "end"])
def test_linear_model_equals_the_exact_sampled_kalman_filter(measurement):
    rng = np.random.default_rng(0)
    f = ContinuousDiscreteEKF(carrier(), x0=[0.2, -0.1], P0=0.5 * np.eye(2),
                              measurement=measurement)
    ys = rng.normal(size=(40, 1)) * 3
    x, P, _ = kf_update(np.array([0.2, -0.1]), 0.5 * np.eye(2), ys[0], C, V / h)
    np.testing.assert_allclose(f.step(ys[0]), x)
    for y in ys[1:]:
        x, P = exact_step(x, P, y, measurement == "average")
        np.testing.assert_allclose(f.step(y), x, rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(f.P, P, rtol=1e-8, atol=1e-10)


def test_the_running_average_lags_the_end_value_by_half_an_interval():
    """s(t_k) = (1/h) ∫ x1 dt; x1(t_k) − s ≈ h/2 · ẋ1 = h x2 / 2 (the 'end' model's bias)."""
    z, S = cd_ekf_propagate(carrier(), [0.0, 2.0], np.zeros((2, 2)), average=True)
    assert z.shape == (3,) and S.shape == (3, 3)
    np.testing.assert_allclose(z[0] - z[2], h * 2.0 / 2, rtol=0.02)


def test_propagation_is_stable_and_accurate_where_van_der_pol_is_stiff():
    """At x1 = 18, J22 = -323: a fixed 20-step RK4 would blow up the covariance."""
    m = van_der_pol_continuous_model(VDP)
    x0, P0 = np.array([18.0, -0.05]), np.diag([5.0, 0.02])
    x, P = cd_ekf_propagate(m, x0, P0, substeps=20)

    def moments(t, y):
        xs, Ps = y[:2], y[2:].reshape(2, 2)
        J = m.J(xs)
        return np.concatenate([m.a(xs), (J @ Ps + Ps @ J.T + m.GQGT).ravel()])

    ref = solve_ivp(moments, (0, h), np.concatenate([x0, P0.ravel()]), method="Radau",
                    rtol=1e-10, atol=1e-12).y[:, -1]
    np.testing.assert_allclose(x, ref[:2], rtol=1e-4)
    np.testing.assert_allclose(P, ref[2:].reshape(2, 2), rtol=1e-3, atol=1e-6)


def test_batch_equals_single_systems():
    m = van_der_pol_continuous_model(VDP)
    Y = np.random.default_rng(2).normal(size=(15, 3, 1)) * 7
    batch = ContinuousDiscreteEKF(m, x0=[1.0, 1.0], P0=5 * np.eye(2))
    singles = [ContinuousDiscreteEKF(m, x0=[1.0, 1.0], P0=5 * np.eye(2)) for _ in range(3)]
    for y in Y:
        xb = batch.step(y)
        for b, f in enumerate(singles):
            np.testing.assert_allclose(xb[b], f.step(y[b]), rtol=1e-12, atol=1e-12)


def test_input_enters_the_drift():
    m = ContinuousModel.linear(A=A, C=C, G=G, Q=Q, R=V, dt=h, B=[[0.0], [1.0]])
    x, _ = cd_ekf_propagate(m, [0.0, 0.0], np.zeros((2, 2)), [2.0])
    _, Bd, _ = discretize_lti(A, h, B=[[0.0], [1.0]])
    np.testing.assert_allclose(x, Bd @ [2.0], rtol=1e-9)


def test_contract_errors_and_registry():
    with pytest.raises(TypeError, match="ContinuousModel"):
        ContinuousDiscreteEKF(LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2), R=1.0))
    with pytest.raises(ValueError, match="measurement must be one of"):
        ContinuousDiscreteEKF(carrier(), measurement="middle")
    with pytest.raises(ValueError, match="substeps"):
        ContinuousDiscreteEKF(carrier(), substeps=0)
    assert estimator_class("cd-ekf") is ContinuousDiscreteEKF


@pytest.mark.parametrize("x1", [0.5, 30.0], ids=["mild", "stiff"])
def test_the_step_count_is_the_documented_rule(x1: float) -> None:
    """RK4 with ``max(substeps, ⌈2 ‖J(x̂)‖_∞ h / 1.5⌉)`` steps, ``substeps`` = 20 by default
    (the module docstring): the default call is the same computation as one given that
    count explicitly — 20 where the system is mild, the raised count where it is stiff
    (mutation testing found the rule's constants free to change)."""
    cm = van_der_pol_continuous_model(VDP)
    x, P = np.array([x1, 0.2]), 0.5 * np.eye(2)
    J = np.asarray(cm.J(x[None], np.zeros((1, cm.n_u))))[0]
    count = max(20, int(np.ceil(2.0 * np.abs(J).sum(axis=1).max() * cm.dt / 1.5)))
    assert (count > 20) == (x1 > 10)
    for average in (False, True):
        default = cd_ekf_propagate(cm, x, P, average=average)
        explicit = cd_ekf_propagate(cm, x, P, substeps=count, average=average)
        for a, b in zip(default, explicit, strict=True):
            np.testing.assert_array_equal(a, b)
