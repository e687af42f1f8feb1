"""Exact discretisation against independent computations."""

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from fir_gym.estimators import discretize_lti, linear_model_from_continuous


def random_system(seed, n=3, m=2, q=2):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    B = rng.standard_normal((n, m))
    G = rng.standard_normal((n, q))
    L = rng.standard_normal((q, q))
    return A, B, G, L @ L.T


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), dt=st.floats(0.01, 1.0))
def test_against_scipy_cont2discrete_and_quadrature(seed, dt):
    A, B, G, Q = random_system(seed)
    A_d, B_d, Q_d = discretize_lti(A, dt, B=B, G=G, Q=Q)
    ref = scipy.signal.cont2discrete((A, B, np.eye(3), np.zeros((3, 2))), dt, method="zoh")
    np.testing.assert_allclose(A_d, ref[0], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(B_d, ref[1], rtol=1e-10, atol=1e-12)
    Q_quad, _ = scipy.integrate.quad_vec(
        lambda s: scipy.linalg.expm(A * s) @ G @ Q @ G.T @ scipy.linalg.expm(A * s).T,
        0.0, dt, epsabs=1e-13, epsrel=1e-11)
    np.testing.assert_allclose(Q_d, Q_quad, rtol=1e-8, atol=1e-12)
    np.testing.assert_array_equal(Q_d, Q_d.T)


def test_stationary_covariance_is_preserved():
    A = np.array([[0.0, 1.0], [-2.0, -0.5]])
    G = np.array([[0.0], [1.0]])
    P = scipy.linalg.solve_continuous_lyapunov(A, -G @ G.T * 0.7)
    A_d, _, Q_d = discretize_lti(A, 0.3, G=G, Q=0.7)
    np.testing.assert_allclose(A_d @ P @ A_d.T + Q_d, P, rtol=1e-12, atol=1e-14)


def test_linear_model_from_continuous():
    A, B, G, Q = random_system(3)
    m = linear_model_from_continuous(A=A, B=B, G=G, Q=Q, C=np.eye(3)[:1], R=0.2, dt=0.1)
    A_d, B_d, Q_d = discretize_lti(A, 0.1, B=B, G=G, Q=Q)
    np.testing.assert_array_equal(m.A, A_d)
    np.testing.assert_array_equal(m.B, B_d)
    np.testing.assert_allclose(m.Q, Q_d)
    assert m.n_w == 3 and m.dt == 0.1 and m.R[0, 0] == 0.2


def test_no_noise_and_no_input():
    A_d, B_d, Q_d = discretize_lti(np.zeros((2, 2)), 1.0)
    np.testing.assert_array_equal(A_d, np.eye(2))
    assert B_d.shape == (2, 0) and not np.any(Q_d)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"A": np.ones((2, 3)), "dt": 1.0}, "A must be square"),
    ({"A": np.eye(2), "dt": -1.0}, "dt must be"),
    ({"A": np.eye(2), "dt": 1.0, "Q": -np.eye(2)}, "Q must be positive semi-definite"),
    ({"A": np.eye(2), "dt": 1.0, "Q": np.eye(3)}, "Q must be 2x2"),
])
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        discretize_lti(**kwargs)
