"""The generic filter kinds of :mod:`fir_gym.jax`: filters any plant runs on its
:meth:`~fir_gym.jax._plant.FilteredPlant.filter_model`.

A plant's own filter (``"ekf"``, ``"kf"``) runs inside the plant's step, where it can share
the plant's integration loop; the kinds here run after it
(:meth:`~fir_gym.jax._plant.FilteredPlant.finish_step`) on the model alone, each as a
:class:`FilterKind` — its options (the numpy filter's keywords the JAX twin supports, all
static), the memory it keeps beyond the mean and covariance (a pytree in the env state's
``memory``), its update at a reset and its step:

* ``"ukf"`` — :mod:`fir_gym.jax.unscented` (:class:`~fir_gym.estimators.unscented.
  UnscentedKalmanFilter`; options ``alpha``, ``beta``, ``kappa``);
* ``"efir"`` — :mod:`fir_gym.jax.fir` (:class:`~fir_gym.estimators.efir.ExtendedFIRFilter`
  as the env builds it; option ``horizon``);
* ``"fir"`` — :mod:`fir_gym.jax.fir` (:class:`~fir_gym.estimators.fir.FIRFilter`, linear
  plants; option ``horizon``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import jax

from . import fir, unscented
from .filter_model import FilterModel

#: (memory, x, P, nis) after an update or a step
Result = tuple[Any, jax.Array, jax.Array, jax.Array]


@dataclass(frozen=True)
class FilterKind:
    """One generic filter. ``options``: the option names and their defaults (``None``
    for ``horizon``: the plant's ``default_horizon``). ``start(x0, P0, options)`` is the
    memory after the prior is set, before the first measurement; ``update(memory, x, P,
    y, model, options)`` the reset's update with ``y[0]``; ``predict_update(memory, x, P, y,
    u, model, options)`` one env step under the applied action ``u``. Each returns
    ``(memory, x, P, nis)`` with NaN where the numpy filter fails (the divergence watch
    then keeps the last finite estimate)."""

    options: Mapping[str, Any]
    start: Callable[[jax.Array, jax.Array, Mapping[str, Any]], Any]
    update: Callable[[Any, jax.Array, jax.Array, jax.Array, FilterModel, Mapping[str, Any]],
                     Result]
    predict_update: Callable[[Any, jax.Array, jax.Array, jax.Array, jax.Array, FilterModel,
                              Mapping[str, Any]], Result]

    def check(self, n_x: int, options: Mapping[str, Any]) -> None:
        """ValueError naming a bad option value (the names and defaults are the env's
        business, :class:`~fir_gym.jax._plant.FilteredPlant`)."""
        if "alpha" in options:
            _weights(n_x, options)


def _weights(n: int, options: Mapping[str, Any]) -> unscented.SigmaWeights:
    return unscented.merwe_weights(n, float(options["alpha"]), float(options["beta"]),
                                   float(options["kappa"]))


def _ukf_update(memory: Any, x: jax.Array, P: jax.Array, y: jax.Array, model: FilterModel,
                options: Mapping[str, Any]) -> Result:
    return (memory, *unscented.ukf_update(x, P, y, model, _weights(x.shape[-1], options)))


def _ukf_step(memory: Any, x: jax.Array, P: jax.Array, y: jax.Array, u: jax.Array,
              model: FilterModel, options: Mapping[str, Any]) -> Result:
    return (memory, *unscented.ukf_predict_update(x, P, y, u, model,
                                                      _weights(x.shape[-1], options)))


UKF = FilterKind(
    options={"alpha": 1e-3, "beta": 2.0, "kappa": 0.0},
    start=lambda x0, P0, options: (),
    update=_ukf_update, predict_update=_ukf_step)


def _windowed(start: Callable[..., Any], update: Callable[..., Result],
              predict_update: Callable[..., Result]) -> FilterKind:
    """A FIR-family filter of :mod:`fir_gym.jax.fir`: one option, ``horizon`` (the bank's
    length), which only its memory's start needs."""
    return FilterKind(
        options={"horizon": None},
        start=lambda x0, P0, options: start(x0, P0, options["horizon"]),
        update=lambda memory, x, P, y, model, options: update(memory, x, P, y, model),
        predict_update=lambda memory, x, P, y, u, model, options: predict_update(
            memory, x, P, y, u, model))


EFIR = _windowed(fir.efir_start, fir.efir_update, fir.efir_predict_update)
FIR = _windowed(fir.fir_start, fir.fir_update, fir.fir_predict_update)

#: the generic filter kinds by name (the numpy registry's names)
GENERIC_FILTERS: dict[str, FilterKind] = {"ukf": UKF, "efir": EFIR, "fir": FIR}
