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
  plants; option ``horizon``);
* ``"ufir"`` — :mod:`fir_gym.jax.fir` (:class:`~fir_gym.estimators.ufir.UFIRFilter`, the
  unbiased FIR filter of linear plants: the FIR on the model with ``Q = 0``, ``R = I``;
  option ``horizon``; no NIS, :attr:`FilterKind.reports_nis`).

**Missing measurements.** ``update`` and ``predict_update`` take ``missing`` (a traced
bool, default ``False``): the step's reading did not arrive, and the kind does what its
numpy filter does on ``step(None)`` — what :class:`~fir_gym.wrappers.EstimatorObservation`
calls where ``info["measurement_missing"]``, at the reset too. The UKF predicts only
(:func:`~fir_gym.jax.unscented.ukf_correct`: ``x⁻, P⁻``, at the reset the prior); the
windowed filters keep the sample in their window as a gap and estimate from the rest
(:mod:`fir_gym.jax.fir`); the NIS is NaN. ``y`` is then ignored, whatever it holds. The
caller hands the divergence watch ``usable=~missing``
(:func:`~fir_gym.jax.kalman.watch`: such a step ends a run of high NIS, as the numpy
watch's ``valid``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import jax

from . import fir, unscented
from .filter_model import FilterModel

#: (memory, x, P, nis) after an update or a step
Result = tuple[Any, jax.Array, jax.Array, jax.Array]


class Update(Protocol):
    """A kind's update at a reset: ``(memory, x, P, y, model, options, missing=False)`` →
    :data:`Result`."""

    def __call__(self, memory: Any, x: jax.Array, P: jax.Array, y: jax.Array,
                 model: FilterModel, options: Mapping[str, Any],
                 missing: jax.Array | bool = False) -> Result: ...


class PredictUpdate(Protocol):
    """A kind's env step: ``(memory, x, P, y, u, model, options, missing=False)`` →
    :data:`Result`."""

    def __call__(self, memory: Any, x: jax.Array, P: jax.Array, y: jax.Array, u: jax.Array,
                 model: FilterModel, options: Mapping[str, Any],
                 missing: jax.Array | bool = False) -> Result: ...


@dataclass(frozen=True)
class FilterKind:
    """One generic filter. ``options``: the option names and their defaults (``None``
    for ``horizon``: the plant's ``default_horizon``). ``start(x0, P0, options)`` is the
    memory after the prior is set, before the first measurement; ``update(memory, x, P,
    y, model, options, missing=False)`` the reset's update with ``y[0]``;
    ``predict_update(memory, x, P, y, u, model, options, missing=False)`` one env step under
    the applied action ``u``; ``missing`` (a traced bool) says the step's reading did not
    arrive (the module docstring). Each returns ``(memory, x, P, nis)`` with NaN where the
    numpy filter fails (the divergence watch then keeps the last finite estimate), the NIS
    NaN where the reading is missing."""

    options: Mapping[str, Any]
    start: Callable[[jax.Array, jax.Array, Mapping[str, Any]], Any]
    update: Update
    predict_update: PredictUpdate
    #: whether the filter hands the divergence watch a NIS (the UFIR has none: its NaN
    #: never counts as high)
    reports_nis: bool = True

    def check(self, n_x: int, options: Mapping[str, Any]) -> None:
        """ValueError naming a bad option value (the names and defaults are the env's
        business, :class:`~fir_gym.jax._plant.FilteredPlant`)."""
        if "alpha" in options:
            _weights(n_x, options)


def _weights(n: int, options: Mapping[str, Any]) -> unscented.SigmaWeights:
    return unscented.merwe_weights(n, float(options["alpha"]), float(options["beta"]),
                                   float(options["kappa"]))


def _ukf_update(memory: Any, x: jax.Array, P: jax.Array, y: jax.Array, model: FilterModel,
                options: Mapping[str, Any], missing: jax.Array | bool = False) -> Result:
    return (memory, *unscented.ukf_update(x, P, y, model, _weights(x.shape[-1], options),
                                          missing=missing))


def _ukf_step(memory: Any, x: jax.Array, P: jax.Array, y: jax.Array, u: jax.Array,
              model: FilterModel, options: Mapping[str, Any],
              missing: jax.Array | bool = False) -> Result:
    return (memory, *unscented.ukf_predict_update(x, P, y, u, model,
                                                      _weights(x.shape[-1], options),
                                                      missing=missing))


UKF = FilterKind(
    options={"alpha": 1e-3, "beta": 2.0, "kappa": 0.0},
    start=lambda x0, P0, options: (),
    update=_ukf_update, predict_update=_ukf_step)


def _windowed(start: Callable[..., Any], update: Callable[..., Result],
              predict_update: Callable[..., Result], reports_nis: bool = True) -> FilterKind:
    """A FIR-family filter of :mod:`fir_gym.jax.fir`: one option, ``horizon`` (the bank's
    length), which only its memory's start needs."""

    def kind_update(memory: Any, x: jax.Array, P: jax.Array, y: jax.Array,
                    model: FilterModel, options: Mapping[str, Any],
                    missing: jax.Array | bool = False) -> Result:
        return update(memory, x, P, y, model, missing=missing)

    def kind_step(memory: Any, x: jax.Array, P: jax.Array, y: jax.Array, u: jax.Array,
                  model: FilterModel, options: Mapping[str, Any],
                  missing: jax.Array | bool = False) -> Result:
        return predict_update(memory, x, P, y, u, model, missing=missing)

    return FilterKind(options={"horizon": None},
                      start=lambda x0, P0, options: start(x0, P0, options["horizon"]),
                      update=kind_update, predict_update=kind_step, reports_nis=reports_nis)


EFIR = _windowed(fir.efir_start, fir.efir_update, fir.efir_predict_update)
FIR = _windowed(fir.fir_start, fir.fir_update, fir.fir_predict_update)
UFIR = _windowed(fir.fir_start, fir.ufir_update, fir.ufir_predict_update, reports_nis=False)

#: the generic filter kinds by name (the numpy registry's names)
GENERIC_FILTERS: dict[str, FilterKind] = {"ukf": UKF, "efir": EFIR, "fir": FIR, "ufir": UFIR}
