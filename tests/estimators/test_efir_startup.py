"""EFIR's start-up with a prior: the Kalman filter from (x0, P0) until the window is full."""

import gymnasium as gym
import numpy as np
import pytest

import fir_gym  # noqa: F401
from fir_gym.estimators import (
    ExtendedFIRFilter,
    FIRFilter,
    KalmanFilter,
    LinearModel,
)


def random_linear(seed):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(3, 3)) * 0.5 + np.eye(3) * 0.6
    A *= 1.05 / np.max(np.abs(np.linalg.eigvals(A)))    # mildly unstable, well conditioned
    C = rng.normal(size=(2, 3))
    L = rng.normal(size=(3, 3)) * 0.2
    return LinearModel(A=A, C=C, Q=L @ L.T + 1e-3 * np.eye(3), R=np.diag([0.05, 0.1]),
                       B=rng.normal(size=(3, 1)))


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("form", ["filter", "predictor"])
def test_prior_startup_equals_the_kalman_filter_then_the_fir_filter(seed, form):
    model = random_linear(seed)
    rng = np.random.default_rng(10 + seed)
    x0, P0 = rng.normal(size=3), np.diag([0.5, 1.0, 2.0])
    L = 6
    efir = ExtendedFIRFilter(model, horizon=L, form=form, x0=x0, P0=P0, startup="prior")
    kf = KalmanFilter(model, x0=x0, P0=P0)
    fir = FIRFilter(model, horizon=L, form=form)
    Y, U = rng.normal(size=(25, 2)), rng.normal(size=(25, 1))
    for k in range(25):
        u = None if k == 0 else U[k - 1]
        x_efir, x_kf, x_fir = efir.step(Y[k], u), kf.step(Y[k], u), fir.step(Y[k], u)
        if efir.last_info["startup"]:
            if form == "filter":      # the window y[0..k] with the prior on x[0]: the KF
                np.testing.assert_allclose(x_efir, x_kf, rtol=0, atol=1e-10)
                np.testing.assert_allclose(efir.P, kf.P, rtol=0, atol=1e-10)
        else:   # two gain computations (bank vs fixed two-stage gain): round-off, relative
            np.testing.assert_allclose(x_efir, x_fir, rtol=1e-9, atol=1e-12)
    assert not efir.last_info["startup"]


def test_prior_startup_tames_the_orbit_velocity_at_the_start():
    env = gym.make("fir_gym/Orbit-v0", initial_state_cov=[[0.0025, 0.0], [0.0, 0.04]])
    model = env.unwrapped.model
    errors = {"diffuse": [], "prior": []}
    for seed in range(10):
        for startup in errors:
            y, info = env.reset(seed=seed)
            filt = ExtendedFIRFilter(model, horizon=20, x0=[7.99, 1.99],
                                     P0=np.diag([0.0025, 0.04]), startup=startup)
            filt.step(y)
            for _ in range(15):                         # inside the start-up
                y, _, _, _, info = env.step(np.array([0.3]))
                errors[startup].append(filt.step(y, info["action"]) - info["state"])
    v_rmse = {k: float(np.sqrt(np.mean(np.square(np.array(v)[:, 1])))) for k, v in errors.items()}
    assert v_rmse["prior"] < 0.3 < v_rmse["diffuse"]       # the prior's σ_v is 0.2


def test_startup_option_is_validated():
    with pytest.raises(ValueError, match="startup"):
        ExtendedFIRFilter(random_linear(0), horizon=4, startup="optimistic")


@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_a_window_with_no_measurement_predicts_the_previous_estimate(path: str) -> None:
    """Once a system's whole window is missing (``nan_policy="skip"``) its information is
    singular, and the EFIR falls back to the model's prediction of its previous estimate:
    ``x = f(x̂, u)``, ``P = F P Fᵀ + G Q Gᵀ`` (the module docstring's fallback) — for that
    system only, the other one of the batch keeping its window (mutation testing found the
    prediction's transpose and its process noise untested)."""
    from compiled_paths import on_path
    from sample_models import duffing_model

    from fir_gym.estimators import make_estimator
    model = duffing_model()
    L = 6
    efir = make_estimator("efir", model, horizon=L, nan_policy="skip", x0=[0.5, 0.2, 1.0],
                          P0=0.01 * np.eye(3))
    rng = np.random.default_rng(3)
    x_true = np.array([0.5, 0.0, 1.0])
    with on_path(path):
        for k in range(40):
            u = rng.normal(size=(2, 1)) * 0.3
            x_true = model.f(x_true, u[0])
            y = np.stack([model.h(x_true), model.h(x_true)]) + 0.05 * rng.normal(size=(2, 2))
            if k >= 20:
                y[1] = np.nan                                   # system 1 goes blind
            x_prev, P_prev = efir.x.copy(), efir.P.copy()
            efir.step(y, None if k == 0 else u)
            if k >= 20 + L:                                     # its whole window is missing
                f, F = model.linearize(x_prev[1], u[1])
                np.testing.assert_allclose(efir.x[1], f, rtol=1e-12, atol=1e-14)
                np.testing.assert_allclose(efir.P[1], F @ P_prev[1] @ F.T + model.GQGT,
                                           rtol=1e-10, atol=1e-14)
