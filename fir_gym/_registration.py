"""Registration of the fir-gym environment ids with Gymnasium.

Every id's entry point is a factory (``fir_gym._registration:<name>``) that builds
the plant and, when asked, wraps it: ``gym.make(id, estimator="ekf",
estimator_kwargs={...}, observation="estimate")`` (see
:func:`fir_gym.wrappers.factory.make_plant`).
"""

from __future__ import annotations

import gymnasium as gym

from .wrappers.factory import plant_factory, plant_vector_factory

#: (id, entry-point name in this module, plant class, max_episode_steps, native vector env)
_SPECS: tuple[tuple[str, str, str, int, bool], ...] = (
    ("fir_gym/Orbit-v0", "orbit", "fir_gym.envs.orbit:OrbitEnv", 1000, True),
    ("fir_gym/UncertainOscillator-v0", "uncertain_oscillator",
     "fir_gym.envs.uncertain_oscillator:UncertainOscillatorEnv", 500, True),
    ("fir_gym/CarrierMotion-v0", "carrier_motion",
     "fir_gym.envs.carrier_motion:CarrierMotionEnv", 1000, True),
    ("fir_gym/VanDerPol-v0", "van_der_pol", "fir_gym.envs.van_der_pol:VanDerPolEnv", 100, True),
    ("fir_gym/PendulumSlider-v0", "pendulum_slider",
     "fir_gym.envs.pendulum_slider:PendulumSliderEnv", 5000, False),
)

#: Every environment id that ``import fir_gym`` registers.
ENV_IDS: tuple[str, ...] = tuple(spec[0] for spec in _SPECS)
#: The ids with a native (batched numpy) vector env.
VECTOR_ENV_IDS: tuple[str, ...] = tuple(spec[0] for spec in _SPECS if spec[4])

# Module attributes per plant (``orbit`` and ``orbit_vector``, ...), so that each
# registered entry point is a plain string "fir_gym._registration:<name>".
for _env_id, _name, _plant, _steps, _native in _SPECS:
    globals()[_name] = plant_factory(_plant)
    if _native:
        globals()[_name + "_vector"] = plant_vector_factory(_plant)


def register_envs() -> None:
    """Register every id in :data:`ENV_IDS` (idempotent)."""
    for env_id, name, _plant, max_steps, native in _SPECS:
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point=f"fir_gym._registration:{name}",
                     vector_entry_point=f"fir_gym._registration:{name}_vector" if native else None,
                     max_episode_steps=max_steps)
