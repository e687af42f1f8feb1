"""The benchmark's tables: per plant × condition × strength, one row per controller.

A *cell* is one (plant, condition, strength); its rows are the controllers evaluated there
— the LQG on the true state and on each estimator (plain, ``+gate``), and each learned
kind in each training regime — all on the same evaluation episodes. Per row
(:func:`cell_rows`):

* ``iqm`` with ``low``/``high`` — the interquartile mean of the per-seed mean returns
  and its 95 % bootstrap interval, which resamples the shared episodes (one draw for
  every row: a paired design) and each row's seeds
  (:func:`fir_gym.training.stats.episode_bootstrap`);
* ``gap`` with ``gap_low``/``gap_high`` — the **estimation gap**: the return of the same
  controller family on the true state minus this row's, as a share of this row's cost,
  ``(IQM(true) − IQM(row)) / |IQM(row)|`` — the part of the cost that knowing the state
  would remove (0: none; 0.9: nine tenths; negative: the row does better than the
  true-state controller), its interval from the same paired draws; the LQG rows against
  ``lqg-true``, a learned row against PPO on the true state of its own training regime.
  (Normalised by the row's cost, not the true-state one's: a plant whose true-state cost
  is near zero — CarrierMotion-v0's compensation — would make the other ratio huge.)
* ``rmse`` (per state), ``nees_median``, ``nees_in_band`` (the fraction of steps inside
  the 95 % χ² band; 0.95 for a consistent filter), ``nees_mean`` (the ANEES),
  ``diverged`` (the fraction of episodes whose divergence flag rose), ``recovery``
  (after a burst: the median recovery time over episodes, and whether it is censored).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from fir_gym.training.stats import episode_bootstrap, iqm, percentile_interval

from .recovery import median_recovery

#: the bootstrap's resamples (seeded: the intervals are reproducible)
RESAMPLES = 2000


def row_name(task: dict[str, Any]) -> str:
    """A controller's name in the tables: ``lqg-ekf+gate``, ``ekf (nominal)``, …"""
    regime = task.get("regime")
    return task["kind"] if regime is None else f"{task['kind']} ({regime})"


def reference_of(task: dict[str, Any]) -> str | None:
    """The true-state row a row's estimation gap is measured against: ``lqg-true`` for an
    LQG, PPO on the true state of the same training regime for a learned controller."""
    kind = task["kind"]
    if kind.startswith("lqg-"):
        return None if kind == "lqg-true" else "lqg-true"
    if kind == "true":
        return None
    return row_name({"kind": "true", "regime": task.get("regime")})


def cells(records: Iterable[dict[str, Any]]) -> dict[tuple[str, str, float], list[dict[str, Any]]]:
    """The records grouped by (plant, condition, strength), in the order first seen."""
    out: dict[tuple[str, str, float], list[dict[str, Any]]] = {}
    for record in records:
        t = record["task"]
        out.setdefault((t["env_id"], t["condition"], float(t["strength"])), []).append(record)
    return out


def cell_rows(records: Sequence[dict[str, Any]], seed: int = 0) -> list[dict[str, Any]]:
    """One row per controller of a cell (module docstring), in the order first seen."""
    runs: dict[str, list[dict[str, Any]]] = {}
    for record in records:
        runs.setdefault(row_name(record["task"]), []).append(record)
    returns = {name: np.array([r["returns"] for r in rs], dtype=np.float64)
               for name, rs in runs.items()}
    draws = episode_bootstrap(returns, resamples=RESAMPLES, seed=seed)
    centres = {name: iqm(R.mean(axis=1)) for name, R in returns.items()}
    rows = []
    for name, rs in runs.items():
        low, high = percentile_interval(draws[name])
        row: dict[str, Any] = {"name": name, "kind": rs[0]["task"]["kind"],
                               "regime": rs[0]["task"].get("regime"), "seeds": len(rs),
                               "episodes": returns[name].shape[1], "iqm": centres[name],
                               "low": low, "high": high, "gap": None, "gap_low": None,
                               "gap_high": None}
        ref = reference_of(rs[0]["task"])
        if ref is not None and ref in draws:
            scale = abs(centres[name]) or 1.0
            row["gap"] = (centres[ref] - centres[name]) / scale
            gap_draws = (draws[ref] - draws[name]) / np.maximum(np.abs(draws[name]), 1e-300)
            row["gap_low"], row["gap_high"] = percentile_interval(gap_draws)
        rmse = [r["rmse"] for r in rs if r.get("rmse") is not None]
        row["rmse"] = np.mean(rmse, axis=0).tolist() if rmse else None
        nees = [r["nees"] for r in rs if r.get("nees") and r["nees"].get("median") is not None]
        row["nees_median"] = float(np.median([n["median"] for n in nees])) if nees else None
        row["nees_in_band"] = float(np.mean([n["in_band"] for n in nees])) if nees else None
        row["nees_mean"] = float(np.mean([n["mean"] for n in nees])) if nees else None
        diverged = [r["diverged"] for r in rs if r.get("diverged") is not None]
        row["diverged"] = (float(sum(diverged)) / (len(diverged) * row["episodes"])
                           if diverged else None)
        recovery = [r["recovery"] for r in rs if r.get("recovery")]
        if recovery:
            steps = [np.nan if v is None else v for rec in recovery for v in rec["steps"]]
            censored = [c for rec in recovery for c in rec["censored"]]
            median, censored_median = median_recovery(steps, censored)
            row["recovery"] = None if np.isnan(median) else median
            row["recovery_censored"] = censored_median
        rows.append(row)
    return rows


def paired_difference(records: Sequence[dict[str, Any]], a: str, b: str, seed: int = 0
                      ) -> tuple[float, float, float]:
    """``IQM(a) − IQM(b)`` of a cell's rows ``a`` and ``b`` with the 95 % interval of the
    paired bootstrap (the same episode draws for both)."""
    runs: dict[str, list[list[float]]] = {}
    for record in records:
        runs.setdefault(row_name(record["task"]), []).append(record["returns"])
    data = {name: np.array(runs[name], dtype=np.float64) for name in (a, b)}
    draws = episode_bootstrap(data, resamples=RESAMPLES, seed=seed)
    centre = iqm(data[a].mean(axis=1)) - iqm(data[b].mean(axis=1))
    low, high = percentile_interval(draws[a] - draws[b])
    return centre, low, high
