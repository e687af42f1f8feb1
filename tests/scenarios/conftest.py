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


@pytest.fixture
def tiny_sweep(monkeypatch):
    """The sweeps scenario shrunk to one ratio, one window, one δ and short runs."""
    from fir_gym.scenarios import sweeps

    monkeypatch.setitem(sweeps.RATIOS, True, (0.9,))
    monkeypatch.setitem(sweeps.ORBIT_WINDOWS, True, (10,))
    monkeypatch.setitem(sweeps.ORBIT_STEPS, True, 120)
    monkeypatch.setitem(sweeps.DELTAS, True, (0.15,))
    monkeypatch.setitem(sweeps.OSC_STEPS, True, 420)
    return sweeps
