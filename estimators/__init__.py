"""fir_gym.estimators — state estimators for the fir-gym plants.

Imports numpy and scipy only: a filter is usable without Gymnasium. Importing
this package registers every estimator's short name (``make_estimator("ekf", model)``).
"""

from . import bounds, continuous_fir
from .augment import AugmentedModel, ParametricModel, augment
from .base import Estimator
from .bpf import BlockPulseKalmanFilter
from .cd_ekf import ContinuousDiscreteEKF
from .continuous import ContinuousModel
from .discretize import discretize_lti, linear_model_from_continuous
from .extended import ExtendedKalmanFilter
from .kalman import Innovation, KalmanFilter, LinearizedKalmanFilter, kf_predict, kf_update
from .metrics import anees, chi2_band, mean_nis, nees, nis, rmse, within_band
from .model import LinearModel, StateSpaceModel, SystemMatrices, TimeVaryingLinearModel
from .registry import estimator_class, estimator_names, make_estimator, register_estimator
from .unscented import (
    CubatureSigmaPoints,
    MerweScaledSigmaPoints,
    SigmaPoints,
    UnscentedKalmanFilter,
    matrix_sqrt,
    unscented_transform,
)

__all__ = [
    "AugmentedModel",
    "BlockPulseKalmanFilter",
    "ContinuousDiscreteEKF",
    "ContinuousModel",
    "CubatureSigmaPoints",
    "Estimator",
    "ExtendedKalmanFilter",
    "Innovation",
    "KalmanFilter",
    "LinearModel",
    "LinearizedKalmanFilter",
    "MerweScaledSigmaPoints",
    "ParametricModel",
    "SigmaPoints",
    "StateSpaceModel",
    "SystemMatrices",
    "TimeVaryingLinearModel",
    "UnscentedKalmanFilter",
    "anees",
    "augment",
    "bounds",
    "chi2_band",
    "continuous_fir",
    "discretize_lti",
    "estimator_class",
    "estimator_names",
    "kf_predict",
    "kf_update",
    "linear_model_from_continuous",
    "make_estimator",
    "matrix_sqrt",
    "mean_nis",
    "nees",
    "nis",
    "register_estimator",
    "rmse",
    "unscented_transform",
    "within_band",
]
