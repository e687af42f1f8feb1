"""An estimator run beside the loop: it sees what the controller sees, and feeds nothing back."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from fir_gym.estimators import Estimator

from .estimator_observation import EstimatorObservation


class ShadowEstimator(EstimatorObservation):
    """Run an estimator in shadow mode: the observation stays the plant's measurement.

    The estimator is built and fed exactly as by :class:`EstimatorObservation` (the
    plant's model and prior, ``y[k]`` with the applied action), and ``info`` gains
    ``estimate``, ``estimation_error``, ``estimator_diverged`` and ``estimator_info``,
    and ``render()`` draws the estimate over the plant's frame — but the observation
    (and its space) is the wrapped env's, unchanged. Use it to watch or log an
    estimator next to a controller that sees something else: the raw measurement, or
    (under :class:`~fir_gym.wrappers.TrueStateObservation`) the true state, as
    ``fir-gym watch`` does for a run trained on those.

    Args:
        env: a fir-gym plant (possibly wrapped) whose observation is the measurement.
        estimator: an :class:`~fir_gym.estimators.Estimator` instance, class or
            registry name.
        **options: the estimator's options, as for :class:`EstimatorObservation`.
    """

    def __init__(self, env: gym.Env, estimator: Estimator | type[Estimator] | str,
                 **options: Any) -> None:
        super().__init__(env, estimator, observation="estimate", **options)
        self.observation_space = env.observation_space

    def _observe(self, x_hat: NDArray[np.float64], y: NDArray[np.float64]) -> Any:
        return y
