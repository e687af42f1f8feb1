"""Nothing non-finite leaves a plant (issue 18, item 5): failed steps, reset states, renders."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym
from fir_gym.envs._base import SIMULATION_FAILURES
from fir_gym.envs._draw import ACCENT, BACKGROUND
from fir_gym.envs.carrier_motion import CarrierMotionEnv
from fir_gym.wrappers import EstimatorObservation, TrueStateObservation

ENV_IDS = fir_gym.ENV_IDS


def assert_failed_step(out, failure, previous_obs, previous_state):
    """A failed step: terminated with the flag, at the last valid state, all finite."""
    obs, reward, terminated, truncated, info = out
    assert terminated and not truncated
    assert info["simulation_failure"] == failure and failure in SIMULATION_FAILURES
    np.testing.assert_array_equal(obs, previous_obs)
    np.testing.assert_array_equal(info["state"], previous_state)
    assert np.isfinite(reward)
    for key, value in info.items():
        if key != "simulation_failure":
            assert np.all(np.isfinite(value)), key


def test_a_state_that_goes_nan_ends_the_episode_at_the_last_valid_state():
    """VanDerPol with a huge noise intensity: the first Heun steps overflow to NaN. The
    env used to report the NaN state (and TrueStateObservation returned [nan, nan])."""
    env = gym.make("fir_gym/VanDerPol-v0", Q=1e300).unwrapped
    obs0, info0 = env.reset(seed=0)
    out = env.step(np.zeros(1))
    assert_failed_step(out, "nonfinite_state", obs0, info0["state"])
    assert "x1_average" not in out[4]                  # the NaN extra is left out
    np.testing.assert_array_equal(env.state, info0["state"])
    # a failed step is a termination: it pays the terminal penalty (issue 13's honest
    # tasks; the reward of staying at the start would let a policy end early cheaply)
    assert out[1] == pytest.approx(-env.cost_cap * env.max_episode_steps)


def test_true_state_observation_stays_finite_when_the_plant_fails():
    env = TrueStateObservation(gym.make("fir_gym/VanDerPol-v0", Q=1e300))
    first, _ = env.reset(seed=0)
    obs, reward, terminated, _, info = env.step(np.zeros(1))
    np.testing.assert_array_equal(obs, first)
    assert terminated and info["simulation_failure"] == "nonfinite_state"
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)


def test_true_state_observation_guards_an_env_that_reports_nan():
    """An env outside fir-gym whose info['state'] goes NaN: the wrapper repeats the last
    finite state and ends the episode with the flag."""

    class Broken(gym.Env):
        state_names = ("a", "b")
        observation_space = gym.spaces.Box(-np.inf, np.inf, (1,))
        action_space = gym.spaces.Box(-1.0, 1.0, (1,))

        def reset(self, *, seed=None, options=None):
            self.k = 0
            return np.zeros(1), {"state": np.array([1.0, 2.0])}

        def step(self, action):
            self.k += 1
            state = np.array([3.0, 4.0]) if self.k == 1 else np.array([np.nan, 0.0])
            return np.zeros(1), -1.0, False, False, {"state": state}

    env = TrueStateObservation(Broken())
    env.reset()
    np.testing.assert_array_equal(env.step(np.zeros(1))[0], [3.0, 4.0])
    obs, _, terminated, _, info = env.step(np.zeros(1))
    np.testing.assert_array_equal(obs, [3.0, 4.0])
    assert terminated and info["simulation_failure"] == "nonfinite_state"

    class BrokenStart(Broken):
        def reset(self, *, seed=None, options=None):
            return np.zeros(1), {"state": np.array([np.inf, 0.0])}

    with pytest.raises(ValueError, match="reset returned a state that is not finite"):
        TrueStateObservation(BrokenStart()).reset()


def test_estimator_in_the_loop_sees_finite_measurements_when_the_plant_fails():
    env = EstimatorObservation(gym.make("fir_gym/VanDerPol-v0", Q=1e300), "ekf")
    env.reset(seed=0)
    obs, reward, terminated, _, info = env.step(np.zeros(1))
    assert terminated and info["simulation_failure"] == "nonfinite_state"
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(info["estimation_error"]))
    assert np.isfinite(reward)


def test_a_state_beyond_the_state_limit_is_a_failed_step():
    """The printed reading of paper 000's oscillator with δ = 1e200: x2 = 0.12 becomes
    1.2e199 in one step (beyond the 1e150 limit, where the quadratic rewards would
    overflow); the state bound is opened so that only the limit can end the episode."""
    env = gym.make("fir_gym/UncertainOscillator-v0", delta_schedule=((1, 5, 1e200),),
                   state_bound=1e300).unwrapped
    env.reset(seed=0)
    obs, _, terminated, _, info = env.step(np.zeros(1))
    assert not terminated and "simulation_failure" not in info
    out = env.step(np.zeros(1))
    assert_failed_step(out, "state_overflow", obs, info["state"])


class _RewardOverflow(CarrierMotionEnv):
    """A plant whose transition reward is not finite (as -x² is beyond 1e154)."""

    def _reward(self, x, a, x_next):
        return -np.inf


class _MeasurementOverflow(CarrierMotionEnv):
    """A plant whose measurement of a transition is not finite."""

    def _noise_free_measurement(self, x, extra):
        return np.full(x.shape[:-1] + (1,), np.inf) if extra else x @ self._C.T


@pytest.mark.parametrize(("cls", "failure"), [(_RewardOverflow, "nonfinite_reward"),
                                              (_MeasurementOverflow, "nonfinite_observation")])
def test_a_non_finite_reward_or_measurement_is_a_failed_step(cls, failure):
    env = cls()
    obs0, info0 = env.reset(seed=0)
    assert_failed_step(env.step(np.zeros(1)), failure, obs0, info0["state"])


@pytest.mark.parametrize("env_id", ["fir_gym/CarrierMotion-v0", "fir_gym/Orbit-v0"])
def test_reset_to_a_state_of_1e200_is_refused(env_id):
    """Issue 18: CarrierMotion and Orbit reset to 1e200 returned reward -inf (and
    CarrierMotion terminated=False). Such a state is not a valid start."""
    env = gym.make(env_id)
    with pytest.raises(ValueError, match=r"options\['state'\] must be finite and within"):
        env.reset(seed=0, options={"state": [1e200, 1e200]})
    with pytest.raises(ValueError, match=r"options\['state'\] must be finite"):
        env.reset(seed=0, options={"state": [np.nan, 0.0]})


OUTSIDE = {
    "fir_gym/Orbit-v0": [0.5, 2.0],                      # inside the planet (r <= r_min)
    "fir_gym/UncertainOscillator-v0": [2e4, 0.0, 0.5],   # beyond the state bound 1e4
    "fir_gym/VanDerPol-v0": [25.0, 0.0],                 # beyond the state bound 20
    "fir_gym/PendulumSlider-v0": [0.5, 0.0, 0.0, 0.0],   # off the rail (|x - l0| > 0.3)
}


@pytest.mark.parametrize("env_id", sorted(OUTSIDE))
def test_reset_to_a_state_outside_the_domain_is_refused(env_id):
    """The decision: a state where the episode would end at once is refused at reset
    (naming options['state'] and the domain), not accepted and terminated at step 0."""
    env = gym.make(env_id)
    with pytest.raises(ValueError, match=r"options\['state'\] = .* is outside the domain"):
        env.reset(seed=0, options={"state": OUTSIDE[env_id]})
    env.reset(seed=0)                                    # the env is still usable


def test_the_mujoco_plant_uses_mujocos_state_limit():
    env = gym.make("fir_gym/PendulumSlider-v0")
    with pytest.raises(ValueError, match=r"within ±1e\+10"):
        env.reset(seed=0, options={"state": [0.025, 0.0, 0.0, 2e10]})


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, 1e200])
def test_render_of_a_broken_state_draws_something(env_id, bad):
    """render() used to raise "cannot convert float NaN to integer" (envs/_draw.py)."""
    env = gym.make(env_id, render_mode="rgb_array").unwrapped
    env.reset(seed=0)
    healthy = env.render()
    env.state = np.full(len(env.state_names), bad)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == healthy.shape
    if getattr(env, "mj_model", None) is None:         # MuJoCo draws its own simulation
        assert tuple(frame[0, 0]) == ACCENT and tuple(frame[-1, -1]) == ACCENT   # red frame
        assert tuple(healthy[0, 0]) == BACKGROUND
        if np.isnan(bad) or np.isfinite(bad):            # a view that can still be fitted:
            inside = frame[10:-10, 10:-10].reshape(-1, 3)   # the finite parts are drawn
            assert len(np.unique(inside, axis=0)) >= 2


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_long_random_runs_never_flag_a_failure(env_id):
    """The guard is silent on the plants' own dynamics: no flag over random episodes."""
    env = gym.make(env_id, max_episode_steps=300)
    rng = np.random.default_rng(0)
    for episode in range(3):
        env.reset(seed=episode)
        for _ in range(300):
            obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, (1,)))
            assert "simulation_failure" not in info
            assert np.all(np.isfinite(obs)) and np.isfinite(reward)
            if terminated or truncated:
                break


# ---------------------------------------------------------------------------- vector envs
def make_vector(env_id, num_envs=3, **kwargs):
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


def test_vector_env_sub_envs_fail_alone_with_the_same_rules():
    """Three oscillators, one started at x2 = 1e20: its first step overflows (δ = 1e140
    from k = 0) and it alone terminates at its last state, flagged; the others go on.
    The next step autoresets it."""
    venv = make_vector("fir_gym/UncertainOscillator-v0", delta_schedule=((0, 5, 1e140),),
                       state_bound=1e300)
    start = np.array([[0.0, 0.0, 0.5], [0.0, 1e20, 0.5], [0.1, 0.0, 0.5]])
    obs0, _ = venv.reset(seed=0, options={"state": start})
    obs, reward, terminated, truncated, info = venv.step(np.zeros((3, 1)))
    np.testing.assert_array_equal(terminated, [False, True, False])
    assert not truncated.any()
    assert list(info["simulation_failure"]) == [None, "state_overflow", None]
    np.testing.assert_array_equal(info["_simulation_failure"], [False, True, False])
    np.testing.assert_array_equal(info["state"][1], start[1])
    np.testing.assert_array_equal(obs[1], obs0[1])
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
    assert np.all(np.abs(info["state"]) <= 1e150)
    # a failed step is a termination: the terminal penalty (issue 13's honest tasks)
    plant = venv.unwrapped.plant
    assert reward[1] == pytest.approx(-plant.cost_cap * plant.max_episode_steps)
    obs, reward, terminated, _, info = venv.step(np.zeros((3, 1)))     # autoreset of env 1
    assert reward[1] == 0.0 and not terminated[1]
    np.testing.assert_array_equal(info["state"][1], plant.initial_state)


def test_vector_env_masks_non_finite_extras_of_failed_sub_envs():
    """VanDerPol with a huge noise intensity: every sub-env's state goes NaN at once."""
    venv = make_vector("fir_gym/VanDerPol-v0", Q=1e300)
    obs0, info0 = venv.reset(seed=0)
    obs, reward, terminated, _, info = venv.step(np.zeros((3, 1)))
    assert terminated.all() and list(info["simulation_failure"]) == ["nonfinite_state"] * 3
    np.testing.assert_array_equal(obs, obs0)
    np.testing.assert_array_equal(info["state"], info0["state"])
    assert np.all(np.isfinite(reward))
    assert not info["_x1_average"].any() and np.all(info["x1_average"] == 0.0)


@pytest.mark.parametrize("env_id", fir_gym.VECTOR_ENV_IDS)
def test_vector_env_normal_steps_have_no_failure_key(env_id):
    venv = make_vector(env_id, 4)
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(50):
        _, reward, _, _, info = venv.step(rng.uniform(-1, 1, (4, 1)))
        assert "simulation_failure" not in info and np.all(np.isfinite(reward))
