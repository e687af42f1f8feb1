"""Short names for estimators: ``make_estimator("ekf", model, **options)``.

The names are what command lines, ``gym.make(..., estimator="efir")`` and the
scenario reports use. Each estimator module registers its classes with
:func:`register_estimator` when it is imported by ``fir_gym.estimators``.
"""

from __future__ import annotations

from typing import Any

from .base import Estimator
from .errors import check_options
from .model import StateSpaceModel

_REGISTRY: dict[str, type[Estimator]] = {}


def register_estimator(name: str, cls: type[Estimator]) -> type[Estimator]:
    """Register ``cls`` under ``name`` (lower case); re-registering a name is an error."""
    key = name.lower()
    if key in _REGISTRY and _REGISTRY[key] is not cls:
        raise ValueError(f"estimator name {name!r} is already registered to "
                         f"{_REGISTRY[key].__name__}")
    _REGISTRY[key] = cls
    return cls


def estimator_names() -> list[str]:
    """The registered names, sorted."""
    return sorted(_REGISTRY)


def estimator_class(name: str) -> type[Estimator]:
    """The class registered under ``name``; an unknown name lists the known ones."""
    if not isinstance(name, str):
        raise TypeError(f"estimator name must be a string; got {type(name).__name__}")
    try:
        return _REGISTRY[name.lower()]
    except KeyError:
        raise ValueError(f"unknown estimator {name!r}; known estimators are "
                         f"{', '.join(estimator_names()) or '(none)'}") from None


def make_estimator(name: str, model: StateSpaceModel, **options: Any) -> Estimator:
    """Build the estimator registered under ``name`` for ``model`` with ``options``.

    An option the estimator does not take is an
    :class:`~fir_gym.estimators.errors.EstimatorOptionError` that lists the ones it does.
    """
    cls = estimator_class(name)
    check_options(cls, options, label=name)
    return cls(model, **options)
