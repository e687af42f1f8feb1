"""The plant conditions: per-episode parameter draws (randomize) and bursts, on every plant,
single and vectorised (docs/robustness.md#plant-conditions)."""

from __future__ import annotations

import copy
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import fir_gym
from fir_gym.envs._conditions import CONDITION_STREAM


def make(env_id, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make(env_id, **kwargs)


def randomizable(env_id):
    return tuple(make(env_id).unwrapped.randomizable)


PLANTS = [e for e in fir_gym.ENV_IDS if randomizable(e)]


def test_every_plant_can_randomize_something():
    assert PLANTS == list(fir_gym.ENV_IDS)


def _expected_draw(seed, nominal, spreads):
    """The documented draw, derived independently of the plant's code: PCG64 on the seed
    sequence [seed, CONDITION_STREAM], one uniform(-1, 1) per parameter in sorted order."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed,
                                                                     CONDITION_STREAM])))
    return {name: nominal[name] * (1.0 + spreads[name] * rng.uniform(-1.0, 1.0))
            for name in sorted(spreads)}


@pytest.mark.parametrize("env_id", PLANTS)
def test_randomize_draws_the_documented_values_and_reports_them(env_id):
    names = randomizable(env_id)
    spreads = {name: 0.05 * (i + 1) for i, name in enumerate(names)}
    env = make(env_id, randomize=spreads)
    plant = env.unwrapped
    for seed in (0, 7):
        _, info = env.reset(seed=seed)
        expected = _expected_draw(seed, plant.nominal_params, spreads)
        assert info["true_params"] == pytest.approx(expected, rel=0, abs=0)
        for name, value in expected.items():
            nominal = plant.nominal_params[name]
            assert abs(value - nominal) <= spreads[name] * abs(nominal)
            assert plant.true_params[name] == value
        _, _, _, _, step_info = env.step(env.action_space.sample() * 0)
        assert step_info["true_params"] == info["true_params"]


@pytest.mark.parametrize("env_id", PLANTS)
def test_randomize_leaves_the_noise_and_the_model_alone(env_id):
    """The same seed gives the same reset measurement with and without the draws (their
    generator is separate), and the filter's model keeps the nominal parameters."""
    names = randomizable(env_id)
    plain, drawn = make(env_id), make(env_id, randomize={n: 0.2 for n in names})
    y0, i0 = plain.reset(seed=3)
    y1, i1 = drawn.reset(seed=3)
    np.testing.assert_array_equal(y0, y1)
    np.testing.assert_array_equal(i0["state"], i1["state"])
    x = np.asarray(i0["state"])
    u = np.zeros(plain.action_space.shape)
    np.testing.assert_array_equal(plain.unwrapped.model.f(x, u), drawn.unwrapped.model.f(x, u))


def test_randomized_truth_follows_the_drawn_parameters():
    """Orbit (no process noise): every transition is the model built from the drawn
    parameters (the plant's own model class, fed the draw)."""
    env = make("fir_gym/Orbit-v0", randomize={"mu": 0.1, "thrust_max": 0.2})
    _, info = env.reset(seed=5)
    truth = env.unwrapped.make_model(**info["true_params"])
    x = info["state"]
    for a in (0.3, -0.2, 0.9):
        _, _, _, _, info = env.step(np.array([a], dtype=np.float32))
        np.testing.assert_allclose(info["state"], truth.f(x, info["action"]), rtol=1e-15)
        x = info["state"]


@pytest.mark.parametrize("bad", [{"mu": 1.0}, {"mu": -0.1}, {"mu": float("nan")},
                                 {"mu": True}, {"r_ref": 0.1}, ["mu"]])
def test_bad_randomize_is_refused_naming_it(bad):
    with pytest.raises((ValueError, TypeError), match="randomize"):
        make("fir_gym/Orbit-v0", randomize=bad)


@pytest.mark.parametrize("bad", [((5, 2, 0.1),), ((-1, 3, 0.1),), ((1, 3, -1.0),),
                                 ((1, 3, float("inf")),), ((1.5, 3, 0.1),), "x"])
def test_bad_burst_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match="burst"):
        make("fir_gym/Orbit-v0", burst=bad)


def test_burst_stretches_the_increment_inside_its_window_only():
    """Orbit without process noise: x[k+1] = x[k] + (1 + δ)(f(x[k], u) − x[k]) for k in the
    window, f(x[k], u) outside, with f the plant's own model at the true parameters."""
    delta, first, last = 0.3, 4, 7
    env = make("fir_gym/Orbit-v0", burst=((first, last, delta),))
    _, info = env.reset(seed=1)
    f = env.unwrapped.make_model(**env.unwrapped.params).f
    x = info["state"]
    for k in range(12):
        _, _, _, _, info = env.step(np.array([0.2], dtype=np.float32))
        plain = f(x, info["action"])
        inside = first <= k <= last
        expected = x + (1 + delta) * (plain - x) if inside else plain
        np.testing.assert_allclose(info["state"], expected, rtol=1e-14)
        assert info["burst"] == (delta if inside else 0.0)
        x = info["state"]


def test_van_der_pol_burst_stretches_the_interval_average_with_the_path():
    """Without noise the burst's path is x(0) + (1 + δ)(x(t) − x(0)): its end and its
    interval average of x1 (the measurement's mean) are stretched alike."""
    delta = 0.5
    env = make("fir_gym/VanDerPol-v0", Q=0.0, burst=((0, 0, delta),))
    _, info = env.reset(seed=2)
    x0 = info["state"]
    dyn = env.unwrapped.dynamics
    _, _, _, _, info = env.step(np.array([0.1], dtype=np.float32))
    end, average, _ = dyn.integrate(x0, info["action"])
    np.testing.assert_allclose(info["state"], x0 + (1 + delta) * (end - x0), rtol=1e-13)
    np.testing.assert_allclose(info["x1_average"], x0[0] + (1 + delta) * (average - x0[0]),
                               rtol=1e-13)


def test_oscillator_burst_acts_through_its_own_delta():
    """UncertainOscillator-v0 adds the burst to its δ schedule: the transition is eq (29) in
    the plant's reading with δ = the burst's, and info says both."""
    env = make("fir_gym/UncertainOscillator-v0", Q=0.0, delta_schedule=(),
               uncertainty="rate", burst=((0, 2, 0.15),))
    _, info = env.reset(seed=0)
    dyn = env.unwrapped._dynamics
    x = info["state"]
    for _ in range(3):
        _, _, _, _, info = env.step(np.array([0.1], dtype=np.float32))
        np.testing.assert_allclose(info["state"], dyn.step(x, info["action"], 0.15),
                                   rtol=1e-15)
        assert info["burst"] == 0.15 and info["delta"] == 0.15
        x = info["state"]


VECTOR = [e for e in fir_gym.VECTOR_ENV_IDS if e in PLANTS]


@pytest.mark.parametrize("env_id", VECTOR)
def test_vector_env_draws_per_sub_env_as_single_envs_do(env_id):
    """generators='per_env': sub-env i reset with seed s plays the episode a single env reset
    with seed s + i plays — draws, burst and autoreset included (episodes of 12 steps)."""
    names = randomizable(env_id)
    kwargs = {"randomize": {n: 0.2 for n in names}, "burst": ((3, 6, 0.2),),
              "max_episode_steps": 12}
    if env_id == "fir_gym/PendulumSlider-v0":
        kwargs["frame_skip"] = 10
    n, steps, seed = 3, 30, 40
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (steps, n, 1)).astype(np.float32)
    venv = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point",
                        generators="per_env", **kwargs)
    obs, info = venv.reset(seed=seed)
    vec_obs, vec_params = [obs], [info["true_params"]]
    for t in range(steps):
        obs, _, _, _, info = venv.step(actions[t])
        vec_obs.append(obs)
        vec_params.append(info["true_params"])
    # Orbit, the oscillator and Van der Pol compute elementwise: bit for bit. CarrierMotion's
    # matrix products of a batch and of one system may round differently (BLAS kernels):
    # a few ulps. PendulumSlider's vector env integrates the analytic equations where the
    # single env runs MuJoCo (docs/envs/pendulum-slider.md: ~2e-15 over an episode).
    tolerance = {"fir_gym/CarrierMotion-v0": 1e-14,
                 "fir_gym/PendulumSlider-v0": 1e-12}.get(env_id, 0.0)
    for i in range(n):
        env = make(env_id, **kwargs)
        obs, info = env.reset(seed=seed + i)
        single_obs, single_params = [obs], [info["true_params"]]
        done = False
        for t in range(steps):
            if done:           # next-step autoreset: this step resets, its action ignored
                obs, info = env.reset()
                done = False
            else:
                obs, _, term, trunc, info = env.step(actions[t, i])
                done = term or trunc
            single_obs.append(obs)
            single_params.append(info["true_params"])
        np.testing.assert_allclose(np.array(vec_obs)[:, i], np.array(single_obs), rtol=0,
                                   atol=tolerance)
        for v, s in zip(vec_params, single_params, strict=True):
            assert {k: float(a[i]) for k, a in v.items()} == s


@pytest.mark.parametrize("env_id", PLANTS)
@pytest.mark.parametrize("condition", ["randomize", "burst"])
def test_every_plant_condition_passes_check_env(env_id, condition):
    kwargs = ({"randomize": {n: 0.1 for n in randomizable(env_id)}} if condition == "randomize"
              else {"burst": ((0, 20, 0.1),)})
    env = make(env_id, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(env.unwrapped, skip_render_check=True)


@pytest.mark.parametrize("env_id", PLANTS)
def test_conditions_survive_copies_mid_episode(env_id):
    kwargs = {"randomize": {n: 0.1 for n in randomizable(env_id)}, "burst": ((2, 5, 0.2),)}
    env = make(env_id, **kwargs)
    env.reset(seed=9)
    for _ in range(3):
        env.step(np.full(env.action_space.shape, 0.1, dtype=np.float32))
    for twin in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        a = [env.step(np.full(env.action_space.shape, 0.2, dtype=np.float32))
             for _ in range(4)]
        b = [twin.step(np.full(env.action_space.shape, 0.2, dtype=np.float32))
             for _ in range(4)]
        for (oa, ra, *_), (ob, rb, *_) in zip(a, b, strict=True):
            np.testing.assert_array_equal(oa, ob)
            assert ra == rb
        env.reset(seed=9)
        for _ in range(3):
            env.step(np.full(env.action_space.shape, 0.1, dtype=np.float32))
