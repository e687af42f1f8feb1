"""One JAX CPU device per core, asked for before JAX starts.

XLA runs a program on one CPU device with one thread, so a batch on one device uses one core
however many the machine has. Sharded across several CPU devices — one per core — the parts
run side by side. JAX makes that many CPU devices only if asked before its backends start:
before the first JAX operation, and before ``import gymnax`` or :mod:`fir_gym.jax`, whose
imports start them (docs/jax.md, "Every core of a CPU"). This module is outside
:mod:`fir_gym.jax` for that reason: importing it imports nothing of JAX.
"""

from __future__ import annotations

__all__ = ["request_cpu_devices"]


def request_cpu_devices(count: int) -> int:
    """Ask JAX for ``count`` CPU devices (``jax_num_cpu_devices``); once its backends have
    started the count stays as it was. Returns the number of CPU devices JAX has.

    Raises:
        ValueError: ``count`` is not a positive integer.
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"count must be a positive integer; got {count!r}")
    import jax

    try:
        jax.config.update("jax_num_cpu_devices", count)
    except RuntimeError:                  # the backends have started: keep what they have
        pass
    return len(jax.devices("cpu"))
