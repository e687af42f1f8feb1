"""A plant of a user's own: an inverted pendulum, ``θ̈ = (g/l) sin θ − b θ̇ + τ``, upright
at θ = 0 (nonlinear, unstable in open loop), built as the tutorial
docs/tutorials/your-own-plant.md builds it, from module-level callables (picklable, so that
joblib's workers and copies can rebuild it).

Importing the module registers it as :data:`ENV_ID`: what
``fir-gym benchmark-robustness --plants user_pendulum:user_pendulum/Pendulum-v0`` imports
(Gymnasium's ``module:id`` convention); tests/envs/test_model_plant.py builds its own ids
from the same pieces."""

from __future__ import annotations

import numpy as np

import fir_gym
from fir_gym.estimators import ContinuousModel

ENV_ID = "user_pendulum/Pendulum-v0"
DT, G_OVER_L, DAMPING, TORQUE = 0.02, 9.81, 0.1, 15.0
R_INTENSITY = 1e-5                       # the sampled angle's noise: R/dt, σ ≈ 0.022 rad
STEPS = 200


class Drift:
    """``[θ̇, (g/l) sin θ − b θ̇ + τ]`` for a batch of states along the leading axis."""

    def __init__(self, g_over_l: float) -> None:
        self.g_over_l = g_over_l

    def __call__(self, x, u):
        theta, omega = x[..., 0], x[..., 1]
        return np.stack([omega, self.g_over_l * np.sin(theta) - DAMPING * omega + u[..., 0]],
                        axis=-1)


def angle(x):
    """The sensor reads the angle."""
    return x[..., :1].copy()


def pendulum(g_over_l: float = G_OVER_L) -> ContinuousModel:
    return ContinuousModel(a=Drift(g_over_l), h=angle, Q=[[0.01]], G=[[0.0], [1.0]],
                           R=[[R_INTENSITY]], dt=DT, n_u=1, name="inverted pendulum")


#: the plant's keywords besides its model (torque = 15 · action; fallen beyond 0.8 rad)
PLANT = dict(action_scale=TORQUE, state_bounds=([-0.8, -8.0], [0.8, 8.0]),
             initial_state=[0.1, 0.0], initial_state_cov=np.diag([0.05 ** 2, 0.05 ** 2]),
             state_names=["theta", "omega"], max_episode_steps=STEPS)

fir_gym.register_plant(ENV_ID, model=pendulum(), **PLANT)
