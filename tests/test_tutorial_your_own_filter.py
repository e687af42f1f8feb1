"""docs/tutorials/your-own-filter.md runs as written (its Python blocks, in order, in one module
of their own), and its particle filter is right: against the Kalman filter on a linear-Gaussian
model, copies and pickles continuing bit for bit, seeds, and in the loop next to the EKF."""

from __future__ import annotations

import copy
import pickle
import re
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from fir_gym.estimators import KalmanFilter, LinearModel, estimator_names, registry

PAGE = Path(__file__).resolve().parents[1] / "docs" / "tutorials" / "your-own-filter.md"
MODULE = "tutorial_your_own_filter"
NAME = "my-pf"


def blocks() -> list[str]:
    text = PAGE.read_text(encoding="utf-8")
    return re.findall(r"^```python\n(.*?)^```", text, re.MULTILINE | re.DOTALL)


@pytest.fixture(scope="module")
def page():
    """The page's module, run once (a registry name is registered once per process); a real
    module in ``sys.modules``, so that its class pickles as a user's script's would. The name
    leaves the registry afterwards: the other tests iterate over the registered estimators."""
    assert NAME not in estimator_names()
    module = types.ModuleType(MODULE)
    sys.modules[MODULE] = module
    try:
        for block in blocks():
            exec(compile(block, str(PAGE), "exec"), module.__dict__)
        yield module
    finally:
        registry._REGISTRY.pop(NAME, None)
        sys.modules.pop(MODULE, None)


def linear_model() -> LinearModel:
    """A constant-velocity target, its position measured."""
    return LinearModel(A=[[1.0, 0.1], [0.0, 1.0]], C=[[1.0, 0.0]], Q=np.diag([1e-3, 1e-2]),
                       R=[[0.1]])


def linear_data(model: LinearModel, steps: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x, ys = np.array([0.0, 1.0]), []
    for _ in range(steps):
        ys.append(model.C @ x + rng.normal(0.0, np.sqrt(0.1), 1))
        x = model.A @ x + rng.multivariate_normal(np.zeros(2), model.Q)
    return np.array(ys)


def test_the_page_runs_and_registers_its_filter(page):
    code = blocks()
    assert len(code) == 3
    first = code[0]
    assert len([line for line in first.splitlines() if line.strip()]) <= 50
    from fir_gym.estimators import estimator_class, make_estimator
    assert estimator_class(NAME) is page.BootstrapPF
    assert isinstance(make_estimator(NAME, linear_model(), seed=0), page.BootstrapPF)
    # (d) in the loop on Orbit: the particle filter's RMSE within a factor 2 of the EKF's
    ekf, pf = page.rmse["ekf"], page.rmse[NAME]
    assert np.all(np.isfinite(pf)) and np.all(pf < 2 * ekf) and np.all(ekf < 2 * pf)


def test_on_a_linear_gaussian_model_it_is_the_kalman_filter(page):
    """(a) With N = 2000 particles the estimate is the KF's within Monte Carlo error: the error
    in units of the KF's sqrt(P / N) (weights and resampling inflate it a little), and the
    weighted covariance the KF's within 20 %. A PF with a wrong R, or without the process
    noise, misses both by far."""
    model, n = linear_model(), 2000
    ys = linear_data(model, 40, seed=3)
    kf = KalmanFilter(model, x0=[0.0, 1.0], P0=np.eye(2))
    pf = page.BootstrapPF(model, n_particles=n, seed=5, x0=[0.0, 1.0], P0=np.eye(2))
    z, ratio = [], []
    for y in ys:
        x_kf, x_pf = kf.step(y), pf.step(y)
        P_kf = kf.P
        z.append((x_pf - x_kf) / np.sqrt(np.diag(P_kf) / n))
        ratio.append(np.diag(pf.P) / np.diag(P_kf))
    z_abs = np.abs(np.array(z))
    assert z_abs.mean() < 3.0 and z_abs.max() < 12.0
    assert np.all(np.abs(np.array(ratio)[5:] - 1.0) < 0.2)


def test_a_missing_measurement_is_a_prediction_only(page):
    model = linear_model()
    ys = linear_data(model, 10, seed=4)
    pf = page.BootstrapPF(model, n_particles=2000, seed=0, x0=[0.0, 1.0], P0=np.eye(2))
    for y in ys:
        pf.step(y)
    x, P = pf.x, pf.P
    x_next = pf.step(None)
    # the particles moved through A with process noise: the mean follows A x, P grows by ~Q
    assert np.allclose(x_next, model.A @ x, atol=4 * np.sqrt(np.diag(P) / 2000).max() + 1e-3)
    P_pred = model.A @ P @ model.A.T + model.Q
    assert np.allclose(pf.P, P_pred, rtol=0.15)
    masked = np.ma.masked_array([0.0], mask=[True])
    before = pf.P
    pf.step(masked)
    assert np.trace(pf.P) > np.trace(before)           # no update shrank it


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copy_mid_run_continues_bit_for_bit(page, how):
    """(b) The generator's state travels with the particles; the original is left alone."""
    model = linear_model()
    ys = linear_data(model, 30, seed=6)
    pf = page.BootstrapPF(model, n_particles=300, seed=7, x0=[0.0, 1.0], P0=np.eye(2))
    for y in ys[:12]:
        pf.step(y)
    twin = copy.deepcopy(pf) if how == "deepcopy" else pickle.loads(pickle.dumps(pf))
    assert twin.rng is not pf.rng
    for y in ys[12:]:
        assert np.array_equal(twin.step(y), pf.step(y))
        assert np.array_equal(twin.P, pf.P)
    assert np.array_equal(twin.particles, pf.particles)


def test_seeds(page):
    """(c) Same seed: the same run bit for bit (reset restarts the generator too); another
    seed: another run."""
    model = linear_model()
    ys = linear_data(model, 20, seed=8)

    def run(seed: int, pf=None) -> np.ndarray:
        pf = pf or page.BootstrapPF(model, n_particles=300, seed=seed, x0=[0.0, 1.0],
                                    P0=np.eye(2))
        return pf.filter(ys).x

    same = run(1)
    assert np.array_equal(same, run(1))
    assert not np.array_equal(same, run(2))
    used = page.BootstrapPF(model, n_particles=300, seed=1, x0=[0.0, 1.0], P0=np.eye(2))
    run(1, used)
    used.reset([0.0, 1.0], np.eye(2))
    assert np.array_equal(run(1, used), same)


def test_a_batch_restarts_some_systems(page):
    """A restarted system of a batch takes a first step from its prior (the KF's first update,
    within Monte Carlo error) while the other goes on."""
    model = linear_model()
    ys = linear_data(model, 10, seed=9)
    pf = page.BootstrapPF(model, n_particles=2000, seed=0, x0=[0.0, 1.0], P0=np.eye(2))
    Y = np.stack([ys, ys], axis=1)
    for y in Y[:5]:
        pf.step(y)
    going_on = pf.P[0]
    pf.restart([1])
    x = pf.step(Y[5])
    assert pf.particles.shape == (2, 2000, 2)
    first = KalmanFilter(model, x0=[0.0, 1.0], P0=np.eye(2))
    x_first = first.step(Y[5, 1])
    assert np.allclose(np.diag(pf.P[1]), np.diag(first.P), rtol=0.2)
    assert np.all(np.abs(x[1] - x_first) < 6 * np.sqrt(np.diag(first.P) / 2000) + 1e-3)
    # system 0 predicted and updated: its spread is near the one it had, not the prior's
    assert np.trace(pf.P[0]) < 2 * np.trace(going_on) < np.trace(first.P)
