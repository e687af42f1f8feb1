"""Honest tasks: bounded rewards, a terminal penalty that makes ending early never pay,
and trivial policies that score below the LQG baseline on every plant."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym
from fir_gym.wrappers import wrap_observation

ENV_IDS = fir_gym.ENV_IDS


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_reward_is_finite_and_no_worse_than_the_cost_cap(env_id):
    """Random actions from random starts: every reward lies in [-cost_cap, 0] unless the
    step terminates, when it is the documented penalty; and the reward of any state, even
    an absurd or non-finite one, is finite and at least -cost_cap."""
    env = gym.make(env_id)
    plant = env.unwrapped
    cap, T = plant.cost_cap, plant.max_episode_steps
    assert np.isfinite(cap) and cap > 0 and T == gym.spec(env_id).max_episode_steps
    rng = np.random.default_rng(0)
    for seed in range(3):
        env.reset(seed=seed)
        for k in range(1, 60):
            _, reward, terminated, _, _ = env.step(rng.uniform(-1, 1, 1))
            assert np.isfinite(reward)
            if terminated:
                assert reward == pytest.approx(-cap * (1 + T - k), rel=1e-12)
                break
            assert -cap <= reward <= 0.0
    n_x = len(plant.state_names)
    a = np.array([0.5])
    for x_next in (np.full(n_x, 1e200), np.full(n_x, -1e160), np.full(n_x, np.inf),
                   np.full(n_x, np.nan), rng.normal(scale=1e3, size=n_x)):
        with np.errstate(over="ignore", invalid="ignore"):
            reward = float(plant._reward(plant.initial_state, a, x_next))
        assert np.isfinite(reward) and -cap <= reward <= 0.0


@pytest.mark.parametrize(("env_id", "start"), [("fir_gym/CarrierMotion-v0", [1e149, 0.0]),
                                               ("fir_gym/Orbit-v0", [99.0, 1e149])])
def test_a_huge_start_state_gives_a_finite_reward(env_id, start):
    """Issue 18's report: reset(options={"state": [1e200, 0]}) gave reward -inf. Such a
    state is now refused (beyond ±state_limit); the largest accepted ones give the cap
    (the carrier: no termination) or the terminal penalty (the orbit leaves its domain)."""
    env = gym.make(env_id)
    env.reset(seed=0, options={"state": start})
    _, reward, terminated, _, _ = env.step(np.zeros(1))
    plant = env.unwrapped
    assert np.isfinite(reward)
    expected = -plant.cost_cap * plant.max_episode_steps if terminated else -plant.cost_cap
    assert reward == pytest.approx(expected)
    assert terminated == env_id.endswith("Orbit-v0")


@pytest.mark.parametrize("env_id", [e for e in ENV_IDS if not e.endswith("CarrierMotion-v0")])
def test_ending_early_never_pays(env_id):
    """Drive the plant out of its domain: the crash's return is at most what any way of
    staying alive for the rest of the episode could return (each step >= -cost_cap)."""
    env = gym.make(env_id)
    plant = env.unwrapped
    start = {"fir_gym/Orbit-v0": lambda: [1.2, -3.0],
             "fir_gym/UncertainOscillator-v0": lambda: [9000.0, 9000.0, 0.5],
             "fir_gym/VanDerPol-v0": lambda: [19.5, 19.5],
             "fir_gym/PendulumSlider-v0": lambda: [plant.params["l0"] + 0.29, 3.0, 0.0, 0.0],
             }[env_id]()
    env.reset(seed=0, options={"state": start})
    rewards = []
    for _ in range(plant.max_episode_steps):
        _, reward, terminated, truncated, _ = env.step(np.ones(1))
        rewards.append(float(reward))
        if terminated or truncated:
            break
    assert terminated, "the plant was meant to leave its domain"
    k = len(rewards)
    crash = sum(rewards)
    best_staying_alive_floor = sum(rewards[:-1]) - plant.cost_cap * (plant.max_episode_steps - k
                                                                      + 1)
    assert crash <= best_staying_alive_floor + 1e-9 * abs(crash)


def test_the_vector_env_pays_the_same_terminal_penalty():
    venv = gym.make_vec("fir_gym/Orbit-v0", 2, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    plant = venv.unwrapped.plant
    venv.unwrapped.states[0] = [1.05, -5.0]
    _, reward, terminated, _, _ = venv.step(np.zeros((2, 1)))
    assert terminated.tolist() == [True, False]
    assert reward[0] == pytest.approx(-plant.cost_cap * plant.max_episode_steps)
    assert -plant.cost_cap <= reward[1] <= 0


def test_the_plant_learns_its_limit_from_the_constructor_and_the_vector_env():
    assert gym.make("fir_gym/Orbit-v0").unwrapped.max_episode_steps == 1000
    assert fir_gym.envs.OrbitEnv(max_episode_steps=300).max_episode_steps == 300
    venv = gym.make_vec("fir_gym/Orbit-v0", 2, vectorization_mode="vector_entry_point",
                        max_episode_steps=200)
    assert venv.unwrapped.plant.max_episode_steps == 200
    with pytest.raises(ValueError, match="max_episode_steps"):
        fir_gym.envs.OrbitEnv(max_episode_steps=0)


# ---------------------------------------------------------------------------- baselines
def _returns(env, policy, seeds):
    out = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total = 0.0
        while True:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total += float(reward)
            if terminated or truncated:
                break
        out.append(total)
    return np.array(out)


#: seeds per plant (the carrier's and the Van der Pol oscillator's returns vary most between
#: episodes: on VanDerPol-v0 one episode's return ranges from about -150 to -2600 under
#: the same policy), and a shorter time limit for the MuJoCo plant (its penalty then
#: over-counts: still honest)
SEEDS = {"fir_gym/CarrierMotion-v0": range(10), "fir_gym/VanDerPol-v0": range(40),
         "fir_gym/PendulumSlider-v0": range(3)}
LIMIT = {"fir_gym/PendulumSlider-v0": 2000}


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_trivial_policies_score_below_the_lqg_baseline(env_id):
    from fir_gym.controllers import LQGController

    seeds = SEEDS.get(env_id, range(4))
    limit = {"max_episode_steps": LIMIT[env_id]} if env_id in LIMIT else {}
    plain = gym.make(env_id, **limit)
    rng = np.random.default_rng(0)
    trivial = {f"constant {c:+g}": _returns(plain, lambda o, c=c: np.array([c]), seeds)
               for c in (-1.0, 0.0, 1.0)}
    trivial["uniform random"] = _returns(plain, lambda o: rng.uniform(-1, 1, 1), seeds)
    for kind in ("true", "ekf"):
        env = wrap_observation(gym.make(env_id, **limit), kind)
        controller = LQGController(env)
        lqg = _returns(env, lambda o, c=controller: c.predict(o)[0], seeds)
        for name, returns in trivial.items():
            # paired: the same seeds, so the same noise where actions do not change it
            assert returns.mean() < lqg.mean(), (kind, name, returns.mean(), lqg.mean())
