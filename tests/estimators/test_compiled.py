"""The compiled twins (numba) piece by piece against the numpy references they twin.

Oracle: the numpy reference of the same function (batched ``matmul``/BLAS, closed
forms, ``Estimator._accept``), an implementation that shares no code with the loops.
The two sum in different orders, so they agree to round-off, not bit for bit; the bound
used is ``1e-12`` relative to the size of the numbers, far below any filter's error and
far above double round-off (~1e-16 per operation, a few dozen operations). The rules
for the edge cases must match exactly: where ``S`` is not positive definite the estimate
is kept and the system flagged, where a measurement is missing ``x⁻, P⁻`` are kept with
a NaN NIS.
"""

import os
import subprocess
import sys
import types

import numpy as np
import pytest
from compiled_paths import numpy_path
from matrices import spd, unit_diagonal

from fir_gym.estimators import compiled
from fir_gym.estimators._kalman_linalg import cholesky, spd_inverse
from fir_gym.estimators.kalman import LinearGains, StepMatrices, predict_covariance, update_kernel
from fir_gym.estimators.state import GATE, NIS_THRESHOLD, FilterState, new_limits
from fir_gym.estimators.unscented import (
    CubatureSigmaPoints,
    MerweScaledSigmaPoints,
    matrix_sqrt,
    unscented_transform,
)

numba = pytest.importorskip("numba")
pytestmark = pytest.mark.skipif(not compiled.ENABLED, reason="the compiled twins are off")

from fir_gym.estimators.compiled import kalman as ck  # noqa: E402
from fir_gym.estimators.compiled import linalg as cl  # noqa: E402
from fir_gym.estimators.compiled import unscented as cu  # noqa: E402
from fir_gym.estimators.compiled import watch  # noqa: E402

RTOL = 1e-12
LIMITS = new_limits(1e300, 10, 1e300)          # a watch that flags nothing finite


def close(a, b, scale=1.0):
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * scale)


def record(x, P, limits=LIMITS):
    """A filter's state record over copies of ``x``, ``P``, the watch cleared."""
    return FilterState.of_batch(x, P, limits.copy())


@pytest.mark.parametrize("wrong", ["F", "H", "R"])
def test_predict_update_refuses_a_matrix_with_neither_one_row_nor_one_per_system(wrong):
    """F, H and R each have one row for all systems or one per system; another count is
    refused, whatever the others are (mutation testing found the check's ``and`` could be an
    ``or``)."""
    rng = np.random.default_rng(0)
    B, n, m = 3, 2, 1
    x, P = rng.normal(size=(B, n)), spd(rng, (B,), n)
    rows = {"F": 1, "H": 1, "R": 1, wrong: 2}
    F = np.broadcast_to(np.eye(n), (rows["F"], n, n)).copy()
    H = np.ones((rows["H"], m, n))
    R = np.broadcast_to(np.eye(m), (rows["R"], m, m)).copy()
    with pytest.raises(ValueError, match="a row per system"):
        ck.predict_update(record(x, P), x, F, np.eye(n), np.zeros((B, m)), np.zeros((B, m)),
                          H, R, np.ones(B, bool), np.ones(B, bool))


@pytest.mark.parametrize(("n", "m"), [(1, 1), (2, 1), (3, 2), (4, 2), (5, 3), (6, 4)])
@pytest.mark.parametrize("shared", [False, True])
def test_predict_update_equals_predict_covariance_then_update_kernel(n, m, shared):
    rng = np.random.default_rng(n * 10 + m)
    B = 150                                        # more than two blocks, one partial
    x = rng.normal(size=(B, n))
    P = spd(rng, (B,), n)
    F = rng.normal(size=(1 if shared else B, n, n)) / np.sqrt(n) + np.eye(n)
    H = rng.normal(size=(1 if shared else B, m, n))
    R = spd(rng, (1 if shared else B,), m, 0.1)
    Q = spd(rng, (), n, 0.01)
    y, hx = rng.normal(size=(B, m)), rng.normal(size=(B, m))
    valid = rng.uniform(size=B) > 0.1
    predict = rng.uniform(size=B) > 0.1            # some systems take their first step
    s = record(x, P)
    ck.predict_update(s, x, F, Q, y, hx, H, R, valid, predict)
    xs, Ps, diverged, run, nis, logdet = s.x, s.P, s.diverged, s.nis_run, s.nis, s.logdet
    P_pred = np.where(predict[:, None, None], predict_covariance(P, F[0] if shared else F, Q),
                      P)
    want = update_kernel(x, P_pred, y - hx, H[0] if shared else H, R[0] if shared else R,
                         valid)
    for a, b in zip((xs, Ps, nis), (want[0], want[1], want[3]), strict=True):
        close(a, b, np.nanmax(np.abs(b)))
    assert np.isnan(nis[~valid]).all() and np.isfinite(nis[valid]).all()
    H_all = np.broadcast_to(H, (B, m, n))
    S = H_all @ P_pred @ H_all.mT + np.broadcast_to(R, (B, m, m))
    sign, want_logdet = np.linalg.slogdet(S)               # log det S, by LU: independent
    assert (sign[valid] > 0).all() and np.isnan(logdet[~valid]).all()
    np.testing.assert_allclose(logdet[valid], want_logdet[valid], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(xs[~valid], x[~valid])
    np.testing.assert_array_equal(Ps, Ps.swapaxes(1, 2))                 # symmetric exactly
    assert not diverged.any() and not run.any()


@pytest.mark.parametrize(("n", "m"), [(1, 1), (3, 1), (4, 2), (5, 3)])
def test_predict_update_gates_as_update_kernel_and_as_a_missing_measurement(n, m):
    """The gate (``limits[GATE]``, a NIS threshold) in the kernel: the systems above it end
    bit for bit where the same kernel leaves them without their measurement (``valid``
    False), their NIS kept and booked; against ``update_kernel(..., gate=)`` (the numpy
    reference) to round-off, the rejections exactly. Thresholds are placed between the
    systems' NIS, never within round-off of one."""
    rng = np.random.default_rng(40 + n * 10 + m)
    B = 90
    x, P = rng.normal(size=(B, n)), spd(rng, (B,), n)
    F = rng.normal(size=(B, n, n)) / np.sqrt(n) + np.eye(n)
    H, R = rng.normal(size=(1, m, n)), spd(rng, (1,), m, 0.1)
    Q = spd(rng, (), n, 0.01)
    y, hx = 3.0 * rng.normal(size=(B, m)), rng.normal(size=(B, m))
    valid = rng.uniform(size=B) > 0.1
    predict = np.ones(B, bool)

    def run(valid, limits):
        s = record(x, P, limits)
        ck.predict_update(s, x, F, Q, y, hx, H, R, valid, predict)
        return s.x, s.P, s.nis, s.nis_run
    _, _, nis_free, _ = run(valid, LIMITS)
    q = np.sort(nis_free[valid])
    half = len(q) // 2
    gate = 0.5 * (q[half - 1] + q[half])                      # the upper half above
    gated = new_limits(gate, 10, 1e300)                       # the watch's NIS run, too
    gated[GATE] = gate
    xs, Ps, nis, runs = run(valid, gated)
    rejected = valid & (nis_free > gate)
    assert rejected.sum() == len(q) - half
    xm, Pm, _, runs_missing = run(valid & ~rejected, new_limits(gate, 10, 1e300))
    np.testing.assert_array_equal(xs, xm)
    np.testing.assert_array_equal(Ps, Pm)
    np.testing.assert_array_equal(nis[valid], nis_free[valid])     # reported all the same
    np.testing.assert_array_equal(runs, rejected.astype(int))     # and booked by the watch
    assert not runs_missing.any()
    P_pred = predict_covariance(P, F, Q)
    want = update_kernel(x, P_pred, y - hx, H[0], R[0], valid, gate)   # x⁻ = x here
    for a, b in zip((xs, Ps, nis), (want[0], want[1], want[3]), strict=True):
        close(a, b, np.nanmax(np.abs(b)))
    np.testing.assert_array_equal(want[0][rejected], x[rejected])
    np.testing.assert_array_equal(want[1][rejected], P_pred[rejected])


@pytest.mark.parametrize("steady", [False, True])
def test_linear_step_writes_nothing_when_the_gate_fires_under_a_shortcut(steady):
    """A shared covariance (or the steady state) cannot hold a rejected system's own ``P⁻``:
    ``linear_step`` returns False before writing any state; with the gate off it runs."""
    rng = np.random.default_rng(8)
    n, m, B = 3, 1, 7
    A = 0.9 * np.eye(n) + 0.05 * rng.normal(size=(n, n))
    C, Q, R = rng.normal(size=(m, n)), 0.1 * np.eye(n), np.array([[0.5]])
    x, P = rng.normal(size=(B, n)), np.eye(n)[None].copy()
    y = rng.normal(size=(B, m))
    y[4] += 1e3                                               # one outlier
    gains = LinearGains(n, m, may_settle=True)
    gains.K, gains.W = rng.normal(size=(n, m, 1)), np.full((m, m, 1), 0.3)
    gains.regime[0] = int(steady)
    valid, predict = np.ones(B, bool), np.ones(B, bool)
    limits = new_limits(1e300, 10, 1e300)
    limits[GATE] = 30.0
    s = record(x, P, limits)
    s.logdet[:] = -7.0
    fields = ("x", "P", "diverged", "nis_run", "nis", "logdet")
    before = [getattr(s, f).copy() for f in fields] + [a.copy() for a in
                                                       (gains.K, gains.W, gains.regime)]
    mats = StepMatrices(A, np.zeros((n, 0)), C, Q, R)
    u = np.zeros((1, 0))
    def linear_step():
        return ck.linear_step(mats.A, mats.B, mats.Qd, mats.C, mats.R, u, y, valid, predict,
                              gains.K, gains.W, gains.regime, s.x, s.P, s.diverged, s.nis_run,
                              s.nis, s.logdet, s.limits)
    done = linear_step()
    assert done is False
    after = [getattr(s, f) for f in fields] + [gains.K, gains.W, gains.regime]
    for name, b, a in zip((*fields, "K", "W", "regime"), before, after, strict=True):
        scratch = name in ("K", "W")                          # the gains: written afresh by
        if steady or not scratch:                             # every step out of the steady
            np.testing.assert_array_equal(b, a, err_msg=name)  # state
    s.limits[GATE] = np.inf
    assert linear_step() is True
    assert np.isfinite(s.nis).all()


@pytest.mark.parametrize("m", [1, 2, 3])
def test_predict_update_keeps_the_estimate_and_flags_where_S_is_not_positive_definite(m):
    """The numpy reference gives NaN there (``update_kernel``) and ``Estimator._accept`` keeps
    the last estimate and flags the system; the twin does both in one pass."""
    rng = np.random.default_rng(m)
    B, n = 6, 3
    x, P = rng.normal(size=(B, n)), spd(rng, (B,), n)
    F, H = np.eye(n)[None], rng.normal(size=(1, m, n))
    R = np.repeat(0.1 * np.eye(m)[None], B, axis=0)
    R[2] = -1e3 * np.eye(m)                        # S indefinite for system 2 only
    y = rng.normal(size=(B, m))
    valid = predict = np.ones(B, dtype=bool)
    s = record(x, P)
    ck.predict_update(s, x, F, np.zeros((n, n)), y, np.zeros((B, m)), H, R, valid, predict)
    xs, Ps, diverged, nis = s.x, s.P, s.diverged, s.nis
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = update_kernel(x, predict_covariance(P, F[0], np.zeros((n, n))), y, H[0], R,
                            valid)
    bad = ~np.isfinite(ref[0]).all(axis=1)
    np.testing.assert_array_equal(bad, np.arange(B) == 2)
    np.testing.assert_array_equal(diverged, bad)
    np.testing.assert_array_equal(xs[2], x[2])
    np.testing.assert_array_equal(Ps[2], P[2])
    close(xs[~bad], ref[0][~bad], np.abs(ref[0][~bad]).max())
    assert np.isnan(nis[2]) and np.isfinite(np.delete(nis, 2)).all()


def test_the_watch_equals_the_numpy_accept():
    """watch.accept against ``Estimator._accept`` (the numpy reference of the watch), bit for
    bit, on new estimates that are finite, non-finite, over the trace limit, with NIS runs
    across steps, NaN NIS and skipped measurements."""
    import copy

    from fir_gym.estimators import ExtendedKalmanFilter, LinearModel

    model = LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2), R=[[1.0]])
    B = 12
    a = ExtendedKalmanFilter(model, x0=np.zeros((B, 2)), P0=np.repeat(np.eye(2)[None], B, 0),
                             nis_patience=2, max_covariance_trace=50.0)    # a P per system
    a.step(np.zeros((B, 1)))
    b = copy.deepcopy(a)
    rng = np.random.default_rng(3)
    flagged = []
    for k in range(8):
        x_new, P_new = rng.normal(size=(B, 2)), spd(rng, (B,), 2)
        nis_new = rng.uniform(0.0, 2.0 * a.state.limits[NIS_THRESHOLD], size=B)
        valid = rng.uniform(size=B) > 0.2
        x_new[k % B] = np.nan
        P_new[(k + 3) % B, 0, 1] = np.inf
        P_new[(k + 5) % B] *= 100.0                              # trace above 50
        nis_new[(k + 7) % B] = np.nan
        nis_new[~valid] = np.nan
        with np.errstate(invalid="ignore"):
            a._accept(x_new.copy(), P_new.copy(), nis_new.copy(), valid)
        watch.accept(x_new, P_new, nis_new, valid, True, b.state)
        for name in ("x", "P", "diverged", "nis_run", "nis"):
            np.testing.assert_array_equal(getattr(a.state, name), getattr(b.state, name),
                                          err_msg=name)
        flagged.append(int(a.state.diverged.sum()))
    assert 0 < flagged[0] < flagged[-1]              # the flags spread as the runs go on


def blockwise(fn, S, *outs):
    """Run a block function of :mod:`.compiled.linalg` over a batch ``S (B, m, m)`` a block
    at a time; returns the outputs ``(B, m, m)`` and the ``ok`` flags."""
    B, m, _ = S.shape
    c = cl.CHUNK
    Ss, blocks, ok = np.empty((m, m, c)), [np.zeros((m, m, c)) for _ in outs], np.empty(c, bool)
    res, oks = [np.empty_like(S) for _ in outs], np.empty(B, bool)
    for b0 in range(0, B, c):
        nb = min(c, B - b0)
        cl.load(S, b0, nb, Ss)
        fn(Ss, *blocks, ok, nb)
        oks[b0:b0 + nb] = ok[:nb]
        for r, blk in zip(res, blocks, strict=True):
            r[b0:b0 + nb] = blk[:, :, :nb].transpose(2, 0, 1)
    return res, oks


@pytest.mark.parametrize("m", [1, 2, 3, 4, 6])
def test_block_cholesky_and_inverse_equal_the_numpy_references(m):
    rng = np.random.default_rng(20 + m)
    S = spd(rng, (70,), m)
    S[5] = -S[5]                                     # not positive definite
    with np.errstate(invalid="ignore", divide="ignore"):
        L_ref, W_ref = cholesky(S), spd_inverse(S)
    ok_ref = np.isfinite(W_ref).all(axis=(1, 2))
    assert not ok_ref[5] and ok_ref.sum() == 69
    (W, _), ok = blockwise(cl.spd_inverse, S, 0, 0)
    np.testing.assert_array_equal(ok, ok_ref)
    close(W[ok], W_ref[ok], np.abs(W_ref[ok]).max())
    close(W[ok] @ S[ok], np.broadcast_to(np.eye(m), S[ok].shape), 1.0)
    (L,), ok = blockwise(cl.cholesky, S, 0)
    np.testing.assert_array_equal(ok, np.isfinite(L_ref).all(axis=(1, 2)))
    low = np.tril(L[ok])
    close(low, L_ref[ok], np.abs(L_ref[ok]).max())
    close(low @ low.swapaxes(1, 2), S[ok], np.abs(S).max())


@pytest.mark.parametrize("jitter", [0.0, 1e-6])
def test_sigma_points_equal_the_numpy_square_root(jitter):
    """Cholesky where ``P`` is positive definite, the eigen-square-root where it is only
    semi-definite (a state known exactly), NaN where it is indefinite: ``matrix_sqrt``'s
    rules."""
    rng = np.random.default_rng(30)
    sp = MerweScaledSigmaPoints(3, 1.0, 2.0, 0.0)
    B = 80
    x, P = rng.normal(size=(B, 3)), spd(rng, (B,), 3, 0.3)
    P[4] = np.diag([1.0, 0.0, 2.0])                  # semi-definite
    P[9] = np.diag([1.0, -1.0, 2.0])                 # indefinite
    X = cu.sigma_points(x, P, sp.xi, jitter)
    with np.errstate(invalid="ignore"):
        X_ref = sp.points(x, matrix_sqrt(P, jitter))
    fine = np.isfinite(X_ref).all(axis=(1, 2))          # a system's points are usable or not
    np.testing.assert_array_equal(np.isfinite(X).all(axis=(1, 2)), fine)
    assert not fine[9] and fine[4] and fine.sum() == B - 1
    close(X[fine], X_ref[fine], np.abs(X_ref[fine]).max())


@pytest.mark.parametrize("points", [MerweScaledSigmaPoints(4, 1e-3, 2.0, 0.0),
                                    MerweScaledSigmaPoints(3, 1.0, 2.0, 0.0),
                                    CubatureSigmaPoints(4)], ids=repr)
def test_cross_moments_equal_the_numpy_moments(points):
    """Including α = 1e-3, whose weights (~ ±1e6) cancel: the deviations from the first
    point keep both paths accurate, so they still agree to round-off of the result."""
    rng = np.random.default_rng(6)
    B, n = 70, points.n
    X = points.sigma_points(rng.normal(size=(B, n)), spd(rng, (B,), n, 0.2))
    Z = np.sin(X[..., :2]) + X[..., 1:3] ** 2
    mean_x, mean_z, Pxz = cu.cross_moments(X, Z, points.Wm, points.Wc, False)
    mz, _, Pz = cu.cross_moments(Z, Z, points.Wm, points.Wc, True)
    np.testing.assert_array_equal(Pz, Pz.swapaxes(1, 2))          # a covariance: symmetric
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
    _, Pxz_ref = _cross_reference(X, Z, points)
    assert (np.abs(Pxz - Pxz_ref) <= gamma * magnitude(X, Z)).all()


def _cross_reference(X, Z, sp):
    from fir_gym.estimators.unscented import _cross, _moments
    _, DX, dx, cx = _moments(X, sp)
    mz, DZ, dz, cz = _moments(Z, sp)
    return mz, _cross(DX, dx, cx, DZ, dz, cz, sp)


@pytest.mark.parametrize(("name", "options"), [("ekf", {}), ("ukf", {"alpha": 1.0}),
                                               ("ukf", {"points": CubatureSigmaPoints(4)})])
def test_batched_filters_run_the_same_with_and_without_kernels(name, options):
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
            with numpy_path():
                trace = [filt.step(y) for y in Y]
        runs.append((np.array(trace), filt.P))
    np.testing.assert_allclose(runs[0][0], runs[1][0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(runs[0][1], runs[1][1], rtol=0,
                               atol=1e-12 * np.abs(runs[1][1]).max())


def test_environment_variable_turns_the_kernels_off(tmp_path):
    code = "from fir_gym.estimators import compiled; print(compiled.ENABLED)"
    for variables, expected in (({"FIR_GYM_NUMBA": "0"}, "False"),
                                ({"FIR_GYM_NUMBA": "off"}, "False"),
                                ({"FIR_GYM_NUMBA": "1"}, "True"),
                                ({"FIR_GYM_NUMBA": "1", "NUMBA_DISABLE_JIT": "1"}, "False")):
        # run outside the checkout: there, its fir_gym/ folder would shadow the install
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             env={**os.environ, **variables}, cwd=tmp_path, check=True)
        assert out.stdout.strip() == expected


def test_without_numba_jit_returns_the_python_function(monkeypatch):
    """Without numba a twin is its own Python loop (same signature, never called while
    ``ENABLED`` is false): never ``None``."""
    monkeypatch.setattr(compiled, "numba", None)

    def twice(x):
        return 2.0 * x
    assert compiled.jit(twice) is twice


@pytest.mark.parametrize("n", [1, 2, 3, 4])
@pytest.mark.parametrize("p", [1, 2, 3])
@pytest.mark.parametrize("per_window", [False, True])
@pytest.mark.parametrize("noise", [False, True])
@pytest.mark.parametrize("size", ["40x6", "2x2 scaled"])
def test_window_bank_kernels_equal_the_numpy_bank(n, p, per_window, noise, size):
    """Time and measurement updates and the read-outs (filter, smoother, with a prior) of a
    40-system, 6-window bank: the compiled passes against the numpy path, step by step,
    with inputs, with or without process noise and a skipped system. (A bank runs with
    process noise at every step or at none: without it ``P`` stays 0 and the time update
    skips ``A P Aᵀ``, so mixing the two leaves an asymmetric ``P``.) Also 2 systems and 2
    windows — the smallest counts that are not shared — with states measured on scales
    seven decades apart, where only the unit-diagonal regularity test calls the
    information regular (mutation testing found both untested)."""
    from fir_gym.estimators._fir_bank import WindowBank
    rng = np.random.default_rng(10 * n + p)
    B, W = (40, 6) if size == "40x6" else (2, 2)
    column_scale = np.ones(n) if size == "40x6" else 10.0 ** np.linspace(-7, 0, n)
    banks = [WindowBank(B, W, n), WindowBank(B, W, n)]
    for bank in banks:
        bank.restart(0, x_ref=np.ones((B, n)))
    lead = (B, W) if per_window else (1,)
    for k in range(2 * W):
        A = np.eye(n) + 0.1 * rng.normal(size=lead + (n, n))
        C = rng.normal(size=lead + (p, n)) * column_scale
        Bu = rng.normal(size=(B, W, n) if per_window else (B, n))
        Qx = spd(rng, (), n, 0.01) if noise else None
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
                with numpy_path():
                    bank.predict(A, Bu, Qx)
                    bank.update(C, R, y, valid)
                    bank.restart(k % W)
        scale = np.abs(banks[1].Z).max()
        np.testing.assert_allclose(banks[0].Z, banks[1].Z, rtol=0, atol=1e-12 * scale)
    w = (2 * W) % W
    prior = spd(rng, (B,), n, 0.5)
    # the read-out solves with the window's information F: round-off grows by κ(F) (of the
    # unit-diagonal F, the scale the rank test uses; singular windows fall back alike)
    kappa = np.linalg.cond(unit_diagonal(-banks[1].Z[:, n:, w, n:2 * n]))
    kappa = kappa[np.isfinite(kappa)].max(initial=1.0)
    tol = max(RTOL, 1e-15 * kappa)
    assert np.isfinite(tol)
    for options in ({}, {"smoother": True}, {"prior": prior}, {"prior": prior[0]}):
        x, P, ok = banks[0].estimate(w, **options)
        with numpy_path():
            x_ref, P_ref, ok_ref = banks[1].estimate(w, **options)
        np.testing.assert_array_equal(ok, ok_ref)
        np.testing.assert_allclose(x, x_ref, rtol=0, atol=tol * np.abs(x_ref).max())
        np.testing.assert_allclose(P, P_ref, rtol=0, atol=tol * np.abs(P_ref).max())


def test_window_bank_readout_falls_back_where_the_information_is_singular():
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
    with numpy_path():
        x_ref, _, ok_ref = bank.estimate(0)
    np.testing.assert_array_equal(ok, ok_ref)
    assert not ok[5] and ok[np.arange(B) != 5].all()
    close(x[ok], x_ref[ok], np.abs(x_ref[ok]).max())


def test_kalman_filter_with_per_system_covariances_equals_the_numpy_path():
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
            with numpy_path():
                trace = [filt.step(Y[k], None if k == 0 else U[k]) for k in range(K)]
        runs.append((np.array(trace), filt.P, filt.steady_state))
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

    monkeypatch.setattr(compiled, "numba", types.SimpleNamespace(njit=njit))
    twice = compiled.jit(lambda x: 2.0 * x)
    assert calls == [True, False] and twice(1.5) == 3.0
