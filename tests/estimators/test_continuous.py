"""ContinuousModel: validation, batching, Jacobians, the factorisation and the sampled view."""

from __future__ import annotations

import numpy as np
import pytest
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
    np.testing.assert_allclose(d.Q, 0.035 * 0.1)
    np.testing.assert_allclose(d.R, 1.0 / 0.1)
    assert d.dt == 0.1 and d.n_x == 2
