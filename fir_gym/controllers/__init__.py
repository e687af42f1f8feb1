"""Classical controllers on estimates: LQG (estimator + LQR) and PID.

Both have stable-baselines3's ``predict(observation, state=None, episode_start=None,
deterministic=True) -> (action, state)``, so ``fir_gym.training.evaluate``, SB3's
``evaluate_policy`` and ``fir-gym compare-controllers`` (kinds ``lqg`` and ``pid``)
treat them as policies. Each plant's operating point and tuning:
``plant.design_point()`` (:mod:`fir_gym.controllers.operating_points`).
"""

from .lqg import LQGController
from .lqr import LQRDesign, linearize, lqr_design
from .operating_points import DesignPoint, design_point
from .pid import PIDController

__all__ = ["DesignPoint", "LQGController", "LQRDesign", "PIDController", "design_point",
           "linearize", "lqr_design"]
