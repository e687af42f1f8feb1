"""Copies are copies: every registered estimator on every plant it applies to, the wrappers
and the wrapped envs survive ``copy.deepcopy`` and ``pickle`` at any point of a run —
fresh, after the first step, mid-episode, after ``reset``, after a restart, diverged — and
the copy's future equals the original's bit for bit while the original is left untouched.

Oracle: the original itself. Each copy is stepped first, on the same data; then the
original, whose steps must give the same bits (a copy that shared state with it would
have moved it on, or changed what it computes next).
"""

from __future__ import annotations

import copy
import pickle
import warnings
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from plant_cases import applicable

import fir_gym
from fir_gym.estimators import estimator_class
from fir_gym.wrappers import VectorEstimatorObservation
from fir_gym.wrappers.estimator_observation import default_prior

HORIZON = 6
COPIERS: dict[str, Callable[[Any], Any]] = {
    "deepcopy": copy.deepcopy, "pickle": lambda obj: pickle.loads(pickle.dumps(obj))}


def same(a: Any, b: Any) -> bool:
    """Bit for bit, through dicts, tuples and lists (NaN equals NaN; dtypes must agree)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(map(same, a, b))
    if isinstance(a, (np.ndarray, np.generic, float)):
        a_, b_ = np.atleast_1d(a), np.atleast_1d(b)
        return a_.dtype == b_.dtype and a_.shape == b_.shape and bool(
            np.array_equal(a_.view(np.uint8), b_.view(np.uint8)))
    return bool(a == b)


CASES = applicable()


def build(env_id: str, name: str, batch: int | None, **options: Any) -> tuple[Any, Any, Any]:
    """The estimator on the plant's model (its prior; FIR horizon 6) and data for it: the
    measurements and applied inputs of one rollout, ``(steps, [B,] n)``."""
    env = gym.make(env_id)
    plant = env.unwrapped
    cls = estimator_class(name)
    x0, P0 = default_prior(env)
    opts: dict[str, Any] = {"x0": x0, "P0": P0} if x0 is not None else {}
    if "fir" in name:
        opts["horizon"] = HORIZON
    flt = cls(getattr(plant, cls.model_attribute), **opts, **options)
    rng = np.random.default_rng(5)
    y, _ = env.reset(seed=2)
    Y, U = [y], [np.zeros(env.action_space.shape)]
    while len(Y) < 30:
        action = 0.3 * rng.uniform(-1, 1, env.action_space.shape)
        y, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            y, _ = env.reset()
        Y.append(y)
        U.append(info["action"])
    env.close()
    Y_, U_ = np.array(Y, dtype=np.float64), np.array(U, dtype=np.float64)
    if batch is not None:                    # the rollout, a little noise per system
        sd = np.sqrt(np.diag(np.atleast_2d(flt.model.R)))
        Y_ = Y_[:, None] + 0.1 * sd * rng.standard_normal((len(Y_), batch, Y_.shape[1]))
        U_ = np.repeat(U_[:, None], batch, axis=1)
    return flt, Y_, U_


def future(flt: Any, Y: np.ndarray, U: np.ndarray, start: int, steps: int = 5) -> list[Any]:
    """What ``flt`` does next: estimate, covariance, flag and diagnostics of each step."""
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k in range(start, start + steps):
            x = flt.step(Y[k % len(Y)], None if k == 0 else U[k % len(U)])
            out.append((x, flt.P, flt.diverged, flt.last_info, flt.time_step))
    return out


def check_copies(flt: Any, Y: np.ndarray, U: np.ndarray, k: int) -> None:
    """Copies of ``flt`` (at step ``k``) step like it, and leave it as it was."""
    before = flt.time_step
    futures = {how: future(copier(flt), Y, U, k) for how, copier in COPIERS.items()}
    assert flt.time_step == before
    mine = future(flt, Y, U, k)
    for how, theirs in futures.items():
        assert same(theirs, mine), how


@pytest.mark.parametrize("batch", [None, 3])
@pytest.mark.parametrize(("env_id", "name"), CASES)
def test_estimator_copies_step_like_the_original(env_id: str, name: str, batch: int | None
                                                 ) -> None:
    flt, Y, U = build(env_id, name, batch)
    prior = flt.x, flt.P                     # before the first step: the prior
    check_copies(flt, Y, U, 0)                                       # fresh
    future(flt, Y, U, 0, 1)
    check_copies(flt, Y, U, 1)                                       # after the first step
    future(flt, Y, U, 1, 6)
    check_copies(flt, Y, U, 7)                                       # mid-episode
    if batch:
        flt.restart([1])
        check_copies(flt, Y, U, 7)                                   # a system restarted
    flt.reset(*prior)
    check_copies(flt, Y, U, 0)                                       # after reset


@pytest.mark.parametrize(("env_id", "name"), CASES)
def test_diverged_estimator_copies_step_like_the_original(env_id: str, name: str) -> None:
    """A filter flagged diverged (a covariance limit every filter exceeds, on measurements
    whose noise is ten times the model's) copies with its flag and its last estimate."""
    flt, Y, U = build(env_id, name, None, max_covariance_trace=1e-12)
    sd = np.sqrt(np.diag(np.atleast_2d(flt.model.R)))
    Y = Y + 10.0 * sd * np.random.default_rng(6).standard_normal(Y.shape)
    future(flt, Y, U, 0, 8)
    assert flt.diverged
    check_copies(flt, Y, U, 8)


def wrapped_future(env: gym.Env, steps: int = 4) -> list[Any]:
    actions = np.linspace(-0.5, 0.5, steps)
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for a in actions:
            out.append(env.step(np.full(env.action_space.shape, a, dtype=np.float32)))
    return out


@pytest.mark.parametrize(("env_id", "name"), CASES)
def test_wrapped_env_pickled_after_reset_and_step(env_id: str, name: str) -> None:
    """What Gymnasium's own env tests do — ``gym.make``, ``reset``, ``step``, pickle — and the
    copy's steps (observations, rewards, flags, info) equal the original's."""
    kwargs = {"estimator_kwargs": {"horizon": HORIZON}} if "fir" in name else {}
    env = gym.make(env_id, estimator=name, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env.reset(seed=4)
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    copies = {how: copier(env) for how, copier in COPIERS.items()}
    futures = {how: wrapped_future(twin) for how, twin in copies.items()}
    mine = wrapped_future(env)
    for how, theirs in futures.items():
        assert same(theirs, mine), how
    for twin in (*copies.values(), env):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            assert same(twin.reset(seed=9), copies["pickle"].reset(seed=9))
        twin.close()


@pytest.mark.parametrize("mode", ["vector_entry_point", "sync"])
@pytest.mark.parametrize("env_id", fir_gym.VECTOR_ENV_IDS)
def test_vector_estimator_observation_copies(env_id: str, mode: str) -> None:
    """The vector wrapper with its batched EKF over a native or sync vector env, copied
    mid-run (after an autoreset restarted some systems): the copies step like it.
    (Gymnasium's sync vector env from ``make_vec`` keeps its env factories as local
    functions, which do not pickle: it is deep-copied only.)"""
    envs = VectorEstimatorObservation(gym.make_vec(env_id, 4, vectorization_mode=mode), "ekf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        envs.reset(seed=1)
        for k in range(3):
            envs.step(np.full(envs.action_space.shape, 0.2 * k, dtype=np.float32))
        envs._prev_done[[0, 2]] = True                     # two sub-envs autoreset next step
    copies = {how: copier(envs) for how, copier in COPIERS.items()
              if how == "deepcopy" or mode != "sync"}
    futures = {how: wrapped_future(twin) for how, twin in copies.items()}
    mine = wrapped_future(envs)
    for how, theirs in futures.items():
        assert same(theirs, mine), how
    for twin in (*copies.values(), envs):
        twin.close()
