"""An estimator in the loop: the controller sees the filter's estimate, not the measurement."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from fir_gym.estimators import Estimator, estimator_class
from fir_gym.estimators._validation import one_of

OBSERVATION_KINDS = ("estimate", "estimate+covariance", "estimate+measurement")

#: Added to a singular initial-state covariance so that sigma-point filters can start:
#: the plant's initial state is then "known up to round-off".
PRIOR_FLOOR = 1e-9


def estimator_class_of(estimator: type[Estimator] | str) -> type[Estimator]:
    """The estimator class of a registry name or a class; anything else is a TypeError."""
    cls = estimator_class(estimator) if isinstance(estimator, str) else estimator
    if not (isinstance(cls, type) and issubclass(cls, Estimator)):
        raise TypeError("estimator must be an Estimator instance, an Estimator subclass or a "
                        f"registry name; got {estimator!r}")
    return cls


def build_estimator(cls: type[Estimator], plant_attr: Callable[[str], Any],
                    options: dict[str, Any]) -> Estimator:
    """``cls`` built for a plant from what the plant publishes, ``plant_attr(name)``.

    The model is the plant's ``cls.model_attribute`` (``model``; ``continuous_model``
    for the continuous filters). Options the caller did not give default to the
    plant's: ``horizon`` to its ``default_horizon`` (windowed filters), ``x0``/``P0`` to
    its initial-state distribution (:func:`prior_of`), and — the prior being known —
    ``startup="prior"`` for filters that can use it while their window fills. One env
    (:class:`EstimatorObservation`) and a vector env
    (:class:`~fir_gym.wrappers.VectorEstimatorObservation`) differ only in
    ``plant_attr``.
    """
    attribute = cls.model_attribute
    model = plant_attr(attribute)
    if model is None:
        raise ValueError(f"the plant has no `{attribute}`: {cls.__name__} needs the plant's "
                         f"model (env.unwrapped.{attribute})")
    options = dict(options)
    accepts = inspect.signature(cls.__init__).parameters
    horizon = plant_attr("default_horizon")
    if horizon is not None and "horizon" in accepts:
        options.setdefault("horizon", horizon)
    x0, P0 = prior_of(plant_attr("initial_state"), plant_attr("initial_state_cov"))
    if x0 is not None:
        options.setdefault("x0", x0)
        options.setdefault("P0", P0)
        if "startup" in accepts:
            options.setdefault("startup", "prior")
    return cls(model, **options)


def resolve_estimator(
    env: gym.Env, estimator: Estimator | type[Estimator] | str, options: dict[str, Any]
) -> Estimator:
    """An estimator instance for ``env`` from an instance, a class or a registry name.

    Classes and names are built by :func:`build_estimator` from ``env.unwrapped``; an
    instance is used as it is (``options`` must then be empty).
    """
    if isinstance(estimator, Estimator):
        if options:
            raise ValueError(f"estimator options {sorted(options)} given with an estimator "
                             "instance; configure the instance instead")
        return estimator
    plant = env.unwrapped
    return build_estimator(estimator_class_of(estimator),
                           lambda name: getattr(plant, name, None), options)


def prior_of(x0: Any, P0: Any) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """A plant's initial-state mean and covariance as a prior, floored to stay positive
    definite (``PRIOR_FLOOR``); ``(None, None)`` when the plant publishes none."""
    if x0 is None or P0 is None:
        return None, None
    x0 = np.array(x0, dtype=np.float64)
    return x0, np.asarray(P0, dtype=np.float64) + PRIOR_FLOOR * np.diag(np.maximum(1.0, x0**2))


def default_prior(env: gym.Env) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """The plant's initial-state mean and covariance (floored to stay positive definite)."""
    plant = env.unwrapped
    return prior_of(getattr(plant, "initial_state", None),
                    getattr(plant, "initial_state_cov", None))


class EstimatorObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Replace the measurement observation by a state estimate (docs/architecture.md#data-flow).

    Args:
        env: a plant whose ``env.unwrapped.model`` is a
            :class:`~fir_gym.estimators.StateSpaceModel`.
        estimator: an :class:`~fir_gym.estimators.Estimator` instance, class, or registry
            name (``"ekf"``, ``"efir"``, ...); classes and names are built from the
            plant's model with ``**options``.
        observation: ``"estimate"`` (a ``Box(n_x)``), ``"estimate+covariance"`` (a
            ``Dict`` with ``estimate`` and ``covariance``, the upper triangle of ``P``
            row by row, ``n_x (n_x + 1) / 2`` numbers) or ``"estimate+measurement"``
            (a ``Dict`` with ``estimate`` and ``measurement``).
        **options: estimator options (``horizon=10``, ``alpha=1e-3``, ``x0``, ``P0``, ...);
            a windowed filter without ``horizon`` gets the plant's ``default_horizon``,
            and without ``x0``/``P0`` the plant's initial-state distribution, which a
            filter that supports it also uses while its window fills
            (``startup="prior"``; pass ``startup="diffuse"`` for the paper's rule).

    On ``reset`` the estimator is reset to its prior and consumes ``y[0]`` (an
    update only); on ``step(u)`` it consumes ``y[k]`` with the *applied* input
    ``info["action"]`` (after the plant's clipping). ``info`` gains ``estimate``,
    ``estimation_error`` (``state - estimate``, where the true state is known),
    ``estimator_diverged`` and ``estimator_info`` (the filter's ``last_info``). A
    filter that diverges keeps returning its last finite estimate and says so;
    the observation is never NaN.
    """

    def __init__(
        self,
        env: gym.Env,
        estimator: Estimator | type[Estimator] | str,
        observation: str = "estimate",
        **options: Any,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, estimator=estimator,
                                                 observation=observation, **options)
        gym.Wrapper.__init__(self, env)
        one_of("observation", observation, OBSERVATION_KINDS)
        self.estimator = resolve_estimator(env, estimator, options)
        self.observation_kind = observation
        self._x0 = self.estimator.x
        self._P0 = self.estimator.P
        n_x = self.estimator.model.n_x
        estimate = spaces.Box(-np.inf, np.inf, shape=(n_x,), dtype=np.float64)
        if observation == "estimate":
            self.observation_space = estimate
        elif observation == "estimate+covariance":
            if not self.estimator.provides_covariance:
                raise ValueError(f"{type(self.estimator).__name__} has no covariance; use "
                                 "observation='estimate' or 'estimate+measurement'")
            self._triu = np.triu_indices(n_x)
            self.observation_space = spaces.Dict({
                "estimate": estimate,
                "covariance": spaces.Box(-np.inf, np.inf, shape=(len(self._triu[0]),),
                                         dtype=np.float64),
            })
        else:
            self.observation_space = spaces.Dict({
                "estimate": estimate,
                "measurement": env.observation_space,
            })

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        y, info = self.env.reset(seed=seed, options=options)
        self.estimator.reset(self._x0, self._P0)
        x_hat = self.estimator.step(y)
        return self._observe(x_hat, y), self._annotate(info, x_hat)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        y, reward, terminated, truncated, info = self.env.step(action)
        u = info.get("action", action)
        x_hat = self.estimator.step(y, u)
        return self._observe(x_hat, y), reward, terminated, truncated, self._annotate(info, x_hat)

    # ------------------------------------------------------------------ helpers
    def _observe(self, x_hat: NDArray[np.float64], y: NDArray[np.float64]) -> Any:
        if self.observation_kind == "estimate":
            return x_hat
        if self.observation_kind == "estimate+covariance":
            return {"estimate": x_hat, "covariance": self.estimator.P[self._triu]}
        return {"estimate": x_hat, "measurement": np.asarray(y, dtype=np.float64)}

    def _annotate(self, info: dict[str, Any], x_hat: NDArray[np.float64]) -> dict[str, Any]:
        info = dict(info)
        info["estimate"] = x_hat.copy()
        if "state" in info:
            info["estimation_error"] = np.asarray(info["state"]) - x_hat
        info["estimator_diverged"] = bool(self.estimator.diverged)
        info["estimator_info"] = dict(self.estimator.last_info)
        return info
