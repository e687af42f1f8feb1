"""Pendulum-slider ODE (paper 003, corrected): energy and power balance, rest position, exact
RK4 Jacobians against finite differences, friction modes, pickling, bad arguments."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from fir_gym.envs.pendulum_slider_dynamics import PendulumSliderDynamics


def test_energy_is_conserved_without_friction_or_input():
    """The corrected eq 15 is Lagrangian; the printed centripetal sign would not conserve E."""
    d = PendulumSliderDynamics(friction="none", M0=0.0)
    x = np.array([0.05, 0.3, 1.0, -2.0])
    E0 = d.energy(x)
    for _ in range(3000):
        x = d.f(x, np.zeros(1))
    assert abs(d.energy(x) - E0) < 1e-8 * abs(E0)


def test_power_balance_with_hinge_damping_and_input():
    """dE/dt = U ẋ − M0 θ̇² (trapezoidal integral over the path, RK4 accuracy)."""
    d = PendulumSliderDynamics(friction="none", M0=0.2, substeps=4)
    x, E0, work = np.array([0.0, 0.0, 0.5, 0.0]), None, 0.0
    E0 = d.energy(x)
    for k in range(2000):
        U = np.array([3.0 * np.cos(7e-3 * k)])
        x1 = d.f(x, U)
        p0 = U[0] * x[1] - 0.2 * x[3] ** 2
        p1 = U[0] * x1[1] - 0.2 * x1[3] ** 2
        work += 0.5 * (p0 + p1) * d.dt
        x = x1
    assert abs(d.energy(x) - E0 - work) < 1e-5 * (abs(work) + abs(E0))


def test_paper_friction_term_moves_the_rest_position():
    d = PendulumSliderDynamics()
    x = np.zeros(4)
    for _ in range(20000):
        x = d.f(x, np.zeros(1))
    expected = 0.025 - 0.2 * (0.654 + 0.7925) * 9.8 / (2 * 100.0)      # ≈ 10.8 mm
    np.testing.assert_allclose(x, [expected, 0, 0, 0], atol=1e-9)


@pytest.mark.parametrize("friction", ["paper", "coulomb", "none"])
def test_rk4_jacobians_match_finite_differences(friction):
    d = PendulumSliderDynamics(friction=friction, substeps=2)
    rng = np.random.default_rng(0)
    x, u, th = rng.normal(size=(6, 4)), rng.normal(size=(6, 1)), 0.1 + rng.random((6, 2))
    Fz, Fp = d.jac_f(x, u, th)
    eps = 1e-6
    num_z = np.stack([(d.f_theta(x + eps * e, u, th) - d.f_theta(x - eps * e, u, th)) / (2 * eps)
                      for e in np.eye(4)], -1)
    num_p = np.stack([(d.f_theta(x, u, th + eps * e) - d.f_theta(x, u, th - eps * e)) / (2 * eps)
                      for e in np.eye(2)], -1)
    np.testing.assert_allclose(Fz, num_z, atol=1e-8)
    np.testing.assert_allclose(Fp, num_p, atol=1e-8)
    np.testing.assert_allclose(d.F(x[0], u[0]), d.jac_f(x[0], u[0], d.theta)[0])


def test_coulomb_friction_opposes_motion():
    d = PendulumSliderDynamics(friction="coulomb", M0=0.0)
    a_plus = d.derivatives(np.array([0.025, 0.5, 0.0, 0.0]), 0.0, 0.2, 0.0)[0]
    a_minus = d.derivatives(np.array([0.025, -0.5, 0.0, 0.0]), 0.0, 0.2, 0.0)[0]
    np.testing.assert_allclose(a_plus[1], -a_minus[1])
    assert a_plus[1] < 0
    exact = PendulumSliderDynamics(friction="coulomb", coulomb_velocity=0.0)
    assert exact.derivatives(np.array([0.025, 0.0, 0.0, 0.0]), 0.0, 0.2, 0.2)[0][1] == 0.0


def test_model_and_pickle():
    d = PendulumSliderDynamics()
    m = d.model()
    assert (m.n_x, m.n_y, m.n_u) == (4, 4, 1) and m.param_names == ("mu", "M0")
    np.testing.assert_allclose(m.GQGT, 1e-6 * np.eye(4))
    again = pickle.loads(pickle.dumps(m))
    x = np.array([0.01, 0.2, 0.3, -0.1])
    np.testing.assert_array_equal(again.f(x, np.ones(1)), m.f(x, np.ones(1)))


def test_bad_arguments():
    with pytest.raises(ValueError, match="friction"):
        PendulumSliderDynamics(friction="viscous")
    with pytest.raises(ValueError, match="m1"):
        PendulumSliderDynamics(m1=0.0)
    with pytest.raises(ValueError, match="mu"):
        PendulumSliderDynamics(mu=-0.1)


@pytest.mark.parametrize("difference", ["backward", "forward", "central"])
def test_least_squares_recovers_parameters_that_fit_the_equations_exactly(difference):
    """Paper 003's LSM against data built to satisfy its two regressions exactly (physical
    equations, as its docstring writes them): smooth velocity sequences, the accelerations
    the chosen finite difference makes of them, then the angles θ that the hinge equation
    requires for M0 = 0.07 and the forces the slider equation requires for μ = 0.3 — so the
    estimate must be those numbers to round-off (mutation testing found the normal force
    and the centripetal term free to change)."""
    d = PendulumSliderDynamics(equations="physical")
    m1, m2, l, g, k, l0 = d.m1, d.m2, d.l, d.g, d.k, d.l0
    m2l, J = m2 * l, d.I_c + m2 * l * l
    mu, M0 = 0.3, 0.07
    K = 80
    t = np.arange(K)
    Y = np.column_stack([0.03 + 0.01 * np.sin(0.05 * t), 0.3 * np.cos(0.02 * t),
                         np.zeros(K), 0.5 * np.sin(0.01 * t) + 0.2])
    idx = {"backward": np.arange(1, K), "forward": np.arange(0, K - 1),
           "central": np.arange(1, K - 1)}[difference]
    v = Y[:, [1, 3]]
    acc = {"backward": lambda i: (v[i] - v[i - 1]) / d.dt,
           "forward": lambda i: (v[i + 1] - v[i]) / d.dt,
           "central": lambda i: (v[i + 1] - v[i - 1]) / (2 * d.dt)}[difference](idx)
    x, w = Y[idx, 0], Y[idx, 3]
    xdd, thdd = acc[:, 0], acc[:, 1]
    # M0 θ̇ = −m2 g l sinθ − J θ̈ + m2 l cosθ ẍ, solved for θ: A sinθ + B cosθ = c
    A, B, c = -m2l * g, m2l * xdd, M0 * w + J * thdd
    th = np.arcsin(c / np.hypot(A, B)) - np.arctan2(B, A)
    Y[idx, 2] = th
    # μ N = U − 2k (x − l0) − m2 l sinθ θ̇² − (m1+m2) ẍ + m2 l cosθ θ̈: the force it needs
    normal = (m1 + m2) * g + m2l * (np.cos(th) * w * w + np.sin(th) * thdd)
    force = (mu * normal + 2 * k * (x - l0) + m2l * np.sin(th) * w * w + (m1 + m2) * xdd
             - m2l * np.cos(th) * thdd)
    U = np.zeros(K)
    if difference == "backward":
        U[idx - 1] = force
    elif difference == "forward":
        U[idx] = force
    else:                                       # the mean of U[k−1] and U[k] is the force
        for j, i in enumerate(idx):
            U[i] = 2 * force[j] - U[i - 1]
    est = d.least_squares_parameters(Y, U, difference)
    assert est["mu"] == pytest.approx(mu, rel=1e-9)
    assert est["M0"] == pytest.approx(M0, rel=1e-9)
