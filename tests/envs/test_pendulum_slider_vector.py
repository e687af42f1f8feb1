"""PendulumSlider-v0's native vector env against single MuJoCo envs, and its conditions.

The vector env integrates the analytic equations of motion (RK4, the true parameters per
system) where a single env runs MuJoCo's RK4 with the paper's force at every stage: the
same ODE by the same method and step, so the two agree to round-off. The oracle of each
sub-env is a single env seeded ``s + i`` (``generators="per_env"``).
"""

from __future__ import annotations

import copy
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import fir_gym  # noqa: F401
from fir_gym.envs import PendulumSliderEnv
from fir_gym.envs._vector import PlantVectorEnv

ENV_ID = "fir_gym/PendulumSlider-v0"
#: 500 steps of 10 ms: the paper's 5 s
FRAME_SKIP, EPISODE = 10, 500

#: |vector − single| allowed per state component [x, ẋ, θ, θ̇]: 1e-14 of each component's
#: scale (0.1 m, 1 m/s, 1 rad, 10 rad/s; the episodes reach 0.08 m, 1.05 m/s, 0.8 rad,
#: 5.8 rad/s). Measured before this test was written, over 60 episodes (6 conditions: the
#: paper's friction, none, randomize, burst, both, process noise; 10 seeds; 4 sub-envs;
#: 520 steps at frame_skip=10 through an autoreset), the worst differences were 7.6e-17 m,
#: 1.0e-15 m/s, 7.2e-16 rad and 5.4e-15 rad/s — at most 1.0e-15 of the scale — so this
#: allows about ten times the worst seen, and nothing near a modelling difference (a
#: friction force frozen across RK4 stages is off by 1e-4, test_pendulum_slider.py).
STATE_TOL = 1e-14 * np.array([0.1, 1.0, 1.0, 10.0])

SPREADS = {"mu": 0.2, "M0": 0.2, "force_max": 0.2}
BURST = ((100, 149, 0.3), (300, 320, -0.5))
CONDITIONS = {
    "nominal": {},
    "randomize": {"randomize": SPREADS},
    "burst": {"burst": BURST},
    "randomize+burst": {"randomize": SPREADS, "burst": BURST},
    "no friction": {"friction": "none"},
    "process noise": {"Q": 1e-8 * np.eye(4)},
}
#: starting states: the first leaves the rail within a step (a termination, then an
#: autoreset to a drawn state), the others run the whole episode (a truncation)
STARTS = np.array([[0.025 + 0.29, 1.5, 0.2, 0.0],
                   [0.0108, 0.0, 0.5, 0.0],
                   [0.03, -0.2, -0.4, 1.0]])


def vector_env(num_envs: int, **kwargs):
    return gym.make_vec(ENV_ID, num_envs, vectorization_mode="vector_entry_point",
                        generators="per_env", frame_skip=FRAME_SKIP,
                        max_episode_steps=EPISODE, **kwargs)


def assert_within(actual: np.ndarray, expected: np.ndarray, tol: np.ndarray) -> None:
    """Componentwise ``|actual − expected| <= tol``."""
    gap = np.abs(actual - expected)
    assert np.all(gap <= tol), f"|difference| {gap} beyond {tol}"


def reward_tolerance(plant: PendulumSliderEnv, x: np.ndarray, reward: float) -> float:
    """How far the reward can move when the state moves by :data:`STATE_TOL`: the bracketed
    cost ``θ² + 0.1 θ̇² + 100 (x − x_rest)²`` (the action's term is the same) changes by at
    most ``Σ |∂c/∂x_j| tol_j + c(tol)``, times the reward's scale; plus rounding."""
    tx, _, tth, tw = STATE_TOL
    e, th, w = abs(x[0] - plant.x_rest), abs(x[2]), abs(x[3])
    change = 200 * e * tx + 2 * th * tth + 0.2 * w * tw + 100 * tx**2 + tth**2 + 0.1 * tw**2
    return plant._reward_scale * change + 8 * np.spacing(abs(reward))


def play_against_single_envs(seed: int, steps: int, starts: np.ndarray | None,
                             **kwargs) -> dict[str, int]:
    """Step the vector env and its single-env oracles with the same random actions; assert
    every step's agreement; return how many terminations, truncations and resets were seen."""
    n = 3
    venv = vector_env(n, **kwargs)
    singles = [PendulumSliderEnv(frame_skip=FRAME_SKIP, max_episode_steps=EPISODE, **kwargs)
               for _ in range(n)]
    obs, info = venv.reset(seed=seed, options=None if starts is None else {"state": starts})
    for i, env in enumerate(singles):
        o, single_info = env.reset(seed=seed + i,
                                   options=None if starts is None else {"state": starts[i]})
        assert_within(info["state"][i], single_info["state"], STATE_TOL)
        assert_within(obs[i], o, STATE_TOL + np.spacing(abs(o)))
        for name, value in single_info.get("true_params", {}).items():
            assert info["true_params"][name][i] == value
    rng = np.random.default_rng(seed)
    seen = {"terminated": 0, "truncated": 0, "resets": 0}
    done = [False] * n
    for _ in range(steps):
        actions = rng.uniform(-1.3, 1.3, (n, 1))                 # some are clipped
        obs, reward, terminated, truncated, info = venv.step(actions)
        for i, env in enumerate(singles):
            if done[i]:                   # next-step autoreset: a reset, its action ignored
                o, single_info = env.reset()
                r, term, trunc = 0.0, False, False
                seen["resets"] += 1
            else:
                o, r, term, _, single_info = env.step(actions[i])
                trunc = env.time_step >= EPISODE
                seen["terminated"] += term
                seen["truncated"] += trunc
                assert info["force"][i] == single_info["force"]
                assert info["action"][i] == single_info["action"]
            done[i] = term or trunc
            assert (terminated[i], truncated[i]) == (term, trunc)
            x = single_info["state"]
            assert_within(info["state"][i], x, STATE_TOL)
            # the same noise draw is added to both: the state's difference and the sum's rounding
            assert_within(obs[i], o, STATE_TOL + np.spacing(abs(o)))
            assert abs(reward[i] - r) <= reward_tolerance(env, x, r)
            for name, value in single_info.get("true_params", {}).items():
                assert info["true_params"][name][i] == value
            if "burst" in single_info:
                assert info["burst"][i] == single_info["burst"]
            assert "simulation_failure" not in single_info and "simulation_failure" not in info
    return seen


@pytest.mark.parametrize("condition", sorted(CONDITIONS))
def test_vector_env_equals_single_mujoco_envs_over_a_whole_episode(condition):
    """Sub-env i of the vector env seeded s is a single env seeded s + i: observations,
    rewards, terminations, truncations, states, true parameters and bursts, over a full
    500-step episode at frame_skip=10, with random actions, through a termination's and a
    truncation's autoreset."""
    seen = play_against_single_envs(7, EPISODE + 10, STARTS, **CONDITIONS[condition])
    # sub-env 0 leaves the rail at step 1 and restarts at step 2, so its second episode is
    # truncated at step 501, the others' first at step 500: four autoresets in all
    assert seen == {"terminated": 1, "truncated": 3, "resets": 4}


@pytest.mark.parametrize("condition", ["nominal", "randomize+burst"])
def test_vector_env_equals_single_envs_from_drawn_starting_states(condition):
    seen = play_against_single_envs(21, EPISODE + 3, None, **CONDITIONS[condition])
    assert seen == {"terminated": 0, "truncated": 3, "resets": 3}


def test_true_params_are_the_single_envs_draws_episode_after_episode():
    """Short episodes (3 steps): every episode's draw, reported in info["true_params"], is
    the one a single env seeded s + i draws for its own episode of that number."""
    n, seed = 4, 3
    venv = gym.make_vec(ENV_ID, n, vectorization_mode="vector_entry_point",
                        generators="per_env", randomize=SPREADS, max_episode_steps=3)
    singles = [PendulumSliderEnv(randomize=SPREADS, max_episode_steps=3) for _ in range(n)]
    _, info = venv.reset(seed=seed)
    draws = [[single.reset(seed=seed + i)[1]["true_params"]] for i, single in
             enumerate(singles)]
    for single, episodes in zip(singles, draws, strict=True):
        episodes += [single.reset()[1]["true_params"] for _ in range(3)]
    reported = [{name: values.copy() for name, values in info["true_params"].items()}]
    for step in range(1, 4 * 4):
        _, _, _, _, info = venv.step(np.zeros((n, 1)))
        if step % 4 == 0:                         # the autoreset step: a new episode's draw
            reported.append({name: values.copy() for name, values in
                             info["true_params"].items()})
    for episode, drawn in enumerate(reported):
        for i in range(n):
            assert {name: float(values[i]) for name, values in drawn.items()} == \
                draws[i][episode]
    nominal = singles[0].nominal_params
    assert all(reported[0][name][0] != nominal[name] for name in SPREADS)


def test_a_randomized_episode_is_the_plant_built_with_the_drawn_parameters():
    """The single env's MuJoCo simulation follows the draw: its states are, bit for bit, those
    of a plant constructed with the drawn μ, M0 and force_max as its parameters."""
    x0 = [0.02, 0.1, 0.4, -0.5]
    drawn = PendulumSliderEnv(randomize=SPREADS, frame_skip=5)
    _, info = drawn.reset(seed=11, options={"state": x0})
    built = PendulumSliderEnv(frame_skip=5, **info["true_params"])
    plain = PendulumSliderEnv(frame_skip=5)                       # the nominal parameters
    for env in (built, plain):
        env.reset(seed=11, options={"state": x0})
    rng = np.random.default_rng(0)
    for _ in range(300):
        a = rng.uniform(-1, 1, 1)
        x = drawn.step(a)[4]["state"]
        np.testing.assert_array_equal(x, built.step(a)[4]["state"])
        nominal = plain.step(a)[4]["state"]
    assert np.max(np.abs(x - nominal)) > 1e-3                     # the draw matters


def test_the_burst_stretches_the_increment_and_the_next_step_starts_from_it():
    """A single env with a burst: x[k+1] = x[k] + (1 + δ)(f(x[k]) − x[k]) inside the window,
    f(x[k]) outside, with f one step of a plain env put at x[k] — so each step starts from
    the stretched state, which the burst put back into MuJoCo."""
    delta, first, last = 0.4, 3, 6
    env = PendulumSliderEnv(frame_skip=10, burst=((first, last, delta),))
    plain = PendulumSliderEnv(frame_skip=10)
    _, info = env.reset(seed=0)
    x = info["state"]
    for k in range(10):
        a = np.array([0.5 * np.sin(k)])
        plain.reset(seed=0, options={"state": x})
        f = plain.step(a)[4]["state"]
        _, _, _, _, info = env.step(a)
        inside = first <= k <= last
        np.testing.assert_array_equal(info["state"], x + (1 + delta) * (f - x) if inside else f)
        assert info["burst"] == (delta if inside else 0.0)
        np.testing.assert_array_equal(env._read_state(), info["state"])   # MuJoCo holds it
        x = info["state"]


@pytest.mark.parametrize("dynamics", ["printed-eq15", "printed-eq5"])
def test_printed_equations_batch_through_their_own_propagate(dynamics):
    """The printed equations run the same numpy RK4 in a single env and in the vector env,
    elementwise: sub-env i equals the single env seeded s + i bit for bit."""
    n, seed = 3, 5
    kwargs = {"dynamics": dynamics, "randomize": SPREADS, "burst": ((4, 9, 0.2),)}
    venv = vector_env(n, **kwargs)
    singles = [PendulumSliderEnv(frame_skip=FRAME_SKIP, max_episode_steps=EPISODE, **kwargs)
               for _ in range(n)]
    venv.reset(seed=seed)
    for i, env in enumerate(singles):
        env.reset(seed=seed + i)
    rng = np.random.default_rng(1)
    for _ in range(60):
        actions = rng.uniform(-1, 1, (n, 1))
        obs, reward, *_ = venv.step(actions)
        for i, env in enumerate(singles):
            o, r, *_ = env.step(actions[i])
            np.testing.assert_array_equal(obs[i], o)
            assert reward[i] == r


class _Replay:
    """Hands the noise out as a single env draws it: ``standard_normal(4)`` per system."""

    def __init__(self, draws: np.ndarray) -> None:
        self.draws = list(draws)

    def standard_normal(self, size):
        return self.draws.pop(0) if size == 4 or size == (4,) else np.stack(
            [self.draws.pop(0) for _ in range(size[0])])


def test_batched_process_noise_is_each_single_envs_term_bit_for_bit():
    """The batch draws (B, 4) first and adds its rows' ``S n``; each equals, bit for bit,
    what the single env's ``x + S @ n`` gives on the same noise-free step and draw."""
    # a full square root, and noise as large as the state so that a last-bit difference in
    # the noise term survives the addition (n @ S.T, a matrix-matrix product, rounds
    # differently from S @ n in most rows with OpenBLAS)
    Q = np.array([[4.0, 1.0, 0.5, 0.0], [1.0, 3.0, 0.2, 0.1], [0.5, 0.2, 2.0, 0.3],
                  [0.0, 0.1, 0.3, 1.0]])
    n = 64
    plant = vector_env(n, Q=Q).unwrapped.plant
    rng = np.random.default_rng(2)
    X = np.column_stack([rng.uniform(0.0, 0.03, n), rng.uniform(-0.5, 0.5, n),
                         rng.uniform(-1, 1, n), rng.uniform(-2, 2, n)])
    A = rng.uniform(-1, 1, (n, 1))
    noise = rng.standard_normal((n, 4))
    batch, _ = plant._transition(X, A, np.zeros(n, int), _Replay(noise))
    free, _ = plant._transition(X, A, np.zeros(n, int), _Replay(np.zeros((n, 4))))
    S = plant._process_sqrt
    for i in range(n):
        assert np.array_equal(batch[i], free[i] + S @ noise[i])


@pytest.mark.parametrize("condition", ["randomize", "burst", "randomize+burst"])
def test_check_env_with_each_condition(condition):
    env = PendulumSliderEnv(**CONDITIONS[condition])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # the ±inf observation bounds (documented)
        check_env(env, skip_render_check=True)


def test_copies_of_the_vector_env_mid_run_continue_as_the_original():
    """deepcopy and pickle mid-episode (draws, a burst, process noise, per-env generators):
    the copy's future is the original's bit for bit, and the original is left untouched."""
    kwargs = {"randomize": SPREADS, "burst": ((5, 12, 0.3),), "Q": 1e-8 * np.eye(4)}
    actions = np.random.default_rng(4).uniform(-1, 1, (20, 3, 1))

    def run(venv, steps):
        return [venv.step(a) for a in steps]

    reference, venv = vector_env(3, **kwargs), vector_env(3, **kwargs)
    reference.reset(seed=1)
    venv.reset(seed=1)
    run(reference, actions[:7])
    run(venv, actions[:7])
    twins = [copy.deepcopy(venv), pickle.loads(pickle.dumps(venv))]
    expected = run(reference, actions[7:])
    for out in [run(twin, actions[7:]) for twin in twins] + [run(venv, actions[7:])]:
        for (o, r, te, tr, info), (o_, r_, te_, tr_, info_) in zip(out, expected, strict=True):
            np.testing.assert_array_equal(o, o_)
            np.testing.assert_array_equal(r, r_)
            np.testing.assert_array_equal(te | tr, te_ | tr_)
            np.testing.assert_array_equal(info["state"], info_["state"])
            for name in SPREADS:
                np.testing.assert_array_equal(info["true_params"][name],
                                              info_["true_params"][name])


def test_coulomb_friction_is_refused_with_one_line_naming_it():
    """MuJoCo's rail contact is not an ODE the analytic equations can reproduce."""
    with pytest.raises(ValueError, match="friction='coulomb'") as refused:
        gym.make_vec(ENV_ID, 2, vectorization_mode="vector_entry_point", friction="coulomb")
    assert "\n" not in str(refused.value)
    venv = PlantVectorEnv(PendulumSliderEnv, 2, friction="coulomb")   # built past the id
    with pytest.raises(ValueError, match="friction='coulomb'"):
        venv.reset(seed=0)
    with pytest.raises(ValueError, match="friction='coulomb'"):
        venv.step(np.zeros((2, 1)))
    gym.make(ENV_ID, friction="coulomb").reset(seed=0)            # a single env simulates it


def test_vector_render_draws_each_sub_envs_state():
    """Each frame is what a single env put at that sub-env's state draws from its own
    simulation (the vector env's states are written into MuJoCo before drawing)."""
    venv = vector_env(3, render_mode="rgb_array")
    venv.reset(seed=0, options={"state": STARTS})
    for _ in range(3):
        venv.step(np.full((3, 1), 0.4))
    frames = venv.render()
    states, steps = venv.unwrapped.states, venv.unwrapped.steps
    single = PendulumSliderEnv(frame_skip=FRAME_SKIP, render_mode="rgb_array")
    for i, frame in enumerate(frames):
        single.reset(seed=0, options={"state": states[i]})
        single.time_step = int(steps[i])
        assert np.array_equal(frame, single.render())
        assert venv.unwrapped.frame_views[i] == single.frame_view
    assert not np.array_equal(frames[1], frames[2])               # two different states
