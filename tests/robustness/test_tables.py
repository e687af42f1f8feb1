"""The benchmark's table rows: IQM, paired intervals and the estimation gap, against
numbers computed by hand from the records."""

from __future__ import annotations

import numpy as np
import pytest

from fir_gym.robustness.tables import cell_rows, paired_difference


def _record(kind, returns, regime=None, seed=0, rmse=None):
    task = {"kind": kind, "env_id": "x", "condition": "nominal", "strength": 0.0}
    if regime is not None:
        task.update(regime=regime, seed=seed)
    return {"task": task, "returns": list(returns), "rmse": rmse, "nees": None,
            "diverged": None}


def test_gap_is_relative_to_the_same_family_on_the_true_state():
    rng = np.random.default_rng(1)
    true = -100 + rng.normal(size=20)
    ekf = true - 10.0                               # the same episodes, 10 worse each
    records = [_record("lqg-true", true), _record("lqg-ekf", ekf, rmse=[0.1, 0.2])]
    rows = {r["name"]: r for r in cell_rows(records)}
    # one run: the IQM of the per-run means is that run's mean return
    assert rows["lqg-true"]["iqm"] == pytest.approx(np.mean(true))
    # the share of the row's cost that the true state would remove
    assert rows["lqg-ekf"]["gap"] == pytest.approx(10.0 / abs(np.mean(ekf)))
    # paired: the difference is exactly 10 in every resample, so the interval is a point
    assert rows["lqg-ekf"]["gap_low"] == pytest.approx(rows["lqg-ekf"]["gap_high"], rel=0.02)
    assert rows["lqg-true"]["gap"] is None


def test_learned_rows_are_compared_within_their_regime():
    records = []
    for seed in range(3):
        records.append(_record("true", np.full(5, -50.0 - seed), "nominal", seed))
        records.append(_record("ekf", np.full(5, -60.0 - seed), "nominal", seed))
        records.append(_record("true", np.full(5, -40.0 - seed), "dr-dropout", seed))
        records.append(_record("ekf", np.full(5, -80.0 - seed), "dr-dropout", seed))
    rows = {r["name"]: r for r in cell_rows(records)}
    # IQM of three seeds (-50, -51, -52) is the trimmed mean of their means: -51
    assert rows["true (nominal)"]["iqm"] == pytest.approx(-51.0)
    assert rows["ekf (nominal)"]["gap"] == pytest.approx(10.0 / 61.0)
    assert rows["ekf (dr-dropout)"]["gap"] == pytest.approx(40.0 / 81.0)


def test_paired_difference_excludes_zero_for_a_constant_shift():
    rng = np.random.default_rng(2)
    a = -100 + 5 * rng.normal(size=30)
    records = [_record("lqg-a", a), _record("lqg-b", a - 1.0)]
    centre, low, high = paired_difference(records, "lqg-a", "lqg-b")
    assert centre == pytest.approx(1.0)
    assert 0 < low <= 1.0 <= high
