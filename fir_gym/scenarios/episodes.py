"""One scripted episode per plant, summarised: the smoke test of every environment.

Each plant runs one full episode (its registered time limit) under a fixed,
documented open-loop input, from a fixed seed; the summary gives, per state
component, its range and spread, and, for the measurement, the empirical noise
standard deviation beside the one the plant's model assumes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from .._registration import ENV_IDS
from .plan import Stage, Task, run_plan
from .runner import Runner

#: The scripted input of each plant (a function of the step index), and why.
SCRIPTS: dict[str, tuple[str, Any]] = {
    "fir_gym/Orbit-v0": ("zero thrust (paper 000 sim 1)", lambda k: 0.0),
    "fir_gym/UncertainOscillator-v0": ("zero input (paper 000 sim 2)", lambda k: 0.0),
    "fir_gym/CarrierMotion-v0": ("compensator held at 0", lambda k: 0.0),
    "fir_gym/VanDerPol-v0": ("zero force (paper 002)", lambda k: 0.0),
}


@dataclass
class EpisodeSummary:
    env_id: str
    script: str
    steps: int
    terminated: bool
    episode_return: float
    state_names: tuple[str, ...]
    state_min: np.ndarray
    state_max: np.ndarray
    state_mean: np.ndarray
    state_std: np.ndarray
    measurement_noise_std: float
    model_noise_std: float


def run_episode(env_id: str, seed: int = 0) -> EpisodeSummary:
    """Run one scripted episode of ``env_id`` and summarise it."""
    description, script = SCRIPTS.get(env_id, ("zero input", lambda k: 0.0))
    env = gym.make(env_id)
    plant: Any = env.unwrapped
    shape = tuple(env.action_space.shape or ())
    obs, info = env.reset(seed=seed)
    states, residuals, ret = [info["state"]], [], 0.0
    k, terminated, truncated = 0, False, False
    while not (terminated or truncated):
        action = np.full(shape, script(k), dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        states.append(info["state"])
        noise_free = info.get("x1_average", plant.model.h(info["state"])[0])
        residuals.append(obs[0] - noise_free)
        ret += float(reward)
        k += 1
    X = np.array(states)
    env.close()
    return EpisodeSummary(
        env_id=env_id, script=description, steps=k, terminated=terminated,
        episode_return=ret, state_names=plant.state_names,
        state_min=X.min(0), state_max=X.max(0), state_mean=X.mean(0), state_std=X.std(0),
        measurement_noise_std=float(np.std(residuals)),
        model_noise_std=float(np.sqrt(plant.model.R[0, 0])),
    )


def episode_task(task: tuple[str, int]) -> EpisodeSummary:
    """:func:`run_episode` as a runner task: ``(env_id, seed)``."""
    return run_episode(*task)


def plan(seed: int = 0) -> Stage:
    """One task per registered plant; the value is the list of summaries."""
    return Stage([Task(episode_task, (env_id, seed), cost=0.3) for env_id in ENV_IDS],
                 lambda out: out, desc="scripted episodes")


def run_all(seed: int = 0, runner: Runner | None = None) -> list[EpisodeSummary]:
    """One scripted episode for every registered plant."""
    return list(run_plan(plan(seed), runner))


def summary_rows(summaries: list[EpisodeSummary]) -> tuple[list[str], list[list[Any]]]:
    """A table: one row per state component of every plant."""
    headers = ["env", "steps", "ended", "state", "min", "max", "mean", "std",
               "y noise std", "model √R"]
    rows: list[list[Any]] = []
    for s in summaries:
        for i, name in enumerate(s.state_names):
            first = i == 0
            rows.append([
                s.env_id.split("/")[-1] if first else "", s.steps if first else None,
                ("terminated" if s.terminated else "truncated") if first else "", name,
                float(s.state_min[i]), float(s.state_max[i]), float(s.state_mean[i]),
                float(s.state_std[i]),
                s.measurement_noise_std if first else None, s.model_noise_std if first else None,
            ])
    return headers, rows
