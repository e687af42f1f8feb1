"""Every plant model's Jacobians ``F = ∂f/∂x`` and ``H = ∂h/∂x`` against high-order central
finite differences of the model's own ``f`` and ``h``, on the numpy loops and on the compiled
interval kernels.

Oracle: the derivative of the map the model computes. ``F`` of an integrated plant is the
exact derivative of its discrete interval map (the product of the substeps' Jacobians), so
the 6th-order central difference of ``f``

    D_h = [−f(x−3h) + 9 f(x−2h) − 45 f(x−h) + 45 f(x+h) − 9 f(x+2h) + f(x+3h)] / (60 h)

must equal it within the stencil's error bound ``|D_h − f'| ≤ T(h) + R(h)``:

* truncation ``T(h) = h⁶ |f⁽⁷⁾| / 140``, estimated by Richardson from the same stencil at
  ``2h``: ``T(h) ≈ |D_2h − D_h| / 63`` (the tolerance takes ``|D_2h − D_h|`` itself,
  63 times that estimate);
* rounding ``R(h) = (Σ|c_i| / 60) δ / h = (110/60) δ / h`` with ``δ`` the evaluation error of
  ``f``, bounded by ``2¹⁰ ε max(1, |f|)`` (1024 ulps: the integrators' ≤ a few hundred
  rounded operations along one path).

The step is ``h_j = 10⁻² max(1, |x_j|)`` per state; the tolerance is ``|D_2h − D_h| + 2 R(h)``
entry by entry, a few 1e-10 on Orbit-v0 — a Jacobian evaluated after the position update
of an Euler substep is off by 4e-8 to 2e-7 there and by ~1e-4 at a fast, low orbit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from compiled_paths import TWINS, on_path
from user_pendulum import PLANT, pendulum

import fir_gym
from fir_gym.envs import ModelPlant
from fir_gym.estimators import StateSpaceModel

H0 = 1e-2                                  # relative FD step
EPS = float(np.finfo(float).eps)
ULPS = 2.0**10                             # evaluation error of f allowed, in ulps
STENCIL = ((-3, -1.0), (-2, 9.0), (-1, -45.0), (1, 45.0), (2, -9.0), (3, 1.0))   # / 60
ROUNDING_GAIN = sum(abs(c) for _, c in STENCIL) / 60.0                         # 110/60
PATHS = ["numpy", pytest.param("compiled", marks=pytest.mark.skipif(
    not TWINS, reason="the compiled kernels are off in this run"))]


def stencil(fun: Callable[[np.ndarray], np.ndarray], X: np.ndarray, step: np.ndarray
            ) -> np.ndarray:
    """``D_h`` of ``fun`` at every row of ``X`` ``(B, n)`` with steps ``step`` ``(B, n)``, in one
    batched call: ``(B, m, n)``."""
    n_b, n = X.shape
    E = step[:, :, None] * np.eye(n)                                     # (B, j, n)
    points = np.concatenate([X[:, None, :] + k * E for k, _ in STENCIL], axis=1)
    values = np.asarray(fun(points.reshape(-1, n))).reshape(n_b, len(STENCIL), n, -1)
    D = sum(c * values[:, i] for i, (_, c) in enumerate(STENCIL)) / (60.0 * step[:, :, None])
    return np.swapaxes(D, 1, 2)                                          # (B, m, j)


def fd_and_bound(fun: Callable[[np.ndarray], np.ndarray], X: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The 6th-order central difference of ``fun`` and the entrywise bound on its error
    (module docstring): ``|D_2h − D_h| + 2 · (110/60) · 1024 ε max(1, |f|) / h``."""
    step = H0 * np.maximum(1.0, np.abs(X))
    D1, D2 = stencil(fun, X, step), stencil(fun, X, 2.0 * step)
    size = np.maximum(1.0, np.abs(np.asarray(fun(X))))                   # (B, m)
    rounding = 2.0 * ROUNDING_GAIN * ULPS * EPS * size[:, :, None] / step[:, None, :]
    return D1, np.abs(D2 - D1) + rounding


def plant_model(env_id: str) -> tuple[StateSpaceModel, np.ndarray]:
    env: Any = gym.make(env_id).unwrapped
    model, x0 = env.model, np.asarray(env.initial_state, dtype=np.float64)
    env.close()
    return model, x0


def model_plant() -> tuple[StateSpaceModel, np.ndarray]:
    kwargs: dict[str, Any] = dict(PLANT)
    env = ModelPlant(model=pendulum(), **kwargs)
    return env.model, np.asarray(env.initial_state, dtype=np.float64)


def registered(env_id: str) -> Callable[[], tuple[StateSpaceModel, np.ndarray]]:
    return lambda: plant_model(env_id)


MODELS: dict[str, Callable[[], tuple[StateSpaceModel, np.ndarray]]] = {
    **{env_id: registered(env_id) for env_id in fir_gym.ENV_IDS},
    "ModelPlant(pendulum)": model_plant,
}


def points(x0: np.ndarray, n_b: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n_b`` states around ``x0`` (±20 % of each state's scale) and inputs in ``[−1, 1]``."""
    rng = np.random.default_rng(seed)
    X = x0 + rng.uniform(-0.2, 0.2, (n_b, x0.size)) * np.maximum(1.0, np.abs(x0))
    return X, rng.uniform(-1.0, 1.0, (n_b, 1))


def check(model: StateSpaceModel, X: np.ndarray, U: np.ndarray) -> None:
    """``F`` and ``H`` of the batch ``X`` and of each row alone against the FD oracle."""
    FD, Fb = fd_and_bound(lambda Z: model.f(Z, np.repeat(U, len(Z) // len(U), axis=0)
                                            if len(Z) != len(U) else U), X)
    HD, Hb = fd_and_bound(model.h, X)
    for F, H in ((model.F(X, U), model.H(X)),
                 (np.array([model.F(x, u) for x, u in zip(X, U, strict=True)]),
                  np.array([model.H(x) for x in X]))):
        excess = np.abs(F - FD) - Fb
        assert excess.max() <= 0.0, (np.abs(F - FD).max(), np.unravel_index(excess.argmax(),
                                                                              F.shape))
        assert (np.abs(H - HD) - Hb).max() <= 0.0, np.abs(H - HD).max()


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("name", list(MODELS))
def test_jacobians_equal_high_order_finite_differences(name: str, path: str) -> None:
    """``F`` and ``H`` within the stencil's error bound of the 6th-order FD of ``f`` and
    ``h``, for a batch (> 32 systems: the array loops) and for single states."""
    model, x0 = MODELS[name]()
    X, U = points(x0, 40, seed=5)
    with on_path(path):
        check(model, X, U)


@pytest.mark.parametrize("path", PATHS)
def test_orbit_jacobian_at_fast_low_orbits(path: str) -> None:
    """Orbit-v0's interval map where the radius changes fast within an interval (``|v|/r``
    large): the Jacobian of every Euler substep must be taken before that substep's
    position update, which the FD oracle resolves by orders of magnitude here."""
    model, _ = plant_model("fir_gym/Orbit-v0")
    X = np.array([[2.0, 20.0], [3.0, -15.0], [5.0, 10.0], [8.0, 2.0]])
    U = np.array([[0.5], [-1.0], [0.0], [1.0]])
    with on_path(path):
        check(model, X, U)
        check(model, np.repeat(X, 10, axis=0), np.repeat(U, 10, axis=0))   # 40: array loop
