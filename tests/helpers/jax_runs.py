"""Tiny JAX training runs for the tests of fir_gym.jax.train and its run folders."""

from typing import Any

ORBIT = "fir_gym/Orbit-v0"
#: two PPO iterations of the shipped rollout (16 envs x 256 steps)
TINY: dict[str, Any] = {"steps": 8192, "checkpoints": 2, "curve_episodes": 2, "episodes": 2}
