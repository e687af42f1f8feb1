"""Block-pulse Kalman filter (paper 002): the Riccati recursion against scipy's ODE solution,
its order, the global form's breakdown, and the Estimator contract."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from fir_gym.envs.van_der_pol import van_der_pol_continuous_model
from fir_gym.estimators import LinearModel
from fir_gym.estimators.bpf import (
    BlockPulseKalmanFilter,
    bpf_riccati,
    bpf_riccati_step,
    bpf_state_step,
    hamiltonian,
)
from fir_gym.estimators.continuous import ContinuousModel
from fir_gym.estimators.continuous_fir import kalman_bucy
from fir_gym.estimators.kalman import kf_update
from fir_gym.estimators.registry import estimator_class

VDP = {"epsilon": 1.0, "u_max": 5.0, "Q": 5.0, "R": 5.0, "h": 0.1}
H = np.array([[1.0, 0.0]])
S = H.T @ H / 5.0                  # Hᵀ R⁻¹ H, R = 5
W = 5.0 * np.ones((2, 2))          # G Q Gᵀ, G = [1, 1]ᵀ, Q = 5
P0 = 5.0 * np.eye(2)
TF = 10.0
GAUSS = np.polynomial.legendre.leggauss(5)


@pytest.fixture(scope="module")
def vdp_riccati():
    """Paper 002's Riccati equation along the noise-free Van der Pol path from [1, 1]."""
    path = solve_ivp(lambda t, x: [x[1], -x[0] + (1 - x[0] ** 2) * x[1]], (0, TF), [1.0, 1.0],
                     rtol=1e-12, atol=1e-12, method="DOP853", dense_output=True)

    def A(t):
        return np.array([[0.0, 1.0], [-1.0, 1.0 - path.sol(t)[0] ** 2]])

    def rhs(t, p):
        P = p.reshape(2, 2)
        return (A(t) @ P + P @ A(t).T + W - P @ S @ P).ravel()

    ref = solve_ivp(rhs, (0, TF), P0.ravel(), rtol=1e-12, atol=1e-12, method="DOP853",
                    dense_output=True)
    return A, ref


def coefficients(A, m, where="average"):
    """Block-pulse coefficients of M(t): interval averages (Gauss–Legendre) or start values."""
    h = TF / m
    starts = np.arange(m) * h
    if where == "start":
        return np.array([hamiltonian(A(t), S, W) for t in starts])
    nodes, weights = GAUSS
    return np.array([sum(w * hamiltonian(A(t + h / 2 * (1 + z)), S, W)
                         for z, w in zip(nodes, weights, strict=True)) / 2 for t in starts])


def max_relative_error(A, ref, m, where="average", form="restart"):
    path = bpf_riccati(P0, coefficients(A, m, where), TF / m, form=form)
    t = np.linspace(0, TF, m + 1)
    exact = np.array([ref.sol(tk).reshape(2, 2) for tk in t])
    return float(np.max(np.linalg.norm(path.P - exact, axis=(1, 2))
                        / np.linalg.norm(exact, axis=(1, 2))))


def fitted_order(errors, ms):
    return -np.polyfit(np.log(ms), np.log(errors), 1)[0]


def test_riccati_within_one_percent_at_m_100(vdp_riccati):
    assert max_relative_error(*vdp_riccati, 100) < 0.01


def test_riccati_error_is_second_order(vdp_riccati):
    ms = np.array([50, 100, 200, 400])
    order = fitted_order([max_relative_error(*vdp_riccati, m) for m in ms], ms)
    assert 1.9 < order < 2.1


def test_freezing_A_at_the_interval_start_is_first_order(vdp_riccati):
    """The adaptive scheme (eqs 2.5–2.10) freezes A at t_k: O(h), 12 % at m = 100."""
    ms = np.array([100, 200, 400])
    errors = [max_relative_error(*vdp_riccati, m, where="start") for m in ms]
    assert 0.9 < fitted_order(errors, ms) < 1.1
    assert errors[0] > 0.05


def test_lti_riccati_matches_expm_solution_and_global_form():
    A = np.array([[0.0, 1.0], [-1.0, 0.5]])
    M = hamiltonian(A, S, W)
    m, h = 200, TF / 200
    restart = bpf_riccati(P0, np.broadcast_to(M, (m, 4, 4)), h)
    globl = bpf_riccati(P0, np.broadcast_to(M, (m, 4, 4)), h, form="global")
    E = scipy.linalg.expm(M * TF)
    xi = E @ np.vstack([np.eye(2), P0])
    exact = np.linalg.solve(xi[:2].T, xi[2:].T).T           # eq 3.11, erratum
    np.testing.assert_allclose(restart.P[-1], exact, rtol=1e-3)
    np.testing.assert_allclose(globl.P, restart.P, rtol=1e-8)  # same numbers, well conditioned
    assert restart.condition.max() < 10 < globl.condition.max()


def test_global_recursion_loses_conditioning_but_never_raises(vdp_riccati):
    """Over 30 s on the stiffer path the global form's inversions become singular."""
    A = np.array([[0.0, 1.0], [-1.0, 1.0 - 3.0 ** 2]])          # x1 = 3: strong damping
    M = np.broadcast_to(hamiltonian(A, S, W), (300, 4, 4))
    with np.errstate(all="raise"):
        path = bpf_riccati(P0, M, 0.1, form="global")
        restart = bpf_riccati(P0, M, 0.1)
    cond = path.condition
    broken = np.flatnonzero(~(cond <= 1e12))
    assert broken.size and broken[0] < 100                       # within 10 s
    np.testing.assert_allclose(path.P[: broken[0]], restart.P[: broken[0]], rtol=1e-6)
    assert np.all(np.isfinite(restart.P)) and restart.condition.max() < 10


def test_riccati_step_is_batched():
    rng = np.random.default_rng(1)
    Ps = np.stack([np.eye(2) * s for s in (1.0, 2.0, 3.0)])
    As = rng.normal(size=(3, 2, 2))
    M = hamiltonian(As, S, W)
    batch = bpf_riccati_step(Ps, M, 0.1)
    for b in range(3):
        one = bpf_riccati_step(Ps[b], M[b], 0.1)
        np.testing.assert_allclose(batch.P_next[b], one.P_next)
        np.testing.assert_allclose(batch.P_bar[b], one.P_bar)


# ---------------------------------------------------------------------------- the filter
def carrier_model(B=None):
    return ContinuousModel.linear(A=[[0.0, 1.0], [-0.36, -0.06]], C=[[1.0, 0.0]],
                                  G=[[0.6], [-0.036]], Q=0.035, R=1.0, dt=0.1, B=B)


def test_first_step_is_the_kalman_update_with_R_over_h():
    m = carrier_model()
    f = BlockPulseKalmanFilter(m, x0=[0.1, 0.0], P0=np.eye(2))
    x = f.step([0.7])
    x_ref, P_ref, _ = kf_update(np.array([0.1, 0.0]), np.eye(2), [0.7], m.C, m.R / m.dt)
    np.testing.assert_allclose(x, x_ref)
    np.testing.assert_allclose(f.P, P_ref)


def test_covariance_converges_to_the_kalman_bucy_steady_state():
    """Linear model: the filter's P tends to the CARE solution (Tustin error O(h²))."""
    m = carrier_model()
    f = BlockPulseKalmanFilter(m, P0=np.eye(2) * 0.1)
    for _ in range(3000):
        f.step([0.0])
    P_inf = kalman_bucy(m)
    np.testing.assert_allclose(f.P, P_inf, rtol=2e-3, atol=1e-6)


def test_input_follows_the_deterministic_system_when_measurements_are_uninformative():
    B = [[0.0], [1.0]]
    m = ContinuousModel.linear(A=[[0.0, 1.0], [-0.36, -0.06]], C=[[1.0, 0.0]],
                               G=[[0.6], [-0.036]], Q=1e-12, R=1e12, dt=0.05, B=B)
    f = BlockPulseKalmanFilter(m, x0=[1.0, 0.0], P0=np.eye(2) * 1e-12)
    f.step([0.0])
    exact = LinearModel(A=scipy.linalg.expm(np.array([[0, 1], [-0.36, -0.06]]) * 0.05),
                        C=[[1.0, 0.0]], Q=np.eye(2), R=1.0)
    Ad = exact.A
    Bd = np.linalg.solve(np.array([[0, 1], [-0.36, -0.06]]), (Ad - np.eye(2)) @ np.array(B))
    x = np.array([1.0, 0.0])
    for k in range(100):
        u = np.array([np.sin(0.1 * k)])
        x = Ad @ x + Bd @ u
        x_hat = f.step([0.0], u)
    np.testing.assert_allclose(x_hat, x, atol=1e-3)


def test_batch_equals_single_systems_and_a_batch_of_one():
    m = van_der_pol_continuous_model(VDP)
    rng = np.random.default_rng(3)
    Y = rng.normal(size=(20, 3, 1)) * 7
    batch = BlockPulseKalmanFilter(m, x0=[1.0, 1.0], P0=5 * np.eye(2))
    singles = [BlockPulseKalmanFilter(m, x0=[1.0, 1.0], P0=5 * np.eye(2)) for _ in range(3)]
    one = BlockPulseKalmanFilter(m, x0=[1.0, 1.0], P0=5 * np.eye(2))
    for y in Y:
        xb = batch.step(y)
        xo = one.step(y[:1])
        for b, f in enumerate(singles):
            np.testing.assert_allclose(xb[b], f.step(y[b]), rtol=1e-12, atol=1e-12)
            # and so does each single system's step information (mutation testing: untested)
            for key in ("riccati_breakdown", "riccati_condition"):
                if key in batch.last_info:
                    assert f.last_info[key] == pytest.approx(batch.last_info[key][b],
                                                             rel=1e-12), key
        np.testing.assert_allclose(xo[0], xb[0], rtol=1e-12, atol=1e-12)
    assert batch.P.shape == (3, 2, 2) and one.x.shape == (1, 2)


def test_missing_measurement_is_a_prediction():
    """With y missing, one interval is the block-pulse step of ẋ = A x and of the Riccati
    equation without its measurement term (eqs 2.14, 2.16, 3.8 with Hᵀ R⁻¹ H = 0)."""
    m = carrier_model()
    f = BlockPulseKalmanFilter(m, nan_policy="skip")
    f.step([0.3])
    x, P = f.x, f.P
    x_next = f.step([np.nan])
    np.testing.assert_allclose(x_next, bpf_state_step(x, m.A, np.zeros(2), m.dt), rtol=1e-12)
    M = hamiltonian(m.A, np.zeros((2, 2)), m.GQGT)
    np.testing.assert_allclose(f.P, bpf_riccati_step(P, M, m.dt).P_next, rtol=1e-12)


def test_global_riccati_in_the_loop_flags_breakdown_and_never_returns_nan():
    from fir_gym.scenarios.paper002 import simulate

    mc = simulate(6, seed=11)
    m = van_der_pol_continuous_model(mc.params)
    opts = {"x0": [1.0, 1.0], "P0": 5 * np.eye(2), "nan_policy": "skip"}
    glob = BlockPulseKalmanFilter(m, riccati="global", **opts)
    rest = BlockPulseKalmanFilter(m, **opts)
    agree_before = []
    for k in range(mc.measurements.shape[1]):
        xg, xr = glob.step(mc.measurements[:, k]), rest.step(mc.measurements[:, k])
        assert np.all(np.isfinite(xg)) and np.all(np.isfinite(glob.P))
        broken = glob.last_info.get("riccati_breakdown", np.zeros(6, bool))
        agree_before.append(np.max(np.abs(xg - xr)[~broken], initial=0.0))
    assert np.all(glob.diverged) and np.all(glob.last_info["riccati_breakdown"])
    assert not np.any(rest.diverged)
    assert max(agree_before) < 1e-6


def test_contract_errors_and_registry():
    with pytest.raises(TypeError, match="ContinuousModel"):
        BlockPulseKalmanFilter(LinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2), R=1.0))
    no_factor = ContinuousModel(a=lambda x, u: -x, h=lambda x: x[..., :1], Q=1.0, R=1.0, dt=0.1,
                                G=np.ones((2, 1)))
    with pytest.raises(ValueError, match="factorisation"):
        BlockPulseKalmanFilter(no_factor)
    with pytest.raises(ValueError, match="riccati must be one of"):
        BlockPulseKalmanFilter(carrier_model(), riccati="local")
    assert estimator_class("bpf-kf") is BlockPulseKalmanFilter


def test_a_singular_system_of_a_batch_gets_nan_and_the_others_their_own_result():
    """The paper-literal global recursion on a batch whose second backward transition is
    exactly singular (ψ = 0) with one shared ``ξ0``: that system's ``P`` is NaN and its
    condition infinite (the estimator flags it), the first system's result is what it gets
    alone — ``M = 0`` leaves ``P`` at ``P0`` (mutation testing found the batched fallback of
    the singular solve untested)."""
    from fir_gym.estimators.bpf import bpf_riccati_global_step
    P0 = np.array([[2.0, 0.3], [0.3, 1.0]])
    xi0 = np.vstack([np.eye(2), P0])
    psi = np.stack([np.eye(4), np.zeros((4, 4))])
    _, step = bpf_riccati_global_step(psi, np.zeros((4, 4)), xi0, 0.1)
    _, alone = bpf_riccati_global_step(psi[0], np.zeros((4, 4)), xi0, 0.1)
    for P, P1 in ((step.P_bar, alone.P_bar), (step.P_next, alone.P_next)):
        np.testing.assert_allclose(P[0], P1, rtol=1e-15)
        np.testing.assert_allclose(P1, P0, rtol=1e-15)
        assert np.isnan(P[1]).all()
    assert np.isfinite(step.condition[0]) and step.condition[1] == np.inf
