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
    with pytest.raises(ValueError, match=r"mode must be one of \('batch_step', 'step'\)"):
        jax_training.jax_stepping_rate(8, 4, 1, mode="step_env", conditions=True)


@pytest.mark.parametrize("conditions", [False, True])
def test_the_batch_step_program_is_the_vmapped_step_program(conditions: bool) -> None:
    """The target row's batch step and gymnax's step vmapped: every env's estimate and
    return the same bits (fir_gym.jax.batch_step is tested through episode ends in
    tests/jax/test_batch_step.py)."""
    import numpy as np

    got = {mode: jax_training.stepping_program(8, 12, mode=mode, conditions=conditions)
           for mode in jax_training.AUTO_RESET}
    results = {mode: run(keys(4)) for mode, (run, keys) in got.items()}
    for a, b in zip(results["batch_step"], results["step"], strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


SHARDED = """
import sys
import numpy as np
from fir_gym.benchmarks.jax_training import stepping_program
from fir_gym.cpu_devices import request_cpu_devices
devices = request_cpu_devices(2)
out = {"devices": np.asarray(devices)}
for n in (1, 2):
    run, keys = stepping_program(8, 12, devices=n)
    estimate, rewards = run(keys(3))
    out[f"estimate{n}"], out[f"rewards{n}"] = np.asarray(estimate), np.asarray(rewards)
    out[f"shards{n}"] = np.asarray(len(rewards.sharding.device_set))
np.savez(sys.argv[1], **out)
"""


def test_sharding_the_envs_across_cpu_devices_changes_no_number(tmp_path) -> None:
    """``devices=2`` (the stepping target's one device per core) splits the envs across two
    CPU devices — asked for in a fresh process, before JAX starts — and every env's estimate
    and return are the bits of the one-device program (the batch step, each device a batch
    of its own) and of this process's gymnax step vmapped."""
    import os
    import subprocess
    import sys

    import numpy as np

    out = tmp_path / "sharded.npz"
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    # -P and a cwd of its own: the installed fir_gym, not a source tree the cwd may hold
    subprocess.run([sys.executable, "-P", "-c", SHARDED, str(out)], check=True, env=env,
                   cwd=tmp_path, timeout=600)
    got = np.load(out)
    assert int(got["devices"]) == 2 and int(got["shards1"]) == 1 and int(got["shards2"]) == 2
    run, keys = jax_training.stepping_program(8, 12, mode="step")   # gymnax's step vmapped
    estimate, rewards = run(keys(3))
    for n in (1, 2):
        np.testing.assert_array_equal(got[f"estimate{n}"], np.asarray(estimate))
        np.testing.assert_array_equal(got[f"rewards{n}"], np.asarray(rewards))
    assert np.isfinite(np.asarray(rewards)).all()


def test_the_stepping_program_refuses_devices_it_cannot_use() -> None:
    import jax

    from fir_gym.cpu_devices import request_cpu_devices

    have = len(jax.devices("cpu"))
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="count must be a positive integer"):
            request_cpu_devices(bad)
    # in a process whose JAX has started, asking for more devices keeps what it has
    assert request_cpu_devices(have + 1) == have
    with pytest.raises(ValueError, match="devices must be between 1 and"):
        jax_training.stepping_program(8, 2, devices=have + 1)
    with pytest.raises(ValueError, match="divide n_envs = 7; got 0"):
        jax_training.stepping_program(7, 2, devices=0)
    with pytest.raises(ValueError, match="mode must be one of"):
        jax_training.stepping_program(8, 2, mode="walk")


def test_the_stepping_rows_name_the_devices() -> None:
    """The row label says which devices stepped (JSON from before the platform field: CPU)."""
    assert jax_training.cpus({"jax_devices": 2}) == "2 CPU devices (one per core)"
    assert jax_training.cpus({}) == "one CPU device"
    assert jax_training.cpus({"jax_devices": 1, "jax_platform": "gpu"}) == "one GPU device"
    assert jax_training.cpus({"jax_devices": 4, "jax_platform": "gpu"}) == "4 GPU devices"
