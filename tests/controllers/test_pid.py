"""PID on the measured output: the discrete law, its memory in predict's state, its limits."""

import gymnasium as gym
import numpy as np
import pytest

from fir_gym.controllers import LQGController, PIDController
from fir_gym.wrappers import wrap_observation


def test_one_step_is_the_textbook_law_with_a_filtered_derivative():
    env = gym.make("fir_gym/Orbit-v0")
    pid = PIDController(env, kp=2.0, ki=0.5, kd=1.0, tau=0.05)
    dt, alpha, u0 = pid.dt, 0.05 / (0.05 + pid.dt), pid.feedforward
    y0, y1 = 7.9, 7.95
    a0, state = pid.predict(np.array([y0]), episode_start=np.array([True]))
    assert a0[0] == pytest.approx(u0 + 2.0 * (8 - y0) + 0.5 * (8 - y0) * dt, rel=1e-6)
    a1, state = pid.predict(np.array([y1]), state=state, episode_start=np.array([False]))
    D = -(1 - alpha) * (y1 - y0) / dt
    I = (8 - y0) * dt + (8 - y1) * dt
    assert a1[0] == pytest.approx(u0 + 2.0 * (8 - y1) + 0.5 * I + 1.0 * D, rel=1e-6)
    # an episode start clears the memory: the same as a fresh start
    a2, _ = pid.predict(np.array([y1]), state=state, episode_start=np.array([True]))
    assert a2[0] == pytest.approx(pid.predict(np.array([y1]))[0][0], rel=1e-12)


def test_the_integral_does_not_wind_up_while_the_output_saturates():
    env = gym.make("fir_gym/Orbit-v0")
    pid = PIDController(env, kp=0.0, ki=10.0, kd=0.0)
    state = None
    for k in range(200):
        action, state = pid.predict(np.array([5.0]), state=state,
                                    episode_start=np.array([k == 0]))
    assert action[0] == 1.0
    # back above the setpoint, the action leaves the limit at once
    action, _ = pid.predict(np.array([8.5]), state=state, episode_start=np.array([False]))
    assert action[0] < 1.0


def test_pid_holds_the_orbit_radius():
    env = gym.make("fir_gym/Orbit-v0")
    pid = PIDController(env)
    y, _ = env.reset(seed=1)
    state, start = None, True
    for _ in range(1000):
        action, state = pid.predict(y, state=state, episode_start=np.array([start]))
        start = False
        y, _, terminated, _, info = env.step(action)
        assert not terminated
    assert abs(info["state"][0] - 8.0) < 0.1


def test_pid_refuses_an_estimate_and_a_task_without_a_setpoint():
    with pytest.raises(ValueError, match="raw measurement"):
        PIDController(wrap_observation(gym.make("fir_gym/Orbit-v0"), "ekf"))
    with pytest.raises(ValueError, match="PID does not apply"):
        PIDController(gym.make("fir_gym/CarrierMotion-v0"))
    with pytest.raises(ValueError, match="kp"):
        PIDController(gym.make("fir_gym/Orbit-v0"), kp=float("nan"))
    with pytest.raises(ValueError, match="output"):
        PIDController(gym.make("fir_gym/PendulumSlider-v0"), output=7)


def test_pid_and_lqg_keep_one_memory_per_env_in_a_batch():
    env = gym.make("fir_gym/Orbit-v0")
    pid = PIDController(env)
    ys = np.array([[7.9], [8.1]])
    batch, state = pid.predict(ys)
    assert state.shape == (2, 3)
    for i in range(2):
        np.testing.assert_allclose(batch[i], pid.predict(ys[i])[0])
    lqg = LQGController(wrap_observation(gym.make("fir_gym/Orbit-v0"), "true"))
    assert lqg.predict(np.zeros((2, 2)) + [8.0, 0.0])[1] is None
