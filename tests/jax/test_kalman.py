"""fir_gym.jax.kalman against the numpy references it mirrors: the KF's prediction and
Joseph-form update (:mod:`fir_gym.estimators.kalman`) on random systems of 1–4 states and
1–3 channels, the NaN rule of a non-positive-definite ``S``, and the divergence watch
against :meth:`fir_gym.estimators.base.Estimator._accept` run by a real numpy filter."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import jax.numpy as jnp  # noqa: E402

from fir_gym.estimators.kalman import KalmanFilter, kf_predict, kf_update  # noqa: E402
from fir_gym.estimators.model import LinearModel  # noqa: E402
from fir_gym.jax import kalman as jk  # noqa: E402


def spd(rng: np.random.Generator, n: int) -> np.ndarray:
    M = rng.normal(size=(n, n))
    return M @ M.T + 0.1 * np.eye(n)


@pytest.mark.parametrize("n,m", [(1, 1), (2, 1), (3, 2), (4, 3)])
def test_predict_and_update_are_the_numpy_kfs(n: int, m: int) -> None:
    rng = np.random.default_rng(10 * n + m)
    for _ in range(5):
        x, P, F, Q = rng.normal(size=n), spd(rng, n), rng.normal(size=(n, n)), spd(rng, n)
        B, u = rng.normal(size=(n, 2)), rng.normal(size=2)
        H, R, y = rng.normal(size=(m, n)), spd(rng, m), rng.normal(size=m)
        xp, Pp = kf_predict(x, P, F, Q, B, u)
        jx, jP = jk.kf_predict(jnp.asarray(x), jnp.asarray(P), jnp.asarray(F), jnp.asarray(Q),
                               jnp.asarray(B @ u))
        np.testing.assert_allclose(jx, xp, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(jP, Pp, rtol=1e-12, atol=1e-13)
        xu, Pu, inn = kf_update(xp, Pp, y, H, R)
        jx, jP, nis = jax.jit(jk.kf_update)(jnp.asarray(xp), jnp.asarray(Pp), jnp.asarray(y),
                                            jnp.asarray(H), jnp.asarray(R))
        np.testing.assert_allclose(jx, xu, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(jP, Pu, rtol=1e-10, atol=1e-12)
        e = y - H @ xp                                   # the NIS from its definition
        assert float(nis) == pytest.approx(float(inn.nis), rel=1e-10)
        assert float(nis) == pytest.approx(e @ np.linalg.solve(H @ Pp @ H.T + R, e), rel=1e-10)


def test_an_indefinite_innovation_covariance_gives_nan() -> None:
    x, P = jnp.zeros(2), jnp.eye(2)
    x_new, P_new, nis = jk.kf_update(x, P, jnp.ones(1), jnp.array([[1.0, 0.0]]),
                                     jnp.array([[-2.0]]))
    assert not np.isfinite(np.asarray(x_new)).any() and np.isnan(float(nis))
    assert not np.isfinite(np.asarray(P_new)).all()


def test_watch_follows_the_numpy_filters_watch() -> None:
    """A KF whose model is wrong by far (its NIS runs high) and whose measurements sometimes
    go missing: the JAX watch, fed the numpy filter's step results, books the same runs, the
    same NIS and the same sticky flag, step for step (thresholds from its own χ² quantile)."""
    model = LinearModel(A=[[1.0, 1.0], [0.0, 1.0]], C=[[1.0, 0.0]], Q=1e-4 * np.eye(2),
                        R=[[1e-2]])
    kf = KalmanFilter(model, x0=[0.0, 0.0], P0=np.eye(2), nis_patience=4)
    limits = jk.watch_limits(1, nis_patience=4)
    assert limits.nis_threshold == pytest.approx(scipy.stats.chi2.isf(1e-9, 1), rel=1e-15)
    rec = jk.belief(jnp.asarray(kf.x), jnp.asarray(kf.P))
    rng = np.random.default_rng(0)
    raised = None
    for k in range(40):
        y = None if k % 7 == 3 else np.array([2.0 * k * k + rng.normal()])  # a parabola the
        kf.step(y)                                           # constant-velocity model misses
        rec = jk.watch(rec, jnp.asarray(kf.x), jnp.asarray(kf.P),
                       jnp.asarray(kf.last_info["nis"]), limits, usable=y is not None)
        assert bool(rec.diverged) == kf.diverged
        assert int(rec.nis_run) == int(kf.state.nis_run[0])
        np.testing.assert_array_equal(np.asarray(rec.x), kf.x)
        if kf.diverged and raised is None:
            raised = k
    assert raised is not None                                   # the flag did go up


def test_watch_keeps_the_last_finite_estimate() -> None:
    rec = jk.belief(jnp.array([1.0, 2.0]), jnp.eye(2))
    limits = jk.watch_limits(1)
    new = jk.watch(rec, jnp.array([jnp.nan, 0.0]), jnp.eye(2), jnp.asarray(1.0), limits)
    np.testing.assert_array_equal(np.asarray(new.x), [1.0, 2.0])
    assert bool(new.diverged)
    big = jk.watch(rec, jnp.zeros(2), 1e13 * jnp.eye(2), jnp.asarray(1.0), limits)
    assert bool(big.diverged) and float(big.P[0, 0]) == 1e13
