"""VanDerPol-v0: paper 002's oscillator, integrated finely, interval-averaged measurement."""

import gymnasium as gym
import numpy as np
import pytest
import scipy.integrate

import fir_gym  # noqa: F401
from fir_gym.estimators import discretize_lti


def vdp(t, x, force=0.0):
    return [x[1], -x[0] + (1 - x[0] ** 2) * x[1] + force]


def test_noise_free_step_matches_an_accurate_ode_solution():
    """Heun with τ = 1 ms has local error O(τ³): the interval map agrees to ~1e-6."""
    env = gym.make("fir_gym/VanDerPol-v0", Q=0.0).unwrapped
    _, info = env.reset(seed=0)
    for a in (0.0, 0.4, -0.6):
        x = info["state"]
        _, _, _, _, info = env.step(np.array([a]))
        sol = scipy.integrate.solve_ivp(vdp, (0, 0.1), x, args=(a * env.params["u_max"],),
                                        rtol=1e-12, atol=1e-12, dense_output=True)
        np.testing.assert_allclose(info["state"], sol.y[:, -1], atol=2e-6)
        average = scipy.integrate.quad(lambda t, s=sol: s.sol(t)[0], 0, 0.1)[0] / 0.1
        assert info["x1_average"] == pytest.approx(average, abs=2e-6)
        np.testing.assert_allclose(env.model.f(x, [a]), info["state"], rtol=1e-15, atol=0)


def test_noise_free_limit_cycle_has_amplitude_about_two():
    env = gym.make("fir_gym/VanDerPol-v0", Q=0.0, max_episode_steps=None).unwrapped
    env.reset(seed=0)
    x1 = [env.step(np.zeros(1))[4]["state"][0] for _ in range(600)]
    amplitude = max(np.abs(x1[300:]))
    assert amplitude == pytest.approx(2.0086, abs=5e-3)     # the known ε = 1 amplitude


def test_measurement_is_interval_average_with_variance_R_over_h():
    env = gym.make("fir_gym/VanDerPol-v0")
    residuals = []
    for episode in range(40):
        env.reset(seed=episode)
        for _ in range(100):
            obs, _, terminated, truncated, info = env.step(np.array([-0.4]))
            residuals.append(obs[0] - info["x1_average"])
            if terminated or truncated:
                break
    residuals = np.array(residuals)
    n = len(residuals)
    assert residuals.var() == pytest.approx(5.0 / 0.1, rel=5 * np.sqrt(2 / n))
    assert abs(residuals.mean()) < 5 * np.sqrt(50.0 / n)


def test_process_noise_matches_the_exact_linear_covariance_near_the_origin():
    """From x = 0 with weak noise the oscillator is linear (A0 = [[0, 1], [-1, 1]]); the
    spread after one interval must equal Van Loan's ∫ e^{A0 s} g Q gᵀ e^{A0ᵀ s} ds."""
    Q = 0.05
    env = gym.make("fir_gym/VanDerPol-v0", Q=Q).unwrapped
    ends = []
    for i in range(4000):
        env.reset(seed=i, options={"state": np.zeros(2)})
        ends.append(env.step(np.zeros(1))[4]["state"])
    _, _, Q_d = discretize_lti(np.array([[0.0, 1.0], [-1.0, 1.0]]), 0.1, G=np.ones((2, 1)), Q=Q)
    cov = np.cov(np.array(ends).T)
    n = len(ends)
    tol = 5 * np.sqrt((np.outer(np.diag(Q_d), np.diag(Q_d)) + Q_d**2) / n)
    assert np.all(np.abs(cov - Q_d) < tol)
    # the model's first-order Q h [1 1; 1 1] is within O(h) of it
    np.testing.assert_allclose(env.model.GQGT, Q * 0.1 * np.ones((2, 2)))
    assert np.max(np.abs(Q_d - env.model.GQGT)) < 0.15 * Q * 0.1


def test_long_uncontrolled_runs_wander_to_the_domain_bound_without_blowing_up():
    env = gym.make("fir_gym/VanDerPol-v0", max_episode_steps=None).unwrapped
    env.reset(seed=2)
    for _ in range(20000):
        _, _, terminated, _, info = env.step(np.zeros(1))
        assert np.all(np.isfinite(info["state"]))
        if terminated:
            break
    assert terminated and np.max(np.abs(info["state"])) < 1.5 * env.state_bound


def test_state_dependent_factorisation_reproduces_the_drift():
    env = gym.make("fir_gym/VanDerPol-v0").unwrapped
    x = np.random.default_rng(0).standard_normal((5, 2))
    drift = np.array([vdp(0, xi) for xi in x])
    np.testing.assert_allclose(np.einsum("bij,bj->bi", env.dynamics.A_of_x(x), x), drift)


@pytest.mark.parametrize("kwargs", [{"Q": -5.0}, {"R": 0.0}, {"h": 0.0}, {"substeps": 2.5},
                                    {"u_max": -1.0}, {"state_bound": 0.0}])
def test_invalid_parameters_raise(kwargs):
    with pytest.raises(ValueError, match="|".join(kwargs)):
        gym.make("fir_gym/VanDerPol-v0", **kwargs)


def test_state_bound_must_respect_the_integrators_stability():
    with pytest.raises(ValueError, match="substeps"):
        gym.make("fir_gym/VanDerPol-v0", state_bound=50.0)
    gym.make("fir_gym/VanDerPol-v0", state_bound=50.0, substeps=1000)
