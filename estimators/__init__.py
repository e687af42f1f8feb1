"""fir_gym.estimators — state estimators for the fir-gym plants.

Imports numpy and scipy only: a filter is usable without Gymnasium. Importing
this package registers every estimator's short name (``make_estimator("ekf", model)``).
"""

from . import bounds, continuous_fir, fir_gains
from .augment import AugmentedModel, ParametricModel, augment
from .base import Estimator
from .bpf import BlockPulseKalmanFilter
from .cd_ekf import ContinuousDiscreteEKF
from .continuous import ContinuousModel
from .continuous_estimator import ContinuousEstimator
from .discretize import discretize_lti, integrated_noise, linear_model_from_continuous
from .efir import ExtendedFIRFilter
from .em import EMResult, em
from .errors import EstimatorOptionError, IncompatibleModelError
from .extended import ExtendedKalmanFilter
from .fir import FIRFilter
from .fir_smoother import FIRSmoother
from .kalman import Innovation, KalmanFilter, kf_predict, kf_update
from .linearized import LinearizedKalmanFilter
from .metrics import (
    NEESSummary,
    anees,
    chi2_band,
    mean_nis,
    nees,
    nees_summary,
    nis,
    rmse,
    within_band,
)
from .model import LinearModel, StateSpaceModel, SystemMatrices, TimeVaryingLinearModel
from .recursive_fir import RecursiveFIRFilter
from .registry import estimator_class, estimator_names, make_estimator, register_estimator
from .ufir import UFIRFilter
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
    "ContinuousEstimator",
    "ContinuousModel",
    "CubatureSigmaPoints",
    "EMResult",
    "Estimator",
    "EstimatorOptionError",
    "ExtendedFIRFilter",
    "ExtendedKalmanFilter",
    "FIRFilter",
    "FIRSmoother",
    "IncompatibleModelError",
    "Innovation",
    "KalmanFilter",
    "LinearModel",
    "LinearizedKalmanFilter",
    "MerweScaledSigmaPoints",
    "NEESSummary",
    "ParametricModel",
    "RecursiveFIRFilter",
    "SigmaPoints",
    "StateSpaceModel",
    "SystemMatrices",
    "TimeVaryingLinearModel",
    "UFIRFilter",
    "UnscentedKalmanFilter",
    "anees",
    "augment",
    "bounds",
    "chi2_band",
    "continuous_fir",
    "discretize_lti",
    "em",
    "estimator_class",
    "estimator_names",
    "fir_gains",
    "integrated_noise",
    "kf_predict",
    "kf_update",
    "linear_model_from_continuous",
    "make_estimator",
    "matrix_sqrt",
    "mean_nis",
    "nees",
    "nees_summary",
    "nis",
    "register_estimator",
    "rmse",
    "unscented_transform",
    "within_band",
]
