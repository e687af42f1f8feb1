"""compare-controllers: seeds × kinds as independent jobs on the serial/joblib/dask runner.

:func:`compare_controllers` first checks every kind, option and keyword argument
(:func:`validate`: building each kind's env and controller, and each algorithm with
its settings, takes seconds), so a bad one fails before any training starts; then it
hands one job per (kind, seed) to :class:`fir_gym.scenarios.runner.Runner`. A job
trains (or designs) the controller in its own folder ``OUT/<kind>-seed<seed>`` and
evaluates it on the same evaluation seeds as every other job; each draw comes from the
job's own seeds, so the numbers are identical on every backend. A finished job writes
``result.json`` with its configuration and :func:`~fir_gym.code_version.code_version`;
with ``resume=True`` a job whose result exists with the same configuration *and* the same
code version is not run again (at other code it is trained again from scratch), and an
interrupted one continues from its latest checkpoint.
"""

from __future__ import annotations

import json
import time
import warnings
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .evaluation import evaluate, load_controller, make_eval_env
from .kinds import is_learned, kind_options
from .run import RunConfig, algorithm_class, build_training_env, train
from .stats import episode_bootstrap, iqm, percentile_interval


def validate(configs: Sequence[RunConfig]) -> None:
    """Build every config's env, controller and algorithm once: errors before training."""
    seen: set[tuple[Any, ...]] = set()
    for config in configs:
        key = (config.observation_kind, json.dumps(config.kind_kwargs, sort_keys=True,
                                                    default=str), config.observation)
        if key in seen:
            continue
        seen.add(key)
        label = config.observation_kind
        try:
            env = make_eval_env(config)
            if not is_learned(config.observation_kind):
                load_controller(config, None, env)
            env.close()
            if is_learned(config.observation_kind):
                settings = config.settings()
                venv = build_training_env(config, 0, None, 1)
                with warnings.catch_warnings():       # a one-env check: batch-size advice
                    warnings.simplefilter("ignore")
                    algorithm_class(config)(settings["policy"], venv, device="cpu",
                                            **settings["algo_kwargs"])
                venv.close()
        except (TypeError, ValueError, KeyError) as err:
            raise ValueError(f"{label}: {err}") from None


def run_job(job: dict[str, Any]) -> dict[str, Any]:
    """Train and evaluate one (kind, seed): the runner's task (module-level: picklable)."""
    from fir_gym.code_version import code_version

    config: RunConfig = job["config"]
    out = Path(job["run_dir"])
    result_file = out / "result.json"
    version = code_version()
    resume = bool(job.get("resume"))
    if resume and result_file.is_file():
        saved = json.loads(result_file.read_text())
        if saved.get("config") == json.loads(config.to_json()):
            if saved.get("code_version") == version:
                return {**saved, "reused": True}
            resume = False              # the same job at other code: train it again
    start = time.perf_counter()
    train(config, out, resume=resume)
    trained = time.perf_counter() - start
    source = out if is_learned(config.observation_kind) else config
    result = evaluate(source, episodes=job["episodes"], seed=job["eval_seed"])
    summary = {"kind": config.observation_kind, "seed": config.seed,
               "config": json.loads(config.to_json()), "code_version": version,
               "mean": result.mean,
               "train_seconds": trained, **result.to_dict()}
    result_file.write_text(json.dumps(summary, indent=1) + "\n")
    return summary


def compare_controllers(
    env_id: str,
    kinds: Sequence[str],
    seeds: Sequence[int],
    out: str | Path,
    *,
    steps: int | None = None,
    algo: str = "ppo",
    episodes: int = 20,
    eval_seed: int = 10_000,
    kind_kwargs: dict[str, Any] | None = None,
    env_kwargs: dict[str, Any] | None = None,
    algo_kwargs: dict[str, Any] | None = None,
    n_envs: int | None = None,
    observation: str = "estimate",
    eval_freq: int = 0,
    checkpoint_freq: int = 0,
    tensorboard: str | None = None,
    resume: bool = False,
    runner: Any = None,
) -> list[dict[str, Any]]:
    """Train (or design) one controller per (kind, seed), evaluate each, summarise per kind.

    Returns one summary per kind: the mean and std over seeds of the per-seed mean
    returns, the per-seed means, their IQM with a 95 % bootstrap interval, and the
    closed-loop estimation RMSE (per state, mean over seeds), the NEES median (as a ratio
    to χ²'s, median over seeds), the fraction of steps in the 95 % χ² band (mean over
    seeds) and the ANEES where the kind has an estimator. ``out/results.json`` holds every
    job's result.
    """
    from fir_gym.scenarios.runner import SERIAL

    configs = make_configs(env_id, kinds, seeds, steps=steps, algo=algo, kind_kwargs=kind_kwargs,
                           env_kwargs=env_kwargs, algo_kwargs=algo_kwargs, n_envs=n_envs,
                           observation=observation, eval_freq=eval_freq,
                           checkpoint_freq=checkpoint_freq, tensorboard=tensorboard)
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes <= 0:
        raise ValueError(f"episodes must be a positive integer; got {episodes!r}")
    validate(configs)
    out = Path(out)
    jobs = [{"config": c, "run_dir": str(out / f"{c.observation_kind}-seed{c.seed}"),
             "episodes": episodes, "eval_seed": eval_seed, "resume": resume} for c in configs]
    results = (runner or SERIAL).map(run_job, jobs, desc=env_id)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    return summarise(results, kinds)


def make_configs(env_id: str, kinds: Sequence[str], seeds: Sequence[int], *,
                 steps: int | None = None, algo: str = "ppo",
                 kind_kwargs: dict[str, Any] | None = None,
                 env_kwargs: dict[str, Any] | None = None,
                 algo_kwargs: dict[str, Any] | None = None, n_envs: int | None = None,
                 observation: str = "estimate", eval_freq: int = 0, checkpoint_freq: int = 0,
                 tensorboard: str | None = None) -> list[RunConfig]:
    """One checked :class:`RunConfig` per (kind, seed) (kind options in the one format)."""
    kinds = list(kinds)
    if not kinds:
        raise ValueError("give at least one kind")
    if len(set(kinds)) != len(kinds):
        raise ValueError(f"kinds repeat: {kinds}")
    if not seeds:
        raise ValueError("give at least one seed")
    options = kind_options(kind_kwargs, kinds)
    base = RunConfig(env_id=env_id, observation_kind=kinds[0], algo=algo, steps=steps,
                     n_envs=n_envs, observation=observation,
                     env_kwargs=dict(env_kwargs or {}), algo_kwargs=dict(algo_kwargs or {}),
                     eval_freq=eval_freq, checkpoint_freq=checkpoint_freq,
                     tensorboard=tensorboard, kind_kwargs=options[kinds[0]])
    return [replace(base, observation_kind=k, kind_kwargs=options[k], seed=int(s))
            for k in kinds for s in seeds]


def summarise(results: Sequence[dict[str, Any]], kinds: Sequence[str]) -> list[dict[str, Any]]:
    """Per kind: mean ± std over seeds, per-seed means, IQM and its interval, RMSE, ANEES.

    The IQM's 95 % interval resamples the evaluation episodes (the same draw for every
    kind: they share the episode seeds) and each kind's seeds
    (:func:`~.stats.episode_bootstrap`), so a classical kind, whose seeds all give the
    same controller, still has an interval: its episodes'.
    """
    per_kind = {kind: [r for r in results if r["kind"] == kind] for kind in kinds}
    draws = episode_bootstrap({k: [list(map(float, r["returns"])) for r in rows]
                               for k, rows in per_kind.items()})
    summary = []
    for kind, rows in per_kind.items():
        means = [float(r["mean"]) for r in rows]
        low, high = percentile_interval(draws[kind])
        rmses = [r["rmse"] for r in rows if r.get("rmse") is not None]
        anees = [r["anees"] for r in rows if r.get("anees") is not None]
        medians = [r["nees_median"] for r in rows if r.get("nees_median") is not None]
        in_band = [r["nees_in_band"] for r in rows if r.get("nees_in_band") is not None]
        summary.append({
            "observation": kind, "mean": float(np.mean(means)), "std": float(np.std(means)),
            "per_seed": means, "iqm": iqm(means), "iqm_low": low, "iqm_high": high,
            "rmse": np.mean(rmses, axis=0).tolist() if rmses else None,
            "anees": float(np.mean(anees)) if anees else None,
            "nees_median": float(np.median(medians)) if medians else None,
            "nees_in_band": float(np.mean(in_band)) if in_band else None,
            "train_seconds": float(np.sum([r.get("train_seconds", 0.0) for r in rows]))})
    return summary
