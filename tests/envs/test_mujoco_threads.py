"""PendulumSlider-v0 in several threads, and MuJoCo's warnings: issue 18, item 4."""

import threading

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import fir_gym  # noqa: F401

FRICTIONS = ("none", "paper", "coulomb")
STEPS = 1500


def make(friction, seed, **kwargs):
    env = gym.make("fir_gym/PendulumSlider-v0", friction=friction, max_episode_steps=None,
                   **kwargs).unwrapped
    env.reset(seed=seed)
    return env


def rollout(env, actions):
    out = []
    for a in actions:
        obs, reward, terminated, _, info = env.step(a)
        assert not terminated
        out.append(np.concatenate([obs, info["state"], [reward]]))
    return np.array(out)


def test_envs_stepped_in_threads_give_exactly_their_solo_trajectories():
    """Two envs per friction mode, each in its own thread, stepped concurrently with a
    thread compiling MuJoCo models meanwhile: observations, states and rewards equal,
    bit for bit, those of the same envs stepped alone; every compilation succeeds."""
    configs = [(friction, seed) for friction in FRICTIONS for seed in (0, 1)]
    rng = np.random.default_rng(0)
    actions = {c: rng.uniform(-1, 1, (STEPS, 1)) for c in configs}
    solo = {c: rollout(make(*c), actions[c]) for c in configs}

    envs = {c: make(*c) for c in configs}
    results, errors = {}, []
    running = threading.Event()
    start = threading.Barrier(len(configs) + 1)

    def step(config):
        try:
            start.wait()
            results[config] = rollout(envs[config], actions[config])
        except BaseException as err:
            errors.append(err)

    compiled = []

    def compile_models():
        start.wait()
        while running.is_set():
            mujoco.MjModel.from_xml_string("<mujoco><worldbody><body><joint/><geom size='1'/>"
                                           "</body></worldbody></mujoco>")
            compiled.append(mujoco.get_mjcb_passive() is None)

    threads = [threading.Thread(target=step, args=(c,)) for c in configs]
    compiler = threading.Thread(target=compile_models)
    running.set()
    for t in (*threads, compiler):
        t.start()
    for t in threads:
        t.join()
    running.clear()
    compiler.join()
    assert errors == []
    for c in configs:
        np.testing.assert_array_equal(results[c], solo[c], err_msg=str(c))
    assert len(compiled) > 0 and all(compiled)
    # the friction modes do differ: the test would see one running under another's law
    assert not np.array_equal(solo[("none", 0)], solo[("paper", 0)])


@pytest.mark.parametrize("friction", FRICTIONS)
@pytest.mark.parametrize("frame_skip", [1, 3])
def test_mujoco_reset_warning_ends_the_episode_with_a_flag(friction, frame_skip, tmp_path,
                                                         monkeypatch):
    """A state whose accelerations MuJoCo finds too large (mjWARN_BADQACC: θ̇ = 1e6 at
    θ = π/2, a centripetal acceleration ~1e11) makes MuJoCo reset its data. The env
    says so and ends the episode at the state it started from, instead of carrying on
    from MuJoCo's reset state."""
    monkeypatch.chdir(tmp_path)                 # MuJoCo appends its warning to MUJOCO_LOG.TXT
    env = make(friction, 0, frame_skip=frame_skip)
    start = [0.0108, 0.0, np.pi / 2, 1e6]
    obs0, _ = env.reset(seed=0, options={"state": start})
    obs, reward, terminated, truncated, info = env.step(np.zeros(1))
    assert terminated and not truncated
    assert info["simulation_failure"] == "mjWARN_BADQACC"
    np.testing.assert_array_equal(info["state"], start)
    np.testing.assert_array_equal(env.state, start)
    np.testing.assert_array_equal(obs, obs0)
    assert np.isfinite(reward)
    # the simulation is back at the start state, not at MuJoCo's reset state
    np.testing.assert_array_equal(env.mj_data.qvel[env._dof], [0.0, 1e6])
    assert not env.mj_data.warning.number.any()


@pytest.mark.parametrize("friction", FRICTIONS)
def test_the_issue_state_that_mujoco_reset_silently_ends_the_episode(friction, tmp_path,
                                                                    monkeypatch):
    """Issue 18's reproducer: θ̇ = 1e7 at rest. The RK4 step blows up (the stages
    overflow to ~1e26); the episode ends with a flag, at the start state."""
    monkeypatch.chdir(tmp_path)                 # MuJoCo may log a warning to MUJOCO_LOG.TXT
    env = make(friction, 0)
    start = [0.0108, 0.0, 0.0, 1e7]
    env.reset(seed=0, options={"state": start})
    obs, reward, terminated, _, info = env.step(np.zeros(1))
    assert terminated
    assert info["simulation_failure"] in ("state_overflow", "mjWARN_BADQACC",
                                          "mjWARN_BADQVEL", "mjWARN_BADQPOS")
    np.testing.assert_array_equal(info["state"], start)
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)
    np.testing.assert_array_equal(env.mj_data.qvel[env._dof], [0.0, 1e7])   # restored


def test_normal_steps_raise_no_flag():
    env = make("paper", 0)
    for _ in range(200):
        _, _, terminated, _, info = env.step(np.array([0.7]))
        assert "simulation_failure" not in info and not terminated
