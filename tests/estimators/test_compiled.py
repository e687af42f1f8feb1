"""The compiled kernels (numba) against the numpy paths they replace.

Oracle: the numpy path of the same function (batched ``matmul``/BLAS, closed
forms), an implementation that shares no code with the loops. The two sum in
different orders, so they agree to round-off, not bit for bit; the bound used is
``1e-12`` relative to the size of the numbers, far below any filter's error and
far above double round-off (~1e-16 per operation, a few dozen operations). The
rules for the edge cases must match exactly: NaN where ``S`` is not positive
definite, ``x⁻, P⁻`` kept and NaN NIS where a measurement is missing.
"""

import os
import subprocess
import sys
import types

import numpy as np
import pytest

from fir_gym.estimators import _compiled
from fir_gym.estimators._kalman_linalg import cholesky
from fir_gym.estimators.kalman import predict_covariance, update_kernel
from fir_gym.estimators.unscented import (
    CubatureSigmaPoints,
    MerweScaledSigmaPoints,
    unscented_transform,
)

numba = pytest.importorskip("numba")

from fir_gym.estimators._kalman_kernels import cholesky_rows, predict_update  # noqa: E402
from fir_gym.estimators._unscented_kernels import cross_moments  # noqa: E402

RTOL = 1e-12


def spd(rng, shape, n, scale=1.0):
    A = rng.normal(size=shape + (n, n))
    return scale * (A @ A.swapaxes(-1, -2)) / n + 0.1 * np.eye(n)


def close(a, b, scale=1.0):
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * scale)


@pytest.fixture
def numpy_path(monkeypatch):
    """Run a block with the compiled kernels switched off."""
    class Switch:
        def __enter__(self):
            monkeypatch.setattr(_compiled, "ENABLED", False)

        def __exit__(self, *exc):
            monkeypatch.setattr(_compiled, "ENABLED", True)
    return Switch()


@pytest.mark.parametrize(("n", "m"), [(1, 1), (2, 1), (3, 2), (4, 2), (5, 3), (6, 4)])
@pytest.mark.parametrize("shared", [False, True])
def test_predict_update_equals_predict_covariance_then_update_kernel(n, m, shared):
    rng = np.random.default_rng(n * 10 + m)
    B = 150                                        # more than two chunks, one partial
    x = rng.normal(size=(B, n))
    P = spd(rng, (B,), n)
    F = rng.normal(size=(1 if shared else B, n, n)) / np.sqrt(n) + np.eye(n)
    H = rng.normal(size=(1 if shared else B, m, n))
    R = spd(rng, (1 if shared else B,), m, 0.1)
    Q = spd(rng, (), n, 0.01)
    e = rng.normal(size=(B, m))
    valid = rng.uniform(size=B) > 0.1
    got = predict_update(x, P, F, Q, e, H, R, valid)
    P_pred = predict_covariance(P, F[0] if shared else F, Q)
    want = update_kernel(x, P_pred, e, H[0] if shared else H, R[0] if shared else R, valid)
    for a, b in zip(got, (want[0], want[1], want[3]), strict=True):
        close(a, b, np.nanmax(np.abs(b)))
    assert np.isnan(got[2][~valid]).all() and np.isfinite(got[2][valid]).all()
    np.testing.assert_array_equal(got[0][~valid], x[~valid])
    np.testing.assert_array_equal(got[1], got[1].swapaxes(1, 2))        # symmetric exactly


@pytest.mark.parametrize("m", [1, 2, 3])
def test_predict_update_gives_nan_where_S_is_not_positive_definite(m):
    rng = np.random.default_rng(m)
    B, n = 6, 3
    x, P = rng.normal(size=(B, n)), spd(rng, (B,), n)
    F, H = np.eye(n)[None], rng.normal(size=(1, m, n))
    R = np.repeat(0.1 * np.eye(m)[None], B, axis=0)
    R[2] = -1e3 * np.eye(m)                        # S indefinite for system 2 only
    valid = np.ones(B, dtype=bool)
    x_new, P_new, nis = predict_update(x, P, F, np.zeros((n, n)), rng.normal(size=(B, m)), H,
                                       R, valid)
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = update_kernel(x, predict_covariance(P, F[0], np.zeros((n, n))),
                            rng.normal(size=(B, m)), H[0], R, valid)
    for got, want in ((x_new, ref[0]), (P_new, ref[1]), (nis, ref[3])):
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    assert np.isnan(x_new[2]).all() and np.isfinite(np.delete(x_new, 2, axis=0)).all()


def test_cholesky_rows_equal_the_column_loop_and_flag_indefinite_rows(numpy_path):
    rng = np.random.default_rng(5)
    for n in (1, 2, 3, 5):
        S = spd(rng, (40,), n)
        S[7] = -S[7]                               # not positive definite
        got = cholesky_rows(S)
        with numpy_path, np.errstate(invalid="ignore"):
            want = cholesky(S)
        ok = np.isfinite(want).all(axis=(1, 2))
        np.testing.assert_array_equal(np.isfinite(got).all(axis=(1, 2)), ok)
        close(got[ok], want[ok], np.abs(want[ok]).max())
        close(got[ok] @ got[ok].swapaxes(1, 2), S[ok], np.abs(S).max())
        assert np.isnan(got[7]).all()


@pytest.mark.parametrize("points", [MerweScaledSigmaPoints(4, 1e-3, 2.0, 0.0),
                                    MerweScaledSigmaPoints(3, 1.0, 2.0, 0.0),
                                    CubatureSigmaPoints(4)], ids=repr)
def test_cross_moments_equal_the_numpy_moments(points, numpy_path):
    """Including α = 1e-3, whose weights (~ ±1e6) cancel: the deviations from the first
    point keep both paths accurate, so they still agree to round-off of the result."""
    rng = np.random.default_rng(6)
    B, n = 70, points.n
    X = points.sigma_points(rng.normal(size=(B, n)), spd(rng, (B,), n, 0.2))
    Z = np.sin(X[..., :2]) + X[..., 1:3] ** 2
    mean_x, mean_z, Pxz = cross_moments(X, Z, points.Wm, points.Wc, False)
    mz, Pz = unscented_transform(Z, points)
    np.testing.assert_array_equal(Pz, Pz.swapaxes(1, 2))          # a covariance: symmetric
    with numpy_path:
        mz_ref, Pz_ref = unscented_transform(Z, points)
        mx_ref, _ = unscented_transform(X, points)
    close(mean_z, mz_ref, 1.0)
    close(mz, mz_ref, 1.0)
    close(mean_x, mx_ref, 1.0)
    # A priori bound for two summation orders of Σ Wᶜ Dₐ D_zᵀ − d_a c_zᵀ − c_a d_zᵀ + (Σ Wᶜ)
    # d_a d_zᵀ (Higham 2002, §3.1: |fl(Σ tᵢ) − Σ tᵢ| <= γ_k Σ |tᵢ|): each path is within
    # γ_{N+4} of the sum of the magnitudes of the terms, which the α = 1e-3 weights make
    # ~1e6 times the result (that is the scheme's conditioning, not either path's error).
    Wm, Wc = np.abs(points.Wm), np.abs(points.Wc)

    def magnitude(A, C):
        Da, Dc = np.abs(A - A[:, :1]), np.abs(C - C[:, :1])
        da, ca = np.einsum("i,bij->bj", Wm, Da), np.einsum("i,bij->bj", Wc, Da)
        dc, cc = np.einsum("i,bij->bj", Wm, Dc), np.einsum("i,bij->bj", Wc, Dc)
        return (np.einsum("i,bij,bik->bjk", Wc, Da, Dc) + da[:, :, None] * cc[:, None]
                + ca[:, :, None] * dc[:, None] + Wc.sum() * da[:, :, None] * dc[:, None])
    gamma = 2 * (points.num_points + 4) * np.finfo(float).eps
    assert (np.abs(Pz - Pz_ref) <= gamma * magnitude(Z, Z)).all()
    with numpy_path:
        _, Pxz_ref = _cross_reference(X, Z, points)
    assert (np.abs(Pxz - Pxz_ref) <= gamma * magnitude(X, Z)).all()


def _cross_reference(X, Z, sp):
    from fir_gym.estimators.unscented import _cross, _moments
    _, DX, dx, cx = _moments(X, sp)
    mz, DZ, dz, cz = _moments(Z, sp)
    return mz, _cross(DX, dx, cx, DZ, dz, cz, sp)


@pytest.mark.parametrize(("name", "options"), [("ekf", {}), ("ukf", {"alpha": 1.0}),
                                               ("ukf", {"points": CubatureSigmaPoints(4)})])
def test_batched_filters_run_the_same_with_and_without_kernels(name, options, numpy_path):
    """Whole EKF/UKF runs (64 systems, 60 steps, a missing measurement) agree with the numpy
    path to round-off (1e-12). Well-conditioned sigma points only: with α = 1e-3 both paths
    drift apart by ~1e-10 (1e6 × eps per step, bounded in the test above)."""
    from fir_gym.benchmarks.kalman import models
    from fir_gym.estimators import make_estimator
    model = models()["nonlinear"]
    rng = np.random.default_rng(7)
    B, K = 64, 60
    x0 = 0.3 * rng.normal(size=(B, 4))
    Y = 0.3 * rng.normal(size=(K, B, 2))
    Y[10, 5] = np.nan                               # a missing measurement
    runs = []
    for enabled in (True, False):
        filt = make_estimator(name, model, x0=x0, P0=0.1 * np.eye(4), nan_policy="skip",
                              **options)
        if enabled:
            trace = [filt.step(y) for y in Y]
        else:
            with numpy_path:
                trace = [filt.step(y) for y in Y]
        runs.append((np.array(trace), filt.P))
    np.testing.assert_allclose(runs[0][0], runs[1][0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(runs[0][1], runs[1][1], rtol=0,
                               atol=1e-12 * np.abs(runs[1][1]).max())


def test_environment_variable_turns_the_kernels_off(tmp_path):
    code = "from fir_gym.estimators import _compiled; print(_compiled.ENABLED)"
    for variables, expected in (({"FIR_GYM_NUMBA": "0"}, "False"),
                                ({"FIR_GYM_NUMBA": "off"}, "False"),
                                ({"FIR_GYM_NUMBA": "1"}, "True"),
                                ({"FIR_GYM_NUMBA": "1", "NUMBA_DISABLE_JIT": "1"}, "False")):
        # run outside the checkout: there, its fir_gym/ folder would shadow the install
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             env={**os.environ, **variables}, cwd=tmp_path, check=True)
        assert out.stdout.strip() == expected


def test_without_numba_kernel_gives_none(monkeypatch):
    monkeypatch.setattr(_compiled, "numba", None)
    assert _compiled.kernel(lambda x: x) is None
    assert not _compiled.active(None)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
@pytest.mark.parametrize("p", [1, 2])
@pytest.mark.parametrize("per_window", [False, True])
def test_window_bank_kernels_equal_the_numpy_bank(n, p, per_window, numpy_path):
    """Time and measurement updates and the read-out of a 40-system, 6-window bank: the
    compiled passes against the numpy path, step by step, with inputs, process noise and a
    skipped system."""
    from fir_gym.estimators._fir_bank import WindowBank
    rng = np.random.default_rng(10 * n + p)
    B, W = 40, 6
    banks = [WindowBank(B, W, n), WindowBank(B, W, n)]
    for bank in banks:
        bank.restart(0, x_ref=np.ones((B, n)))
    lead = (B, W) if per_window else (1,)
    for k in range(2 * W):
        A = np.eye(n) + 0.1 * rng.normal(size=lead + (n, n))
        C = rng.normal(size=lead + (p, n))
        Bu = rng.normal(size=(B, W, n) if per_window else (B, n))
        Qx = spd(rng, (), n, 0.01) if k % 2 else None
        y = rng.normal(size=(B, W, p) if per_window else (B, p))
        R = spd(rng, (), p, 0.1)
        valid = np.ones(B, dtype=bool)
        valid[k % B] = False
        for enabled, bank in zip((True, False), banks, strict=True):
            if enabled:
                bank.predict(A, Bu, Qx)
                bank.update(C, R, y, valid)
                bank.restart(k % W)
            else:
                with numpy_path:
                    bank.predict(A, Bu, Qx)
                    bank.update(C, R, y, valid)
                    bank.restart(k % W)
        scale = np.abs(banks[1].Z).max()
        np.testing.assert_allclose(banks[0].Z, banks[1].Z, rtol=0, atol=1e-12 * scale)
    w = (2 * W) % W
    x, P, ok = banks[0].estimate(w)
    with numpy_path:
        x_ref, P_ref, ok_ref = banks[1].estimate(w)
    np.testing.assert_array_equal(ok, ok_ref)
    close(x, x_ref, np.abs(x_ref).max())
    close(P, P_ref, np.abs(P_ref).max())


def test_window_bank_readout_falls_back_where_the_information_is_singular(numpy_path):
    """A system whose window saw no information gets the numpy path's regular = False."""
    from fir_gym.estimators._fir_bank import WindowBank
    rng = np.random.default_rng(11)
    B, n = 40, 3
    bank = WindowBank(B, 2, n)
    for _ in range(4):
        C = rng.normal(size=(B, 1, n))
        C[5] = 0.0                                   # system 5 measures nothing
        bank.predict(np.eye(n)[None], None, None)
        bank.update(C, np.eye(1), rng.normal(size=(B, 1)))
    x, _, ok = bank.estimate(0)
    with numpy_path:
        x_ref, _, ok_ref = bank.estimate(0)
    np.testing.assert_array_equal(ok, ok_ref)
    assert not ok[5] and ok[np.arange(B) != 5].all()
    close(x[ok], x_ref[ok], np.abs(x_ref[ok]).max())


def test_kalman_filter_with_per_system_covariances_equals_the_numpy_path(numpy_path):
    """Per-system covariances (a batched prior, and a missed measurement) run the compiled
    step; the estimates, covariances and the steady-state hand-over match the numpy path."""
    from fir_gym.estimators import KalmanFilter, LinearModel
    model = LinearModel(A=[[1.0, 0.1], [-0.1, 0.98]], B=[[0.0], [0.1]], C=[[1.0, 0.0]],
                        Q=np.diag([1e-3, 1e-2]), R=0.05)
    rng = np.random.default_rng(12)
    B, K = 50, 400
    P0 = spd(rng, (B,), 2)
    Y = rng.normal(scale=0.3, size=(K, B, 1))
    Y[30, 7] = np.nan
    U = rng.normal(scale=0.5, size=(K, B, 1))
    runs = []
    for enabled in (True, False):
        filt = KalmanFilter(model, x0=np.zeros((B, 2)), P0=P0, nan_policy="skip")
        if enabled:
            trace = [filt.step(Y[k], None if k == 0 else U[k]) for k in range(K)]
        else:
            with numpy_path:
                trace = [filt.step(Y[k], None if k == 0 else U[k]) for k in range(K)]
        runs.append((np.array(trace), filt.P, filt._steady is not None))
    np.testing.assert_allclose(runs[0][0], runs[1][0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(runs[0][1], runs[1][1], rtol=0, atol=1e-14)
    assert runs[0][2] and runs[1][2]                  # both reached the steady regime


def test_kernel_without_a_cache_location_still_compiles(monkeypatch):
    """numba refuses ``cache=True`` where no cache folder is writable; the kernel is then
    compiled uncached rather than breaking ``import fir_gym``."""
    calls, real_njit = [], numba.njit

    def njit(**options):
        calls.append(options["cache"])
        if options["cache"]:
            raise RuntimeError("cannot cache function 'f': no locator available")
        return real_njit(**options)

    monkeypatch.setattr(_compiled, "numba", types.SimpleNamespace(njit=njit))
    compiled = _compiled.kernel(lambda x: 2.0 * x)
    assert calls == [True, False] and compiled(1.5) == 3.0


@pytest.mark.parametrize("m", [1, 2, 3, 4, 6])
def test_spd_inverse_equals_the_numpy_path_and_flags_indefinite_rows(m, numpy_path):
    from fir_gym.estimators._kalman_linalg import spd_inverse
    rng = np.random.default_rng(20 + m)
    S = spd(rng, (70,), m)
    S[5] = -S[5]                                     # not positive definite
    got = spd_inverse(S)
    with numpy_path, np.errstate(invalid="ignore", divide="ignore"):
        want = spd_inverse(S)
    ok = np.isfinite(want).all(axis=(1, 2))
    np.testing.assert_array_equal(np.isfinite(got).all(axis=(1, 2)), ok)
    assert not ok[5] and ok.sum() == 69
    close(got[ok], want[ok], np.abs(want[ok]).max())
    close(got[ok] @ S[ok], np.broadcast_to(np.eye(m), S[ok].shape), 1.0)
