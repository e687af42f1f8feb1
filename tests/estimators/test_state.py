"""The filter's state record (estimators/state.py, docs/architecture.md#filter-state).

Oracles: the record is the state — a filter rebuilt from a copy of it continues bit for bit
— and ``branch`` leaves the flags exactly as a step that never happened would.
"""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from fir_gym.estimators import KalmanFilter, LinearModel, make_estimator
from fir_gym.estimators.state import GATE, MAX_TRACE, NIS_PATIENCE, FilterState, new_limits

MODEL = LinearModel(A=[[1.0, 0.1], [0.0, 1.0]], B=[[0.0], [0.1]], C=[[1.0, 0.0]],
                    Q=0.01 * np.eye(2), R=[[0.1]])


def test_the_record_holds_the_step_state_and_is_the_same_object_through_the_first_step():
    kf = KalmanFilter(MODEL, x0=np.zeros((3, 2)))
    state = kf.state
    assert state.batch == 0 and state.update_next and state.k == 0
    kf.step(np.zeros((3, 1)))
    assert kf.state is state                         # allocated in place, not replaced
    assert state.batch == 3 and state.x.shape == (3, 2) and not state.update_next
    assert state.k == 1 == kf.time_step
    np.testing.assert_array_equal(state.x, kf.x)


def test_limits_are_named_and_live():
    kf = KalmanFilter(MODEL, nis_patience=7, max_covariance_trace=5.0, gate=0.99)
    limits = kf.state.limits
    assert limits[NIS_PATIENCE] == 7 and limits[MAX_TRACE] == 5.0
    kf.nis_patience = 3
    kf.gate = None
    assert limits[NIS_PATIENCE] == 3 and limits[GATE] == np.inf
    fresh = new_limits(1.0, 2, 3.0)
    assert fresh[GATE] == np.inf and fresh[NIS_PATIENCE] == 2.0


@pytest.mark.parametrize(("y", "usable"), [
    (np.zeros((2, 1)), True),
    (np.array([[0.0], [np.nan]]), False),
    (np.ma.masked_array(np.zeros((2, 1)), mask=[[False], [True]]), False),
    (np.ma.masked_array(np.zeros((2, 1)), mask=[[False], [False]]), True),
    (None, False),
])
def test_every_usable_says_whether_every_measurement_of_the_step_is_usable(y, usable):
    kf = KalmanFilter(MODEL, x0=np.zeros((2, 2)), nan_policy="skip")
    kf.step(np.zeros((2, 1)))
    kf.step(y)
    assert kf.state.every_usable is usable


def test_a_predict_that_raises_leaves_the_flags_as_they_were():
    kf = KalmanFilter(MODEL)
    kf.step([0.3])
    before = copy.deepcopy(kf.state)
    with pytest.raises(ValueError, match="u must"):
        kf.predict([np.nan])
    for name in ("k", "update_next", "restarting"):    # (every_usable: this step's input)
        assert getattr(kf.state, name) == getattr(before, name), name
    np.testing.assert_array_equal(kf.state.nis_run, before.nis_run)


def test_branch_restores_k_and_the_nis_run_and_sets_the_next_step():
    state = FilterState.of_batch(np.zeros((2, 1)), np.ones((2, 1, 1)), new_limits(1, 2, 3))
    state.k, state.update_next = 5, False
    state.nis_run[:] = [2, 0]
    with state.branch(update_only=False, keep_nis_run=True):
        assert state.k == 5 and not state.update_next
        state.k += 1
        state.nis_run[:] = 0
    assert state.k == 5 and state.update_next
    np.testing.assert_array_equal(state.nis_run, [2, 0])
    with pytest.raises(RuntimeError), state.branch(update_only=True):
        state.update_next = False
        raise RuntimeError("a step that failed")
    assert state.update_next                          # as it found it


@pytest.mark.parametrize("name", ["kf", "ekf", "ukf", "efir"])
def test_a_copy_of_the_record_is_the_filter(name):
    """Mid-run, a pickled filter and a deep copy continue bit for bit, and their records are
    copies (writing one leaves the other alone)."""
    rng = np.random.default_rng(4)
    f = make_estimator(name, MODEL, **({"horizon": 6} if name == "efir" else {}))
    ys, us = rng.normal(size=(30, 1)), rng.normal(size=(30, 1))
    for k in range(12):
        f.step(ys[k], us[k])
    twins = [copy.deepcopy(f), pickle.loads(pickle.dumps(f))]
    for twin in twins:
        assert twin.state is not f.state and twin.state.x is not f.state.x
    for k in range(12, 30):
        want = f.step(ys[k], us[k])
        for twin in twins:
            np.testing.assert_array_equal(twin.step(ys[k], us[k]), want)
    twins[0].state.x[:] = 1e6
    assert np.abs(f.state.x).max() < 1e6
