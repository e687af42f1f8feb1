"""fir_gym.jax.van_der_pol against the numpy VanDerPol-v0 it mirrors (issue 28).

The oracle is always the numpy reference: ``gym.make("fir_gym/VanDerPol-v0", ...)`` wrapped
as each observation kind is (``observation="true"``, the bare plant, ``estimator="ekf"``),
its generator replaced by one that serves given standard normals, so that both envs run on
the same noise: the numpy plant turns them into its Wiener increments (``√(Q τ) z``, one per
Heun substep) and its measurement noise with its own square roots, and the JAX env is handed
those increments (:meth:`fir_gym.jax.van_der_pol.VanDerPol.reset_with_noise` /
``step_with_noise``). Over whole episodes the two agree to 1e-9 relative in float64: true
states, observations, EKF mean and covariance, rewards, terminated/truncated flags, the
divergence watch (NIS to 1e-9 (1 + nis)).

The actions come from one feedback on the true state that both envs evaluate (closed loop:
see :class:`Feedback` for why). Measured maximum relative errors over the three kinds and
five cases (300-step episodes; the domain-leaving one ends at step 4): states 2.0e-13,
observations 5.2e-12, rewards 9.4e-15, applied actions 6.4e-14, EKF mean 5.2e-12, EKF
covariance 2.1e-12, NIS |Δ|/(1 + nis) 5.8e-15; the dict observations 4.9e-13.
"""

from __future__ import annotations

from dataclasses import dataclass
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
from fir_gym.jax import van_der_pol as jvdp  # noqa: E402

RTOL = 1e-9
ENV_ID = "fir_gym/VanDerPol-v0"


def numpy_env(kind: str, observation: str = "estimate", **kwargs: Any) -> gym.Env:
    if kind == "ekf":
        return gym.make(ENV_ID, estimator="ekf", observation=observation, **kwargs)
    if kind == "true":
        return gym.make(ENV_ID, observation="true", **kwargs)
    return gym.make(ENV_ID, **kwargs)


def run_numpy(kind: str, policy: Feedback, steps: int, rng: np.random.Generator,
              observation: str = "estimate", **kwargs: Any) -> dict[str, Any]:
    """An episode of the numpy env (``steps`` long unless it terminates) on the normals of
    ``rng``, the actions chosen by ``policy`` on the true state: what it returned, the
    applied actions,
    the noise increments it added (for the JAX env) and, for ``"ekf"``, the filter's
    covariance, divergence flag and NIS after each step."""
    env = numpy_env(kind, observation, max_episode_steps=steps, **kwargs)
    plant = env.unwrapped
    plant.max_episode_steps = steps            # the terminal penalty counts to this limit
    normals = QueuedNormals()
    plant.np_random = normals                  # every draw of the plant comes from here
    z0, zy = rng.standard_normal(2), rng.standard_normal(1)
    normals.queue += [z0, zy]
    obs, info = env.reset()
    assert not normals.queue
    # the plant's square roots (the same function on the same matrices: the same bits)
    initial_sqrt = psd_sqrt(plant.initial_state_cov)
    meas = np.diag(psd_sqrt(plant.measurement_cov))   # 1x1: the plant's noise * diag
    dw_scale = np.sqrt(plant.params["Q"] * plant.dynamics.tau)
    substeps = plant.dynamics.substeps
    out: dict[str, Any] = {
        "reset_noise": (z0 @ initial_sqrt.T, zy * meas),
        "process": [], "measurement": [], "action": [], "raw_action": [], "obs": [flat(obs)],
        "state": [info["state"]], "reward": [], "terminated": [], "truncated": [],
        "P": [], "diverged": [], "nis": []}
    estimator = env.get_wrapper_attr("estimator") if kind == "ekf" else None

    def filter_record() -> None:
        if estimator is not None:
            out["P"].append(estimator.P)
            out["diverged"].append(bool(estimator.diverged))
            out["nis"].append(float(estimator.last_info["nis"]))

    filter_record()
    for k in range(steps):
        a = policy.numpy(k, info["state"])
        zw, zv = rng.standard_normal(substeps), rng.standard_normal(1)
        normals.queue += [zw, zv]
        obs, reward, terminated, truncated, info = env.step(a)
        assert not normals.queue, "a failed step: the test episodes avoid them"
        out["action"].append(info["action"])
        out["raw_action"].append(a)
        out["process"].append(dw_scale * zw)
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


def run_jax(kind: str, ref: dict[str, Any], params: Any, policy: Feedback,
            observation: str = "estimate") -> dict[str, np.ndarray]:
    """The JAX env on the numpy episode's noise, under the same feedback: reset, then a scan
    of step_with_noise."""
    env = jvdp.VanDerPol(kind, observation)
    n = len(ref["reward"])
    noise = jvdp.VanDerPolNoise(jnp.asarray(ref["process"]), jnp.asarray(ref["measurement"]))
    x0, y0 = ref["reset_noise"]

    @jax.jit
    def rollout(noise: Any, offsets: Any) -> Any:
        obs0, state = env.reset_with_noise(
            jvdp.VanDerPolResetNoise(jnp.asarray(x0), jnp.asarray(y0)), params)

        def body(state: Any, step: Any) -> Any:
            offset, w = step
            a = policy.jax(offset, state.x)
            obs, state, reward, terminated, info = env.step_with_noise(state, a, w, params)
            return state, (flat_jax(obs), state.x, reward, terminated,
                           env.is_truncated(state, params), info["action"],
                           state.filter_x, state.filter_P, state.diverged, state.nis)

        _, trace = jax.lax.scan(body, state, (offsets, noise))
        return (flat_jax(obs0), state), trace

    (obs0, s0), trace = rollout(noise, jnp.asarray(policy.offset[:n]))
    obs, x, reward, terminated, truncated, action, fx, fP, diverged, nis = map(np.asarray,
                                                                                trace)
    return {"obs": np.concatenate([np.asarray(obs0)[None], obs]),
            "state": np.concatenate([np.asarray(s0.x)[None], x]), "reward": reward,
            "terminated": terminated, "truncated": truncated, "action": action,
            "estimate": np.concatenate([np.asarray(s0.filter_x)[None], fx]),
            "P": np.concatenate([np.asarray(s0.filter_P)[None], fP]),
            "diverged": np.concatenate([[bool(s0.diverged)], diverged]),
            "nis": np.concatenate([[float(s0.nis)], nis])}


@dataclass(frozen=True)
class Feedback:
    """The test's controller, on the true state: ``a = −g₁ x1 − g₂ x2 + offset[k]`` in
    float64 (``offset``: a sinusoid and a random dither, precomputed so that both backends
    add the same numbers; some actions fall beyond ±1 and are clipped by both plants).

    Closed loop on purpose: XLA's CPU backend always contracts ``a * b + c`` into fused
    multiply-adds (there is no flag to turn it off), so the JAX env differs from the numpy
    plant by round-off from the first step; the Van der Pol origin is unstable (``ε/2`` per
    second), and actions replayed open loop would let that round-off grow like ``e^{t/2}``
    over an episode — the feedback keeps both trajectories, and their difference, bounded."""

    gains: tuple[float, float]
    offset: np.ndarray

    def numpy(self, k: int, x: np.ndarray) -> np.ndarray:
        return np.array([-self.gains[0] * x[0] - self.gains[1] * x[1] + self.offset[k]])

    def jax(self, offset: Any, x: Any) -> Any:
        return jnp.reshape(-self.gains[0] * x[0] - self.gains[1] * x[1] + offset, (1,))


def feedback(seed: int, gains: tuple[float, float] = (0.3, 0.5), n: int = 1000) -> Feedback:
    k = np.arange(n)
    return Feedback(gains, 0.5 * np.sin(0.1 * k)
                    + 0.4 * np.random.default_rng(seed).standard_normal(n))


#: full force, always: drives x1 towards 20 (out of a smaller domain)
PUSH = Feedback((0.0, 0.0), np.ones(1000))


CASES: dict[str, tuple[dict[str, Any], Feedback]] = {
    # the paper's plant (ε = 1, Q = 5, R = 5, h = 0.1, 100 Heun substeps), known start
    "paper": ({}, feedback(1)),
    # a random start with a correlated spread, other true ε, u_max, Q, R
    "random_start": ({"initial_state": (0.5, -1.0),
                      "initial_state_cov": [[0.5, 0.1], [0.1, 0.3]], "epsilon": 0.8,
                      "u_max": 15.0, "Q": 3.0, "R": 2.0}, feedback(2)),
    # the model believes another ε, u_max and Q (the model's Q_d from its own limit cycle)
    "mismatch": ({"nominal": {"epsilon": 0.6, "u_max": 18.0, "Q": 3.0}}, feedback(3)),
    # a coarser model (50 Heun steps, another R): the plant's and the model's loops apart
    "coarse_model": ({"nominal": {"substeps": 50, "R": 8.0, "epsilon": 1.2}}, feedback(4)),
    # full force in a domain of ±5: the state leaves it (termination, terminal penalty)
    "leaves": ({"state_bound": 5.0}, PUSH),
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("kind", ["true", "measurement", "ekf"])
def test_an_episode_matches_the_numpy_env(kind: str, case: str) -> None:
    kwargs, policy = CASES[case]
    steps = 300
    ref = run_numpy(kind, policy, steps, np.random.default_rng(28), **kwargs)
    got = run_jax(kind, ref, jvdp.van_der_pol_params(max_episode_steps=steps, **kwargs),
                  policy)
    n = len(ref["reward"])
    if case == "leaves":
        assert n < steps and ref["terminated"][-1] and got["terminated"][-1]
        cost_cap = 5.0 ** 2 / 2 + 0.01
        assert ref["reward"][-1] == pytest.approx(-cost_cap * (1 + steps - n), rel=1e-15)
        assert np.max(np.abs(ref["state"][-1])) > 5.0 >= np.max(np.abs(ref["state"][-2]))
    else:
        assert n == steps and ref["truncated"][-1] and not ref["terminated"].any()
    assert np.any(np.abs(ref["raw_action"]) > 1.0) or case == "leaves"   # clipping exercised
    np.testing.assert_array_equal(got["terminated"], ref["terminated"])
    np.testing.assert_array_equal(got["truncated"], ref["truncated"])
    errors = {key: relative_error(got[key], ref[key])
              for key in ("state", "obs", "reward", "action")}
    nis_error = 0.0
    if kind == "ekf":
        errors["estimate"] = relative_error(got["estimate"], ref["obs"])
        errors["P"] = relative_error(got["P"], ref["P"])
        nis_error = float(np.max(np.abs(got["nis"] - ref["nis"]) / (1.0 + np.abs(ref["nis"]))))
        np.testing.assert_array_equal(got["diverged"], ref["diverged"])
    print(f"{kind}/{case}: {n} steps, max relative errors "
          + ", ".join(f"{key} {value:.2e}" for key, value in errors.items())
          + (f"; nis |Δ|/(1 + nis) {nis_error:.2e}" if kind == "ekf" else ""))
    assert max(errors.values()) <= RTOL, errors
    assert nis_error <= RTOL


@pytest.mark.parametrize("observation", ["estimate+covariance", "estimate+measurement"])
def test_the_ekf_kind_observes_what_estimator_observation_does(observation: str) -> None:
    """The dict observations of EstimatorObservation: estimate with the upper triangle of P,
    or with the measurement, over an episode of the paper's plant."""
    policy = feedback(8)
    ref = run_numpy("ekf", policy, 200, np.random.default_rng(3), observation=observation)
    got = run_jax("ekf", ref, jvdp.van_der_pol_params(max_episode_steps=200), policy,
                  observation=observation)
    assert got["obs"].shape == ref["obs"].shape == (201, 5 if "covariance" in observation else 3)
    error = relative_error(got["obs"], ref["obs"])
    print(f"ekf/{observation}: max relative error of the observation {error:.2e}")
    assert error <= RTOL
    space = jvdp.VanDerPol("ekf", observation).observation_space(jvdp.van_der_pol_params())
    assert sorted(space.spaces) == sorted(("estimate", observation.split("+")[1]))


def test_the_model_is_the_numpy_envs_model() -> None:
    """The params builder's host-side model noise is the numpy model's, bit for bit, and the
    JAX Heun map with its Jacobian is the numpy ``f_and_F``."""
    kwargs = {"epsilon": 0.9, "nominal": {"epsilon": 1.1, "Q": 4.0, "h": 0.12, "substeps": 80}}
    plant = gym.make(ENV_ID, **kwargs).unwrapped
    params = jvdp.van_der_pol_params(**kwargs)
    np.testing.assert_array_equal(np.asarray(params.model_Q), plant.model.GQGT)
    assert params.model_R == plant.model.R[0, 0] == 5.0 / 0.12
    x, u = np.array([1.3, -0.7]), np.array([0.4])
    want_x, want_F = plant._make_dynamics(plant.nominal_params).f_and_F(x, u)
    got_x, got_F = jvdp.heun_model_interval(jnp.asarray(x), 0.4 * params.nominal_u_max,
                                            params.nominal_epsilon,
                                            params.nominal_h / params.nominal_substeps,
                                            params.nominal_substeps)
    assert relative_error(np.asarray(got_x), want_x) <= 1e-13
    assert relative_error(np.asarray(got_F), want_F) <= 1e-13


def test_the_filter_sees_the_measurement_the_plant_returns() -> None:
    """The three kinds share the plant: the true states agree between kinds, and the true
    kind observes the state."""
    policy = feedback(5)
    runs = {kind: run_jax(kind, run_numpy(kind, policy, 50, np.random.default_rng(5)),
                          jvdp.van_der_pol_params(max_episode_steps=50), policy)
            for kind in ("true", "measurement", "ekf")}
    np.testing.assert_array_equal(runs["true"]["state"], runs["ekf"]["state"])
    np.testing.assert_array_equal(runs["true"]["obs"], runs["true"]["state"])
    np.testing.assert_array_equal(runs["measurement"]["state"], runs["ekf"]["state"])


def _batched_rollout(env: Any, params: Any, keys: Any, steps: int) -> Any:
    """gymnax's own reset/step (auto-reset included), vmapped over ``keys``, scanned."""
    def one(key: Any) -> Any:
        k_reset, k_steps = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry: Any, key: Any) -> Any:
            obs, state = carry
            action = jnp.clip(-0.3 * obs[0] - 0.5 * obs[1], -1.0, 1.0)[None]
            obs, state, reward, terminated, truncated, _ = env.step(key, state, action, params)
            return (obs, state), (obs, reward, terminated, truncated, state.filter_P)

        return jax.lax.scan(body, (obs, state), jax.random.split(k_steps, steps))[1]

    return jax.jit(jax.vmap(one))(keys)


def test_jit_and_vmap_over_eight_envs() -> None:
    env = jvdp.VanDerPol("ekf")
    params = env.default_params
    keys = jax.random.split(jax.random.key(0), 8)
    obs, reward, _, truncated, P = _batched_rollout(env, params, keys, 150)
    assert obs.shape == (8, 150, 2) and obs.dtype == jnp.float64
    assert reward.shape == (8, 150) and P.shape == (8, 150, 2, 2)
    assert bool(jnp.all(jnp.isfinite(obs))) and bool(jnp.all(jnp.isfinite(P)))
    assert bool(jnp.all(reward <= 0.0)) and bool(jnp.all(reward >= -params.state_bound ** 2))
    # the time limit (100) truncates every row once, and gymnax resets it
    assert np.array_equal(np.asarray(truncated).sum(axis=1), np.ones(8))
    # each row is the env run alone with its key; different keys, different noise
    one = _batched_rollout(env, params, keys[3:4], 150)
    np.testing.assert_array_equal(np.asarray(one[0][0]), np.asarray(obs[3]))
    assert not np.array_equal(np.asarray(obs[0]), np.asarray(obs[1]))


def test_vmap_over_drawn_epsilon_matches_the_numpy_env_row_by_row() -> None:
    """A batch of true ε, vmapped as a parameter, the model's kept at 1; each row is the
    numpy env built with that ε (and ``nominal={"epsilon": 1.0}``: without it the numpy
    model believes the truth), on the same noise, under the same feedback."""
    epsilons = 1.0 + 0.2 * np.random.default_rng(7).uniform(-1.0, 1.0, 4)
    policy = feedback(10)
    refs = [run_numpy("ekf", policy, 100, np.random.default_rng(100 + i), epsilon=float(eps),
                      nominal={"epsilon": 1.0}) for i, eps in enumerate(epsilons)]
    assert all(len(ref["reward"]) == 100 for ref in refs)
    params = jvdp.van_der_pol_params().replace(epsilon=jnp.asarray(epsilons))
    axes = jax.tree.map(lambda _: None, jvdp.van_der_pol_params()).replace(epsilon=0)
    env = jvdp.VanDerPol("ekf")

    def one(params: Any, x0: Any, y0: Any, noise: Any) -> Any:
        _, state = env.reset_with_noise(jvdp.VanDerPolResetNoise(x0, y0), params)

        def body(state: Any, step: Any) -> Any:
            offset, w = step
            a = policy.jax(offset, state.x)
            obs, state, reward, _, _ = env.step_with_noise(state, a, w, params)
            return state, (obs, state.x, reward, state.filter_P)

        return jax.lax.scan(body, state, (jnp.asarray(policy.offset[:100]), noise))[1]

    stack = lambda key: jnp.asarray(np.stack([ref[key] for ref in refs]))  # noqa: E731
    noise = jvdp.VanDerPolNoise(stack("process"), stack("measurement"))
    x0 = jnp.asarray(np.stack([ref["reset_noise"][0] for ref in refs]))
    y0 = jnp.asarray(np.stack([ref["reset_noise"][1] for ref in refs]))
    obs, x, reward, P = map(np.asarray, jax.jit(jax.vmap(one, in_axes=(axes, 0, 0, 0)))(
        params, x0, y0, noise))
    for i, ref in enumerate(refs):
        assert relative_error(x[i], ref["state"][1:]) <= RTOL
        assert relative_error(obs[i], ref["obs"][1:]) <= RTOL
        assert relative_error(reward[i], ref["reward"]) <= RTOL
        assert relative_error(P[i], ref["P"][1:]) <= RTOL
    # the true ε matters: the rows' trajectories differ
    assert not np.allclose(x[0], x[1])


def test_the_drawn_noise_follows_the_documented_splits() -> None:
    params = jvdp.van_der_pol_params(substeps=40, Q=3.0, R=2.0, h=0.08, epsilon=0.5,
                                     initial_state_cov=np.diag([0.3, 0.2]))
    key = jax.random.key(9)
    noise = jvdp.van_der_pol_noise(key, params)
    z = np.asarray(jax.random.normal(key, (41,), dtype=jnp.float64))
    assert noise.process.shape == (40,) and noise.measurement.shape == (1,)
    np.testing.assert_allclose(np.asarray(noise.process), np.sqrt(3.0 * (0.08 / 40)) * z[:40],
                               rtol=1e-15)
    np.testing.assert_allclose(np.asarray(noise.measurement), np.sqrt(2.0 / 0.08) * z[40:],
                               rtol=1e-15)
    reset = jvdp.van_der_pol_reset_noise(key, params)
    z3 = np.asarray(jax.random.normal(key, (3,), dtype=jnp.float64))
    # psd_sqrt of a diagonal matrix: a signed permutation of its diagonal's roots, hence |·|
    np.testing.assert_allclose(np.abs(np.asarray(reset.initial)),
                               np.abs(psd_sqrt(np.diag([0.3, 0.2])) @ z3[:2]), rtol=1e-15)
    np.testing.assert_allclose(np.asarray(reset.measurement), np.sqrt(2.0 / 0.08) * z3[2:],
                               rtol=1e-15)
    # step_env is step_with_noise on that noise
    env = jvdp.VanDerPol("ekf")
    _, state = env.reset_env(jax.random.key(1), params)
    a = jnp.array([0.2])
    by_key = env.step_env(key, state, a, params)
    by_noise = env.step_with_noise(state, a, noise, params)
    for u, v in zip(jax.tree.leaves(by_key), jax.tree.leaves(by_noise), strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"epsilon": float("nan")}, "epsilon"),
    ({"Q": -1.0}, "Q"),
    ({"R": 0.0}, "R"),
    ({"h": -0.1}, "h"),
    ({"substeps": 2.5}, "substeps"),
    ({"u_max": float("inf")}, "u_max"),
    ({"state_bound": 0.0}, "state_bound"),
    ({"state_bound": 30.0}, "state_bound"),            # beyond the Heun limit
    ({"nominal": {"epsilon": 2.0}}, "state_bound"),    # the model's ε counts for the limit
    ({"nominal": {"mu": 1.0}}, "nominal"),
    ({"nominal": {"R": -1.0}}, "nominal R"),
    ({"nominal": [("epsilon", 1.0)]}, "nominal"),
    ({"initial_state": (1.0, 2.0, 3.0)}, "initial_state"),
    ({"initial_state": (1.0, float("nan"))}, "initial_state"),
    ({"initial_state_cov": [[1.0, 2.0], [2.0, 1.0]]}, "initial_state_cov"),
    ({"max_episode_steps": 0}, "max_episode_steps"),
    ({"nis_tail": 1.5}, "nis_tail"),
    ({"nis_patience": 0}, "nis_patience"),
])
def test_bad_params_are_refused_by_name(kwargs: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        jvdp.van_der_pol_params(**kwargs)


def test_the_heun_limit_is_the_numpy_constructors() -> None:
    """The largest state_bound both accept (ε = 1, τ = 1e-3: √500 ≈ 22.36)."""
    gym.make(ENV_ID, state_bound=22.3)
    jvdp.van_der_pol_params(state_bound=22.3)
    with pytest.raises(ValueError, match="state_bound"):
        gym.make(ENV_ID, state_bound=22.4)
    with pytest.raises(ValueError, match="state_bound"):
        jvdp.van_der_pol_params(state_bound=22.4)


def test_float64_and_spaces() -> None:
    env = jvdp.VanDerPol("ekf")
    obs, state = env.reset(jax.random.key(0), env.default_params)
    assert obs.dtype == jnp.float64 and state.filter_P.dtype == jnp.float64
    assert env.observation_space(env.default_params).shape == (2,)
    assert jvdp.VanDerPol("measurement").observation_space(env.default_params).shape == (1,)
    assert env.action_space().shape == (1,) and env.name == ENV_ID
    with pytest.raises(ValueError, match="kind"):
        jvdp.VanDerPol("recurrent")
    with pytest.raises(ValueError, match="observation"):
        jvdp.VanDerPol("true", "estimate+covariance")
