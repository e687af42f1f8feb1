"""stable-baselines3's PPO trained on a ``fir_gym.jax`` environment: the swap experiment.

The JAX backend's learned rows on Orbit-v0 lean below the SB3 backend's (docs/jax.md). Two
things differ between the backends: the PPO (rejax's, made SB3's) and the environment trained
on (the JAX twin against the native numpy vector env). This script keeps SB3's PPO and swaps
the environment: it trains ``stable_baselines3.PPO`` with the shipped recipe on the JAX env of
the controller benchmark's plan (the plant's episode settings, the kind's options, the
training steps) through :func:`make_vec_env`, a ``VecEnv`` over the vmapped, jitted gymnax
``reset``/``step`` (same-step auto-reset; the terminal observation and
``TimeLimit.truncated`` in the infos, as SB3's ``DummyVecEnv`` gives them), under
``VecNormalize``; then saves each seed as a run folder of ``fir-gym train`` and evaluates it
with the SB3 benchmark's own :func:`fir_gym.training.evaluate` (the numpy env, episodes
``reset(seed=10000 + i)``, the deterministic policy on the final normalisation statistics).
If it scores as the SB3 backend, the JAX PPO differs; if as the JAX backend, the env does.

A measurement, not a test::

    python scripts/sb3_on_jax_env.py --kind ekf --seeds 0,1,2,3,4 [--out DIR]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np


def make_vec_env(env_id: str, kind: str, job: dict[str, Any], n: int, seed: int) -> Any:
    """The JAX env of ``job`` (a :func:`fir_gym.jax.benchmark.benchmark_plan` entry) as an
    SB3 ``VecEnv`` of ``n`` envs whose keys come from ``PRNGKey(seed)``."""
    import gymnasium as gym
    import jax
    import jax.numpy as jnp
    from stable_baselines3.common.vec_env import VecEnv

    import fir_gym.jax as fj

    class Adapter(VecEnv):
        def __init__(self) -> None:
            self.env, self.params = fj.make(env_id, kind, kind_kwargs=job["kind_kwargs"],
                                            **job["env_kwargs"])
            shape = self.env.observation_space(self.params).shape
            space = self.env.action_space(self.params)
            super().__init__(n, gym.spaces.Box(-np.inf, np.inf, shape, np.float64),
                             gym.spaces.Box(np.broadcast_to(np.float32(space.low), space.shape),
                                            np.broadcast_to(np.float32(space.high), space.shape),
                                            space.shape, np.float32))
            self.key = jax.random.PRNGKey(seed)
            self._reset = jax.jit(jax.vmap(self.env.reset, in_axes=(0, None)))
            self._step = jax.jit(jax.vmap(self.env.step, in_axes=(0, 0, 0, None)))
            self.actions = np.zeros((n, *space.shape))

        def reset(self) -> Any:
            self.key, key = jax.random.split(self.key)
            obs, self.state = self._reset(jax.random.split(key, self.num_envs), self.params)
            return np.asarray(obs, dtype=np.float64)

        def step_async(self, actions: Any) -> None:
            self.actions = np.asarray(actions, dtype=np.float64)

        def step_wait(self) -> Any:
            self.key, key = jax.random.split(self.key)
            obs, self.state, reward, terminated, truncated, info = self._step(
                jax.random.split(key, self.num_envs), self.state, jnp.asarray(self.actions),
                self.params)
            terminated, truncated = np.asarray(terminated), np.asarray(truncated)
            done = terminated | truncated
            final = np.asarray(info["final_observation"], dtype=np.float64)
            infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
            for i in np.flatnonzero(done):
                infos[i] = {"terminal_observation": final[i],
                            "TimeLimit.truncated": bool(truncated[i] and not terminated[i])}
            return (np.asarray(obs, dtype=np.float64), np.asarray(reward, dtype=np.float64),
                    done, infos)

        def close(self) -> None:
            pass

        def get_attr(self, name: str, indices: Any = None) -> list[Any]:
            return [None] * self.num_envs

        def set_attr(self, name: str, value: Any, indices: Any = None) -> None:
            pass

        def env_method(self, *args: Any, **kwargs: Any) -> list[Any]:
            return [None] * self.num_envs

        def env_is_wrapped(self, wrapper_class: Any, indices: Any = None) -> list[bool]:
            return [False] * self.num_envs

    return Adapter()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="fir_gym/Orbit-v0")
    parser.add_argument("--kind", default="ekf")
    parser.add_argument("--seeds", default="0,1,2,3,4", help="comma-separated seeds")
    parser.add_argument("--out", default=None,
                        help="keep the run folders here (default: a temporary folder)")
    args = parser.parse_args(argv)
    warnings.filterwarnings("ignore")
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from fir_gym.jax.benchmark import benchmark_plan
    from fir_gym.training.evaluation import evaluate
    from fir_gym.training.run import RunConfig
    from fir_gym.training.stats import iqm

    (job,) = [j for j in benchmark_plan(plants=[args.env]) if j["kind"] == args.kind]
    torch.set_num_threads(1)
    config = RunConfig(args.env, args.kind, algo="ppo", env_kwargs=job["env_kwargs"],
                       kind_kwargs=job["kind_kwargs"])
    settings = config.settings()
    per_seed = []
    folder = contextlib.nullcontext(args.out) if args.out else tempfile.TemporaryDirectory()
    with folder as root:
        for seed in (int(s) for s in args.seeds.split(",")):
            start = time.perf_counter()
            venv = VecNormalize(make_vec_env(args.env, args.kind, job, settings["n_envs"],
                                             seed),
                                gamma=settings["algo_kwargs"].get("gamma", 0.99),
                                **settings["normalize"])
            model = PPO(settings["policy"], venv, seed=seed, device="cpu", verbose=0,
                        **settings["algo_kwargs"])
            model.learn(job["steps"])
            run = Path(root) / f"{args.kind}-seed{seed}"       # fir-gym train's run folder
            run.mkdir(parents=True, exist_ok=True)
            model.save(run / "model.zip")
            venv.save(str(run / "vecnormalize.pkl"))
            (run / "run.json").write_text(config.to_json())
            per_seed.append(float(np.mean(evaluate(run, episodes=job["episodes"]).returns)))
            print(json.dumps({"seed": seed, "mean_return": round(per_seed[-1], 1),
                              "seconds": round(time.perf_counter() - start)}), flush=True)
    print(json.dumps({"env": args.env, "kind": args.kind, "per_seed": per_seed,
                      "iqm": iqm(per_seed)}))

if __name__ == "__main__":
    main()
