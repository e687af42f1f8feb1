"""The float64 check every JAX environment makes (see :mod:`fir_gym.jax`)."""

from __future__ import annotations

import jax
import numpy as np


def require_x64() -> None:
    """Raise unless ``jax_enable_x64`` is on: the environments compute in float64.

    (Read through the dtype JAX gives float64 now: no array is made, so it is cheap inside
    a trace too.)"""
    if jax.dtypes.canonicalize_dtype(np.float64) != np.float64:
        raise RuntimeError("fir_gym.jax computes in float64, but jax_enable_x64 is off (it was "
                           "turned off after `import fir_gym.jax` turned it on); call "
                           'jax.config.update("jax_enable_x64", True)')
