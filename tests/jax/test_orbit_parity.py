"""fir_gym.jax.orbit against the numpy Orbit-v0 it mirrors (issue 28).

The oracle is always the numpy reference: ``gym.make("fir_gym/Orbit-v0", ...)`` wrapped as
each observation kind is (``observation="true"``, the bare plant, ``estimator="ekf"``), its
generator replaced by one that serves given standard normals, so that both envs run on the
same noise: the numpy plant turns them into its increments with its own square roots
(``z @ sqrt.T``), and the JAX env is handed those increments
(:meth:`fir_gym.jax.orbit.Orbit.reset_with_noise` / ``step_with_noise``). Over whole
episodes the two agree to 1e-9 relative in float64: true states, observations, EKF mean and
covariance, rewards, terminated/truncated flags, the divergence watch.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax_parity import QueuedNormals, flat, flat_jax, relative_error  # noqa: E402

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.envs._base import psd_sqrt  # noqa: E402
from fir_gym.jax import orbit as jorbit  # noqa: E402

RTOL = 1e-9


def numpy_env(kind: str, observation: str = "estimate", **kwargs: Any) -> gym.Env:
    if kind == "ekf":
        return gym.make("fir_gym/Orbit-v0", estimator="ekf", observation=observation, **kwargs)
    if kind == "true":
        return gym.make("fir_gym/Orbit-v0", observation="true", **kwargs)
    return gym.make("fir_gym/Orbit-v0", **kwargs)


def run_numpy(kind: str, actions: np.ndarray, rng: np.random.Generator,
              observation: str = "estimate", **kwargs: Any) -> dict[str, Any]:
    """An episode of the numpy env on the normals of ``rng``: what it returned, the noise
    increments it added (for the JAX env) and, for ``"ekf"``, the filter's mean and
    covariance after each step."""
    env = numpy_env(kind, observation, **kwargs)
    plant = env.unwrapped
    normals = QueuedNormals()
    plant.np_random = normals                  # every draw of the plant comes from here
    z0, zy = rng.standard_normal(2), rng.standard_normal(1)
    normals.queue += [z0, zy]
    obs, info = env.reset()
    assert not normals.queue
    # the plant's square roots (the same function on the same matrices: the same bits)
    initial_sqrt, process_sqrt = psd_sqrt(plant.initial_state_cov), psd_sqrt(plant.params["Q"])
    meas = np.diag(psd_sqrt(plant.measurement_cov))   # 1x1: the plant's noise * diag
    noisy = bool(np.any(process_sqrt))
    out: dict[str, Any] = {
        "reset_noise": (z0 @ initial_sqrt.T, zy * meas),
        "process": [], "measurement": [], "obs": [flat(obs)],
        "state": [info["state"]], "reward": [], "terminated": [], "truncated": [],
        "P": [], "diverged": [], "nis": []}
    estimator = env.get_wrapper_attr("estimator") if kind == "ekf" else None

    def filter_record() -> None:
        if estimator is not None:
            out["P"].append(estimator.P)
            out["diverged"].append(bool(estimator.diverged))
            out["nis"].append(float(estimator.last_info["nis"]))

    filter_record()
    for a in actions:
        zw, zv = rng.standard_normal(2), rng.standard_normal(1)
        normals.queue += [zw, zv] if noisy else [zv]
        obs, reward, terminated, truncated, info = env.step(a)
        assert not normals.queue, "a failed step: the test episodes avoid them"
        out["process"].append(zw @ process_sqrt.T if noisy else np.zeros(2))
        out["measurement"].append(zv * meas)
        out["obs"].append(flat(obs))
        out["state"].append(info["state"])
        out["reward"].append(reward)
        out["terminated"].append(terminated)
        out["truncated"].append(truncated)
        filter_record()
        if terminated or truncated:
            break
    env.close()
    return {key: (value if key == "reset_noise" else np.array(value))
            for key, value in out.items()}


def run_jax(kind: str, actions: np.ndarray, ref: dict[str, Any], params: Any,
            observation: str = "estimate") -> dict[str, np.ndarray]:
    """The JAX env on the numpy episode's noise: reset, then a scan of step_with_noise."""
    env = jorbit.Orbit(kind, observation)
    n = len(ref["reward"])
    noise = jorbit.OrbitNoise(jnp.asarray(ref["process"]), jnp.asarray(ref["measurement"]))
    x0, y0 = ref["reset_noise"]

    @jax.jit
    def rollout(noise: Any, actions: Any) -> Any:
        obs0, state = env.reset_with_noise(jorbit.OrbitResetNoise(jnp.asarray(x0),
                                                                  jnp.asarray(y0)), params)

        def body(state: Any, step: Any) -> Any:
            a, w = step
            obs, state, reward, terminated, _ = env.step_with_noise(state, a, w, params)
            return state, (flat_jax(obs), state.x, reward, terminated,
                           env.is_truncated(state, params),
                           state.filter_x, state.filter_P, state.diverged, state.nis)

        _, trace = jax.lax.scan(body, state, (actions, noise))
        return (flat_jax(obs0), state), trace

    (obs0, s0), trace = rollout(noise, jnp.asarray(actions[:n]))
    obs, x, reward, terminated, truncated, fx, fP, diverged, nis = map(np.asarray, trace)
    return {"obs": np.concatenate([np.asarray(obs0)[None], obs]),
            "state": np.concatenate([np.asarray(s0.x)[None], x]), "reward": reward,
            "terminated": terminated, "truncated": truncated,
            "estimate": np.concatenate([np.asarray(s0.filter_x)[None], fx]),
            "P": np.concatenate([np.asarray(s0.filter_P)[None], fP]),
            "diverged": np.concatenate([[bool(s0.diverged)], diverged]),
            "nis": np.concatenate([[float(s0.nis)], nis])}


def hover_actions(n: int, seed: int) -> np.ndarray:
    """Float32 actions around the hover thrust (0.311), some beyond ±1 (clipped)."""
    k = np.arange(n)
    a = 0.311 + 0.8 * np.sin(0.05 * k) + 0.3 * np.random.default_rng(seed).standard_normal(n)
    return a.astype(np.float32)[:, None]


CASES = {
    # the paper's plant: no process noise, a known start, the EKF's wrong μ
    "paper": ({}, lambda n: hover_actions(n, 1)),
    # process noise, a random start and a different true μ and thrust gain
    "noisy": ({"Q": np.diag([1e-6, 4e-6]), "initial_state_cov": np.diag([1e-3, 1e-4]),
               "mu": 19.5, "thrust_max": 1.3}, lambda n: hover_actions(n, 2)),
    # a far wrong μ in the model: the EKF's NIS stays high and the watch flags it
    "diverging": ({"nominal": {"mu": 15.0}}, lambda n: hover_actions(n, 5)),
    # a coarser model (50 Euler steps of 2e-4): the plant's and the model's loops apart
    "coarse_model": ({"nominal": {"substeps": 50, "euler_dt": 2e-4}},
                     lambda n: hover_actions(n, 6)),
    # full reverse thrust: the body reaches the planet (termination, terminal penalty)
    "crash": ({}, lambda n: -np.ones((n, 1), dtype=np.float32)),
}


def jax_params(**kwargs: Any) -> Any:
    return jorbit.orbit_params(**kwargs)


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("kind", ["true", "measurement", "ekf"])
def test_an_episode_matches_the_numpy_env(kind: str, case: str) -> None:
    kwargs, actions_of = CASES[case]
    actions = actions_of(1000)
    ref = run_numpy(kind, actions, np.random.default_rng(28), **kwargs)
    got = run_jax(kind, actions, ref, jax_params(**kwargs))
    n = len(ref["reward"])
    if case == "crash":
        assert n < 1000 and ref["terminated"][-1] and got["terminated"][-1]
        assert ref["reward"][-1] < -49.01 * 100          # the terminal penalty
    else:
        assert n == 1000 and ref["truncated"][-1] and not ref["terminated"].any()
    np.testing.assert_array_equal(got["terminated"], ref["terminated"])
    np.testing.assert_array_equal(got["truncated"], ref["truncated"])
    errors = {key: relative_error(got[key], ref[key]) for key in ("state", "obs", "reward")}
    if kind == "ekf":
        errors["estimate"] = relative_error(got["estimate"], ref["obs"])
        errors["P"] = relative_error(got["P"], ref["P"])
        # the NIS e²/S of a small innovation e = y − x̂₁ (a difference of numbers near 8)
        # inherits the estimate's round-off relative to |e|: it is held to 1e-9 (1 + nis)
        nis_error = float(np.max(np.abs(got["nis"] - ref["nis"]) / (1.0 + np.abs(ref["nis"]))))
        np.testing.assert_array_equal(got["diverged"], ref["diverged"])
        assert ref["diverged"][-1] == (case == "diverging")
    print(f"{kind}/{case}: {n} steps, max relative errors "
          + ", ".join(f"{key} {value:.2e}" for key, value in errors.items())
          + (f"; nis |Δ|/(1 + nis) {nis_error:.2e}" if kind == "ekf" else ""))
    assert max(errors.values()) <= RTOL, errors
    if kind == "ekf":
        assert nis_error <= RTOL


@pytest.mark.parametrize("observation", ["estimate+covariance", "estimate+measurement"])
def test_the_ekf_kind_observes_what_estimator_observation_does(observation: str) -> None:
    """The dict observations of EstimatorObservation: estimate with the upper triangle of P,
    or with the measurement, over an episode of the paper's plant."""
    actions = hover_actions(1000, 8)
    ref = run_numpy("ekf", actions, np.random.default_rng(3), observation=observation)
    got = run_jax("ekf", actions, ref, jax_params(), observation=observation)
    assert got["obs"].shape == ref["obs"].shape == (1001, 5 if "covariance" in observation else 3)
    error = relative_error(got["obs"], ref["obs"])
    print(f"ekf/{observation}: max relative error of the observation {error:.2e}")
    assert error <= RTOL
    space = jorbit.Orbit("ekf", observation).observation_space(jax_params())
    assert sorted(space.spaces) == sorted(("estimate", observation.split("+")[1]))


def test_the_filter_sees_the_measurement_the_plant_returns() -> None:
    """The three kinds share the plant: the true states agree between kinds, and the
    measurement kind's observation is the one the EKF consumed (same noise)."""
    actions = hover_actions(50, 3)
    runs = {kind: run_jax(kind, actions, run_numpy(kind, actions, np.random.default_rng(5)),
                          jax_params()) for kind in ("true", "measurement", "ekf")}
    np.testing.assert_array_equal(runs["true"]["state"], runs["ekf"]["state"])
    np.testing.assert_array_equal(runs["true"]["obs"], runs["true"]["state"])
    np.testing.assert_array_equal(runs["measurement"]["state"], runs["ekf"]["state"])


def _batched_rollout(env: Any, params: Any, keys: Any, steps: int, params_axes: Any = None
                     ) -> Any:
    """gymnax's own reset/step (auto-reset included), vmapped over ``keys``, scanned."""
    def one(key: Any, params: Any) -> Any:
        k_reset, k_steps = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry: Any, key: Any) -> Any:
            obs, state = carry
            action = jnp.clip(0.311 - 0.5 * (obs[0] - 8.0), -1.0, 1.0)[None]
            obs, state, reward, terminated, truncated, _ = env.step(key, state, action, params)
            return (obs, state), (obs, reward, terminated, truncated, state.filter_P)

        return jax.lax.scan(body, (obs, state), jax.random.split(k_steps, steps))[1]

    return jax.jit(jax.vmap(one, in_axes=(0, params_axes)))(keys, params)


def test_jit_and_vmap_over_eight_envs() -> None:
    env = jorbit.Orbit("ekf")
    params = env.default_params
    keys = jax.random.split(jax.random.key(0), 8)
    obs, reward, terminated, truncated, P = _batched_rollout(env, params, keys, 120)
    assert obs.shape == (8, 120, 2) and obs.dtype == jnp.float64
    assert reward.shape == (8, 120) and P.shape == (8, 120, 2, 2)
    assert bool(jnp.all(jnp.isfinite(obs))) and bool(jnp.all(reward <= 0.0))
    # the feedback holds the radius: no crash, and 120 steps are short of the time limit
    assert not bool(jnp.any(terminated)) and not bool(jnp.any(truncated))
    # each row is the env run alone with its key
    one = _batched_rollout(env, params, keys[3:4], 120)
    np.testing.assert_array_equal(np.asarray(one[0][0]), np.asarray(obs[3]))
    # different keys, different noise
    assert not np.array_equal(np.asarray(obs[0]), np.asarray(obs[1]))


def test_the_same_key_gives_bit_identical_rollouts() -> None:
    env = jorbit.Orbit("ekf")
    params = env.default_params
    keys = jax.random.split(jax.random.key(123), 4)
    first = _batched_rollout(env, params, keys, 200)
    second = _batched_rollout(jorbit.Orbit("ekf"), jorbit.orbit_params(), keys, 200)
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_vmap_over_drawn_mu_matches_the_numpy_env_row_by_row() -> None:
    """A batch of true μ drawn around the nominal one, vmapped as a parameter; each row
    is the numpy env built with that μ, on the same noise."""
    mus = 19.91 * (1.0 + 0.05 * np.random.default_rng(7).uniform(-1.0, 1.0, 8))
    actions = hover_actions(150, 4)
    refs = [run_numpy("ekf", actions, np.random.default_rng(100 + i), mu=float(mu))
            for i, mu in enumerate(mus)]
    assert all(len(ref["reward"]) == 150 for ref in refs)
    params = jax_params().replace(mu=jnp.asarray(mus))
    axes = jax.tree.map(lambda _: None, jax_params()).replace(mu=0)
    env = jorbit.Orbit("ekf")

    def one(params: Any, x0: Any, y0: Any, noise: Any) -> Any:
        _, state = env.reset_with_noise(jorbit.OrbitResetNoise(x0, y0), params)

        def body(state: Any, step: Any) -> Any:
            a, w = step
            obs, state, reward, _, _ = env.step_with_noise(state, a, w, params)
            return state, (obs, state.x, reward, state.filter_P)

        return jax.lax.scan(body, state, (jnp.asarray(actions), noise))[1]

    stack = lambda key: jnp.asarray(np.stack([ref[key] for ref in refs]))  # noqa: E731
    noise = jorbit.OrbitNoise(stack("process"), stack("measurement"))
    x0 = jnp.asarray(np.stack([ref["reset_noise"][0] for ref in refs]))
    y0 = jnp.asarray(np.stack([ref["reset_noise"][1] for ref in refs]))
    obs, x, reward, P = map(np.asarray, jax.jit(jax.vmap(one, in_axes=(axes, 0, 0, 0)))(
        params, x0, y0, noise))
    for i, ref in enumerate(refs):
        assert relative_error(x[i], ref["state"][1:]) <= RTOL
        assert relative_error(obs[i], ref["obs"][1:]) <= RTOL
        assert relative_error(reward[i], ref["reward"]) <= RTOL
        assert relative_error(P[i], ref["P"][1:]) <= RTOL
    # the true μ matters: the rows' trajectories differ
    assert not np.allclose(x[0], x[1])


def test_the_drawn_noise_follows_the_documented_splits() -> None:
    params = jax_params(Q=np.diag([1e-6, 4e-6]), initial_state_cov=np.diag([1e-3, 1e-4]))
    key = jax.random.key(9)
    noise = jorbit.orbit_noise(key, params)
    z = np.asarray(jax.random.normal(key, (3,), dtype=jnp.float64))
    # the increments are S z with S the plant's square root (psd_sqrt: V Λ^½ from eigh — for
    # a diagonal matrix a signed permutation of its diagonal's roots, hence the |·|)
    for got, cov in ((noise.process, np.diag([1e-6, 4e-6])),
                     (jorbit.orbit_reset_noise(key, params).initial, np.diag([1e-3, 1e-4]))):
        np.testing.assert_allclose(np.abs(np.asarray(got)), np.abs(psd_sqrt(cov) @ z[:2]),
                                   rtol=1e-15)
    for got in (noise.measurement, jorbit.orbit_reset_noise(key, params).measurement):
        np.testing.assert_allclose(np.asarray(got), np.sqrt(1e-3) * z[2:], rtol=1e-15)
    # step_env is step_with_noise on that noise
    env = jorbit.Orbit("ekf")
    _, state = env.reset_env(jax.random.key(1), params)
    a = jnp.array([0.2])
    by_key = env.step_env(key, state, a, params)
    by_noise = env.step_with_noise(state, a, noise, params)
    for u, v in zip(jax.tree.leaves(by_key), jax.tree.leaves(by_noise), strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))


def test_float64_throughout() -> None:
    env = jorbit.Orbit("ekf")
    obs, state = env.reset(jax.random.key(0), env.default_params)
    assert obs.dtype == jnp.float64 and state.filter_P.dtype == jnp.float64
    assert env.observation_space(env.default_params).shape == (2,)
    assert jorbit.Orbit("measurement").observation_space(env.default_params).shape == (1,)
    with pytest.raises(ValueError, match="kind"):
        jorbit.Orbit("recurrent")
    with pytest.raises(ValueError, match="observation"):
        jorbit.Orbit("true", "estimate+covariance")


def test_x64_turned_off_later_is_refused() -> None:
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError, match="jax_enable_x64"):
            jorbit.Orbit("ekf")
    finally:
        jax.config.update("jax_enable_x64", True)
