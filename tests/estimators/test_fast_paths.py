"""The Kalman family's compiled twins (estimators/compiled/) equal the numpy references.

One filter steps on the compiled twin, a copy on the numpy reference, on the same data;
estimates, covariances, NIS and divergence flags agree to 1e-12 through transients, the
KF's steady state, skipped measurements, divergence and restarts, for one system given
as ``(n_y,)`` and for batches. The oracle is the numpy reference (batched ``matmul`` and
closed forms, sharing no code with the loops). A single system is a batch of one: the
two give the same bits on either path.
"""

import copy

import numpy as np
import pytest
from compiled_paths import needs_twins, numpy_path, step_on
from estimator_checks import assert_rejects_bad_input
from sample_models import Duffing, duffing_model

from fir_gym.estimators import (
    CubatureSigmaPoints,
    ExtendedKalmanFilter,
    KalmanFilter,
    LinearizedKalmanFilter,
    LinearModel,
    StateSpaceModel,
    UnscentedKalmanFilter,
)


def random_linear(rng, n, m, n_u):
    A = rng.normal(size=(n, n))
    A *= 0.97 / np.max(np.abs(np.linalg.eigvals(A)))
    M = rng.normal(size=(m, m))
    return LinearModel(A=A, C=rng.normal(size=(m, n)), B=rng.normal(size=(n, n_u)) if n_u else None,
                       Q=np.diag(rng.uniform(0.01, 0.1, n)), R=M @ M.T + 0.1 * np.eye(m))


def run_pair(make, n_y, n_u, steps, rng, batch=None, nan_at=(), scale=0.3, between=None,
             nis_rtol=1e-10):
    """Step a filter on the compiled twin and its copy on the numpy reference on the same
    data; return the largest differences of x and P and the two filters."""
    twin = make()
    ref = copy.deepcopy(twin)
    shape = (n_y,) if batch is None else (batch, n_y)
    dx = dP = 0.0
    for k in range(steps):
        y = scale * rng.normal(size=shape)
        if k in nan_at:
            y[..., 0] = np.nan
        u = rng.normal(size=shape[:-1] + (n_u,)) if k else None
        xt, xr = step_on(twin, True, y, u), step_on(ref, False, y, u)
        dx = max(dx, np.abs(xt - xr).max())
        dP = max(dP, np.abs(twin.P - ref.P).max())
        np.testing.assert_array_equal(twin.diverged, ref.diverged)
        nt, nr = twin.last_info["nis"], ref.last_info["nis"]
        np.testing.assert_array_equal(np.isnan(nt), np.isnan(nr))
        np.testing.assert_allclose(nt, nr, rtol=nis_rtol)
        if between is not None:
            between(k, twin)
            between(k, ref)
    return dx, dP, twin, ref


@needs_twins
@pytest.mark.parametrize("batch", [None, 5])
@pytest.mark.parametrize(("n", "m", "n_u"), [(1, 1, 0), (2, 1, 1), (3, 2, 1), (4, 2, 0),
                                             (4, 4, 2), (3, 3, 1)])
def test_kalman_twin_equals_numpy_reference(n, m, n_u, batch):
    rng = np.random.default_rng(n * 10 + m)
    model = random_linear(rng, n, m, n_u)
    x0, P0 = rng.normal(size=n), np.eye(n) * 2.0

    def make():
        return KalmanFilter(model, x0=x0, P0=P0, nan_policy="skip")
    dx, dP, twin, ref = run_pair(make, m, n_u, 1200, rng, batch, nan_at=(50, 51, 200))
    assert dx <= 1e-12 and dP <= 1e-12
    assert twin.steady_state and ref.steady_state   # both reached the steady-state regime


@needs_twins
@pytest.mark.parametrize("batch", [None, 7])
def test_kalman_twin_with_per_system_covariances_and_restarts(batch):
    """A batched prior (a covariance per system), skipped measurements and restarts."""
    rng = np.random.default_rng(11)
    model = random_linear(rng, 3, 2, 1)
    B = batch or 1
    P0 = np.stack([np.eye(3) * (1.0 + b) for b in range(B)])

    def make():
        return KalmanFilter(model, x0=np.zeros((B, 3)), P0=P0, nan_policy="skip")

    def between(k, flt):
        if k == 300:
            flt.restart([0])

    dx, dP, twin, _ = run_pair(make, 2, 1, 600, rng, B, nan_at=(40, 41), between=between)
    assert dx <= 1e-12 and dP <= 1e-12
    assert twin.steady_state


@needs_twins
@pytest.mark.parametrize("batch", [None, 4])
@pytest.mark.parametrize("n", [2, 4])
def test_ekf_twin_on_a_linear_model_equals_numpy_reference(n, batch):
    rng = np.random.default_rng(n)
    model = random_linear(rng, n, 2, 1)

    def make():
        return ExtendedKalmanFilter(model, x0=np.ones(n), P0=np.eye(n), nan_policy="skip")
    dx, dP, _, _ = run_pair(make, 2, 1, 300, rng, batch, nan_at=(20,))
    assert dx <= 1e-12 and dP <= 1e-12


@needs_twins
@pytest.mark.parametrize("batch", [None, 6])
@pytest.mark.parametrize("cls", [ExtendedKalmanFilter, LinearizedKalmanFilter])
def test_ekf_and_lkf_twins_on_a_nonlinear_model_equal_numpy_reference(cls, batch):
    rng = np.random.default_rng(3)

    def make():
        return cls(duffing_model(), x0=[0.5, 0.0, 1.0], P0=0.1 * np.eye(3), nan_policy="skip")

    def between(k, flt):
        if k == 150 and batch:
            flt.restart([1, 3])
    dx, dP, _, _ = run_pair(make, 2, 1, 400, rng, batch, nan_at=(30, 31), between=between)
    assert dx <= 1e-12 and dP <= 1e-12


@needs_twins
@pytest.mark.parametrize("batch", [None, 5])
@pytest.mark.parametrize("points", ["merwe", "cubature"])
@pytest.mark.parametrize("redraw", [True, False])
def test_ukf_twin_equals_numpy_reference(points, redraw, batch):
    rng = np.random.default_rng(5)
    model = duffing_model()
    opts = {"alpha": 1.0} if points == "merwe" else {"points": CubatureSigmaPoints(3)}

    def make():
        return UnscentedKalmanFilter(model, x0=[0.5, 0.0, 1.0], P0=0.1 * np.eye(3),
                                     redraw=redraw, nan_policy="skip", **opts)

    def between(k, flt):
        if k == 120 and batch:
            flt.restart([2])
    dx, dP, _, _ = run_pair(make, 2, 1, 300, rng, batch, nan_at=(60,), between=between)
    assert dx <= 1e-12 and dP <= 1e-12


@needs_twins
def test_twins_serve_every_configuration():
    """Finite-difference Jacobians, large sigma-point weights (α = 1e-3) and jitter run on
    the compiled twins too. Both amplify round-off — an FD Jacobian by ``1/step ≈ 2e5``, the
    α = 1e-3 weights by ``1/α² = 1e6`` — so the two paths agree to that factor times the
    1e-12 of the well-conditioned cases (the one-step bound of the unscented moments is in
    test_compiled.py)."""
    d = Duffing()
    fd = StateSpaceModel(f=d.f, h=d.h, Q=np.eye(3) * 1e-4, R=np.eye(2) * 1e-2, n_u=1)
    rng = np.random.default_rng(8)
    for make, tol in ((lambda: ExtendedKalmanFilter(fd, x0=[0.5, 0, 1], P0=0.1 * np.eye(3)),
                       2e5 * 1e-12),
                      (lambda: UnscentedKalmanFilter(duffing_model(), x0=[0.5, 0, 1],
                                                     P0=0.1 * np.eye(3)), 1e6 * 1e-12),
                      (lambda: UnscentedKalmanFilter(duffing_model(), x0=[0.5, 0, 1],
                                                     P0=0.1 * np.eye(3), alpha=1.0,
                                                     jitter=1e-9), 1e-12)):
        assert make().has_compiled_step
        dx, dP, _, _ = run_pair(make, 2, 1, 100, rng, nis_rtol=tol * 100)
        assert dx <= tol and dP <= tol


@needs_twins
@pytest.mark.parametrize("cls", [KalmanFilter, ExtendedKalmanFilter, UnscentedKalmanFilter])
def test_divergence_is_booked_alike_on_both_paths(cls):
    """An overconfident filter whose NIS explodes: both paths flag it after ``nis_patience``
    steps and keep flagging (no hand-back); estimates agree to 1e-12."""
    model = random_linear(np.random.default_rng(0), 2, 1, 1)
    opts = {"alpha": 1.0} if cls is UnscentedKalmanFilter else {}
    twin = cls(model, P0=1e-12 * np.eye(2), nis_patience=3, **opts)
    ref = copy.deepcopy(twin)
    flags = []
    for k in range(8):
        y = np.array([1e3 * (k + 1)])
        xt = step_on(twin, True, y, [0.0] if k else None)
        xr = step_on(ref, False, y, [0.0] if k else None)
        np.testing.assert_allclose(xt, xr, rtol=1e-12, atol=1e-12)
        assert twin.diverged == ref.diverged
        flags.append(twin.diverged)
    assert flags == [False] * 2 + [True] * 6          # three NIS above the threshold: flagged
    assert_rejects_bad_input(twin)
    assert twin.step([0.5], 0.0).shape == (2,)           # a list and a scalar input


@pytest.mark.parametrize("cls", [KalmanFilter, ExtendedKalmanFilter, UnscentedKalmanFilter,
                                 LinearizedKalmanFilter])
def test_a_single_system_is_a_batch_of_one(cls):
    """``(n_y,)`` and ``(1, n_y)`` take the same code: the same bits, on either path."""
    model = duffing_model() if cls is not KalmanFilter else random_linear(
        np.random.default_rng(4), 3, 2, 1)
    rng = np.random.default_rng(9)
    ys, us = 0.3 * rng.normal(size=(200, 2)), rng.normal(size=(200, 1))
    for path in ((), (numpy_path,)):
        a = cls(model, x0=[0.5, 0.0, 1.0], P0=0.1 * np.eye(3))
        b = cls(model, x0=[0.5, 0.0, 1.0], P0=0.1 * np.eye(3))
        for k in range(200):
            u = None if k == 0 else us[k]
            if path:
                with numpy_path():
                    xa, xb = a.step(ys[k], u), b.step(ys[k][None], None if u is None else u[None])
            else:
                xa, xb = a.step(ys[k], u), b.step(ys[k][None], None if u is None else u[None])
            np.testing.assert_array_equal(xa, xb[0])
            np.testing.assert_array_equal(a.P, b.P[0])


def test_returned_estimate_is_a_copy_and_reset_restarts_cleanly():
    model = random_linear(np.random.default_rng(1), 2, 1, 0)
    kf = KalmanFilter(model)
    kf.step(np.zeros(1))
    x = kf.step(np.ones(1))
    x[:] = 1e9
    assert np.all(np.abs(kf.x) < 1e3)
    before = [kf.step(np.ones(1)) for _ in range(3)]
    kf.reset()
    kf.step(np.zeros(1))
    kf.step(np.ones(1))
    assert np.allclose([kf.step(np.ones(1)) for _ in range(3)], before, rtol=0, atol=1e-12)


def test_a_subclass_that_overrides_a_step_hook_steps_on_numpy():
    calls = []

    class Custom(KalmanFilter):
        def _predict_update(self, *args):
            calls.append(1)
            return super()._predict_update(*args)

    assert KalmanFilter.has_compiled_step and not Custom.has_compiled_step
    flt = Custom(random_linear(np.random.default_rng(2), 2, 1, 0))
    flt.step(np.zeros(1))
    flt.step(np.zeros(1))
    assert calls == [1]
