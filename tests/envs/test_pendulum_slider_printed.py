"""Paper 003's printed equations (5) and (15) as options of the slider dynamics and of the env:
checked against the printed matrices solved directly, finite differences, energy, and the env."""

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest

import fir_gym  # noqa: F401  (registers the environments)
from fir_gym.envs.pendulum_slider_dynamics import PAPER_PARAMS, PendulumSliderDynamics

P = PAPER_PARAMS


def printed_rates(eq, z, U, mu, M0):
    """ż from the printed equations, written as printed and solved with np.linalg.solve.

    Eq (15): G Ẋ = F with G = [[1,0,0,0], [0, m1+m2, 0, −m2 l (cos X3 − μ sin X3)], [0,0,1,0],
    [0, −m2 l cos X3, 0, I_c + m1 l²]] and F = [X2, m2 l (sin X3 − μ cos X3) X4² − μ (m1+m2) g
    − 2k (X1 − l0) + U, X4, −M0 X4 − m2 g l sin X3]. Eq (5): the slider row reads
    (m1+m2) ẍ + m2 l (cosθ + μ sinθ) θ̈ + m2 l (μ cosθ − sinθ) θ̇² + μ (m1+m2) g + 2k (x − l0) = U.
    """
    m1, m2, l, g, k, l0, Ic = (P[n] for n in ("m1", "m2", "l", "g", "k", "l0", "I_c"))
    x, xd, th, w = z
    c, s = np.cos(th), np.sin(th)
    coupling = -m2 * l * (c - mu * s) if eq == "printed-eq15" else m2 * l * (c + mu * s)
    G = np.array([[1, 0, 0, 0], [0, m1 + m2, 0, coupling], [0, 0, 1, 0],
                  [0, -m2 * l * c, 0, Ic + m1 * l * l]])
    F = np.array([xd, m2 * l * (s - mu * c) * w * w - mu * (m1 + m2) * g - 2 * k * (x - l0) + U,
                  w, -M0 * w - m2 * g * l * s])
    return np.linalg.solve(G, F)


@pytest.mark.parametrize("eq", ["printed-eq15", "printed-eq5"])
def test_rates_are_the_printed_matrices_solved(eq):
    d = PendulumSliderDynamics(equations=eq)
    rng = np.random.default_rng(3)
    for _ in range(20):
        z = rng.normal(size=4) * [0.02, 0.2, 0.6, 2.0]
        U, mu, M0 = rng.normal(), 0.2 + 0.1 * rng.random(), 0.1 + 0.2 * rng.random()
        a, _, _ = d.derivatives(z, np.array(U), np.array(mu), np.array(M0))
        np.testing.assert_allclose(a, printed_rates(eq, z, U, mu, M0), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("eq", ["printed-eq15", "printed-eq5"])
def test_step_jacobians_match_central_differences(eq):
    d = PendulumSliderDynamics(equations=eq, input_scale=10.0, substeps=2)
    x, u, theta = np.array([0.012, 0.1, 0.4, -1.0]), np.array([0.3]), np.array([0.2, 0.2])
    _, Fz, Fp = d.propagate(x, u, theta, jacobian=True)
    eps = 1e-6

    def f(x_, theta_):
        return d.propagate(x_, u, theta_)[0]

    num_z = np.stack([(f(x + eps * e, theta) - f(x - eps * e, theta)) / (2 * eps)
                      for e in np.eye(4)], axis=-1)
    num_p = np.stack([(f(x, theta + eps * e) - f(x, theta - eps * e)) / (2 * eps)
                      for e in np.eye(2)], axis=-1)
    np.testing.assert_allclose(Fz, num_z, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(Fp, num_p, rtol=1e-6, atol=1e-9)


def test_eq5_creates_energy_where_the_physical_model_conserves_it():
    """Without friction, damping or input the Lagrangian conserves energy; eq 5's asymmetric
    mass matrix does not (eq 15's centripetal sign breaks it too, less)."""
    x0 = np.array([0.025, 0.0, 0.8, 0.0])
    drift = {}
    for eq in ("physical", "printed-eq15", "printed-eq5"):
        d = PendulumSliderDynamics(equations=eq, mu=0.0, M0=0.0)
        x, E0 = x0, d.energy(x0)
        for _ in range(2000):
            x = d.propagate(x, np.zeros(1), d.theta)[0]
        drift[eq] = abs(d.energy(x) - E0) / abs(E0)
    assert drift["physical"] < 1e-8
    assert drift["printed-eq5"] > 1e-2 and drift["printed-eq5"] > 100 * drift["physical"]


@pytest.mark.parametrize("eq", ["printed-eq15", "printed-eq5"])
def test_least_squares_on_the_printed_equations_recovers_the_parameters(eq):
    """Noise-free data of the printed ODE, regressed on the same printed equations."""
    d = PendulumSliderDynamics(equations=eq, input_scale=10.0)
    x, X, U = np.array([0.011, 0.0, 0.5, 0.0]), [], []
    for k in range(1500):
        u = np.array([np.sin(2 * np.pi * k * 1e-3)])
        X.append(x)
        U.append(10.0 * u[0])
        x = d.propagate(x, u, d.theta)[0]
    est = d.least_squares_parameters(np.array(X), np.array(U[:-1]), "central")
    assert est["mu"] == pytest.approx(0.2, abs=1e-4) and est["M0"] == pytest.approx(0.2, abs=1e-4)


def test_env_option_steps_the_printed_ode_and_pickles():
    env = gym.make("fir_gym/PendulumSlider-v0", dynamics="printed-eq15").unwrapped
    env.reset(seed=1)
    x = env.state.copy()
    _, _, _, _, info = env.step(np.array([0.4], dtype=np.float32))
    dyn = PendulumSliderDynamics(equations="printed-eq15", input_scale=10.0)
    np.testing.assert_array_equal(info["state"], dyn.propagate(x, info["action"], dyn.theta)[0])
    assert env.model.name == "PendulumSlider(printed-eq15)"
    for copier in (copy.deepcopy, lambda e: pickle.loads(pickle.dumps(e))):
        clone = copier(env)
        a = np.array([-0.2], dtype=np.float32)
        np.testing.assert_array_equal(clone.step(a)[4]["state"], env.step(a)[4]["state"])
    physical = gym.make("fir_gym/PendulumSlider-v0", nominal={"dynamics": "physical"},
                        dynamics="printed-eq5").unwrapped
    assert physical.model.name == "PendulumSlider(paper)"


def test_env_option_refuses_bad_input():
    with pytest.raises(ValueError, match="dynamics must be one of"):
        gym.make("fir_gym/PendulumSlider-v0", dynamics="printed-eq7")
    with pytest.raises(ValueError, match="friction must be 'paper'"):
        gym.make("fir_gym/PendulumSlider-v0", dynamics="printed-eq15", friction="coulomb")


def test_eq5_plant_ends_its_episode_rather_than_hand_on_a_runaway_state():
    """Eq 5 creates energy: driven hard the slider leaves the rail — the episode terminates
    (the plant's domain) with a finite state, and no non-finite value leaves the env."""
    env = gym.make("fir_gym/PendulumSlider-v0", dynamics="printed-eq5",
                   max_episode_steps=None).unwrapped
    env.reset(seed=0, options={"state": [env.x_rest, 0.0, 0.5, 0.0]})
    for k in range(20_000):
        y, reward, terminated, _, info = env.step(np.array([np.sin(2 * np.pi * k * 1e-3)]))
        assert np.isfinite(y).all() and np.isfinite(reward) and np.isfinite(info["state"]).all()
        if terminated:
            break
    assert terminated
