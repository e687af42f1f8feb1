"""Observation wrappers: estimators in the loop, and the two baselines they are compared with."""

from .baselines import MeasurementObservation, TrueStateObservation
from .estimator_observation import OBSERVATION_KINDS, EstimatorObservation, default_prior
from .factory import wrap_observation
from .measurement_stack import MeasurementStack, VectorMeasurementStack
from .shadow import ShadowEstimator
from .vector_estimator_observation import VectorEstimatorObservation

__all__ = [
    "OBSERVATION_KINDS",
    "EstimatorObservation",
    "MeasurementObservation",
    "MeasurementStack",
    "ShadowEstimator",
    "TrueStateObservation",
    "VectorEstimatorObservation",
    "VectorMeasurementStack",
    "default_prior",
    "wrap_observation",
]
