"""The two mistakes made building an estimator, each with one exception type and a hint.

* :class:`EstimatorOptionError` — an option the estimator does not take (``x_0=``,
  ``Q=``). A ``TypeError``, as Python's own "unexpected keyword argument" is; the
  message names the filter, lists the options it accepts and suggests the near miss
  (``x0``), or says that noise is the model's (``nominal=``).
* :class:`IncompatibleModelError` — the estimator does not apply to the model (a linear
  filter on a nonlinear plant, the block-pulse filter on a model without ``A(x)``); the
  message names the estimators that do (``efir`` for the FIR family, ``ekf``/``ukf``
  for the Kalman filter). It is both a ``TypeError`` and a ``ValueError`` (as numpy's
  ``AxisError`` is both a ``ValueError`` and an ``IndexError``), so code written
  against either of the types these errors had keeps working.

:func:`check_options` is what the name-based entry points call before building an
estimator (:func:`~fir_gym.estimators.make_estimator`, ``gym.make(id, estimator=...,
estimator_kwargs=...)``, the CLI).
"""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Iterable
from typing import Any

#: option names that are really the model's noise (set through the plant's ``nominal=``)
NOISE_NAMES = frozenset({"q", "r", "g", "noise", "process_noise", "measurement_noise",
                         "sigma_w", "sigma_v", "sigma", "std", "var", "variance"})


class EstimatorOptionError(TypeError):
    """An option an estimator does not take; the message lists the ones it does."""


class IncompatibleModelError(TypeError, ValueError):
    """An estimator that does not apply to the model it was given; the message says which do."""


def accepted_options(cls: type) -> list[str]:
    """The keyword options ``cls(model, **options)`` accepts: the named parameters of every
    ``__init__`` along its MRO (subclasses hand ``**options`` on to their bases)."""
    names: set[str] = set()
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None or klass is object:
            continue
        for p in inspect.signature(init).parameters.values():
            if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.name not in (
                    "self", "model"):
                names.add(p.name)
    return sorted(names)


def check_options(cls: type, options: Iterable[str], label: str | None = None) -> None:
    """Refuse options ``cls`` does not take with an :class:`EstimatorOptionError`.

    The message names the estimator (``label``, e.g. its registry name, and its class),
    the unknown options, the accepted ones, the closest accepted name, and — for noise
    such as ``Q=`` or ``R=`` — that noise belongs to the model: set the plant's
    ``nominal=`` parameters, or give the filter a model with that noise.
    """
    accepted = accepted_options(cls)
    bad = [name for name in options if name not in accepted]
    if not bad:
        return
    who = f"{label} ({cls.__name__})" if label else cls.__name__
    hints = []
    for name in bad:
        if name.lower() in NOISE_NAMES:
            hints.append(f"{name!r} is the model's noise, not an option of the filter: set "
                         f"the plant's nominal parameters, gym.make(id, nominal={{{name!r}: "
                         f"...}}) (on the command line --env-kwargs '{{\"nominal\": "
                         f"{{\"{name}\": ...}}}}'; env.unwrapped.nominal_params lists them), "
                         "or build the filter on a model with that noise")
        else:
            near = difflib.get_close_matches(name, accepted, n=1)
            if near:
                hints.append(f"did you mean {near[0]!r} for {name!r}?")
    message = (f"{who} takes no option {', '.join(map(repr, bad))}; it accepts "
               f"{', '.join(accepted)}")
    raise EstimatorOptionError(message + ("; " + "; ".join(hints) if hints else ""))


def needs_linear(estimator: str, model: Any, nonlinear: str) -> IncompatibleModelError:
    """The error for a linear-model estimator given ``model``, suggesting ``nonlinear``."""
    return IncompatibleModelError(
        f"{estimator} needs a LinearModel or TimeVaryingLinearModel; got "
        f"{type(model).__name__}, a nonlinear model: use {nonlinear}")
