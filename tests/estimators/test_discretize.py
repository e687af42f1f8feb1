"""Exact discretisation against independent computations."""

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from fir_gym.estimators import discretize_lti, linear_model_from_continuous
from fir_gym.estimators.discretize import integrated_noise


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


# ------------------------------------------------------------------ integrated_noise
@settings(max_examples=20, deadline=None)
@given(a=st.floats(-5.0, 5.0), g=st.floats(0.1, 3.0), q=st.floats(0.01, 10.0),
       dt=st.floats(0.01, 1.0))
def test_integrated_noise_of_a_scalar_ornstein_uhlenbeck(a, g, q, dt):
    """dx = a x dt + g dw: Var x(dt) = g² q (e^{2a dt} − 1) / (2a), g² q dt at a = 0."""
    x = 2 * a * dt                 # (e^x − 1)/x, 1 at x = 0: also where 2 a dt underflows
    expected = g * g * q * dt * (np.expm1(x) / x if x != 0 else 1.0)
    np.testing.assert_allclose(integrated_noise([[a]], dt, G=[[g]], Q=q), [[expected]],
                               rtol=1e-10)


@pytest.mark.parametrize("dt", [0.01, 0.1, 1.0, 3.0])
def test_integrated_noise_of_a_double_integrator(dt):
    """Velocity driven by white noise of density q: q [[dt³/3, dt²/2], [dt²/2, dt]]."""
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    expected = 0.7 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    np.testing.assert_allclose(integrated_noise(A, dt, G=[[0.0], [1.0]], Q=0.7), expected,
                               rtol=1e-12, atol=1e-15)


def test_integrated_noise_of_a_harmonic_oscillator():
    """ẍ = −ω² x + w: the closed form of ∫ e^{As} g q gᵀ e^{Aᵀs} ds with e^{As} a rotation."""
    w, q, dt = 2.0, 0.3, 0.7
    A = np.array([[0.0, 1.0], [-w * w, 0.0]])
    t = 2.0 * w * dt
    expected = q * np.array([
        [(t - np.sin(t)) / (4 * w**3), (1 - np.cos(t)) / (4 * w**2)],
        [(1 - np.cos(t)) / (4 * w**2), (t + np.sin(t)) / (4 * w)]])
    np.testing.assert_allclose(integrated_noise(A, dt, G=[[0.0], [1.0]], Q=q), expected,
                               rtol=1e-11)


def test_integrated_noise_against_a_monte_carlo_of_the_integrated_noise():
    """The covariance at dt of Euler–Maruyama paths of dx = A x dt + G dw from 0 (2000
    substeps: its bias is O(dt/2000), far below the 5σ sampling band of 20 000 paths)."""
    A = np.array([[0.0, 1.0], [-1.0, 1.0]])          # Van der Pol's linearisation at 0
    G = np.array([[1.0], [1.0]])
    q, dt, steps, n = 5.0, 0.1, 2000, 20_000
    rng = np.random.default_rng(0)
    x = np.zeros((n, 2))
    tau = dt / steps
    for _ in range(steps):
        x = x + tau * x @ A.T + np.sqrt(q * tau) * rng.standard_normal((n, 1)) @ G.T
    cov = np.cov(x.T)
    Q_d = integrated_noise(A, dt, G=G, Q=q)
    sd = np.sqrt((np.outer(np.diag(Q_d), np.diag(Q_d)) + Q_d**2) / n)
    assert np.all(np.abs(cov - Q_d) < 5 * sd)
    # and its small eigenvalue (zero for the first-order G q Gᵀ dt): along [1, −1]
    u = np.array([1.0, -1.0]) / np.sqrt(2.0)
    assert abs(u @ cov @ u - u @ Q_d @ u) < 5 * np.sqrt(2.0 / n) * (u @ Q_d @ u)
    assert u @ Q_d @ u > 0


def test_integrated_noise_of_a_stack_is_each_matrix():
    rng = np.random.default_rng(4)
    As = rng.standard_normal((5, 3, 3))
    G = rng.standard_normal((3, 2))
    stack = integrated_noise(As, 0.2, G=G, Q=[0.5, 2.0])
    assert stack.shape == (5, 3, 3)
    for A, Q_d in zip(As, stack, strict=True):
        np.testing.assert_allclose(Q_d, discretize_lti(A, 0.2, G=G, Q=np.diag([0.5, 2.0]))[2],
                                   rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(integrated_noise(As.reshape(5, 1, 3, 3), 0.2, G=G,
                                                Q=[0.5, 2.0])[:, 0], stack)


@pytest.mark.parametrize("q", [1e-300, 1e-30, 1e30, 1e300])
def test_integrated_noise_is_linear_in_the_density_at_any_scale(q):
    """∫ e^{As} G Q Gᵀ e^{Aᵀs} ds is linear in Q: no overflow or underflow at extreme ones."""
    A = np.array([[0.0, 1.0], [-1.0, 1.0]])
    G = np.ones((2, 1))
    np.testing.assert_allclose(integrated_noise(A, 0.1, G=G, Q=q),
                               q * integrated_noise(A, 0.1, G=G, Q=1.0), rtol=1e-12)
    assert not np.any(integrated_noise(A, 0.1, G=G, Q=0.0))


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"A": np.ones((2, 3))}, ValueError, "A must be square"),
    ({"A": np.ones(3)}, ValueError, "A must be square"),
    ({"A": [[np.nan]]}, ValueError, "A must be finite"),
    ({"A": [[True]]}, TypeError, "A"),
    ({"dt": 0.0}, ValueError, "dt must be"),
    ({"Q": -1.0}, ValueError, "Q must be positive semi-definite"),
    ({"A": np.eye(2), "Q": np.eye(3)}, ValueError, "Q must be 2x2"),
    ({"A": np.eye(2), "G": np.ones((2, 2))}, ValueError, "G must have shape"),
])
def test_integrated_noise_bad_arguments(kwargs, error, match):
    args = {"A": [[0.0]], "dt": 0.1, "Q": 1.0}
    with pytest.raises(error, match=match):
        integrated_noise(**{**args, **kwargs})
