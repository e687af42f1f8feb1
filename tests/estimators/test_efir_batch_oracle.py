"""The extended FIR filter against a brute-force batch linearisation of the same window.

Oracle (paper 000 eqs 3-13, the module docstring of :mod:`fir_gym.estimators.efir`): the
nominal runs open loop from ``x0``, ``x_nom[k] = f(x_nom[k-1], u[k])`` (``u[k]`` is the
input given with ``y[k]``, the one that moves ``x[k-1]`` to ``x[k]``); the perturbation
model of the window is linearised *at the nominal it starts from*,
``δx[k] ≈ F(x_nom[k-1], u[k]) δx[k-1] + w``, and at the nominal of each measurement,
``δy[k] = y[k] − h(x_nom[k]) ≈ H(x_nom[k]) δx[k] + v``; the estimate is
``x_nom[t] + S δY`` with ``S`` the minimum-variance unbiased gain of paper 000 Theorem 1
formed explicitly (:func:`~fir_gym.estimators.fir_gains.batch_gain`, the stacked formula —
not the two-stage recursion the filter runs). Nothing here is read from the filter but its
output; the two must agree to round-off.

The model is strongly nonlinear (a Duffing oscillator with a cubic spring, large
amplitude), so linearising at the *propagated* nominal ``x_nom[k]`` instead of
``x_nom[k-1]`` moves the estimate by orders of magnitude more than round-off.
"""

from __future__ import annotations

import numpy as np
import pytest
from compiled_paths import on_path
from sample_models import duffing_model

from fir_gym.estimators import StateSpaceModel
from fir_gym.estimators.efir import ExtendedFIRFilter
from fir_gym.estimators.fir_gains import batch_gain, make_window

L = 6                                    # measurements per window
STEPS = 30
X0 = np.array([1.5, 0.0, 1.0])           # large amplitude: the cubic spring dominates


def data(model: StateSpaceModel, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Inputs ``u[k]`` (``u[0]`` unused) and noisy measurements of a true trajectory that starts
    away from the nominal's ``x0``."""
    rng = np.random.default_rng(seed)
    U = rng.normal(size=(STEPS, model.n_u)) * 0.5
    x = X0 + np.array([0.2, -0.3, 0.1])
    Y = np.empty((STEPS, model.n_y))
    for k in range(STEPS):
        if k:
            x = model.f(x, U[k]) + rng.normal(size=3) * np.sqrt(np.diag(model.GQGT))
        Y[k] = model.h(x) + rng.normal(size=model.n_y) * np.sqrt(np.diag(model.R))
    return U, Y


def batch_oracle(model: StateSpaceModel, U: np.ndarray, Y: np.ndarray, form: str
                 ) -> dict[int, np.ndarray]:
    """The window estimates of paper 000 by brute force: the open-loop nominal, the window's
    linearisation along it (``F`` at the nominal the transition starts from, ``H`` at the
    measurement's nominal), the stacked minimum-variance unbiased gain. Keys: the step ``k``
    whose estimate it is (only full windows)."""
    nom = [X0.copy()]
    for k in range(1, STEPS):
        nom.append(model.f(nom[-1], U[k]))
    out: dict[int, np.ndarray] = {}
    pred = form == "predictor"
    for k in range(L - 1 + pred, STEPS):
        first = k - L + 1 - pred                      # oldest measurement of the window
        idx = range(first, first + L)
        # A_j maps instant first+j to first+j+1, linearised where it starts: x_nom[first+j]
        A = np.stack([model.F(nom[j], U[j + 1]) if j + 1 < STEPS else np.eye(3) for j in idx])
        C = np.stack([model.H(nom[j]) for j in idx])
        dY = np.concatenate([Y[j] - model.h(nom[j]) for j in idx])
        win = make_window(A, C, model.GQGT, model.R, L)
        S = batch_gain(win, form).S
        out[k] = nom[k] + S @ dY                      # target: x[k] (the newest / the next)
    return out


@pytest.mark.parametrize("path", ["numpy", "compiled"])
@pytest.mark.parametrize("form", ["filter", "predictor"])
def test_open_loop_efir_equals_the_batch_linearisation(form: str, path: str) -> None:
    """Every full-window estimate equals the stacked batch solution of the window linearised
    along the open-loop nominal (``F`` at ``x_nom[k-1]``), to round-off."""
    model = duffing_model()
    U, Y = data(model)
    oracle = batch_oracle(model, U, Y, form)
    efir = ExtendedFIRFilter(model, horizon=L, form=form, nominal="open-loop", x0=X0,
                             P0=np.eye(3))
    with on_path(path):
        compared = 0
        for k in range(STEPS):
            x = efir.step(Y[k], U[k] if k else None)
            if k in oracle:
                assert not efir.last_info["startup"]
                assert not efir.last_info["rank_deficient"]
                err = np.abs(x - oracle[k]).max()
                assert err <= 1e-9 * max(1.0, np.abs(oracle[k]).max()), (k, err)
                compared += 1
    assert compared == len(oracle) > 15


def window_estimate(model: StateSpaceModel, start: np.ndarray, first: int, U: np.ndarray,
                    Y: np.ndarray) -> np.ndarray:
    """The filter-form window ``first .. first+L-1`` by brute force: its own nominal from
    ``start`` at instant ``first``, linearised along it as in :func:`batch_oracle`; the
    estimate of ``x[first+L-1]``."""
    nom = [start]
    for j in range(first + 1, first + L):
        nom.append(model.f(nom[-1], U[j]))
    A = np.stack([model.F(nom[i], U[first + i + 1]) if i + 1 < L else np.eye(3)
                  for i in range(L)])
    C = np.stack([model.H(z) for z in nom])
    dY = np.concatenate([Y[first + i] - model.h(nom[i]) for i in range(L)])
    S = batch_gain(make_window(A, C, model.GQGT, model.R, L), "filter").S
    return nom[-1] + S @ dY


@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_reanchored_efir_equals_the_batch_linearisation_of_each_window(path: str) -> None:
    """``nominal="reanchor"`` (module docstring): the window starting at ``s`` carries its own
    nominal from the prediction ``f(x̂[s−1], u[s])`` (``x0`` at ``s = 0``) — the filter's
    earlier *outputs* are the anchors; the window's estimate is the batch solution along that
    nominal, to round-off."""
    model = duffing_model()
    U, Y = data(model)
    efir = ExtendedFIRFilter(model, horizon=L, form="filter", nominal="reanchor", x0=X0,
                             P0=np.eye(3))
    X_hat = []
    with on_path(path):
        for k in range(STEPS):
            X_hat.append(efir.step(Y[k], U[k] if k else None))
            first = k - L + 1
            if first < 0:
                continue
            assert not efir.last_info["startup"] and not efir.last_info["rank_deficient"]
            start = X0 if first == 0 else model.f(X_hat[first - 1], U[first])
            want = window_estimate(model, start, first, U, Y)
            err = np.abs(X_hat[k] - want).max()
            assert err <= 1e-9 * max(1.0, np.abs(want).max()), (k, err)


def test_the_two_linearisation_points_differ_far_above_round_off() -> None:
    """The test above can tell the linearisation points apart: with ``F`` taken at the
    propagated nominal ``x_nom[k]`` the batch solution moves by far more than its tolerance
    (so an EFIR linearised there fails it)."""
    model = duffing_model()
    U, Y = data(model)
    right = batch_oracle(model, U, Y, "filter")
    shifted = StateSpaceModel(f=model.f, h=model.h, Q=model.Q, R=model.R, n_u=1,
                              F=lambda x, u: model.F(model.f(x, u), u), H=model.H)
    wrong = batch_oracle(shifted, U, Y, "filter")
    gap = max(np.abs(right[k] - wrong[k]).max() for k in right)
    assert gap > 1e-4
