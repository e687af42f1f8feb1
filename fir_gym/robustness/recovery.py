"""How long an estimator takes to recover from a burst, in closed loop.

Paper 000 (simulation 2) shows the extended FIR filter forgetting a temporary model
uncertainty within about one window after it ends, while the EKF, UKF and LKF take 100 to
over 1 000 steps (docs/papers.md#000-sim-2-claims; docs/papers.md#beyond-forgetting).
The benchmark measures the same thing on every plant and in closed loop, per episode:

* the error size at step ``k`` is ``d_k = sqrt(mean_i (e_{k,i} / s_i)²)``, each state's
  error ``e_{k,i} = x_{k,i} − x̂_{k,i}`` scaled by its RMS ``s_i`` over the *reference
  steps* — the second half of the steps before the burst (the first half is the filter's
  start-up);
* the *baseline* ``b`` is the 95th percentile of ``d_k`` over the reference steps;
* the recovery time is the number of steps from the burst's last transition until ``d_k``
  is back at or below ``b`` and stays there for :data:`HOLD` steps running (a filter whose
  error never rose recovers in 1 step, as the first step after the burst is counted).

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

#: the steps the error must stay at its baseline to count as recovered
HOLD = 10


def recovery_time(errors: FloatArray, first: int, last: int) -> tuple[float, bool]:
    """``(steps, censored)`` for one episode's errors ``(T, n_x)`` (NaN after its end) and a
    burst over the transitions ``first..last`` (the error of step ``k`` is that of the state
    ``x[k]``, so the burst's effect starts at step ``first + 1`` and ends at ``last + 1``)."""
    errors = np.asarray(errors, dtype=np.float64)
    steps = int(np.sum(np.all(np.isfinite(errors), axis=1)))
    reference = errors[max(1, first // 2):first + 1]
    reference = reference[np.all(np.isfinite(reference), axis=1)]
    if len(reference) < 2 or steps <= last + 1:
        return math.nan, True
    scale = np.sqrt(np.mean(reference ** 2, axis=0))
    scale = np.where(scale > 0, scale, 1.0)
    size = np.sqrt(np.mean((errors[:steps] / scale) ** 2, axis=1))
    baseline = float(np.quantile(size[max(1, first // 2):first + 1], 0.95))
    end = last + 1                                   # the burst's last affected state
    below = size <= baseline
    run = 0
    for k in range(end + 1, steps):
        run = run + 1 if below[k] else 0
        if run == HOLD:
            return float(k - HOLD + 1 - end), False
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
