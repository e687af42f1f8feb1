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

Prints both rates, the ratio, the CPU model, the cores and the load average before and
after::

    python scripts/jax_training_speed.py                     # 65 536 steps each
    python scripts/jax_training_speed.py --steps 102400 --seeds 4
"""

from __future__ import annotations

import argparse
import time
import warnings
from typing import Any

from fir_gym.machine import cores, cpu_model, load_average

ENV_ID, KIND = "fir_gym/Orbit-v0", "ekf"


def jax_rate(steps: int, seeds: int, cache: str | None) -> dict[str, Any]:
    """``{"steps", "seconds", "compile_seconds", "rate"}`` of JAX PPO (``seeds`` vmapped)."""
    import jax
    import jax.numpy as jnp

    from fir_gym.jax import train as jt

    if cache:
        jt.enable_compilation_cache(cache)
    rec = jt.recipe(ENV_ID, steps=steps)
    env, params = jt.make_env(ENV_ID, KIND)
    algo = jt.make_algorithm(env, params, rec)

    def one(key: Any) -> Any:
        ts = algo.init_state(key)
        ts = jax.lax.fori_loop(0, rec.iterations, lambda _, ts: algo.train_iteration(ts), ts)
        return ts.actor_ts.params

    program = jax.jit(jax.vmap(one))
    keys = [jnp.stack([jax.random.PRNGKey(1000 * r + s) for s in range(seeds)])
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


def sb3_rate(steps: int) -> dict[str, Any]:
    """``{"steps", "seconds", "setup_seconds", "rate"}`` of stable-baselines3's PPO."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from fir_gym.training.run import RunConfig, build_training_env

    torch.set_num_threads(1)
    start = time.perf_counter()
    config = RunConfig(ENV_ID, KIND, steps=steps)
    settings = config.settings()
    venv = build_training_env(config, 0, None, settings["n_envs"])
    venv = VecNormalize(venv, gamma=settings["algo_kwargs"].get("gamma", 0.99),
                        **settings["normalize"])
    model = PPO(settings["policy"], venv, seed=0, device="cpu", verbose=0,
                **settings["algo_kwargs"])
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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=65_536,
                        help="timed training steps per backend (default 65536)")
    parser.add_argument("--seeds", type=int, default=1,
                        help="also time this many seeds vmapped in one JAX program")
    parser.add_argument("--cache", default=None,
                        help="JAX compilation cache folder (default: none, a cold compile)")
    parser.add_argument("--skip-sb3", action="store_true", help="time JAX only")
    args = parser.parse_args(argv)
    warnings.filterwarnings("ignore")
    before = load_average()
    print(f"{cpu_model()}, {cores()} cores, load average {before} at the start")
    jax1 = jax_rate(args.steps, 1, args.cache)
    print(f"JAX PPO, 1 seed x 16 envs: {jax1['rate']:,.0f} env-steps/s ({jax1['steps']} "
          f"steps in {jax1['seconds']:.2f} s; compile {jax1['compile_seconds']:.1f} s)",
          flush=True)
    jaxs = None
    if args.seeds > 1:
        jaxs = jax_rate(args.steps, args.seeds, args.cache)
        print(f"JAX PPO, {args.seeds} seeds vmapped x 16 envs: {jaxs['rate']:,.0f} "
              f"env-steps/s ({jaxs['steps']} steps in {jaxs['seconds']:.2f} s; compile "
              f"{jaxs['compile_seconds']:.1f} s)", flush=True)
    if not args.skip_sb3:
        sb3 = sb3_rate(args.steps)
        print(f"SB3 PPO (torch 1 thread), 16 envs, numpy Orbit-v0 + batched EKF: "
              f"{sb3['rate']:,.0f} env-steps/s ({sb3['steps']} steps in {sb3['seconds']:.2f} "
              f"s; set-up and a warm-up rollout {sb3['setup_seconds']:.1f} s)", flush=True)
        print(f"ratio JAX/SB3, 1 seed: {jax1['rate'] / sb3['rate']:.2f}x"
              + (f"; {args.seeds} seeds vmapped: {jaxs['rate'] / sb3['rate']:.2f}x"
                 if jaxs else ""))
    print(f"load average {load_average()} at the end (start {before})")


if __name__ == "__main__":
    main()
