"""Monte Carlo building blocks of the paper scenarios: seeded episode tasks, batched filtering.

A scenario's Monte Carlo is split into tasks for :class:`~.runner.Runner` — each a
picklable :class:`EpisodeTask` or :class:`VectorTask` that carries its own seed —
so the same seeds give bit-identical data serially, with joblib and on Dask. The
filters then run *batched* over all runs in this process (one filter, ``B``
systems), which costs about as much as one run.

* :func:`simulate_episode` — one episode of a registered env (its own generator),
  the data of one Monte Carlo run;
* :func:`simulate_vector` — ``n`` runs at once in the plant's native vector env
  (one generator for the chunk; cheap for plants whose single step is slow);
* :func:`stack_episodes`, :func:`run_filter`, :func:`rmse_per_step` — gather and
  evaluate.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.estimators import Estimator


def task_seed(seed: int, *keys: int) -> int:
    """A 32-bit seed for one task, derived from the scenario ``seed`` and the task's ``keys``.

    ``SeedSequence([seed, *keys])`` keeps the streams of different tasks (and of
    different scenario seeds) apart without bookkeeping.
    """
    return int(np.random.SeedSequence([int(seed), *map(int, keys)]).generate_state(1)[0])


@dataclass(frozen=True)
class EpisodeTask:
    """One episode of ``env_id``: ``steps`` env steps after ``reset(seed=seed)``.

    ``actions`` (``(steps, n_u)``, normalised) default to zero; ``reset_state`` is
    passed as ``reset(options={"state": ...})``.
    """

    env_id: str
    seed: int
    steps: int
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    actions: np.ndarray | None = None
    reset_state: tuple[float, ...] | None = None


@dataclass
class Episodes:
    """Runs stacked along axis 1: ``X (K+1, B, n_x)``, ``Y (K+1, B, n_y)``, ``U (K, B, n_u)``.

    A run whose episode terminated early (left the plant's domain) holds NaN after
    its last step; ``steps[b]`` counts its valid instants.
    """

    X: np.ndarray
    Y: np.ndarray
    U: np.ndarray
    steps: np.ndarray


def simulate_episode(task: EpisodeTask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run one episode; returns ``(X, Y, U)`` with NaN after an early termination."""
    env = gym.make(task.env_id, max_episode_steps=task.steps + 1, **dict(task.env_kwargs))
    options = None if task.reset_state is None else {"state": list(task.reset_state)}
    y, info = env.reset(seed=task.seed, options=options)
    n_u = _width(env.action_space)
    X = np.full((task.steps + 1, info["state"].size), np.nan)
    Y = np.full((task.steps + 1, y.size), np.nan)
    U = np.zeros((task.steps, n_u))
    X[0], Y[0] = info["state"], y
    zero = np.zeros(n_u, dtype=np.float32)
    for k in range(task.steps):
        a = zero if task.actions is None else task.actions[k]
        y, _, terminated, _, info = env.step(a)
        X[k + 1], Y[k + 1], U[k] = info["state"], y, info["action"]
        if terminated:
            break
    env.close()
    return X, Y, U


@dataclass(frozen=True)
class VectorTask:
    """``n`` zero-input runs of ``env_id``'s native vector env, seeded once with ``seed``."""

    env_id: str
    seed: int
    n: int
    steps: int
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)


def simulate_vector(task: VectorTask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run ``task.n`` systems in lock-step; returns ``(X, Y, U)`` like :func:`simulate_episode`."""
    env = gym.make_vec(task.env_id, num_envs=task.n, vectorization_mode="vector_entry_point",
                       max_episode_steps=task.steps + 1, **dict(task.env_kwargs))
    y, info = env.reset(seed=task.seed)
    n_u = _width(env.single_action_space)
    X = np.full((task.steps + 1, task.n, info["state"].shape[1]), np.nan)
    Y = np.full((task.steps + 1, task.n, y.shape[1]), np.nan)
    U = np.zeros((task.steps, task.n, n_u))
    X[0], Y[0] = info["state"], y
    alive = np.ones(task.n, bool)
    action = np.zeros((task.n, n_u))
    for k in range(task.steps):
        y, _, terminated, _, info = env.step(action)
        X[k + 1] = np.where(alive[:, None], info["state"], np.nan)
        Y[k + 1] = np.where(alive[:, None], y, np.nan)
        alive &= ~terminated
    env.close()
    return X, Y, U


def _width(space: Any) -> int:
    """The size of a ``Box`` action space (the plants' spaces are one-dimensional boxes)."""
    return int(space.shape[0])


def stack_episodes(results: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> Episodes:
    """Stack the outputs of :func:`simulate_episode` / :func:`simulate_vector` along runs."""
    def cat(i: int) -> np.ndarray:
        parts = [r[i][:, None] if r[i].ndim == 2 else r[i] for r in results]
        return np.concatenate(parts, axis=1)

    X, Y, U = cat(0), cat(1), cat(2)
    steps = np.isfinite(Y[..., 0]).sum(axis=0)
    return Episodes(X, Y, U, steps)


def chunks(runs: int, size: int) -> list[int]:
    """Split ``runs`` into chunks of at most ``size`` (fixed by the scenario, not the backend)."""
    full, rest = divmod(runs, size)
    return [size] * full + ([rest] if rest else [])


@dataclass
class FilterRun:
    """Estimates ``x (K+1, B, n)``, covariances ``P (K+1, B, n, n)`` (or None), and flags."""

    x: np.ndarray
    P: np.ndarray | None
    diverged: np.ndarray


def run_filter(estimator: Estimator, Y: np.ndarray, U: np.ndarray | None = None, *,
               covariance: bool = False) -> FilterRun:
    """Feed ``Y[0]``, then ``(Y[k], U[k-1])`` to a batched ``estimator``.

    The estimator's ``nan_policy`` decides what a NaN measurement (a run that
    ended early) does; the scenarios pass ``"skip"``.
    """
    xs, Ps = [], []
    for k in range(Y.shape[0]):
        xs.append(estimator.step(Y[k], None if (k == 0 or U is None) else U[k - 1]))
        if covariance:
            Ps.append(estimator.P)
    return FilterRun(np.array(xs), np.array(Ps) if covariance else None,
                     np.asarray(estimator.diverged))


def rmse_per_step(err: np.ndarray) -> np.ndarray:
    """Monte Carlo RMSE at every step of errors ``(K+1, B)`` (runs that ended are ignored)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.sqrt(np.nanmean(err * err, axis=1))


def nees_per_step(err: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Run-averaged NEES ``eᵀ P⁻¹ e`` at every step (``err (K+1, B, n)``, ``P (K+1, B, n, n)``)."""
    w = np.linalg.solve(P, err[..., None])[..., 0]
    return np.mean(np.einsum("kbi,kbi->kb", err, w), axis=1)
