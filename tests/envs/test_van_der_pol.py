"""VanDerPol-v0: paper 002's oscillator, integrated finely, interval-averaged measurement."""

import gymnasium as gym
import numpy as np
import pytest
import scipy.integrate

import fir_gym  # noqa: F401
from fir_gym.envs.van_der_pol import limit_cycle_states
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
    plant's spread after one interval must equal Van Loan's ∫ e^{A0 s} g Q gᵀ e^{A0ᵀ s} ds
    (the plant's noise; the model's is tested against the plant over the limit cycle below)."""
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


#: the period of the ε = 1 Van der Pol limit cycle (the literature's value, e.g. Strogatz,
#: Nonlinear Dynamics and Chaos, §7.5; checked against solve_ivp below)
PERIOD_EPS1 = 6.663286859323130


def _cycle_by_solve_ivp(points):
    """``points`` states of the ε = 1 limit cycle, equally spaced in time: scipy, not fir-gym."""
    sol = scipy.integrate.solve_ivp(vdp, (0, 60), [2.0, 0.0], rtol=1e-11, atol=1e-11,
                                    dense_output=True)
    return sol.sol(50 + PERIOD_EPS1 * np.arange(points) / points).T


def test_limit_cycle_states_are_one_period_uniform_in_time():
    states = limit_cycle_states(1.0)
    n = len(states)
    # each point reaches the next after T/n, and the last reaches the first: one period
    nxt = [scipy.integrate.solve_ivp(vdp, (0, PERIOD_EPS1 / n), x, rtol=1e-11,
                                     atol=1e-11).y[:, -1] for x in states[::16]]
    np.testing.assert_allclose(nxt, np.roll(states, -1, axis=0)[::16], atol=1e-7)
    # the same closed curve as scipy's from another start
    ref = _cycle_by_solve_ivp(4096)
    gap = np.min(np.linalg.norm(states[:, None] - ref[None], axis=-1), axis=1)
    assert gap.max() < 4 * np.max(np.linalg.norm(np.diff(ref, axis=0), axis=1))
    with pytest.raises(ValueError, match="epsilon > 0"):
        limit_cycle_states(0.0)


def test_model_noise_is_the_plants_one_step_spread_averaged_over_the_limit_cycle():
    """The model's G Q Gᵀ is the covariance the plant's own stochastic Heun integration adds
    over one interval, averaged over starts spread uniformly in time over one period of the
    limit cycle (scipy's, not fir-gym's). Weak noise (Q = 0.05) keeps the spread linear; the
    Monte Carlo's 5σ band (about 2 %) excludes the origin's linearisation (off by 11 % in
    Q12, 17 % in Q22) and the first-order Q h 11ᵀ (rank one)."""
    Q, M = 0.05, 2000
    env = gym.make("fir_gym/VanDerPol-v0", Q=Q).unwrapped
    dyn = env.dynamics
    starts = _cycle_by_solve_ivp(64)
    rng = np.random.default_rng(1)
    dW = np.sqrt(Q * dyn.tau) * rng.standard_normal((dyn.substeps, 64 * M))
    ends, _, _ = dyn.integrate(np.repeat(starts, M, axis=0), np.zeros((64 * M, 1)), dW)
    d = ends.reshape(64, M, 2)
    d = d - d.mean(axis=1, keepdims=True)
    per_start = np.einsum("smi,smj->sij", d, d) / (M - 1)              # (64, 2, 2)
    mc = per_start.mean(axis=0)
    model = env.model.GQGT
    assert env.model.n_w == 2 and np.linalg.eigvalsh(model)[0] > 0
    # sampling sd of an average of 64 sample covariances of M Gaussian draws each
    diag = np.diagonal(per_start, axis1=1, axis2=2)
    var = (diag[:, :, None] * diag[:, None, :] + per_start**2) / (M - 1)
    sd = np.sqrt(var.sum(axis=0)) / 64
    assert np.all(np.abs(mc - model) < 5 * sd), (mc, model, sd)
    # the weak direction [1, −1] (zero in the first-order model) to the same standard
    u = np.array([1.0, -1.0]) / np.sqrt(2.0)
    weak = np.einsum("i,sij,j->s", u, per_start, u)
    sd_weak = np.sqrt(np.sum(2 * weak**2 / (M - 1))) / 64
    assert abs(weak.mean() - u @ model @ u) < 5 * sd_weak


def test_the_ekfs_covariance_keeps_the_floor_its_process_noise_sets():
    """P⁻ = F P Fᵀ + Q_d ⪰ Q_d, and the update adds Hᵀ H h / R to P⁻¹, so after the first
    prediction λ_min(P) ≥ 1 / (1/λ_min(Q_d) + h/R) on every step (the rank-one first-order
    noise let it fall to the prior's 1e-9 across [1, −1], and one step's NEES to ~1e7)."""
    from fir_gym.controllers import LQGController

    env = gym.make("fir_gym/VanDerPol-v0", estimator="ekf")
    estimator = env.get_wrapper_attr("estimator")
    p = env.unwrapped.nominal_params
    floor = 1.0 / (1.0 / np.linalg.eigvalsh(env.unwrapped.model.GQGT)[0] + p["h"] / p["R"])
    for policy in (None, LQGController(env)):
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            for _ in range(100):
                action = np.zeros(1) if policy is None else policy.predict(obs)[0]
                obs, _, terminated, truncated, _ = env.step(action)
                assert np.linalg.eigvalsh(estimator.P)[0] >= floor * (1 - 1e-9)
                if terminated or truncated:
                    break


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
