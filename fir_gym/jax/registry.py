"""The JAX environments by Gymnasium id: ``fir_gym.jax.make(env_id, kind, **kwargs)``.

gymnax's own ``gymnax.make(name)`` returns ``(env, params)``; so does :func:`make`, for the
fir-gym plants this backend has, each with the observation kinds it supports and the
numpy env's keywords (``gym.make(env_id, **kwargs)``'s, ``nominal=`` included) turned into
its validated params by the plant's builder.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class JaxPlant:
    """One plant of the JAX backend: its environment class (built with ``kind`` and the kind's
    options), its params builder (the numpy env's keywords) and its kinds."""

    env_id: str
    env_class: Any
    params: Callable[..., Any]
    kinds: tuple[str, ...]


def _plants() -> dict[str, JaxPlant]:
    from . import carrier_motion, orbit, pendulum_slider, uncertain_oscillator, van_der_pol

    plants = [
        JaxPlant("fir_gym/Orbit-v0", orbit.Orbit, orbit.orbit_params, orbit.KINDS),
        JaxPlant("fir_gym/UncertainOscillator-v0", uncertain_oscillator.UncertainOscillator,
                 uncertain_oscillator.uncertain_oscillator_params, uncertain_oscillator.KINDS),
        JaxPlant("fir_gym/CarrierMotion-v0", carrier_motion.CarrierMotion,
                 carrier_motion.carrier_motion_params, carrier_motion.KINDS),
        JaxPlant("fir_gym/VanDerPol-v0", van_der_pol.VanDerPol, van_der_pol.van_der_pol_params,
                 van_der_pol.KINDS),
        JaxPlant("fir_gym/PendulumSlider-v0", pendulum_slider.PendulumSlider,
                 pendulum_slider.pendulum_slider_params, pendulum_slider.KINDS),
    ]
    return {p.env_id: p for p in plants}


#: the plants of the JAX backend by Gymnasium id
PLANTS: dict[str, JaxPlant] = _plants()


def kinds_line() -> str:
    """One line naming every plant and its kinds (for error messages)."""
    return "; ".join(f"{p.env_id} with kind {', '.join(p.kinds)}" for p in PLANTS.values())


#: the sensor faults of :class:`~fir_gym.wrappers.SensorFaults` the JAX sensor has
JAX_FAULTS = ("dropout", "outliers", "bias", "every", "stuck", "delay")


def make(env_id: str, kind: str | None = None, *,
         kind_kwargs: dict[str, Any] | None = None, **env_kwargs: Any) -> tuple[Any, Any]:
    """``(env, params)`` of ``env_id`` observing ``kind`` (default: the plant's own filter),
    the env built with ``kind_kwargs`` (``observation`` and the kind's options, e.g.
    ``horizon``: :class:`fir_gym.jax._plant.FilteredPlant`) and the params from the numpy
    env's keywords ``env_kwargs``. Of the numpy plants' condition keywords, ``randomize``
    (the ``mismatch`` condition: the truth's parameters drawn at every reset) wraps the env
    in :class:`fir_gym.jax.randomized.Randomized`; ``burst`` (the windows ``(k_first,
    k_last, δ)`` that stretch the dynamics, checked as the numpy plants check them) goes to
    the environment class (:class:`fir_gym.jax._plant.FilteredPlant`). Of ``sensor_faults``
    (``gym.make``'s, the arguments of :class:`~fir_gym.wrappers.SensorFaults`) the JAX sensor
    has every one, :data:`JAX_FAULTS` —
    ``dropout``, ``outliers``, ``bias``, ``every``, ``stuck`` and ``delay`` (:class:`fir_gym.
    jax._plant.FilteredPlant`'s sensor); a filter kind is told the delay, as ``gym.make(id,
    sensor_faults=..., estimator=...)`` tells the numpy estimator
    (:meth:`~fir_gym.jax._plant.FilteredPlant.lagged_step`).

    Raises:
        ValueError: an unknown plant or kind (naming what there is), or a keyword the
            plant's builder or the environment class refuses (naming it).
    """
    from fir_gym.envs._conditions import check_burst

    plant = PLANTS.get(env_id)
    if plant is None:
        raise ValueError(f"env_id must be one of {sorted(PLANTS)}; got {env_id!r}")
    kind = plant.env_class.estimator if kind is None else kind
    if kind not in plant.kinds:
        raise ValueError(f"kind must be one of {plant.kinds} for {env_id}; got {kind!r}")
    randomize = env_kwargs.pop("randomize", None)
    burst = check_burst(env_kwargs.pop("burst", None))     # the numpy plants' ValueError
    faults = _sensor_faults(env_id, env_kwargs.pop("sensor_faults", None))
    try:
        params = plant.params(**env_kwargs)
    except TypeError as error:                       # an unknown keyword
        raise ValueError(f"{env_id}: {error}") from None
    if faults:                                       # every/delay against the episode
        from fir_gym.wrappers.faulty_sensor import check_faults

        check_faults(n_y=plant.env_class.n_y, episode_steps=int(params.max_steps_in_episode),
                     **faults)
    try:
        env = plant.env_class(kind, **faults, burst=burst, **(kind_kwargs or {}))
    except (TypeError, ValueError) as error:
        raise ValueError(f"{env_id} kind {kind}: kind_kwargs: {error}") from None
    if randomize:
        from .randomized import Randomized

        env = Randomized(env, randomize)
    return env, params


def _sensor_faults(env_id: str, sensor_faults: Any) -> dict[str, Any]:
    """``sensor_faults`` as the plant class's keywords (``{}`` for none); ValueError naming a
    fault that is not among :data:`JAX_FAULTS` (the plant's class checks the values)."""
    if not sensor_faults:
        return {}
    if not isinstance(sensor_faults, dict):
        raise ValueError(f"sensor_faults must be a dict of SensorFaults keywords; got "
                         f"{type(sensor_faults).__name__}")
    other = sorted(set(sensor_faults) - set(JAX_FAULTS))
    if other:
        raise ValueError(f"{env_id}: sensor_faults names {other}; the sensor's faults are "
                         f"{', '.join(JAX_FAULTS)}")
    return dict(sensor_faults)
