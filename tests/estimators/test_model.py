"""The model contract: construction, validation, batching, Jacobians."""

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fir_gym.estimators import LinearModel, StateSpaceModel, TimeVaryingLinearModel


class Pendulum:
    """A small picklable nonlinear model with analytic Jacobians."""

    dt = 0.05

    def f(self, x, u):
        th, om = x[..., 0], x[..., 1]
        return np.stack([th + self.dt * om, om + self.dt * (-9.8 * np.sin(th) + u[..., 0])], -1)

    def F(self, x, u):
        J = np.zeros(x.shape[:-1] + (2, 2))
        J[..., 0, 0] = 1.0
        J[..., 0, 1] = self.dt
        J[..., 1, 0] = -self.dt * 9.8 * np.cos(x[..., 0])
        J[..., 1, 1] = 1.0
        return J

    def h(self, x):
        return np.stack([np.sin(x[..., 0]), x[..., 0] * x[..., 1]], -1)

    def H(self, x):
        J = np.zeros(x.shape[:-1] + (2, 2))
        J[..., 0, 0] = np.cos(x[..., 0])
        J[..., 1, 0] = x[..., 1]
        J[..., 1, 1] = x[..., 0]
        return J


def pendulum_model(analytic=True):
    p = Pendulum()
    return StateSpaceModel(f=p.f, h=p.h, F=p.F if analytic else None, H=p.H if analytic else None,
                           Q=np.diag([1e-4, 1e-3]), R=np.eye(2) * 0.01, dt=p.dt, n_u=1)


def test_sizes_are_inferred():
    m = pendulum_model()
    assert (m.n_x, m.n_y, m.n_u, m.n_w) == (2, 2, 1, 2)
    g = StateSpaceModel(f=Pendulum().f, h=Pendulum().h, G=[[0.0], [1.0]], Q=0.3, R=np.eye(2),
                        n_u=1)
    assert (g.n_x, g.n_w) == (2, 1)
    np.testing.assert_allclose(g.GQGT, [[0, 0], [0, 0.3]])
    assert m.has_analytic_jacobians == (True, True)
    assert pendulum_model(False).has_analytic_jacobians == (False, False)


@settings(max_examples=40, deadline=None)
@given(x=arrays(np.float64, (2,), elements=st.floats(-3, 3)),
       u=arrays(np.float64, (1,), elements=st.floats(-2, 2)))
def test_finite_difference_fallback_matches_analytic_jacobians(x, u):
    analytic, fallback = pendulum_model(True), pendulum_model(False)
    np.testing.assert_allclose(fallback.F(x, u), analytic.F(x, u), rtol=0, atol=1e-9)
    np.testing.assert_allclose(fallback.H(x), analytic.H(x), rtol=0, atol=1e-9)


def test_batched_calls_equal_looped_calls_including_fallback():
    rng = np.random.default_rng(0)
    X, U = rng.standard_normal((7, 2)), rng.standard_normal((7, 1))
    for m in (pendulum_model(True), pendulum_model(False)):
        for fun, args in ((m.f, (X, U)), (m.F, (X, U)), (m.h, (X,)), (m.H, (X,))):
            looped = np.array([fun(*(a[i] for a in args)) for i in range(7)])
            np.testing.assert_allclose(fun(*args), looped, rtol=0, atol=1e-15)


def test_missing_input_means_zero_input():
    m = pendulum_model()
    x = np.array([0.3, -0.1])
    np.testing.assert_array_equal(m.f(x), m.f(x, [0.0]))
    X = np.tile(x, (3, 1))
    np.testing.assert_array_equal(m.f(X), m.f(X, np.zeros((3, 1))))


@pytest.mark.parametrize("call", ["f", "F", "h", "H"])
def test_wrongly_shaped_state_raises_naming_x(call):
    m = pendulum_model()
    with pytest.raises(ValueError, match="x must have shape"):
        getattr(m, call)(np.zeros(3))
    with pytest.raises(ValueError, match="x must have shape"):
        getattr(m, call)(np.zeros((2, 2, 2)))


def test_wrongly_shaped_input_raises_naming_u():
    with pytest.raises(ValueError, match="u must have shape"):
        pendulum_model().f(np.zeros(2), np.zeros(2))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"Q": [[1.0, 0.5], [0.4, 1.0]]}, "Q must be symmetric"),
     ({"Q": [[1.0, 2.0], [2.0, 1.0]]}, "Q must be positive semi-definite"),
     ({"R": [[1.0, 0.0], [0.0, -1e-3]]}, "R must be positive semi-definite"),
     ({"R": [[np.nan, 0.0], [0.0, 1.0]]}, "R must be finite"),
     ({"G": np.ones((2, 3))}, "G must have shape"),
     ({"dt": 0.0}, "dt must be"),
     ({"n_u": -1}, "n_u must be"),
     ({"f": "not callable"}, "f must be callable")],
)
def test_invalid_construction_raises_naming_the_argument(kwargs, match):
    p = Pendulum()
    base = {"f": p.f, "h": p.h, "Q": np.eye(2), "R": np.eye(2), "n_u": 1}
    with pytest.raises((ValueError, TypeError), match=match):
        StateSpaceModel(**{**base, **kwargs})


def test_semidefinite_covariances_are_accepted():
    m = StateSpaceModel(f=Pendulum().f, h=Pendulum().h, Q=np.zeros((2, 2)),
                        R=np.diag([1.0, 0.0]), n_u=1)
    assert np.all(m.Q == 0)


def test_matrices_are_read_only():
    m = pendulum_model()
    with pytest.raises(ValueError):
        m.Q[0, 0] = 5.0


def test_replace_and_pickle():
    m = pendulum_model()
    m2 = m.replace(Q=np.eye(2))
    np.testing.assert_array_equal(m2.Q, np.eye(2))
    np.testing.assert_array_equal(m.Q, np.diag([1e-4, 1e-3]))
    with pytest.raises(ValueError, match="unknown argument"):
        m.replace(nonsense=1)
    x = np.array([0.2, 0.1])
    clone = pickle.loads(pickle.dumps(m))
    np.testing.assert_array_equal(clone.f(x, [0.5]), m.f(x, [0.5]))


def test_linear_model():
    rng = np.random.default_rng(1)
    A, B, C = rng.standard_normal((3, 3)), rng.standard_normal((3, 2)), rng.standard_normal((1, 3))
    m = LinearModel(A=A, B=B, C=C, Q=np.eye(3), R=0.5, dt=0.1)
    assert (m.n_x, m.n_u, m.n_y, m.is_linear) == (3, 2, 1, True)
    X, U = rng.standard_normal((4, 3)), rng.standard_normal((4, 2))
    np.testing.assert_allclose(m.f(X, U), X @ A.T + U @ B.T, rtol=1e-14)
    np.testing.assert_allclose(m.h(X), X @ C.T, rtol=1e-14)
    assert m.F(X, U).shape == (4, 3, 3) and np.all(m.F(X, U) == A)
    np.testing.assert_array_equal(m.H(X[0]), C)
    mats = m.matrices(17)
    np.testing.assert_array_equal(mats.A, A)
    clone = pickle.loads(pickle.dumps(m))
    np.testing.assert_array_equal(clone.f(X, U), m.f(X, U))
    assert LinearModel(A=A, C=C, Q=np.eye(3), R=1.0).n_u == 0
    with pytest.raises(ValueError, match="Q must be 3x3"):
        LinearModel(A=A, C=C, Q=np.eye(2), R=1.0)
    with pytest.raises(ValueError, match="R must be 1x1"):
        LinearModel(A=A, C=C, Q=np.eye(3), R=np.eye(2))
    with pytest.raises(ValueError, match="A must be square"):
        LinearModel(A=np.ones((2, 3)), C=C, Q=np.eye(3), R=1.0)


def test_time_varying_linear_model():
    m = TimeVaryingLinearModel(A=lambda k: np.array([[1.0, 0.1 * k], [0.0, 1.0]]),
                               C=[[1.0, 0.0]], Q=np.eye(2), R=lambda k: 1.0 + k, dt=0.5)
    mats = m.matrices(3)
    np.testing.assert_array_equal(mats.A, [[1.0, 0.1 * 3], [0.0, 1.0]])
    assert mats.R[0, 0] == 4.0 and mats.B.shape == (2, 0)
    with pytest.raises(TypeError, match="matrices"):
        m.f(np.zeros(2))
    bad = TimeVaryingLinearModel(A=np.eye(2), C=[[1.0, 0.0]], Q=np.eye(2),
                                 R=lambda k: 1.0 if k < 2 else -1.0)
    with pytest.raises(ValueError, match=r"R\(2\) must be positive semi-definite"):
        bad.matrices(2)


def test_linearize_fused_and_fallback_agree():
    p = Pendulum()
    calls = []

    def fused(x, u):
        calls.append(1)
        return p.f(x, u), p.F(x, u)

    plain = pendulum_model()
    withfF = StateSpaceModel(f=p.f, h=p.h, F=p.F, H=p.H, fF=fused, Q=np.eye(2), R=np.eye(2),
                             n_u=1)
    X, U = np.random.default_rng(0).normal(size=(3, 2)), np.ones((3, 1))
    for model in (plain, withfF):
        fx, Fx = model.linearize(X, U)
        np.testing.assert_array_equal(fx, p.f(X, U))
        np.testing.assert_array_equal(Fx, p.F(X, U))
    assert calls == [1]
    assert withfF.replace(Q=2 * np.eye(2))._fF is fused
    with pytest.raises(TypeError, match="fF must be callable"):
        StateSpaceModel(f=p.f, h=p.h, fF=3, Q=np.eye(2), R=np.eye(2))
