"""fir_gym.jax.randomized: the ``mismatch`` condition's per-episode draws in JAX.

Oracles: the numpy plants' own draw (``info["true_params"]`` of a numpy env built with
``randomize=``, replayed from its condition generator), the params builders (host-side,
numpy and scipy) given the drawn values as the truth and the nominal values as the model,
and the plain JAX plant run by hand on the wrapper's draws — which, with the per-plant
parity tests (a JAX plant on given params equals the numpy plant on them), ties the wrapped
env to the numpy plant with ``randomize``.
"""

from __future__ import annotations

import copy
import pickle
import warnings
from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import fir_gym.jax as fj  # noqa: E402
from fir_gym.envs._conditions import condition_generator  # noqa: E402
from fir_gym.jax.randomized import Randomized  # noqa: E402
from fir_gym.jax.registry import PLANTS  # noqa: E402

ENV_IDS = list(PLANTS)
SPREAD = 0.2


def numpy_plant(env_id: str, **kwargs: Any) -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make(env_id, **kwargs).unwrapped


def spreads(env_id: str, s: float = SPREAD) -> dict[str, float]:
    return {name: s for name in PLANTS[env_id].env_class.randomizable}


def test_every_plant_randomizes_what_its_numpy_plant_does() -> None:
    for env_id, plant in PLANTS.items():
        assert plant.env_class.randomizable == type(numpy_plant(env_id)).randomizable


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_draw_law_is_the_numpy_plants(env_id: str) -> None:
    """Given the numpy plant's own ``ξ`` (its condition generator, one ``uniform`` per name in
    sorted order), :meth:`Randomized.values_of` gives the numpy plant's drawn values to the
    last bit (the same float64 operations)."""
    plant = numpy_plant(env_id, randomize=spreads(env_id))
    env, params = fj.make(env_id, randomize=spreads(env_id))
    for seed in (0, 1, 7):
        _, info = plant.reset(seed=seed)
        rng = condition_generator(seed)
        xi = np.array([rng.uniform(-1.0, 1.0) for _ in sorted(env.spreads)])
        got = env.values_of(jnp.asarray(xi), params)
        assert sorted(got) == sorted(info["true_params"])
        for name, value in info["true_params"].items():
            assert float(got[name]) == value, (name, float(got[name]), value)


#: fields the numpy plant fixes at construction and a draw does not rebuild (its
#: ``_apply_params`` samples ``A_d`` and ``Q_d`` only): CarrierMotion-v0's reward normaliser and
#: stationary start belong to the constructed sea, not to the episode's draw; PendulumSlider-v0's
#: rest position (the reward's ``x_rest``) and start stay the constructor's ("the task does not
#: move with the draw", its docstring)
KEPT = {"fir_gym/CarrierMotion-v0": (".sigma1", ".initial_state_cov", ".initial_sqrt"),
        "fir_gym/PendulumSlider-v0": (".x_rest", ".initial_state")}


def _nominal_of(env_id: str, name: str) -> Any:
    return numpy_plant(env_id).nominal_params[name]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_with_true_values_is_the_builder_given_those_values(env_id: str) -> None:
    """The plant's ``with_true_values`` (traced) equals its params builder (host-side) called
    with the drawn values as the truth and the old values as the model's: every field, to
    round-off where the truth is derived (CarrierMotion-v0 samples ``A_d`` and ``Q_d`` again:
    compared as ``A_d`` and ``S Sᵀ``, a square root's columns' signs being free) — but the
    fields of :data:`KEPT`, which stay the constructed plant's, as in numpy."""
    env, base = fj.make(env_id)
    centres = env.draw_centres(base)
    values = {name: float(centres[name]) * (1.0 + 0.15 * (-1) ** i)
              for i, name in enumerate(sorted(centres))}
    nominal = {name: _nominal_of(env_id, name) for name in values}
    want = PLANTS[env_id].params(**values, nominal=nominal)
    got = jax.jit(env.with_true_values)(base, {k: jnp.asarray(v) for k, v in values.items()})
    leaves_w, tree_w = jax.tree_util.tree_flatten_with_path(want)
    leaves_g, tree_g = jax.tree_util.tree_flatten_with_path(got)
    assert tree_w == tree_g
    leaves_b = jax.tree_util.tree_leaves(base)
    for (path, w), (_, g), b in zip(leaves_w, leaves_g, leaves_b, strict=True):
        name = jax.tree_util.keystr(path)
        if name in KEPT.get(env_id, ()):
            w = b
        w_, g_ = np.asarray(w, dtype=np.float64), np.asarray(g, dtype=np.float64)
        if name == ".process_sqrt":
            w_, g_ = w_ @ w_.T, g_ @ g_.T
        scale = max(1.0, float(np.max(np.abs(w_), initial=0.0)))
        tol = 0.0 if name not in (".A_d", ".process_sqrt") else 8 * np.finfo(float).eps * scale
        assert np.max(np.abs(g_ - w_), initial=0.0) <= tol, name


def _reference_rollout(env: Randomized, params: Any, key: Any, actions: np.ndarray) -> Any:
    """The wrapper's episodes run by hand on the plain plant: draw at every reset from the
    reset's key, step with the drawn truth, auto-reset as gymnax's ``step`` does."""
    plain = env.env
    reset, step = jax.jit(plain.reset_env), jax.jit(plain.step_env)
    draw, rebuild = jax.jit(env.draw), jax.jit(plain.with_true_values)
    values = draw(key, params)
    obs, state = reset(key, rebuild(params, values))
    out = []
    for t, a in enumerate(actions):
        k_step, k_reset = jax.random.split(jax.random.fold_in(key, t))
        obs_st, st, reward, terminated, _ = step(k_step, state, jnp.asarray(a),
                                                 rebuild(params, values))
        if bool(terminated) or int(st.time) >= params.max_steps_in_episode:
            values = draw(k_reset, params)
            obs, state = reset(k_reset, rebuild(params, values))
        else:
            obs, state = obs_st, st
        out.append((np.asarray(obs), float(reward), {k: float(v) for k, v in values.items()}))
    return out


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_wrapper_plays_each_episode_on_its_draw(env_id: str) -> None:
    """Two and a half short episodes through gymnax's ``step`` (auto-reset included) equal
    the plain plant run by hand on the wrapper's draws: observations, rewards and the
    reported ``true_params``; each episode draws anew."""
    env, params = fj.make(env_id, randomize=spreads(env_id), max_episode_steps=6)
    key = jax.random.key(3)
    actions = np.linspace(-0.8, 0.8, 15)[:, None]
    want = _reference_rollout(env, params, key, actions)
    step = jax.jit(env.step)
    _, state = jax.jit(env.reset)(key, params)
    drawn = []
    for t, a in enumerate(actions):
        obs, state, reward, _, _, info = step(jax.random.fold_in(key, t), state,
                                              jnp.asarray(a), params)
        w_obs, w_reward, w_values = want[t]
        np.testing.assert_allclose(np.asarray(obs), w_obs, rtol=1e-13, atol=1e-300)
        assert float(reward) == pytest.approx(w_reward, rel=1e-13, abs=1e-300)
        assert {k: float(v) for k, v in state.true_params.items()} == w_values
        drawn.append(tuple(w_values.values()))
        # info reports the truth the step ran on (the episode's, before an auto-reset)
        assert set(info["true_params"]) == set(env.spreads)
    assert len(set(drawn)) == 3                           # three episodes, three draws


def test_no_spread_is_the_plain_plant_on_the_same_noise() -> None:
    """The draws come from the key's condition stream: with every spread 0 the wrapped env
    is the plain env whose truth is the model's (the draws' centre: ``mu`` 19.91 on
    Orbit-v0) on the same keys, bit for bit — the plant's noise untouched, so an episode
    under mismatch and the nominal one on one key are a pair."""
    env_id = "fir_gym/Orbit-v0"
    wrapped, params = fj.make(env_id, "ekf", randomize=spreads(env_id, 0.0))
    plain, plain_params = fj.make(env_id, "ekf", mu=float(params.nominal_mu))
    assert isinstance(wrapped, Randomized)
    keys = jax.random.split(jax.random.key(11), 40)

    def roll(env: Any, params: Any) -> Any:
        def body(state: Any, key: Any) -> Any:
            obs, state, reward, *_ = env.step(key, state, jnp.array([0.3]), params)
            return state, (obs, reward)
        _, state = env.reset(keys[0], params)
        return jax.lax.scan(body, state, keys)[1]

    a = jax.jit(lambda: roll(wrapped, params))()
    b = jax.jit(lambda: roll(plain, plain_params))()
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_the_draws_are_uniform_around_the_centres() -> None:
    """Over 4000 resets: every value within ``θ (1 ± s)``, the ``ξ`` of each name spread over
    ``(−1, 1)`` with mean 0 and variance 1/3 (within 5 standard errors), the names
    uncorrelated."""
    env_id = "fir_gym/PendulumSlider-v0"
    env, params = fj.make(env_id, randomize={"mu": 0.3, "M0": 0.1, "force_max": 0.05})
    keys = jax.random.split(jax.random.key(5), 4000)
    values = jax.jit(jax.vmap(env.draw, in_axes=(0, None)))(keys, params)
    centres = env.draw_centres(params)
    xi = np.stack([(np.asarray(values[n]) / float(centres[n]) - 1.0) / s
                   for n, s in env.spreads.items()])
    n = xi.shape[1]
    assert np.all(np.abs(xi) <= 1.0 + 1e-12)
    assert np.all(np.abs(xi.mean(axis=1)) <= 5 * np.sqrt(1 / 3 / n))
    assert np.all(np.abs(xi.var(axis=1) - 1 / 3) <= 5 * np.sqrt(4 / 45 / n))
    corr = np.corrcoef(xi)
    assert np.all(np.abs(corr[~np.eye(3, dtype=bool)]) <= 5 / np.sqrt(n))
    assert xi.min() < -0.99 and xi.max() > 0.99


def test_bad_randomize_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match=r"randomize names \['g'\].*mu, thrust_max"):
        fj.make("fir_gym/Orbit-v0", randomize={"g": 0.1})
    with pytest.raises(ValueError, match=r"randomize\['mu'\] must be a relative spread"):
        fj.make("fir_gym/Orbit-v0", randomize={"mu": 1.0})
    with pytest.raises(TypeError, match="randomize must be a mapping"):
        fj.make("fir_gym/Orbit-v0", randomize=[("mu", 0.1)])


def test_the_wrapper_is_the_plant_to_its_users_and_survives_copies() -> None:
    """Kind, options and spaces are the plant's; ``deepcopy`` and ``pickle`` give envs that
    play the same episode."""
    env, params = fj.make("fir_gym/VanDerPol-v0", "efir", kind_kwargs={"horizon": 7},
                          randomize={"epsilon": 0.2})
    assert env.kind == "efir" and env.horizon == 7 and env.name == "fir_gym/VanDerPol-v0"
    assert env.observation_space(params).shape == (2,)
    key = jax.random.key(2)
    _, state = env.reset(key, params)
    for other in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        assert isinstance(other, Randomized) and other.spreads == env.spreads
        _, s2 = other.reset(key, params)
        for x, y in zip(jax.tree.leaves(state), jax.tree.leaves(s2), strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
