"""What a filter of :mod:`fir_gym.jax` believes about a plant: :class:`FilterModel`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import jax


@dataclass(frozen=True)
class FilterModel:
    """What a filter believes about a plant, as pure JAX functions of one system (the
    :class:`fir_gym.estimators.model.StateSpaceModel` a numpy plant publishes as ``model``,
    built from the params' ``nominal_*`` fields inside the traced step):

    * ``f(x, u)``: the model's state after one env step from ``x`` under the applied (clipped)
      action ``u`` (shape ``(1,)``), no noise;
    * ``f_and_F(x, u)``: ``f`` and its Jacobian ``∂f/∂x`` at ``x``;
    * ``H``: the measurement matrix (every fir-gym plant measures linearly, ``y = H x + v``);
    * ``Q``: the process noise covariance the model adds per step (``G Q Gᵀ``), ``n_x × n_x``;
    * ``R``: the measurement noise covariance, ``n_y × n_y``.
    """

    f: Callable[[jax.Array, jax.Array], jax.Array]
    f_and_F: Callable[[jax.Array, jax.Array], tuple[jax.Array, jax.Array]]
    H: jax.Array
    Q: jax.Array
    R: jax.Array
