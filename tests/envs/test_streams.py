"""Buffered per-system streams: bit for bit the numbers each generator draws one call at a
time, whatever the pattern of rows and sizes, reseeding, and copies."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from fir_gym.envs._streams import RowStreams


@pytest.mark.parametrize("kind", ["normal", "uniform"])
@pytest.mark.parametrize("block", [1, 7, 512])
def test_draws_equal_each_generators_own_scalar_calls(kind, block):
    n = 6
    streams = RowStreams([np.random.default_rng(i) for i in range(n)], kind, block=block)
    own = [np.random.default_rng(i) for i in range(n)]
    pattern = np.random.default_rng(99)
    for _ in range(300):
        rows = pattern.random(n) < 0.6
        k = int(pattern.integers(1, 6))
        got = streams.draw(rows, k)
        for row, i in zip(got, np.flatnonzero(rows), strict=True):
            expected = [own[i].standard_normal() if kind == "normal" else own[i].random()
                        for _ in range(k)]
            np.testing.assert_array_equal(row, expected)
    assert streams.draw(np.zeros(n, dtype=bool), 3).shape == (0, 3)


def test_a_replaced_generator_starts_its_row_afresh():
    streams = RowStreams([np.random.default_rng(i) for i in range(3)], "normal", block=8)
    streams.draw(None, 3)
    streams.replace(1, np.random.default_rng(42))
    got = streams.draw(None, 2)
    np.testing.assert_array_equal(got[1], np.random.default_rng(42).standard_normal(2))
    np.testing.assert_array_equal(got[0], np.random.default_rng(0).standard_normal(5)[3:])


def test_copies_continue_identically():
    streams = RowStreams([np.random.default_rng(i) for i in range(4)], "uniform", block=5)
    streams.draw(None, 3)
    twins = [copy.deepcopy(streams), pickle.loads(pickle.dumps(streams))]
    ours = streams.draw(None, 9)
    for twin in twins:
        np.testing.assert_array_equal(twin.draw(None, 9), ours)
