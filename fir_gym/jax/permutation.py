"""``jax.random.permutation(key, n)`` to the bit, with a sort XLA's CPU backend runs fast.

JAX draws a permutation of ``n`` by sorting ``0, …, n − 1`` by random 32-bit keys, in as many
rounds as make ties negligible (``⌈3 ln n / ln(2³² − 1)⌉``: two for PPO's 4096 samples), each
round a *stable* key-value sort (``lax.sort_key_val``) by fresh keys. On a CPU, XLA sorts
several operands with a compiled comparator called per comparison: one such sort of 4096
took 0.68 ms on the development machine, and PPO's ten epochs of an iteration drew ten
permutations, two sorts each — about a quarter of the JAX PPO's time on an environment whose
step costs nothing (a profile of ``fir_gym.benchmarks.jax_training.free_env``'s training).

A stable sort of ``(key, value)`` is one unstable sort of the composite ``key · 2³² + i``
(``i``: the position; a key's ties keep their order) — a single unsigned 64-bit operand,
which XLA sorts without a comparator call per pair (0.15 ms for 4096). The values then follow
by a gather. The permutation is the same, bit for bit, because a stable sort's result is
determined by its keys (``tests/jax/test_permutation.py`` compares it with
``jax.random.permutation`` and the stable sort with ``lax.sort_key_val`` on keys full of ties).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ._x64 import require_x64

#: the rounds' exponent of ``jax.random.permutation`` (``jax._src.random``'s ``_shuffle``)
EXPONENT = 3


def rounds(n: int) -> int:
    """How many sorts ``jax.random.permutation`` makes for ``n`` elements."""
    return math.ceil(EXPONENT * np.log(max(1, n)) / np.log(np.iinfo(np.uint32).max))


def stable_order(keys: jax.Array) -> jax.Array:
    """The positions ``0, …, n − 1`` of the 32-bit unsigned ``keys`` in a stable sort by key
    (the second result of ``lax.sort_key_val(keys, arange(n))``), by one sort of
    ``key · 2³² + position``."""
    require_x64()                                  # the composite keys are 64-bit
    n = keys.shape[0]
    if n >= 2 ** 32:
        raise ValueError(f"keys must have fewer than 2**32 entries; got {n}")
    composite = (keys.astype(jnp.uint64) << 32) | jnp.arange(n, dtype=jnp.uint64)
    return (jax.lax.sort(composite) & jnp.uint64(0xFFFFFFFF)).astype(jnp.int64)


def permutation(key: jax.Array, n: int) -> jax.Array:
    """``jax.random.permutation(key, n)``, the same integers (int64 under x64), each round's
    stable sort done by :func:`stable_order`."""
    x = jnp.arange(n)
    for _ in range(rounds(n)):
        key, subkey = jax.random.split(key)
        x = x[stable_order(jax.random.bits(subkey, (n,), jnp.uint32))]
    return x
