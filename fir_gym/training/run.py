"""One run: a controller of one kind on one plant, trained (or designed) and saved.

A run's folder holds ``run.json`` (everything needed to rebuild the env and the
controller, so ``evaluate`` needs the folder alone) and, for a learned kind,
``model.zip`` (the policy), ``vecnormalize.pkl`` (observation and reward
normalisation statistics), ``monitor.monitor.csv`` (one line per training episode),
``best/best_model.zip`` (the evaluation callback's best, with ``--eval-freq``),
``checkpoints/`` (with ``--checkpoint-freq``; ``resume=True`` continues from the latest)
and, with ``tensorboard``, its logs. A classical kind (``lqg``, ``pid``) has nothing to
train: its folder holds ``run.json`` only.

Training uses :func:`~fir_gym.training.make_sb3_vec_env` (the native batched plant
where there is one) with the hyperparameters of the plant's entry in the shipped RL
Zoo YAML (:mod:`.hyperparams`), overridden by the config.
"""

from __future__ import annotations

import importlib.util
import json
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.estimators._validation import one_of

from . import hyperparams
from .kinds import check_kind, is_learned, recipe

ALGORITHMS = ("ppo", "sac")


@dataclass
class RunConfig:
    """What ``fir-gym train`` needs to build, train and later rebuild a controller.

    ``steps`` and ``n_envs`` default (``None``) to the hyperparameter file's
    ``n_timesteps`` and ``n_envs``; ``algo_kwargs`` override its other entries.
    ``kind_kwargs`` are the options of ``observation_kind`` (see :mod:`.kinds`).
    """

    env_id: str
    observation_kind: str = "true"
    algo: str = "ppo"
    steps: int | None = None
    seed: int = 0
    n_envs: int | None = None
    observation: str = "estimate"           # for estimators: see EstimatorObservation
    kind_kwargs: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    algo_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_freq: int = 0                      # timesteps between evaluations (0: none)
    eval_episodes: int = 5
    checkpoint_freq: int = 0                # timesteps between checkpoints (0: none)
    tensorboard: str | None = None          # folder for TensorBoard logs
    hyperparams: str | None = None          # a YAML file instead of the shipped one

    def __post_init__(self) -> None:
        one_of("algo", self.algo, ALGORITHMS)
        check_kind(self.observation_kind)
        if self.observation_kind == "recurrent" and self.algo != "ppo":
            raise ValueError("the recurrent kind trains sb3-contrib's RecurrentPPO: algo must "
                             f"be 'ppo'; got {self.algo!r}")
        for name in ("steps", "n_envs"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                      or value <= 0):
                raise ValueError(f"{name} must be a positive integer; got {value!r}")
        for name in ("eval_freq", "checkpoint_freq"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be a non-negative integer; got {value!r}")
        if self.eval_episodes <= 0:
            raise ValueError(f"eval_episodes must be positive; got {self.eval_episodes!r}")
        if self.tensorboard and importlib.util.find_spec("tensorboard") is None:
            raise ValueError("tensorboard logs need the tensorboard package "
                             "(pip install tensorboard)")
        recipe(self.observation_kind, self.kind_kwargs, self.observation)

    @property
    def algo_name(self) -> str:
        """The hyperparameter file's algorithm: ``recurrent-ppo`` for the recurrent kind."""
        return "recurrent-ppo" if self.observation_kind == "recurrent" else self.algo

    def settings(self) -> dict[str, Any]:
        """The run's resolved hyperparameters: the YAML entry, then the overrides."""
        entry = hyperparams.hyperparameters(self.algo_name, self.env_id, self.hyperparams)
        zoo, algo = hyperparams.split(entry)
        algo.update(self.algo_kwargs)
        if "policy_kwargs" in self.algo_kwargs and isinstance(
                self.algo_kwargs["policy_kwargs"], str):
            algo["policy_kwargs"] = hyperparams.parse_policy_kwargs(
                self.algo_kwargs["policy_kwargs"])
        steps = self.steps or int(zoo.get("n_timesteps", 100_000))
        n_envs = self.n_envs or int(zoo.get("n_envs", 8))
        if self.algo_name != "sac":
            # a rollout no longer than the budget, minibatches no larger than a rollout
            algo["n_steps"] = int(min(algo.get("n_steps", 2048), max(32, steps // n_envs)))
            algo["batch_size"] = int(min(algo.get("batch_size", 64), algo["n_steps"] * n_envs))
        return {"steps": steps, "n_envs": n_envs, "policy": zoo.get("policy", "MlpPolicy"),
                "normalize": hyperparams.normalize_options(zoo.get("normalize", True)),
                "algo_kwargs": algo}

    def env_kwargs_for_sb3(self) -> dict[str, Any]:
        """The arguments of :func:`make_sb3_vec_env` for this config's kind."""
        return {**recipe(self.observation_kind, self.kind_kwargs, self.observation).kwargs(),
                **self.env_kwargs}

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, default=_jsonable) + "\n"

    @classmethod
    def load(cls, run_dir: str | Path) -> RunConfig:
        data = json.loads((Path(run_dir) / "run.json").read_text())
        if "estimator_kwargs" in data:                 # run folders of fir-gym <= 0.1
            data["kind_kwargs"] = data.pop("estimator_kwargs")
        return cls(**data)


def algorithm_class(config: RunConfig) -> Any:
    """The stable-baselines3 (or sb3-contrib) class that trains ``config``."""
    if config.algo_name == "recurrent-ppo":
        from sb3_contrib import RecurrentPPO

        return RecurrentPPO
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[config.algo]


def build_training_env(config: RunConfig, seed: int, monitor: str | None, n_envs: int
                       ) -> Any:
    """The VecEnv a run trains on: native where possible, with a ``VecMonitor``."""
    from stable_baselines3.common.vec_env import VecMonitor

    from .vec_env import make_sb3_vec_env

    venv = make_sb3_vec_env(config.env_id, n_envs, seed=seed, **config.env_kwargs_for_sb3())
    return VecMonitor(venv, filename=monitor)


def train(config: RunConfig, out: str | Path, *, progress_bar: bool = False,
          resume: bool = False) -> Path:
    """Train a controller as ``config`` says and save the run in ``out`` (module docstring).

    ``resume=True`` continues from the latest checkpoint in ``out/checkpoints`` (the
    total budget stays ``steps``); a run whose ``model.zip`` exists is left as it is. Both
    only when the folder's ``code_version.txt`` is this code's
    (:func:`~fir_gym.code_version.code_version`): a run begun at other code, or without the
    stamp, starts over.
    """
    from fir_gym.code_version import code_version

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if not is_learned(config.observation_kind):
        (out / "run.json").write_text(config.to_json())
        return out
    stamp = out / "code_version.txt"
    if resume and (not stamp.is_file() or stamp.read_text().strip() != code_version()):
        resume = False                  # begun at other code (or before the stamp existed)
    stamp.write_text(code_version() + "\n")
    if resume and (out / "model.zip").is_file() and (out / "run.json").is_file():
        return out
    import torch
    from stable_baselines3.common.callbacks import (
        BaseCallback,
        CallbackList,
        CheckpointCallback,
        EvalCallback,
    )
    from stable_baselines3.common.vec_env import VecNormalize

    # Small MLP policies run fastest on one thread, and parallel runs then do not
    # oversubscribe the cores.
    torch.set_num_threads(1)
    settings = config.settings()
    n_envs, steps = settings["n_envs"], settings["steps"]
    venv = build_training_env(config, config.seed, str(out / "monitor"), n_envs)
    cls = algorithm_class(config)
    checkpoint = _latest_checkpoint(out / "checkpoints") if resume else None
    if settings["normalize"] is not None:
        if checkpoint is not None and checkpoint[2].is_file():
            venv = VecNormalize.load(str(checkpoint[2]), venv)
        else:
            venv = VecNormalize(venv, **{"gamma": settings["algo_kwargs"].get("gamma", 0.99),
                                         **settings["normalize"]})
    policy = settings["policy"]
    if isinstance(venv.observation_space, gym.spaces.Dict) and policy == "MlpPolicy":
        policy = "MultiInputPolicy"
    tensorboard = str(config.tensorboard) if config.tensorboard else None
    if checkpoint is not None:
        model = cls.load(checkpoint[1], env=venv, device="cpu", tensorboard_log=tensorboard)
        done = checkpoint[0]
    else:
        model = cls(policy, venv, seed=config.seed, verbose=0, device="cpu",
                    tensorboard_log=tensorboard, **settings["algo_kwargs"])
        done = 0
    callbacks: list[BaseCallback] = []
    if config.checkpoint_freq:
        callbacks.append(CheckpointCallback(max(1, config.checkpoint_freq // n_envs),
                                            str(out / "checkpoints"), name_prefix="model",
                                            save_vecnormalize=True))
    if config.eval_freq:
        eval_env = build_training_env(config, config.seed + 1_000_000, None, 1)
        if settings["normalize"] is not None:
            eval_env = VecNormalize(eval_env, training=False, norm_reward=False)
        callbacks.append(EvalCallback(eval_env, n_eval_episodes=config.eval_episodes,
                                      eval_freq=max(1, config.eval_freq // n_envs),
                                      best_model_save_path=str(out / "best"),
                                      log_path=str(out / "best"), deterministic=True,
                                      verbose=0))
    model.learn(total_timesteps=max(0, steps - done), progress_bar=progress_bar,
                reset_num_timesteps=checkpoint is None,
                callback=CallbackList(callbacks) if callbacks else None,
                tb_log_name=f"{config.observation_kind}-seed{config.seed}")
    model.save(out / "model.zip")
    if isinstance(venv, VecNormalize):
        venv.save(str(out / "vecnormalize.pkl"))
    (out / "run.json").write_text(config.to_json())
    venv.close()
    return out


def _latest_checkpoint(folder: Path) -> tuple[int, Path, Path] | None:
    """``(timesteps, model path, VecNormalize path)`` of the newest checkpoint, if any."""
    found = []
    for path in folder.glob("model_*_steps.zip"):
        match = re.fullmatch(r"model_(\d+)_steps\.zip", path.name)
        if match:
            steps = int(match.group(1))
            found.append((steps, path, folder / f"model_vecnormalize_{steps}_steps.pkl"))
    return max(found) if found else None


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot store {type(value).__name__} in run.json")
