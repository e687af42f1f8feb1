"""The learned grid: PPO controllers trained in a regime, evaluated under every condition.

One task is one (plant, kind, training regime, seed): it trains the controller with
fir-gym's recipe (:func:`fir_gym.training.run.train`, the shipped YAML) on the nominal
plant or with a condition on (domain randomisation, :data:`~.plan.REGIMES`), then plays
it under every evaluated condition and strength on the shared evaluation episodes
(:func:`~.closed_loop.play`: one episode per sub-env of a native vector env, the policy
deterministic, observations normalised with the run's statistics). A controller on an
estimate is evaluated twice per setting: with the estimator as trained and with its
innovation gate on (the gate changes the estimate the policy sees, not the policy).

The task's result is cached in its run folder (``robustness.json``) under a key made of
the training configuration, :func:`~fir_gym.code_version.code_version`, the settings,
episodes and seeds: a rerun with the same key reuses it, anything else recomputes it
(and retrains when the configuration or the code changed).
"""

from __future__ import annotations

import json
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fir_gym.conditions import condition_setup

from .closed_loop import build_env, play
from .plan import GATE, PLAIN_KINDS, REGIMES, episode_steps, plant_plan
from .summaries import episode_summary


@dataclass(frozen=True)
class LearnedTask:
    """One trained controller and everything it is evaluated on."""

    env_id: str
    kind: str
    regime: str
    seed: int
    steps: int
    episodes: int
    eval_seed: int
    settings: tuple[tuple[str, float], ...]
    run_dir: str


class SB3Policy:
    """A trained stable-baselines3 model (and its observation normaliser) as
    :func:`~.closed_loop.play`'s policy; a recurrent one carries its LSTM state."""

    def __init__(self, model: Any, normaliser: Any) -> None:
        self.model, self.normaliser = model, normaliser

    def __call__(self, obs: Any, start: np.ndarray, state: Any) -> tuple[np.ndarray, Any]:
        seen = obs if self.normaliser is None else self.normaliser.normalize_obs(obs)
        actions, state = self.model.predict(seen, state=state, episode_start=start,
                                            deterministic=True)
        return np.asarray(actions), state


def training_config(task: LearnedTask) -> Any:
    """The :class:`~fir_gym.training.run.RunConfig` the task trains."""
    import gymnasium as gym

    from fir_gym.training.run import RunConfig

    plan = plant_plan(task.env_id)
    env_kwargs: dict[str, Any] = dict(plan.env_kwargs)
    regime = REGIMES[task.regime]
    if regime is not None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plant = gym.make(task.env_id, **plan.env_kwargs).unwrapped
        setup = condition_setup(regime[0], regime[1], plant, episode_steps(task.env_id))
        env_kwargs.update(setup.plant_kwargs)
        if setup.sensor_faults:
            env_kwargs["sensor_faults"] = setup.sensor_faults
    kind_kwargs = {} if task.kind in PLAIN_KINDS else dict(plan.estimator_kwargs.get(task.kind,
                                                                                     {}))
    return RunConfig(env_id=task.env_id, observation_kind=task.kind, steps=task.steps,
                     seed=task.seed, env_kwargs=env_kwargs, kind_kwargs=kind_kwargs)


def task_key(task: LearnedTask, config: Any) -> dict[str, Any]:
    """What must be equal for a cached result to be reused."""
    from fir_gym.code_version import code_version

    return {"config": json.loads(config.to_json()), "code_version": code_version(),
            "settings": [list(s) for s in task.settings], "episodes": task.episodes,
            "eval_seed": task.eval_seed, "gate": GATE}


def evaluate_controller(task: LearnedTask, config: Any, policy: Any
                        ) -> tuple[list[dict[str, Any]], float]:
    """The trained ``policy`` of ``task`` (its training configuration ``config``) played under
    every setting, plain and — on an estimate — gated: the records and the seconds taken.
    Both backends' controllers are evaluated here (:class:`SB3Policy`, and
    :class:`fir_gym.jax.policy.JaxPolicy` in :mod:`fir_gym.jax.robustness`)."""
    import gymnasium as gym

    plan = plant_plan(task.env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plant: Any = gym.make(task.env_id, **plan.env_kwargs).unwrapped
    observed = "measurement" if task.kind == "recurrent" else task.kind
    gates = (False, True) if task.kind not in PLAIN_KINDS else (False,)
    records = []
    start = time.perf_counter()
    for condition, strength in task.settings:
        setup = condition_setup(condition, strength, plant, episode_steps(task.env_id))
        burst = setup.plant_kwargs.get("burst")
        for gated in gates:
            options = dict(config.kind_kwargs)
            if gated:
                options["gate"] = GATE
            venv = build_env(task.env_id, task.episodes, observed, setup,
                             env_kwargs=plan.env_kwargs, estimator_kwargs=options)
            episodes = play(venv, policy, task.eval_seed, keep_errors=burst is not None)
            venv.close()
            records.append({
                "task": {"kind": task.kind + ("+gate" if gated else ""), "regime": task.regime,
                         "seed": task.seed, "env_id": task.env_id, "condition": condition,
                         "strength": strength},
                **episode_summary(episodes, n_x=len(plant.state_names),
                                  burst=burst[0][:2] if burst else None)})
    return records, time.perf_counter() - start


def run_learned_task(task: LearnedTask) -> dict[str, Any]:
    """Train (or reuse), then evaluate under every setting (module docstring)."""
    from fir_gym.training.evaluation import load_controller
    from fir_gym.training.run import train

    config = training_config(task)
    out = Path(task.run_dir)
    cache = out / "robustness.json"
    key = task_key(task, config)
    if cache.is_file():
        saved = json.loads(cache.read_text())
        if saved.get("key") == key:
            return {**saved, "reused": True}
    start = time.perf_counter()
    train(config, out, resume=True)
    trained = time.perf_counter() - start
    model, normaliser = load_controller(config, out, None)
    records, evaluated = evaluate_controller(task, config, SB3Policy(model, normaliser))
    result = {"key": key, "train_seconds": trained, "eval_seconds": evaluated,
              "records": records}
    out.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps(result) + "\n")
    return result
