"""fir_gym.jax.uncertain_oscillator against the numpy UncertainOscillator-v0 it mirrors
(issue 28).

The oracle is always the numpy reference: ``gym.make("fir_gym/UncertainOscillator-v0", ...)``
wrapped as each observation kind is (``observation="true"``, the bare plant,
``estimator="ekf"``), its generator replaced by one that serves given standard normals, so
that both envs run on the same noise: the numpy plant turns them into its increments
(``z @ sqrt.T`` of the initial spread, ``dt * sqrt(Q) * z`` on the velocity, ``z * sqrt(R)``
on the measurement), and the JAX env is handed those increments
(:meth:`~fir_gym.jax.uncertain_oscillator.UncertainOscillator.reset_with_noise` /
``step_with_noise``). Over whole episodes (500 steps, or to the termination) the two agree
to 1e-9 relative in float64: true states, observations, rewards, the δ of each transition,
EKF mean and covariance, terminated/truncated flags, the divergence watch; the NIS to
``1e-9 (1 + nis)``.

Measured maxima of the relative errors over the three kinds (state / observation / reward;
for ``"ekf"`` also estimate / covariance, and the NIS as ``|Δ| / (1 + nis)``); the δ of
every transition agrees exactly:

* ``paper`` (the printed reading, δ = 0.15 over 350..400, Q = 0.4; the EKF diverges in the
  window and its watch flags it): 1.1e-12 / 1.1e-12 / 4.3e-13; 6.6e-13 / 1.2e-12; 2.4e-13;
* ``rate_random_start`` (the "rate" reading, a random start, process noise, two
  overlapping δ windows): 4.5e-14 / 4.5e-14 / 3.3e-14; 1.8e-14 / 1.8e-12; 2.0e-15;
* ``mismatch`` (every nominal parameter wrong, truth's R and drive changed, no δ window):
  5.7e-14 / 3.3e-14 / 8.8e-14; 3.3e-14 / 3.4e-13; 1.8e-15;
* ``blowup`` (δ = 0.15 over 100..300: the state leaves ``|x| <= 1e4`` on the 181st step,
  which terminates with the terminal penalty): 9.0e-14 / 9.2e-14 / 4.9e-15; 1.8e-14 / 2.3e-12;
  1.7e-13;
* a simulation failure (δ = 100 from k = 10, ``state_bound`` 1e300: ``state_overflow`` on
  the 85th step): 7.8e-16 / 7.8e-16 / 1.3e-16; the EKF until its watch flags it 1.3e-15 /
  1.6e-15;
* the dict observations of the ``"ekf"`` kind (the "rate" reading, a random start):
  ``estimate+covariance`` 2.7e-13, ``estimate+measurement`` 8.5e-14.

The plant is not bit for bit the numpy one: XLA's CPU backend contracts ``a * b + c`` into
fused multiply-adds (numpy rounds the product first), so the JAX states differ from the
numpy ones by an ulp per step, and the printed reading's δ window (×1.15 per step over 51
steps) amplifies that to the 1e-12 above.
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
from fir_gym.jax import uncertain_oscillator as juo  # noqa: E402

RTOL = 1e-9
ENV_ID = "fir_gym/UncertainOscillator-v0"
STEPS = 500


def numpy_env(kind: str, observation: str = "estimate", **kwargs: Any) -> gym.Env:
    if kind == "ekf":
        return gym.make(ENV_ID, estimator="ekf", observation=observation, **kwargs)
    if kind == "true":
        return gym.make(ENV_ID, observation="true", **kwargs)
    return gym.make(ENV_ID, **kwargs)


def run_numpy(kind: str, actions: np.ndarray, rng: np.random.Generator,
              observation: str = "estimate", **kwargs: Any) -> dict[str, Any]:
    """An episode of the numpy env on the normals of ``rng``: what it returned, the noise
    increments it added (for the JAX env) and, for ``"ekf"``, the filter's mean and
    covariance after each step."""
    env = numpy_env(kind, observation, **kwargs)
    plant = env.unwrapped
    normals = QueuedNormals()
    plant.np_random = normals                  # every draw of the plant comes from here
    z0, zy = rng.standard_normal(3), rng.standard_normal(1)
    normals.queue += [z0, zy]
    obs, info = env.reset()
    assert not normals.queue
    # the plant's square roots and its velocity-noise scale (the same numbers, same bits)
    initial_sqrt = psd_sqrt(plant.initial_state_cov)
    meas = np.diag(psd_sqrt(plant.measurement_cov))   # 1x1: the plant's noise * diag
    velocity_scale = plant.params["dt"] * plant._noise_std
    out: dict[str, Any] = {
        "reset_noise": (z0 @ initial_sqrt.T, zy * meas),
        "process": [], "measurement": [], "obs": [flat(obs)],
        "state": [info["state"]], "reward": [], "terminated": [], "truncated": [],
        "delta": [], "P": [], "diverged": [], "nis": []}
    estimator = env.get_wrapper_attr("estimator") if kind == "ekf" else None

    def filter_record() -> None:
        if estimator is not None:
            out["P"].append(estimator.P)
            out["diverged"].append(bool(estimator.diverged))
            out["nis"].append(float(estimator.last_info["nis"]))

    filter_record()
    for a in actions:
        zw, zv = np.asarray(rng.standard_normal()), rng.standard_normal(1)
        normals.queue += [zw, zv]
        obs, reward, terminated, truncated, info = env.step(a)
        if "simulation_failure" in info:       # a failed step draws no measurement
            assert normals.queue.pop(0) is zv and terminated
            out["failure"] = info["simulation_failure"]
        assert not normals.queue
        out["process"].append(velocity_scale * zw)
        out["measurement"].append(zv * meas)
        out["obs"].append(flat(obs))
        out["state"].append(info["state"])
        out["reward"].append(reward)
        out["terminated"].append(terminated)
        out["truncated"].append(truncated)
        out["delta"].append(info["delta"])
        filter_record()
        if terminated or truncated:
            break
    env.close()
    return {key: (value if key == "reset_noise" else np.array(value))
            for key, value in out.items()}


def run_jax(kind: str, actions: np.ndarray, ref: dict[str, Any], params: Any,
            observation: str = "estimate") -> dict[str, np.ndarray]:
    """The JAX env on the numpy episode's noise: reset, then a scan of step_with_noise."""
    env = juo.UncertainOscillator(kind, observation)
    n = len(ref["reward"])
    noise = juo.UncertainOscillatorNoise(jnp.asarray(ref["process"]),
                                         jnp.asarray(ref["measurement"]))
    x0, y0 = ref["reset_noise"]

    @jax.jit
    def rollout(noise: Any, actions: Any) -> Any:
        obs0, state = env.reset_with_noise(
            juo.UncertainOscillatorResetNoise(jnp.asarray(x0), jnp.asarray(y0)), params)

        def body(state: Any, step: Any) -> Any:
            a, w = step
            obs, state, reward, terminated, info = env.step_with_noise(state, a, w, params)
            return state, (flat_jax(obs), state.x, reward, terminated,
                           env.is_truncated(state, params), info["delta"],
                           state.filter_x, state.filter_P, state.diverged, state.nis,
                           info["simulation_failure"])

        _, trace = jax.lax.scan(body, state, (actions, noise))
        return (flat_jax(obs0), state), trace

    (obs0, s0), trace = rollout(noise, jnp.asarray(actions[:n]))
    obs, x, reward, terminated, truncated, delta, fx, fP, diverged, nis, failure = map(
        np.asarray, trace)
    return {"obs": np.concatenate([np.asarray(obs0)[None], obs]),
            "state": np.concatenate([np.asarray(s0.x)[None], x]), "reward": reward,
            "terminated": terminated, "truncated": truncated, "delta": delta,
            "failure": failure,
            "estimate": np.concatenate([np.asarray(s0.filter_x)[None], fx]),
            "P": np.concatenate([np.asarray(s0.filter_P)[None], fP]),
            "diverged": np.concatenate([[bool(s0.diverged)], diverged]),
            "nis": np.concatenate([[float(s0.nis)], nis])}


def holding_actions(n: int, seed: int) -> np.ndarray:
    """Float32 actions around the holding force (0.52), some beyond ±1 (clipped)."""
    k = np.arange(n)
    a = 0.52 + 0.4 * np.sin(0.05 * k) + 0.3 * np.random.default_rng(seed).standard_normal(n)
    return a.astype(np.float32)[:, None]


CASES = {
    # the paper's plant: the printed reading, δ = 0.15 over 350..400, Q = 0.4, a known
    # start; the EKF (δ = 0) loses the truth in the window and its watch flags it
    "paper": ({}, lambda n: holding_actions(n, 1), True),
    # the "rate" reading, a random start (process noise is the default Q = 0.4) and two
    # overlapping windows (δ adds up to 0.1 over 150..180)
    "rate_random_start": ({"uncertainty": "rate",
                           "initial_state_cov": np.diag([0.04, 0.01, 0.0025]),
                           "delta_schedule": ((100, 180, 0.3), (150, 250, -0.2))},
                          lambda n: holding_actions(n, 2), False),
    # a model mismatch: every nominal parameter differs from the truth; no δ window
    "mismatch": ({"delta_schedule": (), "R": 0.05, "drive": 12.5,
                  "nominal": {"stiffness": 22.0, "damping_gain": 11.0, "drive": 11.0,
                              "u_max": 27.0, "dt": 0.0105, "Q": 0.8, "R": 0.15}},
                 lambda n: holding_actions(n, 3), False),
    # a long window of the printed reading: the state leaves |x| <= 1e4 (termination)
    "blowup": ({"delta_schedule": ((100, 300, 0.15),)}, lambda n: holding_actions(n, 5), True),
}


def jax_params(**kwargs: Any) -> Any:
    return juo.uncertain_oscillator_params(**kwargs)


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("kind", ["true", "measurement", "ekf"])
def test_an_episode_matches_the_numpy_env(kind: str, case: str) -> None:
    kwargs, actions_of, diverges = CASES[case]
    actions = actions_of(STEPS)
    ref = run_numpy(kind, actions, np.random.default_rng(28), **kwargs)
    got = run_jax(kind, actions, ref, jax_params(**kwargs))
    n = len(ref["reward"])
    if case == "blowup":
        assert n < STEPS and ref["terminated"][-1] and got["terminated"][-1]
        assert ref["reward"][-1] <= -2.25 * (STEPS - n + 1)      # the terminal penalty
        assert np.abs(ref["state"][-1]).max() > 1e4
    else:
        assert n == STEPS and ref["truncated"][-1] and not ref["terminated"].any()
    assert ref["delta"].any() == (case != "mismatch")
    np.testing.assert_array_equal(got["terminated"], ref["terminated"])
    np.testing.assert_array_equal(got["truncated"], ref["truncated"])
    errors = {key: relative_error(got[key], ref[key])
              for key in ("state", "obs", "reward", "delta")}
    if kind == "ekf":
        errors["estimate"] = relative_error(got["estimate"], ref["obs"])
        errors["P"] = relative_error(got["P"], ref["P"])
        # the NIS e²/S of an innovation e = y − x̂₁ (a difference) inherits the estimate's
        # round-off relative to |e|: it is held to 1e-9 (1 + nis)
        nis_error = float(np.max(np.abs(got["nis"] - ref["nis"]) / (1.0 + np.abs(ref["nis"]))))
        np.testing.assert_array_equal(got["diverged"], ref["diverged"])
        assert ref["diverged"][-1] == diverges
    print(f"{kind}/{case}: {n} steps, max relative errors "
          + ", ".join(f"{key} {value:.2e}" for key, value in errors.items())
          + (f"; nis |Δ|/(1 + nis) {nis_error:.2e}" if kind == "ekf" else ""))
    assert max(errors.values()) <= RTOL, errors
    if kind == "ekf":
        assert nis_error <= RTOL


@pytest.mark.parametrize("kind", ["true", "measurement", "ekf"])
def test_a_simulation_failure_ends_the_episode_as_in_the_numpy_env(kind: str) -> None:
    """δ = 100 (x ×101 per step) with a domain too wide to leave: the state passes
    ``state_limit`` (1e150), a simulation failure — the plant keeps its last valid state,
    the observation repeats, the terminal penalty is paid and the episode terminates.

    The EKF (δ = 0) is compared until its watch flags it (the same step in both): past
    that its covariance, fed innovations of 1e20 and more, loses positive definiteness in
    float64 in both implementations, and each ends in its own round-off garbage (the
    numpy estimate stays finite, the JAX one meets a NaN and keeps its last finite one)."""
    kwargs = {"state_bound": 1e300, "delta_schedule": ((10, 499, 100.0),)}
    actions = holding_actions(STEPS, 9)
    ref = run_numpy(kind, actions, np.random.default_rng(4), **kwargs)
    got = run_jax(kind, actions, ref, jax_params(**kwargs))
    n = len(ref["reward"])
    assert ref["failure"] == "state_overflow" and n < 100
    assert got["failure"][-1] == 1 + juo.SIMULATION_FAILURES.index("state_overflow")
    assert not got["failure"][:-1].any()
    np.testing.assert_array_equal(got["terminated"], ref["terminated"])
    np.testing.assert_array_equal(got["state"][-1], got["state"][-2])      # kept
    assert ref["reward"][-1] == -2.25 * (1 + STEPS - n)
    errors = {key: relative_error(got[key], ref[key]) for key in ("state", "reward")}
    if kind == "ekf":
        np.testing.assert_array_equal(got["diverged"], ref["diverged"])
        flagged = int(np.argmax(ref["diverged"]))
        assert 0 < flagged < n
        errors["obs"] = relative_error(got["obs"][:flagged], ref["obs"][:flagged])
        errors["P"] = relative_error(got["P"][:flagged], ref["P"][:flagged])
    else:
        np.testing.assert_array_equal(got["obs"][-1], got["obs"][-2])      # repeated
        errors["obs"] = relative_error(got["obs"], ref["obs"])
    print(f"{kind}/failure: {n} steps, max relative errors "
          + ", ".join(f"{key} {value:.2e}" for key, value in errors.items()))
    assert max(errors.values()) <= RTOL, errors


def test_the_schedule_is_read_by_the_step_index() -> None:
    """δ_k of the paper's schedule is 0.15 exactly for the transitions 350..400."""
    params = jax_params()
    ks = jnp.arange(500)
    delta = jax.vmap(lambda k: juo.delta_at(k, params.delta_first, params.delta_last,
                                            params.delta_value))(ks)
    want = np.where((np.arange(500) >= 350) & (np.arange(500) <= 400), 0.15, 0.0)
    np.testing.assert_array_equal(np.asarray(delta), want)


@pytest.mark.parametrize("observation", ["estimate+covariance", "estimate+measurement"])
def test_the_ekf_kind_observes_what_estimator_observation_does(observation: str) -> None:
    """The dict observations of EstimatorObservation: estimate with the upper triangle of P,
    or with the measurement, over an episode of the paper's plant."""
    kwargs = {"uncertainty": "rate", "initial_state_cov": np.diag([0.01, 0.01, 0.001])}
    actions = holding_actions(STEPS, 8)
    ref = run_numpy("ekf", actions, np.random.default_rng(3), observation=observation, **kwargs)
    got = run_jax("ekf", actions, ref, jax_params(**kwargs), observation=observation)
    assert got["obs"].shape == ref["obs"].shape == (STEPS + 1,
                                                    9 if "covariance" in observation else 4)
    error = relative_error(got["obs"], ref["obs"])
    print(f"ekf/{observation}: max relative error of the observation {error:.2e}")
    assert error <= RTOL
    space = juo.UncertainOscillator("ekf", observation).observation_space(jax_params())
    assert sorted(space.spaces) == sorted(("estimate", observation.split("+")[1]))


def test_the_filter_sees_the_measurement_the_plant_returns() -> None:
    """The three kinds share the plant: the true states agree between kinds, and the true
    kind observes the state. (To round-off, not bit for bit: XLA's CPU backend contracts
    ``a * b + c`` into fused multiply-adds, and where it does depends on the whole compiled
    step, which differs between kinds.)"""
    actions = holding_actions(60, 3)
    runs = {kind: run_jax(kind, actions, run_numpy(kind, actions, np.random.default_rng(5)),
                          jax_params()) for kind in ("true", "measurement", "ekf")}
    np.testing.assert_array_equal(runs["true"]["obs"], runs["true"]["state"])
    assert relative_error(runs["ekf"]["state"], runs["true"]["state"]) <= 1e-12
    assert relative_error(runs["measurement"]["state"], runs["true"]["state"]) <= 1e-12


def _batched_rollout(env: Any, params: Any, keys: Any, steps: int, params_axes: Any = None
                     ) -> Any:
    """gymnax's own reset/step (auto-reset included), vmapped over ``keys``, scanned."""
    def one(key: Any, params: Any) -> Any:
        k_reset, k_steps = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry: Any, key: Any) -> Any:
            obs, state = carry
            action = jnp.clip(0.52 - 0.5 * (obs[0] - 1.0), -1.0, 1.0)[None]
            obs, state, reward, terminated, truncated, _ = env.step(key, state, action, params)
            return (obs, state), (obs, reward, terminated, truncated, state.filter_P)

        return jax.lax.scan(body, (obs, state), jax.random.split(k_steps, steps))[1]

    return jax.jit(jax.vmap(one, in_axes=(0, params_axes)))(keys, params)


@pytest.mark.parametrize("uncertainty", ["state", "rate"])
def test_jit_and_vmap_over_eight_envs(uncertainty: str) -> None:
    env = juo.UncertainOscillator("ekf")
    params = jax_params(uncertainty=uncertainty, initial_state_cov=np.diag([0.01, 0.01, 0.0]))
    keys = jax.random.split(jax.random.key(0), 8)
    obs, reward, terminated, truncated, P = _batched_rollout(env, params, keys, 120)
    assert obs.shape == (8, 120, 3) and obs.dtype == jnp.float64
    assert reward.shape == (8, 120) and P.shape == (8, 120, 3, 3)
    assert bool(jnp.all(jnp.isfinite(obs))) and bool(jnp.all(jnp.isfinite(P)))
    assert bool(jnp.all((reward <= 0.0) & (reward >= -2.25)))
    # 120 steps: before the δ window and short of the time limit
    assert not bool(jnp.any(terminated)) and not bool(jnp.any(truncated))
    # each row is the env run alone with its key
    one = _batched_rollout(env, params, keys[3:4], 120)
    np.testing.assert_array_equal(np.asarray(one[0][0]), np.asarray(obs[3]))
    # different keys, different noise
    assert not np.array_equal(np.asarray(obs[0]), np.asarray(obs[1]))


def test_the_same_key_gives_bit_identical_rollouts() -> None:
    env = juo.UncertainOscillator("ekf")
    keys = jax.random.split(jax.random.key(123), 4)
    first = _batched_rollout(env, env.default_params, keys, 200)
    second = _batched_rollout(juo.UncertainOscillator("ekf"), jax_params(), keys, 200)
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_vmap_over_drawn_parameters_matches_the_numpy_env_row_by_row() -> None:
    """A batch of true stiffness (the model keeps the nominal 25) and δ drawn, vmapped as
    parameters; each row is the numpy env built with them, on the same noise."""
    draws = np.random.default_rng(7).uniform(-1.0, 1.0, (2, 6))
    stiffness = 25.0 * (1.0 + 0.1 * draws[0])
    deltas = 0.1 + 0.05 * draws[1]
    actions = holding_actions(150, 4)
    kwargs = [{"stiffness": float(c), "delta_schedule": ((60, 90, float(d)),),
               "nominal": {"stiffness": 25.0}}
              for c, d in zip(stiffness, deltas, strict=True)]
    refs = [run_numpy("ekf", actions, np.random.default_rng(100 + i), **kw)
            for i, kw in enumerate(kwargs)]
    assert all(len(ref["reward"]) == 150 for ref in refs)
    base = jax_params(delta_schedule=((60, 90, 0.1),))
    params = base.replace(stiffness=jnp.asarray(stiffness),
                          delta_value=jnp.asarray(deltas)[:, None])
    axes = jax.tree.map(lambda _: None, base).replace(stiffness=0, delta_value=0)
    env = juo.UncertainOscillator("ekf")

    def one(params: Any, x0: Any, y0: Any, noise: Any) -> Any:
        _, state = env.reset_with_noise(juo.UncertainOscillatorResetNoise(x0, y0), params)

        def body(state: Any, step: Any) -> Any:
            a, w = step
            obs, state, reward, _, _ = env.step_with_noise(state, a, w, params)
            return state, (obs, state.x, reward, state.filter_P)

        return jax.lax.scan(body, state, (jnp.asarray(actions), noise))[1]

    stack = lambda key: jnp.asarray(np.stack([ref[key] for ref in refs]))  # noqa: E731
    noise = juo.UncertainOscillatorNoise(stack("process"), stack("measurement"))
    x0 = jnp.asarray(np.stack([ref["reset_noise"][0] for ref in refs]))
    y0 = jnp.asarray(np.stack([ref["reset_noise"][1] for ref in refs]))
    obs, x, reward, P = map(np.asarray, jax.jit(jax.vmap(one, in_axes=(axes, 0, 0, 0)))(
        params, x0, y0, noise))
    for i, ref in enumerate(refs):
        assert relative_error(x[i], ref["state"][1:]) <= RTOL
        assert relative_error(obs[i], ref["obs"][1:]) <= RTOL
        assert relative_error(reward[i], ref["reward"]) <= RTOL
        assert relative_error(P[i], ref["P"][1:]) <= RTOL
    assert not np.allclose(x[0], x[1])


def test_the_drawn_noise_follows_the_documented_splits() -> None:
    cov = np.diag([1e-2, 4e-3, 1e-4])
    params = jax_params(Q=0.3, R=0.2, dt=0.02, initial_state_cov=cov)
    key = jax.random.key(9)
    noise = juo.uncertain_oscillator_noise(key, params)
    reset = juo.uncertain_oscillator_reset_noise(key, params)
    z2 = np.asarray(jax.random.normal(key, (2,), dtype=jnp.float64))
    z4 = np.asarray(jax.random.normal(key, (4,), dtype=jnp.float64))
    assert np.shape(noise.process) == () and np.shape(noise.measurement) == (1,)
    np.testing.assert_allclose(float(noise.process), 0.02 * np.sqrt(0.3) * z2[0], rtol=1e-15)
    np.testing.assert_allclose(np.asarray(noise.measurement), np.sqrt(0.2) * z2[1:], rtol=1e-15)
    # the initial spread is S z with S the plant's square root (psd_sqrt: V Λ^½ from eigh —
    # for a diagonal matrix a signed permutation of its diagonal's roots, hence the |·|)
    np.testing.assert_allclose(np.abs(np.asarray(reset.initial)), np.abs(psd_sqrt(cov) @ z4[:3]),
                               rtol=1e-15)
    np.testing.assert_allclose(np.asarray(reset.measurement), np.sqrt(0.2) * z4[3:], rtol=1e-15)
    # step_env is step_with_noise on that noise, reset_env reset_with_noise
    env = juo.UncertainOscillator("ekf")
    _, state = env.reset_env(jax.random.key(1), params)
    _, by_noise = env.reset_with_noise(juo.uncertain_oscillator_reset_noise(
        jax.random.key(1), params), params)
    for u, v in zip(jax.tree.leaves(state), jax.tree.leaves(by_noise), strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))
    a = jnp.array([0.2])
    by_key = env.step_env(key, state, a, params)
    by_noise_step = env.step_with_noise(state, a, noise, params)
    for u, v in zip(jax.tree.leaves(by_key), jax.tree.leaves(by_noise_step), strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"uncertainty": "printed"}, "uncertainty"),
    ({"delta_schedule": ((400, 350, 0.15),)}, "delta_schedule"),
    ({"delta_schedule": ((350, 400, -1.0),)}, "delta_schedule"),
    ({"Q": -0.1}, "Q"),
    ({"R": 0.0}, "R"),
    ({"dt": 0.0}, "dt"),
    ({"stiffness": -25.0}, "stiffness"),
    ({"u_max": float("inf")}, "u_max"),
    ({"drive": float("nan")}, "drive"),
    ({"state_bound": 0.0}, "state_bound"),
    ({"setpoint": float("inf")}, "setpoint"),
    ({"initial_state": (0.0, 0.0)}, "initial_state"),
    ({"initial_state_cov": -np.eye(3)}, "initial_state_cov"),
    ({"nominal": {"mass": 1.0}}, "nominal"),
    ({"nominal": {"dt": -0.01}}, "nominal dt"),
    ({"nominal": {"Q": -1.0}}, "nominal Q"),
    ({"max_episode_steps": 0}, "max_episode_steps"),
    ({"nis_tail": 1.5}, "nis_tail"),
])
def test_params_refuse_bad_input_naming_it(kwargs: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        jax_params(**kwargs)


def test_the_numpy_plant_refuses_what_the_params_refuse() -> None:
    """The shared checks are the numpy plant's own (its validators), so both refuse."""
    for kwargs in ({"uncertainty": "printed"}, {"delta_schedule": ((400, 350, 0.15),)},
                   {"R": 0.0}, {"dt": 0.0}, {"stiffness": -25.0}, {"nominal": {"mass": 1.0}}):
        with pytest.raises(ValueError):
            gym.make(ENV_ID, **kwargs)


def test_float64_throughout() -> None:
    env = juo.UncertainOscillator("ekf")
    obs, state = env.reset(jax.random.key(0), env.default_params)
    assert obs.dtype == jnp.float64 and state.filter_P.dtype == jnp.float64
    assert env.observation_space(env.default_params).shape == (3,)
    assert juo.UncertainOscillator("measurement").observation_space(
        env.default_params).shape == (1,)
    with pytest.raises(ValueError, match="kind"):
        juo.UncertainOscillator("fir")
    with pytest.raises(ValueError, match="observation"):
        juo.UncertainOscillator("true", "estimate+covariance")


def test_x64_turned_off_later_is_refused() -> None:
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError, match="jax_enable_x64"):
            juo.UncertainOscillator("ekf")
    finally:
        jax.config.update("jax_enable_x64", True)
