"""The Monte Carlo runner: identical numbers serially, with joblib and on a local Dask cluster."""

import numpy as np
import pytest

from fir_gym.scenarios.runner import Runner
from fir_gym.scenarios.runner import seeded_normals as noisy_task

TASKS = [(seed, 2.0) for seed in range(7)]


def test_serial_and_joblib_agree_bit_for_bit():
    serial = Runner("serial").map(noisy_task, TASKS)
    parallel = Runner("joblib", jobs=2).map(noisy_task, TASKS)
    assert len(serial) == len(TASKS)
    for a, b in zip(serial, parallel, strict=True):
        np.testing.assert_array_equal(a, b)


def test_dask_local_cluster_agrees_bit_for_bit():
    pytest.importorskip("distributed")
    serial = Runner("serial").map(noisy_task, TASKS)
    with Runner("dask", jobs=2) as runner:
        distributed = runner.map(noisy_task, TASKS)
    for a, b in zip(serial, distributed, strict=True):
        np.testing.assert_array_equal(a, b)


def test_bad_arguments():
    with pytest.raises(ValueError, match="backend"):
        Runner("spark")
    with pytest.raises(ValueError, match="jobs"):
        Runner("joblib", jobs=0)
    with pytest.raises(ValueError, match="scheduler"):
        Runner("joblib", scheduler="tcp://x:1")
    assert Runner().map(noisy_task, []) == []
