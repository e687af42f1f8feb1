"""The JAX measurements of ``fir-gym speed training`` (fir_gym/benchmarks/jax_training.py)
run and report finite rates — smoke tests with tiny budgets, no timing asserted."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("jax")
pytest.importorskip("gymnax")
pytest.importorskip("rejax")

from fir_gym.benchmarks import jax_training


@pytest.mark.parametrize("free", [False, True])
def test_the_ppo_rate_runs_with_seeds_vmapped(free: bool) -> None:
    res = jax_training.jax_ppo_rate(512, seeds=2, free=free, n_envs=4)
    assert res["steps"] > 0 and math.isfinite(res["rate"]) and res["rate"] > 0
    assert res["seconds"] > 0 and res["compile_seconds"] > 0


def test_the_recurrent_rates_run() -> None:
    pytest.importorskip("sb3_contrib")
    res = jax_training.jax_ppo_rate(512, n_envs=4, kind="recurrent")
    assert res["steps"] > 0 and math.isfinite(res["rate"]) and res["rate"] > 0
    sb3 = jax_training.sb3_ppo_rate(64, kind="recurrent")
    assert sb3["steps"] > 0 and math.isfinite(sb3["rate"]) and sb3["rate"] > 0


@pytest.mark.parametrize("mode", jax_training.MODES)
def test_the_stepping_rate_runs(mode: str) -> None:
    rate, compile_seconds = jax_training.jax_stepping_rate(8, 4, 2, mode=mode)
    assert math.isfinite(rate) and rate > 0 and compile_seconds > 0


def test_the_stepping_rates_under_the_conditions_run() -> None:
    """Mismatch and dropout in the step, on both sides (``stepping_conditions``)."""
    rate, _ = jax_training.jax_stepping_rate(8, 4, 2, conditions=True)
    numpy_rate = jax_training.numpy_stepping_rate(8, 4, 1, conditions=True)
    assert math.isfinite(rate) and rate > 0 and math.isfinite(numpy_rate) and numpy_rate > 0
    with pytest.raises(ValueError, match="mode must be 'step'"):
        jax_training.jax_stepping_rate(8, 4, 1, mode="step_env", conditions=True)
