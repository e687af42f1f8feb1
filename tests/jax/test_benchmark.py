"""``fir-gym benchmark-controllers --backend jax`` (fir_gym.jax.benchmark): the plan is the
SB3 benchmark's restricted to what the JAX backend has, the report's statistics are the
SB3 benchmark's, and an SB3 folder's rows stand beside the JAX rows with the verdict."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("jax")
pytest.importorskip("gymnax")
pytest.importorskip("rejax")

from fir_gym.jax import benchmark
from fir_gym.robustness.plan import PLAIN_KINDS
from fir_gym.robustness.plan import PLANTS as PLANS
from fir_gym.training import benchmark as sb3_benchmark
from fir_gym.training.stats import iqm


def test_the_plan_is_the_sb3_benchmarks_for_the_plants_and_kinds_jax_has() -> None:
    jobs = benchmark.benchmark_plan()
    assert jobs
    for job in jobs:
        spec = sb3_benchmark.PLANTS[job["env_id"]]
        assert job["steps"] == spec["steps"] and job["env_kwargs"] == spec["env_kwargs"]
        assert job["seeds"] == sb3_benchmark.SEEDS and job["episodes"] == sb3_benchmark.EPISODES
        plan = PLANS[job["env_id"]]
        assert job["kind"] in (*PLAIN_KINDS, *plan.learned_estimators)
        assert job["kind_kwargs"] == plan.estimator_kwargs.get(job["kind"], {})
    assert {j["kind"] for j in jobs if j["env_id"] == "fir_gym/Orbit-v0"} == {
        "true", "measurement", "measurement-stack", "recurrent", "ekf", "ukf", "efir"}
    assert {j["kind"] for j in jobs if j["env_id"] == "fir_gym/CarrierMotion-v0"} == {
        "true", "measurement", "measurement-stack", "recurrent", "kf", "ukf", "fir", "ufir"}
    quick = benchmark.benchmark_plan(quick=True, seeds=3, plants=["fir_gym/Orbit-v0"],
                                     kinds=["ekf"])
    assert [(j["kind"], j["seeds"], j["steps"]) for j in quick] == [
        ("ekf", 3, sb3_benchmark.QUICK["steps"])]
    with pytest.raises(ValueError, match="plants must be"):
        benchmark.benchmark_plan(plants=["fir_gym/NoSuchPlant-v0"])
    only = benchmark.benchmark_plan(seeds=3, kinds=["recurrent"])   # --kinds
    assert {j["kind"] for j in only} == {"recurrent"}
    assert {j["env_id"] for j in only} == {j["env_id"] for j in jobs}
    with pytest.raises(ValueError, match=r"kinds must be among .*; got recurent"):
        benchmark.benchmark_plan(kinds=["recurent"])


def test_a_quick_run_writes_rows_beside_the_sb3_ones(tmp_path: Path) -> None:
    sb3 = tmp_path / "sb3"
    sb3.mkdir()
    (sb3 / "results.json").write_text(json.dumps({"tables": {"fir_gym/Orbit-v0": [
        {"kind": "true", "iqm": -50.0, "low": -1e9, "high": 0.0, "seeds": 5}]}}))
    report = benchmark.run_benchmark(tmp_path / "jax", quick=True, seeds=2,
                                     plants=["fir_gym/Orbit-v0"], kinds=["true"],
                                     compare_with=sb3, progress=False)
    (row,) = report["tables"]["fir_gym/Orbit-v0"]
    assert row["kind"] == "true" and row["seeds"] == [0, 1]
    assert row["iqm"] == pytest.approx(iqm([sum(e) / len(e) for e in row["episode_returns"]]))
    assert row["low"] <= row["iqm"] <= row["high"]
    assert row["inside"] is True and row["sb3_iqm"] == -50.0       # inside (-1e9, 0]
    # the same policies in the numpy env, on the SB3 benchmark's episodes
    assert len(row["numpy_returns"]) == 2 and all(len(r) == 2 for r in row["numpy_returns"])
    assert row["numpy_iqm"] == pytest.approx(
        iqm([sum(e) / len(e) for e in row["numpy_returns"]]))
    text = (tmp_path / "jax" / "BENCHMARK.md").read_text()
    assert "fir_gym/Orbit-v0" in text and "inside" in text and "yes" in text
    busy = row["compile_seconds"] + row["train_seconds"]            # one row, one process
    assert (f"Its 1 learned row compiled (or loaded from the cache) for "
            f"{row['compile_seconds']:.0f} s and trained for {row['train_seconds']:.0f} s in "
            f"all: no schedule in one process does that in less than {busy:.0f} s. The other "
            f"{report['seconds'] - busy:.0f} s went") in text
    assert (tmp_path / "jax" / "Orbit-v0" / "true" / "results.json").is_file()
    with pytest.raises(ValueError, match="compare-with"):
        benchmark.run_benchmark(tmp_path / "x", compare_with=tmp_path / "nothing",
                                progress=False)


def test_rows_on_two_worker_processes_are_the_rows_of_one(tmp_path: Path) -> None:
    """``jobs=2`` hands the rows to two processes, the costliest first: the report has the
    same rows in the plan's order, with the same numbers to the bit (each row is its own
    compiled program and seeds, whichever process runs it)."""
    kinds = ["true", "recurrent", "lqg"]          # recurrent: the costliest, handed out first
    assert benchmark.row_cost(("learned", {"kind": "recurrent", "steps": 10, "seeds": 1},
                               tmp_path)) > benchmark.row_cost(
        ("learned", {"kind": "true", "steps": 10, "seeds": 1}, tmp_path))
    one, two = (benchmark.run_benchmark(tmp_path / str(jobs), quick=True, seeds=1,
                                        plants=["fir_gym/Orbit-v0"], kinds=kinds,
                                        progress=False, jobs=jobs) for jobs in (1, 2))
    assert (one["jobs"], two["jobs"]) == (1, 2)
    rows_one, rows_two = (r["tables"]["fir_gym/Orbit-v0"] for r in (one, two))
    assert [r["kind"] for r in rows_two] == [r["kind"] for r in rows_one] == kinds
    for a, b in zip(rows_one, rows_two, strict=True):
        assert a["numpy_returns"] == b["numpy_returns"]
        assert a["episode_returns"] == b["episode_returns"]
    assert (tmp_path / "2" / "Orbit-v0" / "recurrent" / "results.json").is_file()
    busy = sum(r["compile_seconds"] + r["train_seconds"] for r in rows_two)
    assert ("on 2 worker processes, compilation included. Its 2 learned rows compiled"
            in (tmp_path / "2" / "BENCHMARK.md").read_text())
    assert (f"does that in less than {busy / 2:.0f} s. The other "
            f"{two['seconds'] * 2 - busy:.0f} s of the {two['seconds'] * 2:.0f} worker-seconds"
            in (tmp_path / "2" / "BENCHMARK.md").read_text())


def test_the_lqg_row_is_the_sb3_benchmarks_evaluation(tmp_path: Path) -> None:
    """The classical row: the SB3 benchmark's LQG job (``run_job``: its configuration,
    evaluated on the same episodes) gives the same returns; no JAX column, nothing timed."""
    from fir_gym.training.compare import run_job

    report = benchmark.run_benchmark(tmp_path / "jax", quick=True, plants=["fir_gym/Orbit-v0"],
                                     kinds=["lqg"], progress=False)
    (row,) = report["tables"]["fir_gym/Orbit-v0"]
    assert row["kind"] == "lqg" and row["iqm"] is None and row["seeds"] == [0]
    (job,) = [j for j in sb3_benchmark.benchmark_jobs(tmp_path / "sb3", quick=True,
                                                      plants=["fir_gym/Orbit-v0"])
              if j["config"].observation_kind == "lqg"]
    assert row["numpy_returns"] == [run_job(job)["returns"]]
    assert "| lqg " in (tmp_path / "jax" / "BENCHMARK.md").read_text()


def test_markdown_tables_read_the_benchmark_section_only() -> None:
    text = """
*fir_gym/Orbit-v0*

| controller | seeds | IQM return [95% CI] |
|---|---:|---|
| true | 3 | -1 [-2, -0.5] |

<!-- benchmark:start -->
*fir_gym/Orbit-v0*

| controller        | seeds | IQM return [95% CI]     | estimation gap |
|-------------------|------:|-------------------------|----------------|
| true              |     3 | -552.1 [-639.6, -464]   | —              |
| ekf               |     3 | -586.6 [-685.9, -491.1] | 0.06           |

## fir_gym/VanDerPol-v0

| kind | seeds | IQM return [95% CI] |
|---|---:|---|
| measurement-stack | 5 | -1.5e+03 [-2e+03, -1e+03] |
<!-- benchmark:end -->
| true | 3 | -9 [-9, -9] |
"""
    tables = benchmark.markdown_tables(text)
    assert tables == {
        "fir_gym/Orbit-v0": {"true": {"iqm": -552.1, "low": -639.6, "high": -464.0, "seeds": 3},
                             "ekf": {"iqm": -586.6, "low": -685.9, "high": -491.1, "seeds": 3}},
        "fir_gym/VanDerPol-v0": {"measurement-stack": {"iqm": -1500.0, "low": -2000.0,
                                                       "high": -1000.0, "seeds": 5}}}

