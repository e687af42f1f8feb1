"""Timing helpers of the benchmarks: best-of blocks, alternating blocks, env steppers."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np


def best_time(fn: Callable[[], Any], budget: float, repeats: int = 3, max_calls: int = 20000
              ) -> float:
    """Seconds per call of ``fn``: best of ``repeats`` blocks of about ``budget`` seconds."""
    t0 = time.perf_counter()
    fn()
    first = time.perf_counter() - t0
    calls = int(min(max_calls, max(1, budget / max(first, 1e-7))))
    return min(first, per_call(fn, calls, repeats, warmup=0))


def per_call(fn: Callable[[], Any], calls: int, repeats: int, warmup: int = 1) -> float:
    """Seconds per call of ``fn``: best of ``repeats`` blocks of ``calls`` calls, after
    ``warmup`` calls (the best block is the one least disturbed by other load)."""
    for _ in range(warmup):
        fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return best


def interleaved(runs: dict[str, tuple[Callable[[], Any], int]], repeats: int
                ) -> dict[str, float]:
    """Seconds per call of each ``(function, calls per block)``, timed in alternating blocks
    (best block each): a change of machine load then does not favour one side of a ratio."""
    best = dict.fromkeys(runs, float("inf"))
    for fn, _ in runs.values():
        fn()                                         # warm-up
    for _ in range(repeats):
        for name, (fn, calls) in runs.items():
            t0 = time.perf_counter()
            for _ in range(calls):
                fn()
            best[name] = min(best[name], (time.perf_counter() - t0) / calls)
    return best


def counting(step: Callable[[int], Any]) -> Callable[[], Any]:
    """``step(k)`` as a function of no argument that counts ``k`` itself."""
    k = [0]

    def call() -> Any:
        k[0] += 1
        return step(k[0])
    return call


def stepper(env_id: str, unwrap: bool = True, **kwargs: Any) -> Callable[[], None]:
    """One env step (reset when the episode ends), of the unwrapped env or of ``gym.make``'s."""
    env = gym.make(env_id, **kwargs)
    return env_stepper(env.unwrapped if unwrap else env)


def vector_stepper(env: Any) -> Callable[[], None]:
    env.reset(seed=0)
    actions = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    return lambda: env.step(actions)


def env_stepper(env: gym.Env) -> Callable[[], None]:
    """One step of ``env`` with a fixed action (zeros, or a sample of a shapeless space),
    resetting it when the episode ends."""
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype) \
        if env.action_space.shape else env.action_space.sample()

    def step() -> None:
        out = env.step(action)
        if out[2] or out[3]:
            env.reset()
    return step
