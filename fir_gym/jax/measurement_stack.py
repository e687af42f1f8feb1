"""The memory baseline of :mod:`fir_gym.jax`: the last ``K`` measurements and actions.

The twin of :class:`fir_gym.wrappers.measurement_stack.MeasurementStack` (kind
``"measurement-stack"``): the observation is ``[y[k−K+1], …, y[k], a[k−K], …, a[k−1]]``
(oldest first, ``K·n_y + K·n_u`` numbers), padded at a reset with the episode's first
measurement and zero actions; each step shifts both windows by one and appends the new
measurement (a failed step's repeated one) and the applied, clipped action. The windows
live in the env state (:class:`StackMemory`), so the kind is as pure as the plant.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class StackMemory:
    """The window of the last ``K`` measurements ``y`` (K, n_y) and actions ``a`` (K, n_u),
    oldest first."""

    y: Any
    a: Any


def stack_start(y: jax.Array, horizon: int, n_u: int = 1) -> StackMemory:
    """The windows at a reset: ``K`` copies of the first measurement, zero actions
    (:meth:`MeasurementStack.reset`)."""
    y = jnp.reshape(y, (-1,))
    return StackMemory(jnp.broadcast_to(y, (horizon, y.shape[0])),
                       jnp.zeros((horizon, n_u), dtype=y.dtype))


def stack_push(memory: StackMemory, y: jax.Array, a: jax.Array) -> StackMemory:
    """The windows after a step: both shifted by one, ``y`` and the applied ``a`` appended
    (:meth:`MeasurementStack.step`)."""
    return StackMemory(jnp.concatenate([memory.y[1:], jnp.reshape(y, (1, -1))]),
                       jnp.concatenate([memory.a[1:], jnp.reshape(a, (1, -1))]))


def stack_observation(memory: StackMemory) -> jax.Array:
    """``[y window, a window]`` flattened row by row (:meth:`MeasurementStack._window`)."""
    return jnp.concatenate([memory.y.ravel(), memory.a.ravel()])
