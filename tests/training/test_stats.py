"""IQM and the stratified bootstrap, against their definitions and scipy."""

import numpy as np
import pytest
import scipy.stats

from fir_gym.training.stats import (
    episode_bootstrap,
    iqm,
    iqm_ci,
    normalised_iqm_ci,
    percentile_interval,
    stratified_bootstrap_ci,
)


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


def test_episode_bootstrap_of_one_run_is_the_bootstrap_of_its_mean():
    """One run (a deterministic controller): the draws are the percentile bootstrap of the
    mean over its episodes (scipy as the oracle)."""
    rng = np.random.default_rng(5)
    episodes = rng.normal(-100.0, 30.0, size=20)
    draws = episode_bootstrap({"lqg": [episodes]}, resamples=20_000, seed=1)["lqg"]
    low, high = percentile_interval(draws)
    ref = scipy.stats.bootstrap((episodes,), np.mean, method="percentile", n_resamples=20_000,
                                random_state=2).confidence_interval
    assert low == pytest.approx(ref.low, abs=0.6) and high == pytest.approx(ref.high, abs=0.6)
    assert high - low > 10.0                                   # not a point: episodes vary


def test_episode_bootstrap_pairs_the_shared_episodes_and_resamples_runs():
    rng = np.random.default_rng(6)
    episodes = rng.normal(-100.0, 30.0, size=20)
    runs = np.stack([episodes + shift for shift in (-3.0, 0.0, 3.0, 1.0, -1.0)])
    draws = episode_bootstrap({"a": [episodes], "b": [episodes - 2.0], "same": [episodes] * 3,
                               "learned": runs})
    # the same episode draw for every kind: a constant shift is exactly the difference
    np.testing.assert_allclose(draws["a"] - draws["b"], 2.0, rtol=0, atol=1e-9)
    # identical runs add nothing to the interval
    np.testing.assert_allclose(draws["same"], draws["a"], rtol=0, atol=1e-9)
    # the runs' spread does: the learned kind's draws differ from a's by more than a shift
    assert np.ptp(draws["learned"] - draws["a"]) > 1.0
    with pytest.raises(ValueError, match="at least one run"):
        episode_bootstrap({"a": np.zeros((0, 3))})
