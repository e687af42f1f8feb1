"""fir_gym.envs — the paper plants as Gymnasium environments.

Each plant publishes its ``model`` (a :class:`fir_gym.estimators.StateSpaceModel`
built from nominal parameters) and its :class:`DesignPoint` (the operating point and
reward weights the classical controllers design on: ``plant.design_point()``), and never
imports a concrete filter.
"""

from ._design import DesignPoint
from .carrier_motion import CarrierMotionEnv
from .orbit import OrbitEnv
from .pendulum_slider import PendulumSliderEnv
from .uncertain_oscillator import UncertainOscillatorEnv
from .van_der_pol import VanDerPolEnv

__all__ = ["CarrierMotionEnv", "DesignPoint", "OrbitEnv", "PendulumSliderEnv",
           "UncertainOscillatorEnv", "VanDerPolEnv"]
