"""ContinuousModel: validation, batching, Jacobians, the factorisation and the sampled view."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from fir_gym.envs.van_der_pol import van_der_pol_continuous_model
from fir_gym.estimators import StateSpaceModel
from fir_gym.estimators.continuous import ContinuousModel

VDP = {"epsilon": 1.0, "u_max": 5.0, "Q": 5.0, "R": 5.0, "h": 0.1}
A = np.array([[0.0, 1.0], [-0.36, -0.06]])
C = np.array([[1.0, 0.0]])
G = np.array([[0.6], [-0.036]])


def carrier(**kw):
    return ContinuousModel.linear(A=A, C=C, G=G, Q=0.035, R=1.0, dt=0.1, **kw)


def test_linear_model_callables_and_shapes():
    m = carrier(B=[[0.0], [1.0]])
    x = np.array([[1.0, 2.0], [-0.5, 0.3], [0.0, 1.0]])
    u = np.array([[0.5], [0.0], [-1.0]])
    np.testing.assert_allclose(m.a(x, u), x @ A.T + u @ np.array([[0.0, 1.0]]))
    np.testing.assert_allclose(m.a(x[0], u[0]), m.a(x, u)[0])
    assert m.J(x).shape == (3, 2, 2) and m.H(x).shape == (3, 1, 2)
    np.testing.assert_allclose(m.A_of_x(x[1]), A)
    np.testing.assert_allclose(m.h(x), x[:, :1])
    np.testing.assert_allclose(m.R_inv @ m.R, np.eye(1))
    np.testing.assert_allclose(m.GQGT, 0.035 * G @ G.T)
    assert (m.n_x, m.n_y, m.n_u, m.n_w) == (2, 1, 1, 1) and m.has_factorisation


@pytest.mark.parametrize("kwargs, error, match", [
    ({"a": 3}, TypeError, "a must be callable"),
    ({"A_of_x": "no"}, TypeError, "A_of_x must be callable"),
    ({"R": 0.0}, ValueError, "R must be positive definite"),
    ({"Q": -1.0}, ValueError, "Q must be positive semi-definite"),
    ({"dt": 0.0}, ValueError, "dt must be a positive"),
    ({"G": np.ones((2, 2))}, ValueError, "G must have shape"),
    ({"n_u": -1}, ValueError, "n_u must be"),
])
def test_bad_arguments_name_the_argument(kwargs, error, match):
    args = {"a": lambda x, u: x, "h": lambda x: x[..., :1], "Q": 1.0, "R": 1.0, "dt": 0.1,
            "G": np.ones((2, 1))}
    with pytest.raises(error, match=match):
        ContinuousModel(**{**args, **kwargs})


def test_bad_state_and_input_shapes_raise():
    m = carrier()
    with pytest.raises(ValueError, match="x must have shape"):
        m.a(np.zeros(3))
    with pytest.raises(ValueError, match="u must have shape"):
        carrier(B=[[0.0], [1.0]]).a(np.zeros(2), np.zeros(2))
    no_factor = ContinuousModel(a=lambda x, u: x, h=lambda x: x[..., :1], Q=1.0, R=1.0, dt=0.1,
                                G=np.ones((2, 1)))
    assert not no_factor.has_factorisation
    with pytest.raises(TypeError, match="factorisation"):
        no_factor.A_of_x(np.zeros(2))


@settings(max_examples=25, deadline=None)
@given(st.floats(-4, 4), st.floats(-4, 4))
def test_van_der_pol_factorisation_and_jacobian(x1, x2):
    """a(x, 0) = A(x) x (paper 002, eq 2.2) and the analytic J matches central differences."""
    m = van_der_pol_continuous_model(VDP)
    x = np.array([x1, x2])
    np.testing.assert_allclose(m.a(x), m.A_of_x(x) @ x, atol=1e-12)
    fd = ContinuousModel(a=m.a, h=m.h, Q=m.Q, R=m.R, dt=m.dt, G=m.G, n_u=1)
    np.testing.assert_allclose(fd.J(x, [0.3]), m.J(x, [0.3]), rtol=1e-7, atol=1e-7)


def test_sampled_view_is_the_exact_flow_to_rk4_accuracy():
    m = carrier()
    d = m.sampled(substeps=10)
    assert isinstance(d, StateSpaceModel)
    x = np.array([[1.0, -0.5], [0.2, 0.4]])
    exact = x @ scipy.linalg.expm(A * 0.1).T
    np.testing.assert_allclose(d.f(x), exact, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.R, 1.0 / 0.1)
    assert d.dt == 0.1 and d.n_x == 2


def quadrature_noise(J, G, Q, dt):
    """∫₀^dt e^{J s} G Q Gᵀ e^{Jᵀ s} ds by adaptive quadrature (not Van Loan's exponential)."""
    return scipy.integrate.quad_vec(
        lambda s: scipy.linalg.expm(J * s) @ G @ np.atleast_2d(Q) @ G.T
        @ scipy.linalg.expm(J * s).T, 0.0, dt, epsabs=1e-14, epsrel=1e-11)[0]


def test_sampled_noise_of_a_linear_model_is_the_integrated_noise():
    """Exact for a linear model wherever it is linearised: ∫ e^{As} G Q Gᵀ e^{Aᵀs} ds, full
    rank (G Q Gᵀ dt, the first-order term, is rank one here), with G = I."""
    m = carrier()
    expected = quadrature_noise(A, G, 0.035, 0.1)
    for at in (None, [3.0, -1.0], np.ones((4, 2))):
        d = m.sampled(at=at)
        np.testing.assert_allclose(d.Q, expected, rtol=1e-9, atol=1e-15)
        np.testing.assert_array_equal(d.G, np.eye(2))
        assert d.n_w == 2
    assert np.linalg.matrix_rank(expected) == 2


def test_sampled_noise_of_a_nonlinear_model_is_taken_at_its_linearisation():
    """Van der Pol: at the origin by default; at given states, the mean of each state's
    integral of its own Jacobian (quadrature of the closed-form J = [[0, 1], [−1 − 2ε x1 x2,
    ε (1 − x1²)]])."""
    m = van_der_pol_continuous_model(VDP)
    g = np.ones((2, 1))

    def J(x1, x2):
        return np.array([[0.0, 1.0], [-1.0 - 2.0 * x1 * x2, 1.0 - x1 * x1]])

    np.testing.assert_allclose(m.sampled().Q, quadrature_noise(J(0, 0), g, 5.0, 0.1),
                               rtol=1e-9)
    states = np.array([[2.0, 0.0], [-1.0, 2.5], [0.5, -1.0]])
    expected = np.mean([quadrature_noise(J(*x), g, 5.0, 0.1) for x in states], axis=0)
    np.testing.assert_allclose(m.sampled(at=states).Q, expected, rtol=1e-9)
    np.testing.assert_allclose(m.integrated_noise(states)[1],
                               quadrature_noise(J(*states[1]), g, 5.0, 0.1), rtol=1e-9)
    assert m.integrated_noise(states).shape == (3, 2, 2)
    with pytest.raises(ValueError, match="at must have shape"):
        m.sampled(at=np.zeros(3))
