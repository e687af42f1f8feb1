"""FIRFilter: exactness, the diffuse Kalman limit, gain paths, start-up, batching, errors."""

from __future__ import annotations

import numpy as np
import pytest

from fir_gym.estimators import LinearModel, TimeVaryingLinearModel
from fir_gym.estimators.efir import ExtendedFIRFilter
from fir_gym.estimators.fir import FIRFilter
from fir_gym.estimators.fir_gains import model_window, stacked_window, two_stage_gain
from fir_gym.estimators.fir_smoother import FIRSmoother
from fir_gym.estimators.recursive_fir import RecursiveFIRFilter
from fir_gym.estimators.registry import make_estimator
from fir_gym.estimators.ufir import UFIRFilter

GAINS = ("two-stage", "batch", "riccati")


def lti(seed: int = 0, rho: float = 1.1, n: int = 3, p: int = 1, n_u: int = 1,
        q: float = 0.1) -> LinearModel:
    """A random system; ``rho`` > 1 makes it unstable."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A *= rho / np.max(np.abs(np.linalg.eigvals(A)))
    return LinearModel(A=A, C=rng.normal(size=(p, n)), B=rng.normal(size=(n, n_u)),
                       Q=q * np.eye(n), R=0.5 * np.eye(p))


def ltv(seed: int = 0) -> TimeVaryingLinearModel:
    base = lti(seed)
    A, C = np.asarray(base.A), np.asarray(base.C)
    return TimeVaryingLinearModel(A=lambda k: A * (1.0 + 0.1 * np.sin(k)),
                                  C=lambda k: C + 0.2 * np.cos(0.7 * k), B=base.B,
                                  Q=lambda k: (0.1 + 0.05 * np.sin(k)) * np.eye(3), R=[[0.5]])


def simulate(model, steps: int, seed: int = 1, noise: bool = True, x0=None):
    """Truth, measurements and inputs (``u[k]`` drives ``x[k] → x[k+1]``)."""
    rng = np.random.default_rng(seed)
    n, p = model.n_x, model.n_y
    x = rng.normal(size=n) * 5.0 if x0 is None else np.asarray(x0, float)
    xs, ys, us = [], [], rng.normal(size=(steps, model.n_u))
    for k in range(steps):
        m = model.matrices(k)
        xs.append(x)
        ys.append(m.C @ x + (rng.multivariate_normal(np.zeros(p), m.R) if noise else 0.0))
        x = m.A @ x + m.B @ us[k] + (m.G @ rng.multivariate_normal(np.zeros(m.Q.shape[0]), m.Q)
                                      if noise else 0.0)
    return np.array(xs), np.array(ys), us


def run(f: FIRFilter, ys: np.ndarray, us: np.ndarray) -> np.ndarray:
    return np.array([f.step(y, us[k - 1] if k else None) for k, y in enumerate(ys)])


@pytest.mark.parametrize("form", ["filter", "predictor"])
@pytest.mark.parametrize("gain", GAINS)
@pytest.mark.parametrize("model", [lti(0, rho=1.15), lti(1, rho=0.8, p=2), ltv(2)],
                         ids=["unstable", "stable-p2", "time-varying"])
def test_exact_on_noise_free_data_once_full(model, gain: str, form: str) -> None:
    L = 5
    xs, ys, us = simulate(model, 30, noise=False)
    est = run(FIRFilter(model, horizon=L, form=form, gain=gain), ys, us)
    first = L - 1 if form == "filter" else L
    scale = np.abs(xs[first:]).max(axis=1, keepdims=True)
    assert np.all(np.abs(est[first:] - xs[first:]) <= 1e-9 * np.maximum(1.0, scale))


def kalman_from_window_start(model, ys, us, kappa: float, predict_last: bool):
    """Textbook KF over the window, started at its first instant with x = 0, P = κI."""
    n = model.n_x
    x, P = np.zeros(n), kappa * np.eye(n)
    for j, y in enumerate(ys):
        m = model.matrices(j)
        if j:
            mp = model.matrices(j - 1)
            x, P = mp.A @ x + mp.B @ us[j - 1], mp.A @ P @ mp.A.T + mp.G @ mp.Q @ mp.G.T
        S = m.C @ P @ m.C.T + m.R
        K = np.linalg.solve(S, m.C @ P).T
        x, P = x + K @ (y - m.C @ x), (np.eye(n) - K @ m.C) @ P
    if predict_last:
        m = model.matrices(len(ys) - 1)
        x = m.A @ x + m.B @ us[len(ys) - 1]
    return x


@pytest.mark.parametrize("form", ["filter", "predictor"])
@pytest.mark.parametrize("model", [lti(3, rho=0.95), ltv(4)], ids=["lti", "ltv"])
def test_equals_kalman_filter_with_diffuse_prior_in_the_limit(model, form: str) -> None:
    L = 6
    _, ys, us = simulate(model, L + 1, seed=8)
    f = FIRFilter(model, horizon=L, form=form)
    est = run(f, ys[:L + (form == "predictor")], us)[-1]
    gaps = [np.abs(kalman_from_window_start(model, ys[:L], us, kappa, form == "predictor")
                   - est).max() for kappa in (1e2, 1e4, 1e6)]
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] < 1e-4 * max(1.0, np.abs(est).max())
    assert 30 < gaps[0] / gaps[1] < 300                   # the gap shrinks like 1/κ


@pytest.mark.parametrize("form", ["filter", "predictor"])
def test_with_stationary_prior_equals_kalman_filter_with_that_prior(form: str) -> None:
    model = LinearModel(A=[[0.9, 0.2], [-0.1, 0.8]], C=[[1.0, 0.0]], Q=0.2 * np.eye(2),
                        R=[[0.4]])
    P = np.linalg.solve(np.eye(4) - np.kron(model.A, model.A), (0.2 * np.eye(2)).ravel())
    _, ys, us = simulate(model, 6, seed=3)
    L = 5
    est = run(FIRFilter(model, horizon=L, form=form, prior="stationary"),
              ys[:L + (form == "predictor")], us)[-1]
    n = 2
    x, Pk = np.zeros(n), P.reshape(2, 2)
    for j, y in enumerate(ys[:L]):                        # the prior is on x[window start]
        if j:
            x, Pk = model.A @ x, model.A @ Pk @ model.A.T + model.GQGT
        K = Pk @ model.C.T / (model.C @ Pk @ model.C.T + model.R)
        x, Pk = x + (K @ (y - model.C @ x)), (np.eye(n) - K @ model.C) @ Pk
    if form == "predictor":
        x = model.A @ x
    assert np.allclose(est, x, atol=1e-12)


@pytest.mark.parametrize("form", ["filter", "predictor"])
def test_time_varying_paths_agree_on_noisy_data(form: str) -> None:
    model = ltv(5)
    _, ys, us = simulate(model, 25, seed=6)
    outs = [run(FIRFilter(model, horizon=6, form=form, gain=g), ys, us) for g in GAINS]
    scale = max(1.0, np.abs(outs[1]).max())
    assert np.abs(outs[0] - outs[1]).max() <= 1e-9 * scale
    assert np.abs(outs[2] - outs[1]).max() <= 1e-9 * scale


def test_startup_prior_then_growing_window() -> None:
    model = lti(6, rho=0.9)
    _, ys, us = simulate(model, 10, seed=2)
    x0 = np.array([1.0, -2.0, 0.5])
    f = FIRFilter(model, horizon=6, x0=x0)
    flags, est = [], []
    for k, y in enumerate(ys):
        est.append(f.step(y, us[k - 1] if k else None))
        flags.append((f.last_info["startup"], f.last_info["rank_deficient"]))
    assert flags[:5] == [(True, True), (True, True), (True, False), (True, False), (True, False)]
    assert all(fl == (False, False) for fl in flags[5:])
    assert np.allclose(est[0], x0)                                  # the prior …
    assert np.allclose(est[1], model.A @ x0 + model.B @ us[0])       # … propagated open loop
    for k in (2, 3, 4):                                  # growing window: same estimator
        win = model_window(model, 0, k + 1)
        sw = stacked_window(win)
        S = two_stage_gain(win).S
        xu = sw.MB @ us[:k + 1].ravel()                  # known input response
        expect = S @ (ys[:k + 1].ravel() - sw.Dt @ us[:k + 1].ravel()) + xu
        assert np.allclose(est[k], expect, atol=1e-10)


def test_short_horizon_raises_naming_horizon_and_minimum() -> None:
    model = lti(0, n=3, p=1)
    with pytest.raises(ValueError, match=r"horizon=2 .* horizon >= 3"):
        FIRFilter(model, horizon=2)
    unobservable = LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2), R=[[1.0]])
    with pytest.raises(ValueError, match="not observable"):
        FIRFilter(unobservable, horizon=5)
    with pytest.raises(TypeError):
        FIRFilter(object(), horizon=3)                     # type: ignore[arg-type]
    with pytest.raises(ValueError, match="form"):
        FIRFilter(model, horizon=3, form="smoother")


@pytest.mark.parametrize("model", [lti(7, rho=1.05), ltv(8)], ids=["lti", "ltv"])
def test_batch_in_lockstep_equals_separate_filters(model) -> None:
    B, T = 5, 20
    data = [simulate(model, T, seed=10 + b) for b in range(B)]
    Y = np.stack([d[1] for d in data], axis=1)
    U = np.stack([d[2] for d in data], axis=1)
    x0 = np.random.default_rng(0).normal(size=(B, 3))
    batch = FIRFilter(model, horizon=5, x0=x0)
    together = np.array([batch.step(Y[k], U[k - 1] if k else None) for k in range(T)])
    for b in range(B):
        alone = run(FIRFilter(model, horizon=5, x0=x0[b]), Y[:, b], U[:, b])
        assert np.abs(together[:, b] - alone).max() <= 1e-12 * max(1.0, np.abs(alone).max())


@pytest.mark.parametrize("form", ["filter", "predictor"])
def test_missing_measurement_uses_the_rest_of_the_window(form: str) -> None:
    """The predictor form (window ``y[k−L..k−1]``) is the filter estimate at ``k − 1`` over
    that window, predicted one step (mutation testing found its masked path untested)."""
    model = lti(9, rho=0.9, p=2)
    _, ys, us = simulate(model, 12, seed=4)
    ys = ys.copy()
    ys[9, 1] = np.nan                                      # one output missing at k = 9
    f = FIRFilter(model, horizon=6, nan_policy="skip", form=form)
    est = run(f, ys, us)
    last = 11 if form == "filter" else 10                  # the window's newest measurement
    first = last - 5
    # oracle: the stacked formula for the window first..last with that measurement removed
    win = model_window(model, 6, 6)
    sw = stacked_window(win)
    keep = np.ones(12, bool)
    keep[(9 - first) * 2 + 1:(9 - first) * 2 + 2] = False  # whole y[9]: the filter skips it
    keep[(9 - first) * 2] = False
    Ct, Gt = sw.Ct[keep], sw.Gt[keep]
    Pi = Gt @ sw.Qbd @ Gt.T + sw.Rbd[np.ix_(keep, keep)]
    U = np.linalg.solve(Pi, Ct).T
    FiU = np.linalg.solve(U @ Ct, U)
    V = sw.M @ sw.Qbd @ Gt.T @ np.linalg.inv(Pi)
    S = sw.Phi @ FiU + V - V @ Ct @ FiU
    Y = (ys[first:last + 1].ravel() - sw.Dt @ us[first:last + 1].ravel())[keep]
    want = S @ Y + sw.MB @ us[first:last + 1].ravel()
    if form == "predictor":
        want = model.A @ want + model.B @ us[10]
    assert np.allclose(est[11], want, atol=1e-10)
    assert not f.last_info["rank_deficient"]


def test_rank_deficient_time_varying_window_flags_and_predicts() -> None:
    A = np.array([[1.0, 0.1], [0.0, 1.0]])
    blind = lambda k: np.zeros((1, 2)) if 10 <= k < 20 else np.array([[1.0, 0.0]])  # noqa: E731
    model = TimeVaryingLinearModel(A=A, C=blind, Q=0.01 * np.eye(2), R=[[0.1]])
    _, ys, _ = simulate(model, 25, seed=5)
    f = FIRFilter(model, horizon=4)
    for k, y in enumerate(ys):
        prev, prev_P = f.x, f.P
        x = f.step(y)
        if 12 <= k < 20:                                  # at most one informative sample
            assert f.last_info["rank_deficient"]
            assert np.allclose(x, A @ prev)
            assert np.allclose(f.P, A @ prev_P @ A.T + 0.01 * np.eye(2))
        elif k >= 23:
            assert not f.last_info["rank_deficient"]


def test_registered_and_batched_info() -> None:
    model = lti(0, rho=0.9)
    f = make_estimator("fir", model, horizon=4)
    assert isinstance(f, FIRFilter)
    f.step(np.zeros((3, 1)))
    assert f.last_info["rank_deficient"].shape == (3,)


def restart_matches_fresh(make, x0: np.ndarray, Y: np.ndarray, U: np.ndarray, k_r: int,
                          who: int, startup_steps: int = 4) -> None:
    """After ``restart([who])`` before step ``k_r``, ``who`` equals a fresh filter on the rest
    (its estimates and the divergence watch's NIS).

    ``make(x0)`` builds the filter; the batch gets the rows of ``x0``, each fresh
    single filter its own row. The other systems must not notice the restart.
    """
    T, B = Y.shape[:2]
    batch = make(x0)
    out, nis = [], []
    for k in range(T):
        if k == k_r:
            batch.restart([who])
        out.append(batch.step(Y[k], U[k - 1] if k else None))
        nis.append(batch.last_info["nis"])
        if k >= k_r:
            assert batch.last_info["startup"][who] == (k - k_r < startup_steps)
    out, nis = np.array(out), np.array(nis)
    for b in range(B):
        start = k_r if b == who else 0
        alone = make(x0[b])
        ref, ref_nis = [], []
        for k in range(start, T):
            ref.append(alone.step(Y[k, b], U[k - 1, b] if k > start else None))
            ref_nis.append(alone.last_info["nis"])
        ref, ref_nis = np.array(ref), np.array(ref_nis)
        assert np.abs(out[start:, b] - ref).max() <= 1e-10 * max(1.0, np.abs(ref).max())
        # the divergence watch's innovation test restarts with the estimate: the same NIS
        np.testing.assert_allclose(nis[start:, b], ref_nis, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("gain", GAINS)
@pytest.mark.parametrize("form", ["filter", "predictor"])
def test_restarting_one_system_of_a_batch(form: str, gain: str) -> None:
    model = lti(12, rho=0.95)
    rng = np.random.default_rng(3)
    Y, U = rng.normal(size=(24, 3, 1)), rng.normal(size=(24, 3, 1))
    x0 = rng.normal(size=(3, 3))
    horizon = 5 if form == "filter" else 4                  # start-up lasts 4 steps in both
    restart_matches_fresh(lambda x0: FIRFilter(model, horizon=horizon, form=form, gain=gain,
                                               x0=x0), x0, Y, U, 11, 1)


FAMILY = {
    "efir-open-loop": lambda m, L, x0: ExtendedFIRFilter(m, horizon=L, x0=x0),
    "efir-reanchor": lambda m, L, x0: ExtendedFIRFilter(m, horizon=L, x0=x0, nominal="reanchor"),
    "efir-predictor": lambda m, L, x0: ExtendedFIRFilter(m, horizon=L - 1, x0=x0,
                                                         form="predictor"),
    "smoother": lambda m, L, x0: FIRSmoother(m, horizon=L, x0=x0),
    "rfir": lambda m, L, x0: RecursiveFIRFilter(m, horizon=L, x0=x0, reinit_every=7),
    "ufir-iterative": lambda m, L, x0: UFIRFilter(m, horizon=L, x0=x0, method="iterative"),
}


@pytest.mark.parametrize("name", FAMILY)
def test_restart_in_the_rest_of_the_family(name: str) -> None:
    model = lti(13, rho=0.95)
    rng = np.random.default_rng(4)
    Y, U = rng.normal(size=(30, 3, 1)), rng.normal(size=(30, 3, 1))
    restart_matches_fresh(lambda x0: FAMILY[name](model, 5, x0), rng.normal(size=(3, 3)),
                          Y, U, 13, 0)
