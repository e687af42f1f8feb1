"""``fir-gym reproduce``: the structure of every ``--quick`` report, and identical numbers on
every runner backend (serial, joblib, a local Dask cluster)."""

import importlib
import re

import numpy as np
import pytest

from fir_gym.scenarios import (
    SCENARIOS,
    paper000_orbit,
    paper000_oscillator,
    paper001,
    paper002,
    paper003,
)
from fir_gym.scenarios import paper000 as p000
from fir_gym.scenarios._montecarlo import (
    EpisodeTask,
    VectorTask,
    simulate_episode,
    simulate_vector,
    task_seed,
)
from fir_gym.scenarios.report import Comparison
from fir_gym.scenarios.runner import Runner

#: every number printed in the papers' tables (paper 002 and 004 print none)
PAPER_NUMBERS = {
    "paper000": set(paper000_oscillator.PAPER_TABLE1.values()),
    "paper001": set(paper001.PAPER_TABLE1["dpi1"]) | set(paper001.PAPER_TABLE1["dpi2"]),
    "paper003": {v for pair in paper003.PAPER_TABLE4.values() for v in pair}
    | {v for method in paper003.PAPER_TABLE5.values() for v in method.values()},
}


def _number(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def test_scenario_order():
    assert SCENARIOS == ("paper000", "paper001", "paper002", "paper003", "paper004", "sweeps")


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_report_starts_with_comparison_rows(quick_report, name):
    report = quick_report(name)
    assert report.comparisons and all(isinstance(c, Comparison) for c in report.comparisons)
    for c in report.comparisons:
        assert c.quantity and c.reading and c.ours is not None
        if c.paper is not None and _number(c.paper) is not None:
            assert c.note, f"{c.quantity}: a paper number needs the reason for any difference"
    text = report.to_text(markdown=True)
    assert "### Paper beside ours" in text
    # every Markdown table is well formed: no cell may contain a bare "|"
    for block in re.findall(r"(?:^\|.*\n?)+", text, flags=re.MULTILINE):
        counts = {line.count("|") for line in block.strip().splitlines()}
        assert len(counts) == 1, block.splitlines()[0]
    assert re.search(r"\|\s*quantity\s*\|\s*paper\s*\|\s*ours\s*\|\s*reading\s*\|\s*note\s*\|",
                     text)


@pytest.mark.parametrize("name", sorted(PAPER_NUMBERS))
def test_every_paper_number_appears_beside_ours(quick_report, name):
    printed = {_number(c.paper) for c in quick_report(name).comparisons}
    assert PAPER_NUMBERS[name] <= printed


@pytest.mark.parametrize(("name", "runs"), [("paper002", 2), ("paper003", 1)])
def test_same_seed_same_figures(name, runs):
    module = importlib.import_module(f"fir_gym.scenarios.{name}")
    a, b = module.run(seed=7, quick=True, runs=runs), module.run(seed=7, quick=True, runs=runs)
    np.testing.assert_equal(a.figures, b.figures)
    assert a.to_text() == b.to_text()


def test_paper001_columns_are_deterministic():
    """Paper 001 has no randomness: a column computed twice is identical (coarse grid)."""
    task = (1.0, "perturbed", 30)
    np.testing.assert_equal(paper001.column(task), paper001.column(task))


def test_paper000_same_seed_same_figures(monkeypatch):
    monkeypatch.setitem(paper000_orbit.STEPS, True, 120)
    monkeypatch.setitem(paper000_oscillator.STEPS, True, 405)
    monkeypatch.setattr(paper000_oscillator, "CHUNK", 1)        # one vector-env task per run
    a, b = p000.run(seed=5, quick=True, runs=2), p000.run(seed=5, quick=True, runs=2)
    np.testing.assert_equal(a.figures, b.figures)
    assert a.to_text() == b.to_text()


def test_joblib_and_dask_give_the_serial_numbers():
    """Every task carries its own seed, so any backend reproduces the serial numbers bit for
    bit: a whole scenario (paper 002, one episode per task) and the two kinds of Monte Carlo
    task the other scenarios use (single-env episodes and vector-env chunks)."""
    pytest.importorskip("distributed")
    tasks = {simulate_episode: [EpisodeTask("fir_gym/Orbit-v0", task_seed(1, i), 30)
                                for i in range(3)],
             simulate_vector: [VectorTask("fir_gym/UncertainOscillator-v0", task_seed(2, i), 2,
                                          360) for i in range(3)]}
    serial = {fn: Runner().map(fn, items) for fn, items in tasks.items()}
    report = paper002.run(seed=5, quick=True, runs=3)
    with Runner("joblib", jobs=2) as joblib, Runner("dask", jobs=2) as dask:
        for runner in (joblib, dask):
            for fn, items in tasks.items():
                np.testing.assert_equal(runner.map(fn, items), serial[fn])
            other = paper002.run(seed=5, quick=True, runs=3, runner=runner)
            np.testing.assert_equal(other.figures, report.figures)


def test_sweep_cells_filtered_in_workers_match_serial(tiny_sweep):
    """The sweep's tasks run the filters themselves: joblib workers must give the same bits."""
    serial = tiny_sweep.run(seed=2, quick=True, runs=2)
    parallel = tiny_sweep.run(seed=2, quick=True, runs=2, runner=Runner("joblib", jobs=2))
    np.testing.assert_equal(parallel.figures, serial.figures)
