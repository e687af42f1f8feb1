"""The three FIR gain paths of fir_gains agree, are unbiased and minimum-variance."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from fir_gym.estimators.fir import observability_index
from fir_gym.estimators.fir_gains import (
    FORMS,
    Window,
    batch_gain,
    information_is_regular,
    input_gain,
    riccati_gain,
    stacked_window,
    stationary_prior,
    two_stage_forward,
    two_stage_gain,
)

TOL = 1e-9


def random_window(seed: int, n: int, p: int, n_w: int, L: int, n_u: int = 1,
                  singular_A: bool = False) -> Window:
    """A time-varying window: A_j with singular values in [0.5, 1.5] (or one zero)."""
    rng = np.random.default_rng(seed)
    A = np.empty((L, n, n))
    for j in range(L):
        U, _ = np.linalg.qr(rng.normal(size=(n, n)))
        V, _ = np.linalg.qr(rng.normal(size=(n, n)))
        s = rng.uniform(0.5, 1.5, n)
        if singular_A:
            s[-1] = 0.0
        A[j] = U @ np.diag(s) @ V.T
    C = rng.normal(size=(L, p, n))
    G = rng.normal(size=(L, n, n_w))                      # rank n_w < n: singular GQGᵀ
    Qx = 0.3 * G @ G.swapaxes(1, 2)
    Rh = rng.normal(size=(L, p, p))
    R = 0.2 * Rh @ Rh.swapaxes(1, 2) + 0.5 * np.eye(p)
    return Window(A, C, Qx, R, rng.normal(size=(L, n, n_u)))


def conditioning(win: Window) -> float:
    F = two_stage_forward(win).F
    d = np.sqrt(np.diag(F))
    return float(np.linalg.cond(F / np.outer(d, d)))


def close(a: np.ndarray, b: np.ndarray, tol: float = TOL) -> bool:
    return bool(np.max(np.abs(a - b)) <= tol * max(1.0, np.max(np.abs(a))))


systems = st.tuples(st.integers(0, 2**31), st.integers(1, 4)).flatmap(
    lambda sn: st.tuples(st.just(sn[0]), st.just(sn[1]), st.integers(1, sn[1]),
                         st.integers(1, sn[1]), st.integers(0, 4)))


@settings(max_examples=40, deadline=None)
@given(systems)
def test_paths_agree_without_prior(sys: tuple[int, int, int, int, int]) -> None:
    seed, n, p, n_w, extra = sys
    L = -(-n // p) + extra                                 # ≥ the observability index
    win = random_window(seed, n, p, n_w, L)
    assume(conditioning(win) < 1e6)                        # else no path can reach 1e-9
    for form in ("filter", "predictor"):
        a, b, c = batch_gain(win, form), riccati_gain(win, form), two_stage_gain(win, form)
        assert close(a.S, c.S) and close(a.P, c.P)
        assert close(a.S, b.S) and close(a.P, b.P)
    a, c = batch_gain(win, "smoother"), two_stage_gain(win, "smoother")
    assert close(a.S, c.S) and close(a.P, c.P)


@settings(max_examples=30, deadline=None)
@given(systems)
def test_paths_agree_with_prior(sys: tuple[int, int, int, int, int]) -> None:
    seed, n, p, n_w, extra = sys
    win = random_window(seed, n, p, n_w, 1 + extra)
    M = np.random.default_rng(seed + 1).normal(size=(n, n))
    P0 = M @ M.T + 0.1 * np.eye(n)
    for form in FORMS:                                    # Theorem 2.1 and Theorem 3.1
        a = batch_gain(win, form, P0)
        for other in (riccati_gain(win, form, P0), two_stage_gain(win, form, P0)):
            assert close(a.S, other.S) and close(a.P, other.P)


@settings(max_examples=30, deadline=None)
@given(systems)
def test_unbiased_S_Ct_equals_Phi(sys: tuple[int, int, int, int, int]) -> None:
    seed, n, p, n_w, extra = sys
    win = random_window(seed, n, p, n_w, -(-n // p) + extra)
    assume(conditioning(win) < 1e6)
    for form in FORMS:
        sw = stacked_window(win, form)
        for path in (batch_gain, two_stage_gain):
            S = path(win, form).S
            assert close(S @ sw.Ct, sw.Phi, 1e-8 * max(1.0, np.abs(S).max()))


@pytest.mark.parametrize("form", FORMS)
def test_minimum_variance_among_unbiased_gains(form: str) -> None:
    win = random_window(7, 3, 1, 2, 6)
    sw = stacked_window(win, form)
    S = two_stage_gain(win, form).S

    def trace_cov(K: np.ndarray) -> float:                # error covariance of any unbiased K
        Nw = sw.M - K @ sw.Gt
        return float(np.trace(Nw @ sw.Qbd @ Nw.T + K @ sw.Rbd @ K.T))

    null = sla.null_space(sw.Ct.T).T                      # rows z with z C̃ = 0
    rng = np.random.default_rng(0)
    for _ in range(20):
        D = rng.normal(size=(3, null.shape[0])) @ null * 1e-3
        assert np.allclose(D @ sw.Ct, 0.0, atol=1e-12)
        assert trace_cov(S + D) > trace_cov(S)


def test_information_matrix_is_Ct_Pi_Ct() -> None:
    win = random_window(3, 3, 2, 2, 5)
    sw = stacked_window(win)
    Pi = sw.Gt @ sw.Qbd @ sw.Gt.T + sw.Rbd
    assert np.allclose(two_stage_forward(win).F, sw.Ct.T @ np.linalg.solve(Pi, sw.Ct),
                       rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("form", FORMS)
def test_input_gain_makes_noise_free_estimate_exact(form: str) -> None:
    win = random_window(11, 3, 1, 3, 6, n_u=2)
    rng = np.random.default_rng(5)
    x = rng.normal(size=3) * 10.0
    U = rng.normal(size=(6, 2))
    xs, ys = [], []
    for j in range(6):
        xs.append(x)
        ys.append(win.C[j] @ x)
        x = win.A[j] @ x + win.B[j] @ U[j]
    xs.append(x)
    S = two_stage_gain(win, form).S
    Su = input_gain(win, S, form)
    target = {"filter": xs[5], "predictor": xs[6], "smoother": xs[0]}[form]
    est = S @ np.concatenate(ys) + Su @ U.ravel()
    assert np.allclose(est, target, rtol=1e-10, atol=1e-10)
    sw = stacked_window(win, form)
    assert np.allclose(Su, sw.MB - S @ sw.Dt, atol=1e-12)


def test_stationary_prior_cor_2_1() -> None:
    rng = np.random.default_rng(2)
    A = rng.normal(size=(3, 3))
    A *= 0.9 / np.max(np.abs(np.linalg.eigvals(A)))
    Qx = np.diag([0.5, 0.0, 0.2])
    P = stationary_prior(A, Qx)
    assert np.allclose(A @ P @ A.T + Qx, P)
    win = Window(np.broadcast_to(A, (5, 3, 3)), np.broadcast_to([[1.0, 0.0, 0.0]], (5, 1, 3)),
                 np.broadcast_to(Qx, (5, 3, 3)), np.broadcast_to([[0.3]], (5, 1, 1)),
                 np.zeros((5, 3, 0)))
    assert close(riccati_gain(win, "filter", P).S, batch_gain(win, "filter", P).S)
    with pytest.raises(ValueError, match="stable"):
        stationary_prior(2.0 * A / 0.9, Qx)


@pytest.mark.parametrize("path", [batch_gain, riccati_gain, two_stage_gain])
def test_rank_deficient_window_raises(path) -> None:   # type: ignore[no-untyped-def]
    win = random_window(1, 3, 1, 3, 2)                    # 2 scalar measurements, 3 states
    with pytest.raises(ValueError, match="rank-deficient"):
        path(win, "filter")


def test_cor_2_2_needs_invertible_A_two_stage_does_not() -> None:
    win = random_window(4, 3, 2, 2, 5, singular_A=True)
    with pytest.raises(ValueError, match="invertible A"):
        riccati_gain(win, "filter")
    assert close(two_stage_gain(win).S, batch_gain(win).S)


def test_riccati_has_no_no_prior_smoother() -> None:
    with pytest.raises(ValueError, match=r"Cor 3\.2"):
        riccati_gain(random_window(0, 2, 1, 2, 4), "smoother")


def test_observability_index() -> None:
    A = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    assert observability_index(A, [[1.0, 0.0, 0.0]]) == 3
    assert observability_index(A, np.eye(3)) == 1
    assert observability_index(A, [[0.0, 0.0, 1.0]]) is None
    assert not information_is_regular(np.ones((1, 2, 2)))[0]
    assert information_is_regular(np.diag([1e-8, 1e8])[None])[0]      # scale-free
