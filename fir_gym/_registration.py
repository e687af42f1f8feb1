"""Registration of the fir-gym environment ids with Gymnasium (docs/architecture.md#registration).

One row of :data:`PAPER_PLANTS` per plant — its id, its class, its episode length and
whether it has a native vector env — is all a paper plant needs here: adding a plant is its
own file (with its docs page) and one row. :func:`register_envs` registers each row with
:func:`gymnasium.register` under string entry points, as Gymnasium registers its own
environments (so ``EnvSpec.to_json`` works): ``"fir_gym._registration:<entry>"`` builds the
plant and, when asked, wraps it — ``gym.make(id, estimator="ekf", estimator_kwargs={...},
observation="estimate")`` (see :func:`fir_gym.wrappers.factory.make_plant`) — and
``"fir_gym._registration:<entry>_vector"`` builds its native vector env,
``gym.make_vec(id, n, vectorization_mode="vector_entry_point")``. The entry points are this
module's attributes, made from the rows below (a plant class may refuse an option its vector
env cannot honour: ``PlantEnv.check_vector_options``).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import gymnasium as gym

from .wrappers.factory import plant_factory, plant_vector_factory


class PaperPlant(NamedTuple):
    """One registered plant of the papers."""

    #: the Gymnasium id
    id: str
    #: the plant class, ``"module:Class"``
    plant: str
    #: this module's attribute of its entry point (``<entry>_vector``: its vector env's)
    entry: str
    #: the ``TimeLimit`` of an episode
    max_episode_steps: int
    #: what it is, in one line
    about: str
    #: whether it has a native (batched numpy) vector env
    vector: bool = True


#: The paper plants, one row each.
PAPER_PLANTS: tuple[PaperPlant, ...] = (
    PaperPlant("fir_gym/Orbit-v0", "fir_gym.envs.orbit:OrbitEnv", "orbit", 1000,
               "paper 000, simulation 1: rectilinear orbit determination"),
    PaperPlant("fir_gym/UncertainOscillator-v0",
               "fir_gym.envs.uncertain_oscillator:UncertainOscillatorEnv",
               "uncertain_oscillator", 500,
               "paper 000, simulation 2: the oscillator with a temporary model uncertainty"),
    PaperPlant("fir_gym/CarrierMotion-v0", "fir_gym.envs.carrier_motion:CarrierMotionEnv",
               "carrier_motion", 1000, "paper 001: aircraft-carrier motion at sea, sampled "
               "exactly"),
    PaperPlant("fir_gym/VanDerPol-v0", "fir_gym.envs.van_der_pol:VanDerPolEnv", "van_der_pol",
               100, "paper 002: the stochastic Van der Pol oscillator with a continuous "
               "measurement"),
    PaperPlant("fir_gym/PendulumSlider-v0", "fir_gym.envs.pendulum_slider:PendulumSliderEnv",
               "pendulum_slider", 5000, "paper 003: the pendulum on a spring-loaded slider "
               "(MuJoCo; its vector env integrates the same equations of motion, batched)"),
)

# The entry points "fir_gym._registration:<entry>" and "...:<entry>_vector" of the rows.
for _row in PAPER_PLANTS:
    globals()[_row.entry] = plant_factory(_row.plant)
    if _row.vector:
        globals()[f"{_row.entry}_vector"] = plant_vector_factory(_row.plant)
del _row

#: Every environment id that ``import fir_gym`` registers.
ENV_IDS: tuple[str, ...] = tuple(row.id for row in PAPER_PLANTS)
#: The ids with a native (batched numpy) vector env.
VECTOR_ENV_IDS: tuple[str, ...] = tuple(row.id for row in PAPER_PLANTS if row.vector)


def register_envs() -> None:
    """Register every row of :data:`PAPER_PLANTS`; ids already registered are left alone.

    ``import fir_gym`` calls it; calling it again (or importing the package in a
    process that registered the ids otherwise) changes nothing and warns of nothing.
    """
    for row in PAPER_PLANTS:
        if row.id in gym.registry:
            continue
        gym.register(
            id=row.id,
            entry_point=f"fir_gym._registration:{row.entry}",
            vector_entry_point=f"fir_gym._registration:{row.entry}_vector" if row.vector
            else None,
            max_episode_steps=row.max_episode_steps,
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
