"""benchmark-controllers: the --quick run end to end, and the answers computed from a table."""

import json

import pytest

pytest.importorskip("stable_baselines3")

from fir_gym.cli import main
from fir_gym.training.benchmark import KINDS, PLANTS, answers, benchmark_jobs, plant_kinds


def _row(kind, iqm, low, high, norm=(1.0, 1.0, 1.0)):
    return {"kind": kind, "iqm": iqm, "low": low, "high": high, "normalised": norm[0],
            "normalised_low": norm[1], "normalised_high": norm[2]}


def test_answers_follow_the_intervals():
    table = {"fir_gym/Orbit-v0": [
        _row("true", -100, -101, -99),
        _row("ekf", -103, -106, -100, (0.97, 0.94, 1.01)),
        _row("ukf", -120, -125, -115, (0.83, 0.8, 0.87)),
        _row("measurement-stack", -150, -160, -140),
        _row("recurrent", -130, -140, -120),
        _row("lqg", -95, -95, -95)]}
    text = answers(table)[0]
    assert "best estimate-fed controller (ekf) scores 0.97 [0.94, 1.01]" in text
    assert "matches it" in text
    assert "the best filter (ekf) beats" in text and "(recurrent)" in text
    assert "LQG beats (-95 vs -103, intervals apart) the best learned controller without " \
           "the true state (ekf)" in text
    assert "beats (-95 vs -100" in text
    # within 1 %: a match, however narrow the intervals
    table["fir_gym/Orbit-v0"][-1] = _row("lqg", -100.5, -100.5, -100.5)
    assert "and matches (-100.5 vs -100, within 1%) PPO on the true state" in answers(table)[0]


def test_quick_benchmark_runs_every_plant_and_kind(tmp_path, capsys):
    assert main(["benchmark-controllers", "--quick", "--out", str(tmp_path),
                 "--no-progress"]) == 0
    report = json.loads((tmp_path / "results.json").read_text())
    assert report["quick"] and set(report["tables"]) == set(PLANTS)
    for env_id, table in report["tables"].items():
        assert [r["kind"] for r in table] == list(plant_kinds(env_id))
        estimated = {r["kind"]: r["rmse"] for r in table}
        filters = [k for k in estimated if k not in ("true", "measurement",
                                                     "measurement-stack", "recurrent")]
        assert len(filters) >= 4 and all(estimated[k] is not None for k in filters)
        assert estimated["true"] is None
    assert len(report["answers"]) == len(PLANTS)
    text = (tmp_path / "BENCHMARK.md").read_text()
    assert "IQM return [95% CI]" in text and "## Answers" in text
    for env_id in PLANTS:                  # a figure exactly where a training episode finished
        figure = tmp_path / "figures" / f"{env_id.split('/')[-1]}_learning_curves.png"
        assert figure.is_file() == report["learning_curves"][env_id]
        assert (figure.name in text) == figure.is_file()
    assert "Answers" in capsys.readouterr().out


def test_unknown_benchmark_plant_is_an_error(tmp_path, capsys):
    assert main(["benchmark-controllers", "--quick", "--plants", "fir_gym/Nope-v0",
                 "--out", str(tmp_path)]) == 2
    assert "unknown benchmark plant" in capsys.readouterr().err


def test_answers_compare_paired_episodes_when_the_table_has_them():
    """With each row's episode returns, a kind that is worse on every shared episode loses
    although its interval overlaps the other's; a noisy difference around 0 is a tie."""
    import numpy as np

    rng = np.random.default_rng(0)
    e = rng.normal(-100.0, 30.0, size=20)
    noise = np.where(np.arange(20) % 2 == 0, 20.0, -20.0) - 2.5
    rows = {"true": [e], "ekf": [e + noise], "recurrent": [e - 40.0], "lqg": [e - 2.0]}
    table = []
    for kind, runs in rows.items():
        mean = float(np.mean(runs[0]))
        table.append({**_row(kind, mean, mean - 15, mean + 15), "episode_returns": runs})
    text = answers({"fir_gym/Orbit-v0": table})[0]
    assert "and loses to (-107.5 vs -105.5, paired difference [-2, -2]) PPO on the true " \
           "state" in text
    assert "the best filter (ekf) beats" in text
    table[-1]["episode_returns"] = [e + noise]
    table[-1]["iqm"] = float(np.mean(e + noise))
    assert "contains 0) PPO on the true state" in answers({"fir_gym/Orbit-v0": table})[0]


def test_the_kinds_per_plant_are_the_jax_backends_and_readmes():
    """Both backends train the same rows: the robustness plan's learned estimators per plant
    (CarrierMotion-v0, a linear plant: kf, ukf, fir, ufir), the plain kinds and the LQG."""
    assert plant_kinds("fir_gym/CarrierMotion-v0") == (
        "true", "measurement", "measurement-stack", "recurrent", "kf", "ukf", "fir", "ufir",
        "lqg")
    assert plant_kinds("fir_gym/Orbit-v0")[4:] == ("ekf", "ukf", "efir", "lqg")
    assert set(KINDS) == {k for env_id in PLANTS for k in plant_kinds(env_id)}


def test_kinds_choose_rows_and_a_plant_without_one_has_no_such_row(tmp_path):
    jobs = benchmark_jobs(tmp_path, seeds=2, kinds=["ekf", "lqg"],
                          plants=["fir_gym/Orbit-v0", "fir_gym/CarrierMotion-v0"])
    got = [(j["config"].env_id.split("/")[-1], j["config"].observation_kind, j["config"].seed)
           for j in jobs]
    assert got == [("Orbit-v0", "ekf", 0), ("Orbit-v0", "ekf", 1), ("Orbit-v0", "lqg", 0),
                   ("CarrierMotion-v0", "lqg", 0)]
    with pytest.raises(ValueError, match="kinds must be among"):
        benchmark_jobs(tmp_path, kinds=["ekf", "bogus"])
