"""The learned grid on the JAX backend: ``fir-gym benchmark-robustness --backend jax``.

The same tasks as :mod:`fir_gym.robustness.learned_grid` — (plant, kind, regime, seed), the
shipped recipe, the plant's steps — trained by :func:`fir_gym.jax.train.train`: every seed
of one (plant, kind, regime) in one compiled program (a *group*), saved as one JAX run folder
(``runs/<plant>/<regime>-<kind>-jax``). Each seed's controller is then evaluated exactly as
a stable-baselines3 one (:func:`fir_gym.robustness.learned_grid.evaluate_controller`: the
numpy envs, every condition and strength, plain and gated, the shared episodes), through
:class:`fir_gym.jax.policy.JaxPolicy`; so the two backends' records differ only by the
controllers, and the report is built from them the same way.

**What the JAX backend trains** (:func:`refusal`): the kinds :data:`fir_gym.jax.train.
SUPPORTED` lists — every kind of the learned grid, ``recurrent`` included
(:mod:`fir_gym.jax.recurrent_ppo`); a task it cannot train is left out and the report says
so (``learned_skipped``) — in every regime: on the nominal plant, under ``dr-mismatch``
(the truth's parameters drawn at every reset: :class:`fir_gym.jax.randomized.Randomized`)
and under ``dr-dropout`` (the sensor's dropout:
:meth:`fir_gym.jax._plant.FilteredPlant.reading_missing`, the filters predicting through a
lost reading).

Each task's records are cached in its own folder (``robustness.json``) under
:func:`fir_gym.robustness.learned_grid.task_key` plus the backend: a rerun with the same key
reuses them; a group retrains when any of its seeds has no valid cache.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fir_gym.robustness.learned_grid import (
    LearnedTask,
    evaluate_controller,
    task_key,
    training_config,
)

#: the training regimes the JAX backend has: all of :data:`fir_gym.robustness.plan.REGIMES`
JAX_REGIMES = ("nominal", "dr-mismatch", "dr-dropout")


def refusal(task: LearnedTask) -> str | None:
    """Why the JAX backend does not train ``task``, or ``None``."""
    from .train import SUPPORTED

    if task.kind not in SUPPORTED.get(task.env_id, ()):
        return f"the JAX backend has no {task.kind} kind on {task.env_id}"
    if task.regime not in JAX_REGIMES:
        return (f"the JAX backend has no {task.regime} training (its regimes: "
                f"{', '.join(JAX_REGIMES)})")
    return None


def groups(tasks: Sequence[LearnedTask]) -> list[list[LearnedTask]]:
    """The tasks by (plant, kind, regime), seeds in order: one compiled program each."""
    by: dict[tuple[str, str, str], list[LearnedTask]] = {}
    for task in tasks:
        by.setdefault((task.env_id, task.kind, task.regime), []).append(task)
    return [sorted(g, key=lambda t: t.seed) for g in by.values()]


def group_folder(group: Sequence[LearnedTask]) -> Path:
    """The JAX run folder of a group: beside its tasks' folders."""
    first = group[0]
    return Path(first.run_dir).parent / f"{first.regime}-{first.kind}-jax"


def run_group(group: Sequence[LearnedTask]) -> list[dict[str, Any]]:
    """Train the group's seeds in one program (or reuse every seed's cached records), then
    evaluate each seed: one result per task, as
    :func:`fir_gym.robustness.learned_grid.run_learned_task` returns (``train_seconds``: the
    group's compile and training time shared equally)."""
    from .policy import JaxPolicy
    from .train import save, train

    configs = [training_config(task) for task in group]       # each builds the plant once
    keys = [{**task_key(task, config), "backend": "jax"}
            for task, config in zip(group, configs, strict=True)]
    cached = []
    for task, key in zip(group, keys, strict=True):
        cache = Path(task.run_dir) / "robustness.json"
        saved = json.loads(cache.read_text()) if cache.is_file() else None
        cached.append(saved if saved and saved.get("key") == key else None)
    if all(c is not None for c in cached):
        return [{**c, "reused": True} for c in cached if c is not None]
    first, config = group[0], configs[0]
    start = time.perf_counter()
    result = train(first.env_id, first.kind, [t.seed for t in group], steps=first.steps,
                   env_kwargs=dict(config.env_kwargs), kind_kwargs=dict(config.kind_kwargs))
    save(result, group_folder(group))
    trained = (time.perf_counter() - start) / len(group)
    out = []
    policies = JaxPolicy.every_seed(result)
    for task, config, key, policy in zip(group, configs, keys, policies, strict=True):
        records, evaluated = evaluate_controller(task, config, policy)
        one = {"key": key, "train_seconds": trained, "eval_seconds": evaluated,
               "backend": "jax", "records": records}
        folder = Path(task.run_dir)
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "robustness.json").write_text(json.dumps(one) + "\n")
        out.append(one)
    return out


def run_groups(tasks: Sequence[LearnedTask], runner: Any = None
               ) -> tuple[list[dict[str, Any]], list[str]]:
    """Every task the JAX backend trains, group by group (one compiled program each) on
    ``runner`` (a :class:`fir_gym.scenarios.runner.Runner`; default: this process): the
    results, and one sentence per (plant, kind, regime) left out. The groups keep the
    tasks' order (:func:`fir_gym.robustness.benchmark.learned_tasks`: the costliest first),
    so a pool of workers is handed the recurrent groups first."""
    from fir_gym.scenarios.runner import SERIAL

    kept = [t for t in tasks if refusal(t) is None]
    skipped = sorted({f"{t.env_id.split('/')[-1]} {t.kind} [{t.regime}]: {refusal(t)}"
                      for t in tasks if refusal(t) is not None})
    done = (runner or SERIAL).map(run_group, groups(kept), desc="learned grid (jax)")
    return [result for group in done for result in group], skipped
