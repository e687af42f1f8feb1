"""How long an estimator takes to recover from a burst, in closed loop.

Paper 000 (simulation 2) shows the extended FIR filter forgetting a temporary model
uncertainty within about one window after it ends, while the EKF, UKF and LKF take 100 to
over 1 000 steps (docs/papers.md#000-sim-2-claims; docs/papers.md#beyond-forgetting).
The benchmark measures the same thing on every plant and in closed loop, per episode:

* the error size at step ``k`` is ``d_k = mean_i (e_{k,i} / s_i)²``, each state's error
  ``e_{k,i} = x_{k,i} − x̂_{k,i}`` scaled by its RMS ``s_i`` over the *reference steps* —
  the second half of the steps before the burst (the first half is the filter's start-up);
* the error *level* at step ``k`` is the mean of ``d`` over the :data:`WINDOW` steps from
  ``k`` on (a window, so that one noisy step neither ends nor prolongs a recovery), and the
  *baseline* is the 95th percentile of the level over the reference steps;
* the recovery time is the number of steps from the burst's last affected state until the
  level is back at or below the baseline (a filter whose error never rose recovers in 1
  step: the first step after the burst counts).

An episode that ends before that is *censored*: its recovery time is at least the steps it
had left; :func:`median_recovery` reports the median over episodes with censored ones
counted as longer than every observed one, and says when the median itself is censored.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: the steps over which the error level is averaged
WINDOW = 10


def recovery_time(errors: FloatArray, first: int, last: int) -> tuple[float, bool]:
    """``(steps, censored)`` for one episode's errors ``(T, n_x)`` (NaN after its end) and a
    burst over the transitions ``first..last`` (the error of step ``k`` is that of the state
    ``x[k]``, so the burst acts on steps ``first + 1`` to ``last + 1``). NaN (and censored)
    when the episode ends before the burst does or has too few reference steps."""
    errors = np.asarray(errors, dtype=np.float64)
    steps = int(np.sum(np.all(np.isfinite(errors), axis=1)))
    start = max(1, first // 2)
    end = last + 1                                   # the burst's last affected state
    reference = errors[start:first + 1]
    if len(reference) < WINDOW + 1 or steps <= end + 1:
        return math.nan, True
    scale = np.sqrt(np.mean(reference ** 2, axis=0))
    scale = np.where(scale > 0, scale, 1.0)
    size = np.mean((errors[:steps] / scale) ** 2, axis=1)
    level = np.convolve(size, np.ones(WINDOW) / WINDOW, mode="valid")   # level[k]: k..k+W−1
    baseline = float(np.quantile(level[start:first + 2 - WINDOW], 0.95))
    for k in range(end + 1, len(level)):
        if level[k] <= baseline:
            return float(k - end), False
    return float(steps - end), True


def median_recovery(times: Any, censored: Any) -> tuple[float, bool]:
    """The median recovery time over episodes, censored ones counted as longer than every
    observed one; ``(median, whether the median is itself a censored lower bound)``. NaN
    when no episode could be measured."""
    t = np.asarray(times, dtype=np.float64)
    c = np.asarray(censored, dtype=bool)
    keep = np.isfinite(t)
    t, c = t[keep], c[keep]
    if not len(t):
        return math.nan, True
    order = np.lexsort((t, c))                       # observed first, each group ascending
    t, c = t[order], c[order]
    mid = (len(t) - 1) // 2
    return float(t[mid]), bool(c[mid])
