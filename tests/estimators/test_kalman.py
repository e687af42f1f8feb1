"""Kalman filter and linearised Kalman filter: oracles are scipy's DARE, plain textbook loops
written here with ``np.linalg.solve``, χ² statistics and exact algebraic identities."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.stats
from compiled_paths import on_path

from fir_gym.estimators import LinearModel, StateSpaceModel, TimeVaryingLinearModel
from fir_gym.estimators.kalman import (
    KalmanFilter,
    kf_predict,
    kf_update,
)
from fir_gym.estimators.linearized import LinearizedKalmanFilter
from fir_gym.estimators.registry import estimator_names, make_estimator


def random_system(rng, n, m, n_u=0, scale=1.0):
    A = rng.normal(size=(n, n)) * scale / np.sqrt(n)
    C = rng.normal(size=(m, n))
    Gq = rng.normal(size=(n, n))
    Q = Gq @ Gq.T / n + 0.1 * np.eye(n)
    Gr = rng.normal(size=(m, m))
    R = Gr @ Gr.T / m + 0.1 * np.eye(m)
    B = rng.normal(size=(n, n_u)) if n_u else None
    return LinearModel(A=A, C=C, Q=Q, R=R, B=B)


def textbook_kf(A, B, C, Q, R, x0, P0, ys, us):
    """Plain KF: P⁺ = (I - K C) P⁻ (I - K C)ᵀ + K R Kᵀ with K from np.linalg.solve."""
    x, P, out = x0.copy(), P0.copy(), []
    for k, y in enumerate(ys):
        if k:
            x = A @ x + (B @ us[k] if B is not None else 0.0)
            P = A @ P @ A.T + Q
        S = C @ P @ C.T + R
        K = np.linalg.solve(S, C @ P).T
        x = x + K @ (y - C @ x)
        IKC = np.eye(len(x)) - K @ C
        P = IKC @ P @ IKC.T + K @ R @ K.T
        out.append((x.copy(), P.copy()))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_steady_state_covariance_equals_dare(seed):
    rng = np.random.default_rng(seed)
    n, m = [(1, 1), (2, 1), (3, 2), (4, 2), (5, 3), (6, 4)][seed]
    model = random_system(rng, n, m, scale=1.3)          # often unstable: still detectable
    kf = KalmanFilter(model)
    for _ in range(2000):
        kf.step(rng.normal(size=m))
    A, C, Q, R = model.A, model.C, model.Q, model.R
    P_pred = scipy.linalg.solve_discrete_are(A.T, C.T, Q, R)
    P_filt = P_pred - P_pred @ C.T @ np.linalg.solve(C @ P_pred @ C.T + R, C @ P_pred)
    np.testing.assert_allclose(kf.P, P_filt, rtol=1e-8, atol=1e-8 * np.abs(P_filt).max())


@pytest.mark.parametrize("n,m,n_u", [(2, 1, 0), (3, 2, 1), (4, 3, 2), (5, 4, 1)])
def test_matches_textbook_loop(n, m, n_u):
    rng = np.random.default_rng(10 + n)
    model = random_system(rng, n, m, n_u)
    x0, P0 = rng.normal(size=n), 2.0 * np.eye(n)
    ys, us = rng.normal(size=(40, m)), rng.normal(size=(40, max(n_u, 1)))[:, :n_u]
    kf = KalmanFilter(model, x0=x0, P0=P0)
    ref = textbook_kf(model.A, model.B if n_u else None, model.C, model.Q, model.R,
                      x0, P0, ys, us)
    for k in range(40):
        x = kf.step(ys[k], us[k] if k and n_u else None)
        np.testing.assert_allclose(x, ref[k][0], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.P, ref[k][1], rtol=1e-10, atol=1e-12)


def test_steady_state_shortcut_equals_full_recursion():
    """A constant TimeVaryingLinearModel never takes the shortcut; results must agree."""
    rng = np.random.default_rng(3)
    model = random_system(rng, 3, 2, 1)
    tv = TimeVaryingLinearModel(A=model.A, B=model.B, C=model.C, Q=model.Q, R=model.R)
    a, b = KalmanFilter(model), KalmanFilter(tv)
    for _k in range(600):
        y, u = rng.normal(size=2), rng.normal(size=1)
        np.testing.assert_allclose(a.step(y, u), b.step(y, u), rtol=1e-12, atol=1e-13)
    assert a.steady_state                                  # the shortcut was exercised
    np.testing.assert_allclose(a.P, b.P, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_time_varying_convention(path):
    """Prediction into x[k] uses matrices(k-1)'s A, B, Q; the update at k uses C(k), R(k) — on
    the numpy reference and on the compiled twin (mutation testing found the reference's
    index untested: the run took the twin)."""
    rng = np.random.default_rng(4)
    As = [rng.normal(size=(2, 2)) * 0.7 for _ in range(8)]
    Cs = [rng.normal(size=(1, 2)) for _ in range(8)]
    Qs = [np.eye(2) * (0.1 + 0.05 * k) for k in range(8)]
    Rs = [np.array([[0.2 + 0.1 * k]]) for k in range(8)]
    Bs = [rng.normal(size=(2, 1)) for _ in range(8)]
    tv = TimeVaryingLinearModel(A=lambda k: As[k], C=lambda k: Cs[k], Q=lambda k: Qs[k],
                                R=lambda k: Rs[k], B=lambda k: Bs[k])
    kf = KalmanFilter(tv)
    x, P = np.zeros(2), np.eye(2)
    for k in range(8):
        y, u = rng.normal(size=1), rng.normal(size=1)
        if k:
            x, P = As[k - 1] @ x + Bs[k - 1] @ u, As[k - 1] @ P @ As[k - 1].T + Qs[k - 1]
        S = Cs[k] @ P @ Cs[k].T + Rs[k]
        K = np.linalg.solve(S, Cs[k] @ P).T
        x, P = x + K @ (y - Cs[k] @ x), (np.eye(2) - K @ Cs[k]) @ P
        with on_path(path):
            estimate = kf.step(y, u)
        np.testing.assert_allclose(estimate, x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.P, P, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("batched_prior", [False, True])
def test_batched_equals_looped(batched_prior):
    rng = np.random.default_rng(5)
    model = random_system(rng, 3, 2, 1)
    B = 7
    x0 = rng.normal(size=(B, 3))
    P0 = np.stack([np.eye(3) * (1 + i) for i in range(B)]) if batched_prior else 2 * np.eye(3)
    batch = KalmanFilter(model, x0=x0, P0=P0, nan_policy="skip")
    singles = [KalmanFilter(model, x0=x0[i], P0=P0[i] if batched_prior else P0,
                            nan_policy="skip") for i in range(B)]
    for k in range(300):
        Y, U = rng.normal(size=(B, 2)), rng.normal(size=(B, 1))
        if k in (50, 51, 120):
            Y[k % B] = np.nan                               # missing measurements
        X = batch.step(Y, U)
        for i, f in enumerate(singles):
            np.testing.assert_allclose(X[i], f.step(Y[i], U[i]), rtol=1e-12, atol=1e-12)
    for i, f in enumerate(singles):
        np.testing.assert_allclose(batch.P[i], f.P, rtol=1e-12, atol=1e-14)


def test_nees_in_chi2_band():
    """NEES of a correctly specified filter, averaged over 200 fixed-seed runs, is χ²(M n)/M."""
    rng = np.random.default_rng(6)
    n, m, M, T = 3, 2, 200, 60
    model = random_system(rng, n, m)
    Lq, Lr = np.linalg.cholesky(model.Q), np.linalg.cholesky(model.R)
    P0 = np.eye(n)
    x = rng.normal(size=(M, n))                             # x[0] ~ N(0, P0)
    kf = KalmanFilter(model, P0=P0)
    lo, hi = (scipy.stats.chi2.ppf(q, M * n) / M for q in (0.025, 0.975))
    inside = []
    for k in range(T):
        if k:
            x = x @ model.A.T + rng.normal(size=(M, n)) @ Lq.T
        y = x @ model.C.T + rng.normal(size=(M, m)) @ Lr.T
        e = kf.step(y) - x
        nees = np.einsum("bi,bij,bj->b", e, np.linalg.inv(kf.P), e)
        inside.append(lo <= nees.mean() <= hi)
    assert np.mean(inside) >= 0.9                            # 95 % band, 60 times


def test_kf_update_pure_function_and_nis():
    rng = np.random.default_rng(7)
    x, P = rng.normal(size=3), np.diag([1.0, 2.0, 3.0])
    H, R, y = rng.normal(size=(2, 3)), np.diag([0.5, 0.25]), rng.normal(size=2)
    x1, P1, info = kf_update(x, P, y, H, R)
    S = H @ P @ H.T + R
    e = y - H @ x
    np.testing.assert_allclose(info.S, S)
    np.testing.assert_allclose(info.nis, e @ np.linalg.solve(S, e))
    np.testing.assert_allclose(x1, x + P @ H.T @ np.linalg.solve(S, e))
    np.testing.assert_allclose(P1, P - P @ H.T @ np.linalg.solve(S, H @ P), atol=1e-14)
    xb, _Pb, _infob = kf_update(np.stack([x, x]), np.stack([P, P]), np.stack([y, y]), H, R)
    np.testing.assert_allclose(xb[1], x1, rtol=1e-14)
    xp, Pp = kf_predict(x, P, np.eye(3) * 2, np.eye(3), B=np.ones((3, 1)), u=[1.0])
    np.testing.assert_allclose(xp, 2 * x + 1)
    np.testing.assert_allclose(Pp, 4 * P + np.eye(3))


def test_kf_pure_functions_take_scalars_for_a_one_state_system():
    """A scalar ``F``, ``Q``, ``H``, ``R`` stands for the 1 x 1 matrix (mutation testing found
    the rule untested): the scalar textbook recursion."""
    x, P, F, Q, H, R, y = 0.5, 2.0, 0.9, 0.1, 1.5, 0.4, 1.2
    xp, Pp = kf_predict([x], [[P]], F, Q)
    np.testing.assert_allclose(xp, [F * x])
    np.testing.assert_allclose(Pp, [[F * P * F + Q]])
    x1, P1, info = kf_update(xp, Pp, [y], H, R)
    S = H * Pp[0, 0] * H + R
    K = Pp[0, 0] * H / S
    np.testing.assert_allclose(info.S, [[S]])
    np.testing.assert_allclose(x1, [xp[0] + K * (y - H * xp[0])])
    np.testing.assert_allclose(P1, [[(1 - K * H) ** 2 * Pp[0, 0] + K * R * K]])


def test_kf_pure_functions_name_the_batched_shape_they_accept():
    """A batch's wrong matrix is refused with both shapes it could have had."""
    x, P = np.zeros((3, 2)), np.stack([np.eye(2)] * 3)
    with pytest.raises(ValueError, match=r"F must have shape \(2, 2\) or \(3, 2, 2\); got "
                                         r"shape \(3, 3\)"):
        kf_predict(x, P, np.eye(3), np.eye(2))
    with pytest.raises(ValueError, match=r"F must have shape \(2, 2\); got shape \(3, 3\)$"):
        kf_predict(x[0], P[0], np.eye(3), np.eye(2))


def test_kf_update_rejects_singular_S_and_bad_shapes():
    with pytest.raises(ValueError, match="positive definite"):
        kf_update(np.zeros(2), np.zeros((2, 2)), [1.0], [[1.0, 0.0]], [[0.0]])
    with pytest.raises(ValueError, match="P must"):
        kf_update(np.zeros(2), np.eye(3), [1.0], [[1.0, 0.0]], [[1.0]])
    with pytest.raises(ValueError, match="H must"):
        kf_update(np.zeros(2), np.eye(2), [1.0], [[1.0, 0.0, 0.0]], [[1.0]])
    with pytest.raises(ValueError, match=r"H must have shape \(m, 2\); got shape \(2,\)"):
        kf_update(np.zeros(2), np.eye(2), [1.0], [1.0, 0.0], [[1.0]])
    with pytest.raises(ValueError, match=r"H must have shape \(m, 2\) or \(3, m, 2\)"):
        kf_update(np.zeros((3, 2)), np.stack([np.eye(2)] * 3), np.ones((3, 1)), 1.0, [[1.0]])
    with pytest.raises(ValueError, match="R must"):
        kf_update(np.zeros(2), np.eye(2), [1.0], [[1.0, 0.0]], np.eye(2))


def test_bad_input():
    model = LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2), R=[[1.0]])
    with pytest.raises(TypeError, match="model"):
        KalmanFilter(StateSpaceModel(f=lambda x, u: x, h=lambda x: x, Q=1.0, R=1.0))
    with pytest.raises(ValueError, match="P0 must be symmetric"):
        KalmanFilter(model, P0=[[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="P0 must be positive semi-definite"):
        KalmanFilter(model, P0=[[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="P0"):
        KalmanFilter(model, P0=np.eye(3))
    with pytest.raises(ValueError, match="x0"):
        KalmanFilter(model, x0=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="Q must be symmetric"):
        LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=[[1.0, 0.3], [0.0, 1.0]], R=[[1.0]])
    with pytest.raises(ValueError, match="R must be positive semi-definite"):
        LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2), R=[[-1.0]])
    kf = KalmanFilter(model)
    with pytest.raises(ValueError, match="y must have shape"):
        kf.step([1.0, 2.0])
    with pytest.raises(ValueError, match="y must be finite"):
        kf.step([np.nan])
    kf.step([1.0])
    with pytest.raises(ValueError, match="u must have shape"):
        kf.step([1.0], u=[1.0])
    with pytest.raises(ValueError, match="y must have shape"):
        kf.step(np.ones((3, 1)))                           # batch size changed


def test_nan_policy_skip_predicts_only():
    model = LinearModel(A=[[1.0, 1.0], [0.0, 1.0]], C=[[1.0, 0.0]], Q=np.eye(2) * 0.1, R=[[1.0]])
    kf = KalmanFilter(model, x0=[1.0, 2.0], nan_policy="skip")
    kf.step([1.5])
    x, P = kf.x, kf.P
    out = kf.step([np.nan])
    np.testing.assert_allclose(out, model.A @ x)
    np.testing.assert_allclose(kf.P, model.A @ P @ model.A.T + model.Q)
    assert np.isnan(kf.last_info["nis"]) and not kf.diverged


def test_covariance_symmetric_psd_over_long_run():
    """1e5 steps here (the 1e6 figure is in the report); P stays symmetric PSD and bounded."""
    rng = np.random.default_rng(8)
    model = random_system(rng, 4, 1, scale=1.2)
    kf = KalmanFilter(model, nan_policy="skip")
    Y = rng.normal(size=(100_000, 1))
    Y[rng.random(100_000) < 0.3] = np.nan                  # breaks the steady-state shortcut
    for y in Y:
        kf.step(y)
    P = kf.P
    assert np.array_equal(P, P.T)
    assert np.linalg.eigvalsh(P)[0] > 0 and not kf.diverged


def test_lkf_equals_kf_on_linear_model():
    rng = np.random.default_rng(9)
    model = random_system(rng, 3, 2, 1)
    x0 = rng.normal(size=3)
    kf, lkf = KalmanFilter(model, x0=x0), LinearizedKalmanFilter(model, x0=x0)
    for _k in range(50):
        y, u = rng.normal(size=2), rng.normal(size=1)
        np.testing.assert_allclose(lkf.step(y, u), kf.step(y, u), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(lkf.P, kf.P, rtol=1e-10, atol=1e-13)


def test_lkf_along_exact_nominal_equals_kf_on_linearised_model():
    """On a nonlinear model the LKF is the KF of the perturbation model along x_nom."""
    dt = 0.05

    def f(x, u):
        return np.stack([x[..., 0] + dt * x[..., 1],
                         x[..., 1] + dt * (-np.sin(x[..., 0]) + u[..., 0])], axis=-1)

    def F(x, u):
        J = np.zeros(x.shape[:-1] + (2, 2))
        J[..., 0, 0] = J[..., 1, 1] = 1.0
        J[..., 0, 1] = dt
        J[..., 1, 0] = -dt * np.cos(x[..., 0])
        return J

    def h(x):
        return np.stack([np.sin(x[..., 0]), x[..., 0] * x[..., 1]], axis=-1)

    def H(x):
        return np.stack([np.stack([np.cos(x[..., 0]), 0 * x[..., 0]], -1),
                         np.stack([x[..., 1], x[..., 0]], -1)], -2)

    Q, R = np.eye(2) * 1e-3, np.eye(2) * 1e-2
    model = StateSpaceModel(f=f, h=h, F=F, H=H, Q=Q, R=R, n_u=1, dt=dt)
    rng = np.random.default_rng(11)
    T, x0 = 40, np.array([0.4, -0.2])
    us = rng.normal(size=(T, 1))
    xs = [x0]
    for k in range(1, T):
        xs.append(f(xs[-1], us[k]))
    As = [F(xs[k], us[k + 1]) for k in range(T - 1)] + [np.eye(2)]
    Cs = [H(x) for x in xs]
    tv = TimeVaryingLinearModel(A=lambda k: As[k], C=lambda k: Cs[k], Q=Q, R=R)
    lkf, kf = LinearizedKalmanFilter(model, x0=x0), KalmanFilter(tv)
    for k in range(T):
        y = h(xs[k]) + rng.normal(size=2) * 0.1
        dx = kf.step(y - h(xs[k]))          # δy = y − h(x_nom) = C δx + v
        np.testing.assert_allclose(lkf.step(y, us[k]), xs[k] + dx, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(lkf.x_nominal, xs[k], rtol=1e-12)


def test_registry():
    model = LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2), R=[[1.0]])
    assert {"kf", "lkf"} <= set(estimator_names())
    assert isinstance(make_estimator("kf", model, x0=[1.0, 0.0]), KalmanFilter)
    with pytest.raises(ValueError, match=r"known estimators are .*kf"):
        make_estimator("nope", model)


@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_a_restart_in_the_steady_state_leaves_it_and_starts_from_the_prior(path):
    """Once the batch has settled (``P``, ``K`` kept), restarting one system leaves the
    steady-state regime: that system starts from its prior as a fresh filter does (the
    textbook recursion, :func:`textbook_kf`), the others keep their estimates, and the batch
    settles again later (mutation testing found the restart's regime switch untested)."""
    rng = np.random.default_rng(8)
    model = random_system(rng, 3, 2, 1)
    x0, P0 = np.zeros(3), 4.0 * np.eye(3)
    T, k_r = 700, 600
    Y, U = rng.normal(size=(T, 2, 2)), rng.normal(size=(T, 2, 1))
    with on_path(path):
        kf = KalmanFilter(model, x0=np.zeros((2, 3)), P0=P0)
        out = []
        for k in range(T):
            if k == k_r:
                assert kf.steady_state                       # the batch had settled
                kf.restart([1])
                assert not kf.steady_state
            out.append(kf.step(Y[k], U[k - 1] if k else None))
        assert kf.steady_state                               # and settles again
    out = np.array(out)
    fresh = textbook_kf(model.A, model.B, model.C, model.Q, model.R, x0, P0, Y[k_r:, 1],
                        np.concatenate([np.zeros((1, 1)), U[k_r:-1, 1]]))
    np.testing.assert_allclose(out[k_r:, 1], [x for x, _ in fresh], rtol=1e-9, atol=1e-10)
    alone = KalmanFilter(model, x0=x0, P0=P0)
    ref = np.array([alone.step(Y[k, 0], U[k - 1, 0] if k else None) for k in range(T)])
    np.testing.assert_allclose(out[:, 0], ref, rtol=1e-9, atol=1e-10)
