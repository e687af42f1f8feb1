"""Joint state–parameter estimation: the augmented model's algebra, its Jacobians against finite
differences, and paper 003's experiment on the pendulum-slider ODE (EKF and UKF)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from fir_gym.envs.pendulum_slider_dynamics import PendulumSliderDynamics
from fir_gym.estimators import StateSpaceModel
from fir_gym.estimators.augment import ParametricModel, augment
from fir_gym.estimators.extended import ExtendedKalmanFilter
from fir_gym.estimators.unscented import UnscentedKalmanFilter

R_PAPER = np.diag([0.003, 0.03, 0.03, 0.3]) ** 2       # paper 003, eq 18 (std²)


def toy(jac=True):
    def f(x, u, th):
        return np.stack([x[..., 0] + 0.1 * th[..., 0] * x[..., 1],
                         x[..., 1] * np.exp(-th[..., 1]) + u[..., 0]], -1)

    def h(x, th):
        return (x[..., :1] * th[..., 2:3])

    def jac_f(x, u, th):
        Fx = np.zeros(x.shape[:-1] + (2, 2))
        Fx[..., 0, 0] = 1.0
        Fx[..., 0, 1] = 0.1 * th[..., 0]
        Fx[..., 1, 1] = np.exp(-th[..., 1])
        Ft = np.zeros(x.shape[:-1] + (2, 3))
        Ft[..., 0, 0] = 0.1 * x[..., 1]
        Ft[..., 1, 1] = -x[..., 1] * np.exp(-th[..., 1])
        return Fx, Ft

    return ParametricModel(f=f, h=h, params={"a": 2.0, "b": 0.5, "c": 3.0}, Q=[0.1, 0.2],
                           R=0.3, n_u=1, jac_f=jac_f if jac else None)


def test_parametric_model_is_its_nominal_model():
    m = toy()
    x, u = np.array([1.0, 2.0]), np.array([0.5])
    np.testing.assert_allclose(m.f(x, u), [1.0 + 0.1 * 2.0 * 2.0, 2.0 * np.exp(-0.5) + 0.5])
    np.testing.assert_allclose(m.h(x), [3.0])
    assert m.params == {"a": 2.0, "b": 0.5, "c": 3.0}
    np.testing.assert_allclose(m.with_params(c=1.0).h(x), [1.0])
    with pytest.raises(ValueError, match="unknown parameter"):
        m.with_params(d=1.0)


@pytest.mark.parametrize("jac", [True, False])
def test_augmented_model_algebra_and_jacobians(jac):
    aug = augment(toy(jac), ["c", "a"], Q_params=[1e-3, 2e-3])
    assert aug.n_x == 4 and aug.param_names == ("c", "a")
    z = np.array([[1.0, 2.0, 5.0, 0.7], [0.3, -1.0, 2.0, 1.5]])
    u = np.array([[0.5], [-0.5]])
    out = aug.f(z, u)
    np.testing.assert_allclose(out[:, 2:], z[:, 2:])                 # constant parameters
    np.testing.assert_allclose(out[:, 0], z[:, 0] + 0.1 * z[:, 3] * z[:, 1])
    np.testing.assert_allclose(aug.h(z)[:, 0], z[:, 0] * z[:, 2])     # per-sample θ
    np.testing.assert_allclose(aug.GQGT[2:, 2:], np.diag([1e-3, 2e-3]))
    np.testing.assert_allclose(aug.GQGT[:2, :2], np.diag([0.1, 0.2]))
    fd = StateSpaceModel(f=aug.f, h=aug.h, Q=aug.Q, R=aug.R, G=aug.G, n_u=1)   # FD Jacobians
    np.testing.assert_allclose(aug.F(z, u), fd.F(z, u), rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(aug.H(z), fd.H(z), rtol=1e-8, atol=1e-9)


def test_augment_rejects_bad_arguments():
    with pytest.raises(TypeError, match="ParametricModel"):
        augment(StateSpaceModel(f=lambda x, u: x, h=lambda x: x, Q=1.0, R=1.0))
    with pytest.raises(ValueError, match="params"):
        augment(toy(), ["zeta"])
    with pytest.raises(ValueError, match="params"):
        augment(toy(), ["a", "a"])
    with pytest.raises(TypeError, match="params"):
        augment(toy(), "a")
    with pytest.raises(ValueError, match="Q_params must be positive semi-definite"):
        augment(toy(), ["a"], Q_params=-1.0)


def simulate(T=501, seed=None):
    """Paper 003 plant from rest, U = 5 sin 2πt, 1 ms sampling; noisy or noise-free y."""
    truth = PendulumSliderDynamics()
    xs, us, x = np.zeros((T, 4)), np.zeros((T, 1)), np.zeros(4)
    for k in range(T):
        xs[k] = x
        us[k] = 5.0 * np.sin(2 * np.pi * k * 1e-3)
        x = truth.f(x, us[k])
    ys = xs.copy()
    if seed is not None:
        ys += np.sqrt(np.diag(R_PAPER)) * np.random.default_rng(seed).standard_normal(xs.shape)
    return truth, xs, us, ys


def run_joint(cls, ys, us):
    truth = PendulumSliderDynamics()
    aug = augment(truth.model(Q=1e-6, R=R_PAPER), ["mu", "M0"])     # paper eq 16-19
    flt = cls(aug, x0=np.zeros(6), P0=np.eye(6))
    for k in range(len(ys)):
        est = flt.step(ys[k], us[k - 1] if k else None)
    return est, flt


@pytest.mark.parametrize("cls", [UnscentedKalmanFilter, ExtendedKalmanFilter])
def test_joint_estimation_noise_free_data_within_3_percent(cls):
    """Paper 003 §5 ("noise-free data"), its Q, R, P0 = I6, zero start: after 0.5 s
    both μ and M0 are within 3 % (the report lists the values: EKF ~0.03 %, UKF ~2.3 %)."""
    _, _xs, us, ys = simulate()
    est, flt = run_joint(cls, ys, us)
    np.testing.assert_allclose(est[4:], [0.2, 0.2], rtol=0.03)
    assert not flt.diverged


@pytest.mark.parametrize("cls", [UnscentedKalmanFilter, ExtendedKalmanFilter])
def test_joint_estimation_noisy_data_is_consistent(cls):
    """With measurement noise R the posterior std of M0 after 0.5 s is ~3.6 % (μ ~1.6 %),
    so "within 3 %" is a ~55 % event; what must hold is that the error is within 3σ."""
    _, xs, us, ys = simulate(seed=0)
    est, flt = run_joint(cls, ys, us)
    std = np.sqrt(np.diag(flt.P)[4:])
    assert np.all(np.abs(est[4:] - 0.2) < 3 * std)
    assert np.all(std < 0.2 * 0.05)                  # both known to better than 5 %
    assert np.all(np.abs(est[:4] - xs[-1]) < 3 * np.sqrt(np.diag(flt.P)[:4]))


def test_augmented_model_pickles():
    aug = augment(PendulumSliderDynamics().model(), ["mu"])
    again = pickle.loads(pickle.dumps(aug))
    z, u = np.array([0.01, 0.1, 0.2, -0.3, 0.25]), np.array([1.0])
    np.testing.assert_array_equal(again.f(z, u), aug.f(z, u))
