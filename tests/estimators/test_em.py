"""EM of a linear model's Q and R against pykalman: the robot data set ships the
log-likelihood of each iteration of a reference implementation's EM, and pykalman's own
``em`` gives the fitted covariances."""

from __future__ import annotations

import numpy as np
import pytest
from sequence_data import pykalman_robot, robot

from fir_gym.estimators import LinearModel, em

pykalman = pytest.importorskip("pykalman")


def test_em_follows_the_data_sets_loglikelihoods_and_pykalmans_covariances():
    model, d, ys, us = robot(initial=True)
    prior = {"x0": d["initial_state_mean"], "P0": d["initial_state_covariance"]}
    every = em(model, ys, us, **prior, n_iter=len(d["loglikelihoods"]))      # all 50
    np.testing.assert_allclose(every.log_likelihoods, d["loglikelihoods"], rtol=1e-12)
    assert (np.diff(every.log_likelihoods) > 0).all()           # EM never goes down
    fit = em(model, ys, us, **prior, n_iter=5)
    pk = pykalman_robot(d, initial=True,
                        em_vars=["transition_covariance", "observation_covariance"])
    pk = pk.em(d["observations"], n_iter=5)
    np.testing.assert_allclose(fit.model.Q, pk.transition_covariance, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fit.model.R, pk.observation_covariance, rtol=1e-9, atol=1e-12)


def test_em_refuses_what_it_cannot_fit():
    model, _, ys, us = robot()
    with pytest.raises(ValueError, match="n_iter"):
        em(model, ys, us, x0=np.zeros(5), P0=np.eye(5), n_iter=0)
    with pytest.raises(ValueError, match="G must be the identity"):
        em(LinearModel(A=np.eye(2), C=[[1.0, 0.0]], G=[[1.0], [0.0]], Q=1.0, R=1.0),
           np.zeros((5, 1)), x0=np.zeros(2), P0=np.eye(2))
    with pytest.raises(ValueError, match="one sequence"):
        em(model, np.zeros((5, 3, 2)), x0=np.zeros(5), P0=np.eye(5))
