"""What drives a scripted episode of ``fir-gym watch`` and ``fir-gym record``.

``--policy`` is one of :data:`POLICIES` or a run folder of ``fir-gym train``:

* ``"zero"`` — no action (the plant's free motion);
* ``"lqg"`` — :class:`fir_gym.controllers.LQGController`: the LQR of the plant's nominal
  model, designed at its operating point, acting on the estimate the env observes;
* a run folder (``run.json``, ``model.zip``, ``vecnormalize.pkl``) — the trained controller,
  deterministic, fed its observation normalised with the run's statistics.

Each command builds its own env (a video renders, a dataset records the measurement); the
policies, the run's configuration and its checks are here, once.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from ._extras import INSTALL, MissingExtra

if TYPE_CHECKING:
    from .training import RunConfig

__all__ = ["POLICIES", "Policy", "classical_policy", "run_config", "trained_policy"]

#: what ``--policy`` accepts besides a run folder
POLICIES = ("zero", "lqg")

Policy = Callable[[Any], NDArray[Any]]


def classical_policy(env: gym.Env, policy: str) -> Policy:
    """The ``"zero"`` or ``"lqg"`` policy of ``env`` (an env observing an estimate)."""
    if policy == "lqg":
        from .controllers import LQGController

        controller = LQGController(env)
        return lambda obs: np.asarray(controller.predict(obs)[0])
    zeros: NDArray[Any] = np.zeros(env.action_space.shape or (), dtype=np.float32)
    return lambda obs: zeros


def run_config(run: Path, env_id: str | None) -> RunConfig:
    """The configuration of a run folder of ``fir-gym train`` (``RunConfig.load``), refused
    with a ``ValueError`` when ``run`` is not one, or when ``env_id`` is given and is not the
    env the run was trained on."""
    from .training import RunConfig

    if not (run / "run.json").is_file():
        raise ValueError(f"policy must be one of {', '.join(POLICIES)} or a run folder of "
                         f"`fir-gym train` (with run.json); {str(run)!r} is neither")
    config = RunConfig.load(run)
    if env_id is not None and env_id != config.env_id:
        raise ValueError(f"env is {env_id!r} but the run {str(run)!r} was trained on "
                         f"{config.env_id!r} (leave env out to use the run's)")
    return config


def trained_policy(run: Path, algo: str, env: gym.Env) -> Policy:
    """The run's deterministic policy, its observations normalised as in training."""
    try:
        from stable_baselines3 import PPO, SAC
        from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    except ModuleNotFoundError as err:
        raise MissingExtra(f"a run's policy needs stable-baselines3 ({err.name} is missing): "
                           f"{INSTALL['rl']}") from None
    algorithm: Any = {"ppo": PPO, "sac": SAC}[algo]
    model = algorithm.load(run / "model.zip", device="cpu")
    stats = VecNormalize.load(str(run / "vecnormalize.pkl"), DummyVecEnv([lambda: env]))

    def act(obs: Any) -> NDArray[Any]:
        action, _ = model.predict(stats.normalize_obs(obs), deterministic=True)
        return np.asarray(action)

    return act
