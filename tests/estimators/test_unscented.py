"""Unscented Kalman filter: equals the KF on linear models, matches a textbook UKF written here
with plain loops (mean-subtracted sums, Table 1 weights), batches exactly, rejects bad input."""

from __future__ import annotations

import numpy as np
import pytest

from fir_gym.estimators import LinearModel, StateSpaceModel
from fir_gym.estimators.kalman import KalmanFilter
from fir_gym.estimators.registry import make_estimator
from fir_gym.estimators.unscented import (
    CubatureSigmaPoints,
    MerweScaledSigmaPoints,
    UnscentedKalmanFilter,
    unscented_transform,
)


def nonlinear_model():
    dt = 0.05

    def f(x, u):
        return np.stack([x[..., 0] + dt * x[..., 1],
                         x[..., 1] + dt * (-np.sin(x[..., 0]) - 0.2 * x[..., 1] * x[..., 2]),
                         x[..., 2] + dt * u[..., 0] * np.cos(x[..., 0])], -1)

    def h(x):
        return np.stack([np.hypot(x[..., 0], 1.0 + x[..., 2]), np.arctan2(x[..., 1], 2.0)], -1)

    return StateSpaceModel(f=f, h=h, Q=np.diag([1e-4, 1e-3, 1e-4]), R=np.diag([1e-2, 4e-3]),
                           n_u=1, dt=dt)


def textbook_ukf(model, x0, P0, ys, us, alpha, beta, kappa, redraw):
    """Paper 003 Table 2 with +Q, +R and the outer product restored; plain loops."""
    n = len(x0)
    lam = alpha**2 * (n + kappa) - n
    Wm = [lam / (n + lam)] + [1 / (2 * (n + lam))] * (2 * n)
    Wc = [lam / (n + lam) + 1 - alpha**2 + beta] + [1 / (2 * (n + lam))] * (2 * n)

    def sigmas(x, P):
        L = np.linalg.cholesky((n + lam) * P)
        return [x] + [x + L[:, i] for i in range(n)] + [x - L[:, i] for i in range(n)]

    def transform(points, noise):
        mean = sum(w * p for w, p in zip(Wm, points, strict=True))
        cov = sum(w * np.outer(p - mean, p - mean) for w, p in zip(Wc, points, strict=True))
        return mean, cov + noise

    x, P, out = x0.copy(), P0.copy(), []
    for k, y in enumerate(ys):
        X = sigmas(x, P)
        if k:
            X = [model.f(s, us[k]) for s in X]
            x, P = transform(X, model.GQGT)
            if redraw:
                X = sigmas(x, P)
        Z = [model.h(s) for s in X]
        z, S = transform(Z, model.R)
        Pxz = sum(w * np.outer(s - x, zz - z) for w, s, zz in zip(Wc, X, Z, strict=True))
        if not redraw and k:
            xm = sum(w * s for w, s in zip(Wm, X, strict=True))
            Pxz = sum(w * np.outer(s - xm, zz - z) for w, s, zz in zip(Wc, X, Z, strict=True))
        K = Pxz @ np.linalg.inv(S)
        x = x + K @ (y - z)
        P = P - K @ S @ K.T
        out.append((x.copy(), P.copy()))
    return out


@pytest.mark.parametrize("alpha,beta,kappa,redraw", [(0.5, 2.0, 0.0, True), (1.0, 0.0, 0.0, True),
                                                     (0.3, 2.0, 1.0, False)])
def test_matches_textbook_ukf(alpha, beta, kappa, redraw):
    model = nonlinear_model()
    rng = np.random.default_rng(0)
    x0, P0 = np.array([0.3, -0.2, 0.5]), np.diag([0.2, 0.1, 0.05])
    T = 60
    ys, us = rng.normal(size=(T, 2)) * 0.1 + [1.2, 0.0], rng.normal(size=(T, 1))
    ref = textbook_ukf(model, x0, P0, ys, us, alpha, beta, kappa, redraw)
    ukf = UnscentedKalmanFilter(model, x0=x0, P0=P0, alpha=alpha, beta=beta, kappa=kappa,
                                redraw=redraw)
    for k in range(T):
        np.testing.assert_allclose(ukf.step(ys[k], us[k] if k else None), ref[k][0],
                                   rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(ukf.P, ref[k][1], rtol=1e-9, atol=1e-11)


@pytest.mark.parametrize("options", [{}, {"alpha": 1.0}, {"alpha": 0.1, "kappa": 2.0},
                                     {"points": "cubature"}])
def test_equals_kf_on_linear_model(options):
    rng = np.random.default_rng(1)
    A, C = rng.normal(size=(3, 3)) * 0.6, rng.normal(size=(2, 3))
    model = LinearModel(A=A, C=C, B=rng.normal(size=(3, 1)), Q=np.eye(3) * 0.1, R=np.eye(2))
    if options.get("points") == "cubature":
        options = {"points": CubatureSigmaPoints(3)}
    kf, ukf = KalmanFilter(model), UnscentedKalmanFilter(model, **options)
    for _ in range(100):
        y, u = rng.normal(size=2), rng.normal(size=1)
        np.testing.assert_allclose(ukf.step(y, u), kf.step(y, u), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(ukf.P, kf.P, rtol=1e-9, atol=1e-12)


def test_unscented_transform_exact_for_linear_maps_and_weights():
    rng = np.random.default_rng(2)
    x, L = rng.normal(size=4), rng.normal(size=(4, 4))
    P = L @ L.T
    M = rng.normal(size=(3, 4))
    for sp in (MerweScaledSigmaPoints(4, 1e-3, 2.0, 0.0), MerweScaledSigmaPoints(4, 0.7, 0, 1),
               CubatureSigmaPoints(4)):
        assert np.isclose(sp.Wm.sum(), 1.0)
        Z = sp.sigma_points(x, P) @ M.T
        mean, cov = unscented_transform(Z, sp, noise_cov=np.eye(3))
        np.testing.assert_allclose(mean, M @ x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(cov, M @ P @ M.T + np.eye(3), rtol=1e-7, atol=1e-9)
        _mean2, cov2 = unscented_transform(Z, sp.Wm, sp.Wc)
        np.testing.assert_allclose(cov2, cov - np.eye(3), rtol=1e-12, atol=1e-12)
    sp = MerweScaledSigmaPoints(2, alpha=0.5, beta=2.0, kappa=1.0)       # Table 1 by hand
    lam = 0.25 * 3 - 2
    np.testing.assert_allclose(sp.Wm[0], lam / (2 + lam))
    np.testing.assert_allclose(sp.Wc[0], lam / (2 + lam) + 1 - 0.25 + 2.0)
    np.testing.assert_allclose(sp.Wm[1:], 1 / (2 * (2 + lam)))


def test_semidefinite_prior_works_and_indefinite_is_rejected():
    sp = MerweScaledSigmaPoints(2, alpha=1.0)
    pts = sp.sigma_points([1.0, 2.0], [[1.0, 0.0], [0.0, 0.0]])       # PSD, singular
    np.testing.assert_allclose(pts[:, 1], 2.0)
    with pytest.raises(ValueError, match="positive semi-definite"):
        sp.sigma_points([1.0, 2.0], [[1.0, 2.0], [2.0, 1.0]])
    model = nonlinear_model()
    ukf = UnscentedKalmanFilter(model, P0=np.diag([1.0, 0.0, 1.0]))
    assert np.all(np.isfinite(ukf.step([1.0, 0.1]))) and not ukf.diverged


def test_batched_equals_looped():
    model = nonlinear_model()
    rng = np.random.default_rng(3)
    B = 5
    x0 = rng.normal(size=(B, 3)) * 0.3
    batch = UnscentedKalmanFilter(model, x0=x0, P0=np.eye(3) * 0.1)
    singles = [UnscentedKalmanFilter(model, x0=x0[i], P0=np.eye(3) * 0.1) for i in range(B)]
    for _ in range(60):
        Y, U = rng.normal(size=(B, 2)) * 0.1 + [1.2, 0], rng.normal(size=(B, 1))
        X = batch.step(Y, U)
        for i, f in enumerate(singles):
            np.testing.assert_allclose(X[i], f.step(Y[i], U[i]), rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(batch.P[i], f.P, rtol=1e-12, atol=1e-14)


def test_bad_input_and_registry():
    model = nonlinear_model()
    with pytest.raises(ValueError, match="alpha"):
        UnscentedKalmanFilter(model, alpha=0.0)
    with pytest.raises(ValueError, match="points must be for n = 3"):
        UnscentedKalmanFilter(model, points=CubatureSigmaPoints(2))
    with pytest.raises(TypeError, match="points"):
        UnscentedKalmanFilter(model, points="merwe")
    with pytest.raises(ValueError, match="jitter"):
        UnscentedKalmanFilter(model, jitter=-1.0)
    with pytest.raises(ValueError, match="P0 must be symmetric"):
        UnscentedKalmanFilter(model, P0=np.triu(np.ones((3, 3))))
    ukf = make_estimator("ukf", model, alpha=0.5)
    assert ukf.points.alpha == 0.5
    with pytest.raises(ValueError, match="y must have shape"):
        ukf.step(np.zeros(3))


# ---------------------------------------------------------------- from the mutation run
# (docs/mutation.md: each test below kills mutants that survived the tests above)

def test_the_weights_and_unit_points_are_read_only():
    """A sigma-point set is shared by every filter that uses it: its weights cannot be
    changed by accident."""
    for points in (MerweScaledSigmaPoints(3, 0.5, 2.0, 0.0), CubatureSigmaPoints(3)):
        for a in (points.xi, points.Wm, points.Wc):
            with pytest.raises(ValueError, match="read-only"):
                a[0] = 1.0


def test_sigma_points_refuse_a_mean_of_more_than_two_axes():
    points = MerweScaledSigmaPoints(2, 0.5, 2.0, 0.0)
    with pytest.raises(ValueError, match="x and P must have shapes"):
        points.sigma_points(np.zeros((3, 2, 2)), np.stack([np.eye(2)] * 3))


def test_a_non_model_is_refused_as_a_type_error():
    with pytest.raises(TypeError, match="model"):
        UnscentedKalmanFilter("not a model")


def test_options_are_keyword_only_for_every_registered_estimator():
    """``make_estimator(name, model, x0=..., ...)``: after the model every option is passed
    by name, so a positional slip cannot land in the wrong option."""
    import inspect

    from fir_gym.estimators.registry import estimator_class, estimator_names
    for name in estimator_names():
        params = list(inspect.signature(estimator_class(name)).parameters.values())
        assert params[0].kind in (params[0].POSITIONAL_ONLY, params[0].POSITIONAL_OR_KEYWORD), name
        late = [p.name for p in params[1:] if p.kind not in (p.KEYWORD_ONLY, p.VAR_KEYWORD)]
        assert not late, f"{name}: options not keyword-only: {late}"


@pytest.mark.parametrize("points", [MerweScaledSigmaPoints, CubatureSigmaPoints])
@pytest.mark.parametrize("n", [0, -1, 2.0, True])
def test_sigma_points_refuse_a_dimension_that_is_not_a_positive_integer(points, n) -> None:
    with pytest.raises(ValueError, match="n must be a positive integer"):
        points(n)


def test_the_ukf_refuses_a_time_varying_model_naming_the_filter_that_takes_it() -> None:
    """The UKF propagates sigma points through a time-free ``f``; a time-varying linear model
    is the Kalman filter's (mutation testing found the refusal untested)."""
    from fir_gym.estimators import TimeVaryingLinearModel
    model = TimeVaryingLinearModel(A=lambda k: np.eye(2) * (1.0 + 0.1 * k), C=[[1.0, 0.0]],
                                   Q=np.eye(2), R=[[1.0]])
    with pytest.raises(TypeError, match=r"time-free f/h.*use KalmanFilter"):
        UnscentedKalmanFilter(model)
    assert isinstance(KalmanFilter(model), KalmanFilter)
