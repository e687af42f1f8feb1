"""LQG: the operating points, the Riccati gain against brute force, stabilisation, predict."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym
from fir_gym.controllers import LQGController, design_point, lqr_design
from fir_gym.wrappers import wrap_observation

pytest.importorskip("stable_baselines3")


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
def test_the_operating_point_is_a_fixed_point_of_the_nominal_model(env_id):
    plant = gym.make(env_id).unwrapped
    point = design_point(plant)
    x_next = plant.model.f(point.x, point.u)
    np.testing.assert_allclose(x_next, point.x, atol=1e-9 * max(1.0, np.abs(point.x).max()))
    assert point.M.shape == (len(point.x) + 1,) * 2
    np.testing.assert_allclose(point.M, point.M.T)
    assert np.linalg.eigvalsh(point.M).min() >= -1e-12         # a cost: PSD


def _riccati_by_iteration(A, B, Q, R, N, sweeps=200_000):
    """The Riccati difference equation iterated to its fixed point: the DARE's oracle."""
    P = np.zeros_like(Q)
    for _ in range(sweeps):
        S = R + B.T @ P @ B
        K = np.linalg.solve(S, B.T @ P @ A + N.T)
        P_new = A.T @ P @ A - (A.T @ P @ B + N) @ K + Q
        P_new = 0.5 * (P_new + P_new.T)
        if np.max(np.abs(P_new - P)) <= 1e-12 * max(1.0, np.abs(P).max()):
            return P_new, K
        P = P_new
    raise AssertionError("the Riccati iteration did not converge")


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
def test_gain_equals_the_iterated_riccati_equation_and_stabilises(env_id):
    plant = gym.make(env_id).unwrapped
    point = design_point(plant)
    design = lqr_design(plant.model, point)
    s = list(point.states)
    A, B = design.A[np.ix_(s, s)], design.B[s]
    P, K = _riccati_by_iteration(A, B, design.Q, design.R, design.N)
    np.testing.assert_allclose(design.K[:, s], K, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(design.P, P, rtol=1e-6, atol=1e-9)
    assert np.max(np.abs(design.closed_loop_poles)) < 1.0     # the linearisation is stabilised


@pytest.mark.parametrize("env_id", fir_gym.ENV_IDS)
def test_the_riccati_solution_is_the_cost_to_go_of_the_reward_weights(env_id):
    """``x0ᵀ P x0`` is the closed loop's summed cost, each step's cost the design point's
    weights ``M`` on ``[x[k+1]; u[k]]`` (the reward's: the state after the step) — computed
    here by running the linearised closed loop, not from the design's own Q, R, N (mutation
    testing found a scaled cost matrix unseen: it leaves K unchanged and scales P)."""
    plant = gym.make(env_id).unwrapped
    point = design_point(plant)
    design = lqr_design(plant.model, point)
    s = list(point.states)
    A, B, K = design.A[np.ix_(s, s)], design.B[s], design.K[:, s]
    keep = s + [len(point.x) + j for j in range(B.shape[1])]
    M = point.M[np.ix_(keep, keep)]
    x0 = np.random.default_rng(0).normal(size=len(s)) * 1e-2
    x, cost = x0.copy(), 0.0
    for _ in range(100_000):
        u = -K @ x
        x_next = A @ x + B @ u
        z = np.concatenate([x_next, u])
        cost += z @ M @ z
        x = x_next
        if np.abs(x).max() < 1e-14 * np.abs(x0).max():
            break
    assert cost == pytest.approx(x0 @ design.P @ x0, rel=1e-6)


def test_the_carrier_lqr_is_the_one_step_predictor():
    """B = 0: minimising ((x1[k+1] - c_max a) / σ)² gives a = (A x)_1 / c_max."""
    env = wrap_observation(gym.make("fir_gym/CarrierMotion-v0"), "true")
    controller = LQGController(env)
    A = env.unwrapped.model.A
    x = np.array([0.3, -0.2])
    expected = (A @ x)[0] / env.unwrapped.c_max
    assert float(-(controller.design.K @ x)[0]) == pytest.approx(expected, rel=1e-9)
    action, _ = controller.predict(x)
    assert action[0] == np.float32(expected)                 # float32 actions, as SB3's


def _noise_free_run(env_id, steps, start, **kwargs):
    env = wrap_observation(gym.make(env_id, max_episode_steps=steps, **kwargs), "true")
    controller = LQGController(env)
    x, _ = env.reset(seed=0, options={"state": start})
    for _ in range(steps):
        action, _ = controller.predict(x)
        x, _, terminated, truncated, _ = env.step(action)
        assert not terminated
        if truncated:
            break
    return x, design_point(env.unwrapped).x


@pytest.mark.parametrize(("env_id", "steps", "start", "kwargs", "tol"), [
    ("fir_gym/Orbit-v0", 1500, [7.6, 0.8], {"nominal": {"mu": 19.92244165}}, 1e-3),
    ("fir_gym/UncertainOscillator-v0", 400, [0.0, 0.0, 0.5], {"Q": 0.0, "delta_schedule": ()},
     1e-3),
    ("fir_gym/VanDerPol-v0", 200, [1.0, 1.0], {"Q": 0.0}, 1e-3),
    ("fir_gym/PendulumSlider-v0", 3000, None, {}, 2e-3),
])
def test_lqg_on_the_true_state_stabilises_the_plant(env_id, steps, start, kwargs, tol):
    """Noise-free (or noise-free but for the MuJoCo truth), from a start away from the
    operating point, the closed loop settles on it."""
    if start is None:
        plant = gym.make(env_id).unwrapped
        start = [plant.x_rest + 0.05, 0.0, 0.4, 0.0]
    x, target = _noise_free_run(env_id, steps, start, **kwargs)
    np.testing.assert_allclose(x, target, atol=tol)


def test_lqg_holds_the_orbit_where_no_thrust_falls_and_full_reverse_crashes():
    env = wrap_observation(gym.make("fir_gym/Orbit-v0"), "ekf")
    controller = LQGController(env)
    x, _ = env.reset(seed=3)
    for _ in range(1000):
        x, _, terminated, _truncated, info = env.step(controller.predict(x)[0])
        assert not terminated
    assert abs(info["state"][0] - env.unwrapped.r_ref) < 0.05


def test_predict_has_stable_baselines3_shapes_and_stays_in_the_box():
    env = wrap_observation(gym.make("fir_gym/VanDerPol-v0"), "ekf")
    controller = LQGController(env)
    far = np.array([[15.0, -15.0], [0.0, 0.0], [-15.0, 15.0]])
    actions, state = controller.predict(far, state=None, episode_start=np.ones(3, bool),
                                        deterministic=True)
    assert actions.shape == (3, 1) and actions.dtype == np.float32 and state is None
    assert np.all(np.abs(actions) <= 1.0) and np.abs(actions[[0, 2]]).min() == 1.0
    single, _ = controller.predict(far[1])
    assert single.shape == (1,)


def test_predict_reads_the_estimate_of_a_dict_observation():
    env = wrap_observation(gym.make("fir_gym/Orbit-v0"), "ekf",
                           observation="estimate+covariance")
    controller = LQGController(env)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(controller.predict(obs)[0],
                                  controller.predict(obs["estimate"])[0])


def test_stable_baselines3_evaluate_policy_takes_the_controller():
    from stable_baselines3.common.evaluation import evaluate_policy

    from fir_gym.training import make_sb3_vec_env

    venv = make_sb3_vec_env("fir_gym/Orbit-v0", 4, estimator="ekf", seed=0,
                            max_episode_steps=50)
    controller = LQGController(venv)
    returns, lengths = evaluate_policy(controller, venv, n_eval_episodes=4,
                                       return_episode_rewards=True, warn=False)
    assert lengths == [50] * 4 and np.all(np.isfinite(returns))
    single = wrap_observation(gym.make("fir_gym/Orbit-v0", max_episode_steps=50), "ekf")
    mean, _ = evaluate_policy(LQGController(single), single, n_eval_episodes=2, warn=False)
    assert mean == pytest.approx(np.mean(returns), rel=0.5)


def test_lqg_refuses_the_raw_measurement():
    with pytest.raises(ValueError, match="estimate"):
        LQGController(gym.make("fir_gym/Orbit-v0"))


def test_the_van_der_pol_lqg_is_detuned_on_an_estimate_only():
    """VanDerPol-v0's estimate-fed LQG weights the input 3 (its design_point): the same
    design as the reward's weights with a² weighted 3, slower in x2 than the true-state LQR;
    ``input_weight`` overrides it and bad values are refused by name."""
    env_id = "fir_gym/VanDerPol-v0"
    true = LQGController(wrap_observation(gym.make(env_id), "true"))
    estimated = LQGController(gym.make(env_id, estimator="ekf"))
    assert true.point.M[2, 2] == 0.01 and estimated.point.M[2, 2] == 3.0
    np.testing.assert_array_equal(true.point.M[:2, :2], estimated.point.M[:2, :2])
    slow = np.sort(np.abs(estimated.design.closed_loop_poles))
    fast = np.sort(np.abs(true.design.closed_loop_poles))
    assert slow[0] > 10 * fast[0] and np.max(slow) < 1.0
    assert np.all(np.abs(estimated.design.K) < np.abs(true.design.K))
    by_hand = LQGController(gym.make(env_id, estimator="ekf"), input_weight=0.01)
    np.testing.assert_allclose(by_hand.design.K, true.design.K, rtol=1e-12)
    for bad in (0.0, -1.0, float("nan"), "heavy"):
        with pytest.raises(ValueError, match="input_weight"):
            LQGController(gym.make(env_id, estimator="ekf"), input_weight=bad)
