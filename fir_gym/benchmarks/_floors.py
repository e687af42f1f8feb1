"""References and floors the speed command times beside the real thing.

Each is one call, timed in the same alternating blocks as what it bounds:
:func:`numpy_path` (a step with the compiled kernels off), :func:`mujoco_stepper`
(MuJoCo's own steps of one PendulumSlider-v0 env step), :func:`trivial_ekf_step`
(the filter's fixed cost), :func:`trivial_ekf_kernel` (that step's compiled kernel
alone), :func:`kalman_kernels_skipped` (the step without its kernel: its Python side) and
:func:`model_evaluation` (what an EKF step must evaluate of a plant's model).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from types import SimpleNamespace
from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.estimators import compiled


def numpy_path(step: Any, k: int) -> Any:
    """``step(k)`` with the compiled kernels switched off (the numpy reference path)."""
    compiled.ENABLED = False
    try:
        return step(k)
    finally:
        compiled.ENABLED = True


def mujoco_stepper(friction: str) -> Any:
    """MuJoCo's steps of one PendulumSlider-v0 env step alone (with its force law), no env."""
    env: Any = gym.make("fir_gym/PendulumSlider-v0", friction=friction).unwrapped
    env.reset(seed=0)
    return env.advance_physics


def trivial_ekf_step(n_batch: int) -> Any:
    """One batched EKF step on a one-state model whose callables return ready arrays: the
    fixed cost of a filter step (argument checks, bookkeeping, divergence watch, the
    compiled update) with no model evaluation to speak of."""
    from fir_gym.estimators import ExtendedKalmanFilter, StateSpaceModel

    one = np.ones((n_batch, 1, 1))
    model = StateSpaceModel(f=lambda x, u: x, F=lambda x, u: one, h=lambda x: x,
                            H=lambda x: one, Q=[[1.0]], R=[[1.0]])
    ekf = ExtendedKalmanFilter(model, x0=np.zeros((n_batch, 1)))
    y = np.zeros((n_batch, 1))
    ekf.step(y)

    def step() -> Any:
        return ekf.step(y)
    step.estimator = ekf                                  # type: ignore[attr-defined]
    return step


def trivial_ekf_kernel(n_batch: int) -> Any:
    """The compiled kernel of :func:`trivial_ekf_step`'s step called alone, with the arguments
    that step hands it (``compiled.kalman.predict_update``; its numba dispatch included)."""
    from fir_gym.estimators.compiled import kalman

    step = trivial_ekf_step(n_batch)
    state = step.estimator.state
    x, one = state.x, np.ones((n_batch, 1, 1))
    y = np.zeros((n_batch, 1))
    qd = r = np.ones((1, 1, 1))                           # the model's Q and R
    every = np.ones(n_batch, bool)
    return lambda: kalman.predict_update(state, x.copy(), one, qd, y, x.copy(), one, r, every,
                                         every)


@contextmanager
def kalman_kernels_skipped() -> Iterator[None]:
    """A block in which the EKF's compiled kernels are no-ops: what a step then costs is its
    Python side alone (checks, model calls, the kernel's arguments, copies)."""
    from fir_gym.estimators import extended

    real = extended.compiled_kalman
    extended.compiled_kalman = SimpleNamespace(           # type: ignore[assignment]
        predict_update=_no_op, linear_step=_no_op)
    try:
        yield
    finally:
        extended.compiled_kalman = real


def _no_op(*args: Any) -> None:
    return None


def model_evaluation(estimator: Any) -> Any:
    """What an EKF step must evaluate of the plant's model: ``f, F`` and ``h, H`` (batched)."""
    model = estimator.model
    linearize, (_, _, h, H) = model.unchecked_linearizer(), model.unchecked_callables()
    x, u = estimator.x, np.zeros((estimator.x.shape[0], estimator.model.n_u))

    def evaluate() -> None:
        x_next, _ = linearize(x, u)
        h(x_next)
        H(x_next)
    return evaluate
