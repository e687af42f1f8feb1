"""Small models the estimator tests share (importable: pytest's ``pythonpath`` has this folder)."""

from __future__ import annotations

import numpy as np

from fir_gym.estimators import LinearModel, StateSpaceModel

DUFFING_DT = 0.05


class Duffing:
    """A nonlinear 3-state model with two outputs, one input and analytic Jacobians (batched).

    Picklable (its callables are static methods), so filters built on it pickle too.
    """

    @staticmethod
    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        dt = DUFFING_DT
        x0, x1, x2 = x[..., 0], x[..., 1], x[..., 2]
        return np.stack([x0 + dt * x1, x1 - dt * (x0 + x0**3 * x2 + 0.1 * x1 - u[..., 0]),
                         x2 + dt * 0.01 * np.sin(x0)], axis=-1)

    @staticmethod
    def F(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        dt = DUFFING_DT
        x0, x2 = x[..., 0], x[..., 2]
        J = np.zeros(x.shape[:-1] + (3, 3))
        J[..., 0, 0] = J[..., 2, 2] = 1.0
        J[..., 0, 1] = dt
        J[..., 1, 0] = -dt * (1.0 + 3.0 * x0**2 * x2)
        J[..., 1, 1] = 1.0 - 0.1 * dt
        J[..., 1, 2] = -dt * x0**3
        J[..., 2, 0] = dt * 0.01 * np.cos(x0)
        return J

    @staticmethod
    def h(x: np.ndarray) -> np.ndarray:
        return np.stack([np.sin(x[..., 0]), x[..., 1] * x[..., 2]], axis=-1)

    @staticmethod
    def H(x: np.ndarray) -> np.ndarray:
        J = np.zeros(x.shape[:-1] + (2, 3))
        J[..., 0, 0] = np.cos(x[..., 0])
        J[..., 1, 1] = x[..., 2]
        J[..., 1, 2] = x[..., 1]
        return J


def duffing_model() -> StateSpaceModel:
    """:class:`Duffing` as a model: ``Q = diag(1e-4, 1e-3, 1e-6)``, ``R = diag(1e-2, 2e-2)``."""
    d = Duffing()
    return StateSpaceModel(f=d.f, h=d.h, F=d.F, H=d.H, Q=np.diag([1e-4, 1e-3, 1e-6]),
                           R=np.diag([1e-2, 2e-2]), n_u=1, dt=DUFFING_DT)


def random_linear_3x1(radius: float) -> LinearModel:
    """A random 3-state, 1-output, 1-input model (seed 0), ``A`` scaled to spectral radius
    ``radius``; ``Q = 0.1 I``, ``R = 0.4``."""
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3))
    A *= radius / np.max(np.abs(np.linalg.eigvals(A)))
    return LinearModel(A=A, C=rng.normal(size=(1, 3)), B=rng.normal(size=(3, 1)),
                       Q=0.1 * np.eye(3), R=[[0.4]])
