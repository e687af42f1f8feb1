"""Every (plant, estimator) pair the package supports (importable: pytest's ``pythonpath``
has this folder)."""

from __future__ import annotations

import warnings

import gymnasium as gym

import fir_gym


def applicable() -> list[tuple[str, str]]:
    """(plant id, estimator name) of every registered estimator that accepts the plant."""
    from fir_gym.benchmarks.estimators import _applicable

    cases = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for env_id in fir_gym.ENV_IDS:
            env = gym.make(env_id)
            cases += [(env_id, name) for name, _, _ in _applicable(env)]
            env.close()
    return cases


def kalman_filters() -> list[type]:
    """The Kalman-family classes that share the sequence, smoother and public-step API."""
    from fir_gym.estimators import (
        ExtendedKalmanFilter,
        KalmanFilter,
        LinearizedKalmanFilter,
        UnscentedKalmanFilter,
    )

    return [KalmanFilter, ExtendedKalmanFilter, LinearizedKalmanFilter, UnscentedKalmanFilter]
