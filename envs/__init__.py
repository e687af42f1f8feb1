"""fir_gym.envs — the paper plants as Gymnasium environments.

Each plant publishes its ``model`` (a :class:`fir_gym.estimators.StateSpaceModel`
built from nominal parameters) and never imports a concrete filter.
"""

from .carrier_motion import CarrierMotionEnv
from .orbit import OrbitEnv
from .pendulum_slider import PendulumSliderEnv
from .uncertain_oscillator import UncertainOscillatorEnv
from .van_der_pol import VanDerPolEnv

__all__ = ["CarrierMotionEnv", "OrbitEnv", "PendulumSliderEnv", "UncertainOscillatorEnv",
           "VanDerPolEnv"]
