"""Env-steps per second of Orbit-v0 with its EKF: the JAX env (jit + vmap) against numpy's.

A measurement, not a test (issue 28). JAX: :class:`fir_gym.jax.orbit.Orbit` observing its
EKF, gymnax's ``step`` (auto-reset included) vmapped over ``--envs`` systems and scanned
over ``--steps`` steps with :func:`jax.lax.scan`, timed after compilation (best of
``--reps``). numpy: the native vector env ``gym.make_vec("fir_gym/Orbit-v0", B,
vectorization_mode="vector_entry_point")`` inside
:class:`~fir_gym.wrappers.VectorEstimatorObservation` with ``"ekf"`` (its batched EKF), at
each batch size of ``--numpy-batches``, its best one reported. Both run the same closed
loop: the hover thrust (0.311) plus ``0.5 (8 − r̂)`` from the estimate, clipped. Prints both
rates, their ratio, the CPU and the load average.

Needs the ``jax`` extra::

    python scripts/jax_stepping_speed.py                 # 2048 envs x 200 steps
    python scripts/jax_stepping_speed.py --quick
    python scripts/jax_stepping_speed.py --modes step step_env step_with_noise \
        --prng threefry2x32 rbg
"""

from __future__ import annotations

import argparse
import time
import warnings
from typing import Any

import gymnasium as gym
import numpy as np

import fir_gym  # noqa: F401  (registers the ids)
from fir_gym.machine import cores, cpu_model, load_average

#: the policy both envs run: hover thrust plus a proportional correction of the estimated r
HOVER, GAIN, R_REF = 0.311, 0.5, 8.0


def policy(obs: np.ndarray) -> np.ndarray:
    """The numpy env's actions from its estimates ``(B, 2)`` (float32, as a policy's)."""
    return np.clip(HOVER - GAIN * (obs[:, :1] - R_REF), -1.0, 1.0).astype(np.float32)


#: what a JAX step is: gymnax's ``step`` (noise drawn, auto-reset: what training runs),
#: ``step_env`` (noise drawn, no auto-reset) or ``step_with_noise`` (zero noise given: the
#: plant and the filter alone)
MODES = ("step", "step_env", "step_with_noise")


def jax_rate(n_envs: int, steps: int, reps: int, prng: str = "threefry2x32",
             mode: str = "step") -> tuple[float, float]:
    """(env-steps/s of the jitted, vmapped Orbit+EKF env, compile seconds); ``prng`` is the
    keys' implementation (JAX's default ``threefry2x32``, or ``rbg``/``unsafe_rbg``), ``mode``
    one of :data:`MODES`."""
    import jax
    import jax.numpy as jnp

    from fir_gym.jax.orbit import Orbit, OrbitNoise

    env = Orbit("ekf")
    params = env.default_params
    zero = OrbitNoise(jnp.zeros(2), jnp.zeros(1))

    def one(key: Any) -> Any:
        k_reset, k_steps = jax.random.split(key)
        obs, state = env.reset(k_reset, params)

        def body(carry: Any, key: Any) -> Any:
            obs, state = carry
            action = jnp.clip(HOVER - GAIN * (obs[:1] - R_REF), -1.0, 1.0)
            if mode == "step":
                obs, state, reward, _, _, _ = env.step(key, state, action, params)
            elif mode == "step_env":
                obs, state, reward, _, _ = env.step_env(key, state, action, params)
            else:
                obs, state, reward, _, _ = env.step_with_noise(state, action, zero, params)
            return (obs, state), reward

        (_, state), rewards = jax.lax.scan(body, (obs, state), jax.random.split(k_steps, steps))
        return state.filter_x, rewards.sum()

    run = jax.jit(jax.vmap(one))
    keys = jax.random.split(jax.random.key(0, impl=prng), n_envs)
    start = time.perf_counter()
    jax.block_until_ready(run(keys))
    compile_s = time.perf_counter() - start
    best = np.inf
    for rep in range(reps):
        keys = jax.random.split(jax.random.key(rep + 1, impl=prng), n_envs)
        start = time.perf_counter()
        jax.block_until_ready(run(keys))
        best = min(best, time.perf_counter() - start)
    return n_envs * steps / best, compile_s


def numpy_rate(n_envs: int, steps: int, reps: int) -> float:
    """Env-steps/s of the native vector env with the batched EKF (best of ``reps``)."""
    from fir_gym.wrappers import VectorEstimatorObservation

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = VectorEstimatorObservation(
            gym.make_vec("fir_gym/Orbit-v0", num_envs=n_envs,
                         vectorization_mode="vector_entry_point"), "ekf")
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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=2048, help="JAX batch (default 2048)")
    parser.add_argument("--steps", type=int, default=200, help="JAX scan length (default 200)")
    parser.add_argument("--reps", type=int, default=5, help="timed repetitions; the best counts")
    parser.add_argument("--numpy-batches", type=int, nargs="+",
                        default=[16, 64, 256, 1024, 2048], help="numpy vector env batch sizes")
    parser.add_argument("--numpy-steps", type=int, default=50,
                        help="numpy steps per timed repetition (default 50)")
    parser.add_argument("--prng", nargs="+", default=["threefry2x32"],
                        choices=["threefry2x32", "rbg", "unsafe_rbg"],
                        help="JAX key implementation(s) to time (default threefry2x32)")
    parser.add_argument("--modes", nargs="+", default=["step"], choices=MODES,
                        help="JAX step(s) to time (default: gymnax's step, with auto-reset)")
    parser.add_argument("--quick", action="store_true", help="256 envs, 50 steps, 2 reps")
    args = parser.parse_args(argv)
    if args.quick:
        args.envs, args.steps, args.reps, args.numpy_steps = 256, 50, 2, 10
        args.numpy_batches = [64, 256]

    print(f"CPU: {cpu_model()}, {cores()} cores, load average before {load_average()}")
    rates = {}
    for batch in args.numpy_batches:
        rates[batch] = numpy_rate(batch, args.numpy_steps, args.reps)
        print(f"numpy native vector env + VectorEstimatorObservation(ekf), {batch:5d} envs: "
              f"{rates[batch]:12,.0f} env-steps/s")
    best_batch = max(rates, key=lambda b: rates[b])
    print(f"JAX Orbit(ekf), jit(vmap) over {args.envs} envs, lax.scan of {args.steps} steps; "
          f"best numpy: {best_batch} envs, {rates[best_batch]:,.0f} env-steps/s")
    for mode in args.modes:
        for prng in args.prng if mode != "step_with_noise" else args.prng[:1]:
            jax_steps, compile_s = jax_rate(args.envs, args.steps, args.reps, prng, mode)
            keys = f", {prng} keys" if mode != "step_with_noise" else ""
            print(f"  {mode}{keys}: {jax_steps:12,.0f} env-steps/s, ratio JAX / best numpy "
                  f"{jax_steps / rates[best_batch]:.2f} (compile {compile_s:.1f} s)")
    print(f"load average after {load_average()}")


if __name__ == "__main__":
    main()
