"""Shared fixtures: each scenario's ``--quick`` report, computed at most once per test session."""

import importlib

import pytest


@pytest.fixture(scope="session")
def quick_report():
    """``quick_report(name)``: the scenario's ``run(seed=0, quick=True)`` report, cached."""
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = importlib.import_module(f"fir_gym.scenarios.{name}").run(seed=0,
                                                                                  quick=True)
        return cache[name]

    return get
