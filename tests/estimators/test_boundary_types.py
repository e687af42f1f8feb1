"""The estimators' boundary takes real numbers only: booleans, complex numbers, dates,
strings and other objects in ``y``, ``u``, ``x0`` or ``P0`` are refused with a
``TypeError`` naming the argument (numpy would turn ``True`` into 1, ``"0.5"`` into 0.5,
or drop an imaginary part), integers and other float widths are read as floats, and a
refused step changes nothing."""

from __future__ import annotations

import copy
import datetime
from fractions import Fraction

import numpy as np
import pytest
from sample_models import duffing_model

from fir_gym.estimators import ExtendedKalmanFilter, KalmanFilter, LinearModel, make_estimator
from fir_gym.estimators._validation import real_array

LINEAR = LinearModel(A=[[1.0, 0.1], [0.0, 1.0]], C=[[1.0, 0.0]], B=[[0.0], [0.1]],
                     Q=0.01 * np.eye(2), R=[[0.1]])
NOT_REAL = {
    "booleans": [True],
    "a bool array": np.array([False]),
    "complex numbers": [1.0 + 2.0j],
    "dates (datetime64)": np.array(["2024-01-01"], dtype="datetime64[D]"),
    "time spans (timedelta64)": np.array([3], dtype="timedelta64[s]"),
    "strings": ["0.5"],
    "a None": [None],
    "a datetime object": [datetime.datetime(2024, 1, 1)],
}


@pytest.mark.parametrize("name", ["kf", "ekf", "ukf", "lkf", "fir", "efir", "ufir", "rfir",
                                  "fir-smoother"])
@pytest.mark.parametrize("what", list(NOT_REAL))
def test_y_and_u_must_be_real_numbers(name, what):
    opts = {"horizon": 3} if "fir" in name else {}
    flt = make_estimator(name, LINEAR, **opts)
    flt.step([0.1])
    before = copy.deepcopy(flt)
    bad = NOT_REAL[what]
    with pytest.raises(TypeError, match=r"^y must be real numbers"):
        flt.step(bad, [0.0])
    with pytest.raises(TypeError, match=r"^u must be real numbers"):
        flt.step([0.2], bad)
    assert flt.time_step == before.time_step
    np.testing.assert_array_equal(flt.x, before.x)
    np.testing.assert_array_equal(flt.step([0.2], [0.0]), before.step([0.2], [0.0]))


@pytest.mark.parametrize("what", list(NOT_REAL))
def test_the_prior_must_be_real_numbers(what):
    bad = NOT_REAL[what]
    for name, value in (("x0", [bad[0], 0.0]), ("P0", [[bad[0], 0.0], [0.0, 1.0]])):
        with pytest.raises(TypeError, match=rf"^{name} must be real numbers"):
            KalmanFilter(LINEAR, **{name: value})
        flt = KalmanFilter(LINEAR)
        with pytest.raises(TypeError, match=rf"^{name} must be real numbers"):
            flt.reset(**{name: value})


def test_integers_and_other_float_widths_are_read_as_floats():
    a, b = ExtendedKalmanFilter(duffing_model()), ExtendedKalmanFilter(duffing_model())
    a.step(np.array([1, 2], dtype=np.int32))
    b.step([1.0, 2.0])
    a.step(np.array([0.5, 0.25], dtype=np.float32), np.array([1], dtype=np.uint8))
    b.step([0.5, 0.25], [1.0])
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(real_array("y", [Fraction(1, 2), 2]), [0.5, 2.0])


def test_ragged_input_is_a_value_error_naming_the_argument():
    flt = KalmanFilter(LINEAR)
    with pytest.raises(ValueError, match=r"^y must be an array of real numbers"):
        flt.step([[0.1], [0.2, 0.3]])


@pytest.mark.parametrize("batch", [None, 3, 20])         # 20 systems: over 16 values
def test_finiteness_is_exact_although_checked_with_one_sum(batch):
    """Huge finite values whose sum overflows are accepted; one NaN or inf is refused."""
    shape = (1,) if batch is None else (batch, 1)
    big = np.full(shape, 1e308)
    flt = KalmanFilter(LINEAR, nan_policy="raise")
    flt.step(big)
    flt.step(big, big)                                     # y and u: sums overflow, all finite
    for bad in (np.nan, np.inf, -np.inf):
        worse = big.copy()
        worse.flat[-1] = bad
        with pytest.raises(ValueError, match="y must be finite"):
            flt.step(worse)
        with pytest.raises(ValueError, match="u must be finite"):
            flt.step(big, worse)
