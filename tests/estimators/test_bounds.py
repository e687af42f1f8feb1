"""Paper 001: the continuous optimal FIR filter against scipy's ODE solution and the CARE, the
true error covariance against Theorem 2.1's ODEs and a Monte Carlo of the mismatched filter,
Table 1's Δπ₁ at T = 1, and the validity (or not) of the bounds."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from fir_gym.estimators.bounds import (
    corners,
    delta_pi1,
    delta_pi1_from_start,
    delta_pi2,
    error_covariance,
    theorem21,
    worst_case,
)
from fir_gym.estimators.continuous import ContinuousModel
from fir_gym.estimators.continuous_fir import (
    fir_riccati,
    kalman_bucy,
    stationary_covariance,
)

A = np.array([[0.0, 1.0], [-0.36, -0.06]])
G = np.array([[0.6], [-0.036]])


def carrier(q=0.035, v=1.0, d22=0.0, dc=0.0, C=None):
    A_ = A + np.array([[0.0, 0.0], [0.0, d22]])
    C_ = np.array([[1.0 + dc, 0.0]]) if C is None else C
    return ContinuousModel.linear(A=A_, C=C_, G=G, Q=q, R=v, dt=0.1)


def riccati_ode(model, T):
    W, S = model.GQGT, model.C.T @ model.R_inv @ model.C

    def rhs(t, r):
        R = r.reshape(2, 2)
        return (model.A @ R + R @ model.A.T + W - R @ S @ R).ravel()

    Pi = scipy.linalg.solve_continuous_lyapunov(model.A, -W)
    return solve_ivp(rhs, (0, T), Pi.ravel(), rtol=1e-12, atol=1e-14, method="DOP853",
                     dense_output=True)


# ---------------------------------------------------------------------------- the FIR filter
def test_fir_riccati_matches_scipy_ode_solution():
    m = carrier()
    fir = fir_riccati(m, 7.0)
    ref = riccati_ode(m, 7.0)
    exact = np.array([ref.sol(s).reshape(2, 2) for s in fir.sigma])
    np.testing.assert_allclose(fir.R, exact, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fir.K, exact @ m.C.T / m.R[0, 0], rtol=1e-9, atol=1e-12)


def test_closed_loop_transition_matches_its_ode():
    m = carrier()
    fir = fir_riccati(m, 5.0)
    ref = riccati_ode(m, 5.0)

    def rhs(t, p):
        R = ref.sol(t).reshape(2, 2)
        F = m.A - R @ m.C.T @ m.C / m.R[0, 0]
        return (F @ p.reshape(2, 2)).ravel()

    Phi = solve_ivp(rhs, (0, 5.0), np.eye(2).ravel(), rtol=1e-12, atol=1e-14,
                    method="DOP853").y[:, -1].reshape(2, 2)
    np.testing.assert_allclose(fir.to_end()[0], Phi, rtol=1e-8)    # Φ_F(T, 0)
    H = fir.impulse_response()
    np.testing.assert_allclose(H[0], Phi @ fir.K[0], rtol=1e-8)
    np.testing.assert_allclose(H[-1], fir.K[-1], rtol=1e-12)


def test_fir_covariance_tends_to_the_kalman_bucy_steady_state():
    m = carrier()
    P_inf = kalman_bucy(m)
    errors = [np.linalg.norm(fir_riccati(m, T, n_steps=20 * int(T)).R[-1] - P_inf)
              / np.linalg.norm(P_inf) for T in (5, 20, 80, 320)]
    assert all(b < a for a, b in itertools.pairwise(errors))
    assert errors[-1] < 1e-6
    traces = np.trace(fir_riccati(m, 20.0).R, axis1=1, axis2=2)
    assert np.all(np.diff(traces) <= 1e-15)          # R(0) = Π ≥ P∞: decreasing
    assert traces[0] == pytest.approx(np.trace(stationary_covariance(m)))


# ---------------------------------------------------------------------------- R_r
CASES = {"noise": (carrier(), carrier(q=0.045, v=0.9)),
         "model": (carrier(), carrier(d22=0.006, dc=0.1)),
         "both, true V != 1": (carrier(q=0.03, v=1.3, d22=-0.006), carrier(dc=-0.1))}


@pytest.mark.parametrize("case", list(CASES))
def test_joint_covariance_agrees_with_theorem_2_1(case):
    true, nominal = CASES[case]
    ec = error_covariance(true, nominal, 5.0)
    th = theorem21(true, nominal, 5.0)
    np.testing.assert_allclose(ec.R + th.U[-1], ec.R_r, rtol=1e-8, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(ec.R_r - ec.R) > -1e-12)       # the optimum is optimal


def test_kalman_error_covariance_is_the_long_window_limit():
    true, nominal = CASES["both, true V != 1"]
    steady = error_covariance(true, nominal, None)
    long = error_covariance(true, nominal, 400.0, n_steps=4000)
    np.testing.assert_allclose(long.R_r, steady.R_r, rtol=1e-6)
    np.testing.assert_allclose(long.R, steady.R, rtol=1e-6)


def test_true_error_covariance_agrees_with_a_monte_carlo_of_the_mismatched_filter():
    """Independent oracle: simulate the true plant, run the nominal Kalman–Bucy recursion from
    x̂ = 0 over the window with gains from scipy's ODE solver, and average e eᵀ."""
    true, nominal = carrier(), carrier(q=0.1, v=0.4, d22=0.04, dc=0.3)
    T, n, M = 2.0, 1000, 20000
    d = T / n
    rng = np.random.default_rng(20240601)
    gains = riccati_ode(nominal, T)
    Kt = lambda s: gains.sol(s).reshape(2, 2) @ nominal.C.T / nominal.R[0, 0]  # noqa: E731
    Pi = scipy.linalg.solve_continuous_lyapunov(true.A, -true.GQGT)
    x = rng.multivariate_normal(np.zeros(2), Pi, size=M)
    Ad = scipy.linalg.expm(true.A * d)
    Qd = scipy.linalg.solve_continuous_lyapunov(true.A, -true.GQGT)
    Qd = Qd - Ad @ Qd @ Ad.T                            # exact sampled noise of a stable A
    Lq = np.linalg.cholesky(Qd + 1e-18 * np.eye(2))
    x_hat = np.zeros((M, 2))
    for j in range(n):
        x_next = x @ Ad.T + rng.standard_normal((M, 2)) @ Lq.T
        dz = 0.5 * d * (x + x_next) @ true.C.T + np.sqrt(true.R[0, 0] * d) * rng.standard_normal(
            (M, 1))
        K0, K1 = Kt(j * d), Kt((j + 1) * d)
        F0, F1 = nominal.A - K0 @ nominal.C, nominal.A - K1 @ nominal.C
        rhs = x_hat + 0.5 * d * x_hat @ F0.T + dz @ (0.5 * (K0 + K1)).T
        x_hat = np.linalg.solve(np.eye(2) - 0.5 * d * F1, rhs.T).T   # trapezoid step
        x = x_next
    e = x - x_hat
    sq = (e * e).sum(1)
    mc, se = sq.mean(), sq.std(ddof=1) / np.sqrt(M)
    ec = error_covariance(true, nominal, T)
    assert abs(mc - np.trace(ec.R_r)) < 4 * se
    assert abs(mc - np.trace(ec.R)) > 8 * se                          # R_r is not R here
    np.testing.assert_allclose(e.T @ e / M, ec.R_r, rtol=0.05, atol=0.05 * np.trace(ec.R_r))


# ---------------------------------------------------------------------------- Δπ₁
def test_delta_pi1_at_T1_reproduces_table_1():
    bound = delta_pi1(carrier(), carrier(q=0.045, v=0.9), 1.0)
    assert float(f"{bound.paper:.2g}") == 0.0013
    assert bound.paper == pytest.approx(bound.trace, rel=1e-12)       # one output, V = 1
    assert bound.lemma1 >= bound.trace


@pytest.mark.parametrize("horizon", [1.0, 5.0, None])
def test_delta_pi1_trace_is_the_exact_degradation(horizon):
    true, nominal = CASES["noise"]
    ec = error_covariance(true, nominal, horizon)
    bound = delta_pi1(true, nominal, horizon)
    assert bound.trace == pytest.approx(np.trace(ec.R_r - ec.R), rel=1e-5)


def test_delta_pi1_as_printed_is_not_an_upper_bound_with_two_outputs():
    """Two identical decoupled channels: the integrand has two equal eigenvalues, so its
    Frobenius norm is tr/√2 and eq 3.2 falls short of tr(R_r − R) by that factor."""
    def twin(v):
        return ContinuousModel.linear(A=-np.eye(2), C=np.eye(2), G=np.eye(2), Q=np.eye(2),
                                      R=v * np.eye(2), dt=0.1)

    true, nominal = twin(1.0), twin(0.5)
    bound = delta_pi1(true, nominal, 3.0)
    ec = error_covariance(true, nominal, 3.0)
    assert bound.trace == pytest.approx(np.trace(ec.R_r - ec.R), rel=1e-5)
    assert bound.paper == pytest.approx(bound.trace / np.sqrt(2), rel=1e-9)
    assert bound.lemma1 >= bound.trace * (1 - 1e-12)                 # Lemma 1 holds


# ---------------------------------------------------------------------------- Δπ₂
@pytest.mark.parametrize("horizon", [1.0, 5.0, None])
def test_delta_pi2_bounds_the_exact_degradation_on_every_corner(horizon):
    true = carrier()
    for c in corners({"d22": 0.006, "dc": 0.1}):
        nominal = carrier(**c)
        bound = delta_pi2(true, nominal, horizon)
        ec = error_covariance(true, nominal, horizon)
        assert bound.value >= np.trace(ec.R_r - ec.R) > 0
        assert bound.beta >= np.linalg.norm(stationary_covariance(true))
        if horizon is not None:
            T_path = theorem21(true, nominal, horizon).T
            assert bound.alpha1 >= np.linalg.norm(T_path, axis=(1, 2)).max()


def test_delta_pi2_without_model_error_is_the_noise_term():
    true, nominal = CASES["noise"]
    bound = delta_pi2(true, nominal, 5.0)
    assert bound.coupling == 0 and bound.value == bound.noise
    assert bound.value == pytest.approx(delta_pi1(true, nominal, 5.0).trace, rel=1e-12)


def test_worst_case_is_the_largest_corner():
    box = {"dq": 0.01, "dv": 0.1}
    wc = worst_case(lambda c: (carrier(), carrier(q=0.035 + c["dq"], v=1.0 + c["dv"])), box, 1.0)
    assert len(wc.values) == 4 and wc.corner == {"dq": 0.01, "dv": -0.1}
    assert wc.value == max(v for _, v in wc.values)


def test_bad_models_are_rejected():
    vdp = ContinuousModel(a=lambda x, u: -x, h=lambda x: x[..., :1], Q=1.0, R=1.0, dt=0.1,
                          G=np.ones((2, 1)))
    with pytest.raises(TypeError, match="linear ContinuousModel"):
        fir_riccati(vdp, 1.0)
    unstable = ContinuousModel.linear(A=[[0.0, 1.0], [1.0, 0.0]], C=[[1.0, 0.0]], G=G, Q=1.0,
                                      R=1.0, dt=0.1)
    with pytest.raises(ValueError, match="stable"):
        fir_riccati(unstable, 1.0)
    with pytest.raises(ValueError, match="horizon"):
        fir_riccati(carrier(), -1.0)


# ---------------------------------------------------------------------------- Φ_F(τ, 0) reading
def test_delta_pi1_from_start_against_one_ode_solve():
    """Eq 3.2 with Φ_F(τ, 0): one DOP853 solve of both Riccati equations, the transition
    dΦ/dσ = (A_M − K_M C_M) Φ from Φ(0) = I and the integral of the Frobenius norm as a
    fourth component — no Hamiltonian exponential, no Simpson rule (the implementation's)."""
    true, nominal = carrier(), carrier(q=0.045, v=0.9)
    T = 5.0

    def rhs(t, y):
        R, R_M, Phi = y[:4].reshape(2, 2), y[4:8].reshape(2, 2), y[8:12].reshape(2, 2)
        out = []
        for m, P in ((true, R), (nominal, R_M)):
            S = m.C.T @ m.R_inv @ m.C
            out.append((m.A @ P + P @ m.A.T + m.GQGT - P @ S @ P).ravel())
        K, K_M = R @ true.C.T @ true.R_inv, R_M @ nominal.C.T @ nominal.R_inv
        dPhi = (nominal.A - K_M @ nominal.C) @ Phi
        X = Phi @ (K_M - K)
        return np.concatenate([*out, dPhi.ravel(), [np.linalg.norm(X @ X.T)]])

    y0 = np.concatenate([stationary_covariance(true).ravel(),
                         stationary_covariance(nominal).ravel(), np.eye(2).ravel(), [0.0]])
    ref = solve_ivp(rhs, (0, T), y0, rtol=1e-11, atol=1e-14, method="DOP853").y[-1, -1]
    assert delta_pi1_from_start(true, nominal, T) == pytest.approx(ref, rel=1e-6)
    # the two readings differ on a window (Φ_F(T, τ) ≠ Φ_F(τ, 0)) ...
    assert abs(delta_pi1(true, nominal, T).paper / ref - 1) > 0.05
    # ... and coincide for the steady-state filter, where both are e^{F τ}
    assert delta_pi1_from_start(true, nominal, None) == pytest.approx(
        delta_pi1(true, nominal, None).paper, rel=1e-12)


def test_from_start_is_the_product_of_the_steps_from_zero():
    fir = fir_riccati(carrier(), 2.0, 40)
    start, end = fir.from_start(), fir.to_end()
    np.testing.assert_allclose(start[0], np.eye(2))
    # Φ_F(T, σ_j) Φ_F(σ_j, 0) = Φ_F(T, 0) at every grid point
    for j in range(len(fir.sigma)):
        np.testing.assert_allclose(end[j] @ start[j], start[-1], rtol=1e-12, atol=1e-14)
