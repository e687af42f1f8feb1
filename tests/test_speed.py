"""fir-gym speed: the timing helpers, the target table and the JSON output (no long timing)."""

import json

import pytest

from fir_gym.benchmarks import speed


def test_interleaved_times_every_function():
    calls = {"a": 0, "b": 0}

    def a():
        calls["a"] += 1

    def b():
        calls["b"] += 1

    t = speed.interleaved({"a": (a, 5), "b": (b, 3)}, repeats=2)
    assert set(t) == {"a", "b"} and all(v >= 0 for v in t.values())
    assert calls == {"a": 1 + 2 * 5, "b": 1 + 2 * 3}       # warm-up + blocks


def test_targets_report_ratios_and_verdicts():
    results = {
        "kalman": {"rows": [{"model": "linear 2x1", "filter": "kf", "ratio": 0.2,
                             "batched_us": 0.3, "throughput_vs_filterpy": 60.0},
                            {"model": "linear 2x1", "filter": "ekf", "data": "mismatched",
                             "ratio": 0.4, "batched_us": 0.05, "throughput_vs_filterpy": 60.0},
                            {"model": "nonlinear 4x2", "filter": "ukf", "ratio": 0.6,
                             "batched_us": 2.5, "throughput_vs_filterpy": None}],
                   "efir": {"batched_us": 3.0, "throughput_vs_filterpy_ekf": 30.0},
                   "fixed_cost": [{"batch": 1, "python_us": 3.0},
                                  {"batch": 64, "python_us": None}]},
        "envs": {"plants": [{"env": "fir_gym/VanDerPol-v0", "sync64_us": 50.0,
                             "native1024_us": 2.0, "wiener1024_us": 1.0}],
                 "pendulum": [{"friction": "paper", "steps_per_s_ratio": 1.1},
                              {"friction": "coulomb", "steps_per_s_ratio": 0.8,
                               "inverted_pendulum_us": 20.0, "mujoco_us": 16.0}]},
        "wrappers": {"vector": [{"env": "fir_gym/Orbit-v0", "mode": "sync", "ratio": 1.1},
                                {"env": "fir_gym/Orbit-v0", "mode": "native", "ratio": 2.0,
                                 "bare_us": 10.0, "ekf_floor_us": 4.0}]},
    }
    rows = {r["target"]: r for r in speed.targets(results)}
    assert rows["kf linear 2x1 (consistent): single / filterpy"]["met"] is True
    assert rows["kf linear 2x1 (consistent): B=1024 µs per system-step"]["met"] is False
    assert rows["ekf linear 2x1 (mismatched): single / filterpy"]["met"] is False   # ≤ 0.35
    assert rows["ekf linear 2x1 (mismatched): B=1024 µs per system-step"]["met"] is True
    assert rows["ukf nonlinear 4x2 (consistent): single / filterpy"]["met"] is False
    assert rows["ukf nonlinear 4x2 (consistent): B=1024 throughput / looped filterpy"][
        "met"] is None
    assert rows["efir n=3 N=10: B=1024 µs per system-step"]["met"] is False     # ≤ 1.6
    assert rows["Estimator.step fixed Python cost, B=1 (µs)"]["met"] is True
    assert rows["Estimator.step fixed Python cost, B=64 (µs)"]["met"] is None
    assert rows["VanDerPol-v0 native×1024 / sync steps per second"]["value"] == 25.0
    assert rows["VanDerPol-v0 native×1024 / sync steps per second"]["met"] is False
    assert rows["VanDerPol-v0 native×1024 / sync steps per second"]["ceiling"] == 50.0
    coulomb = "PendulumSlider-v0 (coulomb) / InvertedPendulum-v5 steps per second"
    assert rows[coulomb]["ceiling"] == 1.25 and rows[coulomb]["met"] is False
    assert rows["PendulumSlider-v0 (paper) / InvertedPendulum-v5 steps per second"][
        "ceiling"] is None
    native = rows["VectorEstimatorObservation(ekf) Orbit-v0 native×64: wrapped / bare"]
    assert native["met"] is False and native["ceiling"] == pytest.approx(1.4)
    assert native["limit"] == "≤ 1.3"
    assert rows["VectorEstimatorObservation(ekf) Orbit-v0 sync×64: wrapped / bare"][
        "ceiling"] is None
    speed.print_targets(list(rows.values()))                 # prints without error


def test_main_rejects_unknown_sections_and_writes_json(tmp_path, monkeypatch, capsys):
    with pytest.raises(SystemExit):
        speed.main(["nonsense"])
    monkeypatch.setitem(speed.RUNNERS, "kalman",
                        (lambda quick: {"rows": [], "efir": {"batched_us": 1.0,
                                                             "throughput_vs_filterpy_ekf": 40.0}},
                         lambda res: print("kalman table")))
    out = tmp_path / "speed.json"
    assert speed.main(["kalman", "--quick", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["kalman"]["efir"]["batched_us"] == 1.0 and "machine" in data
    assert "kalman table" in capsys.readouterr().out
    ran = []
    for name in speed.SECTIONS:
        monkeypatch.setitem(speed.RUNNERS, name, (lambda quick, name=name: ran.append(name) or {},
                                                  lambda res: None))
    monkeypatch.setattr(speed, "targets", lambda results: [])
    assert speed.main(["--quick"]) == 0 and ran == list(speed.SECTIONS)    # default: all


def test_the_kalman_section_prints_its_rows(capsys):
    from fir_gym.benchmarks import kalman_speed
    row = {"model": "linear 2x1", "filter": "kf", "data": "mismatched", "single_us": 2.0,
           "filterpy_us": 16.0, "ratio": 0.125, "batched_us": 0.04,
           "throughput_vs_filterpy": 400.0, "compiled_speedup": 1.0, "flagged": True}
    kalman_speed.print_kalman({
        "rows": [row], "fixed_cost": [{"batch": 1, "step_us": 3.5, "kernel_us": 1.0,
                                       "python_us": 2.5}],
        "efir": {"efir_us": 20.0, "ekf_us": 10.0, "efir_over_ekf": 2.0, "batched_us": 1.0,
                 "throughput_vs_filterpy_ekf": None}})
    out = capsys.readouterr().out
    assert "mismatched" in out and "fixed cost" in out and "2.5" in out
