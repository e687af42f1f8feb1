"""The summary at the top of REPORT.md: its counts are a tally of the verdict column of every
section's tables (read back from the Markdown), and its findings follow the stated rule."""

import math
from collections import Counter

import pytest

from fir_gym.scenarios.prose import Printed
from fir_gym.scenarios.report import Report, claim, reproduced
from fir_gym.scenarios.report_file import write_report
from fir_gym.scenarios.summary import (
    COLUMNS,
    FINDINGS_PER_PAPER,
    FINDINGS_RULE,
    column,
    factor,
    findings,
    summary_text,
    verdict_counts,
)

PAPERS = ("paper000", "paper001", "paper002", "paper003", "paper004")


def _cells(line):
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _sections(text):
    """REPORT.md cut at its ``## `` headings: heading -> lines."""
    out, name = {}, None
    for line in text.splitlines():
        if line.startswith("## "):
            name = line[3:]
            out[name] = []
        elif name is not None:
            out[name].append(line)
    return out


def _tally_of_verdict_columns(lines):
    """Count the verdict cells of every table under ``| quantity | ... | verdict |`` headers."""
    tally, verdict_at = Counter(), None
    for line in lines:
        if not line.startswith("|"):
            verdict_at = None
            continue
        cells = _cells(line)
        if cells[0] == "quantity" and "verdict" in cells:
            verdict_at = cells.index("verdict")
        elif verdict_at is not None and not set(line) <= set("|-: "):
            tally[column(cells[verdict_at])] += 1
    return tally


def test_the_summary_counts_are_a_tally_of_the_report_rows(quick_report, tmp_path):
    """Write REPORT.md from the five papers' quick reports and read it back: each paper's row
    of the summary table equals a tally of the verdict column of that paper's own section,
    and the "all" row their sum. The tally is taken from the text, not from the objects."""
    reports = [quick_report(name) for name in PAPERS]
    text = write_report(tmp_path, reports).read_text()
    sections = _sections(text)
    table = [_cells(line) for line in sections["Summary"] if line.startswith("| ")]
    header, rows = table[0], {row[0]: row for row in table[1:]}
    assert header == ["paper", *COLUMNS, "rows"]
    total = Counter()
    for report in reports:
        heading = next(h for h in sections if h.startswith(f"Paper {report.paper}:"))
        tally = _tally_of_verdict_columns(sections[heading])
        total += tally
        summary = rows[f"Paper {report.paper}"]
        assert [int(v) for v in summary[1:-1]] == [tally[h] for h in COLUMNS], report.paper
        assert int(summary[-1]) == sum(tally.values()) == len(report.comparisons) > 0
    assert [int(v) for v in rows["all"][1:]] == [total[h] for h in COLUMNS] + [
        sum(total.values())]
    assert text.index("## Summary") < text.index("## Verdicts") < text.index("## Paper 000")
    assert FINDINGS_RULE in text


def test_every_reading_line_of_the_report_is_short(quick_report, tmp_path):
    """The readings are a legend, one a line: no "Readings:" paragraph runs on."""
    text = write_report(tmp_path, [quick_report(name) for name in PAPERS]).read_text()
    assert text.count("\nReadings:\n- ") >= 5
    lines = text.splitlines()
    assert not any(line.startswith("Readings: ") for line in lines)
    legend, inside = [], False
    for line in lines:
        inside = line == "Readings:" or (inside and line.startswith("- "))
        if inside and line.startswith("- "):
            legend.append(line)
    assert legend and max(len(line) for line in legend) <= 160


def test_findings_rank_unreproduced_numbers_by_their_closest_reading_then_failed_claims():
    r = Report("999", "test")
    s = r.summary("Table 9", "setup", {"a": "first", "b": "second"})
    # q1: off by 10 (a) or 2 (b): its closest reading, b, is 2 apart
    s.compare("q1", Printed("1.0"), 10.0, "a", "not reproduced: differs")
    s.compare("q1", Printed("1.0"), 2.0, "b", "not reproduced: ambiguous")
    # q2: reproduced under reading b, so not a finding however far reading a lies
    s.compare("q2", Printed("1.0"), 100.0, "a", "not reproduced: differs")
    s.compare("q2", Printed("1.0"), 1.0, "b", reproduced("b"))
    # q3: 5 apart
    s.compare("q3", Printed("2.0"), 0.4, "a", "not reproduced: bound")
    s.compare("c1", "claim", "measured", "a", claim(False))
    s.compare("c2", "claim", "measured", "a", claim(True))
    s.compare("c3", "claim", "measured", "b", claim(False))
    found = findings(r)
    assert len(found) == FINDINGS_PER_PAPER == 3
    assert [(f.row.quantity, f.row.reading) for f in found] == [("q3", "a"), ("q1", "b"),
                                                                 ("c1", "a")]
    assert found[0].factor == pytest.approx(5.0) and found[1].factor == pytest.approx(2.0)
    assert "a factor 5 apart" in found[0].text() and found[2].factor is None
    assert verdict_counts(r) == {"reproduced": 0, "under a reading": 1, "not: bound": 1,
                                 "not: ambiguous": 1, "not: differs": 2, "claim holds": 1,
                                 "claim fails": 2, "beyond": 0}
    assert "Paper 999" in summary_text([r])


def test_factor():
    assert factor(2.0, 2.0) == 1.0
    assert factor(2.0, 8.0) == factor(8.0, 2.0) == pytest.approx(4.0)
    assert math.isinf(factor(0.0, 1.0)) and math.isinf(factor(-1.0, 1.0))
    with pytest.raises(ValueError):
        column("roughly reproduced")
