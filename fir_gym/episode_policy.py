"""What drives a scripted episode of ``fir-gym watch`` and ``fir-gym record``.

``--policy`` is one of :data:`POLICIES` or a run folder of ``fir-gym train``:

* ``"zero"`` — no action (the plant's free motion);
* ``"lqg"`` — :class:`fir_gym.controllers.LQGController`: the LQR of the plant's nominal
  model, designed at its operating point, acting on the estimate the env observes;
* a run folder (``run.json``, ``model.zip``, ``vecnormalize.pkl``) — the trained controller,
  deterministic, fed its observation normalised with the run's statistics;
* a run folder of ``fir-gym train --backend jax`` (``results.json`` of the JAX backend) —
  its first seed's controller, or ``RUN/seed<s>`` for seed ``s``'s, played in the numpy env
  as ``fir-gym evaluate`` plays it (:class:`fir_gym.jax.policy.JaxPolicy`; the ``jax``
  extra).

Each command builds its own env (a video renders, a dataset records the measurement); the
policies, the run's configuration and its checks are here, once.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from ._extras import INSTALL, MissingExtra

if TYPE_CHECKING:
    from .training import RunConfig

__all__ = ["POLICIES", "Policy", "classical_policy", "jax_run", "run_config", "trained_policy"]

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


def jax_run(run: Path) -> tuple[Path, int, dict[str, Any]] | None:
    """``(folder, seed, results)`` where ``run`` is a run folder of ``fir-gym train --backend
    jax`` (its ``results.json`` says so; the seed is its first) or one of its ``seed<s>``
    folders; ``None`` otherwise."""
    folder, seed = run, None
    if run.name.startswith("seed") and run.name[4:].isdigit():
        folder, seed = run.parent, int(run.name[4:])
    try:
        results = json.loads((folder / "results.json").read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(results, dict) or results.get("backend") != "jax":
        return None
    seeds = list(results.get("seeds") or [])
    if seed is None:
        if not seeds:
            return None
        seed = int(seeds[0])
    elif seed not in seeds:
        raise ValueError(f"policy {str(run)!r}: the JAX run {str(folder)!r} has seeds {seeds}, "
                         f"not {seed}")
    return folder, seed, results


def run_config(run: Path, env_id: str | None) -> RunConfig:
    """The configuration of a run folder of ``fir-gym train`` (``RunConfig.load``; a JAX
    run's from its ``results.json``), refused with a ``ValueError`` when ``run`` is not one,
    or when ``env_id`` is given and is not the env the run was trained on."""
    from .training import RunConfig

    found = jax_run(run)
    if found is not None:
        _, seed, results = found
        config = RunConfig(env_id=results["env_id"], observation_kind=results["kind"],
                           seed=seed, kind_kwargs=dict(results.get("kind_kwargs") or {}),
                           env_kwargs=dict(results.get("env_kwargs") or {}))
    elif not (run / "run.json").is_file():
        raise ValueError(f"policy must be one of {', '.join(POLICIES)} or a run folder of "
                         f"`fir-gym train` (with run.json, or a JAX run's results.json); "
                         f"{str(run)!r} is neither")
    else:
        config = RunConfig.load(run)
    if env_id is not None and env_id != config.env_id:
        raise ValueError(f"env is {env_id!r} but the run {str(run)!r} was trained on "
                         f"{config.env_id!r} (leave env out to use the run's)")
    return config


def trained_policy(run: Path, algo: str, env: gym.Env) -> Policy:
    """The run's deterministic policy for one episode, its observations normalised as in
    training (a JAX run's seed: :meth:`fir_gym.jax.policy.JaxPolicy.episode`). ``algo``: the
    run's algorithm as its hyperparameter file names it (``RunConfig.algo_name``: ``ppo``,
    ``sac``, or ``recurrent-ppo`` for the ``recurrent`` kind). A recurrent policy carries its
    LSTM state from call to call, the first call starting the episode: play one episode with
    it (``fir-gym watch`` does)."""
    found = jax_run(run)
    if found is not None:
        from ._extras import require

        require("jax", "gymnax", "rejax")
        from .jax.policy import JaxPolicy
        from .jax.train import load

        folder, seed, _ = found
        result = load(folder)
        return JaxPolicy(result, result.seeds.index(seed)).episode()
    try:
        from stable_baselines3 import PPO, SAC
        from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    except ModuleNotFoundError as err:
        raise MissingExtra(f"a run's policy needs stable-baselines3 ({err.name} is missing): "
                           f"{INSTALL['rl']}") from None
    algorithm: Any
    if algo == "recurrent-ppo":
        try:
            from sb3_contrib import RecurrentPPO
        except ModuleNotFoundError as err:
            raise MissingExtra(f"a recurrent run's policy needs sb3-contrib ({err.name} is "
                               f"missing): {INSTALL['rl']}") from None
        algorithm = RecurrentPPO
    else:
        algorithm = {"ppo": PPO, "sac": SAC}[algo]
    model = algorithm.load(run / "model.zip", device="cpu")
    stats = VecNormalize.load(str(run / "vecnormalize.pkl"), DummyVecEnv([lambda: env]))
    memory: dict[str, Any] = {"state": None, "start": np.ones(1, dtype=bool)}

    def act(obs: Any) -> NDArray[Any]:
        action, memory["state"] = model.predict(stats.normalize_obs(obs), state=memory["state"],
                                                episode_start=memory["start"],
                                                deterministic=True)
        memory["start"] = np.zeros(1, dtype=bool)
        return np.asarray(action)

    return act
