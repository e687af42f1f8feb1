"""PPO's env-steps per second on Orbit-v0 + EKF: fir_gym.jax.train against stable-baselines3.

A measurement, not a test (issue 28). Both train the shipped recipe (``ppo.yml``: 16 envs
x 256 steps, 4 minibatches of 1024, 10 epochs, VecNormalize) on Orbit-v0 observing its
EKF, in one run of this script:

* JAX: :func:`fir_gym.jax.train.make_algorithm` (rejax's PPO on the gymnax Orbit), the
  training iterations of ``--steps`` as one jitted program (no evaluation in it), compiled
  first (its time reported apart: ``--cache`` folder or none), then run twice on fresh
  keys, the faster run timed — steady state. ``--seeds S`` also times S seeds vmapped in
  one program (S x the steps).
* SB3: :class:`stable_baselines3.PPO` on the numpy env (``make_sb3_vec_env``: the batched
  plant and the batched EKF, ``VecNormalize``), torch at one thread as ``fir-gym train``
  sets it; one rollout learned first (set-up, warm-up), then ``--steps`` more timed.

``--kind recurrent`` times the ``recurrent`` kind instead: JAX's RecurrentPPO against
sb3-contrib's, both at ``ppo_lstm.yml`` on the measurement.

Prints both rates, the ratio, the CPU model, the cores and the load average before and
after::

    python scripts/jax_training_speed.py                     # 65 536 steps each
    python scripts/jax_training_speed.py --steps 102400 --seeds 4
    python scripts/jax_training_speed.py --kind recurrent    # RecurrentPPO, sb3-contrib's
"""

from __future__ import annotations

import argparse
import warnings

from fir_gym.benchmarks.jax_training import KIND
from fir_gym.benchmarks.jax_training import jax_ppo_rate as jax_rate
from fir_gym.benchmarks.jax_training import sb3_ppo_rate as sb3_rate
from fir_gym.machine import cores, cpu_model, load_average


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=65_536,
                        help="timed training steps per backend (default 65536)")
    parser.add_argument("--seeds", type=int, default=1,
                        help="also time this many seeds vmapped in one JAX program")
    parser.add_argument("--cache", default=None,
                        help="JAX compilation cache folder (default: none, a cold compile)")
    parser.add_argument("--skip-sb3", action="store_true", help="time JAX only")
    parser.add_argument("--n-envs", type=int, default=None,
                        help="JAX envs (default: the recipe's 16; the minibatch size stays "
                             "the recipe's, so there are more minibatches)")
    parser.add_argument("--network-dtype", default="float32", choices=["float32", "float64"],
                        help="the JAX networks' arithmetic (default: the shipped float32)")
    parser.add_argument("--kind", default=KIND, choices=[KIND, "recurrent"],
                        help=f"what the policy observes (default: {KIND}; recurrent: "
                             "RecurrentPPO at ppo_lstm.yml on the measurement, against "
                             "sb3-contrib's)")
    args = parser.parse_args(argv)
    warnings.filterwarnings("ignore")
    before = load_average()
    print(f"{cpu_model()}, {cores()} cores, load average {before} at the start")
    jax1 = jax_rate(args.steps, 1, args.cache, n_envs=args.n_envs, kind=args.kind,
                    network_dtype=args.network_dtype)
    envs = args.n_envs or 16
    print(f"JAX ({args.kind}), 1 seed x {envs} envs: {jax1['rate']:,.0f} env-steps/s "
          f"({jax1['steps']} steps in {jax1['seconds']:.2f} s; compile "
          f"{jax1['compile_seconds']:.1f} s)", flush=True)
    jaxs = None
    if args.seeds > 1:
        jaxs = jax_rate(args.steps, args.seeds, args.cache, n_envs=args.n_envs,
                        kind=args.kind, network_dtype=args.network_dtype)
        print(f"JAX ({args.kind}), {args.seeds} seeds vmapped x {envs} envs: {jaxs['rate']:,.0f} "
              f"env-steps/s ({jaxs['steps']} steps in {jaxs['seconds']:.2f} s; compile "
              f"{jaxs['compile_seconds']:.1f} s)", flush=True)
    if not args.skip_sb3:
        sb3 = sb3_rate(args.steps, kind=args.kind)
        print(f"SB3 ({args.kind}; torch 1 thread), 16 envs, numpy Orbit-v0: "
              f"{sb3['rate']:,.0f} env-steps/s ({sb3['steps']} steps in {sb3['seconds']:.2f} "
              f"s; set-up and a warm-up rollout {sb3['setup_seconds']:.1f} s)", flush=True)
        print(f"ratio JAX/SB3, 1 seed: {jax1['rate'] / sb3['rate']:.2f}x"
              + (f"; {args.seeds} seeds vmapped: {jaxs['rate'] / sb3['rate']:.2f}x"
                 if jaxs else ""))
    print(f"load average {load_average()} at the end (start {before})")


if __name__ == "__main__":
    main()
