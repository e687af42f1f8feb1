"""An estimator in the loop: the controller sees the filter's estimate, not the measurement."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from fir_gym.estimators import Estimator, estimator_class, estimator_names
from fir_gym.estimators._validation import one_of
from fir_gym.estimators.errors import IncompatibleModelError, check_options

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
    check_options(cls, options, label=registry_name(cls))
    attribute = cls.model_attribute
    model = plant_attr(attribute)
    if model is None:
        other = ("a discrete-time estimator such as 'ekf'" if attribute == "continuous_model"
                 else "an estimator of its model")
        raise IncompatibleModelError(
            f"the plant has no `{attribute}`: {cls.__name__} needs the plant's model "
            f"(env.unwrapped.{attribute}); use {other}")
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
    instance is used as it is (``options`` must then be empty), and must be one system
    whose model fits the plant (:func:`check_fits`).
    """
    plant = env.unwrapped
    if isinstance(estimator, Estimator):
        if options:
            raise ValueError(f"estimator options {sorted(options)} given with an estimator "
                             "instance; configure the instance instead")
        if estimator.x.ndim != 1:
            raise ValueError(f"estimator {type(estimator).__name__} runs a batch of "
                             f"{estimator.x.shape[0]} systems; EstimatorObservation feeds one "
                             "(use VectorEstimatorObservation for a vector env)")
        built = estimator
    else:
        built = build_estimator(estimator_class_of(estimator),
                                lambda name: getattr(plant, name, None), options)
    check_fits(built, plant_dimensions(lambda name: getattr(plant, name, None),
                                       env.observation_space, env.action_space),
               plant_name(env))
    return built


def plant_dimensions(plant_attr: Callable[[str], Any], observation_space: Any,
                     action_space: Any) -> dict[str, int]:
    """The plant's ``n_x`` (its state names, else its model's), ``n_y`` and ``n_u`` (its
    spaces, where they are flat boxes): what an estimator's model must have."""
    dims: dict[str, int] = {}
    names, model = plant_attr("state_names"), plant_attr("model")
    if names:
        dims["n_x"] = len(names)
    elif model is not None:
        dims["n_x"] = int(model.n_x)
    for key, space in (("n_y", observation_space), ("n_u", action_space)):
        if isinstance(space, spaces.Box) and len(space.shape) == 1:
            dims[key] = int(space.shape[0])
    return dims


def check_fits(estimator: Estimator, dims: dict[str, int], plant: str) -> None:
    """Refuse an estimator whose model's ``n_x``, ``n_y`` or ``n_u`` is not the plant's.

    The state of an augmented model (:func:`~fir_gym.estimators.augment`) is the plant's
    state followed by parameters: its ``n_base`` must be the plant's ``n_x``.
    """
    model = estimator.model
    ours = {"n_x": state_size(model), "n_y": int(model.n_y), "n_u": int(model.n_u)}
    wrong = [f"{key}={ours[key]} where the plant has {key}={want}"
             for key, want in dims.items() if ours[key] != want]
    if wrong:
        raise ValueError(f"estimator {type(estimator).__name__} does not fit {plant}: its model "
                         f"{model.name!r} has {'; '.join(wrong)}")


def state_size(model: Any) -> int:
    """How many leading components of the model's state are the plant's state (all of
    them, except for an augmented model, whose parameters follow its ``n_base``)."""
    return int(getattr(model, "n_base", model.n_x))


def plant_name(env: Any) -> str:
    """The id an env (or vector env) was made with, else its class name (for messages)."""
    spec = getattr(env, "spec", None) or getattr(env.unwrapped, "spec", None)
    return spec.id if spec is not None else type(env.unwrapped).__name__


def prior_of(x0: Any, P0: Any) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """A plant's initial-state mean and covariance as a prior, floored to stay positive
    definite (``PRIOR_FLOOR``); ``(None, None)`` when the plant publishes none."""
    if x0 is None or P0 is None:
        return None, None
    x0 = np.array(x0, dtype=np.float64)
    return x0, np.asarray(P0, dtype=np.float64) + PRIOR_FLOOR * np.diag(np.maximum(1.0, x0**2))


def registry_name(cls: type[Estimator]) -> str | None:
    """The name ``cls`` is registered under (``"ekf"``), else ``None``."""
    for name in estimator_names():
        if estimator_class(name) is cls:
            return name
    return None


def estimator_label(estimator: Estimator) -> str:
    """How frames and legends name ``estimator``: its registry name in capitals (``"EKF"``),
    else its class name."""
    name = registry_name(type(estimator))
    return name.upper() if name else type(estimator).__name__


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
    ``info["action"]`` (after the plant's clipping). A step whose
    ``info["measurement_missing"]`` is True (a :class:`~fir_gym.wrappers.SensorFaults`
    reading that was dropped, stuck, not sampled or not yet due) gives the estimator no
    measurement: it predicts only (``step(None, u)``). ``info`` gains ``estimate``,
    ``estimation_error`` (``state - estimate``, where the true state is known),
    ``estimator_diverged`` and ``estimator_info`` (the filter's ``last_info``). A
    filter that diverges keeps returning its last finite estimate and says so;
    the observation is never NaN.

    ``render()`` (with ``render_mode="rgb_array"``, or ``"rgb_array_list"`` through
    ``gym.make``) draws, over the plant's frame, the estimate as magenta rings where it
    puts the plant's bodies, its 2σ region where the filter has a covariance, the
    measurement as teal crosses, a legend and the time (the plant's
    :meth:`~fir_gym.envs._overlay.EstimateDrawing.draw_estimate`); the bare plant's
    frame is ``env.unwrapped.render()``.
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
        self.estimator_label = estimator_label(self.estimator)
        self._last_estimate: NDArray[np.float64] | None = None
        self._last_measurement: NDArray[np.float64] | None = None
        n_x = self.estimator.model.n_x
        self._n_state = state_size(self.estimator.model)     # the plant's part of x_hat
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
        x_hat = self.estimator.step(None if info.get("measurement_missing") else y)
        self._remember(x_hat, y)
        return self._observe(x_hat, y), self._annotate(info, x_hat)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        y, reward, terminated, truncated, info = self.env.step(action)
        u = info.get("action", action)
        x_hat = self.estimator.step(None if info.get("measurement_missing") else y, u)
        self._remember(x_hat, y)
        return self._observe(x_hat, y), reward, terminated, truncated, self._annotate(info, x_hat)

    def render(self) -> Any:
        """The plant's frame with the estimate, its 2σ region and the measurement drawn
        over it (see the class docstring); the plant's own frame where there is nothing
        to draw (before the first ``reset``, or a plant that cannot place an estimate)."""
        frame = self.env.render()
        plant = self.env.unwrapped
        draw = getattr(plant, "draw_estimate", None)
        if not isinstance(frame, np.ndarray) or self._last_estimate is None or draw is None \
                or getattr(plant, "frame_view", None) is None:
            return frame
        return draw(frame, self._last_estimate, self.estimator.P, self._last_measurement,
                    label=self.estimator_label, diverged=bool(self.estimator.diverged))

    # ------------------------------------------------------------------ helpers
    def _remember(self, x_hat: NDArray[np.float64], y: Any) -> None:
        """What the next frame draws: the estimate and the measurement it came from."""
        self._last_estimate = x_hat.copy()
        self._last_measurement = np.array(y, dtype=np.float64)

    def _observe(self, x_hat: NDArray[np.float64], y: NDArray[np.float64]) -> Any:
        if self.observation_kind == "estimate":
            return x_hat
        if self.observation_kind == "estimate+covariance":
            P = cast(NDArray[np.float64], self.estimator.P)   # provides_covariance: checked
            return {"estimate": x_hat, "covariance": P[self._triu]}
        return {"estimate": x_hat, "measurement": np.asarray(y, dtype=np.float64)}

    def _annotate(self, info: dict[str, Any], x_hat: NDArray[np.float64]) -> dict[str, Any]:
        info = dict(info)
        info["estimate"] = x_hat.copy()
        if "state" in info:
            info["estimation_error"] = np.asarray(info["state"]) - x_hat[:self._n_state]
        info["estimator_diverged"] = bool(self.estimator.diverged)
        info["estimator_info"] = dict(self.estimator.last_info)
        return info
