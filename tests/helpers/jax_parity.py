"""The parity tests' tools (tests/jax): the numpy env driven by given standard normals and
the observations and errors compared as flat float64 vectors."""

from __future__ import annotations

from typing import Any

import numpy as np


class QueuedNormals:
    """Stands in for the plant's ``np_random``: serves the queued standard normals, in
    order, each call's shape checked."""

    def __init__(self) -> None:
        self.queue: list[np.ndarray] = []

    def standard_normal(self, size: Any = None) -> np.ndarray:
        z = self.queue.pop(0)
        want = (size,) if isinstance(size, int) else tuple(size)
        assert z.shape == want, f"the plant drew {want}, the queue had {z.shape}"
        return z.copy()


def flat(obs: Any) -> np.ndarray:
    """An observation as one float64 vector (a dict's entries in key order)."""
    if isinstance(obs, dict):
        return np.concatenate([np.asarray(obs[key], dtype=np.float64).reshape(-1)
                               for key in sorted(obs)])
    return np.asarray(obs, dtype=np.float64)


def flat_jax(obs: Any) -> Any:
    """:func:`flat` inside a JAX trace."""
    import jax.numpy as jnp

    if isinstance(obs, dict):
        return jnp.concatenate([jnp.reshape(obs[key], (-1,)) for key in sorted(obs)])
    return obs


def relative_error(got: np.ndarray, want: np.ndarray) -> float:
    """``max |got − want| / |want|`` elementwise (where ``want`` is 0, ``got`` must be 0)."""
    diff = np.abs(got - want)
    scale = np.abs(want)
    if np.any((scale == 0) & (diff > 0)):
        return float("inf")
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.nanmax(np.where(scale > 0, diff / scale, 0.0)))
