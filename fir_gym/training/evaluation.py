"""Evaluating a run: returns, and the closed-loop estimation error of its estimator.

:func:`evaluate` plays ``episodes`` episodes of a run's controller (the trained policy,
deterministic, or the classical controller of an ``lqg``/``pid`` run) on fresh seeds
``seed, seed + 1, ...`` with the raw, unnormalised rewards, and — where the controller
sees an estimate — the estimator's error on the closed loop it drives:

* ``rmse``: per state component, ``sqrt(mean((x − x̂)²))`` over every step of every
  episode (the reset step included);
* ``anees``: the average NEES ``(x − x̂)ᵀ P⁻¹ (x − x̂)`` over the same steps, divided
  by ``n_x`` (1 for a consistent filter; Bar-Shalom et al. 2001, §5.4), where the
  estimator has a covariance (steps where ``P`` is not positive definite are left out
  and counted in ``nees_skipped``);
* ``nees_median``: the median of the same per-step NEES values divided by the median of
  χ²(``n_x``) (1 for a consistent filter, as ``anees`` is the mean divided by ``n_x``,
  the mean of χ²(``n_x``)), and ``nees_in_band``: the fraction of them inside the
  two-sided 95 % band of one χ²(``n_x``) value (0.95 for a consistent filter). A few
  steps with a nearly singular ``P`` can carry the mean by orders of magnitude; the
  median and the in-band fraction show whether the rest are consistent
  (:func:`fir_gym.estimators.metrics.nees_summary`, docs/estimators/metrics.md#nees-summary).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fir_gym.estimators.metrics import nees, nees_summary

from .kinds import controller_options, is_learned, recipe
from .run import RunConfig, algorithm_class


@dataclass
class Evaluation:
    """Per-episode returns and lengths, and the closed-loop estimation error (or None).

    ``anees``, ``nees_median`` and ``nees_in_band`` are described in the module docstring.
    """

    returns: list[float]
    lengths: list[int]
    rmse: list[float] | None = None
    anees: float | None = None
    nees_skipped: int = 0
    diverged_episodes: int = 0
    nees_median: float | None = None
    nees_in_band: float | None = None

    @property
    def mean(self) -> float:
        return float(np.mean(self.returns))

    @property
    def std(self) -> float:
        return float(np.std(self.returns))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def make_eval_env(config: RunConfig) -> Any:
    """One env of ``config``'s kind (what :func:`evaluate` plays; ``make_env`` too)."""
    from .vec_env import make_single_env

    kwargs = recipe(config.observation_kind, config.kind_kwargs, config.observation).kwargs()
    return make_single_env(config.env_id, **kwargs, **config.env_kwargs)


def load_controller(config: RunConfig, run_dir: Path | None, env: Any, *, best: bool = False
                    ) -> tuple[Any, Any]:
    """``(policy with predict, observation normaliser or None)`` of a run.

    ``best`` loads the evaluation callback's ``best/best_model.zip`` (with the run's final
    normalisation statistics: SB3's callback saves none of its own).
    """
    kind = config.observation_kind
    if not is_learned(kind):
        from fir_gym.controllers import LQGController, PIDController

        if kind == "lqg":
            return LQGController(env, **controller_options(kind, config.kind_kwargs)), None
        return PIDController(env, **controller_options(kind, config.kind_kwargs)), None
    if run_dir is None:
        raise ValueError(f"a {kind} controller is learned: evaluate needs its run folder")
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    path = run_dir / "best" / "best_model.zip" if best else run_dir / "model.zip"
    if not path.is_file():
        raise ValueError(f"{run_dir} has no {path.relative_to(run_dir)}"
                         + (" (train with an eval_freq)" if best else ""))
    model = algorithm_class(config).load(path, device="cpu")
    stats = run_dir / "vecnormalize.pkl"
    normaliser = None
    if stats.is_file():
        normaliser = VecNormalize.load(str(stats), DummyVecEnv([lambda: make_eval_env(config)]))
        normaliser.training, normaliser.norm_reward = False, False
    return model, normaliser


def evaluate(run: str | Path | RunConfig, *, episodes: int = 20, seed: int = 10_000,
             best: bool = False) -> Evaluation:
    """Play ``episodes`` episodes of a run (a folder, or the config of a classical kind).

    ``best=True`` plays the evaluation callback's best model instead of the final one.
    """
    if isinstance(run, RunConfig):
        config, run_dir = run, None
    else:
        run_dir = Path(run)
        if not (run_dir / "run.json").is_file():
            raise ValueError(f"{run_dir} is not a run folder (it has no run.json)")
        config = RunConfig.load(run_dir)
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes <= 0:
        raise ValueError(f"episodes must be a positive integer; got {episodes!r}")
    env = make_eval_env(config)
    policy, normaliser = load_controller(config, run_dir, env, best=best)
    estimator = _estimator_of(env)
    returns, lengths, errors, nees_values = [], [], [], []
    skipped = diverged = 0
    for episode in range(episodes):
        obs, info = env.reset(seed=seed + episode)
        state, start, total, length, gone = None, True, 0.0, 0, False
        while True:
            if "estimation_error" in info:
                errors.append(info["estimation_error"])
                value = _nees(info, estimator)
                if value is None:
                    skipped += estimator is not None and estimator.provides_covariance
                else:
                    nees_values.append(value)
            seen = _batch(obs) if normaliser is None else normaliser.normalize_obs(_batch(obs))
            action, state = policy.predict(seen, state=state, episode_start=np.array([start]),
                                           deterministic=True)
            start = False
            obs, reward, terminated, truncated, info = env.step(np.asarray(action)[0])
            total += float(reward)
            length += 1
            gone = gone or bool(info.get("estimator_diverged", False))
            if terminated or truncated:
                break
        returns.append(total)
        lengths.append(length)
        diverged += gone
    env.close()
    n_x = len(env.unwrapped.state_names)
    summary = nees_summary(nees_values, n_x) if nees_values else None
    return Evaluation(
        returns=returns, lengths=lengths,
        rmse=np.sqrt(np.mean(np.square(errors), axis=0)).tolist() if errors else None,
        anees=float(np.mean(nees_values)) / n_x if nees_values else None,
        nees_skipped=int(skipped), diverged_episodes=int(diverged),
        nees_median=None if summary is None else summary.median / summary.expected_median,
        nees_in_band=None if summary is None else summary.in_band)


def _batch(obs: Any) -> Any:
    if isinstance(obs, dict):
        return {k: np.asarray(v)[None] for k, v in obs.items()}
    return np.asarray(obs)[None]


def _estimator_of(env: Any) -> Any:
    try:
        return env.get_wrapper_attr("estimator")
    except AttributeError:
        return None


def _nees(info: dict[str, Any], estimator: Any) -> float | None:
    if estimator is None or not estimator.provides_covariance:
        return None
    P = estimator.P
    try:
        return float(nees(info["state"], info["estimate"], P))
    except ValueError:                                # P not positive definite (start-up)
        return None
