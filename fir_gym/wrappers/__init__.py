"""Observation wrappers: estimators in the loop, and the two baselines they are compared with.

The names are imported on first use (PEP 562), so ``import fir_gym`` — which registers
the ids through :mod:`.factory` — loads no estimator and no numba: ``fir-gym --help``
stays fast.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .baselines import (
        MeasurementObservation,
        TrueStateObservation,
        VectorTrueStateObservation,
    )
    from .estimator_observation import OBSERVATION_KINDS, EstimatorObservation, default_prior
    from .factory import wrap_observation
    from .measurement_stack import MeasurementStack, VectorMeasurementStack
    from .sensor_faults import SensorFaults, VectorSensorFaults
    from .shadow import ShadowEstimator
    from .vector_estimator_observation import VectorEstimatorObservation

#: public name -> the module that defines it
_MODULES = {
    "OBSERVATION_KINDS": "estimator_observation",
    "EstimatorObservation": "estimator_observation",
    "MeasurementObservation": "baselines",
    "MeasurementStack": "measurement_stack",
    "SensorFaults": "sensor_faults",
    "VectorSensorFaults": "sensor_faults",
    "ShadowEstimator": "shadow",
    "TrueStateObservation": "baselines",
    "VectorEstimatorObservation": "vector_estimator_observation",
    "VectorMeasurementStack": "measurement_stack",
    "VectorTrueStateObservation": "baselines",
    "default_prior": "estimator_observation",
    "wrap_observation": "factory",
}

__all__ = [
    "OBSERVATION_KINDS",
    "EstimatorObservation",
    "MeasurementObservation",
    "MeasurementStack",
    "SensorFaults",
    "ShadowEstimator",
    "TrueStateObservation",
    "VectorEstimatorObservation",
    "VectorMeasurementStack",
    "VectorSensorFaults",
    "VectorTrueStateObservation",
    "default_prior",
    "wrap_observation",
]


def __getattr__(name: str) -> Any:
    if name not in _MODULES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_MODULES[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
