"""``fir-gym benchmark-robustness``: the LQG grid, then the learned grid, then the report.

Both grids are lists of independent tasks (:mod:`.lqg_grid`, :mod:`.learned_grid`), each
a module-level function of one picklable argument whose every draw comes from its own
seeds, mapped on the serial, joblib or Dask runner (:class:`fir_gym.scenarios.runner.Runner`):
the numbers are the same on every backend. The LQG grid runs first and is timed on its
own (it needs no training, and no stable-baselines3); the learned grid's tasks reuse a
finished task's cached result when its key — configuration, code version, settings — is
unchanged. ``OUT/results.json`` holds every task's record, the tables and the answers;
``OUT/REPORT.md`` the tables in Markdown; ``OUT/figures/`` return against condition
strength per controller.
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fir_gym.conditions import get_condition

from ..machine import cores, cpu_model, load_average
from .lqg_grid import LQGTask, run_lqg_task
from .plan import (
    EPISODES,
    EVAL_SEED,
    LQG_EPISODES,
    PLAIN_KINDS,
    QUICK,
    REGIMES,
    SEEDS,
    applicable_estimators,
    check_selection,
    plant_plan,
    settings,
    short_name,
)


def run_task(task: Any) -> Any:
    """One task of either grid (the runner's function: module-level, picklable)."""
    from .learned_grid import LearnedTask, run_learned_task

    if isinstance(task, LQGTask):
        return run_lqg_task(task)
    if isinstance(task, LearnedTask):
        return run_learned_task(task)
    raise TypeError(f"not a benchmark task: {task!r}")


def lqg_tasks(plants: Sequence[str], conditions: Sequence[str], *, quick: bool = False
              ) -> list[LQGTask]:
    """Every cell of the LQG grid: per plant, the true state and every applicable estimator
    plain and gated, under every setting — except what an estimator refuses
    (:func:`skipped`)."""
    episodes = QUICK.lqg_episodes if quick else LQG_EPISODES
    tasks = []
    for env_id in plants:
        estimators = applicable_estimators(env_id)
        if quick:
            estimators = estimators[:QUICK.lqg_estimators]
        observed = [("true", False)] + [(e, g) for e in estimators for g in (False, True)]
        for condition, strength in settings(conditions, quick=quick):
            tasks += [LQGTask(env_id, name, gated, condition, strength, episodes, EVAL_SEED)
                      for name, gated in observed
                      if refusal(name, gated, condition) is None]
    return tasks


def refusal(estimator: str, gated: bool, condition: str) -> str | None:
    """Why ``estimator`` (gated or not) cannot run under ``condition``, or ``None``: a filter
    that refuses the gate, or one that needs every measurement under a condition that
    misses some (the LQG grid leaves those cells out and the report says why)."""
    from fir_gym.estimators import estimator_class

    if estimator == "true":
        return None
    cls = estimator_class(estimator)
    if gated and not cls.can_gate:
        return (f"{estimator} refuses the gate ("
                f"{getattr(cls, 'no_gate_reason', 'it has no innovation test')})")
    if not cls.accepts_missing and get_condition(condition).misses_readings:
        return (f"{estimator} needs every measurement, and {condition} leaves some out "
                "(use fir)")
    return None


def skipped(plants: Sequence[str], conditions: Sequence[str]) -> list[str]:
    """The LQG grid's cells left out, one sentence per (plant, estimator, reason)."""
    out: list[str] = []
    for env_id in plants:
        for estimator in applicable_estimators(env_id):
            reasons = {refusal(estimator, gated, condition)
                       for condition in conditions for gated in (False, True)} - {None}
            out += [f"{short_name(env_id)}: {reason}" for reason in sorted(r for r in reasons
                                                                              if r)]
    return out


def learned_tasks(plants: Sequence[str], conditions: Sequence[str], out: Path, *,
                  quick: bool = False, seeds: int | None = None) -> list[Any]:
    """Every (plant, kind, regime, seed) of the learned grid, costliest plants first."""
    from .learned_grid import LearnedTask

    n_seeds = seeds or (QUICK.seeds if quick else SEEDS)
    episodes = QUICK.episodes if quick else EPISODES
    regimes = QUICK.regimes if quick else tuple(REGIMES)
    chosen = settings(conditions, quick=quick)
    tasks = []
    for env_id in plants:
        plan = plant_plan(env_id)
        kinds = list(QUICK.kinds if quick else (*PLAIN_KINDS, *plan.learned_estimators))
        if quick and plan.learned_estimators:
            kinds.append(plan.learned_estimators[0])
        steps = QUICK.steps if quick else plan.steps
        folder = out / "runs" / short_name(env_id)
        for regime in regimes:
            for kind in kinds:
                for seed in range(n_seeds):
                    tasks.append(LearnedTask(
                        env_id, kind, str(regime), seed, steps, episodes, EVAL_SEED,
                        tuple(chosen), str(folder / f"{regime}-{kind}-seed{seed}")))
    # the longest first (RecurrentPPO trains about ten times slower than PPO), so that no
    # worker is left with one at the end
    return sorted(tasks, key=lambda t: t.kind != "recurrent")


def run_benchmark(out: str | Path, *, quick: bool = False, runner: Any = None,
                  plants: Sequence[str] | None = None,
                  conditions: Sequence[str] | None = None, seeds: int | None = None,
                  learned: bool = True, learned_backend: str = "sb3",
                  progress: bool = True) -> dict[str, Any]:
    """Run the grids and write ``OUT/results.json``, ``OUT/REPORT.md`` and the figures.
    ``learned_backend="jax"`` trains the learned grid with :mod:`fir_gym.jax`
    (:mod:`fir_gym.jax.robustness`: what it cannot train is left out and listed in the
    report). ``runner`` (a :class:`fir_gym.scenarios.runner.Runner`) runs both grids' tasks
    — on the JAX backend each (plant, kind, regime) group, every seed in one program;
    default: this process, with a progress bar when ``progress``."""
    if learned_backend not in ("sb3", "jax"):
        raise ValueError(f"learned_backend must be 'sb3' or 'jax'; got {learned_backend!r}")
    from fir_gym.code_version import code_version
    from fir_gym.scenarios.runner import Runner

    from .report import answers, details, markdown, save_figures, tables_of

    out = Path(out)
    chosen_plants, chosen_conditions = check_selection(plants, conditions)
    if quick and plants is None:
        chosen_plants = [p for p in QUICK.plants if p in chosen_plants]
    runner = runner or Runner("serial", progress=progress)
    load_start = load_average()
    start = time.perf_counter()
    lqg = lqg_tasks(chosen_plants, chosen_conditions, quick=quick)
    lqg_results = runner.map(run_task, lqg, desc="LQG grid")
    lqg_seconds = time.perf_counter() - start
    learned_results: list[dict[str, Any]] = []
    learned_seconds = 0.0
    reused = 0
    learned_skipped: list[str] = []
    if learned:
        start = time.perf_counter()
        tasks = learned_tasks(chosen_plants, chosen_conditions, out, quick=quick, seeds=seeds)
        if learned_backend == "jax":
            from fir_gym.jax.robustness import run_groups

            learned_results, learned_skipped = run_groups(tasks, runner)
        else:
            learned_results = runner.map(run_task, tasks, desc="learned grid")
        learned_seconds = time.perf_counter() - start
        reused = sum(bool(r.get("reused")) for r in learned_results)
    records = list(lqg_results) + [rec for r in learned_results for rec in r["records"]]
    tables = tables_of(records)
    report: dict[str, Any] = {
        "quick": quick, "code_version": code_version(),
        "machine": {"cpu": cpu_model(), "cores": cores(), "python": platform.python_version(),
                    "backend": getattr(runner, "backend", "serial"),
                    "learned_backend": learned_backend if learned else None,
                    "jobs": getattr(runner, "jobs", None), "load_start": load_start,
                    "load_end": load_average()},
        "lqg_seconds": lqg_seconds, "lqg_tasks": len(lqg_results),
        "learned_seconds": learned_seconds, "learned_tasks": len(learned_results),
        "learned_reused": reused,
        "train_seconds": sum(float(r.get("train_seconds", 0.0)) for r in learned_results),
        "plants": chosen_plants, "conditions": {
            name: [s for c, s in settings([name], quick=quick) if c == name]
            for name in chosen_conditions},
        "strength_meaning": {name: get_condition(name).strength_meaning
                             for name in chosen_conditions},
        "skipped": skipped(chosen_plants, chosen_conditions),
        "learned_skipped": learned_skipped,
        "tables": tables}
    report["answers"] = answers(report, records)
    report["details"] = details(report, records)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps({**report, "records": records}) + "\n")
    figures = save_figures(report, out / "figures")
    (out / "REPORT.md").write_text(markdown(report, figures) + "\n")
    return report
