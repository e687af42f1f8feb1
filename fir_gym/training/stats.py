"""Aggregate scores over seeds: the interquartile mean and stratified-bootstrap intervals.

Following Agarwal et al., "Deep Reinforcement Learning at the Edge of the Statistical
Precipice" (NeurIPS 2021; the ``rliable`` package): with a handful of seeds per
configuration, report the *interquartile mean* (the mean of the middle 50 % of the
runs, :func:`iqm`) with a 95 % percentile-bootstrap confidence interval whose
resamples draw runs *within each task* (stratified: :func:`stratified_bootstrap_ci`).
Here a task is a plant; a single plant's interval is the ordinary bootstrap over its
seeds.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
import scipy.stats
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def iqm(scores: ArrayLike) -> float:
    """The interquartile mean: the 25 %-trimmed mean of all scores (``rliable``'s IQM)."""
    return float(scipy.stats.trim_mean(np.asarray(scores, dtype=np.float64).ravel(), 0.25))


def stratified_bootstrap_ci(
    tasks: Sequence[ArrayLike],
    statistic: Callable[[Sequence[FloatArray]], float],
    *,
    confidence: float = 0.95,
    resamples: int = 5000,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile interval of ``statistic(tasks)`` under resampling each task's runs.

    ``tasks[t]`` holds task ``t``'s per-run scores (any lengths, at least one run);
    every resample draws, for each task independently, as many runs as it has with
    replacement, and evaluates ``statistic`` on the resampled list. The generator is
    seeded: the interval is reproducible.
    """
    data = [np.asarray(t, dtype=np.float64).ravel() for t in tasks]
    if not data or any(len(t) == 0 for t in data):
        raise ValueError("every task needs at least one score")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1); got {confidence!r}")
    rng = np.random.default_rng(seed)
    values = np.empty(resamples)
    for b in range(resamples):
        values[b] = statistic([t[rng.integers(0, len(t), len(t))] for t in data])
    tail = 50.0 * (1.0 - confidence)
    low, high = np.percentile(values, [tail, 100.0 - tail])
    return float(low), float(high)


def iqm_ci(scores: ArrayLike, *, confidence: float = 0.95, resamples: int = 5000,
           seed: int = 0) -> tuple[float, float, float]:
    """``(IQM, low, high)`` of one task's scores."""
    low, high = stratified_bootstrap_ci([scores], lambda t: iqm(t[0]), confidence=confidence,
                                        resamples=resamples, seed=seed)
    return iqm(scores), low, high


def normalised_iqm_ci(scores: ArrayLike, reference: ArrayLike, *, confidence: float = 0.95,
                      resamples: int = 5000, seed: int = 0) -> tuple[float, float, float]:
    """``IQM(reference) / IQM(scores)`` with its interval, resampling both sets of runs.

    The returns are costs (negative), so the ratio is 1 for a controller as good as the
    reference (the true-state one), below 1 for a worse one (0.5: twice the cost), above
    1 for a better one. Both the controller's runs and the reference's are resampled (two
    strata), so the interval carries the reference's uncertainty too.
    """
    s = np.asarray(scores, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)

    def ratio(t: Sequence[FloatArray]) -> float:
        denominator = iqm(t[0])
        return iqm(t[1]) / denominator if denominator != 0 else float("nan")

    low, high = stratified_bootstrap_ci([s, r], ratio, confidence=confidence,
                                        resamples=resamples, seed=seed)
    return ratio([s, r]), low, high


def episode_bootstrap(runs: Mapping[str, ArrayLike], *, resamples: int = 5000, seed: int = 0
                      ) -> dict[str, FloatArray]:
    """Bootstrap draws of each kind's IQM over its runs of their mean episode returns.

    ``runs[kind]`` is a ``(n_runs, n_episodes)`` array: one row per trained seed (a
    deterministic controller such as the LQG has one run), one column per evaluation
    episode. A kind's score is :func:`iqm` of its runs' mean returns. Each resample
    draws the evaluation episodes with replacement — *one draw shared by every kind*
    with that number of episodes, because every kind is evaluated on the same episode
    seeds (a paired design: the noise an episode brings is common to all kinds) — and
    then, independently per kind, its runs. So a one-run kind's interval is the
    bootstrap over its episodes, and a learned kind's carries both the seed-to-seed and
    the episode-to-episode variation. Returns ``{kind: (resamples,) draws}``; the
    generator is seeded, so the draws are reproducible.
    """
    rng = np.random.default_rng(seed)
    data = {k: np.atleast_2d(np.asarray(v, dtype=np.float64)) for k, v in runs.items()}
    if any(v.size == 0 for v in data.values()):
        raise ValueError("every kind needs at least one run with at least one episode")
    episodes = {n: rng.integers(0, n, (resamples, n))
                for n in sorted({v.shape[1] for v in data.values()})}
    draws = {}
    for kind, R in data.items():
        means = R[:, episodes[R.shape[1]]].mean(axis=-1).T       # (resamples, n_runs)
        picked = np.take_along_axis(means, rng.integers(0, R.shape[0], means.shape), axis=1)
        draws[kind] = np.asarray(scipy.stats.trim_mean(picked, 0.25, axis=1), dtype=np.float64)
    return draws


def percentile_interval(draws: ArrayLike, confidence: float = 0.95) -> tuple[float, float]:
    """The percentile interval of bootstrap draws."""
    tail = 50.0 * (1.0 - confidence)
    low, high = np.percentile(np.asarray(draws, dtype=np.float64), [tail, 100.0 - tail])
    return float(low), float(high)
