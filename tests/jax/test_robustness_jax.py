"""``fir-gym benchmark-robustness --backend jax``: the learned grid trained by fir_gym.jax.

Oracles: the single numpy env of ``fir-gym evaluate`` (:func:`fir_gym.jax.benchmark.
play_in_numpy_env`, one env per episode, ``reset(seed=EVAL_SEED + i)``) replaying the saved
run folder's policies, against the benchmark's records (a native vector env, sub-env ``i``
on seed ``EVAL_SEED + i``) — two code paths that must give the same episodes; and the
training configuration the records name, against what the run folder recorded.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")
pytest.importorskip("rejax")

from fir_gym.jax.robustness import (  # noqa: E402
    group_folder,
    groups,
    refusal,
    run_group,
)
from fir_gym.robustness.benchmark import learned_tasks, run_benchmark  # noqa: E402
from fir_gym.robustness.learned_grid import LearnedTask  # noqa: E402
from fir_gym.robustness.plan import EVAL_SEED, settings  # noqa: E402

ORBIT = "fir_gym/Orbit-v0"


def _task(tmp: Path, kind: str, regime: str, seed: int = 0, steps: int = 2048,
          conditions: tuple[str, ...] = ("nominal",)) -> LearnedTask:
    return LearnedTask(ORBIT, kind, regime, seed, steps, 3, EVAL_SEED,
                       tuple(settings(list(conditions), quick=True)),
                       str(tmp / "runs" / "Orbit-v0" / f"{regime}-{kind}-seed{seed}"))


def test_what_the_backend_leaves_out_is_named(tmp_path: Path) -> None:
    assert refusal(_task(tmp_path, "ekf", "nominal")) is None
    assert refusal(_task(tmp_path, "measurement-stack", "dr-mismatch")) is None
    assert refusal(_task(tmp_path, "efir", "dr-dropout")) is None
    assert refusal(_task(tmp_path, "recurrent", "dr-dropout")) is None
    assert "no ufir kind" in str(refusal(_task(tmp_path, "ufir", "nominal")))
    assert refusal(LearnedTask("fir_gym/CarrierMotion-v0", "ufir", "dr-dropout", 0, 2048, 3,
                               EVAL_SEED, (), "x")) is None
    tasks = [_task(tmp_path, k, r, s) for k in ("true", "ekf") for r in ("nominal",)
             for s in (1, 0, 2)]
    grouped = groups(tasks)
    assert [[t.seed for t in g] for g in grouped] == [[0, 1, 2], [0, 1, 2]]
    assert group_folder(grouped[1]).name == "nominal-ekf-jax"


@pytest.mark.parametrize(("kind", "recorded"), [("ekf", {"ekf", "ekf+gate"}),
                                               ("recurrent", {"recurrent"})])
def test_the_records_are_the_saved_policies_played_in_the_numpy_env(
        tmp_path: Path, kind: str, recorded: set[str]) -> None:
    """A two-seed group: the benchmark's nominal records equal the run folder's policies
    replayed one episode at a time (``play_in_numpy_env``) — right seed, right policy,
    right normalisation, and for ``recurrent`` the LSTM state carried through each episode
    of the benchmark's vector env as through the single env's; a second call reuses every
    record."""
    from fir_gym.jax.benchmark import play_in_numpy_env
    from fir_gym.jax.train import load

    group = [_task(tmp_path, kind, "nominal", seed) for seed in (0, 1)]
    results = run_group(group)
    assert [r["backend"] for r in results] == ["jax", "jax"]
    run = load(group_folder(group))
    assert run.seeds == [0, 1]
    replayed = play_in_numpy_env(run, 3, seed=EVAL_SEED)
    for i, result in enumerate(results):
        (nominal,) = [r for r in result["records"]
                      if r["task"]["condition"] == "nominal" and r["task"]["kind"] == kind]
        assert nominal["task"]["seed"] == i
        np.testing.assert_allclose(nominal["returns"], replayed[i], rtol=1e-9)
        assert {r["task"]["kind"] for r in result["records"]} == recorded
    again = run_group(group)
    assert all(r["reused"] for r in again)
    assert [r["records"] for r in again] == [r["records"] for r in results]


def test_the_randomised_regimes_train_on_their_condition(tmp_path: Path) -> None:
    """dr-mismatch trains on every randomizable parameter drawn with the condition's middle
    spread, dr-dropout with the sensor losing 30 % of the readings — what the SB3 backend
    trains on — recorded in the run."""
    (mismatch,) = groups([_task(tmp_path, "true", "dr-mismatch")])
    (dropout,) = groups([_task(tmp_path, "ekf", "dr-dropout")])
    for group in (mismatch, dropout):
        run_group(group)
    recorded = json.loads((group_folder(mismatch) / "results.json").read_text())
    assert recorded["env_kwargs"]["randomize"] == {"mu": 0.1, "thrust_max": 0.1}
    recorded = json.loads((group_folder(dropout) / "results.json").read_text())
    assert recorded["env_kwargs"]["sensor_faults"] == {"dropout": 0.3}


def test_groups_on_two_worker_processes_give_the_records_of_one(tmp_path: Path) -> None:
    """``run_groups`` on a two-process runner (``--backend jax --jobs 2``): the same
    results in the same order as in this process, every return to the bit."""
    from fir_gym.jax.robustness import run_groups
    from fir_gym.scenarios.runner import Runner

    def tasks(folder: Path) -> list[LearnedTask]:
        return [_task(folder, kind, "nominal", seed) for kind in ("true", "ekf")
                for seed in (0, 1)]

    here, _ = run_groups(tasks(tmp_path / "here"))
    with Runner("joblib", jobs=2) as runner:
        there, _ = run_groups(tasks(tmp_path / "there"), runner)

    def returns(results: list[dict]) -> list[tuple[str, int, str, list[float]]]:
        return [(r["task"]["kind"], r["task"]["seed"], r["task"]["condition"], r["returns"])
                for result in results for r in result["records"]]

    assert returns(there) == returns(here) and len(here) == 4


def test_the_quick_benchmark_runs_every_task(tmp_path: Path) -> None:
    report = run_benchmark(tmp_path, quick=True, plants=[ORBIT], conditions=["dropout"],
                           learned_backend="jax", progress=False)
    tasks = learned_tasks([ORBIT], ["dropout"], tmp_path, quick=True)
    assert report["learned_tasks"] == len(tasks) > 0
    assert {t.regime for t in tasks} == {"nominal", "dr-dropout"}
    assert report["machine"]["learned_backend"] == "jax" and report["learned_skipped"] == []
    assert "trained with the JAX backend" in (tmp_path / "REPORT.md").read_text()
    with pytest.raises(ValueError, match="learned_backend must be"):
        run_benchmark(tmp_path, quick=True, plants=[ORBIT], learned_backend="torch")
