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
    python scripts/jax_stepping_speed.py --devices 1 2     # one core, then both
    python scripts/jax_stepping_speed.py --modes step step_env step_with_noise \
        --prng threefry2x32 rbg
"""

from __future__ import annotations

import argparse

import fir_gym  # noqa: F401  (registers the ids)
from fir_gym.benchmarks.jax_training import MODES
from fir_gym.benchmarks.jax_training import jax_stepping_rate as jax_rate
from fir_gym.benchmarks.jax_training import numpy_stepping_rate as numpy_rate
from fir_gym.cpu_devices import request_cpu_devices
from fir_gym.machine import cores, cpu_model, load_average


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
    parser.add_argument("--modes", nargs="+", default=["batch_step"], choices=MODES,
                        help="JAX step(s) to time (default: batch_step, the target's: the "
                             "resets only where an episode ended; step: gymnax's step "
                             "vmapped)")
    parser.add_argument("--devices", type=int, nargs="+", default=[1],
                        help="CPU devices the JAX envs are sharded across, one figure each "
                             "(default 1; JAX is given the largest number before it starts)")
    parser.add_argument("--quick", action="store_true", help="256 envs, 50 steps, 2 reps")
    args = parser.parse_args(argv)
    have = request_cpu_devices(max(args.devices))
    if max(args.devices) > have:
        parser.error(f"--devices: JAX has {have} CPU device(s); got {max(args.devices)}")
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
    for devices in args.devices:
        for mode in args.modes:
            for prng in args.prng if mode != "step_with_noise" else args.prng[:1]:
                jax_steps, compile_s = jax_rate(args.envs, args.steps, args.reps, prng, mode,
                                                devices=devices)
                keys = f", {prng} keys" if mode != "step_with_noise" else ""
                print(f"  {mode}{keys}, {devices} device(s): {jax_steps:12,.0f} env-steps/s, "
                      f"ratio JAX / best numpy {jax_steps / rates[best_batch]:.2f} (compile "
                      f"{compile_s:.1f} s)")
    print(f"load average after {load_average()}")


if __name__ == "__main__":
    main()
