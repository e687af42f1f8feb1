"""The plant's penalty horizon follows the time limit ``gym.make`` applies.

A plant that leaves its domain is paid ``-cost_cap * (1 + steps left to its horizon)``
(envs/_base.py, "Rewards and episode end"), so that ending an episode early never pays.
``gym.make(id, max_episode_steps=N)`` truncates at ``N`` (Gymnasium's ``TimeLimit``); these
tests check that the plant then charges for exactly the steps left to ``N`` — for ``N``
shorter and longer than the registered limit, with the estimator options, through copies,
spec round trips and vector envs — and that ``gym.make(id)`` is what it was.

The oracles: the ``N`` given to ``gym.make``, the step count the test keeps itself and the
plant's documented worst rate ``cost_cap``; the return of a crash against the worst
continuation to ``N`` step by step.
"""

from __future__ import annotations

import copy
import inspect
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import EnvSpec
from hypothesis import given, settings
from hypothesis import strategies as st

import fir_gym
from fir_gym._registration import PAPER_PLANTS
from fir_gym.wrappers.factory import make_time_limit

ENV_IDS = fir_gym.ENV_IDS
LIMIT = {row.id: row.max_episode_steps for row in PAPER_PLANTS}
CLASS = {row.id: row.plant.split(":")[1] for row in PAPER_PLANTS}

#: a start from which full thrust leaves the domain within a few steps (test_honest_tasks)
CRASH_START = {"fir_gym/Orbit-v0": [1.2, -3.0],
               "fir_gym/UncertainOscillator-v0": [9000.0, 9000.0, 0.5],
               "fir_gym/VanDerPol-v0": [19.5, 19.5]}
CRASH_IDS = tuple(CRASH_START)


def shorter_and_longer(env_id: str) -> tuple[int, int]:
    """A limit below the registered one and one well above it."""
    return LIMIT[env_id] // 2, 3 * LIMIT[env_id] + 7


def crash(env: gym.Env, env_id: str) -> tuple[list[float], bool]:
    """Full thrust from the crash start until the episode ends: the rewards, and whether it
    ended by termination (not by the time limit)."""
    env.reset(seed=0, options={"state": CRASH_START[env_id]})
    rewards: list[float] = []
    while True:
        _, reward, terminated, truncated, _ = env.step(np.ones(1))
        rewards.append(float(reward))
        if terminated or truncated:
            return rewards, bool(terminated)


def assert_penalty_counts_the_steps_left_to(limit: int, rewards: list[float], cap: float
                                            ) -> None:
    """The terminal reward is ``-cap`` for the step and each step left to ``limit``, so the
    crash's return is at most that of any continuation to ``limit`` at the worst rate."""
    k = len(rewards)
    assert k <= limit
    assert rewards[-1] == pytest.approx(-cap * (1 + limit - k), rel=1e-12)
    worst_continuation = sum(rewards[:-1]) + sum(-cap for _ in range(k, limit + 1))
    assert sum(rewards) <= worst_continuation + 1e-9 * abs(worst_continuation)


# ---------------------------------------------------------------------------- the horizon
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_plant_takes_the_limit_of_gym_make_shorter_or_longer(env_id):
    for n in shorter_and_longer(env_id):
        env = gym.make(env_id, max_episode_steps=n)
        assert env.unwrapped.max_episode_steps == n
        assert env.spec.max_episode_steps == n
        env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gym_make_without_a_limit_is_as_before(env_id):
    """The registered limit, the same wrappers, spec and JSON as the registry's, and the
    checker's warnings of an env made with the limit spelled out."""
    env = gym.make(env_id)
    plant = env.unwrapped
    assert plant.max_episode_steps == LIMIT[env_id] == type(plant).default_max_episode_steps
    assert str(env) == f"<TimeLimit<OrderEnforcing<PassiveEnvChecker<{CLASS[env_id]}<{env_id}>>>>>"
    assert env.spec.to_json() == gym.spec(env_id).to_json()
    assert plant.spec.kwargs == {} and plant.spec.max_episode_steps is None
    env.close()


def test_the_checker_sees_nothing_new():
    def warned(**kwargs):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            env = gym.make("fir_gym/Orbit-v0", **kwargs)
            env.reset(seed=0)
            env.step(env.action_space.sample())
        return sorted(str(w.message) for w in caught)

    assert warned(max_episode_steps=3007) == warned()


def test_no_time_limit_keeps_the_default_horizon():
    """``max_episode_steps=-1``: no TimeLimit, and the plant keeps the default horizon
    (no finite penalty covers an episode without an end)."""
    env = gym.make("fir_gym/Orbit-v0", max_episode_steps=-1)
    assert "TimeLimit" not in str(env)
    assert env.unwrapped.max_episode_steps == LIMIT["fir_gym/Orbit-v0"]
    assert env.spec.max_episode_steps is None
    rewards, terminated = crash(env, "fir_gym/Orbit-v0")
    assert terminated
    assert_penalty_counts_the_steps_left_to(LIMIT["fir_gym/Orbit-v0"], rewards,
                                            env.unwrapped.cost_cap)


def test_an_entry_point_called_directly_leaves_the_horizon_alone():
    from fir_gym import _registration

    assert _registration.orbit().max_episode_steps == LIMIT["fir_gym/Orbit-v0"]
    assert _registration.orbit(max_episode_steps=321).max_episode_steps == 321
    assert make_time_limit(None) is None
    assert make_time_limit(inspect.currentframe()) is None      # not gymnasium.make's frame


# ---------------------------------------------------------------------------- the penalty
@pytest.mark.parametrize("env_id", CRASH_IDS)
def test_a_crash_pays_for_exactly_the_steps_left_to_the_limit(env_id):
    """On three plants, for a limit shorter and one longer than the registered one."""
    for n in shorter_and_longer(env_id):
        env = gym.make(env_id, max_episode_steps=n)
        rewards, terminated = crash(env, env_id)
        assert terminated, "the plant was meant to leave its domain"
        assert_penalty_counts_the_steps_left_to(n, rewards, env.unwrapped.cost_cap)


@settings(max_examples=40, deadline=None)
@given(env_id=st.sampled_from(CRASH_IDS), scale=st.floats(0.01, 20.0),
       extra=st.integers(0, 5))
def test_ending_early_never_pays_at_any_limit(env_id, scale, extra):
    """Any limit (from one beyond the crash step up to twenty times the registered one): a
    terminated episode's return is at most that of any continuation to the limit."""
    probe, _ = crash(gym.make(env_id, max_episode_steps=-1), env_id)
    n = max(len(probe) + extra, int(scale * LIMIT[env_id]))
    env = gym.make(env_id, max_episode_steps=n)
    rewards, terminated = crash(env, env_id)
    assert terminated and len(rewards) == len(probe)
    assert_penalty_counts_the_steps_left_to(n, rewards, env.unwrapped.cost_cap)


@pytest.mark.parametrize("estimator", ["ekf", "efir"])
def test_the_estimator_options_keep_the_limit(estimator):
    n = 2500
    env = gym.make("fir_gym/Orbit-v0", estimator=estimator, max_episode_steps=n)
    assert "EstimatorObservation" in str(env)
    assert env.unwrapped.max_episode_steps == n
    rewards, terminated = crash(env, "fir_gym/Orbit-v0")
    assert terminated
    assert_penalty_counts_the_steps_left_to(n, rewards, env.unwrapped.cost_cap)


def test_a_sensor_fault_may_fall_after_the_default_limit_within_a_longer_one():
    """The plant knows the limit before the sensor wrapper is built: a bias at step 200 of a
    300-step VanDerPol-v0 episode (registered limit 100) is accepted."""
    env = gym.make("fir_gym/VanDerPol-v0", max_episode_steps=300, estimator="ekf",
                   sensor_faults={"bias": (200, 0.5)})
    assert env.unwrapped.max_episode_steps == 300


# ---------------------------------------------------------------------------- copies and specs
@pytest.mark.parametrize("env_id", ["fir_gym/Orbit-v0", "fir_gym/PendulumSlider-v0"])
def test_copies_and_remade_specs_keep_the_horizon(env_id):
    n = shorter_and_longer(env_id)[1]
    env = gym.make(env_id, max_episode_steps=n)
    env.reset(seed=0)
    env.step(np.zeros(1))
    for twin in (copy.deepcopy(env), pickle.loads(pickle.dumps(env)), gym.make(env.spec),
                 gym.make(EnvSpec.from_json(env.spec.to_json()))):
        assert twin.unwrapped.max_episode_steps == n
        assert twin.spec.max_episode_steps == n
    assert env.unwrapped.spec.kwargs == {}              # nothing was added to the spec
    assert str(env) == str(gym.make(env_id))


def test_a_copy_still_pays_the_penalty_to_the_limit():
    n = 4321
    env = copy.deepcopy(gym.make("fir_gym/Orbit-v0", max_episode_steps=n))
    rewards, terminated = crash(env, "fir_gym/Orbit-v0")
    assert terminated
    assert_penalty_counts_the_steps_left_to(n, rewards, env.unwrapped.cost_cap)


# ---------------------------------------------------------------------------- vector envs
def test_make_vec_sync_gives_each_sub_env_the_limit():
    n = 1234
    venv = gym.make_vec("fir_gym/Orbit-v0", 2, vectorization_mode="sync", max_episode_steps=n)
    assert [env.unwrapped.max_episode_steps for env in venv.envs] == [n, n]
    venv.close()


@pytest.mark.parametrize("n", [300, 2500])
def test_the_native_vector_env_pays_the_penalty_to_its_limit(n):
    venv = gym.make_vec("fir_gym/Orbit-v0", 2, vectorization_mode="vector_entry_point",
                        max_episode_steps=n)
    plant = venv.unwrapped.plant
    assert plant.max_episode_steps == n
    venv.reset(seed=0)
    venv.unwrapped.states[0] = [1.05, -5.0]
    _, reward, terminated, _, _ = venv.step(np.zeros((2, 1)))
    assert terminated.tolist() == [True, False]
    assert reward[0] == pytest.approx(-plant.cost_cap * n, rel=1e-12)


def test_the_native_vector_env_without_a_limit():
    """``max_episode_steps=-1`` means what it means for ``gym.make``: no truncation, and the
    plant keeps the default horizon."""
    venv = gym.make_vec("fir_gym/VanDerPol-v0", 2, vectorization_mode="vector_entry_point",
                        max_episode_steps=-1)
    assert venv.unwrapped.max_episode_steps is None
    assert venv.unwrapped.plant.max_episode_steps == LIMIT["fir_gym/VanDerPol-v0"]
    venv.reset(seed=0)
    for _ in range(LIMIT["fir_gym/VanDerPol-v0"] + 5):
        _, _, _, truncated, _ = venv.step(np.zeros((2, 1)))
        assert not truncated.any()


# ---------------------------------------------------------------------------- a plant of one's own
def test_register_plant_ids_follow_the_limit_too():
    """``register_plant`` gives the plant its limit as a keyword; ``gym.make``'s limit
    overrides it, and ``-1`` leaves it."""
    env_id = "time_limit_horizon_test/Orbit-v0"
    fir_gym.register_plant(env_id, "fir_gym.envs.orbit:OrbitEnv", max_episode_steps=300)
    try:
        assert gym.make(env_id).unwrapped.max_episode_steps == 300
        assert gym.make(env_id, max_episode_steps=700).unwrapped.max_episode_steps == 700
        assert gym.make(env_id, max_episode_steps=40).unwrapped.max_episode_steps == 40
        assert gym.make(env_id, max_episode_steps=-1).unwrapped.max_episode_steps == 300
    finally:
        del gym.registry[env_id]


# ---------------------------------------------------------------------------- fir-gym's own callers
@pytest.mark.parametrize("steps", [40, 2600, -1])
def test_make_single_env_gives_the_plant_the_limit_and_keeps_the_default_without_one(steps):
    """``fir_gym.training.make_single_env`` (what ``make_sb3_vec_env`` builds each
    non-native sub-env with) sets the horizon by hand for ids registered otherwise; with
    ``-1`` it once set it to -1, and a crash then paid one step's cost."""
    vec_env = pytest.importorskip("fir_gym.training.vec_env")
    env = vec_env.make_single_env("fir_gym/Orbit-v0", observation="true",
                                  max_episode_steps=steps)
    n = LIMIT["fir_gym/Orbit-v0"] if steps == -1 else steps
    assert env.unwrapped.max_episode_steps == n
    rewards, terminated = crash(env, "fir_gym/Orbit-v0")
    assert terminated
    assert_penalty_counts_the_steps_left_to(n, rewards, env.unwrapped.cost_cap)
