"""benchmark-robustness end to end (--quick), its report, the same numbers on every backend,
reuse keyed by the code's version, and its one-line refusals."""

from __future__ import annotations

import json
import warnings

import pytest

from fir_gym.cli import main
from fir_gym.robustness.benchmark import lqg_tasks, run_benchmark, run_task
from fir_gym.scenarios.runner import Runner


def one_line(capsys, argv, *needles):
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "Traceback" not in err[0], err
    for needle in needles:
        assert needle in err[0], err[0]


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("robustness")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["benchmark-robustness", "--quick", "--out", str(out), "--no-progress",
                     "--plants", "fir_gym/Orbit-v0"]) == 0
    return out


def test_quick_run_writes_every_cell_with_its_numbers(quick):
    results = json.loads((quick / "results.json").read_text())
    conditions = set(results["conditions"])
    assert conditions == {"nominal", "mismatch", "burst", "dropout", "outliers", "stuck",
                          "bias", "delay", "multirate"}
    cells = {(c["condition"], c["strength"]) for c in results["tables"]}
    assert len(cells) == len(conditions)                     # --quick: the middle strength
    names = {r["name"] for c in results["tables"] for r in c["rows"]}
    assert {"lqg-true", "lqg-ekf", "lqg-ekf+gate", "true (nominal)",
            "measurement-stack (nominal)", "ekf (nominal)", "ekf+gate (nominal)",
            "true (dr-dropout)"} <= names
    for cell in results["tables"]:
        for row in cell["rows"]:
            assert row["low"] <= row["iqm"] <= row["high"]
            if row["name"] not in ("lqg-true",) and not row["name"].startswith("true"):
                assert row["gap"] is not None
        if cell["condition"] == "burst":
            assert any("recovery" in r for r in cell["rows"])
    assert results["answers"] and all(a.startswith("Orbit-v0: ") for a in results["answers"])
    assert results["records"] and results["code_version"]


def test_quick_report_and_figures(quick):
    report = (quick / "REPORT.md").read_text()
    assert report.startswith("# Robustness in the loop")
    assert "--quick run" in report and "## Answers" in report
    for figure in ("Orbit-v0_lqg.png", "Orbit-v0_learned.png"):
        assert (quick / "figures" / figure).stat().st_size > 10_000
        assert f"figures/{figure}" in report


def test_report_only_rebuilds_from_results(quick, capsys):
    before = (quick / "REPORT.md").read_text()
    (quick / "REPORT.md").unlink()
    assert main(["benchmark-robustness", "--out", str(quick), "--report-only"]) == 0
    assert (quick / "REPORT.md").read_text() == before


def test_a_rerun_reuses_learned_tasks_only_at_the_same_code_version(quick, monkeypatch):
    from fir_gym.robustness import learned_grid
    from fir_gym.robustness.benchmark import learned_tasks
    from fir_gym.robustness.plan import check_selection

    plants, conditions = check_selection(["fir_gym/Orbit-v0"], None)
    task = learned_tasks(plants, conditions, quick, quick=True)[0]
    assert learned_grid.run_learned_task(task).get("reused") is True
    monkeypatch.setattr("fir_gym.code_version.code_version", lambda: "another-version")
    assert not learned_grid.run_learned_task(task).get("reused")


@pytest.mark.parametrize("backend", ["joblib", "dask"])
def test_the_lqg_grid_gives_the_same_numbers_on_every_backend(backend):
    tasks = lqg_tasks(["fir_gym/Orbit-v0"], ["nominal", "dropout", "mismatch"], quick=True)[:8]
    serial = [run_task(t) for t in tasks]
    with Runner(backend, jobs=2) as runner:
        parallel = runner.map(run_task, tasks)
    assert serial == parallel


def test_lqg_only_runs_without_training(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = run_benchmark(tmp_path, quick=True, plants=["fir_gym/CarrierMotion-v0"],
                               conditions=["outliers"], learned=False)
    assert report["learned_tasks"] == 0 and report["lqg_tasks"] > 0
    assert {c["condition"] for c in report["tables"]} == {"nominal", "outliers"}


@pytest.mark.parametrize(("argv", "needle"), [
    (["--conditions", "nominal,rain"], "unknown condition 'rain'"),
    (["--plants", "fir_gym/Nope-v0"], "unknown benchmark plant 'fir_gym/Nope-v0'"),
    (["--report-only"], "holds no results.json"),
])
def test_bad_selections_are_one_line(tmp_path, capsys, argv, needle):
    one_line(capsys, ["benchmark-robustness", "--out", str(tmp_path / "x"), *argv], needle)


def test_the_readme_sections_are_computed_from_the_results(quick, tmp_path):
    """The README's two benchmark sections are written from results.json: every return they
    print is one of the results' IQMs, and the markers keep their place."""
    import importlib.util
    import re
    from pathlib import Path

    script = Path(__file__).parents[2] / "scripts" / "update_readme_benchmarks.py"
    spec = importlib.util.spec_from_file_location("update_readme_benchmarks", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    results = json.loads((quick / "results.json").read_text())
    readme = tmp_path / "README.md"
    readme.write_text("top\n<!-- robustness:start -->\nold\n<!-- robustness:end -->\nmiddle\n"
                      "<!-- benchmark:start -->\nold\n<!-- benchmark:end -->\nend\n")
    text = module.replace_block(readme.read_text(), "robustness",
                                module.robustness_block(results))
    text = module.replace_block(text, "benchmark", module.controllers_block(results))
    assert text.startswith("top\n<!-- robustness:start -->\n**Benchmark: robustness")
    assert "old" not in text and text.endswith("<!-- benchmark:end -->\nend\n")
    iqms = {f"{r['iqm']:.3g}" for c in results["tables"] for r in c["rows"]}
    table = "\n".join(line for line in text.splitlines()
                      if line.startswith("| ") and not line.startswith("| plant"))
    printed = re.findall(r"(?<![\w.])(-?\d+(?:\.\d+)?(?:e[+-]?\d+)?) \(", table)
    assert printed and set(printed) <= iqms
    for answer in results["answers"]:
        assert answer in text
