"""Metrics: RMSE, NEES, NIS against direct formulas; χ² bands against scipy; NaN propagation."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats

from fir_gym.estimators.metrics import anees, chi2_band, mean_nis, nees, nis, rmse, within_band


def test_rmse():
    x = np.zeros((4, 2))
    e = np.array([[1.0, 2.0], [-1.0, 0.0], [1.0, 2.0], [-1.0, 0.0]])
    np.testing.assert_allclose(rmse(x, e), [1.0, np.sqrt(2.0)])
    np.testing.assert_allclose(rmse(x, e, axis=None), np.sqrt(1.5))
    assert np.isnan(rmse([0.0, 0.0], [np.nan, 1.0], axis=None))


def test_nees_and_nis_match_direct_formula():
    rng = np.random.default_rng(0)
    L = rng.normal(size=(5, 3, 3))
    P = L @ L.mT + np.eye(3)
    e = rng.normal(size=(5, 3))
    direct = np.array([e[i] @ np.linalg.solve(P[i], e[i]) for i in range(5)])
    np.testing.assert_allclose(nees(np.zeros((5, 3)), e, P), direct)
    np.testing.assert_allclose(nis(e, P), direct)
    np.testing.assert_allclose(nees(np.zeros(3), e[0], P[0]), direct[0])
    np.testing.assert_allclose(anees(np.zeros((5, 3)), e, P), direct.mean())
    np.testing.assert_allclose(mean_nis(e, P), direct.mean())
    with pytest.raises(ValueError, match="positive definite"):
        nees(np.zeros(2), np.ones(2), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="P must have shape"):
        nees(np.zeros(2), np.ones(2), np.eye(3))


def test_chi2_band_and_monte_carlo_coverage():
    lo, hi = chi2_band(3, 50)
    assert np.isclose(lo, scipy.stats.chi2.ppf(0.025, 150) / 50)
    assert np.isclose(hi, scipy.stats.chi2.ppf(0.975, 150) / 50)
    rng = np.random.default_rng(1)
    samples = (rng.standard_normal((2000, 50, 3)) ** 2).sum(-1).mean(-1)   # mean of 50 χ²(3)
    cover = within_band(samples, 3, 50).mean()
    assert 0.93 < cover < 0.97
    with pytest.raises(ValueError):
        chi2_band(0)
