"""The generic filter kinds of :mod:`fir_gym.jax`: filters any plant runs on its
:meth:`~fir_gym.jax._plant.FilteredPlant.filter_model`.

A plant's own filter (``"ekf"``, ``"kf"``) runs inside the plant's step, where it can share
the plant's integration loop; the kinds here run after it
(:meth:`~fir_gym.jax._plant.FilteredPlant.finish_step`) on the model alone, each as a
:class:`FilterKind`: the memory it keeps beyond the mean and covariance (a pytree in the env
state's ``memory``), its update at a reset and its step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax

from . import fir
from ._plant import FilterModel

#: (memory, x, P, nis) after an update or a step
Result = tuple[Any, jax.Array, jax.Array, jax.Array]


@dataclass(frozen=True)
class FilterKind:
    """One generic filter: ``start(x0, P0, horizon, model) -> memory`` (after the prior is
    set, before the first measurement), ``update(memory, x, P, y, model)`` (the reset's
    update with ``y[0]``) and ``predict_update(memory, x, P, y, u, model)`` (one env step
    under the applied action ``u``), each returning ``(memory, x, P, nis)`` with NaN where
    the numpy filter fails (the divergence watch then keeps the last finite estimate)."""

    start: Callable[[jax.Array, jax.Array, int, FilterModel], Any]
    update: Callable[[Any, jax.Array, jax.Array, jax.Array, FilterModel], Result]
    predict_update: Callable[[Any, jax.Array, jax.Array, jax.Array, jax.Array, FilterModel],
                             Result]


#: the generic filter kinds by name (the numpy registry's names)
GENERIC_FILTERS: dict[str, FilterKind] = {
    "efir": FilterKind(fir.efir_start, fir.efir_update, fir.efir_predict_update),
}
