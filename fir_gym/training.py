"""Training and evaluating controllers on true states, raw measurements or estimates.

A *run* is one controller trained with stable-baselines3 on one plant seeing one
kind of observation (``"true"``, ``"measurement"`` or an estimator name). Its
folder holds ``model.zip`` (the policy), ``vecnormalize.pkl`` (observation and
reward normalisation statistics), ``monitor/*.monitor.csv`` (one line per
training episode) and ``run.json`` (everything needed to rebuild the env), so
``evaluate`` can be called on the folder alone. All three kinds are built by
:func:`fir_gym.wrappers.wrap_observation` on the same plant and the same reward,
so their returns are comparable.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np

from fir_gym.estimators._validation import one_of

from .wrappers import wrap_observation

ALGORITHMS = ("ppo", "sac")

#: PPO settings for these low-dimensional plants (overridable through ``algo_kwargs``):
#: short rollouts and larger batches for frequent, stable updates, and an initial
#: action spread of e⁻¹ instead of SB3's 1 — with actions in [-1, 1], a spread of 1
#: saturates the actuators and hides precise inputs such as the orbit's hover thrust.
#: On Orbit-v0 (true state, 300-step episodes) they reach a hand-tuned PD
#: controller's return in 2e5 steps, where SB3's defaults are still 6x off at 3e5.
PPO_DEFAULTS: dict[str, Any] = {"n_steps": 256, "batch_size": 256, "learning_rate": 1e-3,
                                "gae_lambda": 0.95, "policy_kwargs": {"log_std_init": -1.0}}


@dataclass
class RunConfig:
    """What ``fir-gym train`` needs to build, train and later rebuild a controller."""

    env_id: str
    observation_kind: str = "true"          # "true", "measurement" or an estimator name
    algo: str = "ppo"
    steps: int = 50_000
    seed: int = 0
    n_envs: int = 8
    observation: str = "estimate"           # for estimators: see EstimatorObservation
    estimator_kwargs: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    algo_kwargs: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        one_of("algo", self.algo, ALGORITHMS)
        if self.steps <= 0 or self.n_envs <= 0:
            raise ValueError(f"steps and n_envs must be positive; got {self.steps}, {self.n_envs}")


def make_env(config: RunConfig, seed: int | None = None) -> gym.Env:
    """One environment of ``config``, observing ``config.observation_kind``."""
    env = gym.make(config.env_id, **config.env_kwargs)
    if config.observation_kind in ("true", "measurement"):
        return wrap_observation(env, config.observation_kind)
    return wrap_observation(env, config.observation_kind, observation=config.observation,
                            **config.estimator_kwargs)


def _vec_env(config: RunConfig, seed: int, monitor_dir: str | None, n_envs: int) -> Any:
    from stable_baselines3.common.env_util import make_vec_env

    return make_vec_env(lambda: make_env(config), n_envs=n_envs, seed=seed,
                        monitor_dir=monitor_dir)


def train(config: RunConfig, out: str | Path, *, progress_bar: bool = False) -> Path:
    """Train a controller as ``config`` says and save the run in ``out``."""
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.vec_env import VecNormalize

    # Small MLP policies run fastest on one thread, and parallel runs then do not
    # oversubscribe the cores.
    torch.set_num_threads(1)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    venv = _vec_env(config, config.seed, str(out / "monitor"), config.n_envs)
    venv = VecNormalize(venv, norm_obs=True, norm_reward=True, gamma=0.99)
    policy = "MultiInputPolicy" if isinstance(venv.observation_space, gym.spaces.Dict) \
        else "MlpPolicy"
    cls = {"ppo": PPO, "sac": SAC}[config.algo]
    algo_kwargs = dict(config.algo_kwargs)
    if config.algo == "ppo":
        algo_kwargs = {**PPO_DEFAULTS, **algo_kwargs}
        # a rollout no longer than the budget
        algo_kwargs["n_steps"] = int(min(algo_kwargs["n_steps"],
                                         max(32, config.steps // config.n_envs)))
        algo_kwargs["batch_size"] = int(min(algo_kwargs["batch_size"],
                                            algo_kwargs["n_steps"] * config.n_envs))
    model = cls(policy, venv, seed=config.seed, verbose=0, device="cpu", **algo_kwargs)
    model.learn(total_timesteps=config.steps, progress_bar=progress_bar)
    model.save(out / "model.zip")
    venv.save(str(out / "vecnormalize.pkl"))
    (out / "run.json").write_text(json.dumps(asdict(config), indent=2, default=_jsonable) + "\n")
    venv.close()
    return out


@dataclass
class Evaluation:
    returns: list[float]

    @property
    def mean(self) -> float:
        return float(np.mean(self.returns))

    @property
    def std(self) -> float:
        return float(np.std(self.returns))


def evaluate(run_dir: str | Path, *, episodes: int = 20, seed: int = 10_000) -> Evaluation:
    """Deterministic-policy returns of a saved run on fresh seeds (raw, unnormalised rewards)."""
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import VecNormalize

    run_dir = Path(run_dir)
    config = RunConfig(**json.loads((run_dir / "run.json").read_text()))
    venv = _vec_env(config, seed, None, 1)
    venv = VecNormalize.load(str(run_dir / "vecnormalize.pkl"), venv)
    venv.training, venv.norm_reward = False, False
    cls: Any = {"ppo": PPO, "sac": SAC}[config.algo]
    model = cls.load(run_dir / "model.zip", device="cpu")
    returns, _ = evaluate_policy(model, venv, n_eval_episodes=episodes, deterministic=True,
                                 return_episode_rewards=True, warn=False)
    venv.close()
    return Evaluation([float(r) for r in cast("list[float]", returns)])


def learning_curve(run_dir: str | Path, bins: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Mean training-episode return against timesteps, from the run's monitor files."""
    rows = []
    for path in sorted((Path(run_dir) / "monitor").glob("*.monitor.csv")):
        lines = path.read_text().splitlines()[2:]           # a JSON header, then "r,l,t"
        steps = 0
        for line in lines:
            r, length, _ = line.split(",")
            steps += int(length)
            rows.append((steps, float(r)))
    if not rows:
        return np.zeros(0), np.zeros(0)
    data = np.array(sorted(rows))
    n_files = max(1, len(list((Path(run_dir) / "monitor").glob("*.monitor.csv"))))
    data[:, 0] *= n_files                                   # timesteps across parallel envs
    edges = np.linspace(0, data[-1, 0], bins + 1)
    idx = np.clip(np.digitize(data[:, 0], edges) - 1, 0, bins - 1)
    centers = 0.5 * (edges[1:] + edges[:-1])
    means = np.array([data[idx == b, 1].mean() if np.any(idx == b) else np.nan
                      for b in range(bins)])
    return centers, means


def compare_controllers(
    env_id: str,
    kinds: Sequence[str],
    seeds: Sequence[int],
    out: str | Path,
    *,
    steps: int = 50_000,
    algo: str = "ppo",
    episodes: int = 20,
    estimator_kwargs: dict[str, dict[str, Any]] | None = None,
    env_kwargs: dict[str, Any] | None = None,
    algo_kwargs: dict[str, Any] | None = None,
    n_envs: int = 8,
    progress_bar: bool = False,
) -> list[dict[str, Any]]:
    """Train one controller per (kind, seed), evaluate each, and summarise per kind."""
    out = Path(out)
    summary = []
    for kind in kinds:
        results = []
        for seed in seeds:
            config = RunConfig(env_id=env_id, observation_kind=kind, algo=algo, steps=steps,
                               seed=seed, n_envs=n_envs, env_kwargs=dict(env_kwargs or {}),
                               algo_kwargs=dict(algo_kwargs or {}),
                               estimator_kwargs=dict((estimator_kwargs or {}).get(kind, {})))
            run_dir = train(config, out / f"{kind}-seed{seed}", progress_bar=progress_bar)
            results.append(evaluate(run_dir, episodes=episodes).mean)
        summary.append({"observation": kind, "mean": float(np.mean(results)),
                        "std": float(np.std(results)), "per_seed": results})
    return summary


def plot_learning_curves(out: str | Path, kinds: Sequence[str], seeds: Sequence[int],
                         path: str | Path) -> Path | None:
    """Save a learning-curve plot (mean over seeds per kind); None without matplotlib."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    fig, ax = plt.subplots(figsize=(7, 4))
    for kind in kinds:
        curves = [learning_curve(Path(out) / f"{kind}-seed{s}") for s in seeds]
        curves = [c for c in curves if len(c[0])]
        if not curves:
            continue
        x = curves[0][0]
        y = np.nanmean([np.interp(x, cx, np.nan_to_num(cy, nan=np.nanmean(cy)))
                        for cx, cy in curves], axis=0)
        ax.plot(x, y, label=kind)
    ax.set_xlabel("timesteps")
    ax.set_ylabel("training episode return")
    if ax.lines:
        ax.legend()
    else:
        ax.text(0.5, 0.5, "no training episode finished", ha="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot store {type(value).__name__} in run.json")
