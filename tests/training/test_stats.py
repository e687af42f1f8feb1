"""IQM and the stratified bootstrap, against their definitions and scipy."""

import numpy as np
import pytest
import scipy.stats

from fir_gym.training.stats import iqm, iqm_ci, normalised_iqm_ci, stratified_bootstrap_ci


def test_iqm_is_the_mean_of_the_middle_half():
    assert iqm([1, 2, 3, 4]) == pytest.approx(2.5)
    assert iqm([0, 1, 2, 3, 100, -100, 4, 5]) == pytest.approx(np.mean([1, 2, 3, 4]))
    assert iqm([7.0]) == 7.0


def test_one_task_interval_matches_scipys_percentile_bootstrap():
    rng = np.random.default_rng(3)
    scores = rng.normal(size=12)
    low, high = stratified_bootstrap_ci([scores], lambda t: float(np.mean(t[0])),
                                        resamples=20_000, seed=1)
    ref = scipy.stats.bootstrap((scores,), np.mean, method="percentile", n_resamples=20_000,
                                random_state=2).confidence_interval
    assert low == pytest.approx(ref.low, abs=0.03) and high == pytest.approx(ref.high, abs=0.03)


def test_strata_are_resampled_separately():
    """Two tasks with constant scores: every resample keeps each task's value, so the
    interval of the mean of task means is one point."""
    low, high = stratified_bootstrap_ci([[1.0, 1.0, 1.0], [5.0, 5.0]],
                                        lambda t: float(np.mean([x.mean() for x in t])))
    assert low == high == 3.0


def test_normalised_score_is_one_for_the_reference_and_orders_costs():
    ref = np.array([-100.0, -102.0, -98.0, -101.0, -99.0])
    centre, low, high = normalised_iqm_ci(ref, ref)
    assert centre == pytest.approx(1.0) and low <= 1.0 <= high
    worse, _, hi = normalised_iqm_ci(2 * ref, ref)
    assert worse == pytest.approx(0.5, rel=1e-12) and hi < 1.0
    value, lo, hi = iqm_ci(ref)
    assert lo <= value <= hi
