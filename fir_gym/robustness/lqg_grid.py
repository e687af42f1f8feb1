"""The LQG × estimator × condition grid: nothing to train, every cell a batch of episodes.

One task is one (plant, estimator or the true state, gate or not, condition, strength):
:data:`~.plan.LQG_EPISODES` closed-loop episodes at once on the plant's native vector env
(:func:`~.closed_loop.play`), the LQR of the nominal model acting on what the controller
sees. Tasks are module-level functions of one picklable argument, so the serial, joblib
and Dask runners give the same numbers (every draw comes from the episode seeds).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from fir_gym.conditions import condition_setup

from .closed_loop import build_env, play
from .plan import GATE, episode_steps, plant_plan
from .summaries import episode_summary


@dataclass(frozen=True)
class LQGTask:
    """One cell of the LQG grid."""

    env_id: str
    observed: str          # "true" or an estimator's registry name
    gated: bool
    condition: str
    strength: float
    episodes: int
    seed: int

    @property
    def label(self) -> str:
        return f"lqg-{self.observed}" + ("+gate" if self.gated else "")


class ControllerPolicy:
    """A classical controller (``predict``) as :func:`~.closed_loop.play`'s policy."""

    def __init__(self, controller: Any) -> None:
        self.controller = controller

    def __call__(self, obs: Any, start: np.ndarray, state: Any) -> tuple[np.ndarray, Any]:
        actions, state = self.controller.predict(obs, state, start, deterministic=True)
        return actions, state


def run_lqg_task(task: LQGTask) -> dict[str, Any]:
    """Play one cell; returns its per-episode record (:func:`.summaries.episode_summary`)."""
    import gymnasium as gym

    from fir_gym.controllers import LQGController

    plan = plant_plan(task.env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plant: Any = gym.make(task.env_id, **plan.env_kwargs).unwrapped
    setup = condition_setup(task.condition, task.strength, plant, episode_steps(task.env_id))
    options = dict(plan.estimator_kwargs.get(task.observed, {}))
    if task.gated:
        options["gate"] = GATE
    venv = build_env(task.env_id, task.episodes, task.observed, setup,
                     env_kwargs=plan.env_kwargs, estimator_kwargs=options)
    controller = LQGController(venv)
    episodes = play(venv, ControllerPolicy(controller), task.seed,
                    keep_errors=task.condition == "burst")
    venv.close()
    burst = setup.plant_kwargs.get("burst")
    return {"task": {"kind": task.label, "env_id": task.env_id, "condition": task.condition,
                     "strength": task.strength},
            **episode_summary(episodes, n_x=len(plant.state_names),
                              burst=burst[0][:2] if burst else None)}
