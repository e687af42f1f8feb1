"""Paper 002's data: VanDerPol-v0 episodes under each reading of its noise, and counted models.

Paper 002 writes the noise input ``[1, 1]ᵀ w`` with ``Q = 5·I``, which does not
conform. Two readings (:data:`NOISE_READINGS`; docs/papers.md#002-noise-reading):

* ``"G1"`` — one scalar noise ``w`` (``Q = 5``) drives both states through
  ``[1, 1]ᵀ``: VanDerPol-v0 itself, simulated by its native vector env;
* ``"GI"`` — ``G = I`` with ``Q = 5 I``: independent noise on each state. The env
  has a single noise input, so :func:`simulate_noise_input` integrates the same
  stochastic Heun scheme, interval average and measurement with any noise input
  ``G`` (for ``G = [1, 1]ᵀ`` it reproduces the env, which the tests check).

:class:`Counted` wraps a model callable to count its evaluations: the measurement of
paper 002's claim that the block-pulse method is computationally advantageous.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.envs.van_der_pol import NOISE_INPUT, van_der_pol_continuous_model
from fir_gym.estimators.continuous import ContinuousModel

from ._montecarlo import VectorTask, simulate_vector, stack_episodes, task_seed

ENV_ID = "fir_gym/VanDerPol-v0"
NOISE_READINGS = {"G1": NOISE_INPUT.reshape(2, 1), "GI": np.eye(2)}
#: runs per simulated chunk (fixed by the scenario, not by the backend)
CHUNK = 50


def env_params() -> dict[str, Any]:
    """VanDerPol-v0's parameters (the paper's: ε = 1, Q = 5, R = 5, h = 0.1, 100 intervals)."""
    env = gym.make(ENV_ID)
    plant: Any = env.unwrapped
    spec: Any = env.spec
    params = {**plant.nominal_params, "state_bound": float(plant.state_bound),
              "initial_state": tuple(plant.initial_state), "steps": int(spec.max_episode_steps)}
    env.close()
    return params


def continuous_model(reading: str, params: Mapping[str, Any] | None = None) -> ContinuousModel:
    """The filters' continuous model under a noise reading (``Q`` per noise input)."""
    params = dict(params or env_params())
    cm = van_der_pol_continuous_model(params)
    G = NOISE_READINGS[reading]
    return ContinuousModel(a=cm.a, J=cm.J, A_of_x=cm.A_of_x, h=cm.h, H=cm.H, G=G,
                           Q=params["Q"] * np.eye(G.shape[1]), R=cm.R, dt=cm.dt, n_u=1,
                           name=f"VanDerPol (continuous, {reading})")


def simulate_noise_input(seed: int, n: int, G: np.ndarray, params: Mapping[str, Any]
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` zero-force episodes with noise input ``G`` (``2 × m``), the env's scheme and draws.

    Per interval of ``h``: ``substeps`` stochastic Heun steps with increments
    ``G dW``, ``dW ~ N(0, Q τ I_m)``; the measurement is the trapezoid interval average
    of ``x1`` plus ``N(0, R/h)`` (at ``k = 0``: ``x1(0)`` plus that noise). A run ends
    (NaN from then on) once ``|x|`` exceeds ``state_bound``. Returns ``(X, Y, U)`` like
    :func:`~._montecarlo.simulate_vector`.
    """
    rng = np.random.default_rng(seed)
    eps, h, m = float(params["epsilon"]), float(params["h"]), int(params["substeps"])
    tau, steps = h / m, int(params["steps"])
    sd_w, sd_v = np.sqrt(params["Q"] * tau), np.sqrt(params["R"] / h)
    x = np.broadcast_to(np.asarray(params["initial_state"], float), (n, 2)).copy()
    x = x + rng.standard_normal((n, 2)) @ np.zeros((2, 2))       # the env's initial draw
    X = np.full((steps + 1, n, 2), np.nan)
    Y = np.full((steps + 1, n, 1), np.nan)
    X[0], Y[0] = x, x[:, :1] + sd_v * rng.standard_normal((n, 1))
    alive = np.ones(n, bool)

    def drift(z: np.ndarray) -> np.ndarray:
        return np.stack([z[:, 1], -z[:, 0] + eps * (1.0 - z[:, 0] ** 2) * z[:, 1]], axis=1)

    for k in range(steps):
        # drawn batch first, as the env draws (one run's increments in a row)
        dW = sd_w * np.moveaxis(rng.standard_normal((n, m, G.shape[1])), 1, 0)
        total = 0.5 * x[:, 0]
        for j in range(m):
            g = dW[j] @ G.T
            a0 = drift(x)
            pred = x + a0 * tau + g
            x = x + 0.5 * (a0 + drift(pred)) * tau + g
            total = total + x[:, 0]
        average = (total - 0.5 * x[:, 0]) / m
        y = average[:, None] + sd_v * rng.standard_normal((n, 1))
        X[k + 1] = np.where(alive[:, None], x, np.nan)            # as simulate_vector: the
        Y[k + 1] = np.where(alive[:, None], y, np.nan)            # last step is recorded
        alive &= np.all(np.abs(x) <= params["state_bound"], axis=1)
        x = np.where(alive[:, None], x, 0.0)                      # ended runs stay finite
    return X, Y, np.zeros((steps, n, 1))


def simulate_chunk(reading: str, seed: int, chunk: int, n: int) -> Any:
    """Chunk ``chunk`` (``n`` runs) of reading ``reading``'s Monte Carlo, seeded from ``seed``."""
    s = task_seed(seed, 2, chunk)
    if reading == "G1":
        return stack_episodes([simulate_vector(VectorTask(ENV_ID, s, n, env_params()["steps"]))])
    return stack_episodes([simulate_noise_input(s, n, NOISE_READINGS[reading], env_params())])


@dataclass
class Counted:
    """A model callable that counts its evaluations (one per system of a batch)."""

    fn: Callable[..., Any]
    name: str
    counts: dict[str, int]

    def __call__(self, x: np.ndarray, *rest: Any) -> Any:
        self.counts[self.name] = self.counts.get(self.name, 0) + int(np.prod(np.shape(x)[:-1]))
        return self.fn(x, *rest)


def counted_model(cm: ContinuousModel) -> tuple[ContinuousModel, dict[str, int]]:
    """``cm`` with counting callables ``a, J, A_of_x, h, H``, and the shared counts."""
    counts: dict[str, int] = {}
    wrap = {name: Counted(getattr(cm, name), name, counts)
            for name in ("a", "J", "A_of_x", "h", "H")}
    return ContinuousModel(**wrap, G=cm.G, Q=cm.Q, R=cm.R, dt=cm.dt, n_u=cm.n_u,
                           name=cm.name), counts
