"""Recovery times after a burst, on error trajectories whose answer is known by construction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fir_gym.robustness.recovery import WINDOW, median_recovery, recovery_time


def _trajectory(steps=200, first=100, last=109, settle=None, seed=0):
    """Unit-noise errors before the burst; during and after it an error of size 50 that
    drops back to the pre-burst noise exactly ``settle`` steps after the burst's last
    affected state (``last + 1``); ``settle=None``: it never does."""
    rng = np.random.default_rng(seed)
    errors = rng.normal(size=(steps, 2)) * [0.1, 2.0]
    end = last + 1
    back = steps if settle is None else end + settle
    errors[first + 1:back] = 50.0 * np.array([0.1, 2.0])
    return errors


@pytest.mark.parametrize("settle", [1, 7, 30])
def test_the_recovery_time_is_the_step_the_error_returns(settle):
    """The error is back from step end + settle: no window holding a step of size 50 is at
    the baseline, and the first clean window is unless its noise is in the top 5 % of the
    reference windows' (then a cluster of overlapping windows: at most two windows more).
    Over episodes, the median is exactly ``settle``."""
    times = []
    for seed in range(9):
        steps, censored = recovery_time(_trajectory(settle=settle, seed=seed), 100, 109)
        assert not censored
        assert settle <= steps <= settle + 2 * WINDOW
        times.append(steps)
    assert np.median(times) == settle


def test_an_error_that_never_returns_is_censored_at_the_episode_end():
    steps, censored = recovery_time(_trajectory(settle=None), 100, 109)
    assert censored and steps == 200 - 110


def test_an_episode_that_ends_inside_the_burst_cannot_be_measured():
    errors = _trajectory()
    errors[105:] = np.nan                         # the episode ended at step 104
    steps, censored = recovery_time(errors, 100, 109)
    assert math.isnan(steps) and censored


def test_median_counts_censored_episodes_as_the_longest():
    median, censored = median_recovery([3, 5, 90, 2, 40], [False, False, True, False, True])
    assert (median, censored) == (5.0, False)
    median, censored = median_recovery([3, 90, 80], [False, True, True])
    assert (median, censored) == (80.0, True)
    median, censored = median_recovery([math.nan], [True])
    assert math.isnan(median) and censored
