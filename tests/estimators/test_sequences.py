"""Whole sequences (``Estimator.filter``) and the innovations' log-likelihood.

Oracles: pykalman's robot data set (its shipped reference filtered means and covariances,
the log-likelihood of its EM run's first iteration, and pykalman's own ``loglikelihood``),
an independent brute-force Gaussian density of the stacked measurements, and the filter's
own ``step`` loop (the sequence API must equal it bit for bit).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats
from compiled_paths import needs_twins, numpy_path, on_path
from plant_cases import applicable, kalman_filters
from sequence_data import pykalman_robot, robot, tracking

from fir_gym.estimators import (
    ExtendedFIRFilter,
    FIRFilter,
    KalmanFilter,
    LinearModel,
    RecursiveFIRFilter,
    UFIRFilter,
    UnscentedKalmanFilter,
)

pykalman = pytest.importorskip("pykalman")

KALMAN = kalman_filters()
FIR = [FIRFilter, UFIRFilter, RecursiveFIRFilter, ExtendedFIRFilter]


@pytest.mark.parametrize("cls", KALMAN)
def test_filter_equals_pykalmans_reference_means_covariances_and_loglikelihood(cls):
    model, d, ys, us = robot()
    assert np.ma.count_masked(ys) > 0                  # the data set has missing entries
    for path in ("compiled", "numpy"):
        flt = cls(model, x0=d["initial_state_mean"], P0=d["initial_state_covariance"])
        with on_path(path):
            res = flt.filter(ys, us)
        tol = 1e-6 if cls is UnscentedKalmanFilter else 1e-9      # the UT's round-off
        np.testing.assert_allclose(res.x, d["filtered_state_means"], rtol=tol, atol=tol)
        np.testing.assert_allclose(res.P, d["filtered_state_covariances"], rtol=tol, atol=tol)
        pk = pykalman_robot(d)
        assert res.log_likelihood == pytest.approx(pk.loglikelihood(d["observations"]),
                                                   rel=1e-12 if tol < 1e-6 else 1e-10)
        assert res.log_likelihoods.shape == (501,) and res.nis.shape == (501,)
        masked = np.ma.getmaskarray(ys).any(axis=1)
        assert (res.log_likelihoods[masked] == 0).all() and np.isnan(res.nis[masked]).all()
        assert not res.diverged.any()


def test_loglikelihood_equals_the_data_sets_first_em_iteration():
    """The robot data set ships the log-likelihood of each EM iteration; the first is that of
    the initial covariances."""
    model, d, ys, us = robot(initial=True)
    kf = KalmanFilter(model, x0=d["initial_state_mean"], P0=d["initial_state_covariance"])
    assert kf.filter(ys, us).log_likelihood == pytest.approx(d["loglikelihoods"][0], rel=1e-12)


def test_loglikelihood_equals_the_joint_gaussian_density_of_the_measurements():
    """Brute force: ``y[0..T-1]`` of a linear-Gaussian model is one Gaussian vector (mean and
    covariance from the model's moments); its log-density is the sum of the innovations'."""
    rng = np.random.default_rng(3)
    A = np.array([[1.0, 0.2], [0.0, 0.9]])
    C = np.array([[1.0, 0.0], [0.5, 1.0]])
    Q, R = np.diag([0.05, 0.1]), np.array([[0.3, 0.1], [0.1, 0.2]])
    x0, P0 = np.array([0.5, -1.0]), np.diag([2.0, 1.0])
    T, m = 6, 2
    means, covs = [x0], [P0]                       # moments of x[k]
    for _ in range(T - 1):
        means.append(A @ means[-1])
        covs.append(A @ covs[-1] @ A.T + Q)
    Phi = lambda k, j: np.linalg.matrix_power(A, k - j)   # noqa: E731  x[k] = Φ x[j] + ...
    big = np.zeros((T * m, T * m))
    for k in range(T):
        for j in range(T):
            lo = min(k, j)
            cross = Phi(k, lo) @ covs[lo] @ Phi(j, lo).T  # Cov(x[k], x[j])
            big[k * m:(k + 1) * m, j * m:(j + 1) * m] = C @ cross @ C.T + (R if k == j else 0)
    ys = rng.normal(size=(T, m))
    want = scipy.stats.multivariate_normal(np.concatenate([C @ mu for mu in means]),
                                           big).logpdf(ys.ravel())
    for cls in KALMAN:
        flt = cls(LinearModel(A=A, C=C, Q=Q, R=R), x0=x0, P0=P0)
        assert flt.filter(ys).log_likelihood == pytest.approx(want, rel=1e-9), cls.__name__


@pytest.mark.parametrize("cls", KALMAN + FIR)
def test_filter_equals_the_step_loop_batched_equals_looped(cls):
    model, Y, U = tracking()
    kw = {"horizon": 12} if cls in FIR else {}
    if cls.accepts_missing:
        Y[5, 1] = np.nan                                # one system misses one measurement
    else:                                               # the recursive FIR filter refuses it
        gappy = Y.copy()
        gappy[5, 1] = np.nan
        with pytest.raises(ValueError, match="needs every measurement"):
            cls(model, **kw).filter(gappy, U)
    batch = cls(model, **kw).filter(Y, U)
    assert batch.x.shape == (80, 3, 2)
    for b in range(3):
        one = cls(model, **kw)
        res = one.filter(Y[:, b], U[:, b])
        np.testing.assert_allclose(batch.x[:, b], res.x, rtol=1e-12, atol=1e-12)
        if res.P is not None:
            np.testing.assert_allclose(batch.P[:, b], res.P, rtol=1e-11, atol=1e-12)
        if res.log_likelihoods is not None:
            np.testing.assert_allclose(batch.log_likelihoods[:, b], res.log_likelihoods,
                                       rtol=1e-11)
            assert batch.log_likelihood[b] == pytest.approx(res.log_likelihood, rel=1e-11)
        loop = cls(model, **kw)                          # the env loop, by hand
        for k in range(80):
            y = Y[k, b] if np.isfinite(Y[k, b]).all() else None
            np.testing.assert_array_equal(loop.step(y, None if k == 0 else U[k - 1, b]),
                                          res.x[k])
    if cls in KALMAN and cls.accepts_missing:
        assert batch.log_likelihoods[5, 1] == 0 and batch.log_likelihoods[5, 0] != 0


@needs_twins
@pytest.mark.parametrize("cls", KALMAN + FIR)
def test_filter_on_the_compiled_path_equals_the_numpy_path(cls):
    """The UKF with ``alpha = 1`` as in test_compiled (the default 1e-3 weighs the sums'
    round-off by ``1/alpha²``)."""
    model, _d, ys, us = robot()
    if not cls.accepts_missing:          # it needs every measurement: the data, unmasked
        ys = np.ma.getdata(ys)
        assert np.isfinite(ys).all()
    kw = {"horizon": 12} if cls in FIR else {"alpha": 1.0} if cls is UnscentedKalmanFilter else {}
    fast = cls(model, **kw).filter(ys, us)
    with numpy_path():
        slow = cls(model, **kw).filter(ys, us)
    np.testing.assert_allclose(fast.x, slow.x, rtol=1e-8, atol=1e-8)
    if fast.log_likelihoods is not None:
        np.testing.assert_allclose(fast.log_likelihoods, slow.log_likelihoods, rtol=1e-9)


def test_nan_and_masked_and_none_are_the_same_missing_measurement():
    model, _d, ys, us = robot()
    with_nan = KalmanFilter(model).filter(ys.filled(np.nan), us)       # nan_policy='raise'
    with_mask = KalmanFilter(model).filter(ys, us)
    np.testing.assert_array_equal(with_nan.x, with_mask.x)
    kf = KalmanFilter(model)
    for k in range(len(ys)):
        y = None if np.ma.getmaskarray(ys[k]).any() else ys.data[k]
        x = kf.step(y, None if k == 0 else us[k - 1])
    np.testing.assert_array_equal(x, with_mask.x[-1])


def test_bad_sequences_name_the_argument():
    model, _d, _ys, _us = robot()
    kf = KalmanFilter(model)
    with pytest.raises(ValueError, match="ys must have shape"):
        kf.filter(np.zeros((10, 3)))
    with pytest.raises(ValueError, match="ys must have shape"):
        kf.filter(np.zeros((0, 2)))
    with pytest.raises(ValueError, match="us must have T - 1 = 9 or T = 10 rows"):
        kf.filter(np.zeros((10, 2)), np.zeros((5, 5)))
    with pytest.raises(ValueError, match="us must have shape"):
        kf.filter(np.zeros((10, 2)), np.zeros((9, 4)))
    with pytest.raises(ValueError, match="us must have shape"):
        kf.filter(np.zeros((10, 3, 2)), np.zeros((9, 2, 5)))
    with pytest.raises(TypeError, match="ys"):
        kf.filter(np.array([["a", "b"]]))
    kf.filter(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="reset"):
        kf.filter(np.zeros((3, 4, 2)))


def rollout(env_id: str, name: str):
    """The estimator on a plant's model (its default prior; FIR horizon 6) and one rollout's
    measurements ``ys (T, n_y)`` and inputs ``us (T - 1, n_u)`` (``us[k]`` after ``ys[k]``)."""
    import gymnasium as gym

    from fir_gym.estimators import estimator_class
    from fir_gym.wrappers import default_prior

    env = gym.make(env_id)
    cls = estimator_class(name)
    x0, P0 = default_prior(env)
    opts = {"x0": x0, "P0": P0} if x0 is not None else {}
    if "fir" in name:
        opts["horizon"] = 6
    flt = cls(getattr(env.unwrapped, cls.model_attribute), **opts)
    rng = np.random.default_rng(5)
    y, _ = env.reset(seed=2)
    ys, us = [y], []
    for _ in range(24):
        y, _, terminated, truncated, info = env.step(0.3 * rng.uniform(-1, 1,
                                                                       env.action_space.shape))
        if terminated or truncated:
            break
        ys.append(y)
        us.append(info["action"])
    env.close()
    return flt, np.array(ys, dtype=np.float64), np.array(us[:len(ys) - 1], dtype=np.float64)


@pytest.mark.parametrize(("env_id", "name"), applicable())
def test_every_filter_on_every_plant_filters_a_sequence_as_its_step_loop(env_id, name):
    import copy
    import warnings

    flt, ys, us = rollout(env_id, name)
    loop = copy.deepcopy(flt)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = flt.filter(ys, us)
        for k in range(len(ys)):
            np.testing.assert_array_equal(loop.step(ys[k], None if k == 0 else us[k - 1]),
                                          res.x[k])
    assert res.x.shape == (len(ys), flt.model.n_x)
    assert (res.P is None) == (not flt.provides_covariance)
    assert (res.log_likelihoods is None) == (not flt.reports_likelihood)
    assert res.diverged.shape == (len(ys),)
    if res.log_likelihoods is not None:
        assert np.isfinite(res.log_likelihoods).all()
        assert res.log_likelihood == pytest.approx(res.log_likelihoods.sum())
