"""fir_gym.jax.carrier_motion against the numpy CarrierMotion-v0 it mirrors (issue 28).

The oracle is always the numpy reference: ``gym.make("fir_gym/CarrierMotion-v0", ...)``
wrapped as each observation kind is (``observation="true"``, the bare plant,
``estimator="kf"``), its generator replaced by one that serves given standard normals, so
that both envs run on the same noise: the numpy plant turns them into its increments with
its own square roots (``z @ sqrt.T``), and the JAX env is handed those increments
(:meth:`fir_gym.jax.carrier_motion.CarrierMotion.reset_with_noise` / ``step_with_noise``).
Over whole episodes the two agree to 1e-9 relative in float64: true states, observations,
rewards, terminated/truncated flags, the simulation-failure codes, KF mean and covariance,
the divergence watch. (The relative error is elementwise, so a component passing near 0
shows the largest figure: 1.4e-10 for the KF mean, whose differences are 1.7e-15 of the
episode's largest estimate.)
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
from fir_gym.jax import carrier_motion as jcarrier  # noqa: E402

RTOL = 1e-9
ENV_ID = "fir_gym/CarrierMotion-v0"


def numpy_env(kind: str, observation: str = "estimate", **kwargs: Any) -> gym.Env:
    if kind == "kf":
        return gym.make(ENV_ID, estimator="kf", observation=observation, **kwargs)
    if kind == "true":
        return gym.make(ENV_ID, observation="true", **kwargs)
    return gym.make(ENV_ID, **kwargs)


def run_numpy(kind: str, actions: np.ndarray, rng: np.random.Generator,
              observation: str = "estimate", **kwargs: Any) -> dict[str, Any]:
    """An episode of the numpy env on the normals of ``rng``: what it returned, the noise
    increments it added (for the JAX env) and, for ``"kf"``, the filter's covariance, watch
    and NIS after each step."""
    env = numpy_env(kind, observation, **kwargs)
    plant = env.unwrapped
    normals = QueuedNormals()
    plant.np_random = normals                  # every draw of the plant comes from here
    z0, zy = rng.standard_normal(2), rng.standard_normal(1)
    normals.queue += [z0, zy]
    obs, info = env.reset()
    assert not normals.queue
    # the plant's square roots (its own arrays: the same bits)
    initial_sqrt, process_sqrt = plant._initial_sqrt, plant._process_sqrt
    meas = np.diag(plant._measurement_sqrt)    # 1x1: the plant's noise * diag
    out: dict[str, Any] = {
        "reset_noise": (z0 @ initial_sqrt.T, zy * meas),
        "process": [], "measurement": [], "obs": [flat(obs)],
        "state": [info["state"]], "reward": [], "terminated": [], "truncated": [],
        "failure": [], "P": [], "diverged": [], "nis": []}
    estimator = env.get_wrapper_attr("estimator") if kind == "kf" else None

    def filter_record() -> None:
        if estimator is not None:
            out["P"].append(estimator.P.copy())
            out["diverged"].append(bool(estimator.diverged))
            out["nis"].append(float(estimator.last_info["nis"]))

    filter_record()
    for a in actions:
        zw, zv = rng.standard_normal(2), rng.standard_normal(1)
        normals.queue += [zw, zv]              # the process noise is drawn even for q = 0
        obs, reward, terminated, truncated, info = env.step(a)
        failure = info.get("simulation_failure")
        if failure in ("nonfinite_state", "state_overflow"):
            assert normals.queue == [zv]       # a failed state: no measurement is drawn
            normals.queue.clear()
        assert not normals.queue
        out["process"].append(zw @ process_sqrt.T)
        out["measurement"].append(zv * meas)
        out["obs"].append(flat(obs))
        out["state"].append(info["state"])
        out["reward"].append(reward)
        out["terminated"].append(terminated)
        out["truncated"].append(truncated)
        out["failure"].append(0 if failure is None
                              else 1 + jcarrier.SIMULATION_FAILURES.index(failure))
        filter_record()
        if terminated or truncated:
            break
    env.close()
    return {key: (value if key == "reset_noise" else np.array(value))
            for key, value in out.items()}


def run_jax(kind: str, actions: np.ndarray, ref: dict[str, Any], params: Any,
            observation: str = "estimate") -> dict[str, np.ndarray]:
    """The JAX env on the numpy episode's noise: reset, then a scan of step_with_noise."""
    env = jcarrier.CarrierMotion(kind, observation)
    n = len(ref["reward"])
    noise = jcarrier.CarrierMotionNoise(jnp.asarray(ref["process"]),
                                        jnp.asarray(ref["measurement"]))
    x0, y0 = ref["reset_noise"]

    @jax.jit
    def rollout(noise: Any, actions: Any) -> Any:
        obs0, state = env.reset_with_noise(
            jcarrier.CarrierMotionResetNoise(jnp.asarray(x0), jnp.asarray(y0)), params)

        def body(state: Any, step: Any) -> Any:
            a, w = step
            obs, state, reward, terminated, info = env.step_with_noise(state, a, w, params)
            return state, (flat_jax(obs), state.x, reward, terminated,
                           env.is_truncated(state, params), info["simulation_failure"],
                           state.filter_x, state.filter_P, state.diverged, state.nis)

        _, trace = jax.lax.scan(body, state, (actions, noise))
        return (flat_jax(obs0), state), trace

    (obs0, s0), trace = rollout(noise, jnp.asarray(actions[:n]))
    obs, x, reward, terminated, truncated, failure, fx, fP, diverged, nis = map(np.asarray,
                                                                               trace)
    return {"obs": np.concatenate([np.asarray(obs0)[None], obs]),
            "state": np.concatenate([np.asarray(s0.x)[None], x]), "reward": reward,
            "terminated": terminated, "truncated": truncated, "failure": failure,
            "estimate": np.concatenate([np.asarray(s0.filter_x)[None], fx]),
            "P": np.concatenate([np.asarray(s0.filter_P)[None], fP]),
            "diverged": np.concatenate([[bool(s0.diverged)], diverged]),
            "nis": np.concatenate([[float(s0.nis)], nis])}


def compensator_actions(n: int, seed: int) -> np.ndarray:
    """Float32 offsets: a slow swing with noise, some beyond ±1 (clipped)."""
    k = np.arange(n)
    a = 0.6 * np.sin(0.03 * k) + 0.5 * np.random.default_rng(seed).standard_normal(n)
    return a.astype(np.float32)[:, None]


CASES: dict[str, dict[str, Any]] = {
    # paper 001's plant: process noise, a start drawn from the stationary distribution
    "default": {},
    # the paper's uncertainties on the truth; the filter's model keeps Δ22 = Δc = 0
    "mismatch": {"delta22": 0.006, "delta_c": 0.1},
    # a model given by nominal=: the filter believes a rougher sea and a worse sensor
    "nominal": {"nominal": {"q": 0.07, "v": 2.0, "a21": -0.4}},
    # a coarser sampling and a smaller compensator
    "sampling": {"sample_period": 0.2, "c_max": 0.5},
    # a start near the state limit: the transient carries x1 past 1e150 on step 11
    # (state_overflow: the episode terminates, the plant stays where it was)
    "overflow": {"initial_state": (2e149, 9e149), "initial_state_cov": None},
    # a sensor gain of 1e300 on the truth: the deck's swing from rest at rate 1.5e8 makes
    # the measurement overflow on step 15 (nonfinite_observation); the KF, whose model
    # believes a gain of 1, sees innovations of 1e307 (an infinite NIS) and flags itself
    "sensor_overflow": {"initial_state": (0.0, 1.5e8), "initial_state_cov": None,
                        "delta_c": 1e300},
}


#: the failing cases: steps, the failure's code (SIMULATION_FAILURES, from 1)
FAILING = {"overflow": (11, 2), "sensor_overflow": (15, 3)}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("kind", ["true", "measurement", "kf"])
def test_an_episode_matches_the_numpy_env(kind: str, case: str) -> None:
    kwargs = CASES[case]
    actions = compensator_actions(1000, sorted(CASES).index(case))
    ref = run_numpy(kind, actions, np.random.default_rng(28), **kwargs)
    got = run_jax(kind, actions, ref, jcarrier.carrier_motion_params(**kwargs))
    n = len(ref["reward"])
    if case in FAILING:
        steps, code = FAILING[case]
        assert n == steps and ref["terminated"][-1] and got["terminated"][-1]
        assert ref["failure"][-1] == code
        assert ref["reward"][-1] == -100.0 * (1 + 1000 - steps)  # the terminal penalty
        np.testing.assert_array_equal(ref["state"][-1], ref["state"][-2])
        if kind != "kf":                                 # the KF still steps
            np.testing.assert_array_equal(ref["obs"][-1], ref["obs"][-2])
    else:
        assert n == 1000 and ref["truncated"][-1] and not ref["terminated"].any()
    np.testing.assert_array_equal(got["terminated"], ref["terminated"])
    np.testing.assert_array_equal(got["truncated"], ref["truncated"])
    np.testing.assert_array_equal(got["failure"], ref["failure"])
    errors = {key: relative_error(got[key], ref[key]) for key in ("state", "obs", "reward")}
    nis_error, nis_note = 0.0, ""
    if kind == "kf":
        np.testing.assert_array_equal(got["diverged"], ref["diverged"])
        assert ref["diverged"][-1] == (case in FAILING)
        assert np.isfinite(got["estimate"]).all() and np.isfinite(got["P"]).all()
        # the overflow case too: the prior floor 1e-9 x0² (prior_of) of a start near 1e150
        # gives P0 ≈ 1e290 against R_d = 10, where a plain Joseph product would lose P⁺ to
        # cancellation (round-off ε‖P‖ ≈ 1e274); both filters form it from factors
        errors["estimate"] = relative_error(got["estimate"], ref["obs"])
        errors["P"] = relative_error(got["P"], ref["P"])
        # NIS to 1e-9 (1 + nis + its round-off floor); the sensor overflow's infinite NIS
        # must agree exactly. The floor: an innovation y − H x⁻ of two numbers of the
        # state's size is known to a few ulps of it, 4 ε |x|, so the NIS to (4 ε |x|)² / R
        # (S ≥ R) — 1e-10 for these plants, 1e268 for the start near 1e150 (the NIS of
        # numpy's round-off innovation there: 4e265, JAX's 0: both inside it)
        np.testing.assert_array_equal(np.isinf(got["nis"]), np.isinf(ref["nis"]))
        finite = np.isfinite(ref["nis"])
        R = float(np.asarray(jcarrier.carrier_motion_params(**kwargs).nominal_R).ravel()[0])
        floor = (4 * np.finfo(float).eps * np.abs(ref["state"]).max(axis=1)) ** 2 / R
        nis_error = float(np.max(np.abs(got["nis"][finite] - ref["nis"][finite])
                                 / (1.0 + np.abs(ref["nis"][finite]) + floor[finite] / RTOL)))
        nis_note = f"; nis |Δ|/(1 + nis + floor/rtol) {nis_error:.2e}"
    print(f"{kind}/{case}: {n} steps, max relative errors "
          + ", ".join(f"{key} {value:.2e}" for key, value in errors.items())
          + nis_note)
    assert max(errors.values()) <= RTOL, errors
    assert nis_error <= RTOL


@pytest.mark.parametrize("observation", ["estimate+covariance", "estimate+measurement"])
def test_the_kf_kind_observes_what_estimator_observation_does(observation: str) -> None:
    """The dict observations of EstimatorObservation: estimate with the upper triangle of P,
    or with the measurement, over an episode of the mismatched plant."""
    actions = compensator_actions(1000, 8)
    kwargs = CASES["mismatch"]
    ref = run_numpy("kf", actions, np.random.default_rng(3), observation=observation, **kwargs)
    got = run_jax("kf", actions, ref, jcarrier.carrier_motion_params(**kwargs),
                  observation=observation)
    assert got["obs"].shape == ref["obs"].shape == (1001, 5 if "covariance" in observation else 3)
    error = relative_error(got["obs"], ref["obs"])
    print(f"kf/{observation}: max relative error of the observation {error:.2e}")
    assert error <= RTOL
    space = jcarrier.CarrierMotion("kf", observation).observation_space(
        jcarrier.carrier_motion_params())
    assert sorted(space.spaces) == sorted(("estimate", observation.split("+")[1]))


def test_the_params_are_the_numpy_plants_bit_for_bit() -> None:
    """The host-side sampling is the numpy plant's: its matrices, square roots, σ1 and the
    filter's model, for the truth and a nominal that differs."""
    kwargs = {"delta22": 0.004, "delta_c": -0.05, "sample_period": 0.07, "q": 0.02,
              "nominal": {"v": 1.5}}
    plant = gym.make(ENV_ID, **kwargs).unwrapped
    params = jcarrier.carrier_motion_params(**kwargs)
    model = plant.model
    pairs = [(params.A_d, plant._A_d), (params.process_sqrt, plant._process_sqrt),
             (params.C, plant._C), (params.measurement_std, plant._measurement_sqrt[0, 0]),
             (params.sigma1, plant._sigma1), (params.initial_state_cov, plant.initial_state_cov),
             (params.initial_sqrt, plant._initial_sqrt), (params.nominal_A_d, model.A),
             (params.nominal_Q_d, model.G @ model.Q @ model.G.T), (params.nominal_C, model.C),
             (params.nominal_R, model.R)]
    for got, want in pairs:
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    assert float(params.nominal_R[0, 0]) == 1.5 / 0.07


def test_a_calm_sea_divides_the_reward_by_one() -> None:
    """q = 0: no stationary spread, σ1 = 1 (the numpy plant's rule); the start is then the
    initial state itself."""
    params = jcarrier.carrier_motion_params(q=0.0)
    assert params.sigma1 == 1.0 == gym.make(ENV_ID, q=0.0).unwrapped._sigma1
    actions = compensator_actions(200, 4)
    ref = run_numpy("kf", actions, np.random.default_rng(6), q=0.0,
                    initial_state=(0.5, -0.1), initial_state_cov=None)
    got = run_jax("kf", actions, ref, jcarrier.carrier_motion_params(
        q=0.0, initial_state=(0.5, -0.1), initial_state_cov=None))
    for key in ("state", "obs", "reward", "P"):
        assert relative_error(got[key], ref[key]) <= RTOL, key


def test_the_filter_sees_the_measurement_the_plant_returns() -> None:
    """The three kinds share the plant: the true states agree between kinds, and the
    true kind's observation is the state."""
    actions = compensator_actions(50, 3)
    runs = {kind: run_jax(kind, actions, run_numpy(kind, actions, np.random.default_rng(5)),
                          jcarrier.carrier_motion_params()) for kind in jcarrier.KINDS}
    np.testing.assert_array_equal(runs["true"]["state"], runs["kf"]["state"])
    np.testing.assert_array_equal(runs["true"]["obs"], runs["true"]["state"])
    np.testing.assert_array_equal(runs["measurement"]["state"], runs["kf"]["state"])


def test_a_nan_action_is_a_simulation_failure() -> None:
    """The numpy plant refuses a NaN action (ValueError); under jit it ends the episode as a
    non-finite reward, the plant kept where it was, the terminal penalty paid."""
    env = jcarrier.CarrierMotion("kf")
    params = jcarrier.carrier_motion_params()
    _, state = env.reset(jax.random.key(0), params)
    obs2, new, reward, terminated, info = jax.jit(env.step_env)(
        jax.random.key(1), state, jnp.array([jnp.nan]), params)
    assert bool(terminated) and int(info["simulation_failure"]) == 4
    assert float(reward) == -100.0 * (1 + 999)
    np.testing.assert_array_equal(np.asarray(new.x), np.asarray(state.x))
    np.testing.assert_array_equal(np.asarray(new.y), np.asarray(state.y))
    assert bool(jnp.all(jnp.isfinite(obs2)))


def _batched_rollout(env: Any, params: Any, keys: Any, steps: int, params_axes: Any = None
                     ) -> Any:
    """gymnax's own reset/step (auto-reset included), vmapped over ``keys``, scanned; the
    action is the certainty-equivalent one-step prediction ``C A x̂ / c_max``."""
    def one(key: Any, params: Any) -> Any:
        k_reset, k_steps = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry: Any, key: Any) -> Any:
            obs, state = carry
            action = jnp.clip((params.nominal_A_d @ obs)[:1] / params.c_max, -1.0, 1.0)
            obs, state, reward, terminated, truncated, _ = env.step(key, state, action, params)
            return (obs, state), (obs, reward, terminated, truncated, state.filter_P)

        return jax.lax.scan(body, (obs, state), jax.random.split(k_steps, steps))[1]

    return jax.jit(jax.vmap(one, in_axes=(0, params_axes)))(keys, params)


def test_jit_and_vmap_over_eight_envs() -> None:
    env = jcarrier.CarrierMotion("kf")
    params = env.default_params
    keys = jax.random.split(jax.random.key(0), 8)
    obs, reward, terminated, truncated, P = _batched_rollout(env, params, keys, 120)
    assert obs.shape == (8, 120, 2) and obs.dtype == jnp.float64
    assert reward.shape == (8, 120) and P.shape == (8, 120, 2, 2)
    assert bool(jnp.all(jnp.isfinite(obs))) and bool(jnp.all(jnp.isfinite(P)))
    assert bool(jnp.all(reward <= 0.0)) and bool(jnp.all(reward >= -100.0))
    # predicting the deck does better than doing nothing (about -1 a step)
    assert float(jnp.mean(reward)) > -0.9
    assert not bool(jnp.any(terminated)) and not bool(jnp.any(truncated))
    # each row is the env run alone with its key (to round-off: XLA may group the 2x2
    # products of a batch of 8 differently from those of a batch of 1)
    one = _batched_rollout(env, params, keys[3:4], 120)
    np.testing.assert_allclose(np.asarray(one[0][0]), np.asarray(obs[3]), rtol=1e-12,
                               atol=1e-15)
    # different keys, different noise
    assert not np.array_equal(np.asarray(obs[0]), np.asarray(obs[1]))
    # the same keys, the same rollout, bit for bit
    again = _batched_rollout(jcarrier.CarrierMotion("kf"), jcarrier.carrier_motion_params(),
                             keys, 120)
    for a, b in zip((obs, reward, P), (again[0], again[1], again[4]), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("kind", ["true", "measurement"])
def test_the_other_kinds_run_under_jit_and_vmap(kind: str) -> None:
    env = jcarrier.CarrierMotion(kind)
    keys = jax.random.split(jax.random.key(1), 4)

    def one(key: Any) -> Any:
        obs, state = env.reset(key, env.default_params)
        obs, _, reward, _, _, _ = env.step(key, state, jnp.array([0.2]), env.default_params)
        return obs, reward

    obs, reward = jax.jit(jax.vmap(one))(keys)
    assert obs.shape == (4, 1 if kind == "measurement" else 2)
    assert bool(jnp.all(jnp.isfinite(obs))) and bool(jnp.all(jnp.isfinite(reward)))


def test_vmap_over_drawn_sea_matches_the_numpy_env_row_by_row() -> None:
    """A batch of true Δ22 and Δc (the paper's ranges), each sampled host-side and stacked
    into one params pytree, vmapped; each row is the numpy env built with those values, on
    the same noise."""
    draws = np.random.default_rng(7).uniform(-1.0, 1.0, (6, 2)) * [0.006, 0.1]
    actions = compensator_actions(150, 4)
    refs = [run_numpy("kf", actions, np.random.default_rng(100 + i), delta22=float(d22),
                      delta_c=float(dc)) for i, (d22, dc) in enumerate(draws)]
    assert all(len(ref["reward"]) == 150 for ref in refs)
    rows = [jcarrier.carrier_motion_params(delta22=float(d22), delta_c=float(dc))
            for d22, dc in draws]
    params = jax.tree.map(lambda *leaves: jnp.stack([jnp.asarray(v) for v in leaves]), *rows)
    env = jcarrier.CarrierMotion("kf")

    def one(params: Any, x0: Any, y0: Any, noise: Any) -> Any:
        _, state = env.reset_with_noise(jcarrier.CarrierMotionResetNoise(x0, y0), params)

        def body(state: Any, step: Any) -> Any:
            a, w = step
            obs, state, reward, _, _ = env.step_with_noise(state, a, w, params)
            return state, (obs, state.x, reward, state.filter_P)

        return jax.lax.scan(body, state, (jnp.asarray(actions), noise))[1]

    stack = lambda key: jnp.asarray(np.stack([ref[key] for ref in refs]))  # noqa: E731
    noise = jcarrier.CarrierMotionNoise(stack("process"), stack("measurement"))
    x0 = jnp.asarray(np.stack([ref["reset_noise"][0] for ref in refs]))
    y0 = jnp.asarray(np.stack([ref["reset_noise"][1] for ref in refs]))
    obs, x, reward, P = map(np.asarray, jax.jit(jax.vmap(one))(params, x0, y0, noise))
    for i, ref in enumerate(refs):
        assert relative_error(x[i], ref["state"][1:]) <= RTOL
        assert relative_error(obs[i], ref["obs"][1:]) <= RTOL
        assert relative_error(reward[i], ref["reward"]) <= RTOL
        assert relative_error(P[i], ref["P"][1:]) <= RTOL
    # the truth matters: the rows' trajectories differ
    assert not np.allclose(x[0], x[1])


def test_the_drawn_noise_follows_the_documented_splits() -> None:
    params = jcarrier.carrier_motion_params()
    key = jax.random.key(9)
    z = np.asarray(jax.random.normal(key, (3,), dtype=jnp.float64))
    plant = gym.make(ENV_ID).unwrapped
    noise = jcarrier.carrier_motion_noise(key, params)
    reset_noise = jcarrier.carrier_motion_reset_noise(key, params)
    # the increments are z @ Sᵀ with S the numpy plant's square roots
    np.testing.assert_allclose(np.asarray(noise.process), z[:2] @ plant._process_sqrt.T,
                               rtol=1e-14, atol=1e-18)
    np.testing.assert_allclose(np.asarray(reset_noise.initial), z[:2] @ plant._initial_sqrt.T,
                               rtol=1e-14, atol=1e-18)
    for got in (noise.measurement, reset_noise.measurement):
        np.testing.assert_allclose(np.asarray(got), np.sqrt(1.0 / 0.1) * z[2:], rtol=1e-15)
    # step_env is step_with_noise on that noise
    env = jcarrier.CarrierMotion("kf")
    _, state = env.reset_env(jax.random.key(1), params)
    a = jnp.array([0.2])
    by_key = env.step_env(key, state, a, params)
    by_noise = env.step_with_noise(state, a, noise, params)
    for u, v in zip(jax.tree.leaves(by_key), jax.tree.leaves(by_noise), strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))
    # reset_env is reset_with_noise on the reset's noise
    for u, v in zip(jax.tree.leaves(env.reset_env(key, params)),
                    jax.tree.leaves(env.reset_with_noise(reset_noise, params)), strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"sample_period": 0.0}, "sample_period"),
    ({"sample_period": float("nan")}, "sample_period"),
    ({"q": -0.1}, "q"),
    ({"v": 0.0}, "v"),
    ({"c_max": -1.0}, "c_max"),
    ({"a21": 0.1}, "a21"),
    ({"delta22": 0.1}, "delta22"),
    ({"delta_c": float("inf")}, "delta_c"),
    ({"noise_input": (1.0, 2.0, 3.0)}, "noise_input"),
    ({"initial_state": (1.0, 2.0, 3.0)}, "initial_state"),
    ({"initial_state_cov": "wide"}, "initial_state_cov"),
    ({"initial_state_cov": [[1.0, 0.0], [0.0, -1.0]]}, "initial_state_cov"),
    ({"max_episode_steps": 0}, "max_episode_steps"),
    ({"nominal": {"mu": 1.0}}, "nominal"),
    ({"nominal": {"v": -1.0}}, "nominal v"),
    ({"nominal": {"sample_period": "fast"}}, "nominal sample_period"),
    ({"nis_tail": 1.5}, "nis_tail"),
])
def test_params_validation_names_the_argument(kwargs: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        jcarrier.carrier_motion_params(**kwargs)


def test_float64_throughout() -> None:
    env = jcarrier.CarrierMotion("kf")
    obs, state = env.reset(jax.random.key(0), env.default_params)
    assert obs.dtype == jnp.float64 and state.filter_P.dtype == jnp.float64
    assert env.observation_space(env.default_params).shape == (2,)
    assert jcarrier.CarrierMotion("measurement").observation_space(
        env.default_params).shape == (1,)
    with pytest.raises(ValueError, match="kind"):
        jcarrier.CarrierMotion("ekf")
    with pytest.raises(ValueError, match="observation"):
        jcarrier.CarrierMotion("true", "estimate+covariance")


def test_x64_turned_off_later_is_refused() -> None:
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError, match="jax_enable_x64"):
            jcarrier.CarrierMotion("kf")
    finally:
        jax.config.update("jax_enable_x64", True)
