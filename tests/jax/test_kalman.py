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


@pytest.mark.parametrize("n,m", [(1, 1), (2, 1), (3, 2), (4, 3)])
def test_the_joseph_update_is_formed_from_factors_as_the_numpy_references(n: int, m: int
                                                                         ) -> None:
    """``factored_joseph`` against :func:`fir_gym.estimators._kalman_linalg.factored_joseph`
    (the same factors, the same operations: to a few ulps) and against the plain Joseph
    product of the same float64 inputs in exact rational arithmetic (``fractions``)."""
    from fractions import Fraction

    from fir_gym.estimators._kalman_linalg import factored_joseph

    def exact_joseph(P: np.ndarray, H: np.ndarray, R: np.ndarray, K: np.ndarray
                     ) -> np.ndarray:
        def q(M: np.ndarray) -> list[list[Fraction]]:
            return [[Fraction(float(v)) for v in row] for row in np.atleast_2d(M)]

        def mul(A: list[list[Fraction]], B: list[list[Fraction]]) -> list[list[Fraction]]:
            return [[sum((a * b for a, b in zip(row, col, strict=True)), Fraction(0))
                     for col in zip(*B, strict=True)] for row in A]

        def t(A: list[list[Fraction]]) -> list[list[Fraction]]:
            return [list(c) for c in zip(*A, strict=True)]

        KH = mul(q(K), q(H))
        A = [[Fraction(int(i == j)) - KH[i][j] for j in range(len(KH))]
             for i in range(len(KH))]
        first, second = mul(mul(A, q(P)), t(A)), mul(mul(q(K), q(R)), t(q(K)))
        return np.array([[float(a + b) for a, b in zip(r1, r2, strict=True)]
                         for r1, r2 in zip(first, second, strict=True)])

    rng = np.random.default_rng(7 * n + m)
    for _ in range(5):
        P, H, R = spd(rng, n), rng.normal(size=(m, n)), spd(rng, m)
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R) + 0.1 * rng.normal(size=(n, m))
        ours = np.asarray(jax.jit(jk.factored_joseph)(*map(jnp.asarray, (P, H, R, K))))
        np.testing.assert_array_equal(ours, ours.T)
        theirs = factored_joseph(P[None], H, R, K[None])[0]
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=32 * np.finfo(float).eps
                                   * np.abs(theirs).max())
        exact = exact_joseph(P, H, R, K)
        np.testing.assert_allclose(ours, exact, rtol=0, atol=1e-13 * np.abs(exact).max())


def test_the_joseph_update_stays_positive_semidefinite_far_above_r() -> None:
    """``P⁻ = 1e12 I``, ``R = 1e-12`` (docs/architecture.md, covariance updates): the exact
    ``P⁺ ≈ R`` is smaller than the plain product's round-off ``ε ‖P⁻‖ ≈ 1e-4``, which left
    the cone (the numpy reference's own example); formed from factors it is exactly
    symmetric with no eigenvalue below ``−γ ‖P⁺‖``, and equals the numpy reference's."""
    from fir_gym.estimators._kalman_linalg import factored_joseph

    rng = np.random.default_rng(12)
    worst_plain = 0.0
    for _ in range(50):
        Q, _ = np.linalg.qr(rng.normal(size=(2, 2)))
        P = 1e12 * (Q * np.array([1.0, 3.0])) @ Q.T
        P = 0.5 * (P + P.T)
        H, R = rng.normal(size=(1, 2)), np.array([[1e-12]])
        K = P @ H.T / (H @ P @ H.T + R)[0, 0]
        ours = np.asarray(jk.factored_joseph(*map(jnp.asarray, (P, H, R, K))))
        np.testing.assert_array_equal(ours, ours.T)
        assert np.linalg.eigvalsh(ours).min() >= -4 * np.finfo(float).eps * np.abs(ours).max()
        theirs = factored_joseph(P[None], H, R, K[None])[0]
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=64 * np.finfo(float).eps
                                   * np.abs(theirs).max())
        A = np.eye(2) - K @ H
        plain = A @ P @ A.T + K @ R @ K.T
        worst_plain = min(worst_plain, float(np.linalg.eigvalsh(0.5 * (plain + plain.T)).min()))
    assert worst_plain < -1e-6               # the plain product does leave the cone here


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
