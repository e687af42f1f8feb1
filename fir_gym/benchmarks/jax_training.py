"""Speed of the JAX backend against the numpy one (``fir-gym speed training``).

Three ratios, each of env-steps per second measured in the same run as its reference:

* **PPO**: rejax's PPO on :class:`fir_gym.jax.orbit.Orbit` observing its EKF, the shipped
  recipe (``ppo.yml``: 16 envs × 256 steps, 4 minibatches, 10 epochs, normalisation), the
  training iterations as one jitted program timed after compilation (steady state: the
  faster of two runs on fresh keys), against stable-baselines3's PPO on the numpy
  Orbit-v0 with its batched EKF (:func:`fir_gym.training.make_sb3_vec_env`, torch at one
  thread, as ``fir-gym train`` runs it) — target ≥ 6;
* **recurrent** (no target): the ``recurrent`` kind's training, JAX's RecurrentPPO
  (:mod:`fir_gym.jax.recurrent_ppo`) against sb3-contrib's, both at ``ppo_lstm.yml`` on the
  raw measurement of Orbit-v0;
* **stepping**: the JAX Orbit-v0 + EKF, 2048 envs stepped as a batch with the resets
  computed only where an episode ended (:func:`fir_gym.jax.batch_step.batch_step`; gymnax's
  auto-resetting ``step`` vmapped — the same numbers — is reported beside it) and scanned over
  the steps (a proportional policy on the estimate), against the
  native numpy vector env with :class:`~fir_gym.wrappers.VectorEstimatorObservation`
  (``"ekf"``) running the same policy at its best batch size among 256, 1024 and 4096 (it,
  too, resets only the envs whose episode ended) —
  target ≥ 2. The JAX envs are sharded across one CPU device per core
  (:func:`fir_gym.cpu_devices.request_cpu_devices`: XLA runs each device's part on its own
  thread, where one device steps the whole batch on one core), as JAX would spread them
  over a GPU's cores; the numpy vector env is one process (numpy's array operations run on
  one core). The
  one-device figure is reported beside it: the ratio per core. The same JAX env stepped
  with the noise given (``step_with_noise``, no key draws, no auto-reset; on the same
  devices) is the floor: the plant and the filter alone. The same ratio is
  measured again **under the conditions** the learned benchmarks train in (:data:`CONDITIONS`:
  every randomizable parameter drawn at each reset with spread 0.1, and the sensor losing 30 %
  of the readings — the EKF predicting through them): on both sides the draws, the held
  readings and the filter's missing-reading path are in the step.

The PPO ratio's floor is PPO's own cost in JAX: the same program on :func:`free_env`, an
environment whose step costs nothing — ``free / SB3`` is the best ratio any JAX plant could
reach at this recipe on this machine.

The functions are also the measurements of ``scripts/jax_stepping_speed.py`` and
``scripts/jax_training_speed.py``, which take more options.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np

from fir_gym.cpu_devices import request_cpu_devices

ENV_ID, KIND = "fir_gym/Orbit-v0", "ekf"
#: the proportional policy both stepping measurements run: hover thrust + gain (8 − r̂)
HOVER, GAIN, R_REF = 0.311, 0.5, 8.0
#: what a JAX step is: :func:`fir_gym.jax.batch_step.batch_step` (``"batch_step"``: the
#: batch stepped, the resets computed only where an episode ended — what the target row
#: measures), gymnax's ``step`` vmapped (``"step"``: every env's reset computed at every step,
#: a select keeps it where the episode ended; the same numbers), ``step_env`` (noise drawn,
#: no auto-reset) or ``step_with_noise`` (zero noise given)
MODES = ("batch_step", "step", "step_env", "step_with_noise")
#: the modes that auto-reset (the conditions' draws happen at the resets)
AUTO_RESET = ("batch_step", "step")
JAX_ENVS = 2048
NUMPY_BATCHES = (256, 1024, 4096)
#: the conditions of the second stepping ratio: the robustness benchmark's dr-mismatch and
#: dr-dropout regimes at once (the plant's ``randomize``, the sensor's ``dropout``)
CONDITIONS: dict[str, Any] = {"randomize": {"mu": 0.1, "thrust_max": 0.1},
                              "sensor_faults": {"dropout": 0.3}}


def policy(obs: np.ndarray) -> np.ndarray:
    """The numpy env's actions from its estimates ``(B, 2)`` (float32, as a policy's)."""
    return np.clip(HOVER - GAIN * (obs[:, :1] - R_REF), -1.0, 1.0).astype(np.float32)


def stepping_program(n_envs: int, steps: int, prng: str = "threefry2x32",
                     mode: str = "batch_step",
                     conditions: bool = False, devices: int = 1
                     ) -> tuple[Any, Any]:
    """``(run, keys)``: the jitted closed loop of :func:`jax_stepping_rate` — ``run(keys(i))``
    steps ``n_envs`` Orbit-v0 + EKF envs ``steps`` times from the keys of seed ``i`` and
    returns each env's last estimate and summed reward. ``devices > 1`` shards the envs
    evenly across the first ``devices`` devices of JAX's default backend (a GPU's where there
    is one; on a CPU, one device per core: :func:`request_cpu_devices`; under
    ``"batch_step"`` each device steps its envs as a batch of its own); each env's numbers
    depend neither on it nor on the mode among :data:`AUTO_RESET` (one env's keys and
    arithmetic are the same)."""
    import jax
    import jax.numpy as jnp

    from fir_gym.jax import make
    from fir_gym.jax.batch_step import batch_step
    from fir_gym.jax.orbit import OrbitNoise

    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}; got {mode!r}")
    if conditions and mode not in AUTO_RESET:
        raise ValueError(f"conditions are drawn at the resets: mode must be one of "
                         f"{AUTO_RESET}; got {mode!r}")
    available = jax.devices()              # the default backend's: a GPU's where there is one
    if not 1 <= devices <= len(available) or n_envs % devices:
        raise ValueError(f"devices must be between 1 and the {len(available)} "
                         f"{available[0].platform.upper()} device(s) JAX has "
                         f"(request_cpu_devices on a CPU) and divide n_envs = {n_envs}; got "
                         f"{devices!r}")
    env, params = make(ENV_ID, "ekf", **(CONDITIONS if conditions else {}))
    zero = OrbitNoise(jnp.zeros(2), jnp.zeros(1))

    def act(obs: Any) -> Any:
        return jnp.clip(HOVER - GAIN * (obs[..., :1] - R_REF), -1.0, 1.0)

    def batch(keys: Any) -> Any:
        """The envs of ``keys`` stepped as one batch (:func:`batch_step`), each from the same
        keys as :func:`one` gives it."""
        split = jax.vmap(jax.random.split)(keys)
        obs, state = jax.vmap(env.reset, in_axes=(0, None))(split[:, 0], params)
        step_keys = jax.vmap(lambda k: jax.random.split(k, steps))(split[:, 1])

        def body(carry: Any, keys: Any) -> Any:
            obs, state = carry
            obs, state, reward, _, _, _ = batch_step(env, keys, state, act(obs), params)
            return (obs, state), reward

        (obs, _), rewards = jax.lax.scan(body, (obs, state), jnp.swapaxes(step_keys, 0, 1))
        return obs, rewards.sum(axis=0)

    def one(key: Any) -> Any:
        k_reset, k_steps = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry: Any, key: Any) -> Any:
            obs, state = carry
            action = act(obs)
            if mode == "step":
                obs, state, reward, _, _, _ = env.step(key, state, action, params)
            elif mode == "step_env":
                obs, state, reward, _, _ = env.step_env(key, state, action, params)
            else:
                obs, state, reward, _, _ = env.step_with_noise(state, action, zero, params)
            return (obs, state), reward

        (obs, _), rewards = jax.lax.scan(body, (obs, state), jax.random.split(k_steps, steps))
        return obs, rewards.sum()                  # the estimate (the kind's observation)

    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    # (over one device, the plain placement: nothing is partitioned; the batch step runs per
    # device without shard_map's varying-axes check, which the envs' loops from constants fail)
    mesh = Mesh(np.array(available[:devices]), ("envs",))
    envs = NamedSharding(mesh, PartitionSpec("envs"))
    program = (jax.shard_map(batch, mesh=mesh, in_specs=PartitionSpec("envs"),
                             out_specs=PartitionSpec("envs"), check_vma=False)
               if mode == "batch_step"
               else jax.vmap(one))
    run = jax.jit(program, in_shardings=envs, out_shardings=envs)

    def keys(seed: int) -> Any:
        return jax.device_put(jax.random.split(jax.random.key(seed, impl=prng), n_envs), envs)

    return run, keys


def jax_stepping_rate(n_envs: int, steps: int, reps: int, prng: str = "threefry2x32",
                      mode: str = "batch_step", conditions: bool = False, devices: int = 1
                      ) -> tuple[float, float]:
    """(env-steps/s of the jitted, vmapped Orbit+EKF env — best of ``reps`` —, compile
    seconds); ``prng`` is the keys' implementation, ``mode`` one of :data:`MODES`,
    ``conditions`` the env under :data:`CONDITIONS` (modes :data:`AUTO_RESET`), ``devices`` the
    CPU devices the envs are sharded across (:func:`stepping_program`)."""
    import jax

    run, keys = stepping_program(n_envs, steps, prng, mode, conditions, devices)
    first = keys(0)
    start = time.perf_counter()
    jax.block_until_ready(run(first))
    compile_s = time.perf_counter() - start
    best = np.inf
    for rep in range(reps):
        given = keys(rep + 1)
        start = time.perf_counter()
        jax.block_until_ready(run(given))
        best = min(best, time.perf_counter() - start)
    return n_envs * steps / best, compile_s


def numpy_stepping_rate(n_envs: int, steps: int, reps: int, conditions: bool = False
                        ) -> float:
    """Env-steps/s of the native vector env with the batched EKF (best of ``reps``);
    ``conditions``: under :data:`CONDITIONS` (the plant's ``randomize``, a
    :class:`~fir_gym.wrappers.VectorSensorFaults`)."""
    import gymnasium as gym

    from fir_gym.wrappers import VectorEstimatorObservation, VectorSensorFaults

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        venv: Any = gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode="vector_entry_point",
                                 **({"randomize": CONDITIONS["randomize"]} if conditions else {}))
        if conditions:
            venv = VectorSensorFaults(venv, **CONDITIONS["sensor_faults"])
        env = VectorEstimatorObservation(venv, "ekf")
        obs, _ = env.reset(seed=0)
        for _ in range(3):                                   # warm up (numba, caches)
            obs = env.step(policy(obs))[0]
        best = np.inf
        for _ in range(reps):
            start = time.perf_counter()
            for _ in range(steps):
                obs = env.step(policy(obs))[0]
            best = min(best, time.perf_counter() - start)
        env.close()
    return n_envs * steps / best


def jax_ppo_rate(steps: int, seeds: int = 1, cache: str | None = None, free: bool = False,
                 n_envs: int | None = None, kind: str = KIND,
                 network_dtype: str = "float32") -> dict[str, Any]:
    """``{"steps", "seconds", "compile_seconds", "rate"}`` of JAX PPO (``seeds`` vmapped):
    the training iterations of ``steps`` as one program, the faster of two timed runs;
    ``free``: on :func:`free_env` instead of Orbit-v0 (PPO's own cost); ``n_envs``: the
    recipe's 16 envs replaced (the rollout grows with it, the minibatch size stays);
    ``kind``: what the policy observes (``"recurrent"``: RecurrentPPO's recipe and LSTM
    policy on the measurement); ``network_dtype``: the networks' arithmetic (the shipped
    float32, or float64: :mod:`fir_gym.jax.train`)."""
    import jax

    from fir_gym.jax import train as jt

    if cache:
        jt.enable_compilation_cache(cache)
    rec = jt.recipe(ENV_ID, steps=steps, n_envs=n_envs, kind=kind,
                    network_dtype=network_dtype)
    if free:
        env = free_env()
        params = env.default_params
    else:
        env, params = jt.make_env(ENV_ID, kind)
    algo = jt.make_algorithm(env, params, rec)

    def one(ts: Any) -> Any:
        ts = jax.lax.fori_loop(0, rec.iterations, lambda _, ts: algo.train_iteration(ts), ts)
        return ts.actor_ts.params

    program = jax.jit(jt.over_seeds(one))
    # the initial states outside the program, as fir_gym.jax.train.train does (its QR
    # factorisations, batched inside a program, can deadlock XLA's CPU pool)
    # (one call for the three runs: each call's states are of a class of their own)
    states = jt.initial_states(algo, [1000 * r + s for r in range(3) for s in range(seeds)])
    keys = [jax.tree.map(lambda x, r=r: x[r * seeds:(r + 1) * seeds], states)
            for r in range(3)]
    start = time.perf_counter()
    compiled = program.lower(keys[0]).compile()
    compile_seconds = time.perf_counter() - start
    best = float("inf")
    for key in keys[1:]:
        start = time.perf_counter()
        jax.block_until_ready(compiled(key))
        best = min(best, time.perf_counter() - start)
    trained = rec.iterations * rec.rollout * seeds
    return {"steps": trained, "seconds": best, "compile_seconds": compile_seconds,
            "rate": trained / best}


def free_env() -> Any:
    """A gymnax environment whose step costs (almost) nothing, with Orbit's spaces (two
    observations, one action in ``[-1, 1]``, 1000-step episodes): PPO's own cost per sample
    in JAX, the floor of the PPO ratio."""
    import gymnax.environments.environment as gymnax_env
    import jax.numpy as jnp
    from flax import struct
    from gymnax.environments import spaces

    @struct.dataclass
    class State(gymnax_env.EnvState):
        time: Any

    class Free(gymnax_env.Environment[Any, gymnax_env.EnvParams]):
        @property
        def default_params(self) -> gymnax_env.EnvParams:
            return gymnax_env.EnvParams(max_steps_in_episode=1000)

        def reset_env(self, key: Any, params: Any) -> Any:
            return jnp.zeros(2), State(time=jnp.asarray(0))

        def step_env(self, key: Any, state: Any, action: Any, params: Any) -> Any:
            new = State(time=state.time + 1)
            return jnp.zeros(2) + action[0], new, -jnp.abs(action[0]), jnp.asarray(False), {}

        def is_terminated(self, state: Any, params: Any) -> Any:
            return jnp.asarray(False)

        def observation_space(self, params: Any) -> Any:
            return spaces.Box(-jnp.inf, jnp.inf, (2,), jnp.float64)

        def action_space(self, params: Any = None) -> Any:
            return spaces.Box(-1.0, 1.0, (1,), jnp.float32)

    return Free()


def sb3_ppo_rate(steps: int, kind: str = KIND) -> dict[str, Any]:
    """``{"steps", "seconds", "setup_seconds", "rate"}`` of stable-baselines3's PPO on the
    numpy Orbit-v0 with its batched EKF (one warm-up rollout first, not timed); ``kind``
    ``"recurrent"``: sb3-contrib's RecurrentPPO on the measurement, as ``fir-gym train``
    trains it."""
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    from fir_gym.training.run import RunConfig, algorithm_class, build_training_env

    torch.set_num_threads(1)
    start = time.perf_counter()
    config = RunConfig(ENV_ID, kind, steps=steps)
    settings = config.settings()
    venv = build_training_env(config, 0, None, settings["n_envs"])
    venv = VecNormalize(venv, gamma=settings["algo_kwargs"].get("gamma", 0.99),
                        **settings["normalize"])
    model = algorithm_class(config)(settings["policy"], venv, seed=0, device="cpu",
                                    verbose=0, **settings["algo_kwargs"])
    rollout = model.n_steps * model.n_envs
    model.learn(rollout)                                  # set-up and one warm-up rollout
    setup = time.perf_counter() - start
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    seconds = time.perf_counter() - start
    trained = model.num_timesteps - rollout
    venv.close()
    return {"steps": trained, "seconds": seconds, "setup_seconds": setup,
            "rate": trained / seconds}


def run(quick: bool = False) -> dict[str, Any]:
    """Both ratios and the floor (needs the ``jax`` and ``rl`` extras); ``{"skipped":
    reason}`` without them."""
    from fir_gym.machine import cores

    try:
        import jax
    except ImportError as err:
        return {"skipped": f"needs the jax and rl extras ({err.name} is missing)"}
    # one CPU device per core, asked for before gymnax's import starts JAX's backends (in a
    # process where they have started, what they have: then the stepping uses one device)
    devices = request_cpu_devices(cores())
    try:
        import gymnax  # noqa: F401
        import rejax  # noqa: F401
        import stable_baselines3  # noqa: F401
    except ImportError as err:
        return {"skipped": f"needs the jax and rl extras ({err.name} is missing)"}
    warnings.filterwarnings("ignore", module="rejax")
    ppo_steps = 16_384 if quick else 65_536
    sb3 = sb3_ppo_rate(ppo_steps)
    jax_ppo = jax_ppo_rate(ppo_steps)
    jax_free = jax_ppo_rate(ppo_steps, free=True)
    jax_ppo64 = None if quick else jax_ppo_rate(ppo_steps, network_dtype="float64")
    batches = NUMPY_BATCHES[:1] if quick else NUMPY_BATCHES
    steps, reps = (20, 2) if quick else (100, 3)
    numpy_rates = {b: numpy_stepping_rate(b, max(5, steps * 256 // b), reps) for b in batches}
    best_batch = max(numpy_rates, key=lambda b: numpy_rates[b])
    n_envs = 256 if quick else JAX_ENVS
    devices = min(devices, len(jax.devices()))    # a GPU machine steps on its GPU(s)
    platform = jax.devices()[0].platform
    while n_envs % devices:                        # the envs split evenly across devices
        devices -= 1
    one_device, compile_s = jax_stepping_rate(n_envs, steps, reps)
    stepping = (jax_stepping_rate(n_envs, steps, reps, devices=devices)[0] if devices > 1
                else one_device)
    vmapped, _ = jax_stepping_rate(n_envs, steps, reps, mode="step", devices=devices)
    floor, _ = jax_stepping_rate(n_envs, steps, reps, mode="step_with_noise", devices=devices)
    numpy_faulty = numpy_stepping_rate(best_batch, max(5, steps * 256 // best_batch), reps,
                                       conditions=True)
    faulty, _ = jax_stepping_rate(n_envs, steps, reps, conditions=True, devices=devices)
    lstm_steps = 8192 if quick else 32_768
    sb3_lstm = sb3_ppo_rate(lstm_steps, kind="recurrent")
    jax_lstm = jax_ppo_rate(lstm_steps, kind="recurrent")
    return {"recurrent": {"sb3_steps_per_s": sb3_lstm["rate"],
                          "jax_steps_per_s": jax_lstm["rate"],
                          "jax_compile_seconds": jax_lstm["compile_seconds"],
                          "ratio": jax_lstm["rate"] / sb3_lstm["rate"], "steps": lstm_steps},
            "ppo": {"sb3_steps_per_s": sb3["rate"], "jax_steps_per_s": jax_ppo["rate"],
                    "jax_compile_seconds": jax_ppo["compile_seconds"],
                    "jax_free_steps_per_s": jax_free["rate"],
                    "jax_float64_steps_per_s": jax_ppo64["rate"] if jax_ppo64 else None,
                    "ratio": jax_ppo["rate"] / sb3["rate"],
                    "ceiling": jax_free["rate"] / sb3["rate"], "steps": ppo_steps},
            "stepping": {"numpy_steps_per_s": numpy_rates, "numpy_best_batch": best_batch,
                         "jax_envs": n_envs, "jax_devices": devices,
                         "jax_platform": platform,
                         "jax_steps_per_s": stepping, "jax_one_device_steps_per_s": one_device,
                         "jax_gymnax_step_steps_per_s": vmapped,
                         "ratio_gymnax_step": vmapped / numpy_rates[best_batch],
                         "jax_compile_seconds": compile_s, "jax_given_noise_steps_per_s": floor,
                         "ratio": stepping / numpy_rates[best_batch],
                         "ratio_one_device": one_device / numpy_rates[best_batch],
                         "ceiling": floor / numpy_rates[best_batch]},
            "stepping_conditions": {"numpy_steps_per_s": numpy_faulty,
                                    "numpy_batch": best_batch, "jax_envs": n_envs,
                                    "jax_devices": devices,
                                    "jax_platform": platform,
                                    "jax_steps_per_s": faulty,
                                    "ratio": faulty / numpy_faulty}}


def print_results(res: dict[str, Any]) -> None:
    from ..tables import format_table

    print("\n   the JAX backend (fir_gym.jax) on Orbit-v0 with its EKF\n")
    if "skipped" in res:
        print(f"   skipped: {res['skipped']}")
        return
    p, s = res["ppo"], res["stepping"]
    print(format_table(
        ["what", "numpy steps/s", "JAX steps/s", "ratio", "target", "floor"],
        [["PPO, shipped recipe, 16 envs", p["sb3_steps_per_s"], p["jax_steps_per_s"],
          p["ratio"], "≥ 6", f"PPO alone (a free env): {p['jax_free_steps_per_s']:.4g} "
          f"steps/s (ceiling {p['ceiling']:.3g}); compile {p['jax_compile_seconds']:.1f} s, "
          "not counted" + (f"; networks in float64: {f64:.4g} steps/s"
                           if (f64 := p.get("jax_float64_steps_per_s")) else "")],
         [f"stepping, JAX {s['jax_envs']} envs on {cpus(s)} / numpy best "
          f"({s['numpy_best_batch']} envs, one process)",
          s["numpy_steps_per_s"][s["numpy_best_batch"]], s["jax_steps_per_s"], s["ratio"],
          "≥ 2", f"noise given, no auto-reset: {s['jax_given_noise_steps_per_s']:.4g} "
          f"steps/s (ceiling {s['ceiling']:.3g})"]]
        + ([["  the same, JAX on one CPU device (one core)",
             s["numpy_steps_per_s"][s["numpy_best_batch"]], s["jax_one_device_steps_per_s"],
             s["ratio_one_device"], "—", "per core"]]
           if s.get("jax_devices", 1) > 1 else [])
        + ([["  the same, gymnax's step vmapped (every env's reset computed at every step)",
             s["numpy_steps_per_s"][s["numpy_best_batch"]], s["jax_gymnax_step_steps_per_s"],
             s["ratio_gymnax_step"], "—", "the same numbers"]]
           if "jax_gymnax_step_steps_per_s" in s else [])
        + ([[f"stepping under mismatch 0.1 + dropout 0.3, JAX {c['jax_envs']} envs on "
             f"{cpus(c)} / numpy {c['numpy_batch']} envs", c["numpy_steps_per_s"],
             c["jax_steps_per_s"], c["ratio"], "—",
             "the EKF predicting through the lost readings"]]
           if (c := res.get("stepping_conditions")) else [])
        + ([["RecurrentPPO, ppo_lstm.yml, 16 envs (the recurrent kind, on the measurement)",
             r["sb3_steps_per_s"], r["jax_steps_per_s"], r["ratio"], "—",
             f"compile {r['jax_compile_seconds']:.1f} s, not counted"]]
           if (r := res.get("recurrent")) else []), floatfmt=".4g"))


def cpus(stepping: dict[str, Any]) -> str:
    """How many devices a stepping figure used, in words (CPU devices: one per core)."""
    n, platform = stepping.get("jax_devices", 1), stepping.get("jax_platform", "cpu").upper()
    per_core = " (one per core)" if platform == "CPU" else ""
    return f"one {platform} device" if n == 1 else f"{n} {platform} devices{per_core}"


def targets(res: dict[str, Any]) -> list[tuple[str, float | None, float, float | None]]:
    """``(what, measured, limit, ceiling)`` of the two JAX targets (lower bounds)."""
    if not res or "skipped" in res:
        return []
    p, s = res["ppo"], res["stepping"]
    return [("JAX PPO / SB3 PPO env-steps per second (Orbit-v0 + EKF, 16 envs)",
             p["ratio"], 6.0, p["ceiling"]),
            (f"JAX Orbit-v0 + EKF step at {s['jax_envs']} envs on {cpus(s)} / best numpy "
             "vector env",
             s["ratio"], 2.0, s["ceiling"])]
