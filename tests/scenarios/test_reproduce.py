"""``fir-gym reproduce``: the structure of every ``--quick`` report (verdicts, scannable tables,
no number typed into a sentence), prose that follows the results, and byte-identical reports
on every runner backend (serial, joblib, a local Dask cluster)."""

import importlib
import re

import numpy as np
import pytest

from fir_gym.cli import main
from fir_gym.scenarios import SCENARIOS, paper001, paper003
from fir_gym.scenarios import paper000_oscillator as osc
from fir_gym.scenarios.prose import Prose, literal_numbers
from fir_gym.scenarios.report import Comparison, is_verdict

#: every number printed in the papers' tables (paper 002 and 004 print none)
PAPER_NUMBERS = {
    "paper000": set(osc.PAPER_TABLE1.values()),
    "paper001": set(paper001.PAPER_TABLE1["dpi1"]) | set(paper001.PAPER_TABLE1["dpi2"]),
    "paper003": {v for pair in paper003.PAPER_TABLE4.values() for v in pair}
    | {v for method in paper003.PAPER_TABLE5.values() for v in method.values()},
}
#: the widest a table line may be (the report must be scannable)
MAX_TABLE_LINE = 200


def _number(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def test_scenario_order():
    assert SCENARIOS == ("paper000", "paper001", "paper002", "paper003", "paper004", "sweeps")


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_report_opens_with_verdict_rows(quick_report, name):
    report = quick_report(name)
    assert report.summaries and all(isinstance(c, Comparison) for c in report.comparisons)
    for s in report.summaries:
        assert s.rows and s.setup
    for c in report.comparisons:
        assert c.quantity and c.reading and c.ours is not None and is_verdict(c.verdict)
        if c.paper is not None and _number(c.paper) is not None:
            assert c.note, f"{c.quantity}: a paper number needs the reason for any difference"
        if c.paper is None:
            assert c.verdict == "beyond the paper"
    text = report.to_text(markdown=True)
    # every Markdown table is well formed (no cell holds a bare "|") and scannable
    for block in re.findall(r"(?:^\|.*\n?)+", text, flags=re.MULTILINE):
        counts = {line.count("|") for line in block.strip().splitlines()}
        assert len(counts) == 1, block.splitlines()[0]
    for line in text.splitlines():
        if line.startswith("|"):
            assert len(line) <= MAX_TABLE_LINE, line[:120]
    assert re.search(r"\|\s*quantity\s*\|\s*paper\s*\|\s*ours\s*\|\s*reading\s*\|\s*verdict\s*\|"
                     r"\s*why\s*\|", text)


@pytest.mark.parametrize("name", SCENARIOS)
def test_no_sentence_carries_a_number_typed_into_the_code(quick_report, name):
    """Every number in a note, reading, setup line, quantity or reason is formatted from a
    value (a result or a setting), never written into the sentence (prose.literal_numbers)."""
    offenders = [(str(t)[:80], literal_numbers(t)) for t in quick_report(name).sentences()
                 if literal_numbers(t)]
    assert offenders == []


@pytest.mark.parametrize("name", sorted(PAPER_NUMBERS))
def test_every_paper_number_appears_beside_ours(quick_report, name):
    printed = {c.paper for c in quick_report(name).comparisons}
    assert PAPER_NUMBERS[name] <= printed


def _values(text):
    return [float(v) for v in re.findall(r"[-+]?\d+\.?\d*(?:e[-+]?\d+)?", text)]


def test_prose_follows_the_results_when_the_seed_changes(monkeypatch):
    """Paper 003's Table 5 note: its ratio and LSM error come from the figures of the run that
    wrote it — another seed, other numbers, each equal to its own figures."""
    monkeypatch.setitem(paper003.SWEEP_AXES, True, {"amplitude": (5.0,), "frequency": (1.0,),
                                                    "theta0": (0.0,), "seconds": (1.0,)})
    monkeypatch.setattr(paper003, "CELLS", {k: paper003.CELLS[k] for k in ("quiet", "lively",
                                                                           "eq15·quiet",
                                                                           "eq5·quiet")})
    notes = {}
    for seed in (1, 2):
        report = paper003.run(seed=seed, quick=True, runs=2)
        note = next(n for n in report.notes if n.startswith("Table 5, UKF M0"))
        assert isinstance(note, Prose)
        q = report.figures["cells"]["quiet"]
        rmse = q["ukf"][("param", q["cell"].t5)][0][1]
        assert note.values["a"] == pytest.approx(rmse / 0.0010)
        assert f"{rmse / 0.0010:.2g}×" in note
        notes[seed] = note
    assert notes[1] != notes[2]


def test_prose_follows_a_changed_setting(monkeypatch):
    """Paper 001's setup line and reasons carry the uncertainty box it ran with."""
    monkeypatch.setitem(paper001.NOISE_BOX, "dq", 0.02)
    monkeypatch.setattr(paper001, "HORIZONS", (1.0, None))
    monkeypatch.setitem(paper001.PAPER_TABLE1, "dpi1", paper001.PAPER_TABLE1["dpi1"][::3])
    monkeypatch.setitem(paper001.PAPER_TABLE1, "dpi2", paper001.PAPER_TABLE1["dpi2"][::3])
    report = paper001.run(quick=True)
    assert "|Δq| ≤ 0.02" in report.summaries[0].setup
    row = next(c for c in report.comparisons if c.quantity == "Δπ₁, FIR T=1"
               and c.reading == paper001.READINGS[paper001.DEFAULT])
    corner = report.figures["res"][(1.0, "perturbed")]["corner_end"]
    assert corner["dq"] == pytest.approx(0.02)
    assert f"{report.figures['res'][(1.0, 'perturbed')]['exact1']:.2g}" in row.note


def test_same_seed_same_figures():
    module = importlib.import_module("fir_gym.scenarios.paper002")
    a, b = module.run(seed=7, quick=True, runs=2), module.run(seed=7, quick=True, runs=2)
    np.testing.assert_equal(a.figures, b.figures)
    assert a.to_text() == b.to_text()


def _reproduce(tmp_path, backend):
    out = tmp_path / backend
    args = ["reproduce", "--quick", "--runs", "2", "--no-progress", "--out", str(out)]
    if backend != "serial":
        args += ["--backend", backend, "--jobs", "2"]
    assert main(args) == 0
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


def test_the_quick_reproduction_is_byte_identical_on_every_backend(tmp_path, capsys):
    """Every task carries its own seed and the task split never depends on the backend, so
    the whole REPORT.md is the same bytes serially, on two joblib workers and on a two-worker
    local Dask cluster; so are the figures, which the workers draw and the client writes."""
    pytest.importorskip("distributed")
    serial = _reproduce(tmp_path, "serial")
    assert sum(name.endswith(".png") for name in serial) >= len(SCENARIOS)
    assert _reproduce(tmp_path, "joblib") == serial
    assert _reproduce(tmp_path, "dask") == serial
    text = serial["REPORT.md"].decode()
    for name in serial:                           # every figure written is in the report
        assert name == "REPORT.md" or f"]({name})" in text
    assert "## Verdicts" in text and text.count("\n## Paper ") == len(SCENARIOS) - 1
    assert "## Beyond the papers" in text
