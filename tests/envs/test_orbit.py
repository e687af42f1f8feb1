"""Orbit-v0: paper 000 simulation 1 facts and model–plant consistency."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym  # noqa: F401  (registers the ids)
from fir_gym.envs.orbit import NOMINAL_MU, TRUE_MU


def euler_orbit(x, mu, steps, dt=1e-4, thrust=0.0):
    """An independent scalar Euler loop of eq (27)."""
    r, v = float(x[0]), float(x[1])
    for _ in range(steps):
        r, v = r + v * dt, v + (-mu / r**2 + thrust) * dt
    return np.array([r, v])


def test_defaults_are_the_papers():
    env = gym.make("fir_gym/Orbit-v0").unwrapped
    assert env.params["mu"] == TRUE_MU == 19.92244165
    assert env.nominal_params["mu"] == NOMINAL_MU == 19.91
    assert env.model.R[0, 0] == 1e-3 and not np.any(env.model.Q)
    assert env.model.dt == pytest.approx(0.01)
    _, info = env.reset(seed=0)
    assert np.array_equal(info["state"], [7.99, 1.99])


def test_env_step_is_one_measurement_interval_of_euler_steps():
    env = gym.make("fir_gym/Orbit-v0").unwrapped
    _, info = env.reset(seed=0)
    x = info["state"]
    for action in (0.0, 0.7, -0.4):
        _, _, _, _, info = env.step(np.array([action]))
        expected = euler_orbit(x, TRUE_MU, 100, thrust=action * env.params["thrust_max"])
        np.testing.assert_allclose(info["state"], expected, rtol=0, atol=1e-12)
        x = info["state"]


def test_model_with_true_mu_reproduces_the_plant_to_round_off():
    env = gym.make("fir_gym/Orbit-v0", nominal={"mu": TRUE_MU}).unwrapped
    _, info = env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(50):
        u = rng.uniform(-1, 1, 1)
        x = info["state"]
        _, _, _, _, info = env.step(u)
        np.testing.assert_allclose(env.model.f(x, u), info["state"], rtol=1e-15, atol=0)


def test_default_model_uses_the_wrong_mu():
    env = gym.make("fir_gym/Orbit-v0").unwrapped
    x = np.array([7.99, 1.99])
    assert not np.allclose(env.model.f(x, [0.0]), euler_orbit(x, TRUE_MU, 100), rtol=0, atol=1e-9)
    np.testing.assert_allclose(env.model.f(x, [0.0]), euler_orbit(x, NOMINAL_MU, 100),
                               rtol=0, atol=1e-12)


def energy(x, mu):
    return 0.5 * x[..., 1] ** 2 - mu / x[..., 0]


def test_noise_free_energy_is_conserved_to_euler_accuracy():
    """Euler is first order: halving Δ halves the energy drift over a fixed time."""
    x0 = np.array([7.99, 1.99])
    drifts = []
    for dt in (2e-4, 1e-4, 5e-5):
        steps = round(10.0 / dt)
        drifts.append(abs(energy(euler_orbit(x0, TRUE_MU, steps, dt), TRUE_MU)
                          - energy(x0, TRUE_MU)))
    # and the env (Δ = 1e-4) shows the middle drift
    env = gym.make("fir_gym/Orbit-v0").unwrapped
    env.reset(seed=0)
    for _ in range(1000):
        _, _, _, _, info = env.step(np.zeros(1))
    assert abs(energy(info["state"], TRUE_MU) - energy(x0, TRUE_MU)) == pytest.approx(drifts[1])
    assert drifts[1] < 1e-3 * abs(energy(x0, TRUE_MU))
    assert drifts[0] / drifts[1] == pytest.approx(2.0, rel=0.05)
    assert drifts[1] / drifts[2] == pytest.approx(2.0, rel=0.05)


def test_measurement_is_radius_plus_noise_of_variance_R():
    env = gym.make("fir_gym/Orbit-v0").unwrapped
    env.reset(seed=3)
    residuals = []
    for _ in range(1000):
        obs, _, _, _, info = env.step(np.zeros(1))
        residuals.append(obs[0] - info["state"][0])
    residuals = np.array(residuals)
    n = len(residuals)
    assert abs(residuals.mean()) < 5 * np.sqrt(1e-3 / n)
    # sample variance of n Gaussians: relative std sqrt(2/n)
    assert residuals.var() == pytest.approx(1e-3, rel=5 * np.sqrt(2 / n))


def test_process_noise_enters_once_per_interval_with_covariance_Q():
    Q = np.array([[1e-4, 2e-5], [2e-5, 4e-4]])
    env = gym.make("fir_gym/Orbit-v0", Q=Q, nominal={"mu": TRUE_MU}).unwrapped
    _, info = env.reset(seed=5)
    w = []
    for _ in range(4000):
        x = info["state"]
        _, _, terminated, _, info = env.step(np.array([0.3]))
        w.append(info["state"] - env.model.f(x, [0.3]))
        if terminated:
            break
    w = np.array(w)
    n = len(w)
    cov = np.cov(w.T)
    tol = 5 * np.sqrt((Q[0, 0] * Q[1, 1] + Q ** 2) / n)       # std of sample covariance entries
    assert np.all(np.abs(cov - Q) < tol)
    np.testing.assert_array_equal(env.model.Q, Q)


def test_terminates_when_the_body_reaches_the_planet():
    env = gym.make("fir_gym/Orbit-v0", initial_state=(1.5, -3.0)).unwrapped
    env.reset(seed=0)
    for _ in range(200):
        _, _, terminated, _, info = env.step(np.array([-1.0]))
        if terminated:
            break
    assert terminated and info["state"][0] <= env.r_min


@pytest.mark.parametrize("kwargs", [{"mu": -1.0}, {"R": -1e-3}, {"Q": [[1, 2], [2, 1]]},
                                    {"substeps": 0}, {"euler_dt": 0.0}, {"r_ref": 0.5},
                                    {"initial_state": (1.0,)}, {"initial_state_cov": -np.eye(2)}])
def test_invalid_parameters_raise(kwargs):
    with pytest.raises(ValueError, match="|".join(kwargs)):
        gym.make("fir_gym/Orbit-v0", **kwargs)


# ---------------------------------------------------------------- from the mutation run
# (docs/mutation.md: each test below kills mutants that survived the tests above)

def test_reward_is_minus_the_saturated_tracking_and_thrust_cost():
    """``r = −min((r' − r_ref)² + 0.01 a², cost_cap)``, the cap being that cost at the planet's
    surface under full thrust, ``(r_ref − r_min)² + 0.01`` (the module docstring)."""
    env = gym.make("fir_gym/Orbit-v0").unwrapped
    env.reset(seed=3)
    cap = (env.r_ref - env.r_min) ** 2 + 0.01 * 1.0 ** 2
    rng = np.random.default_rng(3)
    for _ in range(30):
        a = rng.uniform(-1.0, 1.0, size=1)
        _, reward, terminated, _, info = env.step(a)
        if terminated:
            break
        cost = (info["state"][0] - env.r_ref) ** 2 + 0.01 * a[0] ** 2
        assert reward == pytest.approx(-min(cost, cap), rel=1e-12)
    # the crash pays the cap for the terminal step and every step it forgoes
    crash = gym.make("fir_gym/Orbit-v0", initial_state=(1.5, -3.0)).unwrapped
    crash.reset(seed=0)
    steps, terminated = 0, False
    while not terminated and steps < 200:
        _, reward, terminated, _, _ = crash.step(np.array([-1.0]))
        steps += 1
    assert terminated
    assert reward == pytest.approx(-cap * (1 + crash.max_episode_steps - steps), rel=1e-12)


def test_the_design_point_is_a_fixed_point_of_the_model():
    """The LQG's operating point hovers: the model's interval map (the nominal μ it
    believes) leaves ``(x*, u*)`` where it is, at ``r = r_ref``, ``v = 0``."""
    env = gym.make("fir_gym/Orbit-v0").unwrapped
    point = env.design_point()
    assert point.x[0] == env.r_ref and point.x[1] == 0.0
    np.testing.assert_allclose(env.model.f(point.x, point.u), point.x, rtol=0, atol=1e-12)
