"""One task's episodes as numbers a table can use (JSON-friendly).

Per task (a controller under a condition at a strength, on the shared episode seeds):

* ``returns``, ``lengths`` — per episode (the bootstrap pairs kinds on these episodes);
* ``rmse`` — per state, over every step of every episode, where the controller sees an
  estimate;
* ``nees`` — the per-step NEES pooled over steps and episodes: its mean (the ANEES, which
  a few steps with a nearly singular ``P`` can blow up), its median, and the fraction of
  steps inside the two-sided 95 % χ²(n_x) band (0.95 for a consistent filter), with the
  number of steps where ``P`` was not positive definite;
* ``diverged`` — the episodes whose divergence flag rose;
* ``recovery`` — after a burst, each episode's recovery time and whether it is censored
  (:mod:`.recovery`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .closed_loop import Episodes
from .recovery import recovery_time


def nees_statistics(values: Any, n_x: int) -> dict[str, Any]:
    """:func:`fir_gym.estimators.metrics.nees_summary` of a pooled NEES sample, whose NaN
    entries (the steps without a positive-definite ``P``) are counted and left out."""
    from fir_gym.estimators.metrics import chi2_band, nees_summary

    v = np.asarray(values, dtype=np.float64).ravel()
    finite = v[~np.isnan(v)]
    if not len(finite):
        return {"mean": None, "median": None, "p95": None, "in_band": None,
                "band": list(chi2_band(n_x)), "skipped": int(v.size)}
    summary = nees_summary(finite, n_x)
    return {"mean": summary.mean, "median": summary.median, "p95": summary.p95,
            "in_band": summary.in_band, "band": list(summary.band),
            "skipped": int(v.size - finite.size)}


def episode_summary(episodes: Episodes, *, n_x: int,
                    burst: tuple[int, int] | None = None) -> dict[str, Any]:
    """The task's record (module docstring)."""
    out: dict[str, Any] = {"returns": episodes.returns.tolist(),
                           "lengths": episodes.lengths.tolist()}
    rmse = episodes.rmse
    out["rmse"] = None if rmse is None else rmse.tolist()
    if episodes.nees is not None:
        out["nees"] = nees_statistics(episodes.nees[_live_steps(episodes)], n_x)
    else:
        out["nees"] = None
    out["diverged"] = None if episodes.diverged is None else int(episodes.diverged.sum())
    if burst is not None and episodes.errors is not None:
        first, last = burst
        times = [recovery_time(episodes.errors[:, i], first, last)
                 for i in range(episodes.errors.shape[1])]
        out["recovery"] = {"steps": [None if math.isnan(t) else t for t, _ in times],
                           "censored": [c for _, c in times]}
    return out


def _live_steps(episodes: Episodes) -> np.ndarray:
    """``(T, n)``: the steps that belong to each sub-env's recorded episode."""
    assert episodes.nees is not None
    return np.arange(episodes.nees.shape[0])[:, None] <= episodes.lengths[None, :]
