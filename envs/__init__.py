"""fir_gym.envs — the paper plants as Gymnasium environments.

Each plant publishes its ``model`` (a :class:`fir_gym.estimators.StateSpaceModel`
built from nominal parameters) and its :class:`DesignPoint` (the operating point and
reward weights the classical controllers design on: ``plant.design_point()``), and never
imports a concrete filter. :class:`ModelPlant` is a plant built from a user's own model
(docs/tutorials/your-own-plant.md).
"""

from ._design import DesignPoint
from .carrier_motion import CarrierMotionEnv
from .model_plant import ModelPlant
from .orbit import OrbitEnv
from .pendulum_slider import PendulumSliderEnv
from .uncertain_oscillator import UncertainOscillatorEnv
from .van_der_pol import VanDerPolEnv

__all__ = ["CarrierMotionEnv", "DesignPoint", "ModelPlant", "OrbitEnv", "PendulumSliderEnv",
           "UncertainOscillatorEnv", "VanDerPolEnv"]
