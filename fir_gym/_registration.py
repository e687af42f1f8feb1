"""Registration of the fir-gym environment ids with Gymnasium (docs/architecture.md#registration).

One literal :func:`gymnasium.register` call per id, as Gymnasium registers its own
environments. Every entry point is a module attribute of this file, written out per
plant: ``<plant>`` builds the plant and, when asked, wraps it —
``gym.make(id, estimator="ekf", estimator_kwargs={...}, observation="estimate")``
(see :func:`fir_gym.wrappers.factory.make_plant`) — and ``<plant>_vector`` builds its
native vector env, ``gym.make_vec(id, n, vectorization_mode="vector_entry_point")``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from .wrappers.factory import plant_factory, plant_vector_factory

# Entry points: "fir_gym._registration:<name>" in the register() calls below.
orbit = plant_factory("fir_gym.envs.orbit:OrbitEnv")
orbit_vector = plant_vector_factory("fir_gym.envs.orbit:OrbitEnv")
uncertain_oscillator = plant_factory("fir_gym.envs.uncertain_oscillator:UncertainOscillatorEnv")
uncertain_oscillator_vector = plant_vector_factory(
    "fir_gym.envs.uncertain_oscillator:UncertainOscillatorEnv")
carrier_motion = plant_factory("fir_gym.envs.carrier_motion:CarrierMotionEnv")
carrier_motion_vector = plant_vector_factory("fir_gym.envs.carrier_motion:CarrierMotionEnv")
van_der_pol = plant_factory("fir_gym.envs.van_der_pol:VanDerPolEnv")
van_der_pol_vector = plant_vector_factory("fir_gym.envs.van_der_pol:VanDerPolEnv")
pendulum_slider = plant_factory("fir_gym.envs.pendulum_slider:PendulumSliderEnv")
_pendulum_slider_vector = plant_vector_factory("fir_gym.envs.pendulum_slider:PendulumSliderEnv")


def pendulum_slider_vector(num_envs: int = 1, **kwargs: Any) -> gym.vector.VectorEnv:
    """Build PendulumSlider-v0's native vector env (the analytic equations of motion, batched);
    ``friction="coulomb"`` (MuJoCo's rail contact) is refused here, before anything is built."""
    from fir_gym.envs.pendulum_slider import refuse_batch

    refuse_batch(kwargs.get("friction"))
    return _pendulum_slider_vector(num_envs, **kwargs)


#: Every environment id that ``import fir_gym`` registers.
ENV_IDS: tuple[str, ...] = (
    "fir_gym/Orbit-v0",
    "fir_gym/UncertainOscillator-v0",
    "fir_gym/CarrierMotion-v0",
    "fir_gym/VanDerPol-v0",
    "fir_gym/PendulumSlider-v0",
)
#: The ids with a native (batched numpy) vector env.
VECTOR_ENV_IDS: tuple[str, ...] = (
    "fir_gym/Orbit-v0",
    "fir_gym/UncertainOscillator-v0",
    "fir_gym/CarrierMotion-v0",
    "fir_gym/VanDerPol-v0",
    "fir_gym/PendulumSlider-v0",
)


def register_envs() -> None:
    """Register every id in :data:`ENV_IDS`; ids already registered are left alone.

    ``import fir_gym`` calls it; calling it again (or importing the package in a
    process that registered the ids otherwise) changes nothing and warns of nothing.
    """
    def register(**spec: Any) -> None:
        if spec["id"] not in gym.registry:
            gym.register(**spec)

    # Paper 000, simulation 1: rectilinear orbit determination.
    register(
        id="fir_gym/Orbit-v0",
        entry_point="fir_gym._registration:orbit",
        vector_entry_point="fir_gym._registration:orbit_vector",
        max_episode_steps=1000,
    )
    # Paper 000, simulation 2: the oscillator with a temporary model uncertainty.
    register(
        id="fir_gym/UncertainOscillator-v0",
        entry_point="fir_gym._registration:uncertain_oscillator",
        vector_entry_point="fir_gym._registration:uncertain_oscillator_vector",
        max_episode_steps=500,
    )
    # Paper 001: aircraft-carrier motion at sea, sampled exactly.
    register(
        id="fir_gym/CarrierMotion-v0",
        entry_point="fir_gym._registration:carrier_motion",
        vector_entry_point="fir_gym._registration:carrier_motion_vector",
        max_episode_steps=1000,
    )
    # Paper 002: the stochastic Van der Pol oscillator with a continuous measurement.
    register(
        id="fir_gym/VanDerPol-v0",
        entry_point="fir_gym._registration:van_der_pol",
        vector_entry_point="fir_gym._registration:van_der_pol_vector",
        max_episode_steps=100,
    )
    # Paper 003: the pendulum on a spring-loaded slider (MuJoCo; the vector env integrates
    # the same equations of motion analytically, batched).
    register(
        id="fir_gym/PendulumSlider-v0",
        entry_point="fir_gym._registration:pendulum_slider",
        vector_entry_point="fir_gym._registration:pendulum_slider_vector",
        max_episode_steps=5000,
    )


def register_plant(id: str, plant: str | type = "fir_gym.envs.model_plant:ModelPlant", *,
                   max_episode_steps: int | None = None, vector: bool = True,
                   **kwargs: Any) -> None:
    """Register a plant of the user's own under the user's own id.

    ``register_plant("my_pkg/Pendulum-v0", model=..., state_bounds=..., ...)`` registers a
    :class:`~fir_gym.envs.ModelPlant` built with those keywords (the spec's ``kwargs``);
    ``plant`` may instead name any :class:`~fir_gym.envs._base.PlantEnv` subclass (the class,
    or ``"module:Class"``). The id then works as a fir-gym id does:
    ``gym.make(id, estimator="ekf")`` (the entry point is :func:`make_plant`'s), the native
    vector env ``gym.make_vec(id, n, vectorization_mode="vector_entry_point")`` (``vector``
    False leaves it out) and :func:`fir_gym.training.make_sb3_vec_env`.

    ``max_episode_steps`` (default: the plant's ``max_episode_steps`` keyword, else its
    class's ``default_max_episode_steps``) is the ``TimeLimit`` and is given to the plant
    too, so its terminal penalty counts the steps left to it. An id registered already is
    replaced (Gymnasium warns), so a notebook may re-run its registration cell.
    """
    from gymnasium.envs.registration import load_env_creator

    name = plant if isinstance(plant, str) else f"{plant.__module__}:{plant.__qualname__}"
    if max_episode_steps is None:
        max_episode_steps = kwargs.get("max_episode_steps") or getattr(
            load_env_creator(name), "default_max_episode_steps", None)
    if max_episode_steps is not None:
        kwargs["max_episode_steps"] = int(max_episode_steps)
    gym.register(id=id, entry_point=plant_factory(name),
                 vector_entry_point=plant_vector_factory(name) if vector else None,
                 max_episode_steps=max_episode_steps, kwargs=kwargs)
