"""Registration of the fir-gym environment ids with Gymnasium."""

from __future__ import annotations

import gymnasium as gym

#: (id, entry point, max_episode_steps)
_SPECS: tuple[tuple[str, str, int], ...] = (
    ("fir_gym/Orbit-v0", "fir_gym.envs.orbit:OrbitEnv", 1000),
    ("fir_gym/UncertainOscillator-v0",
     "fir_gym.envs.uncertain_oscillator:UncertainOscillatorEnv", 500),
    ("fir_gym/CarrierMotion-v0", "fir_gym.envs.carrier_motion:CarrierMotionEnv", 1000),
    ("fir_gym/VanDerPol-v0", "fir_gym.envs.van_der_pol:VanDerPolEnv", 100),
)

#: Every environment id that ``import fir_gym`` registers.
ENV_IDS: tuple[str, ...] = tuple(spec[0] for spec in _SPECS)


def register_envs() -> None:
    """Register every id in :data:`ENV_IDS` (idempotent)."""
    for env_id, entry_point, max_steps in _SPECS:
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point=entry_point, max_episode_steps=max_steps)
