"""fir_gym.envs — the paper plants as Gymnasium environments.

Each plant publishes its ``model`` (a :class:`fir_gym.estimators.StateSpaceModel`
built from nominal parameters) and never imports a concrete filter.
"""

from .orbit import OrbitEnv

__all__ = ["OrbitEnv"]
