"""Build a plant with the observation a controller should see.

``gym.make(id, estimator="efir", estimator_kwargs={...}, observation="estimate")``
goes through :func:`make_plant`, the entry point every fir-gym id is registered
with; :func:`wrap_observation` does the same for an existing env from one word
(``"true"``, ``"measurement"`` or an estimator name), which is how
``fir-gym compare-controllers`` builds its three kinds of controller on equal terms.

The plant's penalty horizon follows the time limit: ``gym.make(id, max_episode_steps=N)``
wraps the env in Gymnasium's ``TimeLimit`` of ``N`` steps but does not pass ``N`` to the
entry point, so :class:`PlantEntryPoint` reads the limit ``gymnasium.make`` is about to
apply (:func:`make_time_limit`) and gives it to the plant as its ``max_episode_steps``
before anything wraps it: a terminating step is then charged for exactly the steps left to
``N`` (``envs/_base.py``, "Rewards and episode end").
"""

from __future__ import annotations

import copy
import functools
import inspect
from collections.abc import Callable, Mapping
from types import FrameType
from typing import Any

import gymnasium as gym
from gymnasium.envs import registration
from gymnasium.envs.registration import load_env_creator

# The wrappers (and so the estimators and numba) are imported when an env is built, not
# when ``import fir_gym`` registers the ids with this module's entry points.


def wrap_observation(env: gym.Env, kind: str, *, observation: str = "estimate",
                     **estimator_options: Any) -> gym.Env:
    """Wrap ``env`` so that it observes ``kind``.

    ``kind`` is ``"true"`` (the true state), ``"measurement"`` (the raw noisy
    measurement) or an estimator registry name (``"ekf"``, ``"efir"``, ...), in
    which case ``observation`` and ``estimator_options`` go to
    :class:`EstimatorObservation`.
    """
    from .baselines import MeasurementObservation, TrueStateObservation
    from .estimator_observation import EstimatorObservation

    if kind == "true":
        return TrueStateObservation(env)
    if kind == "measurement":
        return MeasurementObservation(env)
    return EstimatorObservation(env, kind, observation=observation, **estimator_options)


def make_plant(
    plant: str | Callable[..., gym.Env],
    *,
    estimator: Any = None,
    estimator_kwargs: Mapping[str, Any] | None = None,
    observation: str | None = None,
    sensor_faults: Mapping[str, Any] | None = None,
    **plant_kwargs: Any,
) -> gym.Env:
    """Build ``plant(**plant_kwargs)``, wrapped as the estimator/observation options ask.

    Without ``estimator``, ``observation`` may be ``None``/``"measurement"`` (the
    plant's own observation) or ``"true"`` (the true state). With ``estimator``, the
    plant is wrapped in :class:`EstimatorObservation` with ``observation`` (default
    ``"estimate"``) and ``estimator_kwargs``. ``sensor_faults`` (the keywords of
    :class:`~fir_gym.wrappers.SensorFaults`) puts a faulty sensor between the plant and
    the rest; its ``delay`` is told to the estimator unless ``estimator_kwargs`` sets one.
    """
    from .baselines import TrueStateObservation
    from .estimator_observation import EstimatorObservation

    creator = load_env_creator(plant) if isinstance(plant, str) else plant
    env = creator(**plant_kwargs)
    if not isinstance(env, gym.Env):
        raise TypeError(f"plant must build a gymnasium Env; {plant!r} built {type(env).__name__}")
    if sensor_faults:
        from .sensor_faults import SensorFaults, with_known_delay

        if not isinstance(sensor_faults, Mapping):
            raise TypeError("sensor_faults must be a mapping of SensorFaults keywords, e.g. "
                            f"{{'dropout': 0.1}}; got {type(sensor_faults).__name__}")
        env = SensorFaults(env, **dict(sensor_faults))
        estimator_kwargs = with_known_delay(estimator, estimator_kwargs, sensor_faults)
    if estimator is None:
        if estimator_kwargs:
            raise ValueError("estimator_kwargs given without an estimator")
        if observation in (None, "measurement"):
            return env
        if observation == "true":
            return TrueStateObservation(env)
        raise ValueError(f"observation must be None, 'measurement' or 'true' without an "
                         f"estimator; got {observation!r}")
    return EstimatorObservation(env, estimator, observation=observation or "estimate",
                                **dict(estimator_kwargs or {}))


#: the code of :func:`gymnasium.make` (the caller whose time limit an entry point reads)
_MAKE_CODE = registration.make.__code__


def make_time_limit(frame: FrameType | None) -> int | None:
    """The ``TimeLimit`` that :func:`gymnasium.make`, running in ``frame``, applies to the env
    it is creating: its ``max_episode_steps`` argument, else its spec's — what ``make`` does
    with them once the entry point returns. ``None`` when ``frame`` is not ``make``'s (the
    entry point was called directly), for ``max_episode_steps=-1`` (``make`` applies no
    ``TimeLimit``) and when neither gives a positive integer (``TimeLimit`` refuses it).
    """
    if frame is None or frame.f_code is not _MAKE_CODE:
        return None
    given = frame.f_locals.get("max_episode_steps")
    if given == -1:
        return None
    steps = given if given is not None else getattr(frame.f_locals.get("env_spec"),
                                                    "max_episode_steps", None)
    if isinstance(steps, bool) or not isinstance(steps, int) or steps <= 0:
        return None
    return steps


def _with_horizon(creator: Callable[..., Any], steps: int, **kwargs: Any) -> Any:
    """``creator(**kwargs)`` with its plant's penalty horizon set to ``steps`` (anything else
    it builds is left as it is: :func:`make_plant` refuses what is not an env)."""
    from fir_gym.envs._base import PlantEnv

    env = creator(**kwargs)
    plant = env.unwrapped if isinstance(env, gym.Env) else None
    if isinstance(plant, PlantEnv):
        plant.max_episode_steps = steps
    return env


class PlantEntryPoint:
    """The entry point of one plant: ``gym.make``'s creator, with the plant's ``metadata``.

    Calling it is :func:`make_plant` for that plant. Called by :func:`gymnasium.make`, it
    gives the plant the time limit ``make`` applies as its ``max_episode_steps`` (the
    horizon of its terminal penalty: :func:`make_time_limit`), whatever the plant's own
    keywords say; with ``max_episode_steps=-1`` (no ``TimeLimit``) or called directly, the
    plant keeps its own (its ``max_episode_steps`` keyword, else its class's default).
    ``metadata`` (the plant class's, read
    when first asked, so registering imports no plant) is what :func:`gymnasium.make`
    reads to wrap an env as it wraps its own: ``render_mode="rgb_array_list"`` builds the
    plant with ``"rgb_array"`` inside :class:`gymnasium.wrappers.RenderCollection`, and
    ``render_mode="human"`` inside :class:`gymnasium.wrappers.HumanRendering` (which needs
    pygame and a display).
    """

    def __init__(self, plant: str) -> None:
        self.plant = plant
        self.__doc__ = (f"Build {plant} with optional estimator/observation options "
                        "(see make_plant).")

    @property
    def metadata(self) -> dict[str, Any]:
        """The plant class's metadata (its ``render_modes`` and ``render_fps``), a copy."""
        return copy.deepcopy(getattr(load_env_creator(self.plant), "metadata", {}))

    def __call__(self, **kwargs: Any) -> gym.Env:
        here = inspect.currentframe()
        steps = make_time_limit(here.f_back if here is not None else None)
        del here                                    # no reference cycle through the frame
        if steps is None:
            return make_plant(self.plant, **kwargs)
        return make_plant(functools.partial(_with_horizon, load_env_creator(self.plant), steps),
                          **kwargs)

    def __repr__(self) -> str:
        return f"PlantEntryPoint({self.plant!r})"


def plant_factory(plant: str) -> PlantEntryPoint:
    """An entry point for ``plant`` (``"module:Class"``) that accepts the estimator options."""
    return PlantEntryPoint(plant)


class PlantVectorEntryPoint:
    """The ``vector_entry_point`` of one plant: a :class:`~fir_gym.envs._vector.PlantVectorEnv`
    of it (a picklable object, so that an env's spec pickles with it)."""

    def __init__(self, plant: str) -> None:
        self.plant = plant
        self.__doc__ = f"Build a native vector env of {plant} (see PlantVectorEnv)."

    def __call__(self, num_envs: int = 1, **kwargs: Any) -> gym.vector.VectorEnv:
        from fir_gym.envs._base import PlantEnv
        from fir_gym.envs._vector import PlantVectorEnv

        for key in ("estimator", "estimator_kwargs", "observation"):
            if kwargs.get(key) is not None:
                raise ValueError(f"{key} is not an option of the native vector env; wrap it in "
                                 "fir_gym.wrappers.VectorEstimatorObservation instead")
            kwargs.pop(key, None)
        plant_class: Any = load_env_creator(self.plant)
        if not (isinstance(plant_class, type) and issubclass(plant_class, PlantEnv)):
            raise TypeError(f"the native vector env needs a fir-gym plant class; {self.plant!r} "
                            f"is {plant_class!r}")
        plant_class.check_vector_options(kwargs)
        return PlantVectorEnv(plant_class, num_envs=num_envs, **kwargs)

    def __repr__(self) -> str:
        return f"PlantVectorEntryPoint({self.plant!r})"


def plant_vector_factory(plant: str) -> Callable[..., gym.vector.VectorEnv]:
    """A ``vector_entry_point`` for ``plant``: a :class:`~fir_gym.envs._vector.PlantVectorEnv`."""
    return PlantVectorEntryPoint(plant)
