"""The single-system fast paths (generated float kernels, estimators/_small.py) equal the
general batched path: one system given as ``(n_y,)`` against the same system as a batch
of one ``(1, n_y)`` (the general code), to 1e-12, through transients, the KF's steady
state, skipped measurements, divergence and restarts."""

import numpy as np
import pytest
from estimator_checks import assert_rejects_bad_input
from sample_models import Duffing, duffing_model

from fir_gym.estimators import (
    CubatureSigmaPoints,
    ExtendedKalmanFilter,
    KalmanFilter,
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


def run_pair(make, n_y, n_u, steps, rng, nan_at=(), scale=0.3):
    """Step a single-system filter and a batch-of-one twin on the same data; return the
    largest differences of x and P and the two filters."""
    single, batch = make(), make()
    dx = dP = 0.0
    for k in range(steps):
        y = scale * rng.normal(size=n_y)
        if k in nan_at:
            y[0] = np.nan
        u = rng.normal(size=n_u) if k else None
        xs = single.step(y, u)
        xb = batch.step(y[None], None if u is None else u[None])[0]
        dx = max(dx, np.abs(xs - xb).max())
        dP = max(dP, np.abs(single.P - batch.P[0]).max())
        assert single.diverged == bool(batch.diverged[0])
        if single.last_info["nis"] is None or np.isnan(single.last_info["nis"]):
            assert batch.last_info["nis"] is None or np.isnan(batch.last_info["nis"][0])
        else:
            np.testing.assert_allclose(single.last_info["nis"], batch.last_info["nis"][0],
                                       rtol=1e-10)
    return dx, dP, single, batch


@pytest.mark.parametrize(("n", "m", "n_u"), [(1, 1, 0), (2, 1, 1), (3, 2, 1), (4, 2, 0),
                                             (4, 4, 2), (3, 3, 1)])
def test_kalman_fast_path_equals_general_path(n, m, n_u):
    rng = np.random.default_rng(n * 10 + m)
    model = random_linear(rng, n, m, n_u)
    x0, P0 = rng.normal(size=n), np.eye(n) * 2.0

    def make():
        return KalmanFilter(model, x0=x0, P0=P0, nan_policy="skip")
    dx, dP, single, _ = run_pair(make, m, n_u, 1200, rng, nan_at=(50, 51, 200))
    assert single._lean is not None
    assert dx <= 1e-12 and dP <= 1e-12
    assert single._lean_steady is not None             # reached the steady-state regime


@pytest.mark.parametrize("n", [2, 4])
def test_ekf_fast_path_on_a_linear_model_equals_general_path(n):
    rng = np.random.default_rng(n)
    model = random_linear(rng, n, 2, 1)

    def make():
        return ExtendedKalmanFilter(model, x0=np.ones(n), P0=np.eye(n))
    dx, dP, single, _ = run_pair(make, 2, 1, 300, rng)
    assert single._lean is not None and dx <= 1e-12 and dP <= 1e-12


def test_ekf_fast_path_on_a_nonlinear_model_equals_general_path():
    rng = np.random.default_rng(3)

    def make():
        return ExtendedKalmanFilter(duffing_model(), x0=[0.5, 0.0, 1.0], P0=0.1 * np.eye(3))
    dx, dP, single, _ = run_pair(make, 2, 1, 400, rng)
    assert single._lean is not None and dx <= 1e-12 and dP <= 1e-12


@pytest.mark.parametrize("points", ["merwe", "cubature"])
@pytest.mark.parametrize("redraw", [True, False])
def test_ukf_fast_path_equals_general_path(points, redraw):
    rng = np.random.default_rng(5)
    model = duffing_model()
    opts = {"alpha": 1.0} if points == "merwe" else {"points": CubatureSigmaPoints(3)}

    def make():
        return UnscentedKalmanFilter(model, x0=[0.5, 0.0, 1.0], P0=0.1 * np.eye(3),
                                     redraw=redraw, **opts)
    dx, dP, single, _ = run_pair(make, 2, 1, 300, rng)
    assert single._lean is not None and dx <= 1e-12 and dP <= 1e-12


def test_fast_path_stays_off_where_round_off_is_amplified():
    """Finite-difference Jacobians and large sigma-point weights (α = 1e-3) amplify the
    last bits of every operation: those filters stay on the general path."""
    d = Duffing()
    fd = StateSpaceModel(f=d.f, h=d.h, Q=np.eye(3) * 1e-4, R=np.eye(2) * 1e-2, n_u=1)
    ekf = ExtendedKalmanFilter(fd)
    ukf = UnscentedKalmanFilter(duffing_model())               # default α = 1e-3
    for flt in (ekf, ukf):
        flt.step(np.zeros(2))
        assert flt._lean is None


def test_fast_path_hands_divergence_and_bad_input_to_the_general_path():
    """An overconfident filter whose NIS explodes, NaN measurements and odd shapes: the
    fast path returns to the general path, which flags, skips or raises as documented."""
    model = random_linear(np.random.default_rng(0), 2, 1, 1)
    a = KalmanFilter(model, P0=1e-12 * np.eye(2), nis_patience=3)
    b = KalmanFilter(model, P0=1e-12 * np.eye(2), nis_patience=3)
    for k in range(6):
        y = np.array([1e3 * (k + 1)])
        xa, xb = a.step(y, [0.0] if k else None), b.step(y[None], [[0.0]] if k else None)
        np.testing.assert_allclose(xa, xb[0], rtol=1e-12, atol=1e-12)
        assert a.diverged == bool(b.diverged[0])
    assert a.diverged
    assert_rejects_bad_input(a)
    x_list = a.step([0.5], 0.0)                             # a list and a scalar input
    assert x_list.shape == (2,)


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


def test_a_subclass_that_overrides_a_step_hook_gets_no_fast_path():
    class Custom(KalmanFilter):
        def _predict_update(self, *args):
            return super()._predict_update(*args)

    flt = Custom(random_linear(np.random.default_rng(2), 2, 1, 0))
    flt.step(np.zeros(1))
    assert flt._lean is None
