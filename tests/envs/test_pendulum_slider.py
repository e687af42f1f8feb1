"""PendulumSlider-v0: the MuJoCo plant against an RK4 integration of the corrected ODE."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import fir_gym  # noqa: F401
from fir_gym.envs.pendulum_slider_dynamics import PendulumSliderDynamics

INPUTS = {
    "sine": lambda t: 0.5 * np.sin(2 * np.pi * t),          # the paper's U = 5 sin 2πt
    "steps": lambda t: 0.3 * np.sign(np.sin(7.0 * t)),
    "chirp": lambda t: 0.8 * np.sin(2 * np.pi * (0.5 + 2.0 * t) * t),
}
STARTS = [(0.02, 0.0, 0.0, 0.0), (0.05, -0.2, 0.8, -1.0), (0.0, 0.3, -2.5, 4.0)]


def rk4_rollout(friction, x0, u_of_t, seconds):
    """The ODE of paper 003 (with the errata), integrated by classical RK4 at 1 ms."""
    dyn = PendulumSliderDynamics(friction=friction, input_scale=10.0)
    x, out = np.array(x0, dtype=float), []
    for k in range(round(seconds / 1e-3)):
        x = dyn.f(x, np.array([u_of_t(k * 1e-3)]))
        out.append(x)
    return np.array(out)


def mujoco_rollout(friction, x0, u_of_t, seconds):
    env = gym.make("fir_gym/PendulumSlider-v0", friction=friction, max_episode_steps=None).unwrapped
    env.reset(seed=0, options={"state": x0})
    return np.array([env.step(np.array([u_of_t(k * 1e-3)]))[4]["state"]
                     for k in range(round(seconds / 1e-3))])


@pytest.mark.parametrize(("friction", "tol"), [("none", 1e-6), ("paper", 1e-5)])
@pytest.mark.parametrize("start", STARTS)
@pytest.mark.parametrize("signal", sorted(INPUTS))
def test_mujoco_matches_rk4_of_the_ode_over_two_seconds(friction, tol, start, signal):
    u = INPUTS[signal]
    sim, ode = mujoco_rollout(friction, start, u, 2.0), rk4_rollout(friction, start, u, 2.0)
    assert np.max(np.abs(sim - ode)) <= tol


def test_a_force_frozen_across_rk4_stages_would_not_be_enough():
    """The exactness above is not automatic: holding the paper's force over a step misses."""
    env = gym.make("fir_gym/PendulumSlider-v0", friction="none").unwrapped
    dyn = PendulumSliderDynamics(friction="paper", input_scale=10.0)
    x0 = np.array(STARTS[1])
    env.reset(seed=0, options={"state": x0})
    d = env.mj_data
    x = x0.copy()
    err = 0.0
    for k in range(2000):
        u = INPUTS["sine"](k * 1e-3)
        a = dyn.derivatives(x, np.array(10.0 * u), dyn.mu, dyn.M0)[0]
        # the paper's force at the start of the step, held: F = -μ N
        N = (dyn.m1 + dyn.m2) * dyn.g + dyn.m2 * dyn.l * (np.cos(x[2]) * x[3] ** 2
                                                          + np.sin(x[2]) * a[3])
        d.qfrc_applied[0] = -dyn.mu * N
        env.step(np.array([u]))
        x = dyn.f(x, np.array([u]))
        err = max(err, float(np.max(np.abs(env.state - x))))
    assert err > 1e-4


def test_coulomb_slider_sticks_inside_the_band_and_slides_when_driven():
    env = gym.make("fir_gym/PendulumSlider-v0", friction="coulomb",
                   max_episode_steps=None).unwrapped
    p = env.params
    band = p["mu"] * (p["m1"] + p["m2"]) * p["g"] / (2 * p["k"])      # |x - l0| for sticking
    x0 = p["l0"] + 0.7 * band
    env.reset(seed=0, options={"state": [x0, 0.0, 0.0, 0.0]})
    xs = np.array([env.step(np.zeros(1))[4]["state"][0] for _ in range(10_000)])
    assert np.max(np.abs(xs - x0)) <= 1e-4
    env.reset(seed=0, options={"state": [x0, 0.0, 0.0, 0.0]})
    xs = np.array([env.step(np.array([0.5 * np.sin(2 * np.pi * k * 1e-3)]))[4]["state"][0]
                   for k in range(2000)])
    assert np.ptp(xs) > 2 * band                       # it slides well beyond its stick band
    # outside the band the spring wins: released there, it moves
    env.reset(seed=0, options={"state": [p["l0"] + 1.5 * band, 0.0, 0.0, 0.0]})
    xs = np.array([env.step(np.zeros(1))[4]["state"][0] for _ in range(500)])
    assert abs(xs[-1] - xs[0]) > 1e-3


def test_coulomb_friction_force_uses_the_true_normal_force():
    env = gym.make("fir_gym/PendulumSlider-v0", friction="coulomb").unwrapped
    env.reset(seed=0, options={"state": [0.025, 0.0, 0.0, 0.0]})
    env.step(np.zeros(1))
    m, d = env.mj_model, env.mj_data
    normal = 0.0
    force = np.zeros(6)
    for i in range(d.ncon):
        mujoco.mj_contactForce(m, d, i, force)
        normal += force[0]
    p = env.params
    assert normal == pytest.approx((p["m1"] + p["m2"]) * p["g"], rel=1e-3)


def test_paper_friction_moves_the_rest_position_to_10_8_mm():
    env = gym.make("fir_gym/PendulumSlider-v0").unwrapped
    assert env.x_rest == pytest.approx(0.010824, abs=1e-6)
    env.reset(seed=0, options={"state": [env.x_rest, 0.0, 0.0, 0.0]})
    for _ in range(500):
        _, _, _, _, info = env.step(np.zeros(1))
    np.testing.assert_allclose(info["state"], [env.x_rest, 0, 0, 0], atol=1e-12)


def test_measurement_noise_std_matches_R():
    env = gym.make("fir_gym/PendulumSlider-v0", max_episode_steps=None).unwrapped
    env.reset(seed=3)
    res = []
    for k in range(4000):
        obs, _, _, _, info = env.step(np.array([0.5 * np.sin(2 * np.pi * k * 1e-3)]))
        res.append(obs - info["state"])
    std = np.array(res).std(axis=0)
    n = len(res)
    np.testing.assert_allclose(std, [0.003, 0.03, 0.03, 0.3], rtol=5 / np.sqrt(2 * n))


def test_force_is_reported_and_frame_skip_steps_several_milliseconds():
    one = gym.make("fir_gym/PendulumSlider-v0").unwrapped
    ten = gym.make("fir_gym/PendulumSlider-v0", frame_skip=10).unwrapped
    one.reset(seed=0)
    _, start = ten.reset(seed=0)
    for _ in range(10):
        _, _, _, _, info_one = one.step(np.array([0.25]))
    _, _, _, _, info_ten = ten.step(np.array([0.25]))
    assert info_ten["force"] == pytest.approx(2.5)
    np.testing.assert_allclose(info_ten["state"], info_one["state"], rtol=0, atol=1e-15)
    assert ten.model.dt == pytest.approx(0.01)
    np.testing.assert_allclose(ten.model.f(start["state"], [0.25]), info_ten["state"],
                               atol=1e-13)


def test_model_is_parametric_in_mu_and_M0_with_the_papers_Q():
    env = gym.make("fir_gym/PendulumSlider-v0", nominal={"mu": 0.25}).unwrapped
    model = env.model
    assert model.params == {"mu": 0.25, "M0": 0.2}          # nominal μ, true M0
    np.testing.assert_allclose(model.Q, 1e-6 * np.eye(4))
    np.testing.assert_allclose(model.R, np.diag(np.square([0.003, 0.03, 0.03, 0.3])))
    assert env.params["mu"] == 0.2


def test_several_envs_and_other_mujoco_models_coexist():
    """The exact-friction callback is installed only while an env steps."""
    a = gym.make("fir_gym/PendulumSlider-v0").unwrapped
    b = gym.make("fir_gym/PendulumSlider-v0", mu=0.3).unwrapped
    a.reset(seed=0)
    b.reset(seed=0)
    for _ in range(5):
        a.step(np.zeros(1))
        b.step(np.zeros(1))
    assert mujoco.get_mjcb_passive() is None
    mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")    # compiles fine
    assert a.state[0] != b.state[0]


@pytest.mark.parametrize("kwargs", [{"friction": "sticky"}, {"m1": -1.0}, {"mu": -0.1},
                                    {"frame_skip": 0}, {"R": -np.eye(4)},
                                    {"initial_state_cov": "wobble"}])
def test_invalid_parameters_raise(kwargs):
    with pytest.raises(ValueError, match="|".join(kwargs)):
        gym.make("fir_gym/PendulumSlider-v0", **kwargs)


def test_unknown_physical_parameter_raises_type_error():
    with pytest.raises(TypeError, match="mass"):
        gym.make("fir_gym/PendulumSlider-v0", mass=1.0)
