"""fir_gym.jax.pendulum_slider against the numpy PendulumSlider-v0 it mirrors (issue 28).

The oracle is the numpy env, ``gym.make("fir_gym/PendulumSlider-v0", ...)`` wrapped as each
observation kind is (``observation="true"``, the bare plant, ``estimator="ekf"``), its
generator replaced by one that serves given standard normals. Its plant is MuJoCo; the JAX
plant integrates the analytic equations of motion (the same ODE, friction law and RK4), so
the two plants cannot agree to 1e-9 bit for bit, and the tests split the claim:

* **given the same states** (the MuJoCo plant's, handed to
  :meth:`~fir_gym.jax.pendulum_slider.PendulumSlider.step_with_transition`, and the same
  measurement noise), whole episodes of every kind agree to 1e-9 relative: observations,
  rewards, terminated/truncated, and the EKF — mean, covariance, divergence flag, NIS — fed
  the same measurement sequence by the same code path;
* **the plant** (:meth:`~fir_gym.jax.pendulum_slider.PendulumSlider.step_with_noise`, the
  JAX RK4) is measured against the MuJoCo plant over whole episodes at the benchmark
  settings (``frame_skip=10``, 500 steps), the tolerance set from round-off propagation
  along the trajectory (:func:`roundoff_bound`), and against the numpy analytic equations
  (:class:`~fir_gym.envs.pendulum_slider_dynamics.PendulumSliderDynamics`, the numpy model's
  and native vector env's map) to 1e-9 with its Jacobian.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")
pytest.importorskip("mujoco")

import gymnasium as gym  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax_parity import QueuedNormals, flat, flat_jax, relative_error  # noqa: E402

import fir_gym  # noqa: E402, F401  (registers the ids)
from fir_gym.envs._base import _diagonal_of, psd_sqrt  # noqa: E402
from fir_gym.envs.pendulum_slider_dynamics import PendulumSliderDynamics  # noqa: E402
from fir_gym.jax import pendulum_slider as jps  # noqa: E402

RTOL = 1e-9
ENV_ID = "fir_gym/PendulumSlider-v0"
#: the benchmark settings
BENCH = {"frame_skip": 10, "max_episode_steps": 500}


def numpy_env(kind: str, observation: str = "estimate", max_episode_steps: int = 500,
              **kwargs: Any) -> gym.Env:
    """The numpy env of ``kind``; its plant's own ``max_episode_steps`` (the terminal
    penalty's horizon) set to the ``TimeLimit``'s, as fir-gym's tools set it."""
    if kind == "ekf":
        env = gym.make(ENV_ID, estimator="ekf", observation=observation,
                       max_episode_steps=max_episode_steps, **kwargs)
    elif kind == "true":
        env = gym.make(ENV_ID, observation="true", max_episode_steps=max_episode_steps,
                       **kwargs)
    else:
        env = gym.make(ENV_ID, max_episode_steps=max_episode_steps, **kwargs)
    env.unwrapped.max_episode_steps = max_episode_steps
    return env


def run_numpy(kind: str, actions: np.ndarray, rng: np.random.Generator,
              observation: str = "estimate", **kwargs: Any) -> dict[str, Any]:
    """An episode of the numpy (MuJoCo) env on the normals of ``rng``: what it returned,
    the noise increments it added (bit for bit as the plant forms them) and, for ``"ekf"``,
    the filter's covariance, NIS and divergence flag after each step."""
    env = numpy_env(kind, observation, **kwargs)
    plant = env.unwrapped
    normals = QueuedNormals()
    plant.np_random = normals                  # every draw of the plant comes from here
    z0, zy = rng.standard_normal(4), rng.standard_normal(4)
    normals.queue += [z0, zy]
    obs, info = env.reset()
    assert not normals.queue
    initial_sqrt, process_sqrt = psd_sqrt(plant.initial_state_cov), psd_sqrt(plant.params["Q"])
    meas_sqrt = psd_sqrt(plant.measurement_cov)
    diagonal = _diagonal_of(meas_sqrt)

    def measurement_noise(z: np.ndarray) -> np.ndarray:        # PlantEnv._measure's
        return z * diagonal if diagonal is not None else z @ meas_sqrt.T

    noisy = bool(np.any(process_sqrt))
    out: dict[str, Any] = {
        "reset_noise": (z0 @ initial_sqrt.T, measurement_noise(zy)),
        "process": [], "measurement": [], "action": [], "obs": [flat(obs)],
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
        zw, zv = rng.standard_normal(4), rng.standard_normal(4)
        normals.queue += [zw, zv] if noisy else [zv]
        obs, reward, terminated, truncated, info = env.step(a)
        assert not normals.queue, "a failed step: the test episodes avoid them"
        assert "simulation_failure" not in info
        out["process"].append(process_sqrt @ zw if noisy else np.zeros(4))  # the plant's S @ n
        out["measurement"].append(measurement_noise(zv))
        out["action"].append(info["action"])
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
            observation: str = "estimate", forced: bool = True) -> dict[str, np.ndarray]:
    """The JAX env on the numpy episode's noise: reset, then a scan of
    ``step_with_transition`` on the numpy plant's states (``forced``) or of
    ``step_with_noise`` (the JAX plant)."""
    env = jps.PendulumSlider(kind, observation)
    n = len(ref["reward"])
    x0, y0 = ref["reset_noise"]

    @jax.jit
    def rollout(actions: Any, states: Any, process: Any, measurement: Any) -> Any:
        obs0, state = env.reset_with_noise(
            jps.PendulumSliderResetNoise(jnp.asarray(x0), jnp.asarray(y0)), params)

        def body(state: Any, step: Any) -> Any:
            a, x_next, w, v = step
            if forced:
                obs, state, reward, terminated, info = env.step_with_transition(
                    state, a, x_next, v, params)
            else:
                obs, state, reward, terminated, info = env.step_with_noise(
                    state, a, jps.PendulumSliderNoise(w, v), params)
            return state, (flat_jax(obs), state.x, reward, terminated,
                           env.is_truncated(state, params), state.filter_x, state.filter_P,
                           state.diverged, state.nis, info["simulation_failure"])

        _, trace = jax.lax.scan(body, state, (actions, states, process, measurement))
        return (flat_jax(obs0), state), trace

    (obs0, s0), trace = rollout(jnp.asarray(actions[:n]), jnp.asarray(ref["state"][1:]),
                                jnp.asarray(ref["process"]), jnp.asarray(ref["measurement"]))
    obs, x, reward, terminated, truncated, fx, fP, diverged, nis, failure = map(np.asarray,
                                                                                 trace)
    assert not failure.any()
    return {"obs": np.concatenate([np.asarray(obs0)[None], obs]),
            "state": np.concatenate([np.asarray(s0.x)[None], x]), "reward": reward,
            "terminated": terminated, "truncated": truncated,
            "estimate": np.concatenate([np.asarray(s0.filter_x)[None], fx]),
            "P": np.concatenate([np.asarray(s0.filter_P)[None], fP]),
            "diverged": np.concatenate([[bool(s0.diverged)], diverged]),
            "nis": np.concatenate([[float(s0.nis)], nis])}


# ---------------------------------------------------------------------------- action sequences
def swing_actions(n: int, seed: int) -> np.ndarray:
    """Float32 forcing near the pendulum's resonance (≈ 1.1 Hz at 10 ms steps) with noise,
    some beyond ±1 (clipped)."""
    k = np.arange(n)
    a = 0.7 * np.sin(2 * np.pi * 1.1 * 0.01 * k) \
        + 0.3 * np.random.default_rng(seed).standard_normal(n)
    return a.astype(np.float32)[:, None]


def random_hold_actions(n: int, seed: int) -> np.ndarray:
    """Uniform actions held for 10 steps (100 ms)."""
    a = np.repeat(np.random.default_rng(seed).uniform(-1.0, 1.0, n // 10 + 1), 10)[:n]
    return a.astype(np.float32)[:, None]


def bang_bang_actions(n: int, hz: float = 1.0) -> np.ndarray:
    return np.sign(np.sin(2 * np.pi * hz * 0.01 * np.arange(n) + 0.1)).astype(
        np.float32)[:, None]


def pumping_actions(n: int) -> np.ndarray:
    """Full force along the slider's velocity, planned on the ODE from the swing start
    ``[x_rest, 0, 0.5, 0]``: it pumps the slider's oscillation until it leaves the rail
    (after about 220 steps of 10 ms)."""
    ode = PendulumSliderDynamics(dt=1e-2, substeps=10, input_scale=10.0)
    x = np.array([0.025 - 0.2 * (0.654 + 0.7925) * 9.8 / 200.0, 0.0, 0.5, 0.0])
    actions = np.zeros((n, 1), dtype=np.float32)
    for k in range(n):
        actions[k] = 1.0 if x[1] >= 0.0 else -1.0
        x = ode.propagate(x, actions[k].astype(np.float64), ode.theta)[0]
    return actions


NOISY = {"Q": np.diag([1e-8, 1e-6, 1e-6, 1e-4]),
         "initial_state_cov": np.diag([1e-5, 1e-4, 0.01, 0.04])}
CASES = {
    # the benchmark settings: the swing start, no process noise, the model's Q = 1e-6 I
    "benchmark": ({}, lambda n: swing_actions(n, 1)),
    # process noise and a random start in every state
    "noisy": (NOISY, lambda n: random_hold_actions(n, 2)),
    # the model believes other friction, damping and motor gain (a mismatch)
    "mismatch": ({"nominal": {"mu": 0.26, "M0": 0.14, "force_max": 9.0, "k": 95.0}},
                 lambda n: bang_bang_actions(n)),
    # no rail friction in the plant; the model's (weak) Coulomb law and its own R
    "coulomb_model": ({"friction": "none", "nominal": {"friction": "coulomb", "mu": 0.02,
                                                       "R": np.square([0.004, 0.03, 0.04, 0.3])}},
                      lambda n: swing_actions(n, 3)),
    # a model far off (a tenth of the rail spring, 5 ms steps for the 10 ms interval, a
    # quarter of R): the EKF's NIS stays high and the watch flags it
    "diverging": ({"nominal": {"k": 10.0, "frame_skip": 5,
                               "R": 0.25 * np.square(jps.PAPER_R_STD)}},
                  lambda n: bang_bang_actions(n, 1.9)),
    # pumped off the rail from a known start: termination and the terminal penalty
    "off_the_rail": ({"initial_state_cov": None}, lambda n: pumping_actions(n)),
}


def jax_params(**kwargs: Any) -> Any:
    return jps.pendulum_slider_params(**{**BENCH, **kwargs})


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("kind", ["true", "measurement", "ekf"])
def test_an_episode_on_the_mujoco_states_matches_the_numpy_env(kind: str, case: str) -> None:
    """Everything but the plant's transition, over whole episodes: handed the MuJoCo
    plant's new states and the measurement noise, the JAX env's observations, rewards,
    termination, truncation and EKF are the numpy env's to 1e-9."""
    kwargs, actions_of = CASES[case]
    actions = actions_of(500)
    ref = run_numpy(kind, actions, np.random.default_rng(28), **BENCH, **kwargs)
    got = run_jax(kind, actions, ref, jax_params(**kwargs))
    n = len(ref["reward"])
    if case == "off_the_rail":
        assert n < 500 and ref["terminated"][-1] and got["terminated"][-1]
        assert ref["reward"][-1] == -20.0 * (1 + 500 - n)    # -cost_cap (1 + steps left)
    else:
        assert n == 500 and ref["truncated"][-1] and not ref["terminated"].any()
    np.testing.assert_array_equal(got["terminated"], ref["terminated"])
    np.testing.assert_array_equal(got["truncated"], ref["truncated"])
    np.testing.assert_array_equal(got["state"], ref["state"])      # handed over
    errors = {key: relative_error(got[key], ref[key]) for key in ("obs", "reward")}
    if kind == "ekf":
        errors["estimate"] = relative_error(got["estimate"], ref["obs"])
        errors["P"] = relative_error(got["P"], ref["P"])
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
    actions = swing_actions(300, 8)
    ref = run_numpy("ekf", actions, np.random.default_rng(3), observation=observation, **BENCH)
    got = run_jax("ekf", actions, ref, jax_params(), observation=observation)
    assert got["obs"].shape == ref["obs"].shape == (301, 14 if "covariance" in observation
                                                    else 8)
    error = relative_error(got["obs"], ref["obs"])
    print(f"ekf/{observation}: max relative error of the observation {error:.2e}")
    assert error <= RTOL
    space = jps.PendulumSlider("ekf", observation).observation_space(jax_params())
    assert sorted(space.spaces) == sorted(("estimate", observation.split("+")[1]))


# ---------------------------------------------------------------------------- the plant
def step_jacobians(states: np.ndarray, actions: np.ndarray, params: Any) -> np.ndarray:
    """The JAX env step's Jacobian ``∂x_{k+1}/∂x_k`` along a trajectory (the plant's ODE)."""
    p = jps._physics(params, nominal=False)

    def one(x: Any, a: Any) -> Any:
        return jps.slider_interval_and_jacobian(x, a[0] * params.force_max, p, params.friction,
                                                params.frame_skip)[1]

    return np.asarray(jax.jit(jax.vmap(one))(jnp.asarray(states), jnp.asarray(actions)))


def roundoff_bound(states: np.ndarray, actions: np.ndarray, params: Any) -> np.ndarray:
    """How far two float64 RK4 integrations of the same ODE may drift apart by round-off,
    per step and component (the tolerance of the plant-agreement test, from the physics).

    Each RK4 step ends ``z + (h/6)(k1 + 2k2 + 2k3 + k4)``: its final rounding moves each
    component by up to ½ ulp, ``ε/2 |z_i|`` (ε = 2⁻⁵²), in each of the two integrators, and
    the increment's own rounding is smaller by ``h ω`` ≈ 0.01 (ω ≈ 12 rad/s, the slider's
    spring): one ``ε · s_i`` per RK4 step and component, ``s_i`` the component's range over
    the episode. A rounding made at env step ``j`` reaches step ``k`` through the
    trajectory's own state-transition matrix ``Φ(k, j) = F_{k−1} ⋯ F_j`` (the exact
    Jacobians of the env step), so, in units of the ranges ``D = diag(s)``, the difference
    at step ``k`` is at most ``frame_skip · ε · Σ_{j<k} ‖D⁻¹ Φ(k, j+1) D‖_∞ · s`` — the
    worst case, every rounding adding up: returned as ``(n + 1, 4)``."""
    n = len(actions)
    scale = np.max(np.abs(states), axis=0)
    D = np.diag(scale)
    Dinv = np.diag(1.0 / scale)
    F = Dinv @ step_jacobians(states[:n], actions, params) @ D      # scaled step maps
    per_step = params.frame_skip * np.finfo(np.float64).eps
    bound = np.zeros((n + 1, 4))
    carried = np.zeros((0, 4, 4))                  # Φ(k, j+1) for j < k, scaled
    for k in range(n):
        carried = np.concatenate([F[k] @ carried, np.eye(4)[None]]) if k else np.eye(4)[None]
        gain = np.abs(carried).sum(axis=2).max(axis=1).sum()        # Σ_j ‖·‖_∞
        bound[k + 1] = per_step * gain * scale
    return bound


PLANT_RUNS = {
    "free swing": ({}, lambda n: np.zeros((n, 1), dtype=np.float32)),
    "resonant": ({}, lambda n: swing_actions(n, 11)),
    "random holds": ({}, lambda n: random_hold_actions(n, 12)),
    "bang-bang": ({}, lambda n: bang_bang_actions(n)),
    "noisy, no friction": ({**NOISY, "friction": "none"}, lambda n: random_hold_actions(n, 13)),
}


@pytest.mark.parametrize("run", sorted(PLANT_RUNS))
def test_the_jax_plant_agrees_with_the_mujoco_plant(run: str) -> None:
    """The measured agreement of the JAX plant (the analytic ODE's RK4) with MuJoCo's over
    whole episodes at the benchmark settings, on the same action and noise sequences:
    within the round-off bound of :func:`roundoff_bound` at every step."""
    kwargs, actions_of = PLANT_RUNS[run]
    actions = actions_of(500)
    ref = run_numpy("true", actions, np.random.default_rng(5), **BENCH, **kwargs)
    params = jax_params(**kwargs)
    got = run_jax("true", actions, ref, params, forced=False)
    n = len(ref["reward"])
    assert n == 500 and ref["truncated"][-1]
    diff = np.abs(got["state"] - ref["state"])
    scale = np.max(np.abs(ref["state"]), axis=0)
    bound = roundoff_bound(ref["state"], ref["action"], params)
    print(f"plant/{run}: max |Δ| per state {np.array2string(diff.max(0), precision=2)}, "
          f"max |Δ|/range {np.max(diff / scale):.2e}, bound/range at the end "
          f"{np.max(bound[-1] / scale):.2e}, smallest bound/|Δ| "
          f"{np.min(bound[diff > 0] / diff[diff > 0]):.1f}, reward max relative error "
          f"{relative_error(got['reward'], ref['reward']):.2e}")
    assert np.all(diff <= bound), np.argwhere(diff > bound)[:5]
    np.testing.assert_array_equal(got["terminated"], ref["terminated"])


def test_the_fused_plant_and_model_loop_is_the_two_loops() -> None:
    """``step_with_noise`` of the ``"ekf"`` kind runs the plant's and the model's RK4 in one
    loop; handing the states it produced to ``step_with_transition`` (the model's own loop)
    gives the same filter, to round-off."""
    actions = swing_actions(300, 31)
    ref = run_numpy("ekf", actions, np.random.default_rng(4), **BENCH, **NOISY)
    params = jax_params(**NOISY)
    fused = run_jax("ekf", actions, ref, params, forced=False)
    replay = {**ref, "state": fused["state"]}
    apart = run_jax("ekf", actions, replay, params)
    np.testing.assert_array_equal(apart["state"], fused["state"])
    for key in ("estimate", "P", "reward"):
        assert relative_error(apart[key], fused[key]) <= 1e-12, key
    # and, on the JAX plant's states, the filter is still the numpy one's to 1e-9
    errors = {key: relative_error(fused[key], want) for key, want in
              (("estimate", ref["obs"]), ("P", ref["P"]))}
    print(f"ekf on the JAX plant: max relative errors {errors}")
    assert max(errors.values()) <= RTOL


def test_the_jax_plant_is_the_numpy_analytic_equations_to_1e_9() -> None:
    """The JAX interval map and its Jacobian against
    :meth:`PendulumSliderDynamics.propagate` (the numpy model's and the native vector env's
    map) at the states of an episode, for the plant's and a mismatched model's parameters."""
    actions = swing_actions(500, 21)
    ref = run_numpy("true", actions, np.random.default_rng(9), **BENCH, **NOISY)
    states, applied = ref["state"][:-1], ref["action"]
    for nominal in ({}, {"mu": 0.26, "M0": 0.14, "force_max": 9.0, "friction": "coulomb"}):
        params = jax_params(**NOISY, nominal=nominal)
        numpy_model = PendulumSliderDynamics(
            **{name: getattr(params, f"nominal_{name}") for name in jps.PHYSICAL},
            dt=1e-3 * params.nominal_frame_skip, substeps=params.nominal_frame_skip,
            friction=params.nominal_friction, input_scale=params.nominal_force_max)
        want, want_F, _ = numpy_model.propagate(states, applied, numpy_model.theta,
                                                jacobian=True)
        f_and_F = jax.jit(jax.vmap(jps.ekf_model(params)))
        got, got_F = map(np.asarray, f_and_F(jnp.asarray(states), jnp.asarray(applied)))
        errors = relative_error(got, want), relative_error(got_F, want_F)
        print(f"model {nominal or 'nominal'}: f {errors[0]:.2e}, F {errors[1]:.2e}")
        assert max(errors) <= RTOL


# ---------------------------------------------------------------------------- gymnax API
def _batched_rollout(env: Any, params: Any, keys: Any, steps: int) -> Any:
    """gymnax's own reset/step (auto-reset included), vmapped over ``keys``, scanned."""
    def one(key: Any) -> Any:
        k_reset, k_steps = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry: Any, key: Any) -> Any:
            obs, state = carry
            # damp the swing: push against the pendulum's angular velocity estimate
            action = jnp.clip(0.2 * obs[3], -1.0, 1.0)[None]
            obs, state, reward, terminated, truncated, _ = env.step(key, state, action, params)
            return (obs, state), (obs, reward, terminated, truncated, state.filter_P)

        return jax.lax.scan(body, (obs, state), jax.random.split(k_steps, steps))[1]

    return jax.jit(jax.vmap(one))(keys)


def test_jit_and_vmap_over_eight_envs() -> None:
    env = jps.PendulumSlider("ekf")
    params = jax_params(max_episode_steps=100)
    keys = jax.random.split(jax.random.key(0), 8)
    obs, reward, terminated, truncated, P = _batched_rollout(env, params, keys, 120)
    assert obs.shape == (8, 120, 4) and obs.dtype == jnp.float64
    assert reward.shape == (8, 120) and P.shape == (8, 120, 4, 4)
    assert bool(jnp.all(jnp.isfinite(obs))) and bool(jnp.all(jnp.isfinite(P)))
    assert bool(jnp.all(reward <= 0.0)) and bool(jnp.all(reward >= -20.0))  # cost_cap
    assert not bool(jnp.any(terminated))
    # the time limit of 100 steps truncates (and gymnax auto-resets) every env once
    np.testing.assert_array_equal(np.asarray(truncated).sum(axis=1), 1)
    # each row is the env run alone with its key (to round-off: XLA compiles a batch of
    # one to other kernels); different keys, different noise
    one = _batched_rollout(env, params, keys[3:4], 120)
    np.testing.assert_allclose(np.asarray(one[0][0]), np.asarray(obs[3]), rtol=1e-12,
                               atol=1e-15)
    assert not np.array_equal(np.asarray(obs[0]), np.asarray(obs[1]))


def test_vmap_over_drawn_parameters_matches_the_numpy_env_row_by_row() -> None:
    """A batch of true friction μ and hinge damping M0 (what paper 003 identifies) drawn
    around the model's, the parameter pytrees of the rows stacked and vmapped; each row is
    the numpy env built with its draw, on the same noise: its MuJoCo plant within the
    round-off bound, its EKF to 1e-9."""
    draws = np.random.default_rng(7).uniform(0.6, 1.4, (4, 2)) * 0.2
    rows = [{**NOISY, "mu": float(mu), "M0": float(M0), "nominal": {"mu": 0.2, "M0": 0.2}}
            for mu, M0 in draws]
    actions = swing_actions(200, 41)
    refs = [run_numpy("ekf", actions, np.random.default_rng(200 + i), **BENCH, **row)
            for i, row in enumerate(rows)]
    assert all(len(ref["reward"]) == 200 for ref in refs)
    row_params = [jax_params(**row) for row in rows]
    params = jax.tree.map(lambda *leaves: jnp.stack([jnp.asarray(v) for v in leaves]),
                          *row_params)
    env = jps.PendulumSlider("ekf")

    def one(params: Any, x0: Any, y0: Any, process: Any, measurement: Any) -> Any:
        _, state = env.reset_with_noise(jps.PendulumSliderResetNoise(x0, y0), params)

        def body(state: Any, step: Any) -> Any:
            a, w, v = step
            _, state, _, _, _ = env.step_with_noise(state, a, jps.PendulumSliderNoise(w, v),
                                                    params)
            return state, (state.x, state.filter_x, state.filter_P)

        return jax.lax.scan(body, state, (jnp.asarray(actions), process, measurement))[1]

    def stack(key: str) -> Any:
        return jnp.asarray(np.stack([ref[key] for ref in refs]))

    x0, y0 = (jnp.asarray(np.stack([ref["reset_noise"][i] for ref in refs])) for i in (0, 1))
    x, fx, fP = map(np.asarray, jax.jit(jax.vmap(one))(params, x0, y0, stack("process"),
                                                          stack("measurement")))
    for i, ref in enumerate(refs):
        bound = roundoff_bound(ref["state"], ref["action"], row_params[i])
        assert np.all(np.abs(x[i] - ref["state"][1:]) <= bound[1:])
        assert relative_error(fx[i], ref["obs"][1:]) <= RTOL
        assert relative_error(fP[i], ref["P"][1:]) <= RTOL
    # the draws matter: the rows' trajectories differ
    assert not np.allclose(x[0], x[1])


def test_the_drawn_noise_follows_the_documented_splits() -> None:
    params = jax_params(**NOISY)
    key = jax.random.key(9)
    noise = jps.pendulum_slider_noise(key, params)
    reset_noise = jps.pendulum_slider_reset_noise(key, params)
    z = np.asarray(jax.random.normal(key, (8,), dtype=jnp.float64))
    # S z with S the plant's square root (psd_sqrt: V Λ^½ from eigh — for a diagonal matrix
    # a signed permutation of its diagonal's roots, hence the |·|)
    for got, cov, part in ((noise.process, NOISY["Q"], z[:4]),
                           (reset_noise.initial, NOISY["initial_state_cov"], z[:4]),
                           (noise.measurement, np.diag(np.square(jps.PAPER_R_STD)), z[4:]),
                           (reset_noise.measurement, np.diag(np.square(jps.PAPER_R_STD)), z[4:])):
        np.testing.assert_allclose(np.abs(np.asarray(got)), np.abs(psd_sqrt(cov) @ part),
                                   rtol=1e-15)
    env = jps.PendulumSlider("ekf")
    _, state = env.reset_env(jax.random.key(1), params)
    a = jnp.array([0.2])
    by_key = env.step_env(key, state, a, params)
    by_noise = env.step_with_noise(state, a, noise, params)
    for u, v in zip(jax.tree.leaves(by_key), jax.tree.leaves(by_noise), strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))


def test_the_params_are_the_numpy_envs() -> None:
    """``pendulum_slider_params`` reads the numpy env's keywords as the env does."""
    kwargs = {"frame_skip": 4, "friction": "none", "M0": 0.3, "Q": np.full(4, 1e-7),
              "nominal": {"mu": 0.3, "R": np.ones(4) * 1e-4}}
    plant = gym.make(ENV_ID, **kwargs).unwrapped
    params = jps.pendulum_slider_params(**kwargs)
    assert params.x_rest == plant.x_rest and params.frame_skip == 4
    np.testing.assert_array_equal(np.asarray(params.initial_state), plant.initial_state)
    np.testing.assert_array_equal(np.asarray(params.initial_state_cov), plant.initial_state_cov)
    np.testing.assert_array_equal(np.asarray(params.R), plant.measurement_cov)
    np.testing.assert_array_equal(np.asarray(params.Q), plant.params["Q"])
    np.testing.assert_array_equal(np.asarray(params.nominal_Q), plant.model.GQGT)
    np.testing.assert_array_equal(np.asarray(params.nominal_R), plant.model.R)
    assert jps.BRACKET_CAP * jps._reward_scale(params) == plant.cost_cap
    assert params.nominal_mu == 0.3 and params.mu == 0.2 and params.M0 == 0.3
    default = jps.PendulumSlider().default_params
    assert default.frame_skip == 1 and default.max_steps_in_episode == 5000


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"frame_skip": 0}, "frame_skip"),
    ({"frame_skip": 2.5}, "frame_skip"),
    ({"force_max": -1.0}, "force_max"),
    ({"m1": 0.0}, "m1"),
    ({"mu": -0.1}, "mu"),
    ({"M0": float("nan")}, "M0"),
    ({"R": np.diag([1.0, 1.0, 1.0, 0.0])}, "R"),
    ({"Q": -np.eye(4)}, "Q"),
    ({"friction": "coulomb"}, "friction"),
    ({"friction": "sticky"}, "friction"),
    ({"dynamics": "printed-eq5"}, "dynamics"),
    ({"initial_state": (0.0, 0.0, 0.5)}, "initial_state"),
    ({"initial_state_cov": "wide"}, "initial_state_cov"),
    ({"initial_state_cov": np.ones((3, 3))}, "initial_state_cov"),
    ({"max_episode_steps": 0}, "max_episode_steps"),
    ({"nominal": {"x_rest": 0.0}}, "nominal"),
    ({"nominal": {"k": -1.0}}, "nominal k"),
    ({"nominal": {"dynamics": "printed-eq15"}}, "nominal dynamics"),
    ({"nominal": {"frame_skip": 0}}, "nominal frame_skip"),
    ({"nis_tail": 0.0}, "nis_tail"),
])
def test_bad_params_are_refused_naming_the_argument(kwargs: dict[str, Any], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        jps.pendulum_slider_params(**kwargs)


def test_unknown_keywords_and_kinds_are_refused() -> None:
    with pytest.raises(TypeError, match="mass"):
        jps.pendulum_slider_params(mass=1.0)
    with pytest.raises(ValueError, match="kind"):
        jps.PendulumSlider("fir")
    with pytest.raises(ValueError, match="observation"):
        jps.PendulumSlider("true", "estimate+covariance")


def test_a_nan_action_is_a_simulation_failure() -> None:
    env = jps.PendulumSlider("ekf")
    params = jax_params()
    _, state = env.reset(jax.random.key(2), params)
    obs2, state2, reward, terminated, info = env.step_with_noise(
        state, jnp.array([jnp.nan]), jps.PendulumSliderNoise(jnp.zeros(4), jnp.zeros(4)),
        params)
    assert bool(terminated) and int(info["simulation_failure"]) == 1
    np.testing.assert_array_equal(np.asarray(state2.x), np.asarray(state.x))
    assert float(reward) == -20.0 * 500       # -cost_cap (1 + 499 steps left)
    assert bool(jnp.all(jnp.isfinite(obs2)))


def test_x64_turned_off_later_is_refused() -> None:
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError, match="jax_enable_x64"):
            jps.PendulumSlider("ekf")
    finally:
        jax.config.update("jax_enable_x64", True)
