"""benchmark-robustness on a plant of the user's own (issue 25): ``--plants module:id``
imports the module (which registers the plant) and runs both grids on it, with the plan
a plant the benchmark was not tuned for gets (:func:`fir_gym.robustness.plan.plant_plan`)."""

from __future__ import annotations

import json
import warnings

import pytest

from fir_gym.cli import main
from fir_gym.robustness.plan import DEFAULT_STEPS, WINDOW, plant_plan, short_name

PLANT = "user_pendulum:user_pendulum/Pendulum-v0"


def test_the_plan_of_a_users_plant():
    plan = plant_plan(PLANT)
    assert plan.steps == DEFAULT_STEPS and plan.estimator_kwargs == WINDOW
    # a nonlinear model: the extended Kalman filter, the UKF and the extended FIR filter
    assert plan.learned_estimators == ("ekf", "ukf", "efir")
    assert short_name(PLANT) == "Pendulum-v0"


def test_quick_benchmark_on_a_users_plant(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["benchmark-robustness", "--quick", "--plants", PLANT, "--conditions",
                     "dropout", "--out", str(tmp_path), "--no-progress"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["plants"] == [PLANT]
    cells = {(c["condition"], c["strength"]): c for c in results["tables"]}
    assert set(cells) == {("nominal", 0.0), ("dropout", 0.3)}
    kinds = {r["kind"] for c in cells.values() for r in c["rows"]}
    # the LQG grid (true state, estimators plain and gated) and the learned grid's kinds
    assert {"lqg-true", "true", "measurement-stack", "ekf"} <= kinds
    assert any(k.startswith("lqg-") and k != "lqg-true" for k in kinds)
    assert (tmp_path / "runs" / "Pendulum-v0").is_dir()
    assert "Pendulum-v0" in (tmp_path / "REPORT.md").read_text()


@pytest.mark.parametrize("plant, needle", [
    ("no_such_module_here:x/Y-v0", "cannot import module 'no_such_module_here'"),
    ("user_pendulum:user_pendulum/Nope-v0", "unknown benchmark plant"),
    ("CartPole-v1", "is not a fir-gym plant"),
])
def test_a_plant_that_is_not_one_is_refused_in_one_line(tmp_path, capsys, plant, needle):
    try:
        code = main(["benchmark-robustness", "--quick", "--lqg-only", "--plants", plant,
                     "--out", str(tmp_path)])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and needle in err[0], err
