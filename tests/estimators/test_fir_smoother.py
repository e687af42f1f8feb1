"""FIRSmoother (paper 004 §III): window-start estimates against an RTS smoother."""

from __future__ import annotations

import numpy as np
import pytest

from fir_gym.estimators import LinearModel, TimeVaryingLinearModel
from fir_gym.estimators.fir_gains import stationary_prior
from fir_gym.estimators.fir_smoother import FIRSmoother
from fir_gym.estimators.registry import make_estimator


def lti(seed: int, rho: float = 0.9, n_u: int = 1) -> LinearModel:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(3, 3))
    A *= rho / np.max(np.abs(np.linalg.eigvals(A)))
    return LinearModel(A=A, C=rng.normal(size=(1, 3)),
                       B=rng.normal(size=(3, n_u)) if n_u else None,
                       Q=np.diag([0.2, 0.0, 0.1]), R=[[0.3]])


def ltv(seed: int) -> TimeVaryingLinearModel:
    m = lti(seed)
    A = np.asarray(m.A)
    return TimeVaryingLinearModel(A=lambda k: A * (1 + 0.1 * np.sin(k)), C=m.C, B=m.B, Q=m.Q,
                                  R=m.R)


def simulate(model, steps: int, seed: int, noise: bool = True):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=3) * 3.0
    xs, ys, us = [], [], rng.normal(size=(steps, model.n_u))
    for k in range(steps):
        m = model.matrices(k)
        xs.append(x)
        ys.append(m.C @ x + (np.sqrt(m.R[0, 0]) * rng.normal(size=1) if noise else 0.0))
        x = m.A @ x + m.B @ us[k] + (np.sqrt(np.diag(m.Q)) * rng.normal(size=3) if noise else 0)
    return np.array(xs), np.array(ys), us


def rts_start(model, ys, us, k0: int, P0: np.ndarray):
    """Rauch–Tung–Striebel smoother over ys (instants k0 …), prior N(0, P0) on the first state."""
    n, L = model.n_x, len(ys)
    xf, Pf, xp, Pp = [], [], [], []
    x, P = np.zeros(n), P0
    for j in range(L):
        if j:
            m = model.matrices(k0 + j - 1)
            x, P = m.A @ x + m.B @ us[k0 + j - 1], m.A @ P @ m.A.T + m.G @ m.Q @ m.G.T
        xp.append(x)
        Pp.append(P)
        m = model.matrices(k0 + j)
        K = P @ m.C.T @ np.linalg.inv(m.C @ P @ m.C.T + m.R)
        x, P = x + K @ (ys[j] - m.C @ x), (np.eye(n) - K @ m.C) @ P
        xf.append(x)
        Pf.append(P)
    xs = xf[-1]
    for j in range(L - 2, -1, -1):
        A = model.matrices(k0 + j).A
        J = Pf[j] @ A.T @ np.linalg.inv(Pp[j + 1])
        xs = xf[j] + J @ (xs - xp[j + 1])
    return xs


@pytest.mark.parametrize("gain", ["two-stage", "batch"])
@pytest.mark.parametrize("model", [lti(0, rho=1.1), ltv(1)], ids=["lti", "ltv"])
def test_exact_window_start_on_noise_free_data(model, gain: str) -> None:
    L = 5
    xs, ys, us = simulate(model, 25, seed=2, noise=False)
    s = FIRSmoother(model, horizon=L, gain=gain)
    for k, y in enumerate(ys):
        est = s.step(y, us[k - 1] if k else None)
        t = s.last_info["time"]
        assert t == max(0, k - L + 1)
        if k >= L - 1:
            assert np.abs(est - xs[t]).max() <= 1e-9 * max(1.0, np.abs(xs[t]).max())


@pytest.mark.parametrize("model", [lti(2), ltv(3)], ids=["lti", "ltv"])
def test_no_prior_smoother_is_the_diffuse_rts_limit(model) -> None:
    L, k = 6, 13
    _, ys, us = simulate(model, k + 1, seed=4)
    s = FIRSmoother(model, horizon=L)
    for j in range(k + 1):
        est = s.step(ys[j], us[j - 1] if j else None)
    gaps = [np.abs(rts_start(model, ys[k - L + 1:], us, k - L + 1, kappa * np.eye(3)) - est).max()
            for kappa in (1e3, 1e5, 1e7)]
    assert gaps[0] > gaps[1] > gaps[2] and gaps[2] < 1e-5 * max(1.0, np.abs(est).max())


@pytest.mark.parametrize("gain", ["two-stage", "batch", "riccati"])
def test_stationary_prior_smoother_equals_rts_with_that_prior(gain: str) -> None:
    model = lti(5, n_u=0)
    P = stationary_prior(model.A, model.GQGT)
    L = 5
    _, ys, us = simulate(model, 9, seed=6)
    s = FIRSmoother(model, horizon=L, gain=gain, prior="stationary")
    for y in ys:
        est = s.step(y)
    assert np.allclose(est, rts_start(model, ys[-L:], us, 4, P), atol=1e-11)


def test_riccati_without_prior_is_refused_with_the_reason() -> None:
    with pytest.raises(ValueError, match=r"Cor 3\.2"):
        FIRSmoother(lti(0), horizon=4, gain="riccati")


def test_startup_returns_prior_then_growing_window_and_registry() -> None:
    model = lti(7)
    s = make_estimator("fir-smoother", model, horizon=6, x0=[1.0, 2.0, 3.0])
    assert isinstance(s, FIRSmoother) and s.lag == 5
    xs, ys, us = simulate(model, 4, seed=1, noise=False)
    out = [s.step(y, us[k - 1] if k else None) for k, y in enumerate(ys)]
    assert np.allclose(out[0], [1.0, 2.0, 3.0]) and s.last_info["startup"]
    assert np.allclose(out[3], xs[0], atol=1e-9)                 # 4 samples determine x[0]


def test_batch_in_lockstep_equals_separate_smoothers() -> None:
    model = ltv(9)
    rng = np.random.default_rng(0)
    Y, U = rng.normal(size=(15, 3, 1)), rng.normal(size=(15, 3, 1))
    together = FIRSmoother(model, horizon=5)
    out = np.array([together.step(Y[k], U[k - 1] if k else None) for k in range(15)])
    for b in range(3):
        alone = FIRSmoother(model, horizon=5)
        sep = np.array([alone.step(Y[k, b], U[k - 1, b] if k else None) for k in range(15)])
        assert np.abs(out[:, b] - sep).max() <= 1e-12 * max(1.0, np.abs(sep).max())


@pytest.mark.parametrize("path", ["numpy", "compiled"])
@pytest.mark.parametrize("n_u", [0, 1], ids=["no input", "input"])
@pytest.mark.parametrize("varying", [False, True], ids=["lti", "ltv"])
def test_a_window_with_no_measurement_predicts_the_previous_smoothed_estimate(path: str,
                                                                               n_u: int,
                                                                               varying: bool
                                                                               ) -> None:
    """Once a system's whole window is missing (``nan_policy="skip"``) the smoother falls
    back to the model's prediction of its previous estimate, ``x = A x̂ + B u[k−L]``,
    ``P = A P Aᵀ + G Q Gᵀ`` (the estimate lags by ``L − 1``: the input is the one stored
    with the window's oldest sample, and ``A`` is the model's at that sample's time ``k −
    L``) — that system only, the other one of the batch keeping its window (mutation
    testing found the fallback, and its time index on a time-varying model, untested)."""
    from compiled_paths import on_path
    model = lti(5, n_u=n_u)
    GQG = model.GQGT
    if varying:
        base = np.asarray(model.A)
        model = TimeVaryingLinearModel(A=lambda k: base * (1 + 0.3 * np.sin(k)), C=model.C,
                                       B=model.B, Q=model.Q, R=model.R)
    L = 4
    smoother = FIRSmoother(model, horizon=L, nan_policy="skip")
    rng = np.random.default_rng(6)
    inputs = []                                   # inputs[k]: the u passed with y[k] (u[k−1])
    with on_path(path):
        for k in range(30):
            y = rng.normal(size=(2, 1))
            u = rng.normal(size=(2, n_u)) if n_u and k else None
            inputs.append(u)
            if k >= 12:
                y[1] = np.nan                                   # system 1 goes blind
            x_prev, P_prev = smoother.x.copy(), smoother.P.copy()
            smoother.step(y, u)
            if k >= 12 + L:                                     # its whole window is missing
                A = model.matrices(k - L).A
                want = A @ x_prev[1]
                if n_u:
                    want = want + model.matrices(k - L).B @ inputs[k - L + 1][1]  # u[k − L]
                np.testing.assert_allclose(smoother.x[1], want, rtol=1e-12, atol=1e-14)
                np.testing.assert_allclose(smoother.P[1], A @ P_prev[1] @ A.T + GQG,
                                           rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("gain", ["two-stage", "batch"])
def test_the_innovation_test_predicts_from_the_fir_filter_of_the_same_window(gain: str
                                                                          ) -> None:
    """The smoother's estimate lags by ``L − 1``, so its divergence watch tests the
    innovation of ``y[k]`` against the FIR *filter* over the window ending at ``k − 1``
    (its ``x̂[k−1]`` and ``P``): from the first step whose previous window is full (``k =
    L``) on, the NIS is a :class:`FIRFilter`'s of the same horizon and gain, step for step
    (mutation testing found the start-up boundary of that prior untested)."""
    from fir_gym.estimators.fir import FIRFilter
    model = lti(4)
    L = 5
    _, ys, us = simulate(model, 20, seed=8)
    smoother = FIRSmoother(model, horizon=L, gain=gain)
    filt = FIRFilter(model, horizon=L, gain=gain)
    for k, y in enumerate(ys):
        u = us[k - 1] if k else None
        smoother.step(y, u)
        filt.step(y, u)
        if k >= L:
            assert np.isfinite(smoother.last_info["nis"])
            np.testing.assert_allclose(smoother.last_info["nis"], filt.last_info["nis"],
                                       rtol=1e-9)
