"""The shared argument checks of ``estimators/_validation.py``."""

import pytest

from fir_gym.estimators._validation import one_of


def test_one_of_returns_the_value_or_names_the_argument_and_the_choices():
    assert one_of("form", "filter", ("filter", "predictor")) == "filter"
    with pytest.raises(ValueError, match=r"form must be one of \('filter', 'predictor'\); "
                                         r"got 'smoother'"):
        one_of("form", "smoother", ["filter", "predictor"])
