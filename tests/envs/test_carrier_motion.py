"""CarrierMotion-v0: exact sampling of paper 001's carrier model."""

import gymnasium as gym
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

import fir_gym  # noqa: F401
from fir_gym.envs.carrier_motion import carrier_continuous


def test_discrete_stationary_covariance_equals_the_continuous_one():
    env = gym.make("fir_gym/CarrierMotion-v0").unwrapped
    A, G, _ = carrier_continuous(env.params)
    P_cont = scipy.linalg.solve_continuous_lyapunov(A, -0.035 * G @ G.T)
    m = env.model
    P_disc = scipy.linalg.solve_discrete_lyapunov(m.A, m.GQGT)
    np.testing.assert_allclose(P_disc, P_cont, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(env.stationary_cov, P_cont, rtol=1e-12)


def test_sampled_matrices_against_quadrature():
    """Q_d = ∫ e^{As} G q Gᵀ e^{Aᵀs} ds by adaptive quadrature (independent of Van Loan)."""
    env = gym.make("fir_gym/CarrierMotion-v0", sample_period=0.5).unwrapped
    A, G, C = carrier_continuous(env.params)
    Q_quad, _ = scipy.integrate.quad_vec(
        lambda s: scipy.linalg.expm(A * s) @ G @ G.T @ scipy.linalg.expm(A * s).T * 0.035,
        0.0, 0.5, epsabs=1e-14, epsrel=1e-12)
    np.testing.assert_allclose(env.model.Q, Q_quad, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(env.model.A, scipy.linalg.expm(A * 0.5), rtol=1e-13)
    assert env.model.R[0, 0] == pytest.approx(1.0 / 0.5)
    np.testing.assert_array_equal(env.model.C, C)


def test_calm_sea_plant_follows_the_model_exactly():
    env = gym.make("fir_gym/CarrierMotion-v0", q=0.0, initial_state=(0.3, -0.1)).unwrapped
    _, info = env.reset(seed=0)
    for _ in range(30):
        x = info["state"]
        _, _, _, _, info = env.step(np.array([0.5]))
        np.testing.assert_allclose(info["state"], env.model.f(x, [0.5]), rtol=1e-15, atol=1e-17)


def test_plant_residuals_have_covariance_Q_d_and_states_are_stationary():
    env = gym.make("fir_gym/CarrierMotion-v0", max_episode_steps=None).unwrapped
    _, info = env.reset(seed=9)
    states, w = [info["state"]], []
    for _ in range(20000):
        x = info["state"]
        _, _, _, _, info = env.step(np.zeros(1))
        w.append(info["state"] - env.model.f(x))
        states.append(info["state"])
    w, states = np.array(w), np.array(states)
    n = len(w)
    Q_d = env.model.Q
    tol = 5 * np.sqrt((np.outer(np.diag(Q_d), np.diag(Q_d)) + Q_d**2) / n)
    assert np.all(np.abs(np.cov(w.T) - Q_d) < tol)
    # stationary variance of x1, with ~ n·dt/τ_c effectively independent samples (τ_c ≈ 33 s)
    n_eff = n * 0.1 / (2 * 33.0)
    assert states[:, 0].var() == pytest.approx(env.stationary_cov[0, 0], rel=5 * np.sqrt(2 / n_eff))


def test_true_uncertainty_differs_from_the_nominal_model():
    env = gym.make("fir_gym/CarrierMotion-v0", delta22=0.006, delta_c=0.1, q=0.0,
                   initial_state=(0.5, 0.0)).unwrapped
    env.reset(seed=0)
    nominal = gym.make("fir_gym/CarrierMotion-v0").unwrapped.model
    np.testing.assert_array_equal(env.model.A, nominal.A)      # the model keeps Δ = 0
    _, _, _, _, info = env.step(np.zeros(1))
    assert not np.allclose(info["state"], nominal.f(np.array([0.5, 0.0])), atol=1e-6)
    matched = gym.make("fir_gym/CarrierMotion-v0", delta22=0.006, delta_c=0.1,
                       nominal={"delta22": 0.006, "delta_c": 0.1}).unwrapped
    np.testing.assert_allclose(matched.model.C, [[1.1, 0.0]])


def test_reward_is_normalised_compensation_residual():
    env = gym.make("fir_gym/CarrierMotion-v0").unwrapped
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.array([0.25]))
    sigma = np.sqrt(env.stationary_cov[0, 0])
    assert reward == pytest.approx(-((info["state"][0] - 0.25 * env.c_max) / sigma) ** 2)


@pytest.mark.parametrize("kwargs", [{"a22": 0.5}, {"q": -1.0}, {"v": 0.0},
                                    {"sample_period": -0.1}, {"initial_state_cov": "flat"},
                                    {"noise_input": (1.0, 2.0, 3.0)}])
def test_invalid_parameters_raise(kwargs):
    with pytest.raises(ValueError, match="|".join(kwargs)):
        gym.make("fir_gym/CarrierMotion-v0", **kwargs)


def test_the_default_plant_is_paper_001s():
    """The defaults are the carrier model as paper 001 prints it (docs/papers.md#001-plant):
    ``ẋ = [[0, 1], [−0.36, −0.06 + Δ22]] x + [0.6, −0.036]ᵀ w``, ``z = [1 + Δc, 0] x + v``,
    ``q = 0.035``, ``v = 1`` — the matrices the env samples, with Δ22 and Δc where asked."""
    env = gym.make("fir_gym/CarrierMotion-v0").unwrapped
    A, G, C = carrier_continuous(env.params)
    np.testing.assert_array_equal(A, [[0.0, 1.0], [-0.36, -0.06]])
    np.testing.assert_array_equal(G, [[0.6], [-0.036]])
    np.testing.assert_array_equal(C, [[1.0, 0.0]])
    assert env.params["q"] == 0.035 and env.params["v"] == 1.0
    off = gym.make("fir_gym/CarrierMotion-v0", delta22=0.006, delta_c=-0.1).unwrapped
    A, _, C = carrier_continuous(off.params)
    np.testing.assert_allclose(A, [[0.0, 1.0], [-0.36, -0.054]], rtol=1e-15)
    np.testing.assert_allclose(C, [[0.9, 0.0]], rtol=1e-15)


def test_the_lqr_is_the_one_step_predictor_of_the_deck():
    """The action does not move the deck, so the cost ``((x1[k+1] − c_max a) / σ1)²`` is
    least at ``a = E[x1[k+1] | x] / c_max = (C A_d x) / c_max`` — the LQR on the design
    point must be that certainty-equivalent predictor, on both states (``u = −K x``)."""
    from fir_gym.controllers import design_point
    from fir_gym.controllers.lqr import lqr_design
    for c_max in (0.7, 2.0):
        env = gym.make("fir_gym/CarrierMotion-v0", c_max=c_max).unwrapped
        m = env.model
        predictor = (m.C @ m.A)[0] / c_max
        assert np.all(np.abs(predictor) > 1e-2)                # both states carry weight
        K = lqr_design(m, design_point(env)).K
        np.testing.assert_allclose(-K[0], predictor, rtol=1e-9)   # exact differences of linear f
