"""Metrics: RMSE, NEES, NIS against direct formulas; χ² bands against scipy; NaN propagation."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats

from fir_gym.estimators.metrics import (
    anees,
    chi2_band,
    mean_nis,
    nees,
    nees_summary,
    nis,
    rmse,
    within_band,
)


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


# ------------------------------------------------------------------ nees_summary
@pytest.mark.parametrize("dof", [1, 2, 4, 9])
def test_nees_summary_of_an_exact_chi2_sample(dof):
    """Values drawn from χ²(dof) (scipy): each statistic within its sampling band of the
    distribution's own value — the in-band fraction within a 5σ binomial band of 0.95, the
    median and 95th percentile within 5σ of the quantiles' asymptotic spread
    √(p(1−p)/n) / pdf(quantile), the mean within 5σ of √(2 dof / n)."""
    n = 40_000
    values = scipy.stats.chi2.rvs(dof, size=n, random_state=np.random.default_rng(dof))
    s = nees_summary(values, dof)
    assert abs(s.in_band - 0.95) < 5 * np.sqrt(0.95 * 0.05 / n)
    assert abs(s.mean - dof) < 5 * np.sqrt(2 * dof / n)
    for got, p in ((s.median, 0.5), (s.p95, 0.95)):
        q = scipy.stats.chi2.ppf(p, dof)
        assert abs(got - q) < 5 * np.sqrt(p * (1 - p) / n) / scipy.stats.chi2.pdf(q, dof)
    assert s.expected_median == pytest.approx(scipy.stats.chi2.ppf(0.5, dof), rel=1e-12)
    assert s.expected_p95 == pytest.approx(scipy.stats.chi2.ppf(0.95, dof), rel=1e-12)
    assert s.band == pytest.approx((scipy.stats.chi2.ppf(0.025, dof),
                                    scipy.stats.chi2.ppf(0.975, dof)), rel=1e-12)
    assert (s.count, s.dof, s.confidence) == (n, dof, 0.95)


def test_nees_summary_is_robust_where_the_mean_is_not():
    """A scaled χ²(2) sample (an overconfident filter, NEES ×3) leaves the band more often;
    one exploded step moves the mean by orders of magnitude, not the median or the band."""
    rng = np.random.default_rng(5)
    values = scipy.stats.chi2.rvs(2, size=10_000, random_state=rng)
    over = nees_summary(3.0 * values, 2)
    lo, hi = scipy.stats.chi2.ppf([0.025, 0.975], 2)
    expected = scipy.stats.chi2.cdf(hi / 3, 2) - scipy.stats.chi2.cdf(lo / 3, 2)
    assert abs(over.in_band - expected) < 5 * np.sqrt(expected * (1 - expected) / 1e4)
    exploded = values.copy()
    exploded[17] = 1e9
    a, b = nees_summary(values, 2), nees_summary(exploded, 2)
    assert b.mean > 1e4 * a.mean
    srt = np.sort(values)                      # one value moved: the median by ≤ one rank
    assert srt[4998] <= b.median <= srt[5001] and srt[4998] <= a.median <= srt[5001]
    assert abs(b.in_band - a.in_band) <= 1.5e-4    # one value of 10 000


def test_nees_summary_matches_numpy_on_a_small_sample():
    v = np.array([[0.2, 8.0], [1.0, 3.0], [0.01, 2.0]])
    s = nees_summary(v, 2, confidence=0.9)
    lo, hi = scipy.stats.chi2.ppf([0.05, 0.95], 2)
    assert s.mean == pytest.approx(np.mean(v))
    assert s.median == pytest.approx(np.median(v))
    assert s.p95 == pytest.approx(np.percentile(v, 95))
    assert s.in_band == pytest.approx(np.mean((v >= lo) & (v <= hi)))
    assert s.band == pytest.approx((lo, hi))


def test_nees_summary_infinite_and_bad_values():
    s = nees_summary([1.0, 2.0, np.inf], 2)
    assert s.mean == np.inf and s.median == 2.0 and s.p95 == np.inf
    assert s.in_band == pytest.approx(2 / 3)
    assert nees_summary([1.0, np.inf, np.inf], 2).median == np.inf
    with pytest.raises(ValueError, match="NaN"):
        nees_summary([1.0, np.nan], 2)
    with pytest.raises(ValueError, match="non-negative"):
        nees_summary([-1.0], 2)
    with pytest.raises(ValueError, match="at least one"):
        nees_summary([], 2)
    with pytest.raises(ValueError, match="dof"):
        nees_summary([1.0], 0)
