"""A plant of a user's own, registered when this module is imported: what
``fir-gym benchmark-robustness --plants user_pendulum:user_pendulum/Pendulum-v0`` imports
(Gymnasium's ``module:id`` convention). An inverted pendulum, ``θ̈ = (g/l) sin θ − b θ̇ + τ``,
upright at θ = 0 (nonlinear, unstable in open loop), built as the tutorial
docs/tutorials/your-own-plant.md builds it, from module-level functions (picklable, so
that joblib's workers can build it too)."""

from __future__ import annotations

import numpy as np

import fir_gym
from fir_gym.estimators import ContinuousModel

ENV_ID = "user_pendulum/Pendulum-v0"


def drift(x, u):
    theta, omega = x[..., 0], x[..., 1]
    return np.stack([omega, 9.81 * np.sin(theta) - 0.1 * omega + u[..., 0]], axis=-1)


def angle(x):
    return x[..., :1].copy()


fir_gym.register_plant(
    ENV_ID,
    model=ContinuousModel(a=drift, h=angle, Q=[[0.01]], G=[[0.0], [1.0]], R=[[1e-5]],
                          dt=0.02, n_u=1, name="inverted pendulum"),
    action_scale=15.0, state_bounds=([-0.8, -8.0], [0.8, 8.0]), initial_state=[0.1, 0.0],
    initial_state_cov=np.diag([0.05 ** 2, 0.05 ** 2]), state_names=["theta", "omega"],
    max_episode_steps=200)
