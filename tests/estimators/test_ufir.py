"""UFIRFilter (Shmaliy): OLS over the window = FIRFilter with Q = 0, R = I; iterative = batch."""

from __future__ import annotations

import numpy as np
import pytest

from fir_gym.estimators import LinearModel, TimeVaryingLinearModel
from fir_gym.estimators.fir import FIRFilter
from fir_gym.estimators.registry import make_estimator
from fir_gym.estimators.ufir import UFIRFilter


def lti(seed: int = 0, singular: bool = False) -> LinearModel:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(3, 3))
    A *= 1.05 / np.max(np.abs(np.linalg.eigvals(A)))
    if singular:
        A[:, 2] = 0.0
        A[2, :] = [0.3, 0.2, 0.0]
    return LinearModel(A=A, C=rng.normal(size=(2, 3)), B=rng.normal(size=(3, 1)),
                       Q=0.3 * np.eye(3), R=np.diag([0.5, 2.0]))


def ltv(seed: int = 1) -> TimeVaryingLinearModel:
    """A, C and B all vary with k (a constant C or B would hide an index slip)."""
    m = lti(seed)
    A, C, B = np.asarray(m.A), np.asarray(m.C), np.asarray(m.B)
    return TimeVaryingLinearModel(A=lambda k: A * (1 + 0.1 * np.sin(k)),
                                  C=lambda k: C * (1 + 0.2 * np.cos(k)),
                                  B=lambda k: B * (1 + 0.3 * np.sin(2 * k)), Q=m.Q, R=m.R)


def stream(f, steps: int = 25, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.array([f.step(rng.normal(size=2), rng.normal(size=1) if k else None)
                     for k in range(steps)])


@pytest.mark.parametrize("form", ["filter", "predictor"])
@pytest.mark.parametrize("model", [lti(), ltv()], ids=["lti", "ltv"])
def test_batch_ufir_equals_fir_filter_with_zero_Q_and_unit_R(model, form: str) -> None:
    oracle_model = model.replace(Q=np.zeros((3, 3)), R=np.eye(2))
    a = stream(UFIRFilter(model, horizon=5, form=form))
    b = stream(FIRFilter(oracle_model, horizon=5, form=form))
    assert np.abs(a - b).max() <= 1e-10 * max(1.0, np.abs(b).max())


@pytest.mark.parametrize("form", ["filter", "predictor"])
@pytest.mark.parametrize("model", [lti(), ltv(), lti(2, singular=True)],
                         ids=["lti", "ltv", "singular-A"])
def test_iterative_form_equals_batch_form(model, form: str) -> None:
    a = UFIRFilter(model, horizon=6, form=form)
    b = UFIRFilter(model, horizon=6, form=form, method="iterative")
    ea, eb = stream(a), stream(b)
    assert np.abs(ea - eb).max() <= 1e-10 * max(1.0, np.abs(ea).max())
    assert np.allclose(a.P, b.P, rtol=1e-9, atol=1e-12)


def test_ignores_noise_statistics_and_is_exact_on_noise_free_data() -> None:
    m = lti(4)
    other = m.replace(Q=5.0 * np.eye(3), R=np.diag([0.01, 9.0]))
    assert np.allclose(stream(UFIRFilter(m, horizon=5)), stream(UFIRFilter(other, horizon=5)),
                       rtol=0, atol=1e-12)
    rng = np.random.default_rng(0)
    x, f = rng.normal(size=3) * 4.0, UFIRFilter(m, horizon=5, method="iterative")
    for k in range(15):
        u = rng.normal(size=1)
        if k:
            x = m.A @ x + m.B @ u
        est = f.step(m.C @ x, u if k else None)
    assert np.abs(est - x).max() <= 1e-9 * max(1.0, np.abs(x).max())


def test_covariance_is_noise_power_gain_times_measurement_variance() -> None:
    m = lti(5).replace(R=0.7 * np.eye(2))
    u = UFIRFilter(m, horizon=5)
    f = FIRFilter(m.replace(Q=np.zeros((3, 3))), horizon=5)    # R = r I, Q = 0: same filter
    stream(u), stream(f)
    assert np.allclose(u.P, f.P, rtol=1e-9)
    assert isinstance(make_estimator("ufir", m, horizon=5), UFIRFilter)
    with pytest.raises(ValueError, match="method"):
        UFIRFilter(m, horizon=5, method="kalman")


@pytest.mark.parametrize("method", ["batch", "iterative"])
def test_batch_in_lockstep_equals_separate_filters(method: str) -> None:
    model = ltv()
    rng = np.random.default_rng(2)
    Y, U = rng.normal(size=(15, 3, 2)), rng.normal(size=(15, 3, 1))
    together = UFIRFilter(model, horizon=5, method=method)
    out = np.array([together.step(Y[k], U[k - 1] if k else None) for k in range(15)])
    for b in range(3):
        alone = UFIRFilter(model, horizon=5, method=method)
        sep = np.array([alone.step(Y[k, b], U[k - 1, b] if k else None) for k in range(15)])
        assert np.abs(out[:, b] - sep).max() <= 1e-12 * max(1.0, np.abs(sep).max())


@pytest.mark.parametrize(("form", "target"), [("filter", 4), ("predictor", 5), ("smoother", 0)])
def test_the_batch_gain_recovers_the_targets_state_from_noise_free_data(form, target) -> None:
    """Unbiasedness, the UFIR's defining property: on noise-free data of the window (no
    input), ``S Y`` is exactly the state at the form's target — the last sample (filter),
    one past it (predictor), the first (smoother)."""
    from fir_gym.estimators.fir_gains import make_window
    from fir_gym.estimators.ufir import ufir_gain
    m = lti(4)
    A, C = np.asarray(m.A), np.asarray(m.C)
    L = 5
    x = [np.array([1.0, -0.5, 2.0])]
    for _ in range(L):
        x.append(A @ x[-1])
    Y = np.concatenate([C @ x[t] for t in range(L)])
    S = ufir_gain(make_window(A, C, np.zeros((3, 3)), np.eye(2), L), form).S
    np.testing.assert_allclose(S @ Y, x[target], rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("form", ["filter", "predictor"])
def test_iterative_form_equals_batch_form_with_missing_measurements(form: str) -> None:
    """A window with a missing measurement (``nan_policy="skip"``) leaves the iterative
    recursion for the masked batch estimate: both methods give the same estimates and
    covariances through the gaps (mutation testing found the switch untested)."""
    model = lti(6)
    a = UFIRFilter(model, horizon=6, form=form, nan_policy="skip")
    b = UFIRFilter(model, horizon=6, form=form, method="iterative", nan_policy="skip")
    rng = np.random.default_rng(9)
    for k in range(30):
        y = rng.normal(size=2)
        if k in (9, 10, 17):
            y[k % 2] = np.nan
        u = rng.normal(size=1) if k else None
        ea, eb = a.step(y, u), b.step(y, u)
        np.testing.assert_allclose(eb, ea, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(b.P, a.P, rtol=1e-9, atol=1e-12)


def test_iterative_form_at_the_shortest_horizon() -> None:
    """At the shortest horizon (the observability index, 3 for a chain of integrators seen
    at its first state) the window determines the state only with its last sample: the
    iterative recursion's start-up batch spans the whole window, and the estimate is the
    batch one and exact on noise-free data."""
    A = np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.1], [0.0, 0.0, 1.0]])
    model = LinearModel(A=A, C=[[1.0, 0.0, 0.0]], Q=np.eye(3), R=[[1.0]])
    a = UFIRFilter(model, horizon=3)
    b = UFIRFilter(model, horizon=3, method="iterative")
    x = np.array([0.5, -1.0, 2.0])
    for _ in range(8):
        ea, eb = a.step(x[:1]), b.step(x[:1])
        np.testing.assert_allclose(eb, ea, rtol=1e-10, atol=1e-12)
        x = A @ x
    np.testing.assert_allclose(eb, np.linalg.matrix_power(A, -1) @ x, rtol=1e-9)


def test_the_covariance_scale_of_a_time_varying_model_is_its_first_steps_variance() -> None:
    """``P`` = the noise power gain (the FIR filter's ``P`` with ``Q = 0``, ``R = I``) times
    ``σ² = mean diag R(0)`` (the class docstring), also when ``R`` varies with ``k``."""
    m = lti(1)
    A, C = np.asarray(m.A), np.asarray(m.C)
    varying = TimeVaryingLinearModel(A=lambda k: A * (1 + 0.1 * np.sin(k)),
                                     C=lambda k: C * (1 + 0.2 * np.cos(k)), B=m.B, Q=m.Q,
                                     R=lambda k: np.diag([0.5, 2.0]) * (1.0 + 0.5 * k))
    u = UFIRFilter(varying, horizon=5)
    f = FIRFilter(varying.replace(Q=np.zeros((3, 3)), R=np.eye(2)), horizon=5)
    stream(u), stream(f)
    assert u.noise_scale == pytest.approx(1.25)
    np.testing.assert_allclose(u.P, 1.25 * f.P, rtol=1e-9)
