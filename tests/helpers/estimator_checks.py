"""Checks the estimator tests share (importable: pytest's ``pythonpath`` has this folder)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest


def assert_rejects_bad_input(flt: Any) -> None:
    """A one-output, one-input filter raises, naming the argument, on a NaN measurement
    (default ``nan_policy``), a measurement of the wrong shape and an infinite input."""
    with pytest.raises(ValueError, match="y must be finite"):
        flt.step(np.array([np.nan]), [0.0])
    with pytest.raises(ValueError, match="y must have shape"):
        flt.step(np.zeros(2), [0.0])
    with pytest.raises(ValueError, match="u must"):
        flt.step(np.zeros(1), [np.inf])
