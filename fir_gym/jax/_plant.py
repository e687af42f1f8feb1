"""What every plant of :mod:`fir_gym.jax` shares with the numpy plants it mirrors."""

from __future__ import annotations

import jax
import jax.numpy as jnp

#: the numpy plants' ``STATE_LIMIT`` (:data:`fir_gym.envs._base.STATE_LIMIT`; PendulumSlider-v0
#: has its own)
STATE_LIMIT = 1e150
#: what an estimator kind observes (``OBSERVATION_KINDS`` of
#: :mod:`fir_gym.wrappers.estimator_observation`)
OBSERVATIONS = ("estimate", "estimate+covariance", "estimate+measurement")
#: ``info["simulation_failure"]`` codes (0: none), the numpy plants' names in this order
SIMULATION_FAILURES = ("nonfinite_state", "state_overflow", "nonfinite_observation",
                       "nonfinite_reward")
#: the prior floor of :mod:`fir_gym.wrappers.estimator_observation` (``PRIOR_FLOOR``)
PRIOR_FLOOR = 1e-9


def psd_sqrt(M: jax.Array) -> jax.Array:
    """``V Λ₊^½`` with ``M = V Λ Vᵀ``: :func:`fir_gym.envs._base.psd_sqrt`, the square root
    that turns standard normals into a plant's noise increments."""
    w, V = jnp.linalg.eigh(M)
    return V * jnp.sqrt(jnp.clip(w, 0.0, None))
