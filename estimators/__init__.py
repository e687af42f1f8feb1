"""fir_gym.estimators — state estimators for the fir-gym plants.

Imports numpy and scipy only: a filter is usable without Gymnasium.
"""

from .base import Estimator
from .discretize import discretize_lti, linear_model_from_continuous
from .model import LinearModel, StateSpaceModel, SystemMatrices, TimeVaryingLinearModel
from .registry import estimator_class, estimator_names, make_estimator, register_estimator

__all__ = [
    "Estimator",
    "LinearModel",
    "StateSpaceModel",
    "SystemMatrices",
    "TimeVaryingLinearModel",
    "discretize_lti",
    "estimator_class",
    "estimator_names",
    "linear_model_from_continuous",
    "make_estimator",
    "register_estimator",
]
